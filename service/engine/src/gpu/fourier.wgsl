// The Fourier (or half-range cosine) occupancy series at points, one invocation per point:
// bilinear taps of the pixel-interleaved coefficient maps (grid_sample align_corners=1,
// border: model/sample.rs `taps`), the basis by the angle-addition recurrence (exact at
// zeta = +-1, as model/fourier.rs), the surface-level offset, the clamp to [0, 1]. Points
// beyond the depth range or not finite are 0.
// p: [n, k, size, basis (0 fourier, 1 cosine), zeta_scale, offset]
// pts: [n, 3] crop NDC; maps: [size * size, 2K + 1]; occ: [n].
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> maps: array<f32>;
@group(0) @binding(2) var<storage, read> pts: array<f32>;
@group(0) @binding(3) var<storage, read_write> occ: array<f32>;

// The series itself: series.wgsl (prepended by gpu/fourier.rs).

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = (wg.y * nwg.x + wg.x) * 64u + lid.x;
    if i >= p[0] { return; }
    occ[i] = series(pts[3u * i], pts[3u * i + 1u], pts[3u * i + 2u], p[1], p[2], p[3] == 1u,
                    bitcast<f32>(p[4]), bitcast<f32>(p[5]));
}
