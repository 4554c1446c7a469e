//! The model mode's two network stages, each on a thread of its own with one item in
//! flight (a stage works on the next frame only once the stage after it took the last, so
//! a slower stage downstream throws no work away): **segment** (letterbox, segmentation, the
//! most prominent person, the crop) and **field** (the shape and colour encoders). Frame N + 2
//! is segmented while N + 1 is encoded and N is localized and rendered; above
//! `compute.segment_thread_up_to` (default 129) the field thread segments too (two compute
//! stages for two cores). With `compute.segment_workers` > 1 the segment stage has that many
//! threads (each with one frame in flight, their people handed on in capture order). With
//! `[model] segment_full_every` > 1 (and two segmentation passes) the segment threads share
//! a `SegmentTrack` (each takes a copy, segments, puts it back): between whole frames only
//! the last person's crop is segmented, and `/state` `segment_track` counts the frames. With
//! `compute.threads` > 1 the networks' matrix products use that many threads (tract's pool),
//! so the field stage can take the core the render stage leaves idle at lower resolutions. The field thread also holds the temporal
//! filter (`[temporal]`, `volcap_engine::model::temporal`): the person's mask and crop are
//! steadied before the encoders run and their maps blended with the last frame's after;
//! a frame without a person resets it.

use super::{PipelineState, Shared, Slot, part, stage};
use crate::capture::Frame;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use volcap_engine::model::preprocess::{CloseRangeSwitch, Crop};
use volcap_engine::model::temporal::{Step, Temporal, TemporalSettings};
use volcap_engine::model::{FrameError, FrameInfo, ModelField, ModelView, Models, Tracked};

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

/// A frame's person, segmented and cropped, or why there is none.
pub type Segmented = Result<Person, String>;

/// A segmented frame: the letterboxed input, the person's soft mask, its crop and the
/// people in view.
pub struct Person {
    img: Vec<f32>,
    mask: Vec<f32>,
    crop: Crop,
    people: usize,
}

/// Segment one frame, recording the stage's time and the people count.
fn segment(sh: &Shared, models: &Models, f: &Frame, threads: usize) -> Segmented {
    let t = Instant::now();
    let mut info = FrameInfo::default();
    // A copy of the track for this frame (the segment threads share it); the last frame
    // segmented puts its own back.
    let mut track = *sh.segment_track.lock().unwrap_or_else(|p| p.into_inner());
    let prepared = volcap_engine::model::with_threads(threads, || {
        models.prepare_tracked(&f.rgb, f.width, f.height, &mut info, Some(&mut track))
    });
    *sh.segment_track.lock().unwrap_or_else(|p| p.into_inner()) = track;
    let counter = match info.tracked {
        Tracked::Off => None,
        Tracked::Full => Some(0),
        Tracked::Crop => Some(1),
        Tracked::Lost => Some(2),
    };
    if let Some(i) = counter {
        sh.segment_tracked[i].fetch_add(1, Ordering::Relaxed);
    }
    match prepared {
        Ok((img, mask, crop)) => {
            sh.people.store(info.people, Ordering::Relaxed);
            sh.stats[stage::SEGMENT].record(t.elapsed().as_secs_f64() * 1e3);
            let tm = info.segment_parts;
            for (i, ms) in [
                (part::LETTERBOX, tm.letterbox_ms),
                (part::SEG_NETS, tm.nets_ms),
                (part::PERSON, tm.person_ms),
            ] {
                sh.parts[i].record(ms);
            }
            Ok(Person {
                img,
                mask,
                crop,
                people: info.people,
            })
        }
        Err(FrameError::NoPerson) => {
            sh.people.store(0, Ordering::Relaxed);
            Err("no person in view".to_string())
        }
        Err(e) => Err(format!("model: {e}")),
    }
}

/// Start segment thread `worker` (of `compute.segment_workers`): frames from `input`, the
/// person (or why none) into `out`, in capture order (a person segmented after a newer one
/// is dropped, so the field thread's temporal filter never sees time go back); idle while
/// the live resolution is above `split_up_to` (`compute.segment_thread_up_to`).
pub(super) fn spawn_segment(
    worker: usize,
    sh: Arc<Shared>,
    models: Arc<Models>,
    input: Arc<Slot<Frame>>,
    out: Arc<Slot<(Frame, Segmented)>>,
    threads: usize,
    split_up_to: usize,
) -> std::thread::JoinHandle<()> {
    let name = match worker {
        0 => "segment".to_string(),
        i => format!("segment-{}", i + 1),
    };
    std::thread::Builder::new()
        .name(name)
        .spawn(move || {
            while !sh.stop.load(Ordering::Relaxed) {
                sh.beat_worker(&sh.segment, worker);
                if sh.live().resolution > split_up_to {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                }
                // One frame in flight: segment the next only once the field thread has
                // taken the last (then take the newest frame).
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
                let seg = segment(&sh, &models, &f, threads);
                sh.segment.finished(worker);
                let at = f.at;
                if out.put_newer((f, seg), at) != super::Put::Fresh {
                    sh.stats[stage::SEGMENT]
                        .superseded
                        .fetch_add(1, Ordering::Relaxed);
                }
            }
        })
        .expect("spawning the segment thread")
}

/// Encode one segmented person: the close-range choice, the temporal filter (when on) and
/// the networks; the stage's time covers all three.
#[allow(clippy::too_many_arguments)]
fn encode(
    sh: &Shared,
    models: &Models,
    p: Person,
    view: ModelView,
    t_s: f64,
    switch: &mut CloseRangeSwitch,
    temporal: Option<&mut Temporal>,
    threads: usize,
) -> FieldOutcome {
    let Person {
        img,
        mut mask,
        mut crop,
        people,
    } = p;
    if models.close_range.is_some() {
        crop.cut_by_frame = switch.update(crop.cut_by_frame);
        sh.close_range.store(crop.cut_by_frame, Ordering::Relaxed);
    }
    let t = Instant::now();
    let (crop, temporal) = match temporal {
        Some(tf) => {
            let (steady, step) = tf.steady_input(t_s, people, &mut mask, crop);
            if let Step::Reset(_) = step {
                sh.temporal_resets.fetch_add(1, Ordering::Relaxed);
            }
            (steady.ok_or("no person in view")?, Some(tf))
        }
        None => (crop, None),
    };
    // The temporal filter's crop part (its maps' part is the engine's `temporal_ms`).
    let steady_ms = t.elapsed().as_secs_f64() * 1e3;
    let r = volcap_engine::model::with_threads(threads, || {
        models.encode_steady(&img, &mask, crop, view, temporal)
    })
    .map_err(|e| format!("model: {e}"));
    if let Ok(field) = &r {
        sh.stats[stage::FIELD].record(t.elapsed().as_secs_f64() * 1e3);
        let tm = field.timings();
        for (i, ms) in [
            (part::INPUT, tm.input_ms),
            (part::SHAPE, tm.shape_ms),
            (part::COLOR, tm.color_ms),
            (part::TEMPORAL, steady_ms + tm.temporal_ms),
            (part::FIELD, tm.field_ms),
        ] {
            sh.parts[i].record(ms);
        }
    }
    r
}

/// The field thread's settings from the config: `compute.threads`,
/// `compute.segment_thread_up_to`, `model.close_range_frames`, `[temporal]` (none: off).
pub(super) struct FieldSettings {
    pub threads: usize,
    pub split_up_to: usize,
    pub close_frames: u32,
    pub temporal: Option<TemporalSettings>,
    /// The render stage renders on a device of its own (`compute.render_device = "own"`):
    /// a frame's maps made on the adapter are read back here, in this stage's queue, for it.
    pub maps_to_host: bool,
}

/// Start the field thread: segmented frames from `segmented` (or, above `split_up_to`,
/// frames from `captured`, segmented here), fields (or why none) into `out`. With a
/// close-range model loaded, the choice between it and the main model follows the frames
/// only after `close_frames` of them in a row agree (`CloseRangeSwitch`, held here: the one
/// thread that encodes).
pub(super) fn spawn(
    sh: Arc<Shared>,
    models: Arc<Models>,
    captured: Arc<Slot<Frame>>,
    segmented: Arc<Slot<(Frame, Segmented)>>,
    out: Arc<Slot<(Frame, FieldOutcome)>>,
    settings: FieldSettings,
) -> std::thread::JoinHandle<()> {
    let FieldSettings {
        threads,
        split_up_to,
        close_frames,
        temporal,
        maps_to_host,
    } = settings;
    std::thread::Builder::new()
        .name("field".into())
        .spawn(move || {
            let mut switch = CloseRangeSwitch::new(close_frames);
            // The temporal filter lives here, on the one thread that encodes; frame times
            // are seconds since this thread started.
            let mut temporal = temporal.map(Temporal::new);
            let epoch = Instant::now();
            while !sh.stop.load(Ordering::Relaxed) {
                sh.beat(3);
                // One field in flight: compute the next only once the render thread
                // has taken the last (then take the newest segmented frame).
                if !out.wait_empty(Duration::from_millis(200)) {
                    continue;
                }
                let (f, seg) = if sh.live().resolution <= split_up_to {
                    let Some(s) = segmented.take(Duration::from_millis(200)) else {
                        continue;
                    };
                    s
                } else {
                    // A frame segmented before the switch is older than the camera's newest.
                    let _ = segmented.take(Duration::ZERO);
                    let Some(f) = captured.take(Duration::from_millis(200)) else {
                        continue;
                    };
                    let s = segment(&sh, &models, &f, threads);
                    (f, s)
                };
                let live = sh.live();
                if live.paused {
                    sh.set_state(PipelineState::Paused);
                    continue;
                }
                let view = model_view(&live);
                let t_s = f.at.saturating_duration_since(epoch).as_secs_f64();
                let outcome = match seg {
                    Ok(p) => encode(
                        &sh,
                        &models,
                        p,
                        view,
                        t_s,
                        &mut switch,
                        temporal.as_mut(),
                        threads,
                    ),
                    Err(e) => {
                        if let Some(t) = temporal.as_mut() {
                            t.reset();
                        }
                        Err(e)
                    }
                };
                // Not when `auto` left the render stage on the networks' device (no second
                // one opened): it reads the maps there, and a read-back would cost 2 MB a frame
                // for nothing.
                let to_host = maps_to_host && sh.compute.render_device.get() != Some(&"shared");
                let outcome = match outcome {
                    Ok(field) if to_host => match field.fourier_maps() {
                        Ok(_) => Ok(field),
                        Err(e) => Err(format!("the maps read back for the render device: {e}")),
                    },
                    other => other,
                };
                if out.put((f, outcome)) {
                    sh.stats[stage::FIELD]
                        .superseded
                        .fetch_add(1, Ordering::Relaxed);
                }
            }
        })
        .expect("spawning the field thread")
}

#[cfg(test)]
mod tests {
    use super::super::*;

    /// `compute.segment_workers = 2` in model mode: two segment threads, each taking the
    /// newest frame as it comes free, both segmenting; the people reach the field thread (and
    /// its temporal filter) in capture order, so the published frames go forward only.
    #[test]
    fn two_segment_workers_hand_on_people_in_capture_order() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let cfg = Config::parse(
            &format!(
                "[camera]\nbackend = \"sim\"\nscene = {:?}\n[render]\nfield = \"model\"\n\
                 resolution = 33\ndisplay_size = 0\n[model]\ndir = {:?}\n[dbus]\nbus = \"none\"\n\
                 [compute]\nsegment_workers = 2\nruntime = \"tract\"\n",
                root.join("tests/scenes/front-walk.toml")
                    .display()
                    .to_string(),
                root.join("models").display().to_string()
            ),
            std::path::Path::new("segment-workers.toml"),
        )
        .unwrap();
        let runtime = volcap_engine::model::Runtime::open(
            volcap_engine::model::runtime::RuntimeChoice::Tract,
            None,
        )
        .unwrap()
        .runtime;
        let models = volcap_engine::model::Models::load_on(
            &root.join("models"),
            &cfg.model.name,
            volcap_engine::model::Precision::F32,
            &runtime,
        )
        .unwrap();
        let (factory, _) = crate::capture::factory(&cfg).unwrap();
        let (tx, mut rx) = tokio::sync::watch::channel(None);
        let shared = Arc::new(Shared::new(&cfg, "test".into(), tx));
        let threads = start(&cfg, factory, shared.clone(), Some(Arc::new(models)));
        let seen = published_indices(&mut rx, 15, Duration::from_secs(120));
        shared.stop.store(true, Ordering::Relaxed);
        for t in threads {
            t.join().unwrap();
        }
        assert!(seen.len() >= 15, "{} frames published", seen.len());
        assert!(seen.windows(2).all(|w| w[0] < w[1]), "{seen:?}");
        let per_worker = shared.segment.frame_counts();
        assert!(per_worker.iter().all(|&n| n > 0), "{per_worker:?}");
        assert!(
            shared
                .worker_beats()
                .iter()
                .any(|(n, b)| n == "segment-2" && *b > 0)
        );
    }
}
