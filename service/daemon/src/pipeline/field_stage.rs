//! The field stage of model mode: segmentation and encoders on a thread of their own, one
//! field in flight (it computes the next field only once the render thread took the last,
//! so a slower render throws no work away). With `compute.threads` > 1 the networks' matrix
//! products use that many threads (tract's pool), so the field stage can take the core the
//! render stage leaves idle at lower resolutions.

use super::{PipelineState, Shared, Slot};
use crate::capture::Frame;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use volcap_engine::model::{FrameError, ModelField, ModelView, Models};

/// What the field thread hands the render thread: the model's field of a frame, or why
/// there is none (shown as a degraded state with a placeholder).
pub type FieldOutcome = Result<ModelField, String>;

/// The model's view for the live settings: orbit yaw/pitch about the crop centre; a distance
/// is relative to a 2.5 m nominal one (0 keeps the crop).
fn model_view(live: &super::Live) -> ModelView {
    ModelView {
        yaw_deg: live.yaw,
        pitch_deg: live.pitch,
        zoom: if live.distance > 0.0 {
            2.5 / live.distance
        } else {
            1.0
        },
    }
}

/// Start the field thread: frames from `input`, fields (or why none) into `out`.
pub(super) fn spawn(
    sh: Arc<Shared>,
    models: Arc<Models>,
    input: Arc<Slot<Frame>>,
    out: Arc<Slot<(Frame, FieldOutcome)>>,
    threads: usize,
) -> std::thread::JoinHandle<()> {
    std::thread::Builder::new()
        .name("field".into())
        .spawn(move || {
            while !sh.stop.load(Ordering::Relaxed) {
                sh.beat(3);
                // One field in flight: compute the next only once the render thread
                // has taken the last (then take the newest frame).
                if !out.wait_empty(Duration::from_millis(200)) {
                    continue;
                }
                let Some(f) = input.take(Duration::from_millis(200)) else {
                    continue;
                };
                let live = sh.live();
                if live.paused {
                    sh.set_state(PipelineState::Paused);
                    continue;
                }
                let t = Instant::now();
                let view = model_view(&live);
                let outcome = match volcap_engine::model::with_threads(threads, || {
                    models.frame(&f.rgb, f.width, f.height, view)
                }) {
                    Ok((field, info)) => {
                        sh.people.store(info.people, Ordering::Relaxed);
                        sh.stats[1].record(t.elapsed().as_secs_f64() * 1e3);
                        Ok(field)
                    }
                    Err(FrameError::NoPerson) => {
                        sh.people.store(0, Ordering::Relaxed);
                        Err("no person in view".to_string())
                    }
                    Err(e) => Err(format!("model: {e}")),
                };
                if out.put((f, outcome)) {
                    sh.stats[1].dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        })
        .expect("spawning the field thread")
}
