use super::*;

fn parse(t: &str) -> Result<Scene, SceneError> {
    Scene::parse(t, Path::new("tests/scenes/x.toml"))
}

#[test]
fn minimal_scene_has_defaults() {
    let s = parse("[[subject]]\nid = \"a\"\nmotion = { kind = \"static\", pose = \"rest\" }\n")
        .unwrap();
    assert_eq!(s.camera.width.0, 512);
    assert_eq!(s.name, "x");
    assert!(s.effects.is_empty());
}

/// Hardening round two, #2: 1,000 subjects (217 kB) passed the check and took the
/// daemon past 8 GB with no frame. The work a frame declares is bounded at load.
#[test]
fn per_frame_work_is_bounded_at_load_naming_the_key() {
    let subject = "[[subject]]\nid = \"a\"\nmotion = { kind = \"static\", pose = \"rest\" }\n";
    assert!(parse(&subject.repeat(MAX_SUBJECTS)).is_ok());
    let text = subject.repeat(1000);
    assert!(text.len() < MAX_SCENE_BYTES as usize);
    let t = std::time::Instant::now();
    let e = parse(&text).unwrap_err().to_string();
    assert!(t.elapsed() < std::time::Duration::from_secs(2));
    let line = 3 * MAX_SUBJECTS + 1;
    assert!(
        e.contains("x.toml")
            && e.contains(&format!(":{line}: subject:"))
            && e.contains("1000 subjects"),
        "{e}"
    );
    let effect = "[[effect]]\nvignetting = { strength = 0.1 }\n";
    assert!(parse(&effect.repeat(MAX_EFFECTS)).is_ok());
    let e = parse(&effect.repeat(MAX_EFFECTS + 1))
        .unwrap_err()
        .to_string();
    assert!(e.contains(": effect:") && e.contains("17 effects"), "{e}");
    let e = parse("[camera]\nwidth = 4096\nheight = 4096\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(":2: camera.width:") && e.contains("4096 x 4096"),
        "{e}"
    );
    assert!(parse("[camera]\nwidth = 2048\nheight = 2048\n").is_ok());
    let e = parse("[[effect]]\nmotion-blur = { length_px = 200, angle_deg = 0 }\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("effect[0].motion-blur.length_px") && e.contains("200 px"),
        "{e}"
    );
}

#[test]
fn unknown_key_names_file_line_and_key() {
    let e = parse("frames = 3\n[camera]\nwidht = 100\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("tests/scenes/x.toml") && e.contains("line 3") && e.contains("widht"),
        "{e}"
    );
}

#[test]
fn bad_values_name_line_and_key() {
    let e = parse("frames = 2\n[[effect]]\njpeg = { quality = 101 }\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 3") && e.contains("quality") && e.contains("1..=100"),
        "{e}"
    );
    let e = parse(
        "[[subject]]\nid = \"a\"\ngender = 1.5\nmotion = { kind = \"static\", pose = \"rest\" }\n",
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("line 3") && e.contains("gender") && e.contains("[0, 1]"),
        "{e}"
    );
    let e = parse("[[effect]]\nteleport = { speed = 1 }\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("teleport") && e.contains("line"), "{e}");
    let e = parse("[[effect]]\nvignetting = { strength = 0.5, radius = 3 }\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("radius") && e.contains("line 2"), "{e}");
}

#[test]
fn procedural_hands_parse_and_a_bad_value_names_line_and_choices() {
    use crate::hands::Hands;
    use crate::scene::MotionSpec;
    let hands = |t: &str| -> Result<Hands, String> {
        let s = parse(&format!(
            "[[subject]]\nid = \"a\"\nmotion = {{ kind = \"procedural\", style = \"walk\"{t} }}\n"
        ))
        .map_err(|e| e.to_string())?;
        match &s.subjects[0].motion {
            MotionSpec::Procedural { hands, .. } => Ok(*hands),
            m => Err(format!("{m:?}")),
        }
    };
    assert_eq!(hands(""), Ok(Hands::Rest));
    assert_eq!(hands(", hands = \"varied\""), Ok(Hands::Varied));
    let e = hands(", hands = \"fist\"").unwrap_err();
    assert!(
        e.contains("line 3") && e.contains("fist") && e.contains("rest") && e.contains("varied"),
        "{e}"
    );
}
