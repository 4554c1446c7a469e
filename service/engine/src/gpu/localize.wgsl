// The hierarchical localization's bookkeeping on the adapter (gpu/localize.rs): the same
// steps as localize/hierarchical.rs, per level of the finest grid's integer indices, with the
// index lists built by atomic appends (their order differs from the CPU's; their sets do not)
// and the "already handled" bit claimed by atomicOr, so a point enters a list once.
//
// p (one block per level and list orientation):
//   [n, s (the level's stride), nl (the level's points per axis), cap (list capacity),
//    src (counts index of the list read), dst (counts index of the list written),
//    closure (tight: the sign-change closure), tight (no dilation)]
// counts: [cand, list A, list B, overflow, evaluations, -, -, -, conflict rounds, miss,
//          evaluations before the final level, conflict rounds per level (16: by the level's
//          stride exponent, 0 the finest), points held by the surface's dead band
//          (localize_eval.wgsl, gpu/localize/hold.rs)]
// queued: the "already handled" bits (a bit a point), then, while the dead band holds, its
//         memory (a word a point: localize_eval.wgsl `memory`).
// args: indirect dispatch arguments [x, y, z] of the next list-driven kernel.

// The lists hold pairs (point, its value before evaluation as bits). Eight storage buffers
// per stage is the default limit: the evaluation kernels add two to these six (and a grid
// tiled over several bindings one per further tile, where the adapter allows them).
@group(0) @binding(0) var<uniform> p: array<vec4<u32>, 2>;
// values (binding 1, and more tiles where one binding cannot hold a grid): declared with
// vget / vset by the host (gpu/localize.rs `Tiling::wgsl`) ahead of this source.
@group(0) @binding(2) var<storage, read_write> queued: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> cand: array<u32>;
@group(0) @binding(4) var<storage, read_write> src_list: array<u32>;
@group(0) @binding(5) var<storage, read_write> dst_list: array<u32>;
@group(0) @binding(6) var<storage, read_write> counts: array<atomic<u32>>;
// Only the prep kernels bind it (a group of its own: the indirect dispatches read it).
@group(1) @binding(0) var<storage, read_write> args: array<u32>;
// Only `seeds` binds it: the field's seeds, their count then the finest grid's indices.
@group(1) @binding(1) var<storage, read> seed_nodes: array<u32>;

const CAND: u32 = 0u;

fn pp(i: u32) -> u32 {
    return p[i / 4u][i % 4u];
}
const OVERFLOW: u32 = 3u;
const EVALS: u32 = 4u;
const ROUNDS: u32 = 8u;
const MISS: u32 = 9u;
const MARK: u32 = 10u;
const LEVEL_ROUNDS: u32 = 11u;

fn index(wg: vec3<u32>, nwg: vec3<u32>, lid: vec3<u32>) -> u32 {
    return (wg.y * nwg.x + wg.x) * 64u + lid.x;
}

// Inside iff occupancy > 0.5 (grid.rs `is_inside`), as 0.0 / 1.0.
fn bin(v: f32) -> f32 {
    return select(0.0, 1.0, v > 0.5);
}

fn linear(i: u32, j: u32, k: u32) -> u32 {
    let n = pp(0u);
    return i + n * (j + n * k);
}

// Claim point q: true for the one invocation that set its bit.
fn claim(q: u32) -> bool {
    let bit = 1u << (q & 31u);
    let old = atomicOr(&queued[q >> 5u], bit);
    return (old & bit) == 0u;
}

fn is_queued(q: u32) -> bool {
    return (atomicLoad(&queued[q >> 5u]) & (1u << (q & 31u))) != 0u;
}

// Append (q, pre) to the written list; past its capacity the overflow flag is raised (the
// host grows the lists and runs the frame again).
fn push(q: u32, pre: f32) {
    let at = atomicAdd(&counts[pp(5u)], 1u);
    if at < pp(3u) {
        dst_list[2u * at] = q;
        dst_list[2u * at + 1u] = bitcast<u32>(pre);
    } else {
        atomicStore(&counts[OVERFLOW], 1u);
    }
}

fn list_len(c: u32) -> u32 {
    return min(atomicLoad(&counts[c]), pp(3u));
}

// Indirect arguments for `count` invocations of a 64-wide kernel (gpu/mod.rs `groups`).
fn set_args(count: u32) {
    let g = max((count + 63u) / 64u, 1u);
    if g <= 65535u {
        args[0] = g;
        args[1] = 1u;
    } else {
        let y = (g + 65534u) / 65535u;
        args[0] = (g + y - 1u) / y;
        args[1] = y;
    }
    args[2] = 1u;
}

// The written list and the candidates emptied.
@compute @workgroup_size(1)
fn zero() {
    atomicStore(&counts[pp(5u)], 0u);
    atomicStore(&counts[CAND], 0u);
}

// Arguments over the candidates.
@compute @workgroup_size(1)
fn prep_cand() {
    set_args(min(atomicLoad(&counts[CAND]), pp(3u)));
}

// Arguments over the read list.
@compute @workgroup_size(1)
fn prep_src() {
    set_args(list_len(pp(4u)));
}

// Arguments over the read list, about to be evaluated: counted.
@compute @workgroup_size(1)
fn prep_eval() {
    let c = list_len(pp(4u));
    set_args(c);
    atomicAdd(&counts[EVALS], c);
}

// prep_eval for a conflict round, which the host records a few at a time without reading
// whether the previous one listed anything (record.rs): a round over an empty list is no
// round, and evaluates, lists and counts nothing.
@compute @workgroup_size(1)
fn prep_round() {
    let c = list_len(pp(4u));
    set_args(c);
    atomicAdd(&counts[EVALS], c);
    if c > 0u {
        atomicAdd(&counts[ROUNDS], 1u);
        atomicAdd(&counts[LEVEL_ROUNDS + min(firstTrailingBit(pp(1u)), 15u)], 1u);
    }
}

// After the rounds the host predicted for a level (record.rs, one read-back a frame): the
// list the last of them wrote (read here) is not empty, so the level's loop had more to
// do: the miss flag is raised and the host runs the frame again, reading after each round.
@compute @workgroup_size(1)
fn check_round() {
    if list_len(pp(4u)) > 0u {
        atomicStore(&counts[MISS], 1u);
    }
}

// The evaluations so far kept (the levels below the render's final one).
@compute @workgroup_size(1)
fn mark_evals() {
    atomicStore(&counts[MARK], atomicLoad(&counts[EVALS]));
}

// Every point of the level (the coarsest): claimed and listed for evaluation.
@compute @workgroup_size(64)
fn seed(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    let nl = pp(2u);
    if t >= nl * nl * nl { return; }
    let s = pp(1u);
    let q = linear((t % nl) * s, ((t / nl) % nl) * s, (t / (nl * nl)) * s);
    if claim(q) { push(q, 0.0); }
}

// Our addition (localize/hierarchical.rs `queue_seeds`): each of the field's seeds at the
// level's nearest point, listed with its value before evaluation unless handled.
@compute @workgroup_size(64)
fn seeds(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= seed_nodes[0] { return; }
    let q0 = seed_nodes[1u + t];
    let n = pp(0u);
    let s = pp(1u);
    let c = vec3<u32>(q0 % n, (q0 / n) % n, q0 / (n * n));
    let at = min((c + vec3<u32>(s / 2u)) / s * s, vec3<u32>(n - 1u));
    let q = linear(at.x, at.y, at.z);
    if claim(q) { push(q, vget(q)); }
}

// Step 1: every new point of the level gets the mean of its coarse parents' binarized
// values (1/2, 1/4 or 1/8 of a sum: exact, whatever the order); a fractional mean makes it a
// boundary candidate.
@compute @workgroup_size(64)
fn upsample(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
            @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    let nl = pp(2u);
    if t >= nl * nl * nl { return; }
    let s = pp(1u);
    let a = vec3<u32>(t % nl, (t / nl) % nl, t / (nl * nl));
    let odd = a & vec3<u32>(1u);
    if odd.x + odd.y + odd.z == 0u { return; }
    // Parents: the even level coordinates on either side of each odd one.
    let lo = (a - odd) * s;
    let hi = (a + odd) * s;
    var sum = 0.0;
    for (var c = 0u; c < 8u; c = c + 1u) {
        let b = vec3<u32>(c & 1u, (c >> 1u) & 1u, (c >> 2u) & 1u);
        // Corners differing only along even axes are the same parent: count each once.
        if any((b & (vec3<u32>(1u) - odd)) != vec3<u32>(0u)) { continue; }
        let x = select(lo.x, hi.x, b.x == 1u);
        let y = select(lo.y, hi.y, b.y == 1u);
        let z = select(lo.z, hi.z, b.z == 1u);
        sum = sum + bin(vget(linear(x, y, z)));
    }
    let m = sum / f32(1u << (odd.x + odd.y + odd.z));
    let q = linear(a.x * s, a.y * s, a.z * s);
    vset(q, m);
    if m > 0.0 && m < 1.0 {
        let at = atomicAdd(&counts[CAND], 1u);
        if at < pp(3u) {
            cand[at] = q;
        } else {
            atomicStore(&counts[OVERFLOW], 1u);
        }
    }
}

// Step 2: the candidates and (unless tight) their 1-ring at the level's stride, not yet
// handled, listed with their value before evaluation.
@compute @workgroup_size(64)
fn dilate(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= min(atomicLoad(&counts[CAND]), pp(3u)) { return; }
    let c = cand[t];
    if pp(7u) != 0u {
        if claim(c) { push(c, vget(c)); }
        return;
    }
    let n = pp(0u);
    let s = i32(pp(1u));
    let ci = vec3<i32>(i32(c % n), i32((c / n) % n), i32(c / (n * n)));
    for (var r = 0u; r < 27u; r = r + 1u) {
        let o = vec3<i32>(i32(r % 3u) - 1, i32((r / 3u) % 3u) - 1, i32(r / 9u) - 1) * s;
        let qi = ci + o;
        if any(qi < vec3<i32>(0)) || any(qi >= vec3<i32>(i32(n))) { continue; }
        let q = linear(u32(qi.x), u32(qi.y), u32(qi.z));
        if claim(q) { push(q, vget(q)); }
    }
}

// Step 3, one round of the conflict loop over the points just evaluated (the read list, with
// their interpolated values): a point whose interpolated and evaluated values lie on opposite
// sides of 0.5 lists every unhandled 26-neighbour; with the closure, a point also lists each
// unhandled neighbour whose assumed side differs from its own. Unhandled points keep their
// values during the round, so the listed set does not depend on the order.
@compute @workgroup_size(64)
fn conflict(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
            @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= list_len(pp(4u)) { return; }
    let q0 = src_list[2u * t];
    let v = vget(q0);
    let interp = bitcast<f32>(src_list[2u * t + 1u]);
    let conflict = (interp - 0.5) * (v - 0.5) < 0.0;
    let closure = pp(6u) != 0u;
    if !conflict && !closure { return; }
    let n = pp(0u);
    let s = i32(pp(1u));
    let ci = vec3<i32>(i32(q0 % n), i32((q0 / n) % n), i32(q0 / (n * n)));
    for (var r = 0u; r < 27u; r = r + 1u) {
        if r == 13u { continue; }
        let o = vec3<i32>(i32(r % 3u) - 1, i32((r / 3u) % 3u) - 1, i32(r / 9u) - 1) * s;
        let qi = ci + o;
        if any(qi < vec3<i32>(0)) || any(qi >= vec3<i32>(i32(n))) { continue; }
        let q = linear(u32(qi.x), u32(qi.y), u32(qi.z));
        if is_queued(q) { continue; }
        let assumed = vget(q);
        if conflict || bin(assumed) != bin(v) {
            if claim(q) { push(q, assumed); }
        }
    }
}
