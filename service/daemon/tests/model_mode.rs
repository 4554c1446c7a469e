//! volcapd in model mode on loopback: the trained networks render, the networks' runtime is
//! chosen and named, and the close-range model takes over and is checked at start.

use std::path::Path;
use std::time::Duration;

mod common;
use common::{check_config, request, root, serial, start, wait_for};

/// `[model] segment_full_every = 4`: the segment stage segments the walking person's crop
/// alone between whole frames, says so in `/state` and `/metrics`, and still counts one
/// person and renders them; `map_smooth = 1` reaches the shape model (its field's label).
#[test]
fn the_segmentation_tracks_the_crop_between_whole_frames() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-track-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = root().join("tests/scenes/front-walk.toml");
    std::fs::write(
        dir.join("b.toml"),
        format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nfield = \"model\"\nresolution = 65\ndisplay_size = 0\n[model]\ndir = \"{}\"\nsegment_passes = 2\nsegment_full_every = 4\nmap_smooth = 1\n",
            scene.display(),
            root().join("models").display()
        ),
    )
    .unwrap();
    let d = start(&dir.join("b.toml"));
    let s = wait_for(&d.addr, "tracked frames", Duration::from_secs(60), |s| {
        s["segment_track"]["crop_frames"].as_u64() > Some(4)
            && s["frames_published"].as_u64() > Some(4)
    });
    let t = &s["segment_track"];
    assert_eq!(t["full_every"], 4, "{s}");
    let whole = t["whole_frames"].as_u64().unwrap();
    let crop = t["crop_frames"].as_u64().unwrap();
    // One whole frame in four at most (a lost track adds whole frames, never crop ones).
    assert!(whole >= 1 && crop <= 3 * whole + 3, "{t}");
    assert_eq!(s["people"], 1, "{s}");
    assert!(
        s["field"]
            .as_str()
            .unwrap()
            .contains("segmented twice, maps smoothed once"),
        "{s}"
    );
    let (st, _, metrics) = request(&d.addr, "GET", "/metrics", "");
    assert_eq!(st, 200);
    let metrics = String::from_utf8_lossy(&metrics);
    assert!(
        metrics.contains("volcap_segment_track_frames_total{kind=\"crop\"}"),
        "{metrics}"
    );
    let (st, _, png) = request(&d.addr, "GET", "/snapshot.png", "");
    assert_eq!(st, 200);
    let png = image::load_from_memory(&png).unwrap().to_rgba8();
    let opaque = png.pixels().filter(|p| p[3] == 255).count();
    assert!(opaque > 50, "the tracked person covers {opaque} pixels");
}

#[test]
fn model_mode_renders_network_output() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = root().join("tests/scenes/front-walk.toml");
    std::fs::write(
        dir.join("b.toml"),
        format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nfield = \"model\"\nresolution = 65\ndisplay_size = 0\n[model]\ndir = \"{}\"\n",
            scene.display(),
            root().join("models").display()
        ),
    )
    .unwrap();
    let d = start(&dir.join("b.toml"));
    let s = wait_for(&d.addr, "model frames", Duration::from_secs(60), |s| {
        s["frames_published"].as_u64() > Some(1)
    });
    assert_eq!(s["mode"], "model", "{s}");
    // The segmentation's count of people in the walking scene: exactly one.
    assert_eq!(s["people"], 1, "{s}");
    // No close-range model configured, no segmentation track: nothing to report.
    assert!(s["close_range"].is_null(), "{s}");
    assert!(s["segment_track"].is_null(), "{s}");
    assert!(
        s["mode_note"]
            .as_str()
            .unwrap()
            .contains("trained networks")
    );
    // Where the segment, field and render stages' time goes, in /state and /metrics: the
    // segmentation network, the shape network and the localization timed; the camera's view
    // runs no colour encoder.
    let parts = &s["stage_parts"];
    assert_eq!(parts.as_object().map(|o| o.len()), Some(11), "{s}");
    assert!(
        parts["segment: networks"]["p50_ms"].as_f64() > Some(0.0),
        "{s}"
    );
    assert!(
        parts["field: shape net"]["p50_ms"].as_f64() > Some(0.0),
        "{s}"
    );
    assert!(
        parts["render: localize"]["p50_ms"].as_f64() > Some(0.0),
        "{s}"
    );
    assert!(
        parts["field: colour encoder"]["p99_ms"].as_f64() < Some(0.05),
        "{s}"
    );
    let (st, _, metrics) = request(&d.addr, "GET", "/metrics", "");
    assert_eq!(st, 200);
    let metrics = String::from_utf8_lossy(&metrics);
    assert!(
        metrics.contains("volcap_stage_part_ms{part=\"field: temporal filter\",quantile=\"0.99\"}"),
        "{metrics}"
    );
    let (st, _, png) = request(&d.addr, "GET", "/snapshot.png", "");
    assert_eq!(st, 200);
    let png = image::load_from_memory(&png).unwrap().to_rgba8();
    assert_eq!(png.width(), 65);
    let opaque = png.pixels().filter(|p| p[3] == 255).count();
    assert!(
        opaque > 50,
        "the reconstructed person covers {opaque} pixels"
    );
    assert!(opaque < 65 * 65, "not everything is inside");
    // A missing model folder is a clear start-up error naming the file.
    std::fs::write(
        dir.join("bad.toml"),
        format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nfield = \"model\"\n[model]\ndir = \"nowhere\"\n",
            scene.display()
        ),
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_volcapd"))
        .args(["--check-config", "--config"])
        .arg(dir.join("bad.toml"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("[model]") && err.contains("seg.onnx") && err.contains("not found"),
        "{err}"
    );
    // The networks' runtime: ONNX Runtime asked for by name with a library that is not
    // there is a start-up error naming the key and the file; tract always starts and says
    // so; `auto` starts on one or the other and names it.
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    for (runtime, ok, says) in [
        (
            "runtime = \"onnxruntime\"\nonnxruntime_lib = \"/nowhere/libonnxruntime.so\"",
            false,
            "compute.runtime",
        ),
        ("runtime = \"tract\"", true, "F32 on tract"),
        ("runtime = \"auto\"", true, "F32 on "),
    ] {
        std::fs::write(
            dir.join("rt.toml"),
            format!(
                "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nfield = \"model\"\n[model]\ndir = \"{}\"\n[compute]\n{runtime}\n",
                scene.display(),
                models.display()
            ),
        )
        .unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_volcapd"))
            .args(["--check-config", "--config"])
            .arg(dir.join("rt.toml"))
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(if ok { &out.stdout } else { &out.stderr }).to_string();
        assert_eq!(out.status.success(), ok, "{runtime}: {text}");
        assert!(text.contains(says), "{runtime}: {text}");
        if !ok {
            assert!(text.contains("/nowhere/libonnxruntime.so"), "{text}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A person cut by the frame's lower edge (tests/scenes/cut-by-edge.toml: an upper body)
/// is encoded by the close-range model once `close_range_frames` frames in a row were cut;
/// `/state` says which model encodes.
#[test]
fn close_range_model_takes_over_when_the_frame_cuts_the_person() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-close-live-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("b.toml"),
        format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nfield = \"model\"\nresolution = 33\n[model]\ndir = \"{}\"\nclose_range = \"fourier-small-upper\"\nclose_range_frames = 2\n",
            root().join("tests/scenes/cut-by-edge.toml").display(),
            root().join("models").display()
        ),
    )
    .unwrap();
    let d = start(&dir.join("b.toml"));
    let s = wait_for(&d.addr, "close-range model", Duration::from_secs(60), |s| {
        s["close_range"] == true
    });
    assert_eq!(s["mode"], "model", "{s}");
    drop(d);
    std::fs::remove_dir_all(&dir).ok();
}

/// `[model] close_range`: a committed model loads with the main one at `--check-config`; a
/// missing one is a configuration error naming its file.
#[test]
fn close_range_model_is_checked_at_start() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-close-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |close: &str| {
        let text = format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nfield = \"model\"\n[model]\ndir = \"{}\"\nclose_range = \"{close}\"\n",
            root().join("tests/scenes/front-walk.toml").display(),
            root().join("models").display()
        );
        std::fs::write(dir.join("c.toml"), text).unwrap();
        check_config(&dir.join("c.toml"))
    };
    let (code, e) = run("fourier-small-upper");
    assert_eq!(code, Some(0), "{e}");
    let (code, e) = run("no-such-model");
    assert_eq!(code, Some(2), "{e}");
    assert!(
        e.contains("shape-no-such-model") && e.contains("c.toml"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `[model] thin_parts = "moment-fill"` through the whole daemon: the still person of
/// tests/scenes/still-rest.toml (arms held out from the body, the same to either side),
/// rendered by the oracle and by the model at 129^3 with and without the fill. With the fill,
/// the render reaches as far to either side of the person as the oracle's does (its hands,
/// within 10 % of the reach, measured against each render's own height, since the model
/// frames the person in its own proportions), it adds pixels (not many) and loses at most a
/// map pixel at an edge. The series
/// alone may end at a wrist (printed: `fourier-small` does at both; `fourier-small-seg2`, trained
/// on two-pass masks, at one). The temporal filter is off: each snapshot is then a function of
/// the still scene's one frame, not of how many frames the filter has blended by the time it is
/// taken (two daemons, two frame counts).
/// The config names no model: the daemon's default,
/// `fourier-small-seg2` (`volcap_engine::model::DEFAULT_MODEL`), segmented once.
#[test]
fn thin_parts_moment_fill_brings_the_hands_into_the_render() {
    let _serial = serial();
    let dir = std::env::temp_dir().join(format!("volcapd-thin-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // The snapshot's reach to either side (`Reach`).
    let render = |field: &str, thin: &str| -> Reach {
        let cfg = dir.join(format!("{field}-{thin}.toml"));
        std::fs::write(
            &cfg,
            format!(
                "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nfield = \"{field}\"\nresolution = 129\n[model]\ndir = \"{}\"\nthin_parts = \"{thin}\"\n[temporal]\nenabled = false\n",
                root().join("tests/scenes/still-rest.toml").display(),
                root().join("models").display()
            ),
        )
        .unwrap();
        let d = start(&cfg);
        let s = wait_for(&d.addr, "frames", Duration::from_secs(90), |s| {
            s["frames_published"].as_u64() > Some(2)
        });
        if field == "model" {
            // /state (and D-Bus `Model`) say which reading runs.
            let named = s["field"].as_str().unwrap_or_default();
            assert_eq!(
                named.contains("thin parts: moment-fill"),
                thin == "moment-fill",
                "{s}"
            );
        }
        let (st, _, png) = request(&d.addr, "GET", "/snapshot.png", "");
        assert_eq!(st, 200);
        let r = Reach::of(&image::load_from_memory(&png).unwrap().to_rgba8());
        assert!(r.pixels > 0, "{field} {thin}: nothing rendered");
        r
    };
    let truth = render("oracle", "series");
    let series = render("model", "series");
    let fill = render("model", "moment-fill");
    for (name, r) in [
        ("oracle", &truth),
        ("series", &series),
        ("moment-fill", &fill),
    ] {
        println!(
            "{name}: {} px, columns {}..{}, reach left / right {:.3} / {:.3} of the height",
            r.pixels,
            r.first,
            r.last,
            r.left(),
            r.right()
        );
    }
    // The scene is symmetric: the truth reaches as far to both sides.
    assert!(
        (truth.left() - truth.right()).abs() < 0.05 * truth.left().max(truth.right()),
        "the oracle's reach {:.3} / {:.3}",
        truth.left(),
        truth.right()
    );
    let want = 0.9 * truth.left().min(truth.right());
    assert!(
        fill.left() >= want && fill.right() >= want,
        "the fill's render reaches {:.3} / {:.3} of its height to the left / right, the truth's {:.3} / {:.3}: a hand is missing",
        fill.left(),
        fill.right(),
        truth.left(),
        truth.right()
    );
    // The fill only adds inside at the coefficient maps' pixels; between them the render
    // interpolates the maps, so where a filled pixel borders one that decodes, the edge may move
    // by up to one map pixel: the crop's side over the maps' 128 (the person fills 0.8 of the
    // crop's height, the render's height here).
    let map_px = (series.rows / 0.8 / 128.0).ceil() as u32;
    assert!(
        fill.first <= series.first + map_px && fill.last + map_px >= series.last,
        "the fill's render {}..{} lost more than a map pixel ({map_px} columns) of the series' {}..{}",
        fill.first,
        fill.last,
        series.first,
        series.last
    );
    assert!(
        fill.pixels >= series.pixels && (fill.pixels as f64) < 1.2 * series.pixels as f64,
        "opaque pixels {} -> {}",
        series.pixels,
        fill.pixels
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// How far a render's opaque pixels reach to either side of their mass centre.
struct Reach {
    pixels: usize,
    first: u32,
    last: u32,
    centre: f64,
    rows: f64,
}

impl Reach {
    fn of(png: &image::RgbaImage) -> Self {
        let px: Vec<(u32, u32)> = png
            .enumerate_pixels()
            .filter(|(_, _, p)| p[3] > 0)
            .map(|(x, y, _)| (x, y))
            .collect();
        let cols = px.iter().map(|p| p.0);
        let rows = px.iter().map(|p| p.1);
        let (top, bottom) = (rows.clone().min().unwrap_or(0), rows.max().unwrap_or(0));
        Self {
            pixels: px.len(),
            first: cols.clone().min().unwrap_or(0),
            last: cols.max().unwrap_or(0),
            centre: px.iter().map(|p| p.0 as f64).sum::<f64>() / px.len().max(1) as f64,
            rows: (bottom - top + 1) as f64,
        }
    }

    /// Reach to the left of the mass centre, in units of the render's height.
    fn left(&self) -> f64 {
        (self.centre - self.first as f64) / self.rows
    }

    fn right(&self) -> f64 {
        (self.last as f64 - self.centre) / self.rows
    }
}
