// 2-D transposed convolution, NCHW, grouped, strided, dilated, with bias and a fused
// activation, written as a gather: output (oy, ox) takes input (iy, ix) through tap (ky, kx)
// where oy + pt = iy sh + ky dh (and likewise in x).
// p: [count, N, C, H, W, M, OH, OW, KH, KW, sh, sw, pt, pl, dh, dw, group, act, a, b]
// w: [C, M / group, KH, KW]; bias: [M].
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
    let KH = p[8]; let KW = p[9]; let sh = i32(p[10]); let sw = i32(p[11]);
    let ox = i % OW;
    let oy = (i / OW) % OH;
    let m = (i / (OW * OH)) % M;
    let n = i / (OW * OH * M);
    let mpg = M / p[16];
    let cpg = C / p[16];
    let g = m / mpg;
    let ml = m % mpg;
    var acc = bias[m];
    for (var c = 0u; c < cpg; c = c + 1u) {
        let ci = g * cpg + c;
        let plane = (n * C + ci) * H;
        let wbase = (ci * mpg + ml) * KH;
        for (var ky = 0u; ky < KH; ky = ky + 1u) {
            let ty = i32(oy) + i32(p[12]) - i32(ky * p[14]);
            if ty < 0 || ty % sh != 0 { continue; }
            let iy = ty / sh;
            if iy >= i32(H) { continue; }
            for (var kx = 0u; kx < KW; kx = kx + 1u) {
                let tx = i32(ox) + i32(p[13]) - i32(kx * p[15]);
                if tx < 0 || tx % sw != 0 { continue; }
                let ix = tx / sw;
                if ix >= i32(W) { continue; }
                acc = acc + src[(plane + u32(iy)) * W + u32(ix)] * w[(wbase + ky) * KW + kx];
            }
        }
    }
    dst[i] = act(acc, p[17], pf(18u), pf(19u));
}
