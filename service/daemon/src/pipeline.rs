//! The real-time pipeline on dedicated threads: capture -> field (oracle: ground truth) ->
//! localization + mesh-free render -> encode -> publish. Stages are joined by bounded
//! latest-wins slots, so latency never grows; every frame a slot overwrites is counted as a
//! drop of the stage that produced it.

use crate::config::Config;
use glam::{Quat, Vec3};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use volcap_engine::grid::GridSpec;
use volcap_engine::render::{RenderOptions, Renderer};
use volcap_sim::camera::Camera;
use volcap_sim::sim::GroundTruth;
use volcap_sim::{SimError, Simulator};

/// A one-item slot: `put` replaces what is there (and reports the overwrite), `take` waits.
pub struct Slot<T> {
    item: Mutex<Option<T>>,
    ready: Condvar,
}

impl<T> Default for Slot<T> {
    fn default() -> Self {
        Self {
            item: Mutex::new(None),
            ready: Condvar::new(),
        }
    }
}

impl<T> Slot<T> {
    /// Put `v`; returns true when an unconsumed item was overwritten (a drop).
    pub fn put(&self, v: T) -> bool {
        let mut g = self.item.lock().unwrap_or_else(|p| p.into_inner());
        let dropped = g.replace(v).is_some();
        self.ready.notify_one();
        dropped
    }

    /// Take the latest item, waiting up to `timeout`.
    pub fn take(&self, timeout: Duration) -> Option<T> {
        let g = self.item.lock().unwrap_or_else(|p| p.into_inner());
        let (mut g, _) = self
            .ready
            .wait_timeout_while(g, timeout, |v| v.is_none())
            .unwrap_or_else(|p| p.into_inner());
        g.take()
    }
}

/// Rolling per-stage timings.
#[derive(Default)]
pub struct StageStats {
    samples: Mutex<Vec<f64>>,
    pub frames: AtomicU64,
    pub dropped: AtomicU64,
}

impl StageStats {
    pub fn record(&self, ms: f64) {
        let mut s = self.samples.lock().unwrap_or_else(|p| p.into_inner());
        if s.len() >= 256 {
            s.remove(0);
        }
        s.push(ms);
        self.frames.fetch_add(1, Ordering::Relaxed);
    }

    /// (p50, p99) in ms over the last 256 frames.
    pub fn percentiles(&self) -> (f64, f64) {
        let mut v = self
            .samples
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        if v.is_empty() {
            return (0.0, 0.0);
        }
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
        (q(0.5), q(0.99))
    }
}

/// What the pipeline is doing, for /state and the viewer.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub enum PipelineState {
    Starting,
    Running,
    /// No person in view, several people, or the camera is gone: a reported state, not a
    /// garbled render.
    Degraded(String),
}

/// A published frame.
pub struct Published {
    pub jpeg: Vec<u8>,
    pub rgba: Vec<u8>,
    pub size: usize,
    pub index: u64,
    pub latency_ms: f64,
}

/// Shared between the pipeline threads and the HTTP server.
pub struct Shared {
    pub stats: [StageStats; 4],
    pub e2e: StageStats,
    pub state: Mutex<PipelineState>,
    pub view: Mutex<(f32, f32)>,
    pub stop: AtomicBool,
    pub started: Instant,
    pub published: tokio::sync::watch::Sender<Option<Arc<Published>>>,
    pub mode: &'static str,
    pub resolution: usize,
    /// The latest frame's field, for meshes on request.
    pub latest_field: Mutex<Option<Arc<volcap_sim::oracle::SceneField>>>,
    pub coarse_level: u32,
}

pub const STAGES: [&str; 4] = ["capture", "field", "render", "encode"];

struct Captured {
    index: u64,
    at: Instant,
    gt: GroundTruth,
    people: usize,
}

struct Rendered {
    index: u64,
    at: Instant,
    rgba: Vec<u8>,
    size: usize,
}

fn orbit(cam: &Camera, yaw_deg: f32, pitch_deg: f32) -> Camera {
    let off = cam.eye - cam.target;
    let side = off.cross(Vec3::Y).normalize_or(Vec3::X);
    let q = Quat::from_rotation_y(yaw_deg.to_radians())
        * Quat::from_axis_angle(side, -pitch_deg.to_radians());
    Camera {
        eye: cam.target + q * off,
        ..*cam
    }
}

/// Start the pipeline threads. `sim` is the capture backend.
pub fn start(
    cfg: &Config,
    mut sim: Simulator,
    shared: Arc<Shared>,
) -> Vec<std::thread::JoinHandle<()>> {
    let captured: Arc<Slot<Captured>> = Arc::default();
    let rendered: Arc<Slot<Rendered>> = Arc::default();
    let fps = sim.scene().camera.fps.0 as f64;
    let mut threads = Vec::new();

    // Capture: the simulator paced at the scene's fps.
    {
        let (sh, out) = (shared.clone(), captured.clone());
        threads.push(
            std::thread::Builder::new()
                .name("capture".into())
                .spawn(move || {
                    let period = Duration::from_secs_f64(1.0 / fps);
                    let mut next = Instant::now();
                    let mut index = 0u64;
                    while !sh.stop.load(Ordering::Relaxed) {
                        let now = Instant::now();
                        if next > now {
                            std::thread::sleep(next - now);
                        }
                        next += period;
                        let t = Instant::now();
                        match sim.render(index) {
                            Ok(frame) => {
                                // People in view: subjects covering a visible area of the camera frame.
                                let mut area = [0u32; 256];
                                for &id in &frame.ids {
                                    area[id as usize] += 1;
                                }
                                let min_px = (frame.width * frame.height / 2000).max(20) as u32;
                                let people = (1..volcap_sim::sim::OCCLUDER_ID as usize)
                                    .filter(|&i| area[i] >= min_px)
                                    .count();
                                let gt = sim.ground_truth();
                                sh.stats[0].record(t.elapsed().as_secs_f64() * 1e3);
                                if out.put(Captured {
                                    index,
                                    at: t,
                                    gt,
                                    people,
                                }) {
                                    sh.stats[0].dropped.fetch_add(1, Ordering::Relaxed);
                                }
                            }
                            Err(SimError::Unplugged { frame }) => {
                                *sh.state.lock().unwrap_or_else(|p| p.into_inner()) =
                                    PipelineState::Degraded(format!(
                                        "camera unplugged (frame {frame}); retrying"
                                    ));
                            }
                            Err(e) => {
                                *sh.state.lock().unwrap_or_else(|p| p.into_inner()) =
                                    PipelineState::Degraded(format!("capture failed: {e}"));
                            }
                        }
                        index += 1;
                    }
                })
                .expect("spawning the capture thread"),
        );
    }

    // Field + render: the oracle field through the engine's localization and renderer.
    {
        let (sh, input, out) = (shared.clone(), captured.clone(), rendered.clone());
        let spec = GridSpec::from_resolution(cfg.render.resolution.0)
            .unwrap_or_else(|_| unreachable!("validated in config"));
        let opts = RenderOptions {
            coarse_level: cfg.render.coarse_level,
            background: cfg.render.background,
            shade: false,
        };
        let voxel = cfg.render.oracle_voxel_m;
        threads.push(
            std::thread::Builder::new()
                .name("render".into())
                .spawn(move || {
                    let mut renderer = Renderer::new();
                    while !sh.stop.load(Ordering::Relaxed) {
                        let Some(c) = input.take(Duration::from_millis(200)) else {
                            continue;
                        };
                        if c.people != 1 {
                            *sh.state.lock().unwrap_or_else(|p| p.into_inner()) =
                                PipelineState::Degraded(if c.people == 0 {
                                    "no person in view".into()
                                } else {
                                    format!("{} people in view; one is supported", c.people)
                                });
                            continue;
                        }
                        let t = Instant::now();
                        let (yaw, pitch) = *sh.view.lock().unwrap_or_else(|p| p.into_inner());
                        let view = orbit(&c.gt.camera, yaw, pitch);
                        let field = Arc::new(c.gt.into_field(voxel, view));
                        sh.stats[1].record(t.elapsed().as_secs_f64() * 1e3);
                        *sh.latest_field.lock().unwrap_or_else(|p| p.into_inner()) =
                            Some(field.clone());
                        let t = Instant::now();
                        match renderer.render(field.as_ref(), field.as_ref(), spec, &opts) {
                            Ok(_) => {
                                sh.stats[2].record(t.elapsed().as_secs_f64() * 1e3);
                                if out.put(Rendered {
                                    index: c.index,
                                    at: c.at,
                                    rgba: renderer.rgba().to_vec(),
                                    size: renderer.size(),
                                }) {
                                    sh.stats[2].dropped.fetch_add(1, Ordering::Relaxed);
                                }
                                *sh.state.lock().unwrap_or_else(|p| p.into_inner()) =
                                    PipelineState::Running;
                            }
                            Err(e) => {
                                *sh.state.lock().unwrap_or_else(|p| p.into_inner()) =
                                    PipelineState::Degraded(format!("render failed: {e}"));
                            }
                        }
                    }
                })
                .expect("spawning the render thread"),
        );
    }

    // Encode + publish.
    {
        let (sh, input) = (shared.clone(), rendered);
        let bg = cfg.render.background;
        threads.push(
            std::thread::Builder::new()
                .name("encode".into())
                .spawn(move || {
                    while !sh.stop.load(Ordering::Relaxed) {
                        let Some(r) = input.take(Duration::from_millis(200)) else {
                            continue;
                        };
                        let t = Instant::now();
                        // JPEG has no alpha: composite over the background colour.
                        let rgb: Vec<u8> = r
                            .rgba
                            .chunks_exact(4)
                            .flat_map(|p| {
                                let a = p[3] as f32 / 255.0;
                                [0, 1, 2].map(|c| {
                                    (p[c] as f32 * a + bg[c] * 255.0 * (1.0 - a)).round() as u8
                                })
                            })
                            .collect();
                        let mut jpeg = Vec::new();
                        let ok = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 85)
                            .encode(
                                &rgb,
                                r.size as u32,
                                r.size as u32,
                                image::ExtendedColorType::Rgb8,
                            )
                            .is_ok();
                        if !ok {
                            continue;
                        }
                        sh.stats[3].record(t.elapsed().as_secs_f64() * 1e3);
                        let latency_ms = r.at.elapsed().as_secs_f64() * 1e3;
                        sh.e2e.record(latency_ms);
                        sh.published.send_replace(Some(Arc::new(Published {
                            jpeg,
                            rgba: r.rgba,
                            size: r.size,
                            index: r.index,
                            latency_ms,
                        })));
                    }
                })
                .expect("spawning the encode thread"),
        );
    }
    threads
}
