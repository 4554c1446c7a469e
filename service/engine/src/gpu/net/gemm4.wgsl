// Y = act(A W + bias) for a constant W, four outputs of a row per invocation (the MLPs'
// layers: ONNX Gemm with transA = 0 and MatMul, W and the bias known at plan time).
// A: [M, K]; W: [K, N4] as vec4 (the plan transposes a transB weight, folds alpha into it
// and beta into the bias, and pads N to N4 = 4 ceil(N / 4) with zero columns); bias: [N4].
// Neighbouring invocations take neighbouring columns of one row: A's value is the same for
// them and W's reads are contiguous.
// p: [count, M, N, K, act, a, b] (count = M N4 / 4)
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> A: array<f32>;
@group(0) @binding(2) var<storage, read> W: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> bias: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = linear_id(wg, nwg, lid);
    if i >= p[0] { return; }
    let N = p[2]; let K = p[3];
    let q = (N + 3u) / 4u;
    let col = i % q;
    let m = i / q;
    var acc = bias[col];
    let row = m * K;
    for (var k = 0u; k < K; k = k + 1u) {
        acc = acc + A[row + k] * W[k * q + col];
    }
    let n = col * 4u;
    let o = m * N + n;
    let a = pf(5u);
    let b = pf(6u);
    dst[o] = act(acc.x, p[4], a, b);
    if n + 1u < N { dst[o + 1u] = act(acc.y, p[4], a, b); }
    if n + 2u < N { dst[o + 2u] = act(acc.z, p[4], a, b); }
    if n + 3u < N { dst[o + 3u] = act(acc.w, p[4], a, b); }
}
