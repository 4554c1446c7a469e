//! `[compute] backend = "wgpu"`: the networks of a model-mode daemon on the GPU backend's
//! adapter (lavapipe here and in CI), named with what runs there and counted in `/state`;
//! an adapter that is not there is a start-up error listing the adapters found, or the CPU
//! with `fallback = "cpu"`, said in `/state`; a build without the feature refuses the key.

mod common;
use common::{check_config, root, tmp};
#[cfg(feature = "wgpu")]
use common::{serial, start, wait_for};
#[cfg(feature = "wgpu")]
use std::time::Duration;

fn config(dir: &std::path::Path, compute: &str) -> std::path::PathBuf {
    config_scene(dir, "front-walk", compute)
}

/// [`config`] on `tests/scenes/{scene}.toml`; `compute` may go on with further sections.
fn config_scene(dir: &std::path::Path, scene: &str, compute: &str) -> std::path::PathBuf {
    let p = dir.join("gpu.toml");
    std::fs::write(
        &p,
        format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nfield = \"model\"\nresolution = 65\ndisplay_size = 0\n[model]\ndir = \"{}\"\n[dbus]\nbus = \"none\"\n[compute]\n{compute}\n",
            root().join(format!("tests/scenes/{scene}.toml")).display(),
            root().join("models").display()
        ),
    )
    .unwrap();
    p
}

#[cfg(not(feature = "wgpu"))]
#[test]
fn a_build_without_the_gpu_backend_refuses_it_by_name() {
    let dir = tmp("nogpu");
    let (code, err) = check_config(&config(&dir, "backend = \"wgpu\""));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("compute.backend") && err.contains("`wgpu`"),
        "{err}"
    );
}

#[cfg(feature = "wgpu")]
fn have_adapter() -> bool {
    match volcap_engine::gpu::Gpu::open("auto") {
        Ok(_) => true,
        Err(e) if std::env::var_os("CI").is_some() => panic!("no GPU adapter under CI: {e}"),
        Err(e) => {
            println!("skipped: {e}");
            false
        }
    }
}

#[cfg(feature = "wgpu")]
#[test]
fn an_adapter_that_is_not_there_fails_start_up_or_falls_back_when_asked() {
    let _serial = serial();
    let dir = tmp("gpu-missing");
    let (code, err) = check_config(&config(
        &dir,
        "backend = \"wgpu\"\nadapter = \"no-such-gpu\"",
    ));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("compute.backend") && err.contains("no-such-gpu") && err.contains("adapter"),
        "{err}"
    );
    // With the CPU as fallback it starts, and says why it is on the CPU.
    let d = start(&config(
        &dir,
        "backend = \"wgpu\"\nadapter = \"no-such-gpu\"\nfallback = \"cpu\"",
    ));
    let s = wait_for(&d.addr, "frames", Duration::from_secs(60), |s| {
        s["frames_published"].as_u64() > Some(0)
    });
    assert_eq!(s["compute"]["backend"], "cpu", "{s}");
    assert!(
        s["compute"]["note"]
            .as_str()
            .unwrap_or("")
            .contains("no-such-gpu"),
        "{s}"
    );
    let (_, _, body) = common::request(&d.addr, "GET", "/metrics", "");
    let m = String::from_utf8_lossy(&body);
    assert!(
        m.contains("volcap_compute_backend{backend=\"cpu\"} 1"),
        "{m}"
    );
    assert!(!m.contains("volcap_adapter_"), "{m}");
}

#[cfg(feature = "wgpu")]
#[test]
fn model_mode_runs_its_networks_on_the_adapter() {
    let _serial = serial();
    if !have_adapter() {
        return;
    }
    let dir = tmp("gpu-model");
    let d = start(&config(&dir, "backend = \"wgpu\""));
    let s = wait_for(
        &d.addr,
        "model frames on the adapter",
        Duration::from_secs(120),
        |s| s["frames_published"].as_u64() > Some(2),
    );
    let c = &s["compute"];
    assert_eq!(c["backend"], "wgpu", "{s}");
    assert!(
        !c["adapter"]["name"].as_str().unwrap_or("").is_empty(),
        "{s}"
    );
    assert!(
        c["on_adapter"]
            .as_array()
            .unwrap()
            .iter()
            .any(|v| v == "segment"),
        "{s}"
    );
    // Every published frame ran segmentation and the shape network there.
    let runs = c["adapter_work"]["net_runs"].as_u64().unwrap();
    assert!(
        runs >= 2 * 3,
        "{runs} network runs for {} frames: {s}",
        s["frames_published"]
    );
    assert!(c["adapter_work"]["bytes_down"].as_u64().unwrap() > 0, "{s}");
    // Localization and the render ran there too: a rendered frame each.
    let rendered = c["adapter_work"]["render_runs"].as_u64().unwrap();
    assert!(
        rendered >= 2,
        "{rendered} frames rendered on the adapter: {s}"
    );
    assert!(
        c["adapter_work"]["localize_runs"].as_u64().unwrap() >= rendered,
        "{s}"
    );
    assert!(
        c["on_adapter"]
            .as_array()
            .unwrap()
            .iter()
            .any(|v| v.as_str().unwrap_or("").starts_with("render")),
        "{s}"
    );
    assert!(s["field"].as_str().unwrap().contains("wgpu"), "{s}");
    // `compute.render_device = "auto"` (the default) keeps the render stage on the networks'
    // device on the CPU's adapter (lavapipe; a second device there takes the same cores), on
    // a second device on a GPU.
    let expected = if c["adapter"]["device_type"] == "cpu" {
        "shared"
    } else {
        "own"
    };
    assert_eq!(c["render_device"], expected, "{s}");
    // The same counters for Prometheus.
    let (st, _, body) = common::request(&d.addr, "GET", "/metrics", "");
    let m = String::from_utf8_lossy(&body);
    assert_eq!(st, 200);
    assert!(
        m.contains("volcap_compute_backend{backend=\"wgpu\"} 1"),
        "{m}"
    );
    let runs: f64 = m
        .lines()
        .find_map(|l| l.strip_prefix("volcap_adapter_net_runs_total "))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.0);
    assert!(runs >= 6.0, "{m}");
    assert!(m.contains("volcap_adapter_render_runs_total "), "{m}");
    assert_eq!(s["people"], 1, "{s}");
}

/// The surface's dead band on the adapter (`[temporal] surface_dead_band`, its default): a
/// still person's frames rendered there hold grid points, counted in `/state` and
/// `/metrics` as the CPU renderer's are; nothing refused at 65^3.
#[cfg(feature = "wgpu")]
#[test]
fn a_still_persons_frames_are_held_on_the_adapter() {
    let _serial = serial();
    if !have_adapter() {
        return;
    }
    let dir = tmp("gpu-held");
    let cfg = config_scene(
        &dir,
        "still-rest-noise",
        "backend = \"wgpu\"\n[temporal]\nenabled = true",
    );
    let d = start(&cfg);
    let s = wait_for(
        &d.addr,
        "frames held on the adapter",
        Duration::from_secs(120),
        |s| s["temporal"]["held_sides"]["frames"].as_u64() > Some(1),
    );
    let held = &s["temporal"]["held_sides"];
    let rendered = s["compute"]["adapter_work"]["render_runs"]
        .as_u64()
        .unwrap();
    assert!(
        rendered >= 2,
        "{rendered} frames rendered on the adapter: {s}"
    );
    assert!(held["points"].as_u64() > Some(0), "{s}");
    assert!(held["adapter_refused"].is_null(), "{s}");
    let (st, _, body) = common::request(&d.addr, "GET", "/metrics", "");
    let m = String::from_utf8_lossy(&body);
    assert_eq!(st, 200);
    let frames: f64 = m
        .lines()
        .find_map(|l| l.strip_prefix("volcap_render_held_frames_total "))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.0);
    assert!(frames >= 2.0, "{m}");
}

/// `compute.render_device = "own"`: the render stage on a second device of the adapter, the
/// frame's maps read back by the field stage (some 2 MB a frame, where the shared device
/// brings back a fraction of that: with `shared` this test fails) and written by the render
/// stage; frames are published, rendered there, and counted with the networks' work. With
/// `compute.round_waits = "per-frame"` the levels' conflict rounds are predicted from the
/// frame before (counted in `adapter_work.predicted`). With `compute.render_workers = 2`
/// each of the stage's two threads opens a device and a renderer of its own there.
#[cfg(feature = "wgpu")]
#[test]
fn the_render_stage_runs_on_a_device_of_its_own_when_asked() {
    let _serial = serial();
    if !have_adapter() {
        return;
    }
    let dir = tmp("gpu-own-render");
    let d = start(&config(
        &dir,
        "backend = \"wgpu\"\nrender_device = \"own\"\nround_waits = \"per-frame\"\nrender_workers = 2\nsegment_workers = 2",
    ));
    let s = wait_for(
        &d.addr,
        "frames rendered on the second device",
        Duration::from_secs(120),
        |s| s["frames_published"].as_u64() > Some(2),
    );
    let w = &s["compute"]["adapter_work"];
    let rendered = w["render_runs"].as_u64().unwrap();
    assert!(
        rendered >= 2,
        "{rendered} frames rendered on the adapter: {s}"
    );
    // The maps came down for the render device: 31 x 128 x 128 floats a frame rendered.
    let down = w["bytes_down"].as_u64().unwrap();
    assert!(
        down >= rendered * 31 * 128 * 128 * 4,
        "{down} bytes down for {rendered} frames: {s}"
    );
    assert_eq!(s["compute"]["render_device"], "own", "{s}");
    assert_eq!(s["people"], 1, "{s}");
    // Two render workers, each frame counted by the one that drew it.
    assert_eq!(s["compute"]["render_workers"], 2, "{s}");
    let by_worker: Vec<u64> = s["compute"]["render_worker_frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_u64().unwrap())
        .collect();
    assert_eq!(by_worker.len(), 2, "{s}");
    assert!(
        by_worker.iter().sum::<u64>() >= rendered,
        "{by_worker:?} for {rendered} frames rendered on the adapter: {s}"
    );
    // Two segment workers, their networks on the adapter from two threads.
    assert_eq!(s["compute"]["segment_workers"], 2, "{s}");
    let segmented: u64 = s["compute"]["segment_worker_frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert!(segmented >= rendered, "{segmented} segmented: {s}");
    // The frames after each worker's first of the grid are predicted (but for a frame whose
    // prediction fell short twice, run again per round).
    let predicted = w["predicted"].as_u64().unwrap();
    assert!(
        predicted >= 1 && 2 * (predicted + 1) >= rendered,
        "{predicted} of {rendered} predicted: {s}"
    );
}
