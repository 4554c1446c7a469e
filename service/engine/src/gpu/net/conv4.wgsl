// 2-D convolution as conv.wgsl, four output channels per invocation (ungrouped): each input
// value is read once for the four, and the index arithmetic is shared.
// p: [count, N, C, H, W, M, OH, OW, KH, KW, sh, sw, pt, pl, dh, dw, group, act, a, b]
// (count = N ceil(M / 4) OH OW); w: [M4, C, KH, KW] and bias: [M4], M4 = 4 ceil(M / 4), the
// channels from M on zero (the plan pads them): the last block of four writes only the
// channels below M.
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> w: array<f32>;
@group(0) @binding(3) var<storage, read> bias: array<f32>;
@group(0) @binding(4) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = linear_id(wg, nwg, lid);
    if i >= p[0] { return; }
    let C = p[2]; let H = p[3]; let W = p[4]; let M = p[5]; let OH = p[6]; let OW = p[7];
    let KH = p[8]; let KW = p[9];
    let M4 = (M + 3u) / 4u;
    let ox = i % OW;
    let oy = (i / OW) % OH;
    let m = ((i / (OW * OH)) % M4) * 4u;
    let n = i / (OW * OH * M4);
    let wstride = C * KH * KW;
    var acc = vec4<f32>(bias[m], bias[m + 1u], bias[m + 2u], bias[m + 3u]);
    for (var c = 0u; c < C; c = c + 1u) {
        let plane = (n * C + c) * H;
        let wbase = (m * C + c) * KH;
        for (var ky = 0u; ky < KH; ky = ky + 1u) {
            let iy = i32(oy * p[10] + ky * p[14]) - i32(p[12]);
            if iy < 0 || iy >= i32(H) { continue; }
            let row = (plane + u32(iy)) * W;
            let wrow = (wbase + ky) * KW;
            for (var kx = 0u; kx < KW; kx = kx + 1u) {
                let ix = i32(ox * p[11] + kx * p[15]) - i32(p[13]);
                if ix < 0 || ix >= i32(W) { continue; }
                let x = src[row + u32(ix)];
                let k = wrow + kx;
                acc = acc + x * vec4<f32>(w[k], w[k + wstride], w[k + 2u * wstride], w[k + 3u * wstride]);
            }
        }
    }
    let plane_out = OH * OW;
    let o = ((n * M + m) * OH + oy) * OW + ox;
    let a = pf(18u);
    let b = pf(19u);
    dst[o] = act(acc.x, p[17], a, b);
    if m + 1u < M { dst[o + plane_out] = act(acc.y, p[17], a, b); }
    if m + 2u < M { dst[o + 2u * plane_out] = act(acc.z, p[17], a, b); }
    if m + 3u < M { dst[o + 3u * plane_out] = act(acc.w, p[17], a, b); }
}
