// Resize of NCHW planes in H and W (ONNX Resize, 4-D): mode 0 nearest, 1 linear; coordinate
// transformation 0 half_pixel, 1 align_corners, 2 asymmetric, 3 pytorch_half_pixel; nearest
// rounding 0 round_prefer_floor, 1 round_prefer_ceil, 2 floor, 3 ceil. scale_* = out / in
// (the model's scales, or the sizes' ratio).
// p: [count, planes, H, W, OH, OW, mode, ctm, nearest, scale_h, scale_w]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

fn source(o: u32, n_in: u32, n_out: u32, scale: f32) -> f32 {
    let x = f32(o);
    switch p[7] {
        case 1u: {
            if n_out <= 1u { return 0.0; }
            return x * f32(n_in - 1u) / f32(n_out - 1u);
        }
        case 2u: { return x / scale; }
        case 3u: {
            if n_out <= 1u { return 0.0; }
            return (x + 0.5) / scale - 0.5;
        }
        default: { return (x + 0.5) / scale - 0.5; }
    }
}

fn nearest(x: f32, n: u32) -> u32 {
    var r: f32;
    switch p[8] {
        case 1u: { r = select(round(x), ceil(x), fract(x) == 0.5); }
        case 2u: { r = floor(x); }
        case 3u: { r = ceil(x); }
        default: { r = select(round(x), floor(x), fract(x) == 0.5); }
    }
    return u32(clamp(r, 0.0, f32(n - 1u)));
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = linear_id(wg, nwg, lid);
    if i >= p[0] { return; }
    let H = p[2]; let W = p[3]; let OH = p[4]; let OW = p[5];
    let ox = i % OW;
    let oy = (i / OW) % OH;
    let plane = i / (OW * OH);
    let sy = source(oy, H, OH, pf(9u));
    let sx = source(ox, W, OW, pf(10u));
    let base = plane * H * W;
    if p[6] == 0u {
        dst[i] = src[base + nearest(sy, H) * W + nearest(sx, W)];
        return;
    }
    let cy = clamp(sy, 0.0, f32(H - 1u));
    let cx = clamp(sx, 0.0, f32(W - 1u));
    let y0 = u32(floor(cy));
    let x0 = u32(floor(cx));
    let y1 = min(y0 + 1u, H - 1u);
    let x1 = min(x0 + 1u, W - 1u);
    let fy = cy - f32(y0);
    let fx = cx - f32(x0);
    let top = mix(src[base + y0 * W + x0], src[base + y0 * W + x1], fx);
    let bot = mix(src[base + y1 * W + x0], src[base + y1 * W + x1], fx);
    dst[i] = mix(top, bot, fy);
}
