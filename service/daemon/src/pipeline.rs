//! The real-time pipeline on dedicated threads: capture (a supervised camera backend) ->
//! segment -> field (model mode: the trained networks; oracle: ground truth; camera: the frame
//! itself) -> localization + mesh-free render -> encode -> publish, each stage a module with
//! `spawn` functions of one shape (`capture_stage`, `field_stage`, `render_stage`,
//! `encode_stage`). Stages are joined by bounded latest-wins slots, so latency never grows;
//! every frame a slot overwrites is counted as a drop of the stage that produced it.

use crate::capture::{Backoff, Camera, CameraFactory, CameraState, Frame, Skip, Step, Supervisor};
use crate::config::{Config, FieldMode};

mod adapter_render;
mod capture_stage;
mod encode_stage;
mod field_stage;
mod pixels;
mod render_stage;
mod slot;

pub(crate) use adapter_render::AdapterRenderer;
pub use adapter_render::render_device;
pub use pixels::{composite_over, letterbox};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use volcap_engine::grid::GridSpec;
use volcap_engine::render::{RenderOptions, Renderer};

pub use crate::config::{Live, LiveError};
pub use slot::{Put, Slot, StageStats};

/// What the pipeline is doing, for /state and the viewer.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub enum PipelineState {
    Starting,
    Running,
    /// No person in view, several people, or the camera is gone: a reported state, not a
    /// garbled render.
    Degraded(String),
    /// Paused by the operator (D-Bus `Pause`): frames are captured and dropped.
    Paused,
    /// Cannot go on without the operator (the camera backend cannot be built).
    Failed(String),
}

impl PipelineState {
    /// The state's name (starting, running, degraded, paused, failed) and its reason.
    pub fn name_reason(&self) -> (&'static str, String) {
        match self {
            PipelineState::Starting => ("starting", String::new()),
            PipelineState::Running => ("running", String::new()),
            PipelineState::Degraded(r) => ("degraded", r.clone()),
            PipelineState::Paused => ("paused", "paused over D-Bus".into()),
            PipelineState::Failed(r) => ("failed", r.clone()),
        }
    }
}

/// A published frame.
pub struct Published {
    pub jpeg: Vec<u8>,
    pub rgba: Vec<u8>,
    pub size: usize,
    pub index: u64,
    pub latency_ms: f64,
    /// A placeholder that says why there is no render.
    pub placeholder: bool,
}

impl Published {
    /// The frame as PNG (RGBA, transparent where the background's alpha is 0). CPU work:
    /// call it off the async runtime.
    pub fn to_png(&self) -> Result<Vec<u8>, String> {
        let img = image::RgbaImage::from_raw(self.size as u32, self.size as u32, self.rgba.clone())
            .ok_or("frame buffer of the wrong size")?;
        let mut out = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .map_err(|e| e.to_string())?;
        Ok(out)
    }
}

/// The camera as `/state` and D-Bus report it.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CameraStatus {
    /// Backend and device.
    pub source: String,
    /// opening, running, skipping (open, frames arrive, none decodes), lost, stopped.
    pub state: &'static str,
    /// Typed reason while lost/stopped (no-device, busy, no-signal, unplugged, ...).
    pub fault: &'static str,
    pub reason: String,
    pub frames: u64,
    pub truncated: u64,
    pub corrupt: u64,
    pub faults: u64,
    pub opens: u64,
}

/// A frame's field that `/mesh.glb` can mesh and paint: the oracle's or the model's.
pub trait MeshField:
    volcap_engine::field::OccupancyField + volcap_engine::field::ColorField + Send + Sync
{
}
impl<T: volcap_engine::field::OccupancyField + volcap_engine::field::ColorField + Send + Sync>
    MeshField for T
{
}

/// Shared between the pipeline threads, the HTTP server, D-Bus and the watchdog.
pub struct Shared {
    pub stats: [StageStats; 5],
    /// Model mode: the field and render stages' parts ([`part`]).
    pub parts: [StageStats; part::COUNT],
    pub e2e: StageStats,
    pub state: Mutex<PipelineState>,
    pub camera: Mutex<CameraStatus>,
    pub live: Mutex<Live>,
    pub stop: AtomicBool,
    pub started: Instant,
    pub published: tokio::sync::watch::Sender<Option<Arc<Published>>>,
    pub mode: &'static str,
    /// What produces the field, as D-Bus `Model` says it: `reconstruction: NAME (PRECISION,
    /// [thin parts: moment-fill,] RUNTIME)` in model mode, `oracle` / `camera` for the labelled debugging modes.
    pub field_label: String,
    /// Model mode: what runs the networks ("tract", "onnxruntime 1.32.0"; empty in the
    /// other modes) and, when `compute.runtime = "auto"` fell back to tract, why.
    pub runtime: String,
    pub runtime_note: Option<String>,
    /// `[compute] backend`: the CPU or the adapter, and what runs there.
    pub compute: crate::compute::ComputeStatus,
    /// The latest rendered frame's field (oracle or model mode), for meshes on request.
    pub latest_field: Mutex<Option<Arc<dyn MeshField>>>,
    /// A new camera for the capture thread to switch to (config reload).
    pub camera_swap: Mutex<Option<CameraFactory>>,
    /// One counter per pipeline thread, bumped every loop turn (idle turns included): a
    /// counter that stops moving is a stalled thread, and the watchdog stops its pings.
    pub beats: [AtomicU64; 5],
    /// The render stage's threads (`compute.render_workers`) and the segment stage's
    /// (`compute.segment_workers`, model mode).
    pub render: Workers,
    pub segment: Workers,
    /// People in view in the latest rendered frame (model mode: regions of the
    /// segmentation, the largest one rendered; oracle mode: the simulator's count);
    /// `usize::MAX` while unknown (camera mode, nothing rendered yet).
    pub people: AtomicUsize,
    /// Model mode with `[model] close_range` configured...
    pub close_range_model: bool,
    /// ...and whether that model encodes the frames now (the field thread's
    /// `CloseRangeSwitch`).
    pub close_range: AtomicBool,
    /// Occupancy-field evaluations of every frame rendered so far (localization, final
    /// level, normals), for the pipeline benchmark.
    pub evaluations: AtomicU64,
    /// Rendered frames from which `render.drop_apart` left pieces apart from the body out,
    /// and the level `L - 1` points it dropped in all (`RenderStats::dropped_apart`).
    pub apart_frames: AtomicU64,
    pub apart_points: AtomicU64,
    /// Model mode with `[temporal]` enabled: the field thread's filter is on, with these
    /// settings (`/state`'s `temporal.settings`)...
    pub temporal: Option<volcap_engine::model::temporal::TemporalSettings>,
    /// ...and how often it started again (a new person, a people count change, a gap, a
    /// close-range switch, a frame without a person).
    pub temporal_resets: AtomicU64,
    /// The grid points the render stage gave out on last frame's side (`[temporal]
    /// surface_dead_band`, `volcap_engine::sides`), and the frames it held any in.
    pub held_sides: AtomicU64,
    pub held_frames: AtomicU64,
    /// Why the GPU backend's renderer did not hold its last frame though the band is on (the
    /// grid's memory does not fit one storage binding of the adapter), or `None`.
    pub held_refused: Mutex<Option<String>>,
    /// Model mode: the segmentation's track between frames (`[model] segment_full_every`),
    /// shared by the segment threads (each takes a copy, segments, and puts it back)...
    pub segment_track: Mutex<volcap_engine::model::SegmentTrack>,
    /// ...and the frames segmented whole, in the last crop alone, and those where the track
    /// lost the person (both passes followed).
    pub segment_tracked: [AtomicU64; 3],
}

pub const THREADS: [&str; 5] = ["capture", "render", "encode", "field", "segment"];

/// Whether pipeline thread `i` of [`THREADS`] runs in `mode` (the segment and field stages
/// have threads of their own in model mode only).
pub fn thread_runs(i: usize, mode: &str) -> bool {
    !matches!(THREADS[i], "field" | "segment") || mode == "model"
}

/// Frames skipped in a row (corrupt, truncated) before the state says so.
pub const SKIPS_DEGRADE: u64 = 5;

impl Shared {
    pub fn new(
        cfg: &Config,
        camera_source: String,
        published: tokio::sync::watch::Sender<Option<Arc<Published>>>,
    ) -> Self {
        Self {
            stats: Default::default(),
            parts: Default::default(),
            e2e: Default::default(),
            state: Mutex::new(PipelineState::Starting),
            camera: Mutex::new(CameraStatus {
                source: camera_source,
                state: "opening",
                ..Default::default()
            }),
            live: Mutex::new(Live::from_config(cfg)),
            stop: AtomicBool::new(false),
            started: Instant::now(),
            published,
            mode: cfg.field().name(),
            field_label: match cfg.field() {
                FieldMode::Model => format!(
                    "reconstruction: {} ({}{})",
                    cfg.model.name,
                    match cfg.model.precision {
                        crate::config::Precision::F32 => "f32",
                        crate::config::Precision::Int8 => "int8",
                    },
                    match cfg.model.thin_parts {
                        crate::config::ThinParts::Series => "",
                        crate::config::ThinParts::MomentFill => ", thin parts: moment-fill",
                    },
                ),
                other => other.name().to_string(),
            },
            runtime: String::new(),
            runtime_note: None,
            compute: crate::compute::ComputeStatus::cpu(None),
            latest_field: Mutex::new(None),
            camera_swap: Mutex::new(None),
            beats: Default::default(),
            render: Workers::new(1, cfg.compute.render_workers),
            segment: Workers::new(4, cfg.compute.segment_workers),
            people: AtomicUsize::new(usize::MAX),
            close_range_model: cfg.field() == FieldMode::Model && cfg.model.close_range.is_some(),
            close_range: AtomicBool::new(false),
            evaluations: AtomicU64::new(0),
            apart_frames: AtomicU64::new(0),
            apart_points: AtomicU64::new(0),
            temporal: (cfg.field() == FieldMode::Model)
                .then(|| cfg.temporal.settings())
                .flatten(),
            temporal_resets: AtomicU64::new(0),
            held_sides: AtomicU64::new(0),
            held_frames: AtomicU64::new(0),
            held_refused: Mutex::new(None),
            // Model mode only (the other modes segment nothing); one pass turns it off
            // (`set_segment_passes`).
            segment_track: Mutex::new(volcap_engine::model::SegmentTrack::new(
                if cfg.field() == FieldMode::Model {
                    cfg.model.segment_full_every
                } else {
                    1
                },
            )),
            segment_tracked: Default::default(),
        }
    }

    /// Model mode: how many times each frame is segmented, as the loaded networks run it
    /// (`[model] segment_passes`, unset: as the shape model was trained); two joins the
    /// field's label (`reconstruction: NAME (PRECISION, segmented twice)`), one turns the
    /// segmentation's track off (it tracks the second pass's crop: the engine segments every
    /// frame whole then). Called before [`Self::set_runtime`].
    pub fn set_segment_passes(&mut self, passes: u8) {
        if passes < 2 {
            self.segment_track
                .get_mut()
                .unwrap_or_else(|p| p.into_inner())
                .full_every = 1;
        }
        if self.mode == "model"
            && passes > 1
            && let Some(open) = self.field_label.rfind(')')
        {
            self.field_label.insert_str(open, ", segmented twice");
        }
    }

    /// Model mode: the passes of smoothing the shape model's maps get (`[model] map_smooth`,
    /// `None` for a model without maps); some join the field's label
    /// (`reconstruction: NAME (PRECISION, maps smoothed twice)`).
    pub fn set_map_smooth(&mut self, passes: Option<u8>) {
        let words = match passes {
            Some(1) => "once".to_string(),
            Some(2) => "twice".to_string(),
            Some(n) if n > 2 => format!("{n} times"),
            _ => return,
        };
        if self.mode == "model"
            && let Some(open) = self.field_label.rfind(')')
        {
            self.field_label
                .insert_str(open, &format!(", maps smoothed {words}"));
        }
    }

    /// The segmentation's track's `full_every` while it tracks (model mode, two passes,
    /// `[model] segment_full_every` > 1), else none.
    pub fn segment_tracking(&self) -> Option<u32> {
        let every = self
            .segment_track
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .full_every;
        (every > 1).then_some(every)
    }

    /// Model mode: the runtime the networks were loaded on (its label joins the field's:
    /// `reconstruction: NAME (PRECISION, RUNTIME)`) and why `auto` fell back to tract.
    pub fn set_runtime(&mut self, label: String, fallback: Option<String>) {
        if self.mode == "model" {
            if let Some(open) = self.field_label.rfind(')') {
                self.field_label.insert_str(open, &format!(", {label}"));
            }
            self.runtime = label;
            self.runtime_note = fallback;
        }
    }

    /// The latest frame's oracle field, if any.
    pub fn latest_field(&self) -> Option<Arc<dyn MeshField>> {
        self.latest_field
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    pub fn set_state(&self, s: PipelineState) {
        *self.state.lock().unwrap_or_else(|p| p.into_inner()) = s;
    }

    pub fn live(&self) -> Live {
        *self.live.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Change live settings through `f`; refused (and nothing changed) when the result is
    /// not valid.
    pub fn update_live(&self, f: impl FnOnce(&mut Live)) -> Result<Live, String> {
        let mut g = self.live.lock().unwrap_or_else(|p| p.into_inner());
        let mut next = *g;
        f(&mut next);
        next.check().map_err(|e| e.msg)?;
        *g = next;
        Ok(next)
    }

    fn beat(&self, thread: usize) {
        self.beats[thread].fetch_add(1, Ordering::Relaxed);
    }

    /// Worker `worker`'s heartbeat of a stage's `workers` (0: the stage's thread of
    /// [`THREADS`]).
    fn beat_worker(&self, workers: &Workers, worker: usize) {
        match worker.checked_sub(1) {
            None => self.beat(workers.thread),
            Some(i) => bump(&workers.beats, i),
        }
    }

    /// The names and heartbeats of the stages' further workers (`render-2`, ...,
    /// `segment-2`, ...), for the watchdog; the segment workers only in model mode.
    pub fn worker_beats(&self) -> Vec<(String, u64)> {
        let mut out = self.render.named_beats();
        if self.mode == "model" {
            out.extend(self.segment.named_beats());
        }
        out
    }
}

/// A stage's threads (`compute.render_workers`, `compute.segment_workers`): the first is the
/// stage's thread of [`THREADS`] and beats there; each further one (`render-2`, ...) beats
/// its own counter here, so the watchdog sees any one of them stall. `frames` counts what
/// each worker finished (placeholders and frames a newer one beat included): how the stage's
/// load spreads over its workers.
pub struct Workers {
    /// The stage's index in [`THREADS`].
    thread: usize,
    pub beats: Vec<AtomicU64>,
    pub frames: Vec<AtomicU64>,
}

impl Workers {
    fn new(thread: usize, count: usize) -> Self {
        let counters = |n: usize| (0..n).map(|_| AtomicU64::new(0)).collect();
        let count = count.max(1);
        Workers {
            thread,
            beats: counters(count - 1),
            frames: counters(count),
        }
    }

    /// How many threads the stage runs.
    pub fn count(&self) -> usize {
        self.frames.len()
    }

    /// Worker `worker` finished a frame.
    fn finished(&self, worker: usize) {
        bump(&self.frames, worker);
    }

    /// Each worker's frames so far, in worker order.
    pub fn frame_counts(&self) -> Vec<u64> {
        self.frames
            .iter()
            .map(|n| n.load(Ordering::Relaxed))
            .collect()
    }

    /// The further workers' names (`STAGE-2`, ...) and heartbeats.
    fn named_beats(&self) -> Vec<(String, u64)> {
        self.beats
            .iter()
            .enumerate()
            .map(|(i, b)| {
                (
                    format!("{}-{}", THREADS[self.thread], i + 2),
                    b.load(Ordering::Relaxed),
                )
            })
            .collect()
    }
}

/// Add one to counter `i` of `counters` (none there: nothing).
fn bump(counters: &[AtomicU64], i: usize) {
    if let Some(c) = counters.get(i) {
        c.fetch_add(1, Ordering::Relaxed);
    }
}

pub const STAGES: [&str; 5] = ["capture", "segment", "field", "render", "encode"];

/// Indices of [`STAGES`] in `Shared::stats`.
pub mod stage {
    pub const CAPTURE: usize = 0;
    /// Model mode: letterbox, segmentation, the most prominent person, the crop.
    pub const SEGMENT: usize = 1;
    /// Model mode: the shape and colour encoders; oracle mode: the ground-truth field.
    pub const FIELD: usize = 2;
    pub const RENDER: usize = 3;
    pub const ENCODE: usize = 4;
}

/// The parts of the segment, field and render stages in model mode (`Shared::parts`, by
/// these indices): where each stage's time goes, for the pipeline bench.
pub mod part {
    /// Segment: the frame letterboxed into the networks' square input.
    pub const LETTERBOX: usize = 0;
    /// Segment: the segmentation network, once per pass (on the GPU backend each run with
    /// its upload and read-back).
    pub const SEG_NETS: usize = 1;
    /// Segment: the rest on the host (the most prominent person, the second pass's crop and
    /// paste, the person's crop).
    pub const PERSON: usize = 2;
    /// Field: the image and mask cropped to the networks' input.
    pub const INPUT: usize = 3;
    /// Field: the shape network (on the GPU backend's Fourier frames, with its maps'
    /// temporal filter on the adapter, in the network's submission).
    pub const SHAPE: usize = 4;
    /// Field: the colour encoder.
    pub const COLOR: usize = 5;
    /// Field: the temporal filter of the maps (on the GPU backend's Fourier frames, what stays
    /// on the host: the mask, the crop and the colour features).
    pub const TEMPORAL: usize = 6;
    /// Field: the field made (on the GPU backend, the maps' buffers on the adapter).
    pub const FIELD: usize = 7;
    /// Render: localization and the surface depths (on the GPU backend, the adapter's frame).
    pub const LOCALIZE: usize = 8;
    /// Render: the surface points' colour (and shading), the grid-size image.
    pub const SURFACE: usize = 9;
    /// Render: the rest of the stage (the image at display size).
    pub const DISPLAY: usize = 10;
    pub const COUNT: usize = 11;
    /// The first part of each stage split into parts (segment, field, render), and the end.
    pub const STAGE_STARTS: [usize; 4] = [LETTERBOX, INPUT, LOCALIZE, COUNT];
    pub const NAMES: [&str; COUNT] = [
        "segment: letterbox",
        "segment: networks",
        "segment: person and crop",
        "field: input",
        "field: shape net",
        "field: colour encoder",
        "field: temporal filter",
        "field: series",
        "render: localize",
        "render: surface and colour",
        "render: display",
    ];
}

struct Rendered {
    index: u64,
    at: Instant,
    rgba: Vec<u8>,
    size: usize,
    placeholder: bool,
}

fn camera_status_from(sup: &Supervisor<dyn Camera>, st: &mut CameraStatus) {
    st.frames = sup.frames;
    st.faults = sup.faults;
    st.opens = sup.opens;
    if st.state == "running" && *sup.state() == CameraState::Running {
        // Steady streaming: nothing textual changed; no per-frame formatting.
        return;
    }
    st.source = sup.describe();
    let (state, fault, reason) = match sup.state() {
        CameraState::Opening => ("opening", "", String::new()),
        CameraState::Running => ("running", "", String::new()),
        CameraState::Skipping { in_a_row, last } => (
            "skipping",
            "undecodable",
            format!("{in_a_row} frames in a row did not decode (last: {last})"),
        ),
        CameraState::Lost { fault, retry_in } => (
            "lost",
            fault.kind(),
            format!("{fault}; retrying in {:.1} s", retry_in.as_secs_f32()),
        ),
        CameraState::Stopped(fault) => ("stopped", fault.kind(), fault.to_string()),
    };
    st.state = state;
    st.fault = fault;
    st.reason = reason;
}

pub use field_stage::FieldOutcome;

/// Start the pipeline threads.
pub fn start(
    cfg: &Config,
    factory: CameraFactory,
    shared: Arc<Shared>,
    models: Option<Arc<volcap_engine::model::Models>>,
) -> Vec<std::thread::JoinHandle<()>> {
    let captured: Arc<Slot<Frame>> = Arc::default();
    let rendered: Arc<Slot<Rendered>> = Arc::default();
    let mut threads = Vec::new();

    // Capture: the supervised camera; losses become states and placeholder frames.
    threads.push(capture_stage::spawn(
        shared.clone(),
        factory,
        captured.clone(),
        rendered.clone(),
    ));

    // Model mode: segmentation and the encoders on threads of their own, so that frame N + 2
    // is segmented and N + 1 encoded while frame N is localized and rendered (latest wins
    // between).
    let fielded: Arc<Slot<(Frame, FieldOutcome)>> = Arc::default();
    let render_on = render_device(cfg, models.as_deref());
    if let (FieldMode::Model, Some(models)) = (cfg.field(), models.clone()) {
        let segmented: Arc<Slot<(Frame, field_stage::Segmented)>> = Arc::default();
        // `compute.segment_workers` threads, their people handed on in capture order.
        for worker in 0..shared.segment.count() {
            threads.push(field_stage::spawn_segment(
                worker,
                shared.clone(),
                models.clone(),
                captured.clone(),
                segmented.clone(),
                cfg.compute.threads,
                cfg.compute.segment_thread_up_to,
            ));
        }
        threads.push(field_stage::spawn(
            shared.clone(),
            models,
            captured.clone(),
            segmented,
            fielded.clone(),
            field_stage::FieldSettings {
                threads: cfg.compute.threads,
                split_up_to: cfg.compute.segment_thread_up_to,
                close_frames: cfg.model.close_range_frames,
                temporal: cfg.temporal.settings(),
                maps_to_host: render_on == crate::config::RenderDevice::Own,
            },
        ));
    }

    // Render: the model's field (from the field thread), the oracle field through the
    // engine's localization and renderer, or the camera frame itself; on
    // `compute.render_workers` threads, each taking the latest as it comes free, their
    // frames published in capture order.
    for worker in 0..shared.render.count() {
        threads.push(render_stage::spawn(
            render_stage::Worker {
                index: worker,
                voxel: cfg.render.oracle_voxel_m,
                mode: cfg.field(),
                eval_threads: cfg.compute.threads,
                compute: cfg.compute.clone(),
            },
            shared.clone(),
            captured.clone(),
            fielded.clone(),
            rendered.clone(),
            models.clone(),
        ));
    }

    // Encode + publish.
    threads.push(encode_stage::spawn(shared.clone(), rendered));
    threads
}

/// The indices of the first `n` frames (not placeholders) published to `rx`, as a client
/// sees them, within `timeout` (fewer if it runs out): for the stages' worker tests.
#[cfg(test)]
fn published_indices(
    rx: &mut tokio::sync::watch::Receiver<Option<Arc<Published>>>,
    n: usize,
    timeout: Duration,
) -> Vec<u64> {
    let mut seen = Vec::new();
    let t0 = Instant::now();
    while seen.len() < n && t0.elapsed() < timeout {
        if rx.has_changed().unwrap_or(false) {
            if let Some(p) = rx.borrow_and_update().as_ref()
                && !p.placeholder
            {
                seen.push(p.index);
            }
        } else {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    seen
}
