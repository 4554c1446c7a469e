//! `Models::person_mask` with `segment_passes` 2 (the daemon's `[model] segment_passes`):
//! the person's crop is segmented again and taken back into the frame. On simulated people
//! whose arms are away from the body it keeps more of the true person than one pass, it
//! never loses what the first pass kept, and on frames without a person it stays finite and
//! counts the same people.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use volcap_engine::model::preprocess::{INPUT_SIZE, letterbox};
use volcap_engine::model::{Models, Precision};
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
    let (mut i, mut u) = (0usize, 0usize);
    for (&v, &t) in m.iter().zip(truth) {
        i += (v > 0.5 && t) as usize;
        u += (v > 0.5 || t) as usize;
    }
    i as f64 / u.max(1) as f64
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
