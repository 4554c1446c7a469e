//! The `volcap bench` commands run as a user would.

use std::process::Command;

fn volcap() -> Command {
    Command::new(env!("CARGO_BIN_EXE_volcap"))
}

/// Run `cmd`; it must succeed (its stderr is shown otherwise). Returns its stdout.
fn stdout_of(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The help states the coarse level the code uses (it is generated from the constants).
#[test]
fn coarse_level_help_comes_from_the_engine_constants() {
    let out = volcap()
        .args(["bench", "localize", "--help"])
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let l = volcap_engine::localize::DEFAULT_COARSE_LEVEL;
    let want = format!("default {l}, i.e. {}^3", (1usize << l) + 1);
    assert!(text.contains(&want), "help lacks {want:?}:\n{text}");
    assert!(text.contains("demo-faster"), "help lists demo-faster");
}

#[test]
fn json_rows_cover_every_method_and_nothing_else_is_on_stdout() {
    let text = stdout_of(volcap().args([
        "bench",
        "localize",
        "--scene",
        "sphere",
        "--scene",
        "capsule-human",
        "--res",
        "33,65",
        "--runs",
        "1",
        "--json",
    ]));
    let rows: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line is JSON"))
        .collect();
    // 2 scenes x 2 resolutions x (dense + mise + 7 thresholds + 4 hierarchical (with and
    // without the field's seeds, no conflict, tight) + demo-faster).
    assert_eq!(rows.len(), 2 * 2 * 14);
    assert!(rows.iter().any(|r| r["method"] == "demo-faster"));
    // Analytic fields have no seeds: the two hierarchical rows evaluate the same points.
    let evals = |m: &str, scene: &str, res: u64| {
        rows.iter()
            .find(|r| r["method"] == m && r["scene"] == scene && r["resolution"] == res)
            .map(|r| r["evaluations"].clone())
            .expect("a row")
    };
    for (scene, res) in [("sphere", 33), ("capsule-human", 65)] {
        assert_eq!(
            evals("hierarchical", scene, res),
            evals("hierarchical-unseeded", scene, res)
        );
    }
    for r in &rows {
        for key in [
            "scene",
            "resolution",
            "method",
            "param",
            "evaluations",
            "dense_evaluations",
            "band_bound",
            "iou_vs_dense",
            "lost_components",
            "ms",
        ] {
            assert!(r.get(key).is_some(), "missing {key} in {r}");
        }
        let evals = r["evaluations"].as_u64().unwrap();
        let dense = r["dense_evaluations"].as_u64().unwrap();
        assert!(evals <= dense);
        let res = r["resolution"].as_u64().unwrap();
        assert_eq!(dense, res * res * res);
        let iou = r["iou_vs_dense"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&iou));
        if r["method"] == "hierarchical" || r["method"] == "dense" {
            assert_eq!(iou, 1.0, "{r}");
            assert_eq!(r["lost_components"], 0);
        }
        assert!(r["ms"].as_f64().unwrap() > 0.0);
    }
    let thresholds: Vec<f64> = rows
        .iter()
        .filter(|r| {
            r["method"] == "octree-threshold" && r["scene"] == "sphere" && r["resolution"] == 33
        })
        .map(|r| r["param"].as_f64().unwrap())
        .collect();
    assert_eq!(thresholds.len(), 7);
}

#[test]
fn report_and_plot_are_written() {
    let dir = std::env::temp_dir().join(format!("volcap-bench-{}", std::process::id()));
    stdout_of(
        volcap()
            .args([
                "bench",
                "localize",
                "--scene",
                "torus",
                "--res",
                "33,65",
                "--runs",
                "1",
                "--methods",
                "hierarchical,mise",
            ])
            .arg("--out")
            .arg(&dir),
    );
    let md = std::fs::read_to_string(dir.join("accuracy-vs-time.md")).unwrap();
    assert!(md.contains("| torus | 65 | hierarchical |"));
    assert!(md.contains("| torus | 65 | dense |"));
    let png = std::fs::read(dir.join("accuracy-vs-time.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert!(png.len() > 10_000);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_arguments_are_named() {
    for (args, needle) in [
        (vec!["--scene", "cube"], "unknown scene 'cube'"),
        (vec!["--res", "100"], "--res 100"),
        (vec!["--methods", "octree-threshold@2"], "must be in (0, 1)"),
        (vec!["--methods", "bogus"], "unknown method 'bogus'"),
        (vec!["--runs", "0"], "--runs must be at least 1"),
    ] {
        let out = volcap()
            .args(["bench", "localize", "--json"])
            .args(&args)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(out.stdout.is_empty());
    }
}

fn repo_root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `bench pipeline` with `args` on 3 frames after 1 s of warm-up, JSON rows on stdout and
/// the report in `dir`: the output and its rows.
fn pipeline_rows(args: &[&str], dir: &std::path::Path) -> (String, Vec<serde_json::Value>) {
    let text = stdout_of(
        volcap()
            .current_dir(repo_root())
            .args([
                "bench", "pipeline", "--warmup", "1", "--frames", "3", "--json",
            ])
            .args(args)
            .arg("--out")
            .arg(dir),
    );
    let rows = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    (text, rows)
}

/// `bench pipeline` runs the daemon's pipeline in process: every configuration publishes
/// frames, renders with field evaluations, times every compute stage, compares with its
/// one-thread row, and the table and plot are written.
#[test]
fn pipeline_bench_measures_every_configuration() {
    let dir = std::env::temp_dir().join(format!("volcap-bench-pipeline-{}", std::process::id()));
    let (_, rows) = pipeline_rows(
        &[
            "--res",
            "33,65",
            "--threads",
            "1,2",
            "--segment-thread-up-to",
            "0,65",
            "--seconds",
            "1.5",
        ],
        &dir,
    );
    // res x split x threads, in that order.
    assert_eq!(rows.len(), 8);
    for r in &rows {
        assert!(r["error"].is_null(), "{r}");
        assert!(r["frames"].as_u64().unwrap() > 0, "{r}");
        assert!(r["fps"].as_f64().unwrap() > 0.0, "{r}");
        assert!(r["evaluations"].as_f64().unwrap() > 0.0, "{r}");
        let stages = r["stage_p50_ms"].as_array().unwrap();
        // The segmentation, the encoders and the render stage take time.
        assert_eq!(stages.len(), 5, "{r}");
        assert!(
            stages[1..4].iter().all(|v| v.as_f64().unwrap() > 0.0),
            "{r}"
        );
        let p50 = r["latency_p50_ms"].as_f64().unwrap();
        assert!(
            p50 > 0.0 && p50 <= r["latency_p99_ms"].as_f64().unwrap(),
            "{r}"
        );
        // The segment, field and render stages' parts (model mode): each timed, adding up to
        // about their stage's mean (the segment's and the render's exactly per frame; the
        // field's less the thread's bookkeeping; a frame at the window's edge may count on
        // one side only).
        let parts: Vec<f64> = r["part_mean_ms"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(parts.len(), 11, "{r}");
        assert!(parts.iter().all(|v| v.is_finite() && *v >= 0.0), "{r}");
        // The segmentation network, the shape network, the localization and the surface
        // take time.
        assert!(
            parts[1] > 0.0 && parts[4] > 0.0 && parts[8] > 0.0 && parts[9] > 0.0,
            "{r}"
        );
        let (segment, field, render) = (
            r["segment_mean_ms"].as_f64().unwrap(),
            r["field_mean_ms"].as_f64().unwrap(),
            r["render_mean_ms"].as_f64().unwrap(),
        );
        let s_sum: f64 = parts[..3].iter().sum();
        let (f_sum, r_sum): (f64, f64) = (parts[3..8].iter().sum(), parts[8..].iter().sum());
        assert!(s_sum > 0.75 * segment && s_sum < 1.25 * segment, "{r}");
        assert!(f_sum > 0.5 * field && f_sum < 1.25 * field, "{r}");
        assert!(r_sum > 0.75 * render && r_sum < 1.25 * render, "{r}");
        let x1 = r["speedup_vs_1_thread"].as_f64().unwrap();
        if r["threads"] == 1 {
            assert_eq!(x1, 1.0);
        } else {
            assert!(x1 > 0.0 && x1.is_finite());
        }
    }
    // A finer grid costs more evaluations per frame.
    assert!(rows[4]["evaluations"].as_f64() > rows[0]["evaluations"].as_f64());
    // The segmentation runs on its own thread (split 65) or on the field thread (split 0):
    // timed either way.
    assert!(rows.iter().any(|r| r["segment_thread_up_to"] == 0));
    assert!(rows.iter().any(|r| r["segment_thread_up_to"] == 65));
    let md = std::fs::read_to_string(dir.join("pipeline.md")).unwrap();
    // The default model: one row per configuration in the stages' table and in the parts'.
    let (stages, parts) = md
        .split_once("Where the segment, field and render stages' time goes")
        .expect("the parts' table");
    for table in [stages, parts] {
        assert_eq!(
            table
                .lines()
                // The model's cell: its name, then ", segmented twice" where it is.
                .filter(|l| {
                    l.split('|').nth(1).and_then(|c| c.trim().split(',').next())
                        == Some(volcap_engine::model::DEFAULT_MODEL)
                })
                .count(),
            8
        );
    }
    let png = std::fs::read(dir.join("pipeline.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Bad arguments are refused by name before anything runs.
#[test]
fn pipeline_bench_names_bad_arguments() {
    for (args, want) in [
        (vec!["--model", "nonesuch"], "nonesuch"),
        (vec!["--model", "fourier@int4"], "int4"),
        (vec!["--res", "100"], "100"),
        (vec!["--threads", "0"], "compute.threads"),
        (vec!["--scene", "no/such/scene.toml"], "no/such/scene.toml"),
        (vec!["--seconds", "0"], "--seconds must be in"),
        (
            vec!["--segment-thread-up-to", "100"],
            "--segment-thread-up-to 100",
        ),
        (vec!["--frames", "0"], "--frames 0"),
        (vec!["--yaw", "nan"], "--yaw NaN"),
        (vec!["--yaw", "0,200"], "--yaw 200"),
        (vec!["--render-workers", "0"], "--render-workers 0"),
        (vec!["--render-workers", "1,5"], "--render-workers 5"),
        (vec!["--segment-workers", "0"], "--segment-workers 0"),
        (vec!["--segment-full-every", "0"], "--segment-full-every 0"),
        (
            vec!["--segment-full-every", "1,31"],
            "--segment-full-every 31",
        ),
    ] {
        let out = volcap()
            .current_dir(repo_root())
            .args(["bench", "pipeline", "--warmup", "0"])
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}

/// `--render-workers` x `--segment-workers`: a row per count of render and segment stage
/// threads, each publishing frames and saying how many threads rendered and segmented them.
#[test]
fn pipeline_bench_measures_render_and_segment_workers() {
    let dir = std::env::temp_dir().join(format!("volcap-bench-workers-{}", std::process::id()));
    let (_, rows) = pipeline_rows(
        &[
            "--res",
            "33",
            "--threads",
            "1",
            "--render-workers",
            "1,2",
            "--segment-workers",
            "1,2",
            "--seconds",
            "1.5",
        ],
        &dir,
    );
    assert_eq!(rows.len(), 4);
    for (r, (render, segment)) in rows.iter().zip([(1, 1), (1, 2), (2, 1), (2, 2)]) {
        assert!(r["error"].is_null(), "{r}");
        assert_eq!(r["render_workers"], render, "{r}");
        assert_eq!(r["segment_workers"], segment, "{r}");
        assert!(r["frames"].as_u64().unwrap() > 0, "{r}");
        assert!(r["evaluations"].as_f64().unwrap() > 0.0, "{r}");
    }
    let md = std::fs::read_to_string(dir.join("pipeline.md")).unwrap();
    assert!(md.contains("| 2 render workers |"), "{md}");
    assert!(md.contains("| 2 segment workers |"), "{md}");
    assert!(md.contains("(2 render workers, 2 segment workers)"), "{md}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--segment-full-every`: with two segmentation passes a row per setting of the track,
/// each publishing frames and saying which; with one pass the track has no crop to follow
/// and only the untracked row is measured.
#[test]
fn pipeline_bench_measures_the_segmentation_track() {
    let dir = std::env::temp_dir().join(format!("volcap-bench-track-{}", std::process::id()));
    let (text, rows) = pipeline_rows(
        &[
            "--res",
            "33",
            "--threads",
            "1",
            "--segment-passes",
            "1,2",
            "--segment-full-every",
            "1,4",
            "--seconds",
            "1.5",
        ],
        &dir,
    );
    let got: Vec<(u64, u64)> = rows
        .iter()
        .map(|r| {
            assert!(r["error"].is_null(), "{r}");
            assert!(r["frames"].as_u64().unwrap() > 0, "{r}");
            (
                r["segment_passes"].as_u64().unwrap(),
                r["segment_full_every"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(got, [(1, 1), (2, 1), (2, 4)], "{text}");
    let md = std::fs::read_to_string(dir.join("pipeline.md")).unwrap();
    assert!(md.contains("segmented twice, whole every 4 |"), "{md}");
    assert!(md.contains("(whole every 4)"), "{md}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--yaw`: a row per view, each publishing frames (a turned view runs the colour networks
/// on the surface points; the camera's view takes the input pixel's colour).
#[test]
fn pipeline_bench_measures_turned_views() {
    let dir = std::env::temp_dir().join(format!("volcap-bench-yaw-{}", std::process::id()));
    let (text, rows) = pipeline_rows(
        &[
            "--res",
            "33",
            "--threads",
            "1",
            "--yaw",
            "0,45",
            "--seconds",
            "1",
        ],
        &dir,
    );
    assert_eq!(rows.len(), 2, "{text}");
    for (r, yaw) in rows.iter().zip([0.0, 45.0]) {
        assert_eq!(r["yaw_deg"].as_f64(), Some(yaw), "{r}");
        assert!(
            r["error"].is_null() && r["frames"].as_u64() > Some(0),
            "{r}"
        );
    }
    let md = std::fs::read_to_string(dir.join("pipeline.md")).unwrap();
    assert!(md.contains("| yaw |"), "{md}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `bench mlp` puts the fused MLP and tract next to the SGEMM peak; a plain MLP (nothing
/// fused) is refused by name.
#[test]
fn mlp_bench_reports_throughput_against_the_peak() {
    let text = stdout_of(
        volcap()
            .current_dir(repo_root())
            .args(["bench", "mlp", "--points", "2000", "--runs", "1"]),
    );
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| what"))
        .collect();
    assert_eq!(rows.len(), 3, "{text}");
    for r in &rows {
        let gflops: f64 = r.split('|').nth(3).unwrap().trim().parse().unwrap();
        assert!(gflops > 0.0 && gflops.is_finite(), "{r}");
    }
    let out = volcap()
        .current_dir(repo_root())
        .args(["bench", "mlp", "--model", "compact-plain-z", "--runs", "1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("shape-compact-plain-z.mlp.onnx"), "{err}");
}

/// `volcap bench queues` as a user runs it: two devices on the adapter, the localization
/// timed alone, beside the shape network on its device and on a second device; each row
/// measured (runs, positive times, the same read-backs a run: the field is a table), the
/// table and its reading written to queues.md; a bad argument named.
#[cfg(feature = "wgpu")]
#[test]
fn bench_queues_times_the_localization_on_one_device_and_on_two() {
    match volcap_engine::gpu::Gpu::open("auto") {
        Ok(g) => println!("adapter: {}", g.adapter.label()),
        Err(e) if std::env::var_os("CI").is_some() => panic!("no GPU adapter under CI: {e}"),
        Err(e) => return println!("skipped: {e}"),
    }
    let out = std::env::temp_dir().join(format!("volcap-queues-{}", std::process::id()));
    let o = volcap()
        .current_dir(repo_root())
        .args([
            "bench",
            "queues",
            "--res",
            "33",
            "--seconds",
            "0.3",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(out.join("queues.md")).unwrap();
    let rows: Vec<Vec<&str>> = md
        .lines()
        .filter(|l| l.starts_with("| first") || l.starts_with("| a second"))
        .map(|l| l.split('|').map(str::trim).collect())
        .collect();
    assert_eq!(rows.len(), 3, "{md}");
    let waits: Vec<f64> = rows.iter().map(|r| r[5].parse().unwrap()).collect();
    for r in &rows {
        let runs: usize = r[2].parse().unwrap();
        let (p50, p90): (f64, f64) = (r[3].parse().unwrap(), r[4].parse().unwrap());
        assert!(runs >= 1 && p50 > 0.0 && p90 >= p50, "{r:?}");
    }
    assert!(
        waits[0] >= 1.0 && waits.iter().all(|w| *w == waits[0]),
        "{waits:?}"
    );
    // The rows beside the network name its rate; the one alone does not.
    assert_eq!(rows[0][6], "-");
    assert!(
        rows[1][6].contains("alone") && rows[2][6].contains("alone"),
        "{md}"
    );
    assert!(md.contains("as long as alone; on a second device"), "{md}");
    let o = volcap()
        .current_dir(repo_root())
        .args(["bench", "queues", "--scene", "nope", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--scene \"nope\": one of"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// `volcap bench nets` with the GPU backend's kernel sets side by side: each runtime a column
/// of positive times for every network, the adapter's own set measured once however often
/// it is listed (on lavapipe `wgpu` and `wgpu-rows` are one set), the baselines labelled; an
/// unknown set named.
#[cfg(feature = "wgpu")]
#[test]
fn bench_nets_puts_the_convolution_kernel_sets_side_by_side() {
    let gpu = match volcap_engine::gpu::Gpu::open("auto") {
        Ok(g) => g,
        Err(e) if std::env::var_os("CI").is_some() => panic!("no GPU adapter under CI: {e}"),
        Err(e) => return println!("skipped: {e}"),
    };
    let out = std::env::temp_dir().join(format!("volcap-nets-{}", std::process::id()));
    let o = volcap()
        .current_dir(repo_root())
        .args([
            "bench",
            "nets",
            "--model",
            "fourier-small-seg2",
            "--runtime",
            "wgpu,wgpu-split,wgpu-rows,wgpu-conv4",
            "--runs",
            "1",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(out.join("nets.md")).unwrap();
    let header = md
        .lines()
        .find(|l| l.starts_with("| network |"))
        .unwrap_or_else(|| panic!("{md}"));
    let columns: Vec<&str> = header.split('|').map(str::trim).collect();
    // (the empty cells before and after the row) network, file, then one column per
    // distinct set: the adapter's own (split or rows) and the two others.
    assert_eq!(columns.len(), 2 + 2 + 3, "{header}");
    assert!(header.contains("(conv4 only)"), "{header}");
    let other = if gpu.adapter.device_type == "cpu" {
        "(split convolutions)"
    } else {
        "(no split convolutions)"
    };
    assert!(header.contains(other), "{header}");
    let rows: Vec<Vec<&str>> = md
        .lines()
        .skip_while(|l| !l.starts_with("| network |"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| l.split('|').map(str::trim).collect())
        .collect();
    assert_eq!(rows.len(), 4, "{md}");
    for r in &rows {
        for ms in &r[3..r.len() - 1] {
            assert!(ms.parse::<f64>().unwrap() > 0.0, "{r:?}");
        }
    }
    let o = volcap()
        .current_dir(repo_root())
        .args(["bench", "nets", "--runtime", "wgpu-bogus", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("wgpu-bogus"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let _ = std::fs::remove_dir_all(&out);
}
