// Pieces apart from the body in the adapter's render (gpu/render/pieces.rs; render.rs step
// 1b), appended to localize.wgsl (its bindings and helpers) and run with the parameters of
// level L - 1 (its stride pp(1), nl = pp(2) points a side).
//
// words: first the level's inside bits, each row of nl points in whole words (pieces.rs
// `Pieces::drop_apart_bits`: point (x, j, k) is bit x % 32 of word x / 32 + w (j + nl k));
// then, once the host has found the pieces, the dropped points: their count, then their grid
// indices.
@group(1) @binding(0) var<storage, read_write> words: array<u32>;

// One invocation per word of bits: 32 points of a row of the level.
@compute @workgroup_size(64)
fn pack(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    let nl = pp(2u);
    let w = (nl + 31u) / 32u;
    if t >= w * nl * nl { return; }
    let s = pp(1u);
    let row = t / w;
    let j = (row % nl) * s;
    let k = (row / nl) * s;
    let x0 = (t % w) * 32u;
    var bits = 0u;
    for (var b = 0u; b < 32u && x0 + b < nl; b = b + 1u) {
        if vget(linear((x0 + b) * s, j, k)) > 0.5 {
            bits = bits | (1u << b);
        }
    }
    words[t] = bits;
}

// One invocation per dropped point: set outside, and the point with its 26 neighbours of
// level L marked handled, so that no step of the final level lists them (render.rs `away`:
// the dilation, the field's seeds and the conflict rounds all claim before they list).
@compute @workgroup_size(64)
fn drop_apart(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_id) lid: vec3<u32>) {
    let t = index(wg, nwg, lid);
    if t >= words[0] { return; }
    let q0 = words[1u + t];
    vset(q0, 0.0);
    let n = pp(0u);
    let ci = vec3<i32>(i32(q0 % n), i32((q0 / n) % n), i32(q0 / (n * n)));
    for (var r = 0u; r < 27u; r = r + 1u) {
        let o = vec3<i32>(i32(r % 3u) - 1, i32((r / 3u) % 3u) - 1, i32(r / 9u) - 1);
        let qi = ci + o;
        if any(qi < vec3<i32>(0)) || any(qi >= vec3<i32>(i32(n))) { continue; }
        _ = claim(linear(u32(qi.x), u32(qi.y), u32(qi.z)));
    }
}
