//! Tests of the Fourier (and cosine) series, maps and levels.
use super::*;

fn basis64(z: f64, k: usize) -> Vec<f64> {
    let mut v = vec![1.0];
    for n in 1..=k {
        let a = n as f64 * std::f64::consts::PI * z;
        v.push(a.cos());
        v.push(a.sin());
    }
    v
}

#[test]
fn recurrence_matches_f64_trig_and_is_exact_at_the_ends() {
    for k in [7usize, 15, 31] {
        let mut b = vec![0.0f32; 2 * k + 1];
        for i in 0..=400 {
            let z = -1.0 + 2.0 * i as f64 / 400.0;
            basis(z as f32, k, &mut b);
            let r = basis64(z as f32 as f64, k);
            for (x, y) in b.iter().zip(&r) {
                assert!(
                    (*x as f64 - y).abs() < 2e-5 * k as f64,
                    "k {k} z {z}: {x} vs {y}"
                );
            }
        }
        for z in [-1.0f32, 1.0] {
            basis(z, k, &mut b);
            assert_eq!(b[0], 1.0);
            for n in 1..=k {
                let sign = if n % 2 == 0 { 1.0 } else { -1.0 };
                assert_eq!(b[2 * n - 1], sign, "cos({n} pi) at {z}");
                assert_eq!(b[2 * n], 0.0, "sin({n} pi) at {z}");
            }
        }
        for z in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            basis(z, k, &mut b);
            assert!(b.iter().all(|v| v.is_finite()));
        }
    }
}

/// The coefficients are the L2 projection of the indicator: the series converges to it
/// (away from the edges) and crosses 0.5 at the edges of a wide interval.
#[test]
fn series_of_interval_coefficients_reconstructs_the_indicator() {
    let iv = [[-0.6, -0.2], [0.1, 0.5]];
    for k in [15usize, 31, 63] {
        let c = interval_coeffs(&iv, k);
        let cf: Vec<f32> = c.iter().map(|v| *v as f32).collect();
        let maps = FourierMaps::from_planar(
            &cf.iter().flat_map(|v| [*v; 4]).collect::<Vec<_>>(),
            k,
            2,
            1.0,
        )
        .unwrap();
        let mut out = [0.0f32];
        let mut s = Vec::new();
        let mut worst: f32 = 0.0;
        for i in 0..=200 {
            let z = -1.0 + 2.0 * i as f32 / 200.0;
            let dist = iv
                .iter()
                .flat_map(|w| [(w[0] as f32 - z).abs(), (w[1] as f32 - z).abs()])
                .fold(f32::MAX, f32::min);
            maps.occupancy(&[Vec3::new(0.3, -0.2, z)], &mut out, &mut s);
            let truth = iv.iter().any(|w| w[0] as f32 <= z && z <= w[1] as f32);
            // Away from an edge by a few wavelengths the partial sum is on the right side.
            if dist > 4.0 / k as f32 {
                assert_eq!(out[0] > 0.5, truth, "k {k} z {z}: {}", out[0]);
                worst = worst.max((out[0] - truth as u8 as f32).abs());
            }
        }
        assert!(worst < 0.2, "k {k}: worst error {worst}");
        // At an edge of a wide interval the series is 1/2 (Gibbs is symmetric there).
        maps.occupancy(&[Vec3::new(0.0, 0.0, 0.1)], &mut out, &mut s);
        assert!((out[0] - 0.5).abs() < 0.06, "k {k}: edge value {}", out[0]);
    }
    // Outside the depth range: 0; non-finite: 0.
    let maps = FourierMaps::from_planar(&[1.0; 4], 0, 2, 1.0).unwrap();
    let mut out = [9.0f32; 3];
    let pts = [
        Vec3::new(0.0, 0.0, 1.01),
        Vec3::new(0.0, 0.0, f32::NAN),
        Vec3::new(f32::INFINITY, 0.0, 0.0),
    ];
    maps.occupancy(&pts, &mut out, &mut Vec::new());
    assert_eq!(out, [0.0; 3]);
}

/// The cosine basis against f64 trig, exact at both ends of the depth range; its
/// coefficients against a numerical integral of the indicator (f64 midpoint rule); its
/// series reconstructs the indicator through `FourierMaps` like the full one, and an
/// interval touching an end of the range is reproduced there without the full series'
/// jump (the cosine's even extension is continuous at the ends).
#[test]
fn cosine_basis_coefficients_and_reconstruction() {
    for k in [7usize, 15, 31] {
        let mut b = vec![0.0f32; 2 * k + 1];
        for i in 0..=400 {
            let z = -1.0 + 2.0 * i as f64 / 400.0;
            cosine_basis(z as f32, k, &mut b);
            let t = (z as f32 as f64 + 1.0) * 0.5;
            for (n, x) in b.iter().enumerate() {
                let y = (n as f64 * std::f64::consts::PI * t).cos();
                assert!(
                    (*x as f64 - y).abs() < 3e-5 * k as f64,
                    "k {k} z {z} n {n}: {x} vs {y}"
                );
            }
        }
        cosine_basis(-1.0, k, &mut b);
        assert!(b.iter().all(|v| *v == 1.0));
        cosine_basis(1.0, k, &mut b);
        for (n, v) in b.iter().enumerate() {
            assert_eq!(*v, if n % 2 == 0 { 1.0 } else { -1.0 });
        }
        cosine_basis(f32::NAN, k, &mut b);
        assert!(b.iter().all(|v| v.is_finite()));
    }
    let iv = [[-0.6, -0.2], [0.1, 0.5]];
    let k = 15;
    let c = cosine_interval_coeffs(&iv, k);
    let m = 200_000;
    for (n, cn) in c.iter().enumerate() {
        // a_n = 2 * int_0^1 f(t) cos(n pi t) dt, and c0 = a_0 / 2.
        let integral: f64 = (0..m)
            .map(|i| {
                let t = (i as f64 + 0.5) / m as f64;
                let z = 2.0 * t - 1.0;
                let f = iv.iter().any(|w| w[0] <= z && z <= w[1]) as u8 as f64;
                f * (n as f64 * std::f64::consts::PI * t).cos() / m as f64
            })
            .sum();
        let want = if n == 0 { integral } else { 2.0 * integral };
        assert!((cn - want).abs() < 1e-4, "n {n}: {cn} vs {want}");
    }
    assert_eq!(Basis::Cosine.interval_coeffs(&iv, k), c);
    assert_eq!(
        Basis::Fourier.interval_coeffs(&iv, k),
        interval_coeffs(&iv, k)
    );
    // Through the maps, with an interval touching the back end of the range.
    let iv = [[-1.0, -0.7], [0.1, 0.5]];
    for k in [15usize, 31] {
        let decode = |basis: Basis, z: f32| {
            let c = basis.interval_coeffs(&iv, k);
            let cf: Vec<f32> = c.iter().map(|v| *v as f32).collect();
            let maps = FourierMaps::from_planar(
                &cf.iter().flat_map(|v| [*v; 4]).collect::<Vec<_>>(),
                k,
                2,
                1.0,
            )
            .unwrap()
            .with_basis(basis);
            assert_eq!(maps.basis(), basis);
            let mut out = [0.0f32];
            maps.occupancy(&[Vec3::new(0.1, 0.2, z)], &mut out, &mut Vec::new());
            out[0]
        };
        for i in 0..=200 {
            let z = -1.0 + 2.0 * i as f32 / 200.0;
            let dist = iv
                .iter()
                .flat_map(|w| [(w[0] as f32 - z).abs(), (w[1] as f32 - z).abs()])
                .filter(|d| *d > 0.0 || z > -1.0)
                .fold(f32::MAX, f32::min);
            let truth = iv.iter().any(|w| w[0] as f32 <= z && z <= w[1] as f32);
            if dist > 4.0 / k as f32 {
                let v = decode(Basis::Cosine, z);
                assert_eq!(v > 0.5, truth, "cosine k {k} z {z}: {v}");
            }
        }
        // At the back end, inside: the cosine series is about 1, the full series about
        // 1/2 (its periodic extension jumps there).
        assert!(decode(Basis::Cosine, -0.999) > 0.9, "cosine at the end");
        assert!(
            (decode(Basis::Fourier, -1.0) - 0.5).abs() < 0.1,
            "fourier at the end"
        );
    }
    assert_eq!(Basis::parse("cosine"), Some(Basis::Cosine));
    assert_eq!(Basis::parse("fourier"), Some(Basis::Fourier));
    assert_eq!(Basis::parse("chebyshev"), None);
}

/// The series of one interval with its harmonics damped (`exp(-(n sigma)^2)` on the n-th):
/// a blur that keeps the interval's mass `c0` and its depth centre.
fn damped(iv: [f64; 2], sigma: f64, k: usize) -> Vec<f32> {
    interval_coeffs(&[iv], k)
        .iter()
        .enumerate()
        .map(|(i, v)| (v * (-((i.div_ceil(2)) as f64 * sigma).powi(2)).exp()) as f32)
        .collect()
}

/// The moment fill: a thin part whose series is blurred (its harmonics damped, its mass `c0`
/// and depth centre kept) peaks under the level and vanishes; filled from its moments it
/// decodes at its true place and width. A thick ray, an empty one, one under the least length
/// and other bases are left as they are.
#[test]
fn moment_fill_puts_a_blurred_thin_part_back_where_it_was() {
    let k = 15;
    let blurred = |iv: [f64; 2], sigma: f64| -> FourierMaps {
        let c = damped(iv, sigma, k);
        let planar: Vec<f32> = c.iter().flat_map(|v| [*v; 4]).collect();
        FourierMaps::from_planar(&planar, k, 2, 1.0)
            .unwrap()
            .with_iso_level(0.55)
    };
    let span = |m: &FourierMaps| -> Option<(f32, f32)> {
        let (mut out, mut s) = ([0.0f32], Vec::new());
        let zs: Vec<f32> = (0..=4000)
            .map(|i| -1.0 + 2.0 * i as f32 / 4000.0)
            .filter(|z| {
                m.occupancy(&[Vec3::new(0.1, 0.1, *z)], &mut out, &mut s);
                out[0] > 0.5
            })
            .collect();
        Some((*zs.first()?, *zs.last()?))
    };
    let thin = blurred([0.3, 0.42], 0.25);
    assert_eq!(span(&thin), None, "the blurred part decodes empty");
    let (lo, hi) = span(&thin.clone().with_moment_fill(0.02, 2.0, 1)).expect("filled");
    assert!(
        (lo - 0.3).abs() < 0.03 && (hi - 0.42).abs() < 0.03,
        "filled at [{lo}, {hi}], true [0.3, 0.42]"
    );
    // At most max_len of it, about the same centre.
    let (lo, hi) = span(&thin.clone().with_moment_fill(0.02, 0.08, 1)).expect("filled");
    assert!(
        (hi - lo - 0.08).abs() < 0.03 && ((lo + hi) / 2.0 - 0.36).abs() < 0.02,
        "capped at [{lo}, {hi}]"
    );
    // Near the end of the range: kept inside it at its length.
    let edge = blurred([0.86, 0.99], 0.25);
    assert_eq!(span(&edge), None);
    let (lo, hi) = span(&edge.clone().with_moment_fill(0.02, 2.0, 1)).expect("filled");
    assert!(hi <= 1.0 && (hi - lo - 0.13).abs() < 0.05, "[{lo}, {hi}]");
    // A thick ray decodes as it did; so do an empty ray and one under the least length.
    let thick = blurred([-0.5, 0.3], 0.02);
    assert_eq!(
        thick.clone().with_moment_fill(0.02, 2.0, 1).pixel(0, 0),
        thick.pixel(0, 0)
    );
    let empty = blurred([0.0, 0.0], 0.25);
    assert_eq!(
        empty.clone().with_moment_fill(0.02, 2.0, 1).pixel(0, 0),
        empty.pixel(0, 0)
    );
    assert_eq!(
        thin.clone().with_moment_fill(0.2, 2.0, 1).pixel(0, 0),
        thin.pixel(0, 0)
    );
    let cos = thin.clone().with_basis(Basis::Cosine);
    assert_eq!(
        cos.clone().with_moment_fill(0.02, 2.0, 1).pixel(0, 0),
        cos.pixel(0, 0)
    );
    // Bad knobs leave the maps alone.
    assert_eq!(
        thin.clone().with_moment_fill(f32::NAN, 2.0, 1).pixel(0, 0),
        thin.pixel(0, 0)
    );
}

/// The moment fill on a map: a body (pixels that decode), the blurred band two pixels wide
/// around it and a blurred "hand" reaching six pixels beyond it (both candidates). Filled
/// `away` = 4 pixels from the body: the hand, back to one pixel from the body, not the band.
#[test]
fn moment_fill_restores_what_reaches_beyond_the_band_around_the_body() {
    let (k, n) = (15usize, 32usize);
    let c = 2 * k + 1;
    let body = damped([-0.4, 0.4], 0.0, k);
    let blurred = damped([0.0, 0.14], 0.25, k);
    // Body: x, y in 8..16; band: within 2 of it; hand: x in 16..24, y in 11..13 beyond the band.
    let kind = |x: usize, y: usize| -> u8 {
        let inb = (8..16).contains(&x) && (8..16).contains(&y);
        let band = (6..18).contains(&x) && (6..18).contains(&y);
        let hand = (16..24).contains(&x) && (11..13).contains(&y);
        if inb {
            2
        } else if band || hand {
            1
        } else {
            0
        }
    };
    let mut planar = vec![0.0f32; c * n * n];
    for y in 0..n {
        for x in 0..n {
            let s = match kind(x, y) {
                2 => &body,
                1 => &blurred,
                _ => continue,
            };
            for ch in 0..c {
                planar[ch * n * n + y * n + x] = s[ch];
            }
        }
    }
    let maps = FourierMaps::from_planar(&planar, k, n, 1.0)
        .unwrap()
        .with_iso_level(0.55);
    let filled = maps.clone().with_moment_fill(0.02, 2.0, 4);
    let changed = |x: usize, y: usize| filled.pixel(x, y) != maps.pixel(x, y);
    for y in 0..n {
        for x in 0..n {
            let hand = (16..24).contains(&x) && (11..13).contains(&y);
            match kind(x, y) {
                // The hand, back to the body's edge (its seeds at x >= 19, grown 3 rings).
                1 if hand => assert!(changed(x, y), "hand pixel ({x}, {y}) not filled"),
                // The band away from where the hand meets it.
                1 if x < 15 || !(8..16).contains(&y) => {
                    assert!(!changed(x, y), "band pixel ({x}, {y}) filled")
                }
                0 | 2 => assert!(!changed(x, y), "pixel ({x}, {y}) changed"),
                _ => {}
            }
        }
    }
}

#[test]
fn maps_refuse_bad_shapes_and_non_finite_values() {
    assert!(FourierMaps::from_planar(&[0.0; 12], 1, 2, 1.0).is_some());
    assert!(FourierMaps::from_planar(&[0.0; 11], 1, 2, 1.0).is_none());
    let mut v = [0.0f32; 12];
    v[5] = f32::NAN;
    assert!(FourierMaps::from_planar(&v, 1, 2, 1.0).is_none());
    assert!(FourierMaps::from_planar(&[0.0; 12], 1, 2, 0.0).is_none());
    // A non-finite value in the last of several chunks is found too.
    let mut v = vec![0.0f32; 5 * 13 * 13];
    v[5 * 169 - 1] = f32::INFINITY;
    assert!(FourierMaps::from_planar(&v, 2, 13, 1.0).is_none());
}

#[test]
fn planar_maps_are_interleaved_pixel_by_pixel() {
    // Sizes whose pixel counts are and are not multiples of the transpose's blocks.
    for (k, size) in [(2, 13), (15, 8), (15, 16), (3, 2)] {
        let c = 2 * k + 1;
        let plane = size * size;
        let planar: Vec<f32> = (0..c * plane).map(|i| (i as f32 * 0.37).sin()).collect();
        let maps = FourierMaps::from_planar(&planar, k, size, 1.0).unwrap();
        let data = maps.coefficients();
        assert_eq!(data.len(), planar.len());
        for p in 0..plane {
            for ch in 0..c {
                assert_eq!(
                    data[p * c + ch],
                    planar[ch * plane + p],
                    "k {k} size {size} pixel {p} channel {ch}"
                );
            }
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    /// Adversarial maps (coefficients up to +-1e6, ringing, negative mass) through both
    /// thin-part readings stay finite, keep their shape, and decode in [0, 1] everywhere.
    #[test]
    fn thin_part_readings_of_wild_maps_stay_finite(
        vals in proptest::collection::vec(-1.0e6f32..1.0e6, 7 * 16),
        scale in proptest::sample::select(vec![1e-6f32, 1e-2, 1.0, 1e3]),
        away in 1usize..6,
    ) {
        let planar: Vec<f32> = vals.iter().map(|v| v * scale).collect();
        let maps = FourierMaps::from_planar(&planar, 3, 4, 2.0).unwrap().with_iso_level(0.55);
        for m in [
            maps.clone().with_moment_fill(0.02, 0.1, away),
            maps.clone().with_moment_fill(1e-6, 2.0, away),
            maps.clone().with_peak_relative_level(0.5, 0.2),
        ] {
            proptest::prop_assert_eq!(m.coefficients().len(), planar.len());
            proptest::prop_assert!(m.coefficients().iter().all(|v| v.is_finite()));
            let (mut out, mut s) = (vec![0.0f32; 9], Vec::new());
            let pts: Vec<Vec3> = (0..9).map(|i| Vec3::new(0.3, -0.2, -1.0 + 0.25 * i as f32)).collect();
            m.occupancy(&pts, &mut out, &mut s);
            proptest::prop_assert!(out.iter().all(|v| (0.0..=1.0).contains(v)));
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
    /// The quick "does this ray decode" answer of the moment fill is the full scan's
    /// (`peaks() >= iso` at the same 129 depths) on maps of blurred intervals at any depth,
    /// width, blur and height, with noise, for both bases.
    #[test]
    fn quick_decode_test_agrees_with_the_full_scan(
        rays in proptest::collection::vec(
            (-1.0f64..1.0, 0.0f64..0.8, 0.0f64..0.3, 0.0f32..1.4),
            16,
        ),
        noise in proptest::collection::vec(-1.0f32..1.0, 31 * 16),
        amp in proptest::sample::select(vec![0.0f32, 0.01, 0.1]),
        cosine in proptest::bool::ANY,
    ) {
        let (k, c) = (15, 31);
        let mut planar = vec![0.0f32; c * 16];
        for (p, (lo, len, sigma, gain)) in rays.iter().enumerate() {
            let series = damped([*lo, (*lo + *len).min(1.0)], *sigma, k);
            for ch in 0..c {
                planar[ch * 16 + p] = gain * series[ch] + amp * noise[ch * 16 + p];
            }
        }
        let mut maps = FourierMaps::from_planar(&planar, k, 4, 1.0).unwrap().with_iso_level(0.55);
        if cosine {
            maps = maps.with_basis(Basis::Cosine);
        }
        let full: Vec<bool> = maps.peaks().iter().map(|p| *p >= maps.iso_level()).collect();
        proptest::prop_assert_eq!(maps.decodes(), full);
    }
}

/// The block evaluation's side-by-side recurrences give each point exactly the basis of
/// [`basis`] / [`cosine_basis`] (the same operations in the same order), ends included.
#[test]
fn basis_of_a_block_equals_the_basis_of_each_point() {
    for kind in [Basis::Fourier, Basis::Cosine] {
        for k in [0usize, 1, 3, 7, 15, 31] {
            let c = 2 * k + 1;
            let zeta: [f32; LANES] = [-1.0, 1.0, 0.0, 0.3, -0.77, 0.999, -1e-7, 0.5];
            let mut out = vec![f32::NAN; LANES * c];
            lane_basis(kind, &zeta, k, c, &mut out);
            let mut one = vec![0.0f32; c];
            for (l, z) in zeta.iter().enumerate() {
                kind.values(*z, k, &mut one);
                assert_eq!(
                    &out[l * c..(l + 1) * c],
                    &one[..],
                    "{kind:?} k {k} zeta {z}"
                );
            }
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(96))]

    /// Occupancy against an f64 sum of the same series (each tap's coefficients times the
    /// point's basis, blended by the bilinear weights, offset, clamped), for every order,
    /// both bases, point counts in and off the blocks, and points outside the depth range
    /// or not finite (0).
    #[test]
    fn occupancy_equals_the_series_summed_in_f64(
        k in proptest::sample::select(vec![0usize, 1, 3, 7, 15, 31]),
        size in 2usize..7,
        cosine in proptest::bool::ANY,
        iso in 0.3f32..0.7,
        seed in 0u64..1_000_000,
        n in 0usize..41,
    ) {
        let c = 2 * k + 1;
        let mut s = seed.wrapping_mul(2862933555777941757).wrapping_add(3037000493);
        let mut rnd = move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let planar: Vec<f32> = (0..c * size * size).map(|_| rnd() * 0.4).collect();
        let basis = if cosine { Basis::Cosine } else { Basis::Fourier };
        let maps = FourierMaps::from_planar(&planar, k, size, 1.25)
            .unwrap()
            .with_basis(basis)
            .with_iso_level(iso);
        let pts: Vec<Vec3> = (0..n)
            .map(|i| match i % 11 {
                5 => Vec3::new(rnd(), rnd(), f32::NAN),
                7 => Vec3::new(f32::INFINITY, rnd(), 0.1),
                9 => Vec3::new(rnd(), rnd(), 0.9),
                _ => Vec3::new(rnd() * 1.2, rnd() * 1.2, rnd() * 0.8),
            })
            .collect();
        let mut out = vec![f32::NAN; n];
        maps.occupancy(&pts, &mut out, &mut Vec::new());
        let mut b = vec![0.0f32; c];
        for (p, o) in pts.iter().zip(&out) {
            let zeta = p.z * 1.25;
            if !(p.is_finite() && zeta.abs() <= 1.0) {
                proptest::prop_assert_eq!(*o, 0.0);
                continue;
            }
            basis.values(zeta, k, &mut b);
            let (idx, w) = taps(size, size, p.x, p.y);
            let mut acc = 0.0f64;
            for t in 0..4 {
                let m = &maps.coefficients()[idx[t] * c..(idx[t] + 1) * c];
                let d: f64 = m.iter().zip(&b).map(|(x, y)| *x as f64 * *y as f64).sum();
                acc += w[t] as f64 * d;
            }
            let want = (acc + (0.5 - iso) as f64).clamp(0.0, 1.0);
            proptest::prop_assert!((*o as f64 - want).abs() < 1e-5, "{} vs {}", o, want);
        }
    }
}
