//! `volcap sim ...` run as a user would.

use std::process::Command;

fn volcap() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_volcap"));
    c.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    c
}

fn tmp(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("volcap-{name}-{}", std::process::id()))
}

#[test]
fn render_writes_frames_masks_depth_and_json() {
    let out = tmp("render");
    let o = volcap()
        .args([
            "sim",
            "render",
            "tests/scenes/two-people.toml",
            "--frames",
            "2",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "000000.png",
        "000000_mask.png",
        "000000_depth.png",
        "000001.json",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("000001.json")).unwrap()).unwrap();
    assert_eq!(j["subjects"].as_array().unwrap().len(), 2);
    assert_eq!(j["camera"]["width"], 512);
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn unplugged_scene_stops_cleanly() {
    let out = tmp("unplug");
    let o = volcap()
        .args(["sim", "render", "tests/scenes/unplug.toml", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("unplugged at frame 10"));
    assert!(out.join("000009.png").exists() && !out.join("000010.png").exists());
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn bad_scene_files_are_named_with_line_and_key() {
    let dir = tmp("bad");
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("bad.toml");
    std::fs::write(&f, "frames = 2\n[camera]\nwidth = 12\n").unwrap();
    let o = volcap()
        .args(["sim", "render"])
        .arg(&f)
        .arg("--out")
        .arg(dir.join("o"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("bad.toml") && e.contains("line 3") && e.contains("between 16 and 4096"),
        "{e}"
    );
    let o = volcap()
        .args(["sim", "render", "no/such/scene.toml", "--out"])
        .arg(dir.join("o"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no/such/scene.toml"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn localize_bench_accepts_simulator_scenes() {
    let o = volcap()
        .args([
            "bench",
            "localize",
            "--scene",
            "crouch",
            "--res",
            "65",
            "--methods",
            "hierarchical",
            "--runs",
            "1",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: Vec<serde_json::Value> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), 2);
    assert!(rows.iter().all(|r| r["scene"] == "crouch"));
    assert!(rows[1]["band_bound"].as_u64().unwrap() > 100);
}
