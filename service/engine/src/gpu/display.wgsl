// The frame at display size on the adapter (render.rs `render_display`, one invocation per
// display pixel): the ray at grid position (u (n - 1) / (size - 1), v (n - 1) / (size - 1))
// blends its four columns' occupancy bilinearly, is scanned front to back between the
// nearest of their hits (one node in front) and the farthest (one behind), and the surface
// is placed where the blend crosses 0.5; its colour is the blend of the neighbouring columns'
// surface colours within two grid spacings of its depth (all of them where none is).
//
// d: [n, size, plane, background RGBA8, spacing (f32 bits), -, -, -]
// hits: hit + 1 per column (0: none), then three more regions the kernel does not read.
// cols: per column [depth, r, g, b], then the grid's coordinates (n values).
// out: RGBA8 per pixel, then the depth per pixel (f32 bits; -1 where there is none).

@group(0) @binding(0) var<uniform> d: array<vec4<u32>, 2>;
// values (binding 1 and further tiles): vget, declared ahead of this source
// (gpu/localize.rs `Tiling::wgsl`).
@group(0) @binding(2) var<storage, read> hits: array<u32>;
@group(0) @binding(3) var<storage, read> cols: array<f32>;
@group(0) @binding(4) var<storage, read_write> out: array<u32>;

fn to_u8(x: f32) -> u32 {
    // Rust's f32::round (half away from zero) on a value in [0, 255].
    return u32(floor(clamp(x, 0.0, 1.0) * 255.0 + 0.5));
}

fn coord(k: u32) -> f32 {
    return cols[4u * d[0].z + k];
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let p = (wg.y * nwg.x + wg.x) * 64u + lid.x;
    let n = d[0].x;
    let size = d[0].y;
    let plane = d[0].z;
    if p >= size * size { return; }
    out[p] = d[0].w;
    out[size * size + p] = bitcast<u32>(-1.0);
    let u = p % size;
    let v = p / size;
    let den = size - 1u;
    let nu = u * (n - 1u);
    let nv = v * (n - 1u);
    let i0 = nu / den;
    let j0 = nv / den;
    let i1 = min(i0 + 1u, n - 1u);
    let j1 = min(j0 + 1u, n - 1u);
    let fx = f32(nu % den) / f32(den);
    let fy = f32(nv % den) / f32(den);
    let c = array<u32, 4>(i0 + n * j0, i1 + n * j0, i0 + n * j1, i1 + n * j1);
    let w = array<f32, 4>((1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy);
    var h = array<i32, 4>(0, 0, 0, 0);
    var hmax = -1;
    var hmin = 1 << 30;
    for (var t = 0u; t < 4u; t = t + 1u) {
        h[t] = i32(hits[c[t]]) - 1;
        hmax = max(hmax, h[t]);
        if h[t] >= 0 { hmin = min(hmin, h[t]); }
    }
    if hmax < 0 { return; }
    let top = min(u32(hmax) + 1u, n - 1u);
    let bottom = u32(max(hmin - 1, 0));
    var v_out = 0.0;
    if top + 1u < n {
        for (var t = 0u; t < 4u; t = t + 1u) { v_out = v_out + w[t] * vget(c[t] + (top + 1u) * plane); }
    }
    var found = false;
    var z = 0.0;
    for (var k = top + 1u; k > bottom; k = k - 1u) {
        let kk = k - 1u;
        var v_in = 0.0;
        for (var t = 0u; t < 4u; t = t + 1u) { v_in = v_in + w[t] * vget(c[t] + kk * plane); }
        if v_in > 0.5 {
            if kk + 1u < n {
                let dv = v_in - v_out;
                var s = 0.5;
                if dv > 1e-12 { s = clamp((v_in - 0.5) / dv, 0.0, 1.0); }
                let z0 = coord(kk);
                let z1 = coord(kk + 1u);
                z = z0 + (z1 - z0) * s;
            } else {
                z = 1.0;
            }
            found = true;
            break;
        }
        v_out = v_in;
    }
    if !found { return; }
    let spacing = bitcast<f32>(d[1].x);
    var acc = vec3<f32>(0.0);
    var wsum = 0.0;
    for (var pass_ = 0u; pass_ < 2u; pass_ = pass_ + 1u) {
        for (var t = 0u; t < 4u; t = t + 1u) {
            let ct = c[t];
            if h[t] < 0 || w[t] <= 0.0 { continue; }
            if pass_ == 0u && abs(cols[4u * ct] - z) > 2.0 * spacing { continue; }
            acc = acc + w[t] * vec3<f32>(cols[4u * ct + 1u], cols[4u * ct + 2u], cols[4u * ct + 3u]);
            wsum = wsum + w[t];
        }
        if wsum > 0.0 { break; }
    }
    if wsum <= 0.0 { return; }
    let rgb = acc / wsum;
    out[p] = to_u8(rgb.x) | (to_u8(rgb.y) << 8u) | (to_u8(rgb.z) << 16u) | (255u << 24u);
    out[size * size + p] = bitcast<u32>(z);
}
