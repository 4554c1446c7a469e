//! `preprocess`'s unit tests: the letterbox, the crop and paste rules against their per-pixel
//! forms, the most prominent person, the close-range choice.

use super::*;

fn disc(mask: &mut [f32], size: usize, cx: f32, cy: f32, r: f32) {
    for y in 0..size {
        for x in 0..size {
            if (x as f32 - cx).hypot(y as f32 - cy) <= r {
                mask[y * size + x] = 0.9;
            }
        }
    }
}

#[test]
fn a_mask_goes_back_to_the_frame_it_came_from() {
    // A 400x200 frame: the letterbox is 256x128 at rows 64..192. A block of the frame
    // marked in the square must come back at its place in the frame.
    let s = INPUT_SIZE;
    let (w, h) = (400usize, 200usize);
    let mut sq = vec![0.0f32; s * s];
    // Frame pixels x 100..200, y 50..150 -> square x 64..128, y 64+32..64+96.
    for y in 96..160 {
        for x in 64..128 {
            sq[y * s + x] = 1.0;
        }
    }
    let m = unletterbox_mask(&sq, w, h);
    assert_eq!(m.len(), w * h);
    let on = |x: usize, y: usize| m[y * w + x] == 255;
    assert!(on(150, 100) && on(102, 52) && on(197, 147));
    assert!(!on(95, 100) && !on(205, 100) && !on(150, 45) && !on(150, 155));
    let count = m.iter().filter(|&&v| v == 255).count() as f64;
    assert!((count / 10_000.0 - 1.0).abs() < 0.05, "{count}");
}

#[test]
fn the_largest_person_is_kept_and_people_are_counted() {
    let s = 64;
    let mut m = vec![0.0f32; s * s];
    disc(&mut m, s, 16.0, 32.0, 6.0); // 113 px: a person (>= 0.2 % of 4096 and >= 10 % of the largest)
    disc(&mut m, s, 44.0, 32.0, 12.0); // the most prominent
    m[2] = 0.9; // one stray pixel: a fragment, not a person
    let before = m.clone();
    assert_eq!(keep_most_prominent(&mut m, s), 2);
    for (i, (&a, &b)) in m.iter().zip(&before).enumerate() {
        let (x, y) = ((i % s) as f32, (i / s) as f32);
        let in_big = (x - 44.0).hypot(y - 32.0) <= 12.0;
        assert_eq!(a, if in_big { b } else { 0.0 }, "pixel {x},{y}");
    }
    let mut empty = vec![0.2f32; s * s];
    assert_eq!(keep_most_prominent(&mut empty, s), 0);
    assert!(empty.iter().all(|&v| v == 0.0));
    // A lone speck below the frame fraction is no person.
    let mut speck = vec![0.0f32; s * s];
    speck[100] = 1.0;
    assert_eq!(keep_most_prominent(&mut speck, s), 0);
}

#[test]
fn cut_by_frame_is_a_person_on_the_frames_last_row() {
    let s = INPUT_SIZE;
    // A 4:3 landscape frame: letterboxed with padding rows above and below.
    let (_, _, fh, _, oy) = letterbox_geometry(640, 480);
    assert!(oy > 0 && oy + fh < s);
    let last = oy + fh - 1;
    let column = |rows: std::ops::Range<usize>| {
        let mut m = vec![0.0f32; s * s];
        for y in rows {
            for x in 100..140 {
                m[y * s + x] = 1.0;
            }
        }
        m
    };
    // Reaching the frame's last row: cut. Ending a row above it: a whole body.
    assert!(cut_by_frame(&column(oy + 10..last + 1), 640, 480));
    assert!(!cut_by_frame(&column(oy + 10..last), 640, 480));
    // Mask values in the padding below the frame are not the frame's edge.
    let mut pad = column(oy + 10..last);
    pad[(s - 1) * s + 120] = 1.0;
    assert!(!cut_by_frame(&pad, 640, 480));
    // A portrait frame fills the square's height: its last row is the square's.
    assert!(cut_by_frame(&column(50..s), 480, 640));
    assert!(!cut_by_frame(&column(50..s - 3), 480, 640));
    // Soft values at or below 0.5 are not person; empty inputs are not cut.
    let mut soft = column(oy + 10..last);
    soft[last * s + 120] = 0.5;
    assert!(!cut_by_frame(&soft, 640, 480));
    assert!(!cut_by_frame(&vec![0.0; s * s], 640, 480));
    assert!(!cut_by_frame(&[], 640, 480));
    assert!(!cut_by_frame(&column(0..s), 0, 480));
}

#[test]
fn the_close_range_choice_changes_only_after_frames_in_a_row_disagree() {
    let mut sw = CloseRangeSwitch::new(3);
    assert!(!sw.is_on());
    // Feet flickering at the frame's edge: never three cut frames in a row.
    for cut in [true, true, false, true, false, true, true, false] {
        assert!(!sw.update(cut));
    }
    // Three in a row switch on, at the third.
    assert!(!sw.update(true));
    assert!(!sw.update(true));
    assert!(sw.update(true));
    // And back only after three whole-body frames in a row.
    for cut in [false, false, true, false, false] {
        assert!(sw.update(cut));
    }
    assert!(!sw.update(false));
    // 0 and 1 follow every frame.
    for n in [0, 1] {
        let mut sw = CloseRangeSwitch::new(n);
        for cut in [true, false, false, true, true, false] {
            assert_eq!(sw.update(cut), cut);
        }
    }
}

#[test]
fn crop_round_trips_points() {
    let c = Crop {
        s: 0.6,
        tx: 0.1,
        ty: -0.2,
        cut_by_frame: false,
    };
    let p = Vec3::new(0.3, -0.4, 0.25);
    assert!((c.to_input(c.to_crop(p)) - p).length() < 1e-6);
}

#[test]
fn empty_mask_has_no_crop_and_full_mask_is_identity_like() {
    let s = 16;
    assert_eq!(Crop::from_mask(&vec![0.0; s * s], s), None);
    let c = Crop::from_mask(&vec![1.0; s * s], s).unwrap();
    assert!((c.s - 1.0 / FILL).abs() < 1e-6 && c.tx.abs() < 1e-6 && c.ty.abs() < 1e-6);
    // One pixel: smallest scale, centred on it.
    let mut m = vec![0.0; s * s];
    m[5 * s + 3] = 1.0;
    let c = Crop::from_mask(&m, s).unwrap();
    assert_eq!(c.s, MIN_SCALE);
    assert!((c.tx - (-1.0 + 6.0 / 15.0)).abs() < 1e-6);
}

/// Crops inside, across and outside the square, and a degenerate one (scale 0).
fn test_crops() -> Vec<Crop> {
    [
        (1.0, 0.0, 0.0),
        (0.31, 0.12, -0.27),
        (0.5, 0.9, 0.9),
        (1.7, -0.4, 0.2),
        (0.05, -1.3, 1.1),
        (2.5, 3.0, -3.0),
        (0.0, 0.0, 0.0),
    ]
    .into_iter()
    .map(|(s, tx, ty)| Crop {
        s,
        tx,
        ty,
        cut_by_frame: false,
    })
    .collect()
}

/// The separable resampling gives, value for value, what taking the taps per pixel
/// gives (the rule as it was first written), for crops inside, across and outside the
/// frame, and for a degenerate one.
#[test]
fn crop_resampling_equals_the_per_pixel_rule() {
    fn per_pixel(c: &Crop, img: &[f32], channels: usize, size: usize) -> Vec<f32> {
        let plane = size * size;
        let mut out = vec![0.0f32; channels * plane];
        let to_px = |n: f32| (n + 1.0) * 0.5 * (size - 1) as f32;
        for y in 0..size {
            let uy = -1.0 + 2.0 * y as f32 / (size - 1) as f32;
            let py = to_px(c.s * uy + c.ty);
            for x in 0..size {
                let ux = -1.0 + 2.0 * x as f32 / (size - 1) as f32;
                let px = to_px(c.s * ux + c.tx);
                let (fx0, fy0) = (px.floor(), py.floor());
                let (wx, wy) = (px - fx0, py - fy0);
                let (ix, iy) = (fx0 as i64, fy0 as i64);
                for ch in 0..channels {
                    let src = &img[ch * plane..(ch + 1) * plane];
                    let at = |xx: i64, yy: i64| -> f32 {
                        if xx < 0 || yy < 0 || xx >= size as i64 || yy >= size as i64 {
                            0.0
                        } else {
                            src[yy as usize * size + xx as usize]
                        }
                    };
                    out[ch * plane + y * size + x] =
                        (at(ix, iy) * (1.0 - wx) + at(ix + 1, iy) * wx) * (1.0 - wy)
                            + (at(ix, iy + 1) * (1.0 - wx) + at(ix + 1, iy + 1) * wx) * wy;
                }
            }
        }
        out
    }
    let size = 37;
    let img: Vec<f32> = (0..3 * size * size)
        .map(|i| ((i * 7919) % 1000) as f32 / 999.0)
        .collect();
    for c in test_crops() {
        let (s, tx, ty) = (c.s, c.tx, c.ty);
        let got = c.apply(&img, 3, size);
        let want = per_pixel(&c, &img, 3, size);
        assert!(bit_equal(&got, &want), "crop {s} {tx} {ty}");
    }
}

/// The separable paste equals, value for value, sampling the crop's mask per pixel with
/// `bilinear1` (the rule as first written), for crops inside, across and outside the
/// square and for a degenerate one.
#[test]
fn paste_max_equals_the_per_pixel_rule() {
    fn per_pixel(c: &Crop, m: &[f32], size: usize, into: &mut [f32]) {
        let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (size - 1) as f32;
        for j in 0..size {
            let uy = (ndc(j) - c.ty) / c.s;
            for i in 0..size {
                let ux = (ndc(i) - c.tx) / c.s;
                if uy.abs() <= 1.0 && ux.abs() <= 1.0 {
                    let v = &mut into[j * size + i];
                    *v = v.max(crate::model::sample::bilinear1(m, size, size, ux, uy));
                }
            }
        }
    }
    let mut changed = 0;
    for size in [2, 37, 64] {
        let m: Vec<f32> = (0..size * size)
            .map(|i| ((i * 7919) % 1000) as f32 / 999.0)
            .collect();
        let base: Vec<f32> = (0..size * size)
            .map(|i| ((i * 104729) % 997) as f32 / 996.0 * 0.6)
            .collect();
        for c in test_crops() {
            let (s, tx, ty) = (c.s, c.tx, c.ty);
            let (mut got, mut want) = (base.clone(), base.clone());
            c.paste_max(&m, size, &mut got);
            per_pixel(&c, &m, size, &mut want);
            assert!(bit_equal(&got, &want), "size {size} crop {s} {tx} {ty}");
            changed += usize::from(got != base);
        }
    }
    // Not vacuous: most of the crops paste something.
    assert!(changed >= 10, "{changed} pastes changed the mask");
}

/// The letterbox with its column taps computed once equals, value for value, taking
/// them per pixel (the rule as first written), for wide, tall and larger frames.
#[test]
fn letterbox_equals_the_per_pixel_rule() {
    for (w, h) in [(40usize, 23usize), (23, 40), (300, 200), (257, 256), (1, 5)] {
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| ((i * 31) % 256) as u8).collect();
        let got = letterbox(&rgb, w, h);
        let s = INPUT_SIZE;
        let mut want = vec![0.0f32; 3 * s * s];
        let (scale, fw, fh, ox, oy) = letterbox_geometry(w, h);
        for y in 0..fh {
            let sy = ((y as f32 + 0.5) / scale - 0.5).clamp(0.0, (h - 1) as f32);
            let y0 = sy.floor() as usize;
            let y1 = (y0 + 1).min(h - 1);
            let fy = sy - y0 as f32;
            for x in 0..fw {
                let sx = ((x as f32 + 0.5) / scale - 0.5).clamp(0.0, (w - 1) as f32);
                let x0 = sx.floor() as usize;
                let x1 = (x0 + 1).min(w - 1);
                let fx = sx - x0 as f32;
                for c in 0..3 {
                    let p = |xx: usize, yy: usize| rgb[(yy * w + xx) * 3 + c] as f32;
                    let v = (p(x0, y0) * (1.0 - fx) + p(x1, y0) * fx) * (1.0 - fy)
                        + (p(x0, y1) * (1.0 - fx) + p(x1, y1) * fx) * fy;
                    want[c * s * s + (oy + y) * s + ox + x] = v / 255.0;
                }
            }
        }
        assert!(bit_equal(&got, &want), "{w}x{h}");
    }
}

#[test]
fn identity_crop_reproduces_the_image() {
    let s = 8;
    let img: Vec<f32> = (0..s * s).map(|i| i as f32).collect();
    let c = Crop {
        s: 1.0,
        tx: 0.0,
        ty: 0.0,
        cut_by_frame: false,
    };
    let out = c.apply(&img, 1, s);
    for (a, b) in img.iter().zip(&out) {
        assert!((a - b).abs() < 1e-3, "{a} vs {b}");
    }
}

/// Whether two float slices hold the same values bit for bit.
fn bit_equal(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}
