const PI: f32 = 3.14159265358979;

fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn to_px(n: f32, size: u32) -> f32 {
    var v = 0.0;
    if finite(n) { v = clamp(n, -1.0, 1.0); }
    return (v + 1.0) * 0.5 * f32(size - 1u);
}

// The four taps of the bilinear rule at NDC (x, y) on a size x size grid (model/sample.rs
// `taps`): pixel indices, row-major, and their weights.
struct Taps {
    i: array<u32, 4>,
    w: array<f32, 4>,
}

fn taps(x: f32, y: f32, size: u32) -> Taps {
    let px = to_px(x, size);
    let py = to_px(y, size);
    let x0 = min(u32(floor(px)), size - 1u);
    let y0 = min(u32(floor(py)), size - 1u);
    let x1 = min(x0 + 1u, size - 1u);
    let y1 = min(y0 + 1u, size - 1u);
    let fx = px - f32(x0);
    let fy = py - f32(y0);
    return Taps(
        array<u32, 4>(y0 * size + x0, y0 * size + x1, y1 * size + x0, y1 * size + x1),
        array<f32, 4>((1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy));
}

// The Fourier (or half-range cosine) occupancy series at one crop-NDC point, over the
// pixel-interleaved coefficient maps in the including module's `maps` binding: bilinear taps
// (grid_sample align_corners=1, border: model/sample.rs `taps`), the basis by the
// angle-addition recurrence (exact at zeta = +-1, as model/fourier.rs), the surface-level
// offset, the clamp to [0, 1]. Beyond the depth range or not finite: 0.
fn series(x: f32, y: f32, z: f32, k: u32, size: u32, cosine: bool, zeta_scale: f32,
          offset: f32) -> f32 {
    let c = 2u * k + 1u;
    let zeta = z * zeta_scale;
    if !finite(zeta) || abs(zeta) > 1.0 || !finite(x) || !finite(y) {
        return 0.0;
    }
    let tp = taps(x, y, size);
    let base = array<u32, 4>(tp.i[0] * c, tp.i[1] * c, tp.i[2] * c, tp.i[3] * c);
    let w = tp.w;
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
    return clamp(acc + offset, 0.0, 1.0);
}
