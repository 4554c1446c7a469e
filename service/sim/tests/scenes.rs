//! Every shipped scene under tests/scenes/ loads, renders frame 0 and shows what it declares.

use std::path::PathBuf;
use std::sync::Arc;
use volcap_sim::{HumanAssets, Scene, SimError, Simulator};

fn scenes() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/scenes");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    v.sort();
    v
}

#[test]
fn every_shipped_scene_renders_its_people() {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let all = scenes();
    assert!(all.len() >= 10, "hard-case scenes missing: {all:?}");
    for p in all {
        let scene = Scene::load(&p).unwrap();
        let n_subjects = scene.subjects.len();
        let mut sim = Simulator::new(scene, assets.clone())
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        let f = sim.render(0).unwrap();
        for s in 1..=n_subjects as u8 {
            let px = f.ids.iter().filter(|&&i| i == s).count();
            assert!(px > 50, "{}: subject {s} covers {px} pixels", p.display());
        }
        assert!(f.depth_m.iter().any(|d| d.is_finite()));
    }
}

#[test]
fn unplug_scene_stops_and_cut_by_edge_touches_the_border() {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/scenes");
    let mut sim = Simulator::new(
        Scene::load(&dir.join("unplug.toml")).unwrap(),
        assets.clone(),
    )
    .unwrap();
    assert!(sim.render(9).is_ok());
    assert!(matches!(
        sim.render(10),
        Err(SimError::Unplugged { frame: 10 })
    ));
    let mut sim =
        Simulator::new(Scene::load(&dir.join("cut-by-edge.toml")).unwrap(), assets).unwrap();
    let f = sim.render(0).unwrap();
    let (w, h) = (f.width, f.height);
    let on_border =
        (0..h).any(|y| f.ids[y * w] != 0) || (0..w).any(|x| f.ids[(h - 1) * w + x] != 0);
    assert!(on_border, "the subject should be cut by the frame edge");
}

#[test]
fn unknown_names_in_scenes_give_file_line_and_key() {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let text = "frames = 3\n[[subject]]\nid = \"a\"\noutfit = \"tuxedo\"\nmotion = { kind = \"static\", pose = \"rest\" }\n";
    let e = Simulator::new(
        Scene::parse(text, std::path::Path::new("bad.toml")).unwrap(),
        assets.clone(),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(
        e.contains("bad.toml:4")
            && e.contains("subject[0].outfit")
            && e.contains("tuxedo")
            && e.contains("male_casualsuit02"),
        "{e}"
    );
    let text = "[[subject]]\nid = \"a\"\nmotion = { kind = \"static\", pose = \"moonwalk\" }\n";
    let e = Simulator::new(
        Scene::parse(text, std::path::Path::new("bad.toml")).unwrap(),
        assets,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(
        e.contains("bad.toml:3") && e.contains("moonwalk") && e.contains("tpose"),
        "{e}"
    );
}
