//! The render stage: the model's field (from the field stage), the oracle field or the camera
//! frame itself, localized and rendered mesh-free from the live view; latest wins on both sides.

use super::*;
use glam::{Quat, Vec3};
use volcap_sim::camera::Camera as SimView;

/// One render thread's settings: which worker it is of `compute.render_workers`, and what it
/// renders with.
pub(super) struct Worker {
    pub index: usize,
    pub voxel: f32,
    pub mode: FieldMode,
    pub eval_threads: usize,
    pub compute: crate::config::ComputeConfig,
}

/// Spawn a render thread: take the latest frame (and its field), render, put it latest-wins
/// unless another worker already put a newer one.
pub(super) fn spawn(
    w: Worker,
    sh: Arc<Shared>,
    input: Arc<Slot<Frame>>,
    fielded: Arc<Slot<(Frame, FieldOutcome)>>,
    out: Arc<Slot<Rendered>>,
    models: Option<Arc<volcap_engine::model::Models>>,
) -> std::thread::JoinHandle<()> {
    let name = match w.index {
        0 => "render".to_string(),
        i => format!("render-{}", i + 1),
    };
    std::thread::Builder::new()
        .name(name)
        .spawn(move || {
            let Worker {
                index: worker,
                voxel,
                mode,
                eval_threads,
                compute,
            } = w;
            let mut renderer = Renderer::new();
            renderer.set_threads(eval_threads);
            // On the GPU backend the model's frames are localized and drawn on the adapter
            // (each worker its own renderer there, and its own device where it has one).
            let mut on_adapter = super::AdapterRenderer::open(models.as_deref(), mode, &compute);
            if let Some(r) = &on_adapter {
                let _ = sh.compute.render_device.set(r.device_name());
            }
            // Frames go out in capture order: one finished after a newer one (another
            // worker's) is work nobody needed, as one replaced before it was taken.
            let publish = |r: Rendered| {
                sh.render.finished(worker);
                let at = r.at;
                if out.put_newer(r, at) != Put::Fresh {
                    sh.stats[stage::RENDER]
                        .superseded
                        .fetch_add(1, Ordering::Relaxed);
                }
            };
            let degraded = |why: String, f: &Frame, size: usize, bg: [f32; 4]| {
                let rgba = crate::placeholder::frame(size, bg, "NOT RENDERED", &why);
                sh.set_state(PipelineState::Degraded(why));
                publish(Rendered {
                    index: f.seq,
                    at: f.at,
                    rgba,
                    size,
                    placeholder: true,
                });
            };
            while !sh.stop.load(Ordering::Relaxed) {
                sh.beat_worker(&sh.render, worker);
                let (f, outcome) = if mode == FieldMode::Model {
                    let Some((f, o)) = fielded.take(Duration::from_millis(200)) else {
                        continue;
                    };
                    (f, Some(o))
                } else {
                    let Some(f) = input.take(Duration::from_millis(200)) else {
                        continue;
                    };
                    (f, None)
                };
                let live = sh.live();
                if live.paused {
                    sh.set_state(PipelineState::Paused);
                    continue;
                }
                let (size, bg) = (live.out_size(), live.background);
                let rgba = match mode {
                    FieldMode::Camera => {
                        let t = Instant::now();
                        let rgba = letterbox(&f.rgb, f.width, f.height, size);
                        sh.stats[stage::RENDER].record(t.elapsed().as_secs_f64() * 1e3);
                        rgba
                    }
                    FieldMode::Model => {
                        let field = match outcome {
                            Some(Ok(field)) => field,
                            Some(Err(why)) => {
                                if why.starts_with("model:") {
                                    sh.stats[stage::RENDER].lost.fetch_add(1, Ordering::Relaxed);
                                }
                                degraded(why, &f, size, bg);
                                continue;
                            }
                            None => {
                                degraded("model mode without loaded models".into(), &f, size, bg);
                                continue;
                            }
                        };
                        let field = Arc::new(field);
                        *sh.latest_field.lock().unwrap_or_else(|p| p.into_inner()) =
                            Some(field.clone());
                        // The surface's dead band, while the crop and the view stay put.
                        let band = sh.temporal.map_or(0.0, |t| t.surface_dead_band);
                        renderer.hold_sides(band, Some(field.alignment_key()));
                        let rgba = match on_adapter.as_mut() {
                            Some(a) => a.render(&mut renderer, &sh, field.as_ref(), &live),
                            None => render_field(
                                &mut renderer,
                                &sh,
                                field.as_ref(),
                                field.as_ref(),
                                &live,
                            ),
                        };
                        let Some(rgba) = rgba else {
                            continue;
                        };
                        rgba
                    }
                    FieldMode::Oracle => {
                        let Some(truth) = &f.truth else {
                            degraded(
                                "oracle mode needs the sim camera's ground truth".into(),
                                &f,
                                size,
                                bg,
                            );
                            continue;
                        };
                        sh.people.store(truth.people, Ordering::Relaxed);
                        if truth.people != 1 {
                            degraded(
                                if truth.people == 0 {
                                    "no person in view".into()
                                } else {
                                    format!("{} people in view; one is supported", truth.people)
                                },
                                &f,
                                size,
                                bg,
                            );
                            continue;
                        }
                        let t = Instant::now();
                        let view = orbit(&truth.gt.camera, live.yaw, live.pitch, live.distance);
                        let Some(truth) = f.truth else { continue };
                        let field = Arc::new(truth.gt.into_field(voxel, view));
                        sh.stats[stage::FIELD].record(t.elapsed().as_secs_f64() * 1e3);
                        *sh.latest_field.lock().unwrap_or_else(|p| p.into_inner()) =
                            Some(field.clone());
                        let Some(rgba) =
                            render_field(&mut renderer, &sh, field.as_ref(), field.as_ref(), &live)
                        else {
                            continue;
                        };
                        rgba
                    }
                };
                publish(Rendered {
                    index: f.seq,
                    at: f.at,
                    rgba,
                    size,
                    placeholder: false,
                });
                // Running only while the camera is: a frame captured before the
                // camera was lost must not paint over the lost state.
                let camera_running =
                    sh.camera.lock().unwrap_or_else(|p| p.into_inner()).state == "running";
                if camera_running {
                    sh.set_state(PipelineState::Running);
                }
            }
        })
        .expect("spawning the render thread")
}

/// The view turned about the camera's target by the live yaw and pitch (degrees), at `distance`
/// from it when above 0.
fn orbit(cam: &SimView, yaw_deg: f32, pitch_deg: f32, distance: f32) -> SimView {
    let off = cam.eye - cam.target;
    let side = off.cross(Vec3::Y).normalize_or(Vec3::X);
    let q = Quat::from_rotation_y(yaw_deg.to_radians())
        * Quat::from_axis_angle(side, -pitch_deg.to_radians());
    let mut dir = q * off;
    if distance > 0.0 {
        dir = dir.normalize_or(Vec3::Z) * distance;
    }
    SimView {
        eye: cam.target + dir,
        ..*cam
    }
}

/// Render a field at the live resolution and view settings, timed as the render stage; a
/// failure becomes the degraded state (and `None`).
pub(super) fn render_field(
    renderer: &mut Renderer,
    sh: &Shared,
    field: &dyn volcap_engine::OccupancyField,
    colors: &dyn volcap_engine::ColorField,
    live: &Live,
) -> Option<Vec<u8>> {
    let t = Instant::now();
    let spec = GridSpec::from_resolution(live.resolution).ok()?;
    let opts = RenderOptions {
        coarse_level: live.coarse_level,
        background: live.background,
        shade: false,
        drop_apart: live.drop_apart(),
    };
    let r = renderer.render(field, colors, spec, &opts);
    let r = r.map_err(|e| e.to_string());
    let times = renderer.last_times();
    renderer.set_antialias(live.antialias);
    finish_render(sh, t, live, r.map(|st| (st, times)), |size| {
        // The grid image is the display image at the grid's size without the partial pixels.
        Ok(if size == live.resolution && !live.antialias {
            renderer.rgba().to_vec()
        } else {
            renderer.render_display(size, live.background).to_vec()
        })
    })
}

/// A rendered frame's accounting: its evaluations and time, or the failure as the degraded
/// state; the image at the live output size from `image`.
pub(super) fn finish_render(
    sh: &Shared,
    t: Instant,
    live: &Live,
    r: Result<
        (
            volcap_engine::render::RenderStats,
            volcap_engine::render::RenderTimes,
        ),
        String,
    >,
    image: impl FnOnce(usize) -> Result<Vec<u8>, String>,
) -> Option<Vec<u8>> {
    let fail = |e: String| {
        sh.stats[stage::RENDER].lost.fetch_add(1, Ordering::Relaxed);
        sh.set_state(PipelineState::Degraded(format!("render failed: {e}")));
    };
    let times = match r {
        Ok((st, times)) => {
            let n = st.coarse_evaluations + st.final_evaluations + st.normal_evaluations;
            sh.evaluations.fetch_add(n, Ordering::Relaxed);
            if st.held_sides > 0 {
                sh.held_frames.fetch_add(1, Ordering::Relaxed);
                sh.held_sides.fetch_add(st.held_sides, Ordering::Relaxed);
            }
            if st.dropped_apart > 0 {
                sh.apart_frames.fetch_add(1, Ordering::Relaxed);
                sh.apart_points
                    .fetch_add(st.dropped_apart, Ordering::Relaxed);
            }
            times
        }
        Err(e) => {
            fail(e);
            return None;
        }
    };
    let rgba = match image(live.out_size()) {
        Ok(px) => px,
        Err(e) => {
            fail(e);
            return None;
        }
    };
    let ms = t.elapsed().as_secs_f64() * 1e3;
    sh.stats[stage::RENDER].record(ms);
    if sh.mode == "model" {
        sh.parts[part::LOCALIZE].record(times.localize_ms);
        sh.parts[part::SURFACE].record(times.surface_ms);
        sh.parts[part::DISPLAY].record((ms - times.localize_ms - times.surface_ms).max(0.0));
    }
    Some(rgba)
}

#[cfg(test)]
mod tests {
    use super::super::*;

    /// `compute.render_workers = 3`: the render stage on three threads, each taking the
    /// latest frame as it comes free. The frames that come out are in capture order (a
    /// frame finished after a newer one is dropped, never published after it), more than one
    /// worker rendered, and `/state`'s counters add up to the render stage's frames.
    #[test]
    fn several_render_workers_publish_in_capture_order() {
        let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/scenes/front-walk.toml");
        let cfg = Config::parse(
            &format!(
                "[camera]\nbackend = \"sim\"\nscene = {:?}\n[render]\nfield = \"oracle\"\n\
                 resolution = 65\ndisplay_size = 0\n[dbus]\nbus = \"none\"\n\
                 [compute]\nrender_workers = 3\n",
                scene.display().to_string()
            ),
            std::path::Path::new("workers.toml"),
        )
        .unwrap();
        let (factory, _) = crate::capture::factory(&cfg).unwrap();
        let (tx, mut rx) = tokio::sync::watch::channel(None);
        let shared = Arc::new(Shared::new(&cfg, "test".into(), tx));
        assert_eq!(shared.render.count(), 3);
        let threads = start(&cfg, factory, shared.clone(), None);
        let seen = published_indices(&mut rx, 40, Duration::from_secs(60));
        shared.stop.store(true, Ordering::Relaxed);
        for t in threads {
            t.join().unwrap();
        }
        assert!(seen.len() >= 40, "{} frames published in 60 s", seen.len());
        assert!(
            seen.windows(2).all(|w| w[0] < w[1]),
            "published out of capture order: {seen:?}"
        );
        let per_worker = shared.render.frame_counts();
        assert_eq!(per_worker.len(), 3);
        assert!(
            per_worker.iter().filter(|&&n| n > 0).count() >= 2,
            "one worker did all the work: {per_worker:?}"
        );
        assert_eq!(
            per_worker.iter().sum::<u64>(),
            shared.stats[stage::RENDER].frames.load(Ordering::Relaxed),
            "{per_worker:?}"
        );
        assert!(shared.worker_beats().iter().all(|(_, b)| *b > 0));
    }

    /// `render.antialias` reaches the published frames: with it (the default) the person's
    /// outline has partial pixels (a transparent background: alpha strictly between 0 and
    /// 255), at the display size and at the grid's own; without it every pixel is the person
    /// or the background, and the pixels more than half covered are the same ones.
    #[test]
    fn the_antialiased_outline_reaches_the_published_frames() {
        let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/scenes/front-walk.toml");
        let frame = |antialias: bool, display: usize| {
            let cfg = Config::parse(
                &format!(
                    "[camera]\nbackend = \"sim\"\nscene = {:?}\n[render]\nfield = \"oracle\"\n\
                     resolution = 65\ndisplay_size = {display}\nantialias = {antialias}\n\
                     background = [0.0, 0.0, 0.0, 0.0]\n[dbus]\nbus = \"none\"\n",
                    scene.display().to_string()
                ),
                std::path::Path::new("aa.toml"),
            )
            .unwrap();
            let (factory, _) = crate::capture::factory(&cfg).unwrap();
            let (tx, mut rx) = tokio::sync::watch::channel(None);
            let shared = Arc::new(Shared::new(&cfg, "test".into(), tx));
            let threads = start(&cfg, factory, shared.clone(), None);
            let seen = published_indices(&mut rx, 1, Duration::from_secs(60));
            let rgba = rx.borrow().as_ref().map(|p| p.rgba.clone());
            shared.stop.store(true, Ordering::Relaxed);
            for t in threads {
                t.join().unwrap();
            }
            assert_eq!(seen.len(), 1, "no frame in 60 s");
            let alpha: Vec<u8> = rgba.unwrap().chunks_exact(4).map(|p| p[3]).collect();
            alpha
        };
        for display in [0, 128] {
            let whole = frame(false, display);
            let aa = frame(true, display);
            assert!(whole.iter().all(|&a| a == 0 || a == 255), "{display}");
            let partial = aa.iter().filter(|&&a| a > 0 && a < 255).count();
            let shown = whole.iter().filter(|&&a| a == 255).count();
            eprintln!("{display}: {partial} partial, {shown} shown");
            assert!(
                partial > shown.isqrt(),
                "{display}: {partial} partial of {shown}"
            );
            // The sim's person walks: the frames differ, but both shown about as much.
            let half = aa.iter().filter(|&&a| a > 127).count();
            assert!(
                half.abs_diff(shown) * 10 < shown,
                "{display}: {half} vs {shown}"
            );
        }
    }
}
