// The temporal filter of a frame's Fourier maps on the adapter (model/temporal.rs
// `Temporal::steady_maps`, its shape-map part, the same rule step by step): the last
// frame's maps and their per-value rates of change stay here in two pairs of buffers that
// swap roles each frame (read `last` / `rate`, write `last_next` / `rate_next`).
//  - `rates`, per map pixel: the last maps and rates in this frame's crop (bilinear taps
//    into the last crop's pixels when the crop moved, 0 where the pixel falls outside it:
//    `warp.rs` `Taps`), each value's rate low-passed, the pixel's summed |rate| and |value|;
//  - `reduce`, one workgroup: the maps' mean magnitude, the rates' normalization;
//  - `blend`, per pixel: its weight (the One Euro weight of its normalized speed, at least
//    the crop filter's and, where the mask moved, the motion's; 1 where the last map has
//    no value), the blend in place, the result
//    the next frame's last maps, the weight kept for the host (the colour features);
//  - `prime`, per value: the first frame after a reset: the maps as they are, rates 0.
// A frame whose maps are flagged not finite (maps.wgsl) changes nothing here.
// p: [n, c, size, moved, a, inv_dt, min_cutoff, beta, dt, floor,
//     from tx, ty, s, to tx, ty, s, motion weight, motion bits [ceil(n / 32)]]  (floats as
//     bits; the motion's weight 0 and no bits when the mask moved nowhere)
// maps: [n * c] and the flag; scratch: speed [n], magnitude [n], weight [n], norm.
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read_write> maps: array<f32>;
@group(0) @binding(2) var<storage, read> last: array<f32>;
@group(0) @binding(3) var<storage, read_write> last_next: array<f32>;
@group(0) @binding(4) var<storage, read> rate: array<f32>;
@group(0) @binding(5) var<storage, read_write> rate_next: array<f32>;
@group(0) @binding(6) var<storage, read_write> scratch: array<f32>;

fn pf(i: u32) -> f32 { return bitcast<f32>(p[i]); }

fn flagged() -> bool {
    return bitcast<u32>(maps[p[0] * p[1]]) != 0u;
}

fn index(wg: vec3<u32>, nwg: vec3<u32>, lid: vec3<u32>) -> u32 {
    return (wg.y * nwg.x + wg.x) * 64u + lid.x;
}

// Where pixel q of this crop's map falls in the last crop's map (warp.rs `Taps::set`):
// four pixel indices, their weights, and whether it falls inside.
struct Tap { i: vec4<u32>, w: vec4<f32>, ok: bool }

fn tap(q: u32) -> Tap {
    let size = p[2];
    let m = f32(size - 1u);
    let ux = -1.0 + 2.0 * f32(q % size) / m;
    let uy = -1.0 + 2.0 * f32(q / size) / m;
    let x = pf(15u) * ux + pf(13u);
    let y = pf(15u) * uy + pf(14u);
    let px = ((x - pf(10u)) / pf(12u) + 1.0) * 0.5 * m;
    let py = ((y - pf(11u)) / pf(12u) + 1.0) * 0.5 * m;
    var t: Tap;
    t.ok = px >= 0.0 && py >= 0.0 && px <= m && py <= m;
    if !t.ok { return t; }
    let x0 = min(u32(px), size - 2u);
    let y0 = min(u32(py), size - 2u);
    let fx = px - f32(x0);
    let fy = py - f32(y0);
    let i = y0 * size + x0;
    t.i = vec4<u32>(i, i + 1u, i + size, i + size + 1u);
    t.w = vec4<f32>((1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy);
    return t;
}

// The last value of channel ch at pixel q in this frame's crop (0 outside the last map).
fn last_at(q: u32, ch: u32, t: Tap) -> f32 {
    let c = p[1];
    if p[3] == 0u { return last[q * c + ch]; }
    if !t.ok { return 0.0; }
    return last[t.i.x * c + ch] * t.w.x + last[t.i.y * c + ch] * t.w.y
         + last[t.i.z * c + ch] * t.w.z + last[t.i.w * c + ch] * t.w.w;
}

fn rate_at(q: u32, ch: u32, t: Tap) -> f32 {
    let c = p[1];
    if p[3] == 0u { return rate[q * c + ch]; }
    if !t.ok { return 0.0; }
    return rate[t.i.x * c + ch] * t.w.x + rate[t.i.y * c + ch] * t.w.y
         + rate[t.i.z * c + ch] * t.w.z + rate[t.i.w * c + ch] * t.w.w;
}

fn pixel_tap(q: u32) -> Tap {
    if p[3] == 0u {
        var t: Tap;
        t.ok = true;
        return t;
    }
    return tap(q);
}

@compute @workgroup_size(64)
fn rates(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_id) lid: vec3<u32>) {
    let q = index(wg, nwg, lid);
    let n = p[0];
    if q >= n || flagged() { return; }
    let c = p[1];
    let a = pf(4u);
    let inv_dt = pf(5u);
    let t = pixel_tap(q);
    var acc = 0.0;
    var mag = 0.0;
    for (var ch = 0u; ch < c; ch++) {
        let v = maps[q * c + ch];
        let o = last_at(q, ch, t);
        var r = rate_at(q, ch, t);
        r += a * ((v - o) * inv_dt - r);
        rate_next[q * c + ch] = r;
        acc += abs(r);
        mag += abs(v);
    }
    scratch[q] = acc;
    scratch[n + q] = mag;
}

var<workgroup> partial: array<f32, 256>;

@compute @workgroup_size(256)
fn reduce(@builtin(local_invocation_id) lid: vec3<u32>) {
    let n = p[0];
    let c = p[1];
    let flag = flagged();
    var s = 0.0;
    for (var q = lid.x; q < n; q += 256u) {
        s += scratch[n + q];
    }
    partial[lid.x] = s;
    workgroupBarrier();
    for (var w = 128u; w > 0u; w >>= 1u) {
        if lid.x < w { partial[lid.x] += partial[lid.x + w]; }
        workgroupBarrier();
    }
    if lid.x == 0u && !flag {
        let scale = partial[0] / f32(n * c) + 1e-6;
        scratch[3u * n] = 1.0 / (f32(c) * scale);
    }
}

// model/temporal.rs `one_euro_alpha`, 1 / (1 + tau / dt) with tau = 1 / (2 pi cutoff),
// written without the division by the cutoff (no infinity at a cutoff of 0).
fn one_euro_alpha(cutoff_hz: f32, dt: f32) -> f32 {
    let r = 2.0 * 3.14159265358979 * cutoff_hz * dt;
    return clamp(r / (1.0 + r), 0.0, 1.0);
}

@compute @workgroup_size(64)
fn blend(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_id) lid: vec3<u32>) {
    let q = index(wg, nwg, lid);
    let n = p[0];
    if q >= n || flagged() { return; }
    let c = p[1];
    let t = pixel_tap(q);
    var w = max(one_euro_alpha(pf(6u) + pf(7u) * scratch[q] * scratch[3u * n], pf(8u)), pf(9u));
    // Where the mask moved, at least the motion's weight (model/temporal.rs `motion_floor`).
    let least = pf(16u);
    if least > 0.0 && ((p[17u + q / 32u] >> (q % 32u)) & 1u) != 0u {
        w = max(w, least);
    }
    if !t.ok { w = 1.0; }
    scratch[2u * n + q] = w;
    for (var ch = 0u; ch < c; ch++) {
        var v = maps[q * c + ch];
        if w < 1.0 {
            let o = last_at(q, ch, t);
            v = o + w * (v - o);
            maps[q * c + ch] = v;
        }
        last_next[q * c + ch] = v;
    }
}

@compute @workgroup_size(64)
fn prime(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_id) lid: vec3<u32>) {
    let j = index(wg, nwg, lid);
    if j >= p[0] * p[1] || flagged() { return; }
    last_next[j] = maps[j];
    rate_next[j] = 0.0;
}
