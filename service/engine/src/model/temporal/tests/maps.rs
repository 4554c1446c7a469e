//! The maps' filter (`Temporal::steady_maps`): tremor averaged, motion followed (the rate's
//! weight, the crop filter's floor, the mask's motion), moved crops, colour features.

use super::*;

#[test]
fn maps_follow_the_mask_where_it_moves_and_nowhere_else() {
    // A still body with a limb sweeping 4 px a frame beside it (its blocks move); its map
    // pixels swing between two values frame by frame, a change whose rate averages out
    // like tremor, so the rate's weight alone keeps the filter nearly shut there (a
    // swinging lower leg averaged with where it was). With `map_motion_weight` 1 those
    // pixels take this frame's maps; every other pixel is filtered exactly as without.
    let l = MapLayout {
        channels: 3,
        size: 32,
        interleaved: true,
    };
    let body = |k: usize| {
        let mut m = box_mask(100, 150, 40, 220, 0.95);
        for y in 150..220 {
            for x in 150 + 4 * k..160 + 4 * k {
                m[y * S + x] = 0.95;
            }
        }
        m
    };
    let c = crop_of(&box_mask(60, 230, 40, 220, 0.95));
    let base: Vec<f32> = (0..l.len()).map(|i| 0.5 + 0.1 * (i % 7) as f32).collect();
    let follow = TemporalSettings {
        map_motion_weight: 1.0,
        ..TemporalSettings::default()
    };
    let off = TemporalSettings {
        map_motion_weight: 0.0,
        ..TemporalSettings::default()
    };
    let (mut plain, mut moving) = (Temporal::new(off), Temporal::new(follow));
    // The crop given out moves a little each frame (the limb moves the box): a still crop
    // keeps the maps' filter whole (below).
    let crop_at = |k: usize| Crop {
        tx: c.tx + 0.006 * k as f32,
        ..c
    };
    let (mut followed, mut shut, mut frames_followed) = (0usize, 0usize, 0usize);
    // Pixels the motion reached on some frame so far (their history differs after it).
    let mut ever = vec![false; l.size * l.size];
    for k in 0..12 {
        let (mut m0, mut m1) = (body(k), body(k));
        let t_s = k as f64 / 30.0;
        let crop = plain.steady_input(t_s, 1, &mut m0, crop_at(k)).0.unwrap();
        assert_eq!(
            Some(crop),
            moving.steady_input(t_s, 1, &mut m1, crop_at(k)).0
        );
        // Where this frame's mask moved, in map pixels (none on the first frame).
        let here = moving.motion_pixels(l.size, crop);
        assert!(plain.motion_pixels(l.size, crop).is_none(), "off at 0");
        let here = here.unwrap_or_else(|| vec![false; l.size * l.size]);
        for (e, h) in ever.iter_mut().zip(&here) {
            *e |= *h;
        }
        // The crop moves across only, so a map row's last values come from the same row:
        // rows the motion never reached have the same history either way.
        let ever_row: Vec<bool> = ever.chunks(l.size).map(|r| r.contains(&true)).collect();
        let n = here.iter().filter(|m| **m).count();
        if moving.crop_still {
            assert_eq!(n, 0, "frame {k}: the crop stayed put");
        } else if k > 0 {
            frames_followed += 1;
            assert!(
                n > 0 && n < l.size * l.size / 3,
                "frame {k}: {n} pixels moved"
            );
            // The body's middle (the crop's centre column, above the limb) is still.
            assert!(!here[4 * l.size + l.size / 2], "frame {k}");
        }
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        let new: Vec<f32> = base
            .iter()
            .enumerate()
            .map(|(i, v)| {
                if here[i / 3] {
                    v + (k % 2) as f32
                } else {
                    v + sign * 0.005
                }
            })
            .collect();
        let (mut a, mut b) = (new.clone(), new.clone());
        plain.steady_maps(crop, (l, &mut a), None);
        moving.steady_maps(crop, (l, &mut b), None);
        for (i, ((a, b), n)) in a.iter().zip(&b).zip(&new).enumerate() {
            if here[i / 3] && k > 1 {
                assert_eq!(
                    b, n,
                    "frame {k}, value {i}: the moving part follows at once"
                );
                shut += ((a - n).abs() > 0.2) as usize;
                followed += 1;
            } else if !ever_row[i / 3 / l.size] {
                assert_eq!(
                    a, b,
                    "frame {k}, value {i}: a still pixel filtered as without"
                );
            }
        }
    }
    // The same limb under a crop that stays put: not followed.
    let mut held = Temporal::new(follow);
    for k in 0..4 {
        let mut m = body(k);
        let crop = held.steady_input(k as f64 / 30.0, 1, &mut m, c).0.unwrap();
        assert!(
            k < 2 || held.motion_pixels(l.size, crop).is_none(),
            "frame {k}: a still crop's maps followed the mask"
        );
    }
    let still = ever.chunks(l.size).filter(|r| !r.contains(&true)).count();
    assert!(still > l.size / 3, "{still} map rows never moved");
    assert!(frames_followed >= 6, "followed on {frames_followed} frames");
    assert!(followed > 0);
    assert!(
        shut * 2 > followed,
        "without the motion's weight {shut} of {followed} moving values were held back"
    );
}

#[test]
fn maps_average_tremor_and_follow_motion_within_a_frame() {
    let mut t = Temporal::new(TemporalSettings::default());
    let l = MapLayout {
        channels: 3,
        size: 16,
        interleaved: true,
    };
    let base: Vec<f32> = (0..l.len()).map(|i| 0.5 + 0.1 * (i % 7) as f32).collect();
    let mut m = box_mask(100, 150, 40, 220, 0.95);
    let c = crop_of(&m);
    let crop = t.steady_input(0.0, 1, &mut m, c).0.unwrap();
    let mut first = base.clone();
    t.steady_maps(crop, (l, &mut first), None);
    assert_eq!(first, base, "the first frame passes as it is");
    let mut worst_tremor = 0.0f32;
    for k in 1..30 {
        let mut m = box_mask(100, 150, 40, 220, 0.95);
        let crop = t.steady_input(k as f64 / 30.0, 1, &mut m, c).0.unwrap();
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        let mut maps: Vec<f32> = base.iter().map(|v| v + sign * 0.005).collect();
        // Pixel 0 moves for real from frame 20 on.
        if k >= 20 {
            for ch in 0..3 {
                maps[ch] = base[ch] + 1.0;
            }
        }
        t.steady_maps(crop, (l, &mut maps), None);
        for (p, (a, b)) in maps.iter().zip(&base).enumerate().skip(3) {
            assert!(a.is_finite(), "pixel {p}");
            if k > 5 {
                worst_tremor = worst_tremor.max((a - b).abs());
            }
        }
        // A real change keeps its sign, so its rate builds up at once: nearly half of it
        // on its first frame, three quarters by the second, 90 % by the third (a lag within
        // the two frames the filter may take).
        if let Some(least) = match k {
            20 => Some(0.45),
            21 => Some(0.75),
            22 => Some(0.9),
            _ => None,
        } {
            let got = maps[0] - base[0];
            assert!(
                got > least,
                "a real change of 1.0 came through as {got} on its frame {}",
                k - 19
            );
        }
    }
    assert!(
        worst_tremor < 0.0025,
        "a tremor of 0.005 came through as {worst_tremor}"
    );
}

#[test]
fn a_moved_crop_compares_the_same_place() {
    // The same scene seen through a crop shifted by a quarter of the map: after the
    // resampling the maps agree, so nothing is taken as motion and the blend keeps them.
    let mut t = Temporal::new(TemporalSettings::default());
    let l = MapLayout {
        channels: 1,
        size: 33,
        interleaved: false,
    };
    // A field over input NDC: f(x, y) = x + 2y, sampled through a crop.
    let field = |c: Crop| -> Vec<f32> {
        (0..l.size * l.size)
            .map(|p| {
                let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (l.size - 1) as f32;
                let (ux, uy) = (ndc(p % l.size), ndc(p / l.size));
                (c.s * ux + c.tx) + 2.0 * (c.s * uy + c.ty)
            })
            .collect()
    };
    let mut m = box_mask(100, 150, 40, 220, 0.95);
    let c0 = crop_of(&m);
    let crop0 = t.steady_input(0.0, 1, &mut m, c0).0.unwrap();
    t.steady_maps(crop0, (l, &mut field(crop0)), None);
    let mut m = box_mask(104, 154, 40, 220, 0.95);
    let c1 = crop_of(&m);
    let crop1 = t.steady_input(1.0 / 30.0, 1, &mut m, c1).0.unwrap();
    assert!(crop1.tx > crop0.tx, "the crop follows the person");
    let truth = field(crop1);
    let mut maps = truth.clone();
    t.steady_maps(crop1, (l, &mut maps), None);
    let worst = maps
        .iter()
        .zip(&truth)
        .map(|(a, b)| (*a as f64 - *b as f64).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-4, "resampled maps differ by {worst}");
}

fn shape_and_colour_layouts() -> (MapLayout, MapLayout) {
    (
        MapLayout {
            channels: 3,
            size: 16,
            interleaved: true,
        },
        MapLayout {
            channels: 2,
            size: 8,
            interleaved: false,
        },
    )
}

#[test]
fn colour_features_of_another_size_are_steadied_too() {
    // The Fourier maps are 128 px, the colour features 64: the colour takes the shape
    // map's weights at its own pixels.
    let mut t = Temporal::new(TemporalSettings::default());
    let (sl, cl) = shape_and_colour_layouts();
    let mut m = box_mask(100, 150, 40, 220, 0.95);
    let c = crop_of(&m);
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    for k in 0..90 {
        let mut m2 = m.clone();
        let crop = t.steady_input(k as f64 / 30.0, 1, &mut m2, c).0.unwrap();
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        let mut shape = vec![0.5f32; sl.len()];
        let mut color: Vec<f32> = vec![0.4 + sign * 0.01; cl.len()];
        t.steady_maps(crop, (sl, &mut shape), Some((cl, &mut color)));
        // Past the filter's time constant (~0.5 s): only the tremor's residue is left.
        if k >= 60 {
            lo = color.iter().copied().fold(lo, f32::min);
            hi = color.iter().copied().fold(hi, f32::max);
        }
    }
    m.clear();
    let worst = hi - lo;
    assert!(
        worst < 0.004,
        "a colour tremor of 0.02 (peak to peak) came through as {worst}"
    );
}

#[test]
fn colour_features_that_pause_start_again_without_the_shape_maps() {
    // The camera's own view runs no colour encoder: frames without colour features keep
    // the shape maps' filter going, and the features, when the view turns again, start
    // from their own frame.
    let mut t = Temporal::new(TemporalSettings::default());
    let (sl, cl) = shape_and_colour_layouts();
    let m = box_mask(100, 150, 40, 220, 0.95);
    let c = crop_of(&m);
    for k in 0..80 {
        let mut m2 = m.clone();
        let crop = t.steady_input(k as f64 / 30.0, 1, &mut m2, c).0.unwrap();
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        let mut shape = vec![0.5 + sign * 0.01; sl.len()];
        let raw_color: Vec<f32> = vec![0.4 + sign * 0.01; cl.len()];
        let mut color = raw_color.clone();
        // Colour on frames 0..20 and from 40 on; none on 20..40 (the camera's view).
        let with_color = !(20..40).contains(&k);
        t.steady_maps(
            crop,
            (sl, &mut shape),
            with_color.then_some((cl, &mut color[..])),
        );
        if k >= 10 {
            // The shape maps' filter never starts again: the tremor stays averaged out,
            // on the frames without colour and when it comes back.
            let worst = shape.iter().map(|v| (v - 0.5).abs()).fold(0.0f32, f32::max);
            assert!(
                worst < 0.005,
                "frame {k}: shape tremor of 0.01 came through as {worst}"
            );
        }
        if k == 40 {
            assert_eq!(
                color, raw_color,
                "the first colour frame back passes as it came"
            );
        }
        // A second after it came back (the filter's time constant is ~0.5 s).
        if k >= 70 {
            let worst = color.iter().map(|v| (v - 0.4).abs()).fold(0.0f32, f32::max);
            assert!(
                worst < 0.005,
                "frame {k}: colour tremor of 0.01 came through as {worst}"
            );
        }
    }
}

#[test]
fn a_person_moving_as_a_whole_is_followed_everywhere() {
    // The box moves 8 px a frame (a person walking across): the crop filter opens, and its
    // weight is the maps' floor, so a change that tremor-like alternation would have had
    // averaged away passes nearly whole once the motion is under way.
    let mut t = Temporal::new(TemporalSettings::default());
    let l = MapLayout {
        channels: 2,
        size: 8,
        interleaved: true,
    };
    let mut last_gain = 0.0f32;
    for k in 0..12usize {
        let x0 = 40 + 8 * k;
        let mut m = box_mask(x0, x0 + 50, 40, 220, 0.95);
        let c = crop_of(&m);
        let crop = t.steady_input(k as f64 / 30.0, 1, &mut m, c).0.unwrap();
        let v = if k % 2 == 0 { 0.5 } else { 0.6 };
        let mut maps = vec![v; l.len()];
        t.steady_maps(crop, (l, &mut maps), None);
        assert!(
            maps.iter()
                .all(|x| x.is_finite() && (0.5..=0.6).contains(x))
        );
        if k > 0 {
            // Share of this frame's step (0.1 either way) that reached the output.
            last_gain = 1.0 - (maps[0] - v).abs() / 0.1;
        }
    }
    assert!(
        last_gain > 0.75,
        "a person moving as a whole: only {last_gain} of the maps' change passed"
    );
}
