//! `[compute]`: where and how the pipeline computes (threads, the networks' runtime).

use serde::Deserialize;
use std::path::PathBuf;
pub use volcap_engine::localize::RoundWaits;
use volcap_engine::model::RuntimeChoice;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ComputeBackend {
    /// Native threads on the CPU (the engine's localization and renderer, tract).
    #[default]
    Cpu,
    /// The GPU backend (volcapd built with the `wgpu` feature): the networks run in WGSL
    /// compute shaders on `adapter`; the other stages stay on the CPU until their kernels
    /// land (`/state` `compute.on_adapter` lists what runs there).
    Wgpu,
}

impl ComputeBackend {
    pub fn name(&self) -> &'static str {
        match self {
            ComputeBackend::Cpu => "cpu",
            ComputeBackend::Wgpu => "wgpu",
        }
    }
}

/// `compute.fallback`: what a `wgpu` backend does when no adapter matches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ComputeFallback {
    /// Refuse to start (exit 2, the adapters found listed).
    #[default]
    None,
    /// Run on the CPU and say so (log, `/state`, D-Bus `Compute`).
    Cpu,
}

/// `compute.render_device`: which device of the adapter the render stage uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum RenderDevice {
    /// `own` on a GPU, `shared` on the CPU's adapter (lavapipe), [`RenderDevice::resolve`].
    /// Measured (docs/bench/pipeline-gpu.md, third H200 run): on an NVIDIA H200 `own` took the
    /// pipeline from 49.8 to 78.6 fps at 257^3 (fourier-small, 16 cores, the render stage
    /// 17.7 -> 10.6 ms a frame); on lavapipe it lost (0.6 -> 0.4 fps at 65^3: its second
    /// device takes the same CPU cores from the networks).
    #[default]
    Auto,
    /// The networks' device: one queue for every stage; the frame's maps stay on the
    /// adapter from the shape network to the localizer.
    Shared,
    /// A second device on the same adapter: the render stage's read-backs (some ten a frame)
    /// wait for its own work only, not for the networks the other stages submitted before
    /// them; the frame's maps cross the host between the two (read back by the field stage,
    /// written by the render stage: 2 MB each way at K = 15). `volcap bench queues` says
    /// whether the adapter runs two devices side by side; `volcap bench pipeline
    /// --render-device shared,own` what it buys.
    Own,
}

impl RenderDevice {
    pub const ALL: [RenderDevice; 3] =
        [RenderDevice::Auto, RenderDevice::Shared, RenderDevice::Own];

    /// The config value (`volcap bench pipeline --render-device` takes the same).
    pub fn name(&self) -> &'static str {
        match self {
            RenderDevice::Auto => "auto",
            RenderDevice::Shared => "shared",
            RenderDevice::Own => "own",
        }
    }

    /// The value named `name` (as [`Self::name`] writes it).
    pub fn by_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|d| d.name() == name)
    }

    /// The device used on an adapter of `device_type` (`AdapterSummary::device_type`:
    /// "discrete", "integrated", "virtual", "other" or "cpu"; `None` where the networks do
    /// not run on an adapter): `auto` is `own` on any adapter but the CPU's, `shared`
    /// there; `shared` and `own` stay as they are.
    pub fn resolve(self, device_type: Option<&str>) -> RenderDevice {
        match (self, device_type) {
            (RenderDevice::Auto, Some(t)) if t != "cpu" => RenderDevice::Own,
            (RenderDevice::Auto, _) => RenderDevice::Shared,
            (d, _) => d,
        }
    }
}

/// The compute section.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComputeConfig {
    #[serde(default)]
    pub backend: ComputeBackend,
    /// `backend = "wgpu"`: the adapter, `auto` (the most capable found: a discrete GPU,
    /// then integrated, ..., the CPU's lavapipe last) or a case-insensitive substring of
    /// its name or driver ("orin", "llvmpipe").
    #[serde(default = "d_adapter")]
    pub adapter: String,
    /// `backend = "wgpu"` with no adapter matching: `none` (default: startup fails) or `cpu`.
    #[serde(default)]
    pub fallback: ComputeFallback,
    /// Threads that evaluate the field for the render stage (each batch of points split
    /// across them; the image does not change) and that the field stage's networks spread
    /// their matrix products over (tract's pool), [`THREADS`]. The other pipeline stages
    /// have one thread each. More than 1 pays only where a stage leaves a core idle
    /// (`volcap bench pipeline` measures it).
    #[serde(default = "d_threads")]
    pub threads: usize,
    /// Model mode: the largest render resolution at which the segmentation runs on a thread
    /// of its own (a third compute stage: more frames per second where the render stage
    /// leaves a core idle, one stage more of latency); 0 = never. Default 129
    /// ([`DEFAULT_SEGMENT_THREAD_UP_TO`]; `volcap bench pipeline --segment-thread-up-to`).
    #[serde(default = "d_segment_thread_up_to")]
    pub segment_thread_up_to: usize,
    /// What runs the networks (model mode): `tract` (built in), `onnxruntime` (its shared
    /// library, `tools/onnxruntime.sh`; a config error when it cannot be loaded) or `auto`
    /// (ONNX Runtime when its library is found and loads, else tract, logged and shown in
    /// `/state` and D-Bus). Default `auto`.
    #[serde(default)]
    pub runtime: RuntimeChoice,
    /// ONNX Runtime's library (`libonnxruntime.so`); default: searched in
    /// `$VOLCAP_ONNXRUNTIME`, `/usr/lib/volcap/onnxruntime/`, `target/onnxruntime/`.
    #[serde(default)]
    pub onnxruntime_lib: Option<PathBuf>,
    /// `backend = "wgpu"`: conflict rounds of the localization's levels recorded per
    /// read-back at most ([`ROUNDS_PER_WAIT`]; default 1). More rounds a submission run over
    /// empty lists once the loop has converged but wait on the adapter fewer times a frame;
    /// `volcap bench pipeline --rounds-per-wait` measures the trade on a board's GPU.
    #[serde(default = "d_rounds_per_wait")]
    pub rounds_per_wait: usize,
    /// `backend = "wgpu"`: `auto` (default: `own` on a GPU, `shared` on lavapipe), `shared`
    /// or `own` ([`RenderDevice`]).
    #[serde(default)]
    pub render_device: RenderDevice,
    /// `backend = "wgpu"`: when the render stage's localization reads the conflict loop's
    /// progress: `per-round` (default: after each round, batched by `rounds_per_wait`) or
    /// `per-frame` ([`RoundWaits`], the engine's).
    #[serde(default)]
    pub round_waits: RoundWaits,
    /// Render stage threads, each with its own renderer (on the GPU backend, its own
    /// renderer on the adapter and, with `render_device` `own`, its own device), each taking
    /// the latest field as it comes free: frame N + 1 is localized while frame N waits on
    /// its read-backs. The frames are published in capture order (a frame finished after a
    /// newer one is dropped, counted as the render stage's superseded). Default 1
    /// ([`RENDER_WORKERS`]); more pays only where the render stage waits more than it
    /// computes (a GPU's read-backs), not on a CPU whose cores the other stages keep busy
    /// (`volcap bench pipeline --render-workers` measures it).
    #[serde(default = "d_render_workers")]
    pub render_workers: usize,
    /// Model mode, where the segmentation has a thread of its own (`segment_thread_up_to`):
    /// that many segment threads, each taking the newest frame as it comes free, their
    /// people handed to the field thread in capture order (its temporal filter sees time
    /// go forward; a person segmented after a newer one is dropped, counted as the segment
    /// stage's superseded). Default 1 ([`SEGMENT_WORKERS`]); more pays where a frame's
    /// segmentation mostly waits (on a GPU its network's read-backs: two passes took 10 ms
    /// a frame on an H200, 1.2 ms of each on the adapter), not on two CPU cores.
    #[serde(default = "d_segment_workers")]
    pub segment_workers: usize,
}

/// Accepted range of `compute.segment_workers`.
pub const SEGMENT_WORKERS: std::ops::RangeInclusive<usize> = 1..=4;

fn d_segment_workers() -> usize {
    1
}

/// Accepted range of `compute.render_workers`.
pub const RENDER_WORKERS: std::ops::RangeInclusive<usize> = 1..=4;

fn d_render_workers() -> usize {
    1
}

/// Accepted range of `compute.rounds_per_wait`.
pub const ROUNDS_PER_WAIT: std::ops::RangeInclusive<usize> = 1..=64;

fn d_rounds_per_wait() -> usize {
    1
}

/// Default of `compute.segment_thread_up_to`: measured on 2 cores, the split takes 129^3 from
/// about 15 to 17-19 fps (latency p50 about 90 -> 150 ms) and would take 257^3 from 14 to 12
/// fps (three compute threads for two cores), so it stops at 129.
pub const DEFAULT_SEGMENT_THREAD_UP_TO: usize = 129;

fn d_segment_thread_up_to() -> usize {
    DEFAULT_SEGMENT_THREAD_UP_TO
}

impl Default for ComputeConfig {
    fn default() -> Self {
        Self {
            backend: ComputeBackend::default(),
            adapter: d_adapter(),
            fallback: ComputeFallback::default(),
            threads: d_threads(),
            segment_thread_up_to: d_segment_thread_up_to(),
            runtime: RuntimeChoice::default(),
            onnxruntime_lib: None,
            rounds_per_wait: d_rounds_per_wait(),
            render_device: RenderDevice::default(),
            round_waits: RoundWaits::default(),
            render_workers: d_render_workers(),
            segment_workers: d_segment_workers(),
        }
    }
}

fn d_adapter() -> String {
    "auto".into()
}

fn d_threads() -> usize {
    1
}
/// Accepted range of `compute.threads`.
pub const THREADS: std::ops::RangeInclusive<usize> = 1..=64;
