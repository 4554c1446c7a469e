// 2-D pooling over NCHW planes: mode 0 average (count_include_pad: divide by the window's
// size, else by its cells inside the input), 1 max; padded cells are left out of a max.
// p: [count, planes, H, W, OH, OW, KH, KW, sh, sw, pt, pl, mode, count_include_pad]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = linear_id(wg, nwg, lid);
    if i >= p[0] { return; }
    let H = p[2]; let W = p[3]; let OH = p[4]; let OW = p[5]; let KH = p[6]; let KW = p[7];
    let ox = i % OW;
    let oy = (i / OW) % OH;
    let plane = i / (OW * OH);
    let is_max = p[12] == 1u;
    var acc = select(0.0, -3.0e38, is_max);
    var cells = 0u;
    for (var ky = 0u; ky < KH; ky = ky + 1u) {
        let iy = i32(oy * p[8] + ky) - i32(p[10]);
        if iy < 0 || iy >= i32(H) { continue; }
        for (var kx = 0u; kx < KW; kx = kx + 1u) {
            let ix = i32(ox * p[9] + kx) - i32(p[11]);
            if ix < 0 || ix >= i32(W) { continue; }
            let v = src[(plane * H + u32(iy)) * W + u32(ix)];
            acc = select(acc + v, max(acc, v), is_max);
            cells = cells + 1u;
        }
    }
    if !is_max {
        let d = select(max(cells, 1u), KH * KW, p[13] == 1u);
        acc = acc / f32(d);
    }
    dst[i] = acc;
}
