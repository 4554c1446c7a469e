// Element-wise a op b with NumPy broadcasting (stride 0 on a broadcast axis), the output
// contiguous. op: 0 add, 1 sub, 2 mul, 3 div, 4 max, 5 min.
// p: [count, op, shape[6], a_stride[6], b_stride[6]]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = linear_id(wg, nwg, lid);
    if i >= p[0] { return; }
    var rem = i;
    var ai = 0u;
    var bi = 0u;
    for (var d = 5u; d < 6u; d = d - 1u) {
        let n = p[2u + d];
        let c = rem % n;
        rem = rem / n;
        ai = ai + c * p[8u + d];
        bi = bi + c * p[14u + d];
    }
    let x = a[ai];
    let y = b[bi];
    var r: f32;
    switch p[1] {
        case 0u: { r = x + y; }
        case 1u: { r = x - y; }
        case 2u: { r = x * y; }
        case 3u: { r = x / y; }
        case 4u: { r = max(x, y); }
        default: { r = min(x, y); }
    }
    dst[i] = r;
}
