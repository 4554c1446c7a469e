//! The render stage: the model's field (from the field stage), the oracle field or the camera
//! frame itself, localized and rendered mesh-free from the live view; latest wins on both sides.

use super::*;

/// Spawn the render thread: take the latest frame (and its field), render, put latest-wins.
#[allow(clippy::too_many_arguments)]
pub(super) fn spawn(
    sh: Arc<Shared>,
    input: Arc<Slot<Frame>>,
    fielded: Arc<Slot<(Frame, FieldOutcome)>>,
    out: Arc<Slot<Rendered>>,
    voxel: f32,
    mode: FieldMode,
    eval_threads: usize,
    compute: crate::config::ComputeConfig,
    models: Option<Arc<volcap_engine::model::Models>>,
) -> std::thread::JoinHandle<()> {
    std::thread::Builder::new()
        .name("render".into())
        .spawn(move || {
            let mut renderer = Renderer::new();
            renderer.set_threads(eval_threads);
            // On the GPU backend the model's frames are localized and drawn on the adapter.
            let mut on_adapter = super::AdapterRenderer::open(models.as_deref(), mode, &compute);
            if let Some(r) = &on_adapter {
                let _ = sh.compute.render_device.set(r.device_name());
            }
            let degraded = |why: String, f: &Frame, size: usize, bg: [f32; 4]| {
                let rgba = crate::placeholder::frame(size, bg, "NOT RENDERED", &why);
                sh.set_state(PipelineState::Degraded(why));
                if out.put(Rendered {
                    index: f.seq,
                    at: f.at,
                    rgba,
                    size,
                    placeholder: true,
                }) {
                    sh.stats[stage::RENDER]
                        .superseded
                        .fetch_add(1, Ordering::Relaxed);
                }
            };
            while !sh.stop.load(Ordering::Relaxed) {
                sh.beat(1);
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
                if out.put(Rendered {
                    index: f.seq,
                    at: f.at,
                    rgba,
                    size,
                    placeholder: false,
                }) {
                    sh.stats[stage::RENDER]
                        .superseded
                        .fetch_add(1, Ordering::Relaxed);
                }
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
