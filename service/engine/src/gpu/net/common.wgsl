// Shared by every network kernel (prepended to each). Parameters come as a read-only
// storage array of u32 (floats bit-cast): p[0] is always the invocation count.
// Invocations are numbered over a 2-D grid of 64-wide workgroups (gpu::groups).

fn linear_id(wg: vec3<u32>, nwg: vec3<u32>, lid: vec3<u32>) -> u32 {
    return (wg.y * nwg.x + wg.x) * 64u + lid.x;
}

fn pf(i: u32) -> f32 {
    return bitcast<f32>(p[i]);
}

// Activations, fused into conv / gemm or run alone (unary): 0 none, 1 relu, 2 leaky relu (a),
// 3 hard-swish, 4 sigmoid, 5 tanh, 6 clip [a, b], 7 hard-sigmoid (a x + b clipped to [0, 1]).
// Sigmoid and tanh are written to stay finite for any finite input.
fn act(x: f32, op: u32, a: f32, b: f32) -> f32 {
    switch op {
        case 1u: { return max(x, 0.0); }
        case 2u: { return select(a * x, x, x >= 0.0); }
        case 3u: { return x * clamp(x + 3.0, 0.0, 6.0) / 6.0; }
        case 4u: {
            let e = exp(-abs(x));
            return select(e / (1.0 + e), 1.0 / (1.0 + e), x >= 0.0);
        }
        case 5u: {
            let e = exp(-2.0 * abs(x));
            return sign(x) * (1.0 - e) / (1.0 + e);
        }
        case 6u: { return clamp(x, a, b); }
        case 7u: { return clamp(a * x + b, 0.0, 1.0); }
        default: { return x; }
    }
}
