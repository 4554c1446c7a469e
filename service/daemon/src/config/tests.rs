use super::*;

#[test]
fn shipped_sim_config_parses() {
    let p = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../board-config/sim.toml"
    ));
    let c = Config::load(p).unwrap();
    assert_eq!(c.camera.backend, Backend::Sim);
    assert!(c.http.bind.ip().is_loopback());
    let scene = c.scene_path().unwrap();
    assert!(scene.exists(), "{}", scene.display());
}

/// Hardening #5: numbers that passed the check and then broke the daemon.
#[test]
fn out_of_range_and_unhonoured_keys_are_refused_at_load() {
    let base = "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n";
    for (extra, key, line) in [
        (
            "[http]\nheader_timeout_s = 18446744073709551615\n",
            "http.header_timeout_s",
            5,
        ),
        ("[http]\nheader_timeout_s = 0\n", "http.header_timeout_s", 5),
        (
            "[model]\nclose_range_frames = 0\n",
            "model.close_range_frames",
            5,
        ),
        (
            "[model]\nclose_range_frames = 301\n",
            "model.close_range_frames",
            5,
        ),
        (
            "[http]\nheader_timeout_s = 301\n",
            "http.header_timeout_s",
            5,
        ),
    ] {
        let e = Config::parse(&format!("{base}{extra}"), Path::new("b.toml")).unwrap_err();
        assert!(
            e.contains(&format!("line {line}")) && e.contains(key) && e.contains("1..=300"),
            "{extra}: {e}"
        );
    }
    let e = Config::parse(
        &format!("{base}[compute]\nthreads = 1000000\n"),
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("line 5") && e.contains("compute.threads") && e.contains("1..=64"),
        "{e}"
    );
    for bad in [0, 65] {
        let e = Config::parse(
            &format!("{base}[compute]\nrounds_per_wait = {bad}\n"),
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(
            e.contains("line 5") && e.contains("compute.rounds_per_wait") && e.contains("1..=64"),
            "{e}"
        );
    }
    let c = Config::parse(
        &format!("{base}[compute]\nrounds_per_wait = 8\n"),
        Path::new("b.toml"),
    )
    .unwrap();
    assert_eq!(c.compute.rounds_per_wait, 8);
    assert_eq!(c.compute.render_workers, 1);
    for bad in [0, 5] {
        let e = Config::parse(
            &format!("{base}[compute]\nrender_workers = {bad}\n"),
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(
            e.contains("b.toml")
                && e.contains("line 5")
                && e.contains("compute.render_workers")
                && e.contains("1..=4"),
            "{e}"
        );
    }
    let c2 = Config::parse(
        &format!("{base}[compute]\nrender_workers = 2\n"),
        Path::new("b.toml"),
    )
    .unwrap();
    assert_eq!(c2.compute.render_workers, 2);
    assert_eq!(c.compute.segment_workers, 1);
    let e = Config::parse(
        &format!("{base}[compute]\nsegment_workers = 9\n"),
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("line 5") && e.contains("compute.segment_workers") && e.contains("1..=4"),
        "{e}"
    );
    assert_eq!(c.compute.render_device, crate::config::RenderDevice::Auto);
    let c = Config::parse(
        &format!("{base}[compute]\nrender_device = \"own\"\n"),
        Path::new("b.toml"),
    )
    .unwrap();
    assert_eq!(c.compute.render_device, crate::config::RenderDevice::Own);
    let e = Config::parse(
        &format!("{base}[compute]\nrender_device = \"other\"\n"),
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("line 5") && e.contains("render_device") && e.contains("own"),
        "{e}"
    );
    assert_eq!(c.compute.round_waits, crate::config::RoundWaits::PerRound);
    let c = Config::parse(
        &format!("{base}[compute]\nround_waits = \"per-frame\"\n"),
        Path::new("b.toml"),
    )
    .unwrap();
    assert_eq!(c.compute.round_waits, crate::config::RoundWaits::PerFrame);
    let e = Config::parse(
        &format!("{base}[compute]\nround_waits = \"sometimes\"\n"),
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("line 5") && e.contains("round_waits") && e.contains("per-frame"),
        "{e}"
    );
    let e = Config::parse(
        &format!("{base}[compute]\nsegment_thread_up_to = 100\n"),
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("line 5") && e.contains("compute.segment_thread_up_to") && e.contains("100"),
        "{e}"
    );
    for ok in [0, 65, 513] {
        let c = Config::parse(
            &format!("{base}[compute]\nsegment_thread_up_to = {ok}\n"),
            Path::new("b.toml"),
        )
        .unwrap();
        assert_eq!(c.compute.segment_thread_up_to, ok);
    }
    let ok = Config::parse(
        &format!("{base}[http]\nheader_timeout_s = 300\n"),
        Path::new("b.toml"),
    )
    .unwrap();
    assert_eq!(ok.http.header_timeout_s, 300);
}

#[test]
fn errors_name_file_line_and_key() {
    let e = Config::parse(
        "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n[render]\nresolution = 100\n",
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("b.toml")
            && e.contains("line 5")
            && e.contains("resolution")
            && e.contains("257"),
        "{e}"
    );
    let e = Config::parse(
        "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\nfsp = 3\n",
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(e.contains("line 4") && e.contains("fsp"), "{e}");
    // A key of another backend names its line too.
    let e = Config::parse(
        "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n\nfps = 3\n",
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("line 5") && e.contains("camera.fps") && e.contains("does not apply"),
        "{e}"
    );
    let e = Config::parse(
        "[camera]\nbackend = \"v4l2\"\ndevice = \"/dev/video0\"\nwidth = 640\nheight = 480\n",
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(e.contains("camera.fps") && e.contains("required"), "{e}");
    let e = Config::parse(
        "[camera]\nbackend = \"file\"\npath = \"r.mjpg\"\n[render]\nfield = \"oracle\"\n",
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(e.contains("line 5") && e.contains("render.field"), "{e}");
    let e = Config::parse(
        "[camera]\nbackend = \"v4l9\"\nscene = \"x\"\n",
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(e.contains("v4l9"), "{e}");
    let e = Config::parse(
        "[camera]\nbackend = \"sim\"\nscene = \"x\"\n[http]\ntoken = \"abc\"\n",
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(e.contains("token"), "{e}");
}

/// `[temporal]`: on by default with the engine's defaults; a key out of its range names
/// the key, its line and value, on or off; `enabled = false` turns the filter off.
/// `compute.runtime`: auto by default; tract / onnxruntime by name; anything else names the
/// key and the value's line.
#[test]
fn compute_runtime_defaults_and_bad_values() {
    use volcap_engine::model::RuntimeChoice;
    let base = "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n";
    let c = Config::parse(base, Path::new("b.toml")).unwrap();
    assert_eq!(c.compute.runtime, RuntimeChoice::Auto);
    for (v, want) in [
        ("tract", RuntimeChoice::Tract),
        ("onnxruntime", RuntimeChoice::OnnxRuntime),
        ("auto", RuntimeChoice::Auto),
    ] {
        let c = Config::parse(
            &format!("{base}[compute]\nruntime = \"{v}\"\n"),
            Path::new("b.toml"),
        )
        .unwrap();
        assert_eq!(c.compute.runtime, want);
    }
    let e = Config::parse(
        &format!("{base}[compute]\nruntime = \"gpu\"\n"),
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("runtime") && e.contains("gpu") && e.contains("line 5"),
        "{e}"
    );
}

#[test]
fn temporal_section_defaults_bounds_and_off() {
    let base = "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n";
    let c = Config::parse(base, Path::new("b.toml")).unwrap();
    assert_eq!(
        c.temporal.settings(),
        Some(volcap_engine::model::temporal::TemporalSettings::default())
    );
    let c = Config::parse(
        &format!("{base}[temporal]\nmap_beta = 2.5\n"),
        Path::new("b.toml"),
    )
    .unwrap();
    assert_eq!(c.temporal.settings().unwrap().map_beta, 2.5);
    for (extra, key) in [
        ("mask_low = 0.9", "temporal.mask_low"),
        ("mask_high = 1.0", "temporal.mask_high"),
        ("crop_min_cutoff_hz = 0", "temporal.crop_min_cutoff_hz"),
        ("map_beta = -1", "temporal.map_beta"),
        ("max_gap_s = nan", "temporal.max_gap_s"),
        ("mask_hold_frames = 0", "temporal.mask_hold_frames"),
        (
            "mask_still_hold_frames = 256",
            "temporal.mask_still_hold_frames",
        ),
        ("map_change_cutoff_hz = 0", "temporal.map_change_cutoff_hz"),
        ("crop_hold = 0.2", "temporal.crop_hold"),
        ("mask_dead_band = 0.6", "temporal.mask_dead_band"),
        ("surface_dead_band = -0.1", "temporal.surface_dead_band"),
        ("map_motion_weight = 1.5", "temporal.map_motion_weight"),
    ] {
        let e = Config::parse(&format!("{base}[temporal]\n{extra}\n"), Path::new("b.toml"))
            .unwrap_err();
        assert!(e.contains("line 5") && e.contains(key), "{extra}: {e}");
    }
    let c = Config::parse(
        &format!("{base}[temporal]\nenabled = false\n"),
        Path::new("b.toml"),
    )
    .unwrap();
    assert_eq!(c.temporal.settings(), None);
    // Off, a bad value is still an error (it would surface when the filter is turned on).
    assert!(
        Config::parse(
            &format!("{base}[temporal]\nenabled = false\nmask_low = 0.9\n"),
            Path::new("b.toml"),
        )
        .is_err()
    );
}

/// `model.thin_parts`: the series by default, the moment fill by name (with the engine's
/// measured setting), and a misspelt value refused with its file, line and key.
#[test]
fn thin_parts_is_read_and_a_wrong_value_named() {
    let base = "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n";
    let c = Config::parse(base, Path::new("b.toml")).unwrap();
    assert_eq!(c.model.thin_parts, ThinParts::Series);
    assert_eq!(c.model.thin_parts.moment_fill(), None);
    let c = Config::parse(
        &format!("{base}[model]\nthin_parts = \"moment-fill\"\n"),
        Path::new("b.toml"),
    )
    .unwrap();
    assert_eq!(c.model.thin_parts.moment_fill(), Some((0.02, 0.1, 4)));
    let e = Config::parse(
        &format!("{base}[model]\nthin_parts = \"fill\"\n"),
        Path::new("b.toml"),
    )
    .unwrap_err();
    assert!(
        e.contains("b.toml")
            && e.contains("line 5")
            && e.contains("thin_parts")
            && e.contains("moment-fill"),
        "{e}"
    );
}

/// `model.segment_full_every`: 1 (every frame whole) by default, up to 30, and 0 or more
/// refused naming the key, the line and the range.
#[test]
fn segment_full_every_is_read_and_a_wrong_count_named() {
    let base = "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n";
    let c = Config::parse(base, Path::new("b.toml")).unwrap();
    assert_eq!(c.model.segment_full_every, 1);
    for n in [1u32, 8, 30] {
        let c = Config::parse(
            &format!("{base}[model]\nsegment_full_every = {n}\n"),
            Path::new("b.toml"),
        )
        .unwrap();
        assert_eq!(c.model.segment_full_every, n);
    }
    for bad in ["0", "31", "-2", "\"8\""] {
        let e = Config::parse(
            &format!("{base}[model]\nsegment_full_every = {bad}\n"),
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(
            e.contains("b.toml") && e.contains("segment_full_every") && e.contains("line 5"),
            "{bad}: {e}"
        );
    }
}

/// `model.segment_passes`: unset by default (the shape model's own), one or two by choice,
/// and anything else refused naming the key and the range.
#[test]
fn segment_passes_is_read_and_a_wrong_count_named() {
    let base = "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n";
    let c = Config::parse(base, Path::new("b.toml")).unwrap();
    assert_eq!(c.model.segment_passes, None);
    for n in [1u8, 2] {
        let c = Config::parse(
            &format!("{base}[model]\nsegment_passes = {n}\n"),
            Path::new("b.toml"),
        )
        .unwrap();
        assert_eq!(c.model.segment_passes, Some(n));
    }
    for bad in ["0", "3"] {
        let e = Config::parse(
            &format!("{base}[model]\nsegment_passes = {bad}\n"),
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(
            e.contains("b.toml") && e.contains("model.segment_passes") && e.contains("1..=2"),
            "{e}"
        );
    }
}

/// `render.drop_apart`: the engine's gap by default, 0 turns the pass off, and a value out
/// of [0, 1] is refused naming the file and the key.
#[test]
fn drop_apart_is_read_and_a_wrong_value_named() {
    let base = "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n";
    let c = Config::parse(base, Path::new("b.toml")).unwrap();
    let live = Live::from_config(&c);
    assert_eq!(live.drop_apart(), Some(volcap_engine::pieces::DEFAULT_GAP));
    let c = Config::parse(
        &format!("{base}[render]\ndrop_apart = 0\n"),
        Path::new("b.toml"),
    );
    assert_eq!(Live::from_config(&c.unwrap()).drop_apart(), None);
    let c = Config::parse(
        &format!("{base}[render]\ndrop_apart = 0.25\n"),
        Path::new("b.toml"),
    );
    assert_eq!(Live::from_config(&c.unwrap()).drop_apart(), Some(0.25));
    for bad in ["1.5", "-0.1", "nan"] {
        let e = Config::parse(
            &format!("{base}[render]\ndrop_apart = {bad}\n"),
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(
            e.contains("b.toml") && e.contains("drop_apart"),
            "{bad}: {e}"
        );
    }
}

#[test]
fn render_device_auto_is_own_on_a_gpu_and_shared_on_the_cpu() {
    use crate::config::RenderDevice::{Auto, Own, Shared};
    for t in ["discrete", "integrated", "virtual", "other"] {
        assert_eq!(Auto.resolve(Some(t)), Own, "{t}");
    }
    // lavapipe, and no adapter at all (tract or ONNX Runtime run the networks).
    assert_eq!(Auto.resolve(Some("cpu")), Shared);
    assert_eq!(Auto.resolve(None), Shared);
    // A value written in the config is kept whatever the adapter.
    for t in [Some("discrete"), Some("cpu"), None] {
        assert_eq!(Shared.resolve(t), Shared);
        assert_eq!(Own.resolve(t), Own);
    }
    for d in crate::config::RenderDevice::ALL {
        assert_eq!(crate::config::RenderDevice::by_name(d.name()), Some(d));
    }
}

/// `model.map_smooth`: the engine's default passes, 0 to 4 read, anything else refused
/// naming the key, the line and the range.
#[test]
fn map_smooth_is_read_and_a_wrong_count_named() {
    let base = "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n";
    let c = Config::parse(base, Path::new("b.toml")).unwrap();
    assert_eq!(
        c.model.map_smooth,
        volcap_engine::model::fourier::DEFAULT_SMOOTH_PASSES
    );
    for n in [0u8, 1, 4] {
        let c = Config::parse(
            &format!("{base}[model]\nmap_smooth = {n}\n"),
            Path::new("b.toml"),
        )
        .unwrap();
        assert_eq!(c.model.map_smooth, n);
    }
    for bad in ["5", "-1", "1.5", "\"2\""] {
        let e = Config::parse(
            &format!("{base}[model]\nmap_smooth = {bad}\n"),
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(
            e.contains("b.toml") && e.contains("map_smooth") && e.contains("line 5"),
            "{bad}: {e}"
        );
    }
}
