//! `Models::person_mask` with `segment_passes` 2 (the daemon's `[model] segment_passes`):
//! the person's crop is segmented again and taken back into the frame. On simulated people
//! whose arms are away from the body it keeps more of the true person than one pass, it
//! never loses what the first pass kept, and on frames without a person it stays finite and
//! counts the same people.
//!
//! `Models::prepare_tracked` with a `SegmentTrack` (the daemon's `[model]
//! segment_full_every`): between whole frames only the last frame's person's crop is
//! segmented. On a walking person the tracked frames keep the two-pass mask (against the
//! simulator's true mask), the whole frame comes back on schedule, a person who left the
//! crop is found in the whole frame and tracked from there, a person filling the frame is
//! segmented in the whole frame (their crop would magnify nothing), and a frame without a
//! person starts the track over.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use volcap_engine::model::preprocess::{INPUT_SIZE, keep_most_prominent, letterbox};
use volcap_engine::model::{FrameInfo, Models, Precision, SegmentTrack, Tracked};
use volcap_sim::pose::Style;
use volcap_sim::scene::Scene;
use volcap_sim::{HumanAssets, Simulator};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

const SUBJECTS: [&str; 2] = [
    "[[subject]]\nid = \"a\"\ngender = 0.8\nmuscle = 0.5\nweight = 0.5\nheight = 0.5\noutfit = \"male_casualsuit02\"\nhair = \"short02\"\nshoes = \"shoes01\"\n",
    "[[subject]]\nid = \"b\"\ngender = 0.1\nmuscle = 0.4\nweight = 0.6\nheight = 0.4\noutfit = \"female_casualsuit01\"\nhair = \"bob02\"\nshoes = \"shoes02\"\n",
];

/// Both masks of one frame and its true person mask, all `[S, S]`.
struct Masks {
    one: Vec<f32>,
    two: Vec<f32>,
    truth: Vec<bool>,
}

fn masks(models: &mut Models, scene_text: &str, yaw: f32) -> Masks {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let scene = Scene::parse(scene_text, Path::new("case.toml")).unwrap();
    let mut sim = Simulator::new(scene, assets).unwrap();
    sim.set_view_yaw(yaw);
    let f = sim.render(24).unwrap();
    let s = INPUT_SIZE;
    assert_eq!((f.width, f.height), (s, s), "the letterbox is the identity");
    let img = letterbox(&f.rgb, s, s);
    models.segment_passes = 1;
    let (one, p1) = models.person_mask(&img).unwrap();
    models.segment_passes = 2;
    let (two, p2) = models.person_mask(&img).unwrap();
    assert_eq!(p1, p2, "the people are the first pass's");
    Masks {
        one,
        two,
        truth: f.person_mask().iter().map(|&m| m > 127).collect(),
    }
}

fn iou(m: &[f32], truth: &[bool]) -> f64 {
    volcap_engine::metrics::mask_iou(m.iter().zip(truth).map(|(&v, &t)| (v > 0.5, t)))
}

#[test]
fn the_second_pass_keeps_more_of_the_person_and_nothing_less() {
    let mut models = Models::load(&repo().join("models"), "fourier-small", Precision::F32)
        .expect("committed models load");
    let (mut iou1, mut iou2, mut frames) = (0.0, 0.0, 0);
    let (mut missed1, mut missed2) = (0usize, 0usize);
    for (k, subject) in SUBJECTS.iter().enumerate() {
        for (style, yaw) in Style::ALL
            .iter()
            .zip([30.0, 200.0, 120.0, 300.0, 75.0, 160.0])
        {
            let text = volcap_sim::dataset::scene_text(INPUT_SIZE, subject, *style, 7 + k as u32);
            let m = masks(&mut models, &text, yaw);
            for (i, (&a, &b)) in m.one.iter().zip(&m.two).enumerate() {
                assert!(a.is_finite() && b.is_finite() && (0.0..=1.0).contains(&b));
                // The larger value of the two passes: what the first kept stays.
                assert!(
                    b >= a - 1e-6,
                    "pixel {i}: one pass {a}, two passes {b} ({} yaw {yaw})",
                    style.name()
                );
            }
            let missed = |mask: &[f32]| {
                mask.iter()
                    .zip(&m.truth)
                    .filter(|(v, t)| **v <= 0.5 && **t)
                    .count()
            };
            missed1 += missed(&m.one);
            missed2 += missed(&m.two);
            println!(
                "{} yaw {yaw}: IoU {:.4} -> {:.4}",
                style.name(),
                iou(&m.one, &m.truth),
                iou(&m.two, &m.truth)
            );
            iou1 += iou(&m.one, &m.truth);
            iou2 += iou(&m.two, &m.truth);
            frames += 1;
        }
    }
    let (iou1, iou2) = (iou1 / frames as f64, iou2 / frames as f64);
    println!(
        "mask IoU against the truth: one pass {iou1:.4}, two {iou2:.4}; person pixels missed {missed1} -> {missed2}"
    );
    // What the second pass is for: the person pixels the first misses (on 336 held-out
    // renders 291 -> 109 a frame, docs/eval/hands.md section 8), at a few more pixels taken
    // that are not the person's (427 -> 568), so the IoU moves little either way.
    assert!(
        missed2 * 3 <= missed1 * 2,
        "the second pass finds a third of the missed pixels: {missed1} -> {missed2}"
    );
    assert!(iou2 >= iou1 - 0.01, "IoU {iou1} -> {iou2}");
}

#[test]
fn frames_without_a_person_stay_finite_with_two_passes() {
    let mut models = Models::load(&repo().join("models"), "fourier-small", Precision::F32)
        .expect("committed models load");
    let s = INPUT_SIZE;
    let noise: Vec<u8> = (0..s * s * 3)
        .map(|i| ((i * 2654435761usize) >> 9) as u8)
        .collect();
    for (what, rgb) in [
        ("black", vec![0u8; s * s * 3]),
        ("white", vec![255u8; s * s * 3]),
        ("noise", noise),
    ] {
        let img = letterbox(&rgb, s, s);
        models.segment_passes = 1;
        let (one, p1) = models.person_mask(&img).unwrap();
        models.segment_passes = 2;
        let (two, p2) = models.person_mask(&img).unwrap();
        assert_eq!(p1, p2, "{what}");
        assert!(
            two.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
            "{what}"
        );
        if p1 == 0 {
            assert_eq!(one, two, "{what}: no person, no crop, no second pass");
        }
    }
}

fn models() -> Models {
    let mut m = Models::load(&repo().join("models"), "fourier-small-seg2", Precision::F32)
        .expect("committed models load");
    m.segment_passes = 2;
    m
}

/// A scene's frames `0..n`: RGB, size and the true person mask letterboxed as the networks
/// see it.
struct Frame {
    rgb: Vec<u8>,
    w: usize,
    h: usize,
    truth: Vec<bool>,
}

fn frames(text: &str, n: u64) -> Vec<Frame> {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let scene = Scene::parse(text, Path::new("case.toml")).unwrap();
    let mut sim = Simulator::new(scene, assets).unwrap();
    (0..n)
        .map(|i| {
            let f = sim.render(i).unwrap();
            let truth_rgb: Vec<u8> = f.person_mask().iter().flat_map(|&m| [m; 3]).collect();
            let truth = letterbox(&truth_rgb, f.width, f.height);
            Frame {
                truth: truth[..INPUT_SIZE * INPUT_SIZE]
                    .iter()
                    .map(|&v| v > 0.5)
                    .collect(),
                rgb: f.rgb,
                w: f.width,
                h: f.height,
            }
        })
        .collect()
}

fn walker(x: f32) -> String {
    format!(
        "frames = 30\n[camera]\nwidth = 320\nheight = 240\nfps = 30\nheight_m = 2.1\nlook_at = [0.0, 0.9, 0.0]\n\
         [[subject]]\nid = \"w\"\ngender = 1.0\noutfit = \"male_casualsuit02\"\nshoes = \"shoes01\"\n\
         hair = \"short02\"\nposition = [{x}, 0.0, 0.0]\n\
         motion = {{ kind = \"procedural\", style = \"walk\", seed = 3, period = 1.1 }}\n"
    )
}

#[test]
fn a_walking_person_is_tracked_in_the_crop_and_keeps_the_two_pass_mask() {
    let models = models();
    let frames = frames(&walker(0.0), 17);
    let mut track = SegmentTrack::new(8);
    let (mut iou_whole, mut iou_tracked, mut hows) = (0.0, 0.0, Vec::new());
    for (i, f) in frames.iter().enumerate() {
        let mut info = FrameInfo::default();
        let (_, mask, _) = models
            .prepare_tracked(&f.rgb, f.w, f.h, &mut info, Some(&mut track))
            .unwrap();
        let mut whole_info = FrameInfo::default();
        let (_, whole, _) = models.prepare(&f.rgb, f.w, f.h, &mut whole_info).unwrap();
        assert_eq!(whole_info.tracked, Tracked::Off);
        assert!(
            mask.iter()
                .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
        );
        assert_eq!(info.people, 1, "frame {i}: the last whole frame's count");
        let (a, b) = (iou(&whole, &f.truth), iou(&mask, &f.truth));
        println!(
            "frame {i}: {:?}, mask IoU whole {a:.4}, tracked {b:.4}",
            info.tracked
        );
        if i == 0 {
            assert_eq!(mask, whole, "the track's first frame is the untracked path");
        }
        iou_whole += a;
        iou_tracked += b;
        hows.push(info.tracked);
    }
    // The schedule: whole at 0, 8 and 16 (the last two keeping the crop's mask: the person
    // stays inside it), the crop alone between (none lost: the person walks in place, well
    // inside the crop's margin).
    for (i, how) in hows.iter().enumerate() {
        let want = if i % 8 == 0 {
            Tracked::Full
        } else {
            Tracked::Crop
        };
        assert_eq!(*how, want, "frame {i}: {hows:?}");
    }
    let n = frames.len() as f64;
    let (iou_whole, iou_tracked) = (iou_whole / n, iou_tracked / n);
    println!("mean mask IoU: whole frames {iou_whole:.4}, tracked {iou_tracked:.4}");
    assert!(
        iou_tracked >= iou_whole - 0.01,
        "{iou_whole} -> {iou_tracked}"
    );
}

#[test]
fn a_person_who_left_the_crop_is_found_in_the_whole_frame_and_a_person_gone_restarts_the_track() {
    let models = models();
    let left = frames(&walker(-0.5), 1);
    let right = frames(&walker(0.5), 1);
    let mut track = SegmentTrack::new(8);
    let mut info = FrameInfo::default();
    models
        .prepare_tracked(
            &left[0].rgb,
            left[0].w,
            left[0].h,
            &mut info,
            Some(&mut track),
        )
        .unwrap();
    assert_eq!(info.tracked, Tracked::Full);
    let held = track
        .next_crop()
        .expect("the track holds the person's crop");
    // The person is now a metre to the right: the old crop does not hold them.
    let f = &right[0];
    let mut info = FrameInfo::default();
    let (_, mask, _) = models
        .prepare_tracked(&f.rgb, f.w, f.h, &mut info, Some(&mut track))
        .unwrap();
    assert_eq!(info.tracked, Tracked::Lost);
    assert_eq!(info.people, 1);
    let (_, whole, _) = models
        .prepare(&f.rgb, f.w, f.h, &mut FrameInfo::default())
        .unwrap();
    let (lost_iou, whole_iou) = (iou(&mask, &f.truth), iou(&whole, &f.truth));
    println!("mask IoU: the lost frame {lost_iou:.4}, untracked {whole_iou:.4}");
    assert!(lost_iou >= whole_iou - 0.05, "{lost_iou} vs {whole_iou}");
    let next = track.next_crop().expect("the track follows the person");
    assert!(
        next.tx > held.tx + 0.2,
        "the track moved right: {held:?} -> {next:?}"
    );
    // The next frame is tracked again, as good as the two passes.
    let mut info = FrameInfo::default();
    let (_, mask, _) = models
        .prepare_tracked(&f.rgb, f.w, f.h, &mut info, Some(&mut track))
        .unwrap();
    assert_eq!(info.tracked, Tracked::Crop);
    assert!(iou(&mask, &f.truth) >= whole_iou - 0.01);
    // A black frame: no person, and the next frame is segmented whole.
    let s = INPUT_SIZE;
    let black = vec![0u8; s * s * 3];
    let r = models.prepare_tracked(&black, s, s, &mut FrameInfo::default(), Some(&mut track));
    assert!(r.is_err(), "no person in a black frame");
    assert_eq!(track.next_crop(), None);
    let mut info = FrameInfo::default();
    let (_, mask, _) = models
        .prepare_tracked(&f.rgb, f.w, f.h, &mut info, Some(&mut track))
        .unwrap();
    assert_eq!(info.tracked, Tracked::Full);
    assert_eq!(mask, whole, "a whole frame is the untracked path");
}

/// A person filling the frame (the main job's walker: a crop larger than the frame): the
/// tracked frames segment the whole frame once, their mask the first pass's, and keep the
/// person's count; a frame of another size than the track's last is segmented whole.
#[test]
fn a_person_filling_the_frame_is_tracked_in_the_whole_frame() {
    let models = models();
    let text = std::fs::read_to_string(repo().join("tests/scenes/front-walk.toml")).unwrap();
    let frames = frames(&text, 3);
    let mut track = SegmentTrack::new(8);
    // The track starts on another camera's smaller frame: the first frame of this one is
    // segmented whole all the same.
    let small = &self::frames(&walker(0.0), 1)[0];
    models
        .prepare_tracked(
            &small.rgb,
            small.w,
            small.h,
            &mut FrameInfo::default(),
            Some(&mut track),
        )
        .unwrap();
    assert!(track.next_crop().is_some());
    for (i, f) in frames.iter().enumerate() {
        let mut info = FrameInfo::default();
        let (img, mask, crop) = models
            .prepare_tracked(&f.rgb, f.w, f.h, &mut info, Some(&mut track))
            .unwrap();
        assert_eq!(info.people, 1);
        if i == 0 {
            assert_eq!(info.tracked, Tracked::Full);
            assert!(crop.s >= 1.0, "the walker fills the frame: {crop:?}");
            continue;
        }
        assert_eq!(info.tracked, Tracked::Crop, "frame {i}");
        let mut one = models.segment(&img).unwrap();
        keep_most_prominent(&mut one, INPUT_SIZE);
        assert!(mask == one, "frame {i}: not the whole frame's single pass");
        assert!(iou(&mask, &f.truth) > 0.85, "frame {i}");
    }
}

#[test]
fn one_pass_or_full_every_1_is_the_untracked_path() {
    let mut models = models();
    let f = &frames(&walker(0.0), 1)[0];
    for (passes, full_every) in [(2u8, 1u32), (1, 8)] {
        models.segment_passes = passes;
        let mut track = SegmentTrack::new(full_every);
        for _ in 0..3 {
            let mut info = FrameInfo::default();
            let (_, mask, _) = models
                .prepare_tracked(&f.rgb, f.w, f.h, &mut info, Some(&mut track))
                .unwrap();
            let (_, whole, _) = models
                .prepare(&f.rgb, f.w, f.h, &mut FrameInfo::default())
                .unwrap();
            assert_eq!(
                info.tracked,
                Tracked::Off,
                "passes {passes}, every {full_every}"
            );
            assert_eq!(mask, whole);
            assert_eq!(track.next_crop(), None);
        }
    }
}
