//! `Models::prepare_tracked` with a `SegmentTrack` (the daemon's `[model]
//! segment_full_every`): between whole frames only the last frame's person's crop is
//! segmented. On a walking person the tracked frames keep the two-pass mask (against the
//! simulator's true mask), the whole frame comes back on schedule, a person who left the
//! crop is found in the whole frame and tracked from there, and a frame without a person
//! starts the track over.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use volcap_engine::model::preprocess::{INPUT_SIZE, letterbox};
use volcap_engine::model::{FrameInfo, Models, Precision, SegmentTrack, Tracked};
use volcap_sim::scene::Scene;
use volcap_sim::{HumanAssets, Simulator};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
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

fn iou(m: &[f32], truth: &[bool]) -> f64 {
    let (mut i, mut u) = (0usize, 0usize);
    for (&v, &t) in m.iter().zip(truth) {
        i += (v > 0.5 && t) as usize;
        u += (v > 0.5 || t) as usize;
    }
    i as f64 / u.max(1) as f64
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
