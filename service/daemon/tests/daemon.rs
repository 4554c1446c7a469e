//! volcapd end to end on loopback: real clients, endpoints, faults, many slow clients.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

mod common;
use common::{check_config, have, request, root, serial, start, state, wait_for};

/// The sim board in its debugging mode (the oracle at 129^3): the endpoint tests check the
/// server, not the networks, and run at the oracle's cheaper rate.
fn sim_config() -> PathBuf {
    let text = std::fs::read_to_string(root().join("board-config/sim.toml")).unwrap();
    let oracle = text
        .replace("../tests/", &format!("{}/tests/", root().display()))
        .replace("field = \"model\"", "field = \"oracle\"")
        .replace("resolution = 257", "resolution = 129")
        .replace("coarse_level = 4", "coarse_level = 3");
    assert!(oracle.contains("field = \"oracle\"") && oracle.contains("resolution = 129"));
    let p = std::env::temp_dir().join(format!("volcapd-sim-oracle-{}.toml", std::process::id()));
    std::fs::write(&p, oracle).unwrap();
    p
}

/// The main job (README's first command, `board-config/sim.toml` as shipped): the
/// reconstruction, labelled as one, at 257^3 with the temporal filter on, and its mesh.
#[test]
fn the_main_job_shows_the_reconstruction() {
    let _serial = serial();
    let d = start(&root().join("board-config/sim.toml"));
    let s = wait_for(&d.addr, "model frames", Duration::from_secs(60), |s| {
        s["state"] == "running" && s["frames_published"].as_u64() > Some(5)
    });
    assert_eq!(s["mode"], "model", "{s}");
    assert!(
        s["mode_note"].as_str().unwrap().contains("reconstruction"),
        "{s}"
    );
    assert_eq!(s["people"], 1, "{s}");
    assert_eq!(s["resolution"], 257, "{s}");
    assert!(s["temporal"]["resets"].as_u64() >= Some(1), "{s}");
    // The filter runs with the file's settings: each key sim.toml sets is in force, as the
    // file writes it; the others at the engine's defaults.
    let shipped: toml::Table =
        toml::from_str(&std::fs::read_to_string(root().join("board-config/sim.toml")).unwrap())
            .unwrap();
    let given = shipped["temporal"].as_table().unwrap();
    let settings = s["temporal"]["settings"].as_object().unwrap();
    assert_eq!(settings.len(), 16, "{s}");
    // The surface's dead band counts what it held (the walk's crop moves: maybe nothing).
    let held = &s["temporal"]["held_sides"];
    let (frames, points) = (held["frames"].as_u64(), held["points"].as_u64());
    assert!(frames.is_some() && points >= frames, "{s}");
    assert!(given.len() > 1, "sim.toml sets a filter key: {given:?}");
    for (key, value) in given.iter().filter(|(k, _)| *k != "enabled") {
        let file = value.as_float().or(value.as_integer().map(|v| v as f64));
        assert_eq!(settings[key].as_f64(), file, "{key}: {s}");
    }
    let defaults = volcap_engine::model::temporal::TemporalSettings::default();
    if !given.contains_key("mask_low") {
        let default = defaults.mask_low.to_string().parse::<f64>().ok();
        assert_eq!(settings["mask_low"].as_f64(), default, "{s}");
    }
    // The pieces apart from the body left out at the board's gap, counted.
    let apart = &s["drop_apart"];
    assert_eq!(apart["gap"].as_f64(), Some(0.1), "{s}");
    let (frames, points) = (apart["frames"].as_u64(), apart["points"].as_u64());
    assert!(frames.is_some() && points >= frames, "{s}");
    let (_, _, metrics) = request(&d.addr, "GET", "/metrics", "");
    let metrics = String::from_utf8(metrics).unwrap();
    assert!(
        metrics.contains("volcap_render_apart_frames_total ")
            && metrics.contains("volcap_render_apart_points_total ")
            && metrics.contains("volcap_render_held_frames_total ")
            && metrics.contains("volcap_render_held_points_total "),
        "{metrics}"
    );
    let (_, _, viewer) = request(&d.addr, "GET", "/", "");
    assert!(
        String::from_utf8(viewer)
            .unwrap()
            .contains("reconstruction by the trained networks")
    );
    let (st, _, png) = request(&d.addr, "GET", "/snapshot.png", "");
    assert_eq!(st, 200);
    let png = image::load_from_memory(&png).unwrap().to_rgba8();
    assert_eq!(png.width(), 512);
    let opaque = png.pixels().filter(|p| p[3] == 255).count();
    assert!(
        (5_000..512 * 512 / 2).contains(&opaque),
        "the reconstructed person covers {opaque} pixels"
    );
    // The model's field is meshed on request too (it was the oracle's only).
    let (st, head, glb) = request(&d.addr, "GET", "/mesh.glb", "");
    assert_eq!(st, 200, "{head}");
    assert!(
        glb.starts_with(b"glTF") && glb.len() > 10_000,
        "{} bytes",
        glb.len()
    );
}

#[test]
fn endpoints_serve_the_oracle_render() {
    let _serial = serial();
    let d = start(&sim_config());
    let s = wait_for(&d.addr, "running", Duration::from_secs(30), |s| {
        s["state"] == "running" && s["frames_published"].as_u64() > Some(2)
    });
    assert_eq!(s["mode"], "oracle");
    assert!(
        s["mode_note"]
            .as_str()
            .unwrap()
            .contains("not a reconstruction")
    );
    let (st, head, jpg) = request(&d.addr, "GET", "/snapshot.jpg", "");
    assert_eq!(st, 200);
    assert!(head.contains("image/jpeg"));
    let img = image::load_from_memory(&jpg).unwrap();
    // Rendered at 129^3, published at the display size (512 px: more rays than columns).
    assert_eq!((img.width(), img.height()), (512, 512));
    assert_eq!(s["display_size"], 512);
    let (st, _, png) = request(&d.addr, "GET", "/snapshot.png", "");
    assert_eq!(st, 200);
    let png = image::load_from_memory(&png).unwrap().to_rgba8();
    assert_eq!(png.get_pixel(0, 0)[3], 0, "transparent background");
    assert!(png.pixels().any(|p| p[3] == 255), "the person is opaque");
    let (_, _, viewer) = request(&d.addr, "GET", "/", "");
    let viewer = String::from_utf8(viewer).unwrap();
    assert!(viewer.contains("/stream.mjpg") && viewer.contains("oracle"));
    // Issue #37, item 5: frames a latest-wins slot replaced are "superseded", explained
    // where they are shown; "dropped"/"lost" is kept for frames lost.
    let st = state(&d.addr);
    for stage in ["capture", "segment", "field", "render", "encode"] {
        let v = &st["stages"][stage];
        assert!(
            v["superseded"].is_u64() && v["lost"].is_u64() && v.get("dropped").is_none(),
            "{st}"
        );
    }
    assert_eq!(st["stages"]["render"]["lost"], 0, "{st}");
    assert!(
        st["stage_notes"]["superseded"]
            .as_str()
            .unwrap()
            .contains("latest frame wins"),
        "{st}"
    );
    let (_, _, m) = request(&d.addr, "GET", "/metrics", "");
    let m = String::from_utf8(m).unwrap();
    assert!(
        m.contains("# HELP volcap_stage_superseded_total")
            && m.contains("volcap_stage_lost_total{stage=\"render\"} 0"),
        "{m}"
    );
    assert!(
        m.contains("volcap_frames_published_total")
            && m.contains("volcap_stage_ms{stage=\"render\",quantile=\"0.99\"}")
    );
    let (st, head, glb) = request(&d.addr, "GET", "/mesh.glb", "");
    assert_eq!(st, 200);
    assert!(head.contains("model/gltf-binary"));
    assert!(
        glb.starts_with(b"glTF") && glb.len() > 10_000,
        "{} bytes",
        glb.len()
    );
    // On a loopback bind without a token, this machine's user turns the view.
    assert_eq!(s["controls"], "local");
    let (st, _, body) = request(&d.addr, "POST", "/view?yaw=90&pitch=10", "");
    assert_eq!(st, 200, "{}", String::from_utf8_lossy(&body));
    wait_for(&d.addr, "the view turned", Duration::from_secs(5), |s| {
        s["view"]["yaw"] == 90.0 && s["view"]["pitch"] == 10.0
    });
    assert_eq!(request(&d.addr, "GET", "/nope", "").0, 404);
}

#[test]
fn real_clients_decode_the_stream() {
    let _serial = serial();
    let d = start(&sim_config());
    wait_for(&d.addr, "frames", Duration::from_secs(30), |s| {
        s["frames_published"].as_u64() > Some(2)
    });
    let url = format!("http://{}/stream.mjpg", d.addr);
    if have("ffprobe") {
        let o = Command::new("ffprobe")
            .args([
                "-v",
                "error",
                "-show_entries",
                "stream=codec_name,width,height",
                "-of",
                "json",
                &url,
            ])
            .output()
            .unwrap();
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["streams"][0]["codec_name"], "mjpeg");
        assert_eq!(j["streams"][0]["width"], 512);
    }
    if have("ffmpeg") {
        let o = Command::new("ffmpeg")
            .args([
                "-v",
                "error",
                "-i",
                &url,
                "-frames:v",
                "5",
                "-f",
                "rawvideo",
                "-pix_fmt",
                "rgb24",
                "-",
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(o.stdout.len(), 5 * 512 * 512 * 3, "five decoded frames");
    }
}

#[test]
fn token_enables_view_controls_and_client_limit_holds() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-tok-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("b.toml");
    let scene = root().join("tests/scenes/front-walk.toml");
    std::fs::write(&cfg, format!("[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\ndisplay_size = 0\n[http]\nclient_limit = 2\ntoken = \"s3cret-token\"\n", scene.display())).unwrap();
    let d = start(&cfg);
    wait_for(&d.addr, "frames", Duration::from_secs(30), |s| {
        s["frames_published"].as_u64() > Some(1)
    });
    assert_eq!(
        request(
            &d.addr,
            "POST",
            "/view?yaw=90&pitch=10",
            "Authorization: Bearer wrong-token\r\n"
        )
        .0,
        401
    );
    // A bad or missing parameter is named in the refusal.
    for (query, names) in [
        ("/view?yaw=abc&pitch=10", "yaw"),
        ("/view?yaw=10&pitch=1e999", "pitch"),
        ("/view?yaw=10", "pitch"),
        ("/view?yaw=10&pitch=0&resolution=-3", "resolution"),
    ] {
        let (code, _, body) = request(
            &d.addr,
            "POST",
            query,
            "Authorization: Bearer s3cret-token\r\n",
        );
        let body = String::from_utf8_lossy(&body);
        assert_eq!(code, 400, "{query}: {body}");
        assert!(
            body.contains(names),
            "{query}: the refusal does not name {names}: {body}"
        );
    }
    assert_eq!(
        request(
            &d.addr,
            "POST",
            "/view?yaw=90&pitch=10",
            "Authorization: Bearer s3cret-token\r\n"
        )
        .0,
        200
    );
    assert_eq!(state(&d.addr)["view"]["yaw"], 90.0);
    // Resolution, distance and a transparent background at run time; bad values refused.
    let auth = "Authorization: Bearer s3cret-token\r\n";
    let (code, _, body) = request(&d.addr, "POST", "/view?yaw=0&pitch=0&resolution=100", auth);
    assert_eq!(code, 400);
    assert!(String::from_utf8_lossy(&body).contains("resolution 100"));
    assert_eq!(
        request(&d.addr, "POST", "/view?yaw=0&pitch=0&background=1,2", auth).0,
        400
    );
    assert_eq!(
        request(
            &d.addr,
            "POST",
            "/view?yaw=0&pitch=0&distance=3&resolution=65&background=0,0,0,0",
            auth
        )
        .0,
        200
    );
    let s = wait_for(&d.addr, "65^3 frames", Duration::from_secs(20), |s| {
        s["resolution"] == 65
    });
    assert_eq!(s["view"]["distance"], 3.0);
    let t = Instant::now();
    loop {
        let (_, _, png) = request(&d.addr, "GET", "/snapshot.png", "");
        let img = image::load_from_memory(&png).unwrap().to_rgba8();
        if img.width() == 65 {
            assert_eq!(img.get_pixel(0, 0)[3], 0, "transparent background");
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(20), "no 65x65 frame");
        std::thread::sleep(Duration::from_millis(200));
    }
    // Two streams fill the limit; the third is refused; closing one frees a slot at once.
    let open = |addr: &str| {
        let mut s = TcpStream::connect(addr).unwrap();
        write!(s, "GET /stream.mjpg HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
        let mut b = [0u8; 64];
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let n = s.read(&mut b).unwrap();
        (s, String::from_utf8_lossy(&b[..n]).to_string())
    };
    let (a, ha) = open(&d.addr);
    let (_b, hb) = open(&d.addr);
    assert!(ha.starts_with("HTTP/1.1 200") && hb.starts_with("HTTP/1.1 200"));
    let (_c, hc) = open(&d.addr);
    assert!(hc.starts_with("HTTP/1.1 503"), "{hc}");
    drop(a);
    wait_for(&d.addr, "a freed slot", Duration::from_secs(10), |s| {
        s["clients"] == 1
    });
    let (_e, he) = open(&d.addr);
    assert!(he.starts_with("HTTP/1.1 200"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn unplug_is_a_state_and_the_camera_recovers() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-unplug-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("scene.toml"),
        "[camera]\nwidth = 128\nheight = 128\n[[subject]]\nid = \"a\"\noutfit = \"male_casualsuit02\"\n\
         motion = { kind = \"procedural\", style = \"walk\" }\n[[effect]]\nunplug = { at_frame = 20, for_frames = 45 }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("b.toml"),
        "[camera]\nbackend = \"sim\"\nscene = \"scene.toml\"\n[render]\nresolution = 65\ndisplay_size = 0\n",
    )
    .unwrap();
    let d = start(&dir.join("b.toml"));
    wait_for(&d.addr, "running", Duration::from_secs(30), |s| {
        s["state"] == "running"
    });
    let s = wait_for(&d.addr, "unplugged", Duration::from_secs(30), |s| {
        s["state"] == "degraded"
    });
    assert!(s["reason"].as_str().unwrap().contains("unplugged"), "{s}");
    // The camera's typed state, and a placeholder frame that says why.
    let s = wait_for(&d.addr, "placeholder", Duration::from_secs(10), |s| {
        s["showing_placeholder"] == true
    });
    assert_eq!(s["camera"]["state"], "lost", "{s}");
    assert_eq!(s["camera"]["fault"], "unplugged", "{s}");
    let (code, _, jpeg) = request(&d.addr, "GET", "/snapshot.jpg", "");
    assert_eq!(code, 200);
    let img = image::load_from_memory(&jpeg).unwrap().to_rgb8();
    assert_eq!(img.width(), 65);
    // The placeholder's text is drawn in light pixels on the dark background.
    assert!(img.pixels().filter(|p| p[0] > 180).count() > 30);
    let before = s["frames_published"].as_u64().unwrap();
    let s = wait_for(&d.addr, "recovery", Duration::from_secs(30), |s| {
        s["state"] == "running" && s["frames_published"].as_u64() > Some(before + 2)
    });
    assert_eq!(s["mode"], "oracle");
    assert_eq!(s["camera"]["state"], "running", "{s}");
    assert!(s["camera"]["faults"].as_u64() >= Some(1), "{s}");
    assert_eq!(s["showing_placeholder"], false, "{s}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_config_and_bad_scene_exit_with_a_clear_error() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |cfg: &Path| {
        Command::new(env!("CARGO_BIN_EXE_volcapd"))
            .current_dir(root())
            .arg("--config")
            .arg(cfg)
            .output()
            .unwrap()
    };
    let o = run(&dir.join("missing.toml"));
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.toml"));
    std::fs::write(
        dir.join("b.toml"),
        "[camera]\nbackend = \"sim\"\nscene = \"nope.toml\"\n",
    )
    .unwrap();
    let o = run(&dir.join("b.toml"));
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("nope.toml"));
    std::fs::write(dir.join("s.toml"), "[camera]\nwidth = 3\n").unwrap();
    std::fs::write(
        dir.join("c.toml"),
        "[camera]\nbackend = \"sim\"\nscene = \"s.toml\"\n",
    )
    .unwrap();
    let o = run(&dir.join("c.toml"));
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("s.toml") && e.contains("line 2"), "{e}");
    let o = Command::new(env!("CARGO_BIN_EXE_volcapd"))
        .current_dir(root())
        .args(["--check-config", "--config", "board-config/sim.toml"])
        .output()
        .unwrap();
    assert!(o.status.success());
    // A port clash names where the address came from: the --http option when it was given,
    // the config file's http.bind otherwise.
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let o = Command::new(env!("CARGO_BIN_EXE_volcapd"))
        .current_dir(root())
        .args(["--config", "board-config/sim.toml", "--http"])
        .arg(format!("127.0.0.1:{port}"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains(&format!("127.0.0.1:{port}")) && e.contains("--http on the command line"),
        "{e}"
    );
    assert!(!e.contains("http.bind"), "{e}");
    let sim = std::fs::read_to_string(root().join("board-config/sim.toml")).unwrap();
    let clash = dir.join("clash.toml");
    std::fs::write(
        &clash,
        sim.replace("../tests/", &format!("{}/tests/", root().display()))
            .replace("\"../models\"", &format!("\"{}/models\"", root().display()))
            .replace("127.0.0.1:8080", &format!("127.0.0.1:{port}")),
    )
    .unwrap();
    let o = run(&clash);
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("http.bind in") && e.contains("clash.toml"),
        "{e}"
    );
    drop(taken);
    std::fs::remove_dir_all(&dir).ok();
}

/// Headless Chromium loads the viewer and its screenshot shows the stream.
#[test]
fn chromium_shows_the_stream_in_the_viewer() {
    let _serial = serial();
    if !have("chromium") {
        return;
    }
    let d = start(&sim_config());
    wait_for(&d.addr, "frames", Duration::from_secs(30), |s| {
        s["frames_published"].as_u64() > Some(2)
    });
    let dir = std::env::temp_dir().join(format!("volcapd-chr-{}", std::process::id()));
    let shot = dir.join("viewer.png");
    let o = Command::new("chromium")
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--window-size=720,640",
            "--virtual-time-budget=4000",
        ])
        .arg(format!("--user-data-dir={}", dir.join("profile").display()))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(format!("http://{}/", d.addr))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = image::open(&shot).unwrap().to_rgb8();
    // The stream area: the person's blue shirt and jeans are there, not just the page.
    let blue = img
        .pixels()
        .filter(|p| p[2] > 90 && p[2] as i32 > p[0] as i32 + 40)
        .count();
    assert!(
        blue > 2000,
        "only {blue} stream-coloured pixels in the screenshot"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn two_people_is_a_reported_state_not_a_garbled_render() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-two-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = root().join("tests/scenes/two-people.toml");
    std::fs::write(
        dir.join("b.toml"),
        format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n",
            scene.display()
        ),
    )
    .unwrap();
    let d = start(&dir.join("b.toml"));
    let s = wait_for(&d.addr, "degraded", Duration::from_secs(30), |s| {
        s["state"] == "degraded"
    });
    assert!(s["reason"].as_str().unwrap().contains("2 people"), "{s}");
    assert_eq!(
        s["frames_published"], 0,
        "nothing rendered from a two-person field"
    );
    // What is shown is a placeholder that says why, not a render.
    let s = wait_for(&d.addr, "placeholder", Duration::from_secs(10), |s| {
        s["showing_placeholder"] == true
    });
    assert_eq!(s["frames_published"], 0, "{s}");
    let (code, _, jpeg) = request(&d.addr, "GET", "/snapshot.jpg", "");
    assert_eq!(code, 200);
    let img = image::load_from_memory(&jpeg).unwrap().to_rgb8();
    assert!(
        img.pixels().filter(|p| p[0] > 180).count() > 30,
        "text drawn"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The product path: the sim camera through the trained networks (segmentation, shape,
/// colour), localized and rendered by the engine, published like any frame.
fn test_jpeg(w: u32, h: u32, shade: u8) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |x, _| image::Rgb([shade, (x * 4) as u8, 60]));
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 85)
        .encode_image(&img)
        .unwrap();
    out
}

/// A recorded session with corrupt and truncated frames through the `file` backend: bad
/// frames are counted and skipped, good ones are published (camera mode: the frame itself).
#[test]
fn file_backend_counts_and_skips_bad_frames() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-file-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = test_jpeg(160, 120, 220);
    let mut rec = Vec::new();
    for k in 0..12 {
        match k % 4 {
            1 => rec.extend_from_slice(&good[..good.len() / 2]),
            3 => {
                let mut bad = good.clone();
                for b in &mut bad[4..good.len() - 2] {
                    if *b != 0xFF {
                        *b = 0x21;
                    }
                }
                rec.extend_from_slice(&bad);
            }
            _ => rec.extend_from_slice(&good),
        }
    }
    std::fs::write(dir.join("rec.mjpg"), &rec).unwrap();
    std::fs::write(
        dir.join("b.toml"),
        "[camera]\nbackend = \"file\"\npath = \"rec.mjpg\"\nfps = 30\n[render]\nresolution = 129\nfield = \"camera\"\ndisplay_size = 0\n",
    )
    .unwrap();
    let d = start(&dir.join("b.toml"));
    let s = wait_for(&d.addr, "a few loops", Duration::from_secs(30), |s| {
        s["frames_published"].as_u64() > Some(12)
    });
    assert_eq!(s["mode"], "camera", "{s}");
    assert_eq!(s["state"], "running", "{s}");
    let cam = &s["camera"];
    assert_eq!(cam["state"], "running", "{s}");
    let (t, c, f) = (
        cam["truncated"].as_u64().unwrap(),
        cam["corrupt"].as_u64().unwrap(),
        cam["frames"].as_u64().unwrap(),
    );
    // One in four frames of each kind bad: the counts follow the good ones.
    assert!(t >= 3 && c >= 3 && f >= 6, "{s}");
    assert!(t.abs_diff(f / 2) <= 2 && c.abs_diff(f / 2) <= 2, "{s}");
    // The published frame is the recording, letterboxed into the square.
    let (code, _, png) = request(&d.addr, "GET", "/snapshot.png", "");
    assert_eq!(code, 200);
    let img = image::load_from_memory(&png).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (129, 129));
    let centre = img.get_pixel(64, 64);
    assert!(centre[3] == 255 && centre[0] > 190, "{centre:?}");
    assert_eq!(img.get_pixel(64, 2)[3], 0, "letterbox bars are transparent");
    std::fs::remove_dir_all(&dir).ok();
}

/// Bad camera keys are configuration errors (exit 2) that say what to do; a backend this
/// build lacks is checked whole and named in a note (issue #37, item 2).
#[test]
fn camera_config_errors_are_clear() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-camcfg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |text: &str| {
        // Real-camera backends default to the model field: point it at the committed models.
        let models = format!("\n[model]\ndir = \"{}\"\n", root().join("models").display());
        std::fs::write(dir.join("b.toml"), format!("{text}{models}")).unwrap();
        check_config(&dir.join("b.toml"))
    };
    let (code, e) = run("[camera]\nbackend = \"file\"\npath = \"gone.mjpg\"\n");
    assert_eq!(code, Some(2));
    assert!(
        e.contains("gone.mjpg") && e.contains("does not exist"),
        "{e}"
    );
    let (code, e) = run(
        "[camera]\nbackend = \"v4l2\"\ndevice = \"/dev/video0\"\nwidth = 640\nheight = 480\nfps = 30\nformat = \"h264\"\n",
    );
    assert_eq!(code, Some(2));
    assert!(e.contains("line 7") && e.contains("h264"), "{e}");
    let v4l2 = "[camera]\nbackend = \"v4l2\"\ndevice = \"/dev/video0\"\nwidth = 640\nheight = 480\nfps = 30\n";
    let (code, e) = run(v4l2);
    assert_eq!(code, Some(0), "{e}");
    if !cfg!(feature = "v4l2") {
        assert!(e.contains("note:") && e.contains("--features v4l2"), "{e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
