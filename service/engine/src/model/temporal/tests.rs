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

/// The shape maps' and colour features' filter (`steady_maps`).
mod maps;

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
