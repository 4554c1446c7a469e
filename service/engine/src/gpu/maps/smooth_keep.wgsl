// The smoothing's kept runs (model/fourier/smooth.rs `keep_runs`, the same rule): after the
// passes, each pixel of the region (`smooth_region.wgsl`'s flags after the first n * n) whose
// smoothed ray (`maps`) stays under the surface level at every depth of one of its own
// inside runs (`own`, the maps before the passes) takes its own coefficients back. The
// depths are the 129 of `table` (model/fourier.rs `sample_basis`, written by the host), each
// ray's value at one a sum over the channels in their order, as the host sums. One
// invocation per pixel.
// p: [c, n, iso (float bits)]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> own: array<f32>;
@group(0) @binding(2) var<storage, read_write> maps: array<f32>;
@group(0) @binding(3) var<storage, read> flags: array<u32>;
@group(0) @binding(4) var<storage, read> table: array<f32>;

fn at_own(i: u32, j: u32, c: u32) -> f32 {
    var v = 0.0;
    for (var ch = 0u; ch < c; ch++) {
        v += own[i * c + ch] * table[j * c + ch];
    }
    return v;
}

fn at_maps(i: u32, j: u32, c: u32) -> f32 {
    var v = 0.0;
    for (var ch = 0u; ch < c; ch++) {
        v += maps[i * c + ch] * table[j * c + ch];
    }
    return v;
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = (wg.y * nwg.x + wg.x) * 64u + lid.x;
    let c = p[0];
    let n = p[1];
    if i >= n * n || flags[n * n + i] == 0u { return; }
    let iso = bitcast<f32>(p[2]);
    // 0: outside the own ray's runs; 1: in one, the smoothed ray not yet at the level in
    // it; 2: in one where it was.
    var run = 0u;
    var lost = false;
    for (var j = 0u; j < 129u; j++) {
        if at_own(i, j, c) >= iso {
            if run != 2u {
                run = select(1u, 2u, at_maps(i, j, c) >= iso);
            }
        } else {
            if run == 1u {
                lost = true;
                break;
            }
            run = 0u;
        }
    }
    if lost || run == 1u {
        for (var ch = 0u; ch < c; ch++) {
            maps[i * c + ch] = own[i * c + ch];
        }
    }
}
