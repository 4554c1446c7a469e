//! `[rtsp]` in every build: bad keys are config errors naming file, line and key; a build
//! without the `rtsp` feature checks such a board whole with a note, and refuses to run it
//! (exit 2) instead of running without the stream the board asks for.

mod common;
use common::*;
use std::process::Command;

#[test]
fn bad_rtsp_keys_are_named_with_their_line() {
    let dir = tmp("rtsp-bad");
    for (text, key) in [
        (
            "bind = \"127.0.0.1:0\"\nbitrate_kbps = 10",
            "rtsp.bitrate_kbps",
        ),
        ("push = \"http://nvr/x\"", "rtsp.push"),
        ("bind = \"127.0.0.1:0\"\npath = \"live\"", "rtsp.path"),
        (
            "bind = \"127.0.0.1:0\"\nencoder = \"openh264\"\nprofile = \"high\"",
            "rtsp.profile",
        ),
    ] {
        let p = sim_config(&dir, 65, &format!("[rtsp]\n{text}\n"));
        let (code, err) = check_config(&p);
        assert_eq!(code, Some(2), "{text}: {err}");
        assert!(err.contains(key) && err.contains("line "), "{text}: {err}");
    }
    let p = sim_config(
        &dir,
        65,
        "[http]\nbind = \"127.0.0.1:8554\"\n[rtsp]\nbind = \"127.0.0.1:8554\"\n",
    );
    let (code, err) = check_config(&p);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("rtsp.bind"), "{err}");
}

#[test]
fn a_build_without_rtsp_says_so() {
    let dir = tmp("rtsp-feature");
    let p = sim_config(&dir, 65, "[rtsp]\nbind = \"127.0.0.1:0\"\n");
    let out = Command::new(bin())
        .args(["--check-config", "--config"])
        .arg(&p)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    let noted = stdout.contains("without the `rtsp` feature");
    assert_eq!(noted, !cfg!(feature = "rtsp"), "{stdout}");
    if !cfg!(feature = "rtsp") {
        let out = Command::new(bin())
            .args(["--http", "127.0.0.1:0", "--config"])
            .arg(&p)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("--features rtsp"), "{err}");
    }
}
