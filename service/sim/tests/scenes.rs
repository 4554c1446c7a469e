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

/// A scene's `hands = "varied"` poses the hands and the forearms' twist and nothing else: the
/// same motion's head, torso, legs and feet stay where `rest` puts them, and the hands move.
#[test]
fn drawn_hands_move_the_hands_and_forearms_only() {
    use volcap_sim::parts::{Part, vertex_parts};
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let parts = vertex_parts(&assets);
    let posed = |hands: &str| {
        let text = format!(
            "[camera]\nwidth = 64\nheight = 64\n[[subject]]\nid = \"a\"\n\
             motion = {{ kind = \"procedural\", style = \"walk\", seed = 5{hands} }}\n"
        );
        let scene = Scene::parse(&text, std::path::Path::new("hands.toml")).unwrap();
        let mut sim = Simulator::new(scene, assets.clone()).unwrap();
        sim.render(7).unwrap();
        sim.world_meshes()[0].0[0].verts.to_vec()
    };
    let (rest, same, drawn) = (
        posed(""),
        posed(", hands = \"rest\""),
        posed(", hands = \"varied\""),
    );
    assert_eq!(rest, same, "hands = \"rest\" is the default");
    let mut hand_move = 0.0f32;
    for (i, p) in parts.iter().enumerate() {
        let d = (drawn[i] - rest[i]).length();
        match p {
            Part::Head | Part::Torso | Part::Legs | Part::Feet => {
                assert!(d == 0.0, "a {p:?} vertex moved {d} m")
            }
            Part::Hands => hand_move = hand_move.max(d),
            Part::Arms => {}
        }
    }
    assert!(hand_move > 0.03, "the hands moved {hand_move} m at most");
}
