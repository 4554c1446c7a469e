//! `volcap bench pipeline`: the daemon's whole pipeline (capture -> segment + encode ->
//! localize + render -> JPEG -> publish) run in this process for a few seconds per
//! configuration (resolution x model x coarse level x threads), on a simulated scene's frames
//! rendered once beforehand and replayed faster than the pipeline can take them (so the
//! camera and the simulator cost nothing and never cap the rate). Writes a table and a plot:
//! fps, end-to-end latency, ms per stage, field evaluations per frame, and the ratio to the
//! single-threaded run of the same configuration measured in the same invocation.

use crate::PipelineArgs;
use anyhow::{Context, anyhow, bail};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use volcap_engine::model::temporal::TemporalSettings;
use volcap_engine::model::{Models, Precision, Runtime, RuntimeChoice};
use volcapd::capture::Camera;
use volcapd::capture::replay::{ReplayCamera, Still};
use volcapd::config::{Config, RenderDevice, RoundWaits};
use volcapd::pipeline::{self, PipelineState, Shared, stage};

mod report;
use report::{parts_table, plot, table};

/// One configuration's measurement.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub model: String,
    /// What ran the networks ("tract", "onnxruntime 1.32.0").
    pub runtime: String,
    pub resolution: usize,
    pub coarse_level: u32,
    pub threads: usize,
    /// `compute.segment_thread_up_to` of the run.
    pub segment_thread_up_to: usize,
    /// `render.display_size` of the run (0: the grid's resolution).
    pub display_size: usize,
    /// `render.antialias` of the run (rows written before it: whole pixels).
    #[serde(default)]
    pub antialias: bool,
    /// `[temporal] enabled` of the run.
    pub temporal: bool,
    /// `[temporal] surface_dead_band` of the run (0 with the filter off; rows written
    /// before the setting: 0, none).
    #[serde(default)]
    pub surface_dead_band: f32,
    /// `render.yaw` of the run, degrees (0: the camera's view).
    pub yaw_deg: f32,
    /// Frames published per second over the measured window.
    pub fps: f64,
    pub latency_p50_ms: f64,
    pub latency_p99_ms: f64,
    /// p50 ms per stage, in `volcapd::pipeline::STAGES` order (capture, segment, field,
    /// render, encode).
    pub stage_p50_ms: [f64; 5],
    /// Model mode: the mean ms of each part of the segment, field and render stages
    /// (`volcapd::pipeline::part::NAMES` order), with the three stages' means; empty otherwise.
    pub part_mean_ms: Vec<f64>,
    pub segment_mean_ms: f64,
    pub field_mean_ms: f64,
    pub render_mean_ms: f64,
    /// Occupancy evaluations per rendered frame.
    pub evaluations: f64,
    pub frames: u64,
    pub seconds: f64,
    /// fps over the fps of the same (model, resolution, coarse level) with one thread.
    pub speedup_vs_1_thread: Option<f64>,
    /// Bytes written to and read back from the adapter per published frame, and compute
    /// dispatches per frame (0 off the GPU).
    pub bytes_up_per_frame: f64,
    pub bytes_down_per_frame: f64,
    pub dispatches_per_frame: f64,
    /// Read-backs the host waited for per frame (each a round trip to the adapter).
    pub waits_per_frame: f64,
    /// Networks planned and made real on the adapter during the measured seconds (after the
    /// warm-up: 0 when every shape the frames use has its plan).
    pub net_plans: u64,
    /// The networks' milliseconds on the adapter per frame (timestamp queries; 0 without).
    pub adapter_ms_per_frame: f64,
    /// `compute.rounds_per_wait` (the GPU backend's localization levels).
    pub rounds_per_wait: usize,
    /// `compute.render_device` ("shared" or "own").
    pub render_device: &'static str,
    /// `compute.render_workers`: the render stage's threads.
    pub render_workers: usize,
    /// `compute.segment_workers`: the segment stage's threads.
    pub segment_workers: usize,
    /// `compute.round_waits` ("per-round" or "per-frame").
    pub round_waits: &'static str,
    /// Frames whose levels' rounds were predicted, and those of them run again, per frame.
    pub predicted_per_frame: f64,
    pub reruns_per_frame: f64,
    /// `model.segment_passes`.
    pub segment_passes: u8,
    /// `model.segment_full_every` (1: every frame segmented whole).
    pub segment_full_every: u32,
    /// `render.drop_apart` (0: pieces apart from the body kept).
    pub drop_apart: f32,
    /// The adapter's milliseconds per frame, as `adapter_ms_per_frame`, of the frames'
    /// Fourier maps (interleave and temporal filter), of localization and the render's final
    /// level, and of the display image.
    pub maps_ms_per_frame: f64,
    pub localize_ms_per_frame: f64,
    pub display_ms_per_frame: f64,
    /// Why the run produced no frames, if it did not.
    pub error: Option<String>,
}

fn model_spec(s: &str) -> anyhow::Result<(String, Precision)> {
    match s.split_once('@') {
        None => Ok((s.to_string(), Precision::F32)),
        Some((n, "int8")) => Ok((n.to_string(), Precision::Int8)),
        Some((_, p)) => bail!("--model {s}: unknown precision '{p}' (NAME or NAME@int8)"),
    }
}

/// Render `n` frames of `scene` with the simulator (the frames the replay camera loops).
fn frames(scene: &Path, n: usize) -> anyhow::Result<Vec<Still>> {
    let assets = volcap_sim::HumanAssets::embedded().map_err(|e| anyhow!("{e}"))?;
    let s = volcap_sim::Scene::load(scene).map_err(|e| anyhow!("{e}"))?;
    let mut sim = volcap_sim::Simulator::new(s, Arc::new(assets)).map_err(|e| anyhow!("{e}"))?;
    let pb = ProgressBar::new(n as u64).with_style(
        ProgressStyle::with_template("frames {bar:30} {pos}/{len}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let f = sim
            .render(i as u64)
            .map_err(|e| anyhow!("{}: frame {i}: {e}", scene.display()))?;
        out.push(Still {
            rgb: Arc::new(f.rgb),
            width: f.width,
            height: f.height,
        });
        pb.inc(1);
    }
    pb.finish_and_clear();
    Ok(out)
}

/// One configuration: model, precision, resolution, coarse level, threads, segment split,
/// display size, temporal filter on (and its surface dead band), view yaw.
type Setup = (
    String,
    Precision,
    usize,
    u32,
    usize,
    usize,
    (usize, bool),
    (bool, f32),
    f32,
    (
        usize,
        RoundWaits,
        RenderDevice,
        (u8, u32),
        f32,
        (usize, usize),
    ),
);

/// A loaded model set: name, precision, runtime index, segmentation passes.
type ModelKey = (String, Precision, usize, u8);

fn config(scene: &Path, models_dir: &Path, setup: &Setup, runtime: &str) -> anyhow::Result<Config> {
    let (
        name,
        prec,
        res,
        coarse,
        threads,
        split,
        (display, antialias),
        (temporal, band),
        yaw,
        (rounds, waits, device, (passes, full_every), apart, (workers, seg_workers)),
    ) = setup;
    let device = device.name();
    let waits = waits.name();
    let text = format!(
        "description = \"volcap bench pipeline\"\n[camera]\nbackend = \"sim\"\nscene = {scene:?}\n\
         [render]\nresolution = {res}\ncoarse_level = {coarse}\nfield = \"model\"\ndisplay_size = {display}\nantialias = {antialias}\nyaw = {yaw:?}\ndrop_apart = {apart:?}\n\
         [model]\nname = {name:?}\nprecision = \"{}\"\ndir = {models_dir:?}\nsegment_passes = {passes}\nsegment_full_every = {full_every}\n\
         [compute]\nthreads = {threads}\nsegment_thread_up_to = {split}\nruntime = {runtime:?}\nrounds_per_wait = {rounds}\nround_waits = {waits:?}\nrender_device = {device:?}\nrender_workers = {workers}\nsegment_workers = {seg_workers}\n\
         [dbus]\nbus = \"none\"\n\
         [temporal]\nenabled = {temporal}\nsurface_dead_band = {band:?}\n",
        match prec {
            Precision::F32 => "f32",
            Precision::Int8 => "int8",
        },
    );
    Config::parse(&text, Path::new("<volcap bench pipeline>")).map_err(|e| anyhow!("{e}"))
}

/// Run the pipeline on `cfg` for `warmup + seconds` and measure the last `seconds`.
fn measure(
    cfg: &Config,
    models: Arc<Models>,
    stills: Arc<Vec<Still>>,
    fps: f64,
    warmup: f64,
    seconds: f64,
) -> Row {
    let (tx, _rx) = tokio::sync::watch::channel(None);
    let shared = Arc::new(Shared::new(cfg, "replay".into(), tx));
    let factory: volcapd::capture::CameraFactory =
        Box::new(move || Ok(Box::new(ReplayCamera::new(stills, fps)) as Box<dyn Camera>));
    let runtime = models.runtime.label();
    let rt = models.runtime.clone();
    // The device asked for; the one the render stage opened, once it has (`auto` without a
    // second device shares the networks').
    let asked = pipeline::render_device(cfg, Some(&models)).name();
    let threads = pipeline::start(cfg, factory, shared.clone(), Some(models));
    std::thread::sleep(Duration::from_secs_f64(warmup));
    let t0 = Instant::now();
    let published0 = shared.e2e.frames.load(Ordering::Relaxed);
    let rendered0 = shared.stats[stage::RENDER].frames.load(Ordering::Relaxed);
    let evals0 = shared.evaluations.load(Ordering::Relaxed);
    let work0 = crate::backend::adapter_work(&rt);
    std::thread::sleep(Duration::from_secs_f64(seconds));
    let work1 = crate::backend::adapter_work(&rt);
    let wall = t0.elapsed().as_secs_f64();
    let published = shared.e2e.frames.load(Ordering::Relaxed) - published0;
    let rendered = shared.stats[stage::RENDER].frames.load(Ordering::Relaxed) - rendered0;
    let evals = shared.evaluations.load(Ordering::Relaxed) - evals0;
    let (l50, l99, _) = shared.e2e.window(t0);
    let stage_p50_ms = std::array::from_fn(|i| shared.stats[i].window(t0).0);
    let part_mean_ms = if shared.mode == "model" {
        shared.parts.iter().map(|p| p.mean(t0)).collect()
    } else {
        Vec::new()
    };
    let segment_mean_ms = shared.stats[stage::SEGMENT].mean(t0);
    let field_mean_ms = shared.stats[stage::FIELD].mean(t0);
    let render_mean_ms = shared.stats[stage::RENDER].mean(t0);
    let error = match &*shared.state.lock().unwrap_or_else(|p| p.into_inner()) {
        PipelineState::Failed(r) | PipelineState::Degraded(r) => Some(r.clone()),
        _ if published == 0 => Some("no frame published".into()),
        _ => None,
    };
    let render_device = shared.compute.render_device.get().copied().unwrap_or(asked);
    shared.stop.store(true, Ordering::Relaxed);
    for t in threads {
        let _ = t.join();
    }
    Row {
        model: cfg.model.name.clone()
            + match cfg.model.precision {
                volcapd::config::Precision::F32 => "",
                volcapd::config::Precision::Int8 => "@int8",
            },
        runtime,
        resolution: cfg.render.resolution.0,
        coarse_level: cfg.render.coarse_level,
        threads: cfg.compute.threads,
        segment_thread_up_to: cfg.compute.segment_thread_up_to,
        display_size: cfg.render.display_size,
        antialias: cfg.render.antialias,
        temporal: cfg.temporal.enabled,
        surface_dead_band: cfg.temporal.settings().map_or(0.0, |t| t.surface_dead_band),
        yaw_deg: cfg.render.yaw,
        fps: published as f64 / wall,
        latency_p50_ms: l50,
        latency_p99_ms: l99,
        stage_p50_ms,
        part_mean_ms,
        segment_mean_ms,
        field_mean_ms,
        render_mean_ms,
        evaluations: evals as f64 / rendered.max(1) as f64,
        frames: published,
        seconds: wall,
        speedup_vs_1_thread: None,
        bytes_up_per_frame: (work1[0] - work0[0]) as f64 / published.max(1) as f64,
        bytes_down_per_frame: (work1[1] - work0[1]) as f64 / published.max(1) as f64,
        dispatches_per_frame: (work1[2] - work0[2]) as f64 / published.max(1) as f64,
        waits_per_frame: (work1[4] - work0[4]) as f64 / published.max(1) as f64,
        net_plans: work1[5] - work0[5],
        adapter_ms_per_frame: (work1[3] - work0[3]) as f64 / 1e6 / published.max(1) as f64,
        rounds_per_wait: cfg.compute.rounds_per_wait,
        render_device,
        render_workers: cfg.compute.render_workers,
        segment_workers: cfg.compute.segment_workers,
        round_waits: cfg.compute.round_waits.name(),
        predicted_per_frame: (work1[9] - work0[9]) as f64 / published.max(1) as f64,
        reruns_per_frame: (work1[10] - work0[10]) as f64 / published.max(1) as f64,
        segment_passes: cfg.model.segment_passes.unwrap_or(1),
        segment_full_every: cfg.model.segment_full_every,
        drop_apart: cfg.render.drop_apart,
        maps_ms_per_frame: (work1[6] - work0[6]) as f64 / 1e6 / published.max(1) as f64,
        localize_ms_per_frame: (work1[7] - work0[7]) as f64 / 1e6 / published.max(1) as f64,
        display_ms_per_frame: (work1[8] - work0[8]) as f64 / 1e6 / published.max(1) as f64,
        error,
    }
}

pub fn run(a: &PipelineArgs) -> anyhow::Result<()> {
    if !(a.seconds > 0.0 && a.seconds <= 600.0 && a.warmup >= 0.0 && a.warmup <= 600.0) {
        bail!("--seconds must be in (0, 600] and --warmup in [0, 600]");
    }
    if let Some(y) = a.yaws.iter().find(|y| !(-180.0..=180.0).contains(*y)) {
        bail!("--yaw {y}: need degrees in [-180, 180]");
    }
    if let Some(v) = a
        .segment_split
        .iter()
        .find(|v| **v != 0 && ![33, 65, 129, 257, 513].contains(*v))
    {
        bail!("--segment-thread-up-to {v} must be 0 (never) or one of 33, 65, 129, 257, 513");
    }
    if let Some(r) = a.rounds_per_wait.iter().find(|r| !(1..=64).contains(*r)) {
        bail!("--rounds-per-wait {r} must be in 1..=64");
    }
    for (flag, values, range) in [
        (
            "--render-workers",
            &a.render_workers,
            volcapd::config::RENDER_WORKERS,
        ),
        (
            "--segment-workers",
            &a.segment_workers,
            volcapd::config::SEGMENT_WORKERS,
        ),
    ] {
        if let Some(w) = values.iter().find(|w| !range.contains(*w)) {
            bail!("{flag} {w} must be in {range:?}");
        }
    }
    let render_devices = crate::backend::by_names(
        "--render-device",
        &a.render_devices,
        &RenderDevice::ALL,
        RenderDevice::name,
    )?;
    let round_waits = crate::backend::by_names(
        "--round-waits",
        &a.round_waits,
        &RoundWaits::ALL,
        RoundWaits::name,
    )?;
    if !a.segment_passes.is_empty() {
        crate::backend::check_segment_passes(&a.segment_passes)?;
    }
    let every = &volcapd::config::SEGMENT_FULL_EVERY;
    if let Some(n) = a.segment_full_every.iter().find(|n| !every.contains(*n)) {
        bail!("--segment-full-every {n} must be in {every:?}");
    }
    for &g in &a.drop_apart {
        volcap_engine::pieces::gap_setting(g).map_err(|e| anyhow!("--drop-apart {e}"))?;
    }
    if a.frames == 0 || a.frames > 600 {
        bail!("--frames {} must be in 1..=600", a.frames);
    }
    let scene = a
        .scene
        .canonicalize()
        .with_context(|| format!("--scene {}", a.scene.display()))?;
    let models_dir = a
        .models_dir
        .canonicalize()
        .with_context(|| format!("--models-dir {}", a.models_dir.display()))?;
    let mut runtimes = Vec::new();
    for b in &a.backends {
        if b.trim() != "cpu" {
            // The GPU backend: one runtime whatever --runtime says (the CPU's choice).
            let (rt, _) = crate::backend::open(b, "tract", &a.adapter)?;
            runtimes.push((RuntimeChoice::Tract, rt));
            continue;
        }
        for r in &a.runtimes {
            let choice = RuntimeChoice::parse(r.trim()).map_err(|e| anyhow!("--runtime: {e}"))?;
            let opened = Runtime::open(choice, None).map_err(|e| anyhow!("--runtime {r}: {e}"))?;
            if let Some(why) = &opened.fallback {
                eprintln!("--runtime {r}: on tract ({why})");
            }
            runtimes.push((choice, opened.runtime));
        }
    }
    let mut configs = Vec::new();
    for m in &a.models {
        let (name, prec) = model_spec(m)?;
        // Unset: the model's own count, as volcapd runs it.
        let passes_of_model = if a.segment_passes.is_empty() {
            vec![
                volcap_engine::model::trained_segment_passes(&models_dir, &name, prec)
                    .map_err(|e| anyhow!("model {name}: {e}"))?,
            ]
        } else {
            a.segment_passes.clone()
        };
        // The track only where there are two passes (one pass has no crop to track: one
        // untracked row).
        let passes_of_model: Vec<(u8, u32)> = passes_of_model
            .iter()
            .flat_map(|&p| match p {
                1 => vec![(1, 1)],
                _ => a.segment_full_every.iter().map(|&f| (p, f)).collect(),
            })
            .collect();
        for &res in &a.res {
            for &c in &a.coarse_levels {
                for &split in &a.segment_split {
                    for d in a
                        .display_sizes
                        .iter()
                        .flat_map(|&d| a.antialias.iter().map(move |&aa| (d, aa)))
                    {
                        let bands = if a.surface_dead_band.is_empty() {
                            vec![TemporalSettings::default().surface_dead_band]
                        } else {
                            a.surface_dead_band.clone()
                        };
                        // The band only with the filter on.
                        let filters = a.temporal.iter().flat_map(|&on| {
                            let bands = if on { bands.clone() } else { vec![0.0] };
                            bands.into_iter().map(move |b| (on, b))
                        });
                        for tf in filters {
                            for &yaw in &a.yaws {
                                for (&rounds, &waits) in a
                                    .rounds_per_wait
                                    .iter()
                                    .flat_map(|r| round_waits.iter().map(move |w| (r, w)))
                                {
                                    for (&dev, &passes) in render_devices
                                        .iter()
                                        .flat_map(|d| passes_of_model.iter().map(move |p| (d, p)))
                                    {
                                        for ((&apart, &t), workers) in a
                                            .drop_apart
                                            .iter()
                                            .flat_map(|p| a.threads.iter().map(move |t| (p, t)))
                                            .flat_map(|pt| {
                                                a.render_workers.iter().flat_map(move |w| {
                                                    a.segment_workers
                                                        .iter()
                                                        .map(move |sw| (pt, (*w, *sw)))
                                                })
                                            })
                                        {
                                            configs.push((
                                                name.clone(),
                                                prec,
                                                res,
                                                c,
                                                t,
                                                split,
                                                d,
                                                tf,
                                                yaw,
                                                (rounds, waits, dev, passes, apart, workers),
                                            ));
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    // Every configuration (per runtime) is checked before anything runs.
    let mut runs: Vec<(Config, &Setup, usize)> = Vec::new();
    for (ri, (choice, _)) in runtimes.iter().enumerate() {
        for s in &configs {
            runs.push((config(&scene, &models_dir, s, choice.as_str())?, s, ri));
        }
    }
    // Every model is loaded before anything runs (a bad name fails at once).
    // (The segmentation passes are the models' own setting, as in volcapd: a copy each.)
    let mut loaded: Vec<(ModelKey, Arc<Models>)> = Vec::new();
    let key = |cfg: &Config, name: &String, prec: &Precision, ri: &usize| -> ModelKey {
        (
            name.clone(),
            *prec,
            *ri,
            cfg.model.segment_passes.unwrap_or(1),
        )
    };
    for (cfg, (name, prec, ..), ri) in &runs {
        let k = key(cfg, name, prec, ri);
        if !loaded.iter().any(|(l, _)| *l == k) {
            let rt = &runtimes[*ri].1;
            let m = Models::load_on(&models_dir, name, *prec, rt).map_err(|e| {
                anyhow!(
                    "model {name} in {} on {}: {e}",
                    models_dir.display(),
                    rt.label()
                )
            })?;
            let m = Models {
                segment_passes: k.3,
                ..m
            };
            loaded.push((k, Arc::new(m)));
        }
    }
    let stills = Arc::new(frames(&scene, a.frames)?);
    let pb = ProgressBar::new(runs.len() as u64).with_style(
        ProgressStyle::with_template("pipeline {bar:30} {pos}/{len} {msg} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    for (cfg, (name, prec, ..), ri) in &runs {
        pb.set_message(format!(
            "{name} {} x{} {}",
            cfg.render.resolution.0,
            cfg.compute.threads,
            runtimes[*ri].1.name()
        ));
        let k = key(cfg, name, prec, ri);
        let Some((_, models)) = loaded.iter().find(|(l, _)| *l == k) else {
            bail!("model {name} was not loaded");
        };
        rows.push(measure(
            cfg,
            models.clone(),
            stills.clone(),
            a.fps,
            a.warmup,
            a.seconds,
        ));
        pb.inc(1);
    }
    pb.finish_and_clear();
    // The one-thread row of the same configuration (all but the threads), same run.
    let base: Vec<Row> = rows
        .iter()
        .filter(|r| r.threads == 1 && r.error.is_none())
        .cloned()
        .collect();
    for r in &mut rows {
        r.speedup_vs_1_thread = base
            .iter()
            .find(|b| {
                b.model == r.model
                    && b.runtime == r.runtime
                    && b.resolution == r.resolution
                    && b.coarse_level == r.coarse_level
                    && b.segment_thread_up_to == r.segment_thread_up_to
                    && b.display_size == r.display_size
                    && b.antialias == r.antialias
                    && b.temporal == r.temporal
                    && b.surface_dead_band == r.surface_dead_band
                    && b.yaw_deg == r.yaw_deg
                    && b.rounds_per_wait == r.rounds_per_wait
                    && b.render_device == r.render_device
                    && b.render_workers == r.render_workers
                    && b.segment_workers == r.segment_workers
                    && b.round_waits == r.round_waits
                    && b.segment_passes == r.segment_passes
                    && b.segment_full_every == r.segment_full_every
                    && b.drop_apart == r.drop_apart
            })
            .map(|b| r.fps / b.fps.max(1e-9));
    }
    if a.json {
        let mut out = std::io::stdout().lock();
        for r in &rows {
            writeln!(out, "{}", serde_json::to_string(r)?)?;
        }
    } else {
        print!("{}{}", table(&rows), parts_table(&rows));
    }
    if !a.json || a.out.is_some() {
        let dir = a.out.clone().unwrap_or_else(|| PathBuf::from("docs/bench"));
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let md = dir.join("pipeline.md");
        let cmd: Vec<String> = std::env::args().collect();
        let text = format!(
            "# The whole pipeline, in process\n\n`{}`\n\nScene `{}` ({} frames rendered once, replayed at {} fps); \
             {} s measured after {} s of warm-up per row; {} cores. fps = frames published per second; \
             latency = capture to publish; stages are p50 ms (on threads of their own: frame N+2 is \
             segmented while N+1 is encoded (field) and N localized and rendered); evaluations = occupancy \
             evaluations per rendered frame; x1 = fps over the one-thread row of the same model, \
             resolution and coarse level, measured in the same run. Each row is one run of a few seconds: on a \
             shared 2-core machine repeated runs of the same row differ by up to about 10 %, so compare rows \
             of one run.\n\n{}{}",
            cmd.join(" "),
            a.scene.display(),
            a.frames,
            a.fps,
            a.seconds,
            a.warmup,
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            table(&rows) + &parts_table(&rows),
            if rows.iter().any(|r| r.runtime.contains("llvmpipe")) {
                "\nRows on `wgpu llvmpipe` ran the GPU backend's kernels on Mesa's lavapipe, Vulkan emulated \
                 on this CPU: their times say nothing about a GPU (the kernels are written for thousands of \
                 GPU threads, not for two cores); they show that the path runs whole and what crosses \
                 between host and adapter per frame.\n"
            } else {
                ""
            }
        );
        std::fs::write(&md, text).with_context(|| format!("writing {}", md.display()))?;
        let png = dir.join("pipeline.png");
        plot(&rows, &png)?;
        eprintln!("wrote {} and {}", md.display(), png.display());
    }
    if rows.iter().all(|r| r.error.is_some()) {
        bail!("no configuration published a frame");
    }
    Ok(())
}
