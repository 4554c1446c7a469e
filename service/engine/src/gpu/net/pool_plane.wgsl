// 2-D pooling whose window is the whole plane (one output per NCHW plane, no padding: global
// pooling, and AveragePool / MaxPool with kernel = stride = the input's size, as the
// segmentation's squeeze-and-excitation blocks have): one 64-wide workgroup per plane, each
// invocation striding over the plane with four sums of its own (four reads in flight, not
// one: a 128 x 128 plane is 256 reads an invocation, which one sum would wait for one after
// another; 0.16 ms for the segmentation's 16 such planes on an H200, docs/bench/gpu-h200-c),
// then a tree reduction in workgroup memory. pool.wgsl's one invocation per output would read
// a 128 x 128 plane serially (2.1 of the segmentation's 5.5 ms on an H200,
// docs/bench/pipeline-gpu.md).
// p: [count (planes x 64), planes, values per plane, mode (0 average, 1 max)]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

var<workgroup> part: array<f32, 64>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    // The workgroup's plane: uniform across the workgroup (the barriers below need it).
    let plane = wg.y * nwg.x + wg.x;
    if plane >= p[1] { return; }
    let n = p[2];
    let is_max = p[3] == 1u;
    let init = select(0.0, -3.0e38, is_max);
    var a = vec4<f32>(init);
    let base = plane * n;
    var j = lid.x;
    for (; j + 192u < n; j = j + 256u) {
        let v = vec4<f32>(src[base + j], src[base + j + 64u], src[base + j + 128u],
                          src[base + j + 192u]);
        a = select(a + v, max(a, v), is_max);
    }
    for (; j < n; j = j + 64u) {
        let v = src[base + j];
        a.x = select(a.x + v, max(a.x, v), is_max);
    }
    part[lid.x] = select((a.x + a.y) + (a.z + a.w), max(max(a.x, a.y), max(a.z, a.w)), is_max);
    workgroupBarrier();
    for (var s = 32u; s > 0u; s = s >> 1u) {
        if lid.x < s {
            let o = part[lid.x + s];
            part[lid.x] = select(part[lid.x] + o, max(part[lid.x], o), is_max);
        }
        workgroupBarrier();
    }
    if lid.x == 0u {
        dst[plane] = select(part[0] / f32(n), part[0], is_max);
    }
}
