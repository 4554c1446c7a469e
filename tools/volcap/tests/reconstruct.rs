//! `volcap reconstruct` on real photographs and bad inputs, and the people count on a
//! simulated two-person frame.
//!
//! Real photos: scikit-image 0.26.0's `astronaut.png` (public domain, NASA; re-encoded as
//! JPEG here) and `camera.png` (CC0), with person masks drawn by hand for this project
//! (`tests/data/real/README.md`: polygons, person and clothing, held objects excluded).
//! Asserted per photo: the command succeeds with one person; the mask is written at the
//! photo's size and has IoU >= 0.7 with the hand mask; a box on the face is >= 90 % person
//! and a box of pure background <= 5 %; the mesh is a glTF binary; the four renders are
//! RGBA at the grid size with transparent background and an opaque person.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use volcap_engine::model::{FrameInfo, Models, Precision};
use volcap_sim::scene::Scene;
use volcap_sim::{HumanAssets, Simulator};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volcap-rec-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn reconstruct(args: &[&Path], out: &Path) -> (bool, Vec<serde_json::Value>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_volcap"))
        .current_dir(repo())
        .arg("reconstruct")
        .args(args)
        .args(["--res", "65", "--json", "--out"])
        .arg(out)
        .output()
        .unwrap();
    let lines = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}")))
        .collect();
    (
        o.status.success(),
        lines,
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Fraction of mask pixels that are person inside the box [x0, x1) x [y0, y1).
fn box_fraction(m: &image::GrayImage, x0: u32, y0: u32, x1: u32, y1: u32) -> f64 {
    let mut on = 0;
    for y in y0..y1 {
        for x in x0..x1 {
            on += (m.get_pixel(x, y)[0] == 255) as u32;
        }
    }
    on as f64 / ((x1 - x0) * (y1 - y0)) as f64
}

#[test]
fn real_photos_give_masks_meshes_and_renders() {
    let out = tmp("real");
    let real = repo().join("tests/data/real");
    let imgs = [real.join("astronaut.jpg"), real.join("camera.png")];
    let (ok, lines, err) = reconstruct(&[&imgs[0], &imgs[1]], &out);
    assert!(ok, "{err}");
    assert_eq!(lines.len(), 2);
    // Face box, background box (512x512 photos).
    let boxes = [
        ("astronaut", (185, 50, 260, 140), (0, 0, 40, 150)),
        ("camera", (200, 90, 240, 150), (330, 0, 512, 120)),
    ];
    for (line, (name, face, bg)) in lines.iter().zip(boxes) {
        assert_eq!(line["ok"], true, "{line}");
        assert_eq!(line["people"], 1, "{line}");
        for k in [
            "segment_ms",
            "encode_ms",
            "localize_ms",
            "render_ms",
            "mask_fraction",
        ] {
            assert!(
                line[k].as_f64().is_some_and(|v| v.is_finite() && v > 0.0),
                "{k}: {line}"
            );
        }
        let mask = image::open(out.join(format!("{name}.mask.png")))
            .unwrap()
            .to_luma8();
        assert_eq!(mask.dimensions(), (512, 512));
        assert!(mask.pixels().all(|p| p[0] == 0 || p[0] == 255));
        let hand = image::open(real.join(format!("{name}.mask.png")))
            .unwrap()
            .to_luma8();
        let (mut inter, mut union) = (0u32, 0u32);
        for (a, b) in mask.pixels().zip(hand.pixels()) {
            let (a, b) = (a[0] > 127, b[0] > 127);
            inter += (a && b) as u32;
            union += (a || b) as u32;
        }
        let iou = inter as f64 / union as f64;
        println!("{name}: mask IoU vs hand mask {iou:.3}");
        assert!(iou >= 0.7, "{name}: mask IoU {iou:.3}");
        let f = box_fraction(&mask, face.0, face.1, face.2, face.3);
        assert!(f >= 0.9, "{name}: face box {f:.2} person");
        let b = box_fraction(&mask, bg.0, bg.1, bg.2, bg.3);
        assert!(b <= 0.05, "{name}: background box {b:.2} person");
        let glb = std::fs::read(out.join(format!("{name}.glb"))).unwrap();
        assert_eq!(&glb[..4], b"glTF");
        assert_eq!(
            u32::from_le_bytes(glb[8..12].try_into().unwrap()) as usize,
            glb.len()
        );
        for yaw in ["000", "090", "180", "270"] {
            let r = image::open(out.join(format!("{name}.yaw{yaw}.png")))
                .unwrap()
                .to_rgba8();
            assert_eq!(r.dimensions(), (65, 65));
            let opaque = r.pixels().filter(|p| p[3] == 255).count();
            let clear = r.pixels().filter(|p| p[3] == 0).count();
            assert!(
                opaque > 20 && clear > 20,
                "{name} yaw {yaw}: {opaque} opaque, {clear} clear"
            );
        }
    }
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn greyscale_and_rgba_are_converted_and_bad_inputs_are_refused_by_name() {
    let out = tmp("bad");
    let dir = tmp("bad-in");
    let photo = image::open(repo().join("tests/data/real/camera.png")).unwrap();
    let grey_alpha = dir.join("grey_alpha.png");
    image::DynamicImage::ImageLumaA8(photo.to_luma_alpha8())
        .save(&grey_alpha)
        .unwrap();
    let rgba16 = dir.join("rgba16.png");
    image::DynamicImage::ImageRgba16(photo.to_rgba16())
        .save(&rgba16)
        .unwrap();
    let text = dir.join("notes.png");
    std::fs::write(&text, "not an image").unwrap();
    let huge = dir.join("huge.png");
    image::GrayImage::new(9000, 1).save(&huge).unwrap();
    let missing = dir.join("missing.jpg");
    let (ok, lines, err) = reconstruct(&[&grey_alpha, &rgba16, &text, &huge, &missing, &dir], &out);
    assert!(!ok, "failures make the exit status non-zero");
    assert_eq!(lines.len(), 6, "{err}");
    for l in &lines[..2] {
        assert_eq!(l["ok"], true, "{l}");
        assert_eq!(l["people"], 1, "{l}");
    }
    let expect = [
        (&text, "not a readable"),
        (&huge, "too large"),
        (&missing, "cannot read"),
        (&dir, "not a regular file"),
    ];
    for (l, (path, what)) in lines[2..].iter().zip(expect) {
        let e = l["error"].as_str().unwrap_or_default();
        assert_eq!(l["ok"], false);
        assert!(
            e.contains(&*path.display().to_string()) && e.contains(what),
            "{e}"
        );
        assert!(err.contains(e), "stderr repeats the error: {err}");
    }
    std::fs::remove_dir_all(&out).ok();
    std::fs::remove_dir_all(&dir).ok();
}

/// Two simulated people (tests/scenes/two-people.toml): the segmentation finds two regions,
/// the count says 2, and the field is built from the larger one alone.
#[test]
fn two_people_are_counted_and_the_larger_is_kept() {
    let text = std::fs::read_to_string(repo().join("tests/scenes/two-people.toml")).unwrap();
    let scene = Scene::parse(&text, Path::new("two-people.toml")).unwrap();
    let mut sim = Simulator::new(scene, Arc::new(HumanAssets::embedded().unwrap())).unwrap();
    let f = sim.render(0).unwrap();
    let models = Models::load(&repo().join("models"), "fourier", Precision::F32).unwrap();
    let mut info = FrameInfo::default();
    let (_, mask, _) = models
        .prepare(&f.rgb, f.width, f.height, &mut info)
        .unwrap();
    assert_eq!(info.people, 2, "{info:?}");
    // The kept mask is one of the two subjects: it overlaps one subject's true pixels
    // and not the other's.
    let s = volcap_engine::model::preprocess::INPUT_SIZE;
    let truth = volcap_engine::model::preprocess::letterbox(
        &f.ids.iter().flat_map(|&i| [i, i, i]).collect::<Vec<u8>>(),
        f.width,
        f.height,
    );
    let (mut on1, mut on2) = (0, 0);
    for i in 0..s * s {
        if mask[i] > 0.5 {
            let id = (truth[i] * 255.0).round() as u8;
            on1 += (id == 1) as u32;
            on2 += (id == 2) as u32;
        }
    }
    // (The ids are letterboxed bilinearly: a few boundary pixels of subject 2 read as 1.)
    assert!(
        on1.max(on2) > 100 && on1.min(on2) * 50 <= on1.max(on2),
        "kept mask covers subject 1: {on1} px, subject 2: {on2} px"
    );
}

/// `--close-range` / `[model] close_range`: a photo whose person the lower edge cuts is
/// encoded with the close-range model (the field equals that model's own, and differs from
/// the main model's); a whole body standing in a simulator frame keeps the main model.
#[test]
fn the_close_range_model_encodes_people_cut_by_the_frame_and_only_them() {
    use glam::Vec3;
    use volcap_engine::field::OccupancyField;
    use volcap_engine::model::ModelView;
    let dir = repo().join("models");
    let both = Models::load(&dir, "fourier-small", Precision::F32)
        .unwrap()
        .with_close_range(&dir, "fourier-small-upper")
        .unwrap();
    let main = Models::load(&dir, "fourier-small", Precision::F32).unwrap();
    // The frame is segmented before the cut is known, as often as the main model asks
    // (`Models::segment_passes`): alone, the close-range model is given the same count.
    let mut close = Models::load(&dir, "fourier-small-upper", Precision::F32).unwrap();
    close.segment_passes = both.segment_passes;
    let occ = |m: &Models, rgb: &[u8], w: usize, h: usize| {
        let mut info = FrameInfo::default();
        let (img, mask, crop) = m.prepare(rgb, w, h, &mut info).unwrap();
        let field = m.encode(&img, &mask, crop, ModelView::default()).unwrap();
        let pts: Vec<Vec3> = (0..400)
            .map(|i| {
                let t = i as f32 / 400.0;
                Vec3::new(
                    (t * 37.0).sin() * 0.5,
                    (t * 23.0).cos() * 0.8,
                    (t * 11.0).sin() * 0.3,
                )
            })
            .collect();
        let mut out = vec![0.0f32; pts.len()];
        field.occupancy(&pts, &mut out).unwrap();
        assert!(out.iter().all(|v| v.is_finite()));
        (info, crop, out)
    };
    let photo = image::open(repo().join("tests/data/real/astronaut.jpg"))
        .unwrap()
        .to_rgb8();
    let (w, h) = (photo.width() as usize, photo.height() as usize);
    let (info, crop, a) = occ(&both, photo.as_raw(), w, h);
    assert!(crop.cut_by_frame && info.close_range, "{info:?} {crop:?}");
    let (info_main, crop_main, b) = occ(&main, photo.as_raw(), w, h);
    assert!(crop_main.cut_by_frame && !info_main.close_range);
    let (_, _, c) = occ(&close, photo.as_raw(), w, h);
    assert_eq!(a, c, "the close-range field is that model's own");
    let differ = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| (*x - *y).abs() > 1e-3)
        .count();
    assert!(
        differ > 10,
        "only {differ} of 400 values differ from the main model"
    );
    // A whole body in view: the main model.
    let text = std::fs::read_to_string(repo().join("tests/scenes/front-walk.toml")).unwrap();
    let scene = Scene::parse(&text, Path::new("front-walk.toml")).unwrap();
    let mut sim = Simulator::new(scene, Arc::new(HumanAssets::embedded().unwrap())).unwrap();
    let f = sim.render(0).unwrap();
    let (info, crop, a) = occ(&both, &f.rgb, f.width, f.height);
    assert!(!crop.cut_by_frame && !info.close_range, "{info:?} {crop:?}");
    let (_, _, b) = occ(&main, &f.rgb, f.width, f.height);
    assert_eq!(a, b);
}
