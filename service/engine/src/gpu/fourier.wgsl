// The Fourier (or half-range cosine) occupancy series at points, one invocation per point:
// bilinear taps of the pixel-interleaved coefficient maps (grid_sample align_corners=1,
// border: model/sample.rs `taps`), the basis by the angle-addition recurrence (exact at
// zeta = +-1, as model/fourier.rs), the surface-level offset, the clamp to [0, 1]. Points
// beyond the depth range or not finite are 0.
// p: [n, k, size, basis (0 fourier, 1 cosine), zeta_scale, offset]
// pts: [n, 3] crop NDC; maps: [size * size, 2K + 1]; occ: [n].
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> maps: array<f32>;
@group(0) @binding(2) var<storage, read> pts: array<f32>;
@group(0) @binding(3) var<storage, read_write> occ: array<f32>;

const PI: f32 = 3.14159265358979;

fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn to_px(n: f32, size: u32) -> f32 {
    var v = 0.0;
    if finite(n) { v = clamp(n, -1.0, 1.0); }
    return (v + 1.0) * 0.5 * f32(size - 1u);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = (wg.y * nwg.x + wg.x) * 64u + lid.x;
    if i >= p[0] { return; }
    let k = p[1];
    let size = p[2];
    let cosine = p[3] == 1u;
    let c = 2u * k + 1u;
    let x = pts[3u * i];
    let y = pts[3u * i + 1u];
    let zeta = pts[3u * i + 2u] * bitcast<f32>(p[4]);
    if !finite(zeta) || abs(zeta) > 1.0 || !finite(x) || !finite(y) {
        occ[i] = 0.0;
        return;
    }
    let px = to_px(x, size);
    let py = to_px(y, size);
    let x0 = min(u32(floor(px)), size - 1u);
    let y0 = min(u32(floor(py)), size - 1u);
    let x1 = min(x0 + 1u, size - 1u);
    let y1 = min(y0 + 1u, size - 1u);
    let fx = px - f32(x0);
    let fy = py - f32(y0);
    let base = array<u32, 4>((y0 * size + x0) * c, (y0 * size + x1) * c, (y1 * size + x0) * c, (y1 * size + x1) * c);
    let w = array<f32, 4>((1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy);
    // The first harmonic: exact at the ends of the range (f32's pi is not pi).
    var s1 = 0.0;
    var c1 = -1.0;
    if cosine {
        let t = (zeta + 1.0) * 0.5;
        if t == 0.0 { c1 = 1.0; } else if t != 1.0 { s1 = sin(t * PI); c1 = cos(t * PI); }
    } else if abs(zeta) != 1.0 {
        s1 = sin(zeta * PI);
        c1 = cos(zeta * PI);
    }
    var d = array<f32, 4>(maps[base[0]], maps[base[1]], maps[base[2]], maps[base[3]]);
    var cs = c1;
    var sn = s1;
    if cosine {
        // [c0, a_1 .. a_2K]: cos(n pi t), n = 1..2K.
        for (var n = 1u; n < c; n = n + 1u) {
            for (var t = 0u; t < 4u; t = t + 1u) { d[t] = d[t] + maps[base[t] + n] * cs; }
            let cn = cs * c1 - sn * s1;
            sn = sn * c1 + cs * s1;
            cs = cn;
        }
    } else {
        // [c0, a_1, b_1, ..., a_K, b_K]: cos and sin of j pi zeta, j = 1..K.
        for (var j = 0u; j < k; j = j + 1u) {
            for (var t = 0u; t < 4u; t = t + 1u) {
                d[t] = d[t] + maps[base[t] + 1u + 2u * j] * cs;
                d[t] = d[t] + maps[base[t] + 2u + 2u * j] * sn;
            }
            let cn = cs * c1 - sn * s1;
            sn = sn * c1 + cs * s1;
            cs = cn;
        }
    }
    var acc = 0.0;
    for (var t = 0u; t < 4u; t = t + 1u) { acc = acc + w[t] * d[t]; }
    occ[i] = clamp(acc + bitcast<f32>(p[5]), 0.0, 1.0);
}
