// One pass of the maps' smoothing across pixels (model/fourier/smooth.rs `smooth_pass`, the
// same rule): each pixel of the region (`smooth_region.wgsl`'s flags after the first n * n)
// gets the 3x3 binomial mean (1 2 1 / 2 4 2 / 1 2 1) of the region's pixels around it; other
// pixels are copied. Pixel-interleaved maps `src` into `dst`, one invocation per
// value; the weights are summed first and the mean taken as a sum of fractions, as the host
// does.
// p: [len, c, size, ...] (smooth_region.wgsl's parameters)
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;
@group(0) @binding(3) var<storage, read> flags: array<u32>;

fn person(q: u32, n: u32) -> bool {
    return flags[n * n + q] != 0u;
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let j = (wg.y * nwg.x + wg.x) * 64u + lid.x;
    let len = p[0];
    if j >= len { return; }
    let c = p[1];
    let n = p[2];
    let q = j / c;
    let ch = j - q * c;
    if !person(q, n) {
        dst[j] = src[j];
        return;
    }
    let y = q / n;
    let x = q - y * n;
    let y0 = select(y - 1u, 0u, y == 0u);
    let y1 = min(y + 1u, n - 1u);
    let x0 = select(x - 1u, 0u, x == 0u);
    let x1 = min(x + 1u, n - 1u);
    var w = 0.0;
    for (var yy = y0; yy <= y1; yy++) {
        let wy = select(1.0, 2.0, yy == y);
        for (var xx = x0; xx <= x1; xx++) {
            if person(yy * n + xx, n) {
                w += wy * select(1.0, 2.0, xx == x);
            }
        }
    }
    let inv = 1.0 / w;
    var acc = 0.0;
    for (var yy = y0; yy <= y1; yy++) {
        let wy = select(1.0, 2.0, yy == y);
        for (var xx = x0; xx <= x1; xx++) {
            let r = yy * n + xx;
            if person(r, n) {
                acc += (wy * select(1.0, 2.0, xx == x) * inv) * src[r * c + ch];
            }
        }
    }
    dst[j] = acc;
}
