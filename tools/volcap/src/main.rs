//! `volcap`: the command line for benchmarks, evaluation and simulation.

mod backend;
mod bench;
mod ctl;
mod eval;
mod mlp_bench;
mod nets_bench;
mod pipeline_bench;
mod plot;
mod queues_bench;
mod reconstruct;
mod simcmd;

use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "volcap",
    version,
    about = "volcap tools: benchmarks, evaluation, simulation, daemon control"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Benchmarks that put accuracy next to time.
    #[command(subcommand)]
    Bench(BenchCmd),
    /// The full pipeline (segmentation -> shape -> localization -> mesh) on held-out
    /// simulator subjects against ground truth: Chamfer, P2S, IoU, mask IoU, worst 10, time.
    /// (Boxed: its many knobs make it the largest.)
    Eval(Box<eval::EvalArgs>),
    /// Reconstruct people from single images (PNG/JPEG): per image a mask, a mesh (.glb) and
    /// mesh-free renders at yaw 0/90/180/270.
    Reconstruct(reconstruct::ReconstructArgs),
    /// The scene simulator: asset pack, rendering, benchmarks, datasets.
    #[command(subcommand)]
    Sim(simcmd::SimCmd),
    /// Talk to a running volcapd over D-Bus (status, set-view, set-resolution, pause,
    /// resume, reload, snapshot).
    #[command(flatten)]
    Ctl(ctl::CtlCmd),
}

#[derive(Subcommand)]
enum BenchCmd {
    /// Every surface-localization method on the same fields and grids: evaluations, time,
    /// IoU against dense, lost components, band bound. Writes a table and a plot.
    Localize(LocalizeArgs),
    /// The daemon's whole pipeline in this process on a simulated scene, per resolution x
    /// model x coarse level x threads: fps, latency, ms per stage, evaluations, speed-up over
    /// one thread. Writes a table and a plot. (Boxed: its many knobs make it the largest.)
    Pipeline(Box<PipelineArgs>),
    /// Each network on its own (segmentation, shape and colour encoders, the colour MLP on a
    /// frame's surface points): ms per run, and with --profile where tract spends them, per op
    /// kind and node. Writes docs/bench/nets.md.
    Nets(nets_bench::NetsArgs),
    /// The point MLP's throughput (fused and on tract) against the machine's SGEMM peak.
    Mlp(MlpArgs),
    /// GPU backend: whether a stage's waits queue behind another stage's network on one
    /// device, and whether a second device on the same adapter avoids it (the localization
    /// timed alone, beside the shape network on its device, and on a device of its own).
    /// Writes queues.md.
    Queues(queues_bench::QueuesArgs),
    /// The live model path frame by frame on simulated scenes per temporal-filter setting:
    /// flicker on still people, accuracy, jitter and lag on moving ones. Writes a table and
    /// a plot (docs/eval-video).
    Temporal(eval::video::TemporalArgs),
}

#[derive(Args, Debug, Clone)]
pub struct MlpArgs {
    /// Shape model (models/shape-NAME.mlp.onnx, f32, CBN).
    #[arg(long, default_value = "compact")]
    pub model: String,
    /// Points per run.
    #[arg(long, default_value_t = 65536)]
    pub points: usize,
    /// Timed runs (median reported).
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Folder of the ONNX models.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
}

#[derive(Args, Debug, Clone)]
pub struct PipelineArgs {
    /// Scene whose frames are rendered once and replayed.
    #[arg(long, default_value = "tests/scenes/front-walk.toml")]
    pub scene: PathBuf,
    /// Grid resolutions, each 2^L + 1.
    #[arg(long, value_delimiter = ',', default_value = "65,129,257")]
    pub res: Vec<usize>,
    /// Models (NAME or NAME@int8, comma-separated; models/shape-NAME.*).
    #[arg(long = "model", value_delimiter = ',', default_value = volcap_engine::model::DEFAULT_MODEL)]
    pub models: Vec<String>,
    /// Coarsest localization levels (comma-separated).
    #[arg(long = "coarse-level", value_delimiter = ',', default_value = "3")]
    pub coarse_levels: Vec<u32>,
    /// `compute.segment_thread_up_to` values (comma-separated): the largest resolution at
    /// which the segmentation has a thread of its own (0: never).
    #[arg(
        long = "segment-thread-up-to",
        value_delimiter = ',',
        default_value = "129"
    )]
    pub segment_split: Vec<usize>,
    /// Published image sides (`render.display_size`, comma-separated): 0 is the grid's own
    /// resolution, 64..=1024 renders at that display size (the daemon's default is 512).
    #[arg(long = "display-size", value_delimiter = ',', default_value = "0")]
    pub display_sizes: Vec<usize>,
    /// `render.antialias` on and/or off (comma-separated booleans; the daemon's default is
    /// on): the outline's partial pixels against whole ones, what they cost the display part.
    #[arg(long, value_delimiter = ',', default_value = "true")]
    pub antialias: Vec<bool>,
    /// The `[temporal]` filter off and/or on (comma-separated booleans; the daemon's default
    /// is on).
    #[arg(long, value_delimiter = ',', default_value = "true")]
    pub temporal: Vec<bool>,
    /// `[temporal] surface_dead_band` with the filter on (comma-separated; the daemon's
    /// default when not given): what holding the grid's values costs the render stage.
    #[arg(long = "surface-dead-band", value_delimiter = ',')]
    pub surface_dead_band: Vec<f32>,
    /// The render view's yaw about the person (`render.yaw`, degrees, comma-separated): 0 is
    /// the camera's own view, where the surface takes the input pixel's colour; any other
    /// runs the colour networks on the surface points (what turning the view costs).
    #[arg(long = "yaw", value_delimiter = ',', default_value = "0")]
    pub yaws: Vec<f32>,
    /// Runtimes of the networks (`compute.runtime`, comma-separated): tract, onnxruntime,
    /// auto (ONNX Runtime when its library is found, else tract).
    #[arg(long = "runtime", value_delimiter = ',', default_value = "auto")]
    pub runtimes: Vec<String>,
    /// Where the networks run (`compute.backend`, comma-separated): cpu (each --runtime),
    /// wgpu (the GPU backend on --adapter; build with `--features wgpu`).
    #[arg(long = "backend", value_delimiter = ',', default_value = "cpu")]
    pub backends: Vec<String>,
    /// `--backend wgpu`: the adapter, auto or a substring of its name or driver.
    #[arg(long, default_value = "auto")]
    pub adapter: String,
    /// `compute.rounds_per_wait` values (comma-separated, 1..=64): on the GPU backend, the
    /// localization levels' conflict rounds recorded per read-back at most.
    #[arg(long = "rounds-per-wait", value_delimiter = ',', default_value = "1")]
    pub rounds_per_wait: Vec<usize>,
    /// `compute.render_device` values (comma-separated): auto (the daemon's default: own on a
    /// GPU, shared on lavapipe), shared (the networks' device, one queue) and/or own (the
    /// render stage on a second device of the adapter, the maps crossing the host; `bench
    /// queues` measures the mechanism). Each row names the device it used.
    #[arg(long = "render-device", value_delimiter = ',', default_value = "auto")]
    pub render_devices: Vec<String>,
    /// `compute.render_workers` values (comma-separated, 1..=4): render stage threads, each
    /// with its own renderer (and on the GPU backend its own renderer on the adapter, on its
    /// own device where `--render-device` gives it one), frames published in capture order.
    #[arg(long = "render-workers", value_delimiter = ',', default_value = "1")]
    pub render_workers: Vec<usize>,
    /// `compute.segment_workers` values (comma-separated, 1..=4): segment stage threads
    /// (where the segmentation has one: `--segment-thread-up-to`), their people handed on
    /// in capture order.
    #[arg(long = "segment-workers", value_delimiter = ',', default_value = "1")]
    pub segment_workers: Vec<usize>,
    /// `compute.round_waits` values (comma-separated): per-round (the default: the render
    /// stage reads the levels' conflict loop after each round) and/or per-frame (each
    /// level's rounds predicted from the last frame, one read-back for the levels; a frame
    /// the prediction fell short of runs again, counted in the row's note).
    #[arg(
        long = "round-waits",
        value_delimiter = ',',
        default_value = "per-round"
    )]
    pub round_waits: Vec<String>,
    /// `model.segment_passes` values (comma-separated, 1 or 2): 2 segments each frame's
    /// person crop again (one more segmentation a frame; its accuracy in `volcap eval
    /// --segment-passes 1,2`). Unset: each model as it was trained (its file's
    /// `volcap.segment_passes`), as `volcapd` runs it.
    #[arg(long = "segment-passes", value_delimiter = ',')]
    pub segment_passes: Vec<u8>,
    /// `model.segment_full_every` values (comma-separated, 1..=30): with two passes the
    /// whole frame is segmented every this many frames, the frames between only the last
    /// frame's person's crop (one segmentation a frame instead of two; its accuracy in
    /// `volcap bench temporal --setting default,default+segment_full_every=8`). 1 segments
    /// every frame whole.
    #[arg(
        long = "segment-full-every",
        value_delimiter = ',',
        default_value = "1"
    )]
    pub segment_full_every: Vec<u32>,
    /// `render.drop_apart` values (comma-separated fractions of the grid's side in [0, 1]):
    /// inside pieces farther than this from the body left out of the render (0: kept; what
    /// the pass costs; its accuracy in `volcap eval --drop-apart`).
    #[arg(long = "drop-apart", value_delimiter = ',', default_value = "0.1")]
    pub drop_apart: Vec<f32>,
    /// Threads (`compute.threads`, comma-separated); rows with 1 are the baseline.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    pub threads: Vec<usize>,
    /// Seconds measured per configuration.
    #[arg(long, default_value_t = 8.0)]
    pub seconds: f64,
    /// Seconds run before measuring (model warm-up, buffers).
    #[arg(long, default_value_t = 3.0)]
    pub warmup: f64,
    /// Rate of the replayed camera (above what the pipeline reaches, so it never caps it).
    #[arg(long, default_value_t = 60.0)]
    pub fps: f64,
    /// Frames of the scene rendered and looped.
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Folder of the ONNX models.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// JSON Lines on stdout (one object per row); files are then written only if --out is given.
    #[arg(long)]
    pub json: bool,
    /// Folder for pipeline.md and pipeline.png (default docs/bench).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug, Clone)]
pub struct LocalizeArgs {
    /// Scene to measure (repeatable). Default: every analytic scene.
    #[arg(long = "scene", value_name = "NAME")]
    pub scenes: Vec<String>,
    /// Grid resolutions, each 2^L + 1.
    #[arg(long, value_delimiter = ',', default_value = "65,129,257,513")]
    pub res: Vec<usize>,
    /// Methods (comma-separated): dense, mise, octree-threshold (every threshold) or
    /// octree-threshold@T, hierarchical, hierarchical-unseeded (the field's seeds ignored: the
    /// paper's method exactly), hierarchical-no-conflict, hierarchical-tight, demo-faster (the
    /// public demo's "faster" mode). Default: all. Dense always runs (it is the reference).
    #[arg(long, value_delimiter = ',')]
    pub methods: Vec<String>,
    #[arg(long, help = coarse_level_help())]
    pub coarse_level: Option<u32>,
    /// Timed runs per row (median reported); fewer when a row exceeds --time-budget.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Seconds of timed runs per row after which no further run is started.
    #[arg(long, default_value_t = 2.0)]
    pub time_budget: f64,
    /// JSON Lines on stdout (one object per row, nothing else on stdout); files are then
    /// written only if --out is given.
    #[arg(long)]
    pub json: bool,
    /// Folder for accuracy-vs-time.md and accuracy-vs-time.png (default docs/bench).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Trained models (NAME or NAME@int8, repeatable): measure on the network's field for
    /// each simulator scene (default front-walk) instead of the analytic/oracle fields.
    #[arg(long = "model", value_name = "NAME[@int8]")]
    pub models: Vec<String>,
    /// Folder of the ONNX models.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// Scene drawn in the plot (default capsule-human if measured, else the first scene).
    #[arg(long)]
    pub plot_scene: Option<String>,
    /// Threads for field evaluation (each batch split across them; the values and the
    /// evaluated points do not change).
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// With --model: where the networks and the Fourier series run (comma-separated: a row
    /// set each), cpu (tract) or wgpu (the
    /// GPU backend: every field evaluation of the localization one dispatch on the adapter;
    /// the localization's own bookkeeping stays on the CPU). Build with `--features wgpu`.
    #[arg(long = "backend", value_delimiter = ',', default_value = "cpu")]
    pub backends: Vec<String>,
    /// `--backend wgpu`, the `@adapter` rows: conflict rounds recorded per read-back at most
    /// (comma-separated: a row set each; batches of 1, 2, 4, ... up to it). The evaluated
    /// points and the surface do not depend on it; the read-backs the host waits for do.
    /// The default is the engine's (`gpu::localize::DEFAULT_ROUNDS_PER_WAIT`, which a build
    /// without the GPU backend does not have).
    #[arg(long, value_delimiter = ',', default_value = "1")]
    pub rounds_per_wait: Vec<usize>,
    /// `--backend wgpu`, the `@adapter` rows: when the host reads the conflict loop
    /// (comma-separated: a row set each): per-round (after each round or batch) and/or
    /// per-frame (each level's rounds predicted from the run before: one read-back a run;
    /// the runs of a row localize the same field, so the prediction holds after the first).
    #[arg(
        long = "round-waits",
        value_delimiter = ',',
        default_value = "per-round"
    )]
    pub round_waits: Vec<String>,
    /// `--backend wgpu`: the adapter, auto or a substring of its name or driver.
    #[arg(long, default_value = "auto")]
    pub adapter: String,
}

/// The `--coarse-level` help, from the engine's constants (so it cannot drift from them).
fn coarse_level_help() -> String {
    use volcap_engine::localize::{DEFAULT_COARSE_LEVEL, DEMO_COARSE_LEVEL};
    let n = |l: u32| (1usize << l) + 1;
    format!(
        "Coarsest level of the coarse-to-fine methods (default {DEFAULT_COARSE_LEVEL}, i.e. {}^3; \
         the public demo starts at {DEMO_COARSE_LEVEL}, i.e. {}^3)",
        n(DEFAULT_COARSE_LEVEL),
        n(DEMO_COARSE_LEVEL)
    )
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let res = match cli.cmd {
        Cmd::Bench(BenchCmd::Localize(a)) => bench::localize(&a),
        Cmd::Bench(BenchCmd::Pipeline(a)) => pipeline_bench::run(&a),
        Cmd::Bench(BenchCmd::Mlp(a)) => mlp_bench::run(&a),
        Cmd::Bench(BenchCmd::Nets(a)) => nets_bench::run(&a),
        Cmd::Bench(BenchCmd::Temporal(a)) => eval::video::run(&a),
        Cmd::Bench(BenchCmd::Queues(a)) => queues_bench::run(&a),
        Cmd::Eval(a) => eval::eval(&a),
        Cmd::Reconstruct(a) => reconstruct::reconstruct(&a),
        Cmd::Sim(c) => simcmd::run(c),
        Cmd::Ctl(c) => ctl::run(c),
    };
    match res {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("volcap: error: {e:#}");
            ExitCode::from(2)
        }
    }
}

#[cfg(all(test, feature = "wgpu"))]
mod tests {
    use super::*;

    /// `bench localize --rounds-per-wait` defaults to what the daemon's localizer uses.
    #[test]
    fn rounds_per_wait_defaults_to_the_engines() {
        let cli = Cli::try_parse_from(["volcap", "bench", "localize"]).unwrap();
        let Cmd::Bench(BenchCmd::Localize(a)) = cli.cmd else {
            panic!("not bench localize")
        };
        assert_eq!(
            a.rounds_per_wait,
            [volcap_engine::gpu::localize::DEFAULT_ROUNDS_PER_WAIT]
        );
    }
}
