// The mesh-free renderer's final level on the adapter (gpu/render.rs), appended to
// localize.wgsl (its bindings and helpers): the same steps as render.rs, per column of the
// level-L grid (pixel c = i + n j, depth index k, larger k nearer the camera). Hits are kept
// as k + 1 (0: no hit) so that atomicMax raises them.
//
// rp: [plane (n * n), cx (which culled list is read: 0 or 1), -, -]
// cols: [hit + 1 | coarse hit + 1 | value at the hit | value in front of it], each `plane`
// extra: three regions of `cap` (point, value) pairs: the round's log, culled 0, culled 1.

@group(1) @binding(1) var<uniform> rp: vec4<u32>;
@group(1) @binding(2) var<storage, read_write> cols: array<atomic<u32>>;
@group(1) @binding(3) var<storage, read_write> extra: array<u32>;

const LOG: u32 = 5u;
const CULLED0: u32 = 6u;

// Append (q, pre) to the list of counter `slot` held at `base` in `extra`.
fn push_extra(slot: u32, base: u32, q: u32, pre: f32) {
    let at = atomicAdd(&counts[slot], 1u);
    if at < pp(3u) {
        extra[base + 2u * at] = q;
        extra[base + 2u * at + 1u] = bitcast<u32>(pre);
    } else {
        atomicStore(&counts[OVERFLOW], 1u);
    }
}

fn culled_base(x: u32) -> u32 {
    return 2u * pp(3u) * (1u + x);
}

// Whether a column's current hit lets point (c, k) be evaluated: no hit, or k at or in
// front of it (render.rs `keep`).
fn in_front(c: u32, k: u32) -> bool {
    let h = atomicLoad(&cols[c]);
    return h == 0u || k + 1u >= h;
}

// Per column, the first inside node from the front: the coarse hit, and the hit to refine.
@compute @workgroup_size(64)
fn first_hits(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_id) lid: vec3<u32>) {
    let c = index(wg, nwg, lid);
    let plane = rp.x;
    if c >= plane { return; }
    let n = pp(0u);
    var h = 0u;
    for (var k = n; k > 0u; k = k - 1u) {
        if vget(c + (k - 1u) * plane) > 0.5 {
            h = k;
            break;
        }
    }
    atomicStore(&cols[c], h);
    atomicStore(&cols[plane + c], h);
}

// The dilated candidates (the read list) in front of or at their column's coarse hit go to
// the written list; the ones behind it (shadow nodes) to culled list 0.
@compute @workgroup_size(64)
fn split(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= list_len(pp(4u)) { return; }
    let q = src_list[2u * t];
    let pre = bitcast<f32>(src_list[2u * t + 1u]);
    let plane = rp.x;
    let c = q % plane;
    let k = q / plane;
    let h = atomicLoad(&cols[plane + c]);
    if h == 0u || k + 1u >= h {
        push(q, pre);
    } else {
        push_extra(CULLED0, culled_base(0u), q, pre);
    }
}

// The read list into the round's log (the points whose values changed this round).
@compute @workgroup_size(64)
fn log_append(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= list_len(pp(4u)) { return; }
    push_extra(LOG, 0u, src_list[2u * t], bitcast<f32>(src_list[2u * t + 1u]));
}

// localize.wgsl's conflict round with the renderer's culling: a neighbour behind its
// column's current hit is neither evaluated nor marked.
@compute @workgroup_size(64)
fn conflict_keep(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                 @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= list_len(pp(4u)) { return; }
    let q0 = src_list[2u * t];
    let v = vget(q0);
    let interp = bitcast<f32>(src_list[2u * t + 1u]);
    if (interp - 0.5) * (v - 0.5) >= 0.0 { return; }
    let n = pp(0u);
    let plane = rp.x;
    let ci = vec3<i32>(i32(q0 % n), i32((q0 / n) % n), i32(q0 / plane));
    for (var r = 0u; r < 27u; r = r + 1u) {
        if r == 13u { continue; }
        let o = vec3<i32>(i32(r % 3u) - 1, i32((r / 3u) % 3u) - 1, i32(r / 9u) - 1);
        let qi = ci + o;
        if any(qi < vec3<i32>(0)) || any(qi >= vec3<i32>(i32(n))) { continue; }
        let q = linear(u32(qi.x), u32(qi.y), u32(qi.z));
        if is_queued(q) || !in_front(q % plane, q / plane) { continue; }
        if claim(q) { push(q, vget(q)); }
    }
}

fn log_len() -> u32 {
    return min(atomicLoad(&counts[LOG]), pp(3u));
}

// Hits after the round (render.rs `update_hits`), first pass: an inside node in front of its
// column's hit becomes the hit.
@compute @workgroup_size(64)
fn raise(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= log_len() { return; }
    let q = extra[2u * t];
    if vget(q) > 0.5 {
        atomicMax(&cols[q % rp.x], q / rp.x + 1u);
    }
}

// Second pass: a hit node that evaluated outside is refuted, and its column scanned down.
@compute @workgroup_size(64)
fn refute(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= log_len() { return; }
    let q = extra[2u * t];
    let plane = rp.x;
    let c = q % plane;
    let k = q / plane;
    if atomicLoad(&cols[c]) != k + 1u || vget(q) > 0.5 { return; }
    var h = 0u;
    for (var kk = k; kk > 0u; kk = kk - 1u) {
        if vget(c + (kk - 1u) * plane) > 0.5 {
            h = kk;
            break;
        }
    }
    atomicStore(&cols[c], h);
}

// Before a release: the log and the culled list about to be written emptied.
@compute @workgroup_size(1)
fn reset_release() {
    atomicStore(&counts[LOG], 0u);
    atomicStore(&counts[CULLED0 + 1u - rp.y], 0u);
}

// The culled points now in front of their column's hit are released into the log (to be
// evaluated); the rest stay culled, in the other list.
@compute @workgroup_size(64)
fn release(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    let x = rp.y;
    if t >= min(atomicLoad(&counts[CULLED0 + x]), pp(3u)) { return; }
    let base = culled_base(x);
    let q = extra[base + 2u * t];
    let pre = bitcast<f32>(extra[base + 2u * t + 1u]);
    if in_front(q % rp.x, q / rp.x) {
        push_extra(LOG, 0u, q, pre);
    } else {
        push_extra(CULLED0 + 1u - x, culled_base(1u - x), q, pre);
    }
}

// Per column with a hit: the values at the hit and in front of it (the host places the
// surface between them with render.rs `crossing_depth`).
@compute @workgroup_size(64)
fn surface(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_id) lid: vec3<u32>) {
    let c = index(wg, nwg, lid);
    let plane = rp.x;
    if c >= plane { return; }
    let h = atomicLoad(&cols[c]);
    var v_in = 0.0;
    var v_out = 0.0;
    if h > 0u {
        let k = h - 1u;
        v_in = vget(c + k * plane);
        if k + 1u < pp(0u) { v_out = vget(c + (k + 1u) * plane); }
    }
    atomicStore(&cols[2u * plane + c], bitcast<u32>(v_in));
    atomicStore(&cols[3u * plane + c], bitcast<u32>(v_out));
}
