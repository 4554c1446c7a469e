// 2-D convolution, NCHW, grouped (depthwise included), strided, dilated, zero-padded, with
// bias and a fused activation; one invocation per output element.
// p: [count, N, C, H, W, M, OH, OW, KH, KW, sh, sw, pt, pl, dh, dw, group, act, a, b]
// w: [M, C / group, KH, KW]; bias: [M].
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
    let ox = i % OW;
    let oy = (i / OW) % OH;
    let m = (i / (OW * OH)) % M;
    let n = i / (OW * OH * M);
    let cpg = C / p[16];
    let g = m / (M / p[16]);
    var acc = bias[m];
    for (var c = 0u; c < cpg; c = c + 1u) {
        let ci = g * cpg + c;
        let plane = (n * C + ci) * H;
        let wbase = (m * cpg + c) * KH;
        for (var ky = 0u; ky < KH; ky = ky + 1u) {
            let iy = i32(oy * p[10] + ky * p[14]) - i32(p[12]);
            if iy < 0 || iy >= i32(H) { continue; }
            let row = (plane + u32(iy)) * W;
            let wrow = (wbase + ky) * KW;
            for (var kx = 0u; kx < KW; kx = kx + 1u) {
                let ix = i32(ox * p[11] + kx * p[15]) - i32(p[13]);
                if ix < 0 || ix >= i32(W) { continue; }
                acc = acc + src[row + u32(ix)] * w[wrow + kx];
            }
        }
    }
    dst[i] = act(acc, p[17], pf(18u), pf(19u));
}
