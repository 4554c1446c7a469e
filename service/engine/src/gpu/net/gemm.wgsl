// Y = act(alpha op(A) op(B) + beta C) (ONNX Gemm; MatMul with alpha 1, no C), one
// invocation per output element. A: [M, K] (or [K, M] transposed), B: [K, N] (or [N, K]);
// C broadcast through its strides (0 on a broadcast axis).
// p: [count, M, N, K, transA, transB, alpha, beta, c_row_stride, c_col_stride, has_c, act, a, b]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> A: array<f32>;
@group(0) @binding(2) var<storage, read> B: array<f32>;
@group(0) @binding(3) var<storage, read> Cm: array<f32>;
@group(0) @binding(4) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = linear_id(wg, nwg, lid);
    if i >= p[0] { return; }
    let M = p[1]; let N = p[2]; let K = p[3];
    let n = i % N;
    let m = i / N;
    var acc = 0.0;
    for (var k = 0u; k < K; k = k + 1u) {
        let av = select(A[m * K + k], A[k * M + m], p[4] == 1u);
        let bv = select(B[k * N + n], B[n * K + k], p[5] == 1u);
        acc = acc + av * bv;
    }
    var y = pf(6u) * acc;
    if p[10] == 1u {
        y = y + pf(7u) * Cm[m * p[8] + n * p[9]];
    }
    dst[i] = act(y, p[11], pf(12u), pf(13u));
}
