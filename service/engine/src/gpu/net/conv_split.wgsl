// 2-D convolution as conv_row.wgsl (ungrouped, four output channels a block), for layers with
// few outputs and long sums (the encoders' 16 x 16 and 8 x 8 bottlenecks, the
// squeeze-excitation's 1 x 1 planes): one 64-wide workgroup per block of four channels at one
// output pixel, its invocations splitting the sum over input channels and taps (each every
// 64th term), then a tree reduction in workgroup memory. One invocation per block would add
// its C KH KW terms one after another (864 at 96 channels and 3 x 3) while most of a large
// GPU idles.
// p: [count (blocks x 64), N, C, H, W, M, OH, OW, KH, KW, sh, sw, pt, pl, dh, dw, group, act, a,
// b] (blocks = N ceil(M / 4) OH OW); w: [M4 / 4, C, KH, KW] of vec4 and bias: [M4 / 4] of
// vec4, as conv_row.wgsl.
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> w: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> bias: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<f32>;

var<workgroup> part: array<vec4<f32>, 64>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    // The workgroup's block: uniform across the workgroup (the barriers below need it).
    let blk = wg.y * nwg.x + wg.x;
    if blk >= p[0] / 64u { return; }
    let C = p[2]; let H = p[3]; let W = p[4]; let M = p[5]; let OH = p[6]; let OW = p[7];
    let KH = p[8]; let KW = p[9];
    let MB = (M + 3u) / 4u;
    let ox = blk % OW;
    let oy = (blk / OW) % OH;
    let mb = (blk / (OW * OH)) % MB;
    let n = blk / (OW * OH * MB);
    let y0 = i32(oy * p[10]) - i32(p[12]);
    let x0 = i32(ox * p[11]) - i32(p[13]);
    let taps = KH * KW;
    let terms = C * taps;
    let wbase = mb * terms;
    var acc = vec4<f32>(0.0);
    for (var r = lid.x; r < terms; r = r + 64u) {
        let c = r / taps;
        let t = r - c * taps;
        let ky = t / KW;
        let kx = t - ky * KW;
        let iy = y0 + i32(ky * p[14]);
        let ix = x0 + i32(kx * p[15]);
        if iy >= 0 && iy < i32(H) && ix >= 0 && ix < i32(W) {
            acc = acc + src[((n * C + c) * H + u32(iy)) * W + u32(ix)] * w[wbase + r];
        }
    }
    part[lid.x] = acc;
    workgroupBarrier();
    for (var s = 32u; s > 0u; s = s >> 1u) {
        if lid.x < s {
            part[lid.x] = part[lid.x] + part[lid.x + s];
        }
        workgroupBarrier();
    }
    if lid.x == 0u {
        let v = part[0] + bias[mb];
        let m = mb * 4u;
        let plane_out = OH * OW;
        let o = ((n * M + m) * OH + oy) * OW + ox;
        let op = p[17];
        let a = pf(18u);
        let b = pf(19u);
        dst[o] = act(v.x, op, a, b);
        if m + 1u < M { dst[o + plane_out] = act(v.y, op, a, b); }
        if m + 2u < M { dst[o + 2u * plane_out] = act(v.z, op, a, b); }
        if m + 3u < M { dst[o + 3u * plane_out] = act(v.w, op, a, b); }
    }
}
