//! Only declared effects run; removing an effect gives the pure render bit for bit; each
//! effect does what it says.

use std::path::Path;
use std::sync::{Arc, OnceLock};
use volcap_sim::effects::{self, FrameMeta, Hook, Image, Phase};
use volcap_sim::scene::{EffectSpec, Scene};
use volcap_sim::{HumanAssets, SimError, Simulator};

fn assets() -> Arc<HumanAssets> {
    static A: OnceLock<Arc<HumanAssets>> = OnceLock::new();
    A.get_or_init(|| Arc::new(HumanAssets::embedded().expect("embedded pack")))
        .clone()
}

const BASE: &str = r#"
[camera]
width = 128
height = 128
[[subject]]
id = "a"
outfit = "male_casualsuit02"
hair = "short02"
skin = "young_caucasian_male"
motion = { kind = "procedural", style = "walk", seed = 3 }
"#;

fn scene(extra: &str) -> Scene {
    Scene::parse(&format!("{BASE}\n{extra}"), Path::new("test.toml")).unwrap()
}

fn effect(kind: &str) -> String {
    let (_, body) = EXAMPLES.iter().find(|(k, _)| *k == kind).unwrap();
    format!("[[effect]]\n{body}\n")
}

const EXAMPLES: [(&str, &str); 11] = [
    (
        "sensor-noise",
        "sensor-noise = { shot = 0.05, read = 0.02 }",
    ),
    (
        "motion-blur",
        "motion-blur = { length_px = 7, angle_deg = 30 }",
    ),
    (
        "exposure-drift",
        "exposure-drift = { amplitude = 0.3, period_s = 0.5 }",
    ),
    (
        "white-balance-drift",
        "white-balance-drift = { amplitude = 0.3, period_s = 0.5 }",
    ),
    ("jpeg", "jpeg = { quality = 30 }"),
    ("rolling-shutter", "rolling-shutter = { skew_px = 9 }"),
    ("vignetting", "vignetting = { strength = 0.5 }"),
    (
        "occluder",
        "occluder = { center = [0.0, 1.0, 0.5], size = [0.4, 0.4, 0.1] }",
    ),
    ("camera-shake", "camera-shake = { amplitude_deg = 3 }"),
    ("unplug", "unplug = { at_frame = 2 }"),
    ("hang", "hang = { at_frame = 2 }"),
];

/// Effects that decide whether a frame arrives at all, rather than how it looks.
fn source_only(kind: &str) -> bool {
    kind == "unplug" || kind == "hang"
}

#[test]
fn examples_cover_every_effect_kind() {
    let mut kinds: Vec<&str> = EXAMPLES.iter().map(|e| e.0).collect();
    kinds.sort();
    let mut all = EffectSpec::KINDS.to_vec();
    all.sort();
    assert_eq!(kinds, all);
}

#[test]
fn only_declared_stages_are_invoked() {
    let mut sim = Simulator::new(scene(&effect("sensor-noise")), assets()).unwrap();
    for i in 0..3 {
        sim.render(i).unwrap();
    }
    let counts = sim.stage_invocations();
    assert_eq!(counts.len(), 1, "{counts:?}");
    assert_eq!(counts["sensor-noise"], 3);

    let mut pure = Simulator::new(scene(""), assets()).unwrap();
    pure.render(0).unwrap();
    assert!(pure.stage_invocations().is_empty());

    let all: String = EXAMPLES
        .iter()
        .filter(|e| !source_only(e.0))
        .map(|e| effect(e.0))
        .collect();
    let mut sim = Simulator::new(scene(&all), assets()).unwrap();
    sim.render(0).unwrap();
    for (k, _) in EXAMPLES.iter().filter(|e| !source_only(e.0)) {
        assert_eq!(sim.stage_invocations().get(k), Some(&1), "{k}");
    }
}

#[test]
fn removing_an_effect_gives_the_pure_render_bit_for_bit() {
    let mut pure = Simulator::new(scene(""), assets()).unwrap();
    let p = pure.render(1).unwrap();
    for (kind, _) in EXAMPLES.iter().filter(|e| !source_only(e.0)) {
        let with = scene(&effect(kind));
        let mut removed = Simulator::new(with.without_effects(), assets()).unwrap();
        let r = removed.render(1).unwrap();
        assert_eq!(r.rgb, p.rgb, "{kind}: removal changed the render");
        assert_eq!(r.ids, p.ids);
        assert_eq!(r.depth_m, p.depth_m);
        let mut on = Simulator::new(with, assets()).unwrap();
        let f = on.render(1).unwrap();
        assert_ne!(f.rgb, p.rgb, "{kind}: declared but changed nothing");
    }
}

fn grey_image(w: usize, h: usize, v: f32) -> Vec<[f32; 3]> {
    vec![[v; 3]; w * h]
}

fn apply(
    kind_toml: &str,
    index: u64,
    t: f64,
    rgb: &mut Vec<[f32; 3]>,
    w: usize,
    h: usize,
) -> FrameMeta {
    let s = Scene::parse(&format!("[[effect]]\n{kind_toml}\n"), Path::new("t.toml")).unwrap();
    let mut stages = effects::build(&s.effects);
    let mut meta = FrameMeta::default();
    for st in &mut stages {
        assert!(st.phase() > Phase::Geometry);
        let mut img = Image {
            width: w,
            height: h,
            rgb,
        };
        st.apply(index, t, Hook::Image(&mut img, &mut meta));
    }
    meta
}

#[test]
fn sensor_noise_has_the_declared_statistics() {
    let (w, h, x) = (256, 256, 0.5f32);
    let (shot, read) = (0.05f32, 0.02f32);
    let mut img = grey_image(w, h, x);
    apply(
        &format!("sensor-noise = {{ shot = {shot}, read = {read}, seed = 9 }}"),
        0,
        0.0,
        &mut img,
        w,
        h,
    );
    let vals: Vec<f64> = img.iter().flatten().map(|&v| v as f64).collect();
    let mean = vals.iter().sum::<f64>() / vals.len() as f64;
    let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / vals.len() as f64;
    let want = (shot * shot * x + read * read) as f64;
    assert!((mean - x as f64).abs() < 1e-3, "mean {mean}");
    assert!((var / want - 1.0).abs() < 0.05, "variance {var} vs {want}");
    // Different frames, different noise; same frame and seed, same noise.
    let mut a = grey_image(8, 8, x);
    let mut b = grey_image(8, 8, x);
    apply(
        "sensor-noise = { shot = 0.05, read = 0.02 }",
        1,
        0.0,
        &mut a,
        8,
        8,
    );
    apply(
        "sensor-noise = { shot = 0.05, read = 0.02 }",
        1,
        0.0,
        &mut b,
        8,
        8,
    );
    assert_eq!(a, b);
    apply(
        "sensor-noise = { shot = 0.05, read = 0.02 }",
        2,
        0.0,
        &mut b,
        8,
        8,
    );
    assert_ne!(a, b);
}

#[test]
fn motion_blur_spreads_a_point_along_the_declared_direction_and_length() {
    let (w, h) = (64, 64);
    for (angle, along) in [(0.0, (1i32, 0i32)), (90.0, (0, 1))] {
        let mut img = grey_image(w, h, 0.0);
        img[32 * w + 32] = [1.0; 3];
        apply(
            &format!("motion-blur = {{ length_px = 10, angle_deg = {angle} }}"),
            0,
            0.0,
            &mut img,
            w,
            h,
        );
        let lit: Vec<(i32, i32)> = (0..w * h)
            .filter(|&i| img[i][0] > 1e-4)
            .map(|i| ((i % w) as i32 - 32, (i / w) as i32 - 32))
            .collect();
        for &(dx, dy) in &lit {
            // Perpendicular spread within bilinear footprint, extent along the direction <= L/2 + 1.
            let (a, p) = (dx * along.0 + dy * along.1, dx * along.1 - dy * along.0);
            assert!(
                p.abs() <= 1 && a.abs() <= 6,
                "angle {angle}: lit pixel at ({dx}, {dy})"
            );
        }
        let extent = lit
            .iter()
            .map(|&(dx, dy)| dx * along.0 + dy * along.1)
            .max()
            .unwrap()
            - lit
                .iter()
                .map(|&(dx, dy)| dx * along.0 + dy * along.1)
                .min()
                .unwrap();
        assert!((9..=11).contains(&extent), "angle {angle}: extent {extent}");
        let total: f32 = img.iter().map(|p| p[0]).sum();
        assert!((total - 1.0).abs() < 0.02, "energy {total}");
    }
}

#[test]
fn rolling_shutter_skews_a_vertical_edge() {
    let (w, h) = (128, 64);
    let mut img: Vec<[f32; 3]> = (0..w * h)
        .map(|i| if i % w < 40 { [1.0; 3] } else { [0.0; 3] })
        .collect();
    apply("rolling-shutter = { skew_px = 20 }", 0, 0.0, &mut img, w, h);
    let edge = |y: usize| (0..w).position(|x| img[y * w + x][0] < 0.5).unwrap() as i32;
    assert_eq!(edge(0), 40);
    assert!(
        (edge(h - 1) - 60).abs() <= 1,
        "last row edge at {}",
        edge(h - 1)
    );
    assert!((edge(h / 2) - 50).abs() <= 1);
}

#[test]
fn vignetting_darkens_corners_by_the_strength() {
    let (w, h) = (65, 65);
    let mut img = grey_image(w, h, 0.8);
    apply("vignetting = { strength = 0.3 }", 0, 0.0, &mut img, w, h);
    assert!((img[32 * w + 32][0] - 0.8).abs() < 1e-6);
    assert!((img[0][0] - 0.8 * 0.7).abs() < 1e-5);
}

#[test]
fn drifts_follow_their_sine() {
    let (w, h) = (4, 4);
    // period 1 s, t = 0.25 s: sin = 1.
    let mut img = grey_image(w, h, 0.5);
    apply(
        "exposure-drift = { amplitude = 0.2, period_s = 1 }",
        0,
        0.25,
        &mut img,
        w,
        h,
    );
    assert!((img[0][1] - 0.6).abs() < 1e-5);
    let mut img = grey_image(w, h, 0.5);
    apply(
        "white-balance-drift = { amplitude = 0.2, period_s = 1 }",
        0,
        0.25,
        &mut img,
        w,
        h,
    );
    assert!(
        (img[0][0] - 0.6).abs() < 1e-5
            && (img[0][1] - 0.5).abs() < 1e-6
            && (img[0][2] - 0.4).abs() < 1e-5
    );
}

#[test]
fn jpeg_size_grows_with_quality() {
    let mut sizes = Vec::new();
    for q in [10, 50, 95] {
        let mut sim = Simulator::new(
            scene(&format!("[[effect]]\njpeg = {{ quality = {q} }}\n")),
            assets(),
        )
        .unwrap();
        sizes.push(sim.render(0).unwrap().meta.jpeg_bytes.unwrap());
    }
    assert!(sizes[0] < sizes[1] && sizes[1] < sizes[2], "{sizes:?}");
}

#[test]
fn unplug_stops_frames_at_the_declared_index() {
    let mut sim = Simulator::new(scene(&effect("unplug")), assets()).unwrap();
    assert!(sim.render(0).is_ok());
    assert!(sim.render(1).is_ok());
    for i in 2..5 {
        match sim.render(i) {
            Err(SimError::Unplugged { frame }) => assert_eq!(frame, i),
            other => panic!("frame {i}: {:?}", other.map(|f| f.index)),
        }
    }
    // Replugged after `for_frames`.
    let mut sim = Simulator::new(
        scene("[[effect]]\nunplug = { at_frame = 2, for_frames = 3 }\n"),
        assets(),
    )
    .unwrap();
    assert!(sim.render(1).is_ok());
    assert!(sim.render(4).is_err());
    assert!(sim.render(5).is_ok());
}

#[test]
fn hang_is_declared_per_frame_and_counted() {
    let mut sim = Simulator::new(scene(&effect("hang")), assets()).unwrap();
    assert!(sim.render(1).is_ok());
    for i in 2..4 {
        assert!(matches!(sim.render(i), Err(SimError::Hung { frame }) if frame == i));
    }
    assert_eq!(sim.stage_invocations().get("hang"), Some(&3));
}

#[test]
fn occluder_hides_part_of_the_person_and_shake_moves_the_camera() {
    let mut pure = Simulator::new(scene(""), assets()).unwrap();
    let p = pure.render(0).unwrap();
    let mut occ = Simulator::new(scene(&effect("occluder")), assets()).unwrap();
    let o = occ.render(0).unwrap();
    let person = |f: &volcap_sim::SimFrame| f.person_mask().iter().filter(|&&m| m > 0).count();
    assert!(o.ids.contains(&volcap_sim::sim::OCCLUDER_ID));
    assert!(person(&o) < person(&p));
    let mut shake = Simulator::new(scene(&effect("camera-shake")), assets()).unwrap();
    let s = shake.render(3).unwrap();
    assert_ne!(s.camera.eye, p.camera.eye);
    assert!(
        (s.camera.eye - s.camera.target).length() - (p.camera.eye - p.camera.target).length()
            < 1e-4
    );
}
