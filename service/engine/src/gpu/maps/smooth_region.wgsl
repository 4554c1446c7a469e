// The region the maps' smoothing works in (model/fourier/smooth.rs `smooth_region`, the same
// rule): the person pixels (c0 above `inside`) that a square opening of radius r of the
// person pixels keeps, the map's own edge not eroding. Mode 0 erodes (flags[i]: every pixel
// of the window around i a person's), mode 1 dilates that and keeps the person pixels
// (flags[n * n + i]). One invocation per pixel.
// p: [len, c, n, inside (float bits), r, mode]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> maps: array<f32>;
@group(0) @binding(2) var<storage, read_write> flags: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = (wg.y * nwg.x + wg.x) * 64u + lid.x;
    let c = p[1];
    let n = p[2];
    if i >= n * n { return; }
    let inside = bitcast<f32>(p[3]);
    let r = p[4];
    let y = i / n;
    let x = i - y * n;
    let y0 = y - min(y, r);
    let y1 = min(y + r, n - 1u);
    let x0 = x - min(x, r);
    let x1 = min(x + r, n - 1u);
    if p[5] == 0u {
        var all = 1u;
        for (var yy = y0; yy <= y1; yy++) {
            for (var xx = x0; xx <= x1; xx++) {
                if !(maps[(yy * n + xx) * c] > inside) { all = 0u; }
            }
        }
        flags[i] = all;
    } else {
        var any = 0u;
        if maps[i * c] > inside {
            for (var yy = y0; yy <= y1; yy++) {
                for (var xx = x0; xx <= x1; xx++) {
                    if flags[yy * n + xx] != 0u { any = 1u; }
                }
            }
        }
        flags[n * n + i] = any;
    }
}
