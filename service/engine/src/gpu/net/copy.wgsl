// Strided copy (Slice, Concat, Transpose, Pad's interior, Identity): for every index of a
// rank-6 shape, dst[out_off + sum idx * out_stride] = src[in_off + sum idx * in_stride].
// p: [count, in_off, out_off, shape[6], in_stride[6] (i32), out_stride[6]]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = linear_id(wg, nwg, lid);
    if i >= p[0] { return; }
    var rem = i;
    var si = i32(p[1]);
    var di = p[2];
    for (var d = 5u; d < 6u; d = d - 1u) {
        let n = p[3u + d];
        let c = rem % n;
        rem = rem / n;
        si = si + i32(c) * bitcast<i32>(p[9u + d]);
        di = di + c * p[15u + d];
    }
    dst[di] = src[u32(si)];
}
