// The field at the points of the read list (gpu/localize.rs), written into the grid: a table
// of values (`table`: a field the host evaluated, the analytic scenes in the parity tests) or
// the trained Fourier head (`fourier`: the person mask, then the series of series.wgsl,
// prepended), as model/field.rs `ModelField::occupancy` computes them.
//
// f (field parameters): [k, size, basis (0 fourier, 1 cosine), zeta_scale, offset,
//   mask size, band, stamp, to_crop (3 x 3, column-major: render NDC -> crop NDC),
//   memory (its first word in binding 2), -, -, the table of quantized values (256)]
//   (the last three and band / stamp: the surface's dead band, gpu/localize/hold.rs).
// aux: the NDC coordinate of each grid index (GridSpec::coord, computed on the host), then
// the mask [S, S]; maps: the table (one value per grid point) or the coefficient maps.

@group(0) @binding(0) var<uniform> p: array<vec4<u32>, 2>;
// values: vget / vset, declared ahead of this source (gpu/localize.rs `Tiling::wgsl`).
// The "already handled" bits, then the dead band's memory (a word a grid point).
@group(0) @binding(2) var<storage, read_write> memory: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> src_list: array<u32>;
@group(0) @binding(6) var<storage, read_write> counts: array<atomic<u32>>;
@group(1) @binding(0) var<uniform> f: array<vec4<u32>, 69>;
@group(1) @binding(1) var<storage, read> maps: array<f32>;
// The grid's coordinates (n values), then the mask.
@group(1) @binding(2) var<storage, read> aux: array<f32>;

fn pp(i: u32) -> u32 {
    return p[i / 4u][i % 4u];
}

fn ff(i: u32) -> u32 {
    return f[i / 4u][i % 4u];
}

fn point(wg: vec3<u32>, nwg: vec3<u32>, lid: vec3<u32>) -> u32 {
    let t = (wg.y * nwg.x + wg.x) * 64u + lid.x;
    if t >= min(atomicLoad(&counts[pp(4u)]), pp(3u)) { return 0xffffffffu; }
    return src_list[2u * t];
}

// sides.rs `quantize`: 1 + round(254 v) (half away from zero), on v's side of the level.
fn quantize(v: f32) -> u32 {
    let x = clamp(v, 0.0, 1.0) * 254.0;
    var r = floor(x);
    if x - r >= 0.5 {
        r = r + 1.0;
    }
    let q = 1u + u32(r);
    if v > 0.5 {
        return max(q, 129u);
    }
    return min(q, 128u);
}

// Points held by the workgroup, added to counts[HELD] once (count_held).
var<workgroup> wg_held: atomic<u32>;

// The workgroup's held points into the frame's count, by one invocation (called by every
// invocation: a barrier).
fn count_held(l: u32) {
    if ff(7u) == 0u {
        return;
    }
    workgroupBarrier();
    if l == 0u {
        let h = atomicLoad(&wg_held);
        if h > 0u {
            atomicAdd(&counts[HELD], h);
        }
    }
}

// The value grid point q evaluated as v is given out (sides.rs `HeldSides::apply`): within
// the band of last frame's, that; over the level from last frame's side by less than the
// band, the nearest value on that side; else v. Remembered for the next frame.
fn held(q: u32, v: f32) -> f32 {
    let stamp = ff(7u);
    if stamp == 0u {
        return v;
    }
    let band = bitcast<f32>(ff(6u));
    let at = ff(17u) + q;
    let word = atomicLoad(&memory[at]);
    let s = word >> 16u;
    var was = 0u;
    if s == stamp {
        // Evaluated already this frame: last frame's value is one field down.
        was = (word >> 8u) & 255u;
    } else if s + 1u == stamp {
        was = word & 255u;
    }
    var out = v;
    if was != 0u {
        let w = bitcast<f32>(ff(20u + was));
        if abs(v - w) < band {
            out = w;
        } else if (w > 0.5) != (v > 0.5) && abs(v - 0.5) < band {
            // ISO, or the next f32 above it (sides.rs JUST_INSIDE).
            out = select(0.5, bitcast<f32>(0x3f000001u), w > 0.5);
        }
        if out != v {
            atomicAdd(&wg_held, 1u);
        }
    }
    atomicStore(&memory[at], (stamp << 16u) | (was << 8u) | quantize(out));
    return out;
}

@compute @workgroup_size(64)
fn table(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_id) lid: vec3<u32>) {
    let q = point(wg, nwg, lid);
    if q != 0xffffffffu {
        vset(q, held(q, maps[q]));
    }
    count_held(lid.x);
}

// Bilinear sample of the mask (model/sample.rs `bilinear`, one channel; the sum in its order).
fn mask_at(x: f32, y: f32, s: u32) -> f32 {
    let o = pp(0u);
    let t = taps(x, y, s);
    return aux[o + t.i[0]] * t.w[0] + aux[o + t.i[1]] * t.w[1] + aux[o + t.i[2]] * t.w[2]
        + aux[o + t.i[3]] * t.w[3];
}

@compute @workgroup_size(64)
fn fourier(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_id) lid: vec3<u32>) {
    let q = point(wg, nwg, lid);
    if q != 0xffffffffu {
        vset(q, held(q, fourier_at(q)));
    }
    count_held(lid.x);
}

// The Fourier head at grid point q (model/field.rs `ModelField::occupancy`).
fn fourier_at(q: u32) -> f32 {
    let n = pp(0u);
    let r = vec3<f32>(aux[q % n], aux[(q / n) % n], aux[q / (n * n)]);
    let m = mat3x3<f32>(
        bitcast<f32>(ff(8u)), bitcast<f32>(ff(9u)), bitcast<f32>(ff(10u)),
        bitcast<f32>(ff(11u)), bitcast<f32>(ff(12u)), bitcast<f32>(ff(13u)),
        bitcast<f32>(ff(14u)), bitcast<f32>(ff(15u)), bitcast<f32>(ff(16u)));
    let u = m * r;
    var v = 0.0;
    let inside_cube = abs(u.x) <= 1.0 && abs(u.y) <= 1.0;
    if inside_cube && mask_at(u.x, u.y, ff(5u)) >= 0.5 {
        v = series(u.x, u.y, u.z, ff(0u), ff(1u), ff(2u) == 1u, bitcast<f32>(ff(3u)), bitcast<f32>(ff(4u)));
    }
    return v;
}
