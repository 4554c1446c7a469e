//! Tests of the surface levels the maps are read at: the model's own, a level inside a
//! gate, and the peak-relative reading of thin parts.
use super::*;

/// The series of interval `iv` scaled by `g` (a blurring regression's peak under 1) on every
/// pixel of a 2 x 2 map (depth scale 1, the default level): its coefficients and the maps.
fn scaled(iv: [f64; 2], g: f32, k: usize) -> (Vec<f32>, FourierMaps) {
    let c: Vec<f32> = interval_coeffs(&[iv], k)
        .iter()
        .map(|v| g * *v as f32)
        .collect();
    let planar: Vec<f32> = c.iter().flat_map(|v| [*v; 4]).collect();
    let maps = FourierMaps::from_planar(&planar, k, 2, 1.0).unwrap();
    (c, maps)
}

/// A level under 0.5 widens the decoded interval by where the series crosses that level
/// (a blurred thin part comes back), a level above narrows it; occupancy stays in [0, 1]
/// and the default is the series' own 0.5 crossing.
#[test]
fn iso_level_moves_the_surface_to_that_level_of_the_series() {
    let k = 15;
    // A thin interval, its series scaled as a blurring regression would leave it: peak
    // well under 1, so at 0.5 it decodes narrower than it is.
    let (c, raw) = scaled([-0.1, 0.1], 0.6, k);
    assert_eq!(raw.iso_level(), 0.5);
    let width = |m: &FourierMaps| {
        let (mut out, mut s, mut n) = ([0.0f32], Vec::new(), 0);
        for i in 0..=2000 {
            let z = -1.0 + 2.0 * i as f32 / 2000.0;
            m.occupancy(&[Vec3::new(0.1, 0.1, z)], &mut out, &mut s);
            assert!((0.0..=1.0).contains(&out[0]), "{}", out[0]);
            n += (out[0] > 0.5) as usize;
        }
        n as f64 / 1000.0
    };
    let (w_raw, w_low, w_high) = (
        width(&raw),
        width(&raw.clone().with_iso_level(0.3)),
        width(&raw.clone().with_iso_level(0.58)),
    );
    assert!(w_low > w_raw && w_raw > w_high, "{w_low} {w_raw} {w_high}");
    // The level-0.3 surface is where the series equals 0.3: check one crossing in f64.
    let series = |z: f64| -> f64 {
        let mut b = vec![0.0f32; 2 * k + 1];
        basis(z as f32, k, &mut b);
        c.iter()
            .zip(&b)
            .map(|(x, y)| (*x as f64) * (*y as f64))
            .sum()
    };
    let edge = w_low / 2.0;
    assert!(
        (series(edge) - 0.3).abs() < 0.02,
        "series at the edge {}",
        series(edge)
    );
}

/// `with_level_in` reads the gated pixels at the given level, exactly as the whole maps
/// read at that level would, and leaves the other pixels at the maps' own; a gate of the
/// wrong length or a level outside (0, 1) changes nothing.
#[test]
fn level_in_a_gate_reads_only_the_gated_pixels_at_that_level() {
    let k = 15;
    // 2 x 2 pixels, each the same blurred interval.
    let own = scaled([-0.2, 0.3], 0.8, k).1.with_iso_level(0.55);
    let low = own.clone().with_iso_level(0.45);
    let gate = [true, false, false, true];
    let gated = own.clone().with_level_in(0.45, &gate);
    let c = 2 * k + 1;
    let (mut a, mut b, mut s) = ([0.0f32], [0.0f32], Vec::new());
    for (px, g) in gate.iter().enumerate() {
        // The pixel centre of map pixel px (crop NDC; a 2-pixel map spans [-1, 1]).
        let (x, y) = (
            if px % 2 == 0 { -1.0 } else { 1.0 },
            if px < 2 { -1.0 } else { 1.0 },
        );
        for i in 0..=400 {
            let z = -1.0 + 2.0 * i as f32 / 400.0;
            let p = [Vec3::new(x, y, z)];
            gated.occupancy(&p, &mut a, &mut s);
            (if *g { &low } else { &own }).occupancy(&p, &mut b, &mut s);
            assert!(
                (a[0] - b[0]).abs() < 1e-5,
                "pixel {px} z {z}: {} vs {}",
                a[0],
                b[0]
            );
        }
        // Only the constant term moved, by the difference of the levels.
        let (g0, o0) = (gated.coefficients()[px * c], own.coefficients()[px * c]);
        let want = if *g { 0.10 } else { 0.0 };
        assert!((g0 - o0 - want).abs() < 1e-6, "pixel {px}: {g0} - {o0}");
    }
    for m in [
        own.clone().with_level_in(0.45, &gate[..3]),
        own.clone().with_level_in(1.0, &gate),
        own.clone().with_level_in(f32::NAN, &gate),
    ] {
        assert_eq!(m.coefficients(), own.coefficients());
    }
}

/// The peak-relative level brings back a thin part whose blurred series peaks under the
/// surface level, at half its peak (about its true width), and leaves alone a thick part
/// (peak over the level / frac) and an empty ray (peak under `min_peak`).
#[test]
fn peak_relative_level_keeps_thin_parts_and_nothing_else() {
    let k = 15;
    let scaled = |iv: [f64; 2], g: f32| scaled(iv, g, k).1.with_iso_level(0.55);
    let inside = |m: &FourierMaps| {
        let (mut out, mut s) = ([0.0f32], Vec::new());
        (0..=2000)
            .filter(|i| {
                let z = -1.0 + 2.0 * *i as f32 / 2000.0;
                m.occupancy(&[Vec3::new(0.1, 0.1, z)], &mut out, &mut s);
                out[0] > 0.5
            })
            .count() as f64
            / 1000.0
    };
    // A thin part (true width 0.2) blurred to a peak of about 0.45: gone at 0.55.
    let thin = scaled([-0.1, 0.1], 0.45);
    assert_eq!(inside(&thin), 0.0);
    let back = inside(&thin.clone().with_peak_relative_level(0.5, 0.2));
    assert!(
        (back - 0.2).abs() < 0.06,
        "thin part decodes {back} wide (0.2 true)"
    );
    // A thick part at full height: unchanged.
    let thick = scaled([-0.5, 0.3], 1.0);
    assert_eq!(
        inside(&thick),
        inside(&thick.clone().with_peak_relative_level(0.5, 0.2))
    );
    // Nearly nothing on the ray: still nothing.
    let faint = scaled([-0.1, 0.1], 0.15);
    assert_eq!(inside(&faint.with_peak_relative_level(0.5, 0.2)), 0.0);
    // Out-of-range knobs leave the maps as they were.
    let same = thin.clone().with_peak_relative_level(1.5, 0.2);
    assert_eq!(same.pixel(0, 0), thin.pixel(0, 0));
}

/// The gated form reads only the pixels its gate marks: the same blurred thin part on every
/// pixel of a 2 x 2 map comes back on the one gated pixel and stays gone on the others; a
/// gate of the wrong size leaves the maps alone. `mask_gate` averages the mask over each
/// map pixel's footprint.
#[test]
fn gated_peak_level_reads_only_the_gated_pixels() {
    let k = 15;
    let thin = scaled([-0.1, 0.1], 0.45, k).1.with_iso_level(0.55);
    // Inside anywhere on the ray through a map corner (align-corners: (-1, -1) is pixel 0).
    let hit = |m: &FourierMaps, x: f32, y: f32| {
        let (mut out, mut s) = ([0.0f32], Vec::new());
        (0..=400).any(|i| {
            m.occupancy(
                &[Vec3::new(x, y, -1.0 + i as f32 / 200.0)],
                &mut out,
                &mut s,
            );
            out[0] > 0.5
        })
    };
    let gate = [true, false, false, false];
    let gated = thin
        .clone()
        .with_peak_relative_level_in(0.5, 0.2, Some(&gate));
    assert!(hit(&gated, -1.0, -1.0), "the gated pixel stays empty");
    for (x, y) in [(1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        assert!(!hit(&gated, x, y), "an ungated pixel ({x}, {y}) decodes");
        assert!(hit(&thin.clone().with_peak_relative_level(0.5, 0.2), x, y));
    }
    let wrong = thin
        .clone()
        .with_peak_relative_level_in(0.5, 0.2, Some(&[true; 3]));
    assert_eq!(wrong.pixel(0, 0), thin.pixel(0, 0));

    // A 4 x 4 mask over 2 x 2 map pixels: the top-left block full, the rest at 0.3 except
    // one full input pixel in the top-right block (mean 0.475).
    let mut mask = [0.3f32; 16];
    for i in [0, 1, 4, 5, 2] {
        mask[i] = 1.0;
    }
    assert_eq!(mask_gate(&mask, 4, 2, 0.5), vec![true, false, false, false]);
    assert_eq!(mask_gate(&mask, 4, 2, 0.45), vec![true, true, false, false]);
    assert_eq!(
        mask_gate(&mask, 4, 3, 0.1),
        vec![false; 9],
        "4 is not a multiple of 3"
    );
    assert_eq!(
        mask_gate(&mask[..8], 4, 2, 0.1),
        vec![false; 4],
        "a short mask"
    );
}

/// The thin-part gate keeps a 2-pixel bar and a 1-pixel finger off a thick block, and none
/// of the block, its edges and corners included: an opening removes only what is narrower
/// than its square.
#[test]
fn thin_gate_takes_the_narrow_parts_and_leaves_thick_edges() {
    let n = 32;
    let mut mask = vec![false; n * n];
    let mut set = |y0: usize, y1: usize, x0: usize, x1: usize| {
        for y in y0..y1 {
            for x in x0..x1 {
                mask[y * n + x] = true;
            }
        }
    };
    set(4, 20, 4, 16); // the block (torso), 16 x 12
    set(8, 10, 16, 28); // a 2-pixel bar off its side (an arm seen edge-on)
    set(20, 27, 9, 10); // a 1-pixel finger under it
    let gate = thin_gate(&mask, n, 2);
    for y in 0..n {
        for x in 0..n {
            let block = (4..20).contains(&y) && (4..16).contains(&x);
            let thin = mask[y * n + x] && !block;
            assert_eq!(gate[y * n + x], thin, "pixel ({y}, {x})");
        }
    }
    // Radius 0 opens nothing; an empty mask has no thin parts.
    assert!(thin_gate(&mask, n, 0).iter().all(|g| !g));
    assert!(thin_gate(&vec![false; n * n], n, 2).iter().all(|g| !g));
}
