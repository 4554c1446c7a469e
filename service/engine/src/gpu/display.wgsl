// The frame at display size on the adapter (render.rs `render_display`, one invocation per
// display pixel): the ray at grid position (u (n - 1) / (size - 1), v (n - 1) / (size - 1))
// blends its four columns' occupancy bilinearly, is scanned front to back between the
// nearest of their hits (one node in front) and the farthest (one behind), and the surface
// is placed where the blend crosses 0.5; its colour is the blend of the neighbouring columns'
// surface colours within two grid spacings of its depth (all of them where none is).
// Antialiased (d[1].y = 1): where a column of the four has no hit, the pixel is covered by
// `edge_coverage` of the largest blended value and its gradient across the image, and
// composited over the background (render/display.rs).
//
// d: [n, size, plane, background RGBA8, spacing (f32 bits), antialias, -, -]
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

// render/display.rs `edge_coverage`.
fn edge_coverage(v: f32, grad: f32) -> f32 {
    let inside = v > 0.5;
    // `v == v` and the bound: finite (NaN and infinities fail one of them).
    if !(grad > 1e-6 && grad <= 3.4028235e38 && v == v && abs(v) <= 3.4028235e38) {
        return select(0.0, 1.0, inside);
    }
    let c = clamp(0.5 + (v - 0.5) / grad, 0.0, 1.0);
    if inside { return max(c, 0.5 + 1.1920929e-7); }
    return min(c, 0.5);
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
    var edge = false;
    if d[1].y != 0u {
        for (var t = 0u; t < 4u; t = t + 1u) { if h[t] < 0 { edge = true; } }
    }
    var found = false;
    var z = 0.0;
    var v_max = -3.4028235e38;
    var k_max = top;
    for (var k = top + 1u; k > bottom; k = k - 1u) {
        let kk = k - 1u;
        var v_in = 0.0;
        for (var t = 0u; t < 4u; t = t + 1u) { v_in = v_in + w[t] * vget(c[t] + kk * plane); }
        if v_in > v_max {
            v_max = v_in;
            k_max = kk;
        }
        if !found && v_in > 0.5 {
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
            if !edge { break; }
        }
        v_out = v_in;
    }
    var cover = 1.0;
    if edge {
        var a = array<f32, 4>(0.0, 0.0, 0.0, 0.0);
        for (var t = 0u; t < 4u; t = t + 1u) { a[t] = vget(c[t] + k_max * plane); }
        let gx = (1.0 - fy) * (a[1] - a[0]) + fy * (a[3] - a[2]);
        let gy = (1.0 - fx) * (a[2] - a[0]) + fx * (a[3] - a[1]);
        let per_px = f32(n - 1u) / f32(den);
        cover = edge_coverage(v_max, per_px * sqrt(gx * gx + gy * gy));
        if !found && cover > 0.0 {
            z = coord(k_max);
            found = true;
        }
    }
    if cover <= 0.0 { return; }
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
    var rgb = acc / wsum;
    var alpha = 1.0;
    if cover < 1.0 {
        // Over the background (straight alpha), as render/display.rs.
        let b = d[0].w;
        let bg = vec4<f32>(f32(b & 255u), f32((b >> 8u) & 255u), f32((b >> 16u) & 255u),
                           f32(b >> 24u)) / 255.0;
        let rest = bg.w * (1.0 - cover);
        alpha = cover + rest;
        rgb = (cover * rgb + rest * bg.xyz) / alpha;
    }
    out[p] = to_u8(rgb.x) | (to_u8(rgb.y) << 8u) | (to_u8(rgb.z) << 16u) | (to_u8(alpha) << 24u);
    out[size * size + p] = bitcast<u32>(z);
}
