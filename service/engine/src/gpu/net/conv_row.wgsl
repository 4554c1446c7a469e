// 2-D convolution as conv4.wgsl, four output channels by four output columns of a row per
// invocation (ungrouped): each tap's four weights are one vector read once for the four
// columns, each input value read once for the four channels (16 products per five reads,
// against 4 per five in conv4). Blocks whose windows lie inside the input (most of a plane)
// skip the padding tests; the others test each column's tap.
// p: [count, N, C, H, W, M, OH, OW, KH, KW, sh, sw, pt, pl, dh, dw, group, act, a, b]
// (count = N ceil(M / 4) OH ceil(OW / 4)); w: [M4 / 4, C, KH, KW] of vec4 (the block's four
// channels at a tap) and bias: [M4 / 4] of vec4, M4 = 4 ceil(M / 4), the channels from M on
// zero (the plan pads them): only channels below M and columns below OW are written.
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> w: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> bias: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<f32>;

// Input value at (row start, column ix) or 0 outside the row's W columns.
fn tap(row: u32, ix: i32, W: u32) -> f32 {
    if ix < 0 || ix >= i32(W) { return 0.0; }
    return src[row + u32(ix)];
}

fn put(o: u32, v: vec4<f32>, cols: u32, a: f32, b: f32) {
    let op = p[17];
    dst[o] = act(v.x, op, a, b);
    if cols > 1u { dst[o + 1u] = act(v.y, op, a, b); }
    if cols > 2u { dst[o + 2u] = act(v.z, op, a, b); }
    if cols > 3u { dst[o + 3u] = act(v.w, op, a, b); }
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = linear_id(wg, nwg, lid);
    if i >= p[0] { return; }
    let C = p[2]; let H = p[3]; let W = p[4]; let M = p[5]; let OH = p[6]; let OW = p[7];
    let KH = p[8]; let KW = p[9]; let sh = p[10]; let sw = p[11];
    let dh = p[14]; let dw = p[15];
    let OWB = (OW + 3u) / 4u;
    let MB = (M + 3u) / 4u;
    let ox0 = (i % OWB) * 4u;
    let oy = (i / OWB) % OH;
    let mb = (i / (OWB * OH)) % MB;
    let n = i / (OWB * OH * MB);
    // Input row and column of the block's first output at tap (0, 0).
    let y0 = i32(oy * sh) - i32(p[12]);
    let x0 = i32(ox0 * sw) - i32(p[13]);
    let taps = KH * KW;
    // Per channel and tap, a vector of the four channels; a[j] is column ox0 + j.
    var a0 = bias[mb];
    var a1 = a0;
    var a2 = a0;
    var a3 = a0;
    let inside = y0 >= 0 && y0 + i32((KH - 1u) * dh) < i32(H) && x0 >= 0
        && x0 + i32(3u * sw + (KW - 1u) * dw) < i32(W);
    if inside {
        for (var c = 0u; c < C; c = c + 1u) {
            let plane = (n * C + c) * H + u32(y0);
            let wc = (mb * C + c) * taps;
            for (var ky = 0u; ky < KH; ky = ky + 1u) {
                let row = (plane + ky * dh) * W + u32(x0);
                let wr = wc + ky * KW;
                for (var kx = 0u; kx < KW; kx = kx + 1u) {
                    let s = row + kx * dw;
                    let wv = w[wr + kx];
                    a0 = a0 + src[s] * wv;
                    a1 = a1 + src[s + sw] * wv;
                    a2 = a2 + src[s + 2u * sw] * wv;
                    a3 = a3 + src[s + 3u * sw] * wv;
                }
            }
        }
    } else {
        for (var c = 0u; c < C; c = c + 1u) {
            let plane = (n * C + c) * H;
            let wc = (mb * C + c) * taps;
            for (var ky = 0u; ky < KH; ky = ky + 1u) {
                let iy = y0 + i32(ky * dh);
                if iy < 0 || iy >= i32(H) { continue; }
                let row = (plane + u32(iy)) * W;
                let wr = wc + ky * KW;
                for (var kx = 0u; kx < KW; kx = kx + 1u) {
                    let ix = x0 + i32(kx * dw);
                    let wv = w[wr + kx];
                    a0 = a0 + tap(row, ix, W) * wv;
                    a1 = a1 + tap(row, ix + i32(sw), W) * wv;
                    a2 = a2 + tap(row, ix + i32(2u * sw), W) * wv;
                    a3 = a3 + tap(row, ix + i32(3u * sw), W) * wv;
                }
            }
        }
    }
    // Transposed: t[q] holds channel m + q's four columns.
    let t = transpose(mat4x4<f32>(a0, a1, a2, a3));
    let cols = min(4u, OW - ox0);
    let m = mb * 4u;
    let plane_out = OH * OW;
    let o = ((n * M + m) * OH + oy) * OW + ox0;
    let a = pf(18u);
    let b = pf(19u);
    put(o, t[0], cols, a, b);
    if m + 1u < M { put(o + plane_out, t[1], cols, a, b); }
    if m + 2u < M { put(o + 2u * plane_out, t[2], cols, a, b); }
    if m + 3u < M { put(o + 3u * plane_out, t[3], cols, a, b); }
}
