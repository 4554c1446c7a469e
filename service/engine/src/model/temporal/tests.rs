use super::*;

const S: usize = 256;

fn box_mask(x0: usize, x1: usize, y0: usize, y1: usize, v: f32) -> Vec<f32> {
    let mut m = vec![0.0f32; S * S];
    for y in y0..y1 {
        for x in x0..x1 {
            m[y * S + x] = v;
        }
    }
    m
}

fn crop_of(m: &[f32]) -> Crop {
    Crop::from_mask(m, S).unwrap()
}

#[test]
fn one_euro_holds_still_noise_and_follows_a_ramp() {
    // f64 reference of a slow filter: still noise of +-0.01 shrinks; a ramp at 1/s is
    // followed with a lag below 2 frames at 30 fps.
    let (dt, mut f) = (1.0 / 30.0, OneEuro::default());
    let mut spread = 0.0f64;
    for i in 0..300 {
        let x = if i % 2 == 0 { 0.01 } else { -0.01 };
        let y = f.filter(x, dt, 1.0, 40.0) as f64;
        if i > 30 {
            spread = spread.max(y.abs());
        }
    }
    assert!(spread < 0.004, "still noise 0.01 came through as {spread}");
    let mut f = OneEuro::default();
    let mut y = 0.0;
    for i in 0..60 {
        y = f.filter(i as f32 * dt, dt, 1.0, 40.0);
    }
    let lag = (59.0 * dt - y) / dt;
    assert!(lag < 2.0, "a ramp lags {lag} frames");
}

#[test]
fn flickering_edge_pixels_hold_and_a_real_change_passes() {
    let mut t = Temporal::new(TemporalSettings::default());
    let mut m = box_mask(100, 150, 40, 220, 0.95);
    for y in 40..220 {
        m[y * S + 150] = 0.45;
    }
    let c = crop_of(&m);
    t.steady_input(0.0, 1, &mut m, c);
    // An edge column trembles between 0.45 and 0.55 (inside the band, a small change
    // each frame): it keeps its first state (off).
    for k in 1..20 {
        let mut m = box_mask(100, 150, 40, 220, 0.95);
        let v = if k % 2 == 0 { 0.45 } else { 0.55 };
        for y in 40..220 {
            m[y * S + 150] = v;
        }
        let c = crop_of(&m);
        let (crop, step) = t.steady_input(k as f64 / 30.0, 1, &mut m, c);
        assert_eq!(step, Step::Continued);
        assert!(m[100 * S + 150] <= 0.5, "flickering pixel turned on at {k}");
        assert!(crop.unwrap().s.is_finite());
    }
    let mut m = box_mask(100, 160, 40, 220, 0.95);
    let c = crop_of(&m);
    t.steady_input(20.0 / 30.0, 1, &mut m, c);
    assert_eq!(
        m[100 * S + 155],
        0.95,
        "a confident new pixel is taken at once"
    );
    // An edge that moves (four columns from 0 to 0.7: inside the band, but a band of
    // changed pixels, not scattered ones) follows at once too.
    let mut m = box_mask(100, 160, 40, 220, 0.95);
    for y in 40..220 {
        for x in 160..166 {
            m[y * S + x] = 0.7;
        }
    }
    let c = crop_of(&m);
    t.steady_input(21.0 / 30.0, 1, &mut m, c);
    assert_eq!(m[100 * S + 165], 0.7, "a moving edge is not held");
}

#[test]
fn a_slow_change_inside_the_band_is_followed_after_the_hold() {
    // An edge column that crosses 0.5 and stays (an arm near the top of its swing: too
    // few pixels for a moving block, never out of the band) is held for
    // `mask_hold_frames - 1` frames, then followed; it is not held back for good. While
    // the crop given out stays put (a person still as a whole), for
    // `mask_still_hold_frames - 1` frames.
    let settings = TemporalSettings::default();
    let (hold, still_hold) = (
        settings.mask_hold_frames as usize,
        settings.mask_still_hold_frames as usize,
    );
    assert!(
        hold >= 2 && still_hold > hold + 1,
        "the test needs holds of two frames or more, the still one longer"
    );
    let column = |v: f32| {
        let mut m = box_mask(100, 150, 40, 220, 0.95);
        for y in 40..220 {
            m[y * S + 150] = v;
        }
        m
    };
    for crop_moves in [false, true] {
        let mut t = Temporal::new(settings);
        let mut m = column(0.4);
        let c = crop_of(&m);
        // A crop moving by a tenth of its size a frame: the play never holds it.
        let crop = |k: usize| Crop {
            tx: c.tx + if crop_moves { 0.1 * k as f32 } else { 0.0 },
            ..c
        };
        // Two frames on the old side: the crop given out twice (still, or moved).
        for k in 0..2 {
            let mut m = column(0.4);
            t.steady_input(k as f64 / 30.0, 1, &mut m, crop(k));
        }
        let want = if crop_moves { hold } else { still_hold };
        for k in 1..=still_hold + 2 {
            m = column(0.6);
            let (_, step) = t.steady_input((k + 1) as f64 / 30.0, 1, &mut m, crop(k + 1));
            assert_eq!(step, Step::Continued);
            let shown = m[100 * S + 150];
            let what = format!("crop moving {crop_moves}, frame {k}");
            if k < want {
                assert_eq!(shown, 0.4, "{what}: held");
            } else {
                assert_eq!(shown, 0.6, "{what}: followed after {want} frames");
            }
        }
    }
}

#[test]
fn a_slow_edge_inside_a_still_crop_trails_by_at_most_the_band() {
    // What `mask_still_hold_frames` can hold back: a part drifting slowly while the crop
    // stays put (here the crop is given, fixed), too slowly for a moving block (a quarter
    // of a pixel or half a pixel a frame: 4 or 8 of a block's 256 pixels flip), its edge a soft ramp 12 pixels
    // wide. A pixel the edge passes over is taken once the segmenter puts it beyond the
    // band (0.8 growing, 0.2 shrinking), or after the hold: so the edge given out trails
    // the segmenter's 0.5 contour by at most the ramp's distance from 0.5 to the band's
    // edge (0.3 x 12 = 3.6 px, whatever the hold), and stands on it within the hold once
    // the part stops. Growing and shrinking, both holds.
    let settings = TemporalSettings::default();
    let (hi, lo) = (settings.mask_high, settings.mask_low);
    let w = 12.0f32;
    let frames = 120usize;
    // Person on the left of the edge at `e` (x in pixels); rows 40..220.
    let mask = |e: f32| {
        let mut m = vec![0.0f32; S * S];
        for y in 40..220 {
            for x in 60..S {
                m[y * S + x] = (0.5 + (e - x as f32) / w).clamp(0.0, 1.0);
            }
        }
        m
    };
    // The first column given out off the person on row 100, with the edge in sub-pixels.
    let edge_out = |m: &[f32]| (60..S).find(|&x| m[100 * S + x] <= 0.5).unwrap_or(S) as f32;
    let edge_raw = |e: f32| edge_out(&mask(e));
    // (hold, growing, pixels a frame): the default hold where the edge outruns it (0.5 px
    // a frame: 4.5 px in nine frames, the band's 3.6 sooner); holds of 30 frames, whose
    // trail only the band bounds; the moving person's hold.
    let cases = [
        (settings.mask_still_hold_frames, true, 0.5f32),
        (30, true, 0.25),
        (30, false, 0.25),
        (2, true, 0.25),
    ];
    for (still_hold, grow, speed) in cases {
        let s = TemporalSettings {
            mask_still_hold_frames: still_hold,
            ..settings
        };
        let mut t = Temporal::new(s);
        let e0 = if grow { 120.0 } else { 160.0 };
        let crop = crop_of(&mask(e0));
        let dir = if grow { 1.0 } else { -1.0 };
        let bound = (hi - 0.5).max(0.5 - lo) * w + 1.0;
        let mut worst = 0.0f32;
        let mut e = e0;
        for k in 0..frames + still_hold as usize + 2 {
            if k > 0 && k <= frames {
                e += dir * speed;
            }
            let mut m = mask(e);
            let (_, step) = t.steady_input(k as f64 / 30.0, 1, &mut m, crop);
            let want = if k == 0 {
                Step::Reset(ResetCause::First)
            } else {
                Step::Continued
            };
            assert_eq!(step, want, "frame {k}");
            let trail = dir * (edge_raw(e) - edge_out(&m));
            let what = format!("hold {still_hold}, growing {grow}, frame {k}");
            assert!(
                trail >= 0.0,
                "{what}: the edge given out ran ahead by {trail}"
            );
            assert!(
                trail <= bound,
                "{what}: trails by {trail} px (bound {bound})"
            );
            worst = worst.max(trail);
            if k == frames + still_hold as usize + 1 {
                assert_eq!(
                    trail, 0.0,
                    "{what}: not on the contour after the part stopped"
                );
            }
        }
        println!(
            "hold {still_hold}, growing {grow}, {speed} px a frame: trails by up to {worst} px"
        );
        assert!(
            worst >= 1.0,
            "hold {still_hold}: the case holds nothing back"
        );
    }
}

#[test]
fn another_person_or_a_gap_starts_again() {
    let mut t = Temporal::new(TemporalSettings::default());
    let mut a = box_mask(20, 60, 40, 220, 0.9);
    let ca = crop_of(&a);
    t.steady_input(0.0, 1, &mut a, ca);
    let mut a = box_mask(20, 60, 40, 220, 0.9);
    assert_eq!(t.steady_input(0.033, 1, &mut a, ca).1, Step::Continued);
    // One leaves and another enters at the other side: never blended.
    let mut b = box_mask(180, 230, 40, 220, 0.9);
    let cb = crop_of(&b);
    let (crop, step) = t.steady_input(0.066, 1, &mut b, cb);
    assert_eq!(step, Step::Reset(ResetCause::NewPerson));
    assert_eq!(crop.unwrap(), cb, "the new person's own crop, unfiltered");
    let mut b = box_mask(180, 230, 40, 220, 0.9);
    assert_eq!(
        t.steady_input(2.0, 1, &mut b, cb).1,
        Step::Reset(ResetCause::Gap)
    );
    let mut b = box_mask(180, 230, 40, 220, 0.9);
    assert_eq!(
        t.steady_input(2.033, 2, &mut b, cb).1,
        Step::Reset(ResetCause::PeopleCount)
    );
    let mut b = box_mask(180, 230, 40, 220, 0.9);
    let cut = Crop {
        cut_by_frame: true,
        ..cb
    };
    assert_eq!(
        t.steady_input(2.066, 2, &mut b, cut).1,
        Step::Reset(ResetCause::CloseRange)
    );
}

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

#[test]
fn nothing_non_finite_comes_out_and_bad_settings_are_named() {
    let mut t = Temporal::new(TemporalSettings::default());
    let l = MapLayout {
        channels: 2,
        size: 8,
        interleaved: true,
    };
    for k in 0..12 {
        let v = match k % 4 {
            0 => 1.0,
            1 => 0.0,
            2 => f32::NAN,
            _ => 0.5,
        };
        let mut m = vec![v; S * S];
        let raw = Crop {
            s: 1.0,
            tx: 0.0,
            ty: 0.0,
            cut_by_frame: false,
        };
        let (crop, _) = t.steady_input(k as f64 / 30.0, 1, &mut m, raw);
        if let Some(c) = crop {
            assert!(c.s.is_finite() && c.tx.is_finite() && c.ty.is_finite());
            let mut maps = vec![if k % 3 == 0 { f32::INFINITY } else { 1e30 }; l.len()];
            t.steady_maps(c, (l, &mut maps), None);
        }
    }
    let bad = TemporalSettings {
        mask_low: 0.7,
        ..Default::default()
    };
    let (key, msg) = bad.check().unwrap_err();
    assert!(key == "mask_low" && msg.contains("mask_low = 0.7"), "{msg}");
    let bad = TemporalSettings {
        map_beta: f32::NAN,
        ..Default::default()
    };
    assert_eq!(bad.check().unwrap_err().0, "map_beta");
    let bad = TemporalSettings {
        crop_hold: 0.5,
        ..Default::default()
    };
    let (key, msg) = bad.check().unwrap_err();
    assert!(
        key == "crop_hold" && msg.contains("crop_hold = 0.5"),
        "{msg}"
    );
    let bad = TemporalSettings {
        surface_dead_band: 0.3,
        ..Default::default()
    };
    let (key, msg) = bad.check().unwrap_err();
    assert!(
        key == "surface_dead_band" && msg.contains("surface_dead_band = 0.3"),
        "{msg}"
    );
    assert!(TemporalSettings::default().check().is_ok());
}

/// Fourier-like shape maps (interleaved, 16 px) and colour features of half their size
/// (planar, 8 px), as the models' 128 and 64.
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

#[test]
fn a_still_crop_holds_and_a_moving_one_trails_by_the_play() {
    // The backlash alone: within the play nothing moves, beyond it the crop trails by the
    // play, `to`'s flag is kept, a held crop that is not finite gives way.
    let held = Crop {
        s: 1.0,
        tx: 0.0,
        ty: 0.0,
        cut_by_frame: false,
    };
    let to = Crop {
        s: 1.002,
        tx: 0.003,
        ty: -0.01,
        cut_by_frame: true,
    };
    let b = backlash(held, to, 0.004);
    let play = 0.004 * 1.002f64;
    assert_eq!((b.tx, b.s, b.cut_by_frame), (0.0, 1.0, true));
    assert!((b.ty as f64 - (-0.01 + play)).abs() < 1e-6, "{b:?}");
    assert_eq!(backlash(held, to, 0.0), to);
    assert_eq!(
        backlash(
            Crop {
                tx: f32::NAN,
                ..held
            },
            to,
            0.004
        )
        .tx,
        to.tx
    );

    // A still person whose box's right edge jitters by a pixel: with the play the crop
    // given out stops moving once the filter settles; without it, it wanders.
    let run = |hold: f32, moving: bool| -> Vec<Crop> {
        let settings = TemporalSettings {
            crop_hold: hold,
            ..TemporalSettings::default()
        };
        let mut t = Temporal::new(settings);
        (0..90usize)
            .map(|k| {
                let (x0, x1) = if moving {
                    (40 + k, 92 + k)
                } else {
                    (40, 150 + k % 2)
                };
                let mut m = box_mask(x0, x1, 40, 220, 0.95);
                let c = crop_of(&m);
                t.steady_input(k as f64 / 30.0, 1, &mut m, c).0.unwrap()
            })
            .collect()
    };
    let spread = |c: &[Crop]| {
        let (lo, hi) = c.iter().fold((f32::MAX, f32::MIN), |(lo, hi), c| {
            (lo.min(c.tx), hi.max(c.tx))
        });
        hi - lo
    };
    let held = run(TemporalSettings::default().crop_hold, false);
    assert_eq!(spread(&held[30..]), 0.0, "{:?}", &held[30..34]);
    let free = run(0.0, false);
    assert!(spread(&free[30..]) > 0.0);
    // Moving a pixel a frame: followed, never farther behind the free crop than the play.
    let (held, free) = (
        run(TemporalSettings::default().crop_hold, true),
        run(0.0, true),
    );
    assert!(
        held[89].tx - held[10].tx > 0.5,
        "{:?} -> {:?}",
        held[10],
        held[89]
    );
    for (h, f) in held.iter().zip(&free) {
        let play = TemporalSettings::default().crop_hold * f.s;
        assert!((h.tx - f.tx).abs() <= play + 1e-6, "{h:?} against {f:?}");
        assert!((h.s - f.s).abs() <= play + 1e-6);
    }
}

/// `mask_dead_band`: a still person's outline pixels that tremble on their side of 0.5
/// (0.6 <-> 0.7, 0.3 <-> 0.4) are given out exactly as on the first frame, so the mask's
/// 0.5 contour (the field's gate) does not slide; without the band they pass through; a
/// value leaving the band (0.6 -> 0.95) passes at once, and where a block of pixels changes
/// side (a raised arm) the new values pass on their first frame.
#[test]
fn the_mask_dead_band_holds_a_trembling_outline_and_lets_motion_through() {
    let edge = |inner: f32, outer: f32| {
        let mut m = box_mask(100, 150, 40, 220, 0.95);
        for y in 40..220 {
            m[y * S + 149] = inner;
            m[y * S + 150] = outer;
        }
        m
    };
    for dead in [0.0f32, 0.15] {
        let mut t = Temporal::new(TemporalSettings {
            mask_dead_band: dead,
            ..TemporalSettings::default()
        });
        let mut first = edge(0.6, 0.3);
        let c = crop_of(&first);
        t.steady_input(0.0, 1, &mut first, c);
        for k in 1..12 {
            let (inner, outer) = if k % 2 == 0 { (0.6, 0.3) } else { (0.7, 0.4) };
            let mut m = edge(inner, outer);
            t.steady_input(k as f64 / 30.0, 1, &mut m, c);
            let (got_in, got_out) = (m[100 * S + 149], m[100 * S + 150]);
            if dead > 0.0 {
                assert_eq!((got_in, got_out), (0.6, 0.3), "frame {k}: held");
                assert_eq!(m, first, "frame {k}: the whole mask as on the first frame");
            } else {
                assert_eq!((got_in, got_out), (inner, outer), "frame {k}: off");
            }
        }
        // A value leaving the band passes at once.
        let mut m = edge(0.95, 0.3);
        t.steady_input(12.0 / 30.0, 1, &mut m, c);
        assert_eq!(m[100 * S + 149], 0.95, "dead band {dead}");
        // A block of pixels changing side (an arm out of the body's side): followed, and
        // the pixels beside it that stay on their side but change (0.95 -> 0.9) with it.
        let mut m = edge(0.95, 0.3);
        for y in 60..120 {
            m[y * S + 149] = 0.9;
            for x in 150..170 {
                m[y * S + x] = 0.62;
            }
        }
        t.steady_input(13.0 / 30.0, 1, &mut m, c);
        assert_eq!(m[80 * S + 160], 0.62, "dead band {dead}: the arm");
        assert_eq!(m[80 * S + 149], 0.9, "dead band {dead}: beside the arm");
    }
}
