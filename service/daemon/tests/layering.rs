//! The daemon's modules import one way: `config` at the bottom, `compute` and `capture` above it, the
//! pipeline stages above both, the servers (`http`, `dbus`, `rtsp`) on top. A circle (capture taking
//! the camera factory from the pipeline, config validating through the pipeline's `Live`)
//! makes every module a dependency of every other; this keeps it from coming back.

use std::path::{Path, PathBuf};

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            sources(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn module_arrows_run_one_way() {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    // (module, the modules above it that it must not name)
    let rules: [(&str, &[&str]); 4] = [
        (
            "config",
            &[
                "compute", "capture", "pipeline", "http", "dbus", "notify", "rtsp",
            ],
        ),
        // The compute backend (the adapter opened at start) sits on config.
        (
            "compute",
            &["capture", "pipeline", "http", "dbus", "notify", "rtsp"],
        ),
        ("capture", &["pipeline", "http", "dbus", "notify", "rtsp"]),
        ("pipeline", &["http", "dbus", "rtsp"]),
    ];
    let mut checked = 0;
    for (module, above) in rules {
        let mut files = vec![src.join(format!("{module}.rs"))];
        let dir = src.join(module);
        if dir.is_dir() {
            sources(&dir, &mut files);
        }
        for f in files.iter().filter(|f| f.exists()) {
            let text = std::fs::read_to_string(f).unwrap();
            for up in above {
                for needle in [format!("crate::{up}"), format!("volcapd::{up}")] {
                    assert!(
                        !text.contains(&needle),
                        "{} names {needle}: {module} must not depend on {up}",
                        f.display()
                    );
                }
            }
            checked += 1;
        }
    }
    assert!(
        checked >= 8,
        "only {checked} files checked: did the modules move?"
    );
}
