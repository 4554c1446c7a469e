//! The capture stage: the supervised camera; frames go to the latest-wins slot, camera losses
//! become pipeline states and placeholder frames (at most one a second).

use super::*;

/// Spawn the capture thread: take a frame from the camera (or a state), put it latest-wins.
pub(super) fn spawn(
    sh: Arc<Shared>,
    factory: CameraFactory,
    out: Arc<Slot<Frame>>,
    placeholders: Arc<Slot<Rendered>>,
) -> std::thread::JoinHandle<()> {
    std::thread::Builder::new()
        .name("capture".into())
        .spawn(move || {
            let cam = match factory() {
                Ok(c) => c,
                Err(e) => {
                    tracing::error!("camera: {e}");
                    sh.set_state(PipelineState::Failed(format!("camera: {e}")));
                    return;
                }
            };
            let mut sup: Supervisor<dyn Camera> = Supervisor::new(cam, Backoff::default());
            let mut last_placeholder: Option<Instant> = None;
            let mut last_kind = "";
            let mut skips = 0u64;
            let mut skips_in_a_row = 0u64;
            while !sh.stop.load(Ordering::Relaxed) {
                sh.beat(0);
                let swap = sh
                    .camera_swap
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .take();
                if let Some(factory) = swap {
                    match factory() {
                        Ok(cam) => {
                            sup.shutdown();
                            tracing::info!(source = %cam.describe(), "switching camera (config reload)");
                            sup = Supervisor::new(cam, Backoff::default());
                            last_kind = "";
                        }
                        Err(e) => tracing::error!(
                            "camera switch refused, keeping the current one: {e}"
                        ),
                    }
                }
                let step = sup.step(Duration::from_millis(200));
                {
                    let mut st = sh.camera.lock().unwrap_or_else(|p| p.into_inner());
                    camera_status_from(&sup, &mut st);
                    if let Step::Skipped(s) = &step {
                        match s {
                            Skip::Truncated(_) => st.truncated += 1,
                            Skip::Corrupt(_) => st.corrupt += 1,
                        }
                    }
                }
                match step {
                    Step::Frame(f) => {
                        skips_in_a_row = 0;
                        if last_kind != "running" {
                            tracing::info!(source = %sup.describe(), "camera running");
                            last_kind = "running";
                        }
                        sh.stats[stage::CAPTURE].record(f.at.elapsed().as_secs_f64() * 1e3);
                        if out.put(f) {
                            sh.stats[stage::CAPTURE].superseded.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    Step::Skipped(s) => {
                        skips += 1;
                        skips_in_a_row += 1;
                        if skips <= 10 || skips.is_power_of_two() {
                            tracing::warn!(skipped = skips, "camera frame skipped: {s:?}");
                        }
                        // Nothing decodable for a while (a folder of bad files, a
                        // garbled stream): say so, with a placeholder (which also
                        // lets systemd see the daemon up), instead of "starting".
                        if skips_in_a_row >= SKIPS_DEGRADE {
                            let why = format!(
                                "no decodable frame from {}: {skips_in_a_row} skipped in a row (last: {})",
                                sup.describe(),
                                match &s {
                                    Skip::Truncated(m) | Skip::Corrupt(m) => m,
                                }
                            );
                            sh.set_state(PipelineState::Degraded(why.clone()));
                            if last_placeholder
                                .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
                            {
                                last_placeholder = Some(Instant::now());
                                let live = sh.live();
                                placeholders.put(Rendered {
                                    index: 0,
                                    at: Instant::now(),
                                    rgba: crate::placeholder::frame(
                                        live.out_size(),
                                        live.background,
                                        "NO USABLE FRAME",
                                        &why,
                                    ),
                                    size: live.out_size(),
                                    placeholder: true,
                                });
                            }
                        }
                    }
                    Step::State(state) => {
                        let (kind, why) = match &state {
                            CameraState::Lost { fault, retry_in } => (
                                fault.kind(),
                                format!(
                                    "camera lost: {fault}; retrying in {:.1} s",
                                    retry_in.as_secs_f32()
                                ),
                            ),
                            CameraState::Stopped(fault) => {
                                (fault.kind(), format!("camera stopped: {fault}"))
                            }
                            other => ("", format!("camera {other:?}")),
                        };
                        if kind != last_kind {
                            tracing::warn!(source = %sup.describe(), "{why}");
                            last_kind = kind;
                        }
                        sh.set_state(PipelineState::Degraded(why.clone()));
                        if last_placeholder
                            .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
                        {
                            last_placeholder = Some(Instant::now());
                            let live = sh.live();
                            let (size, bg) = (live.out_size(), live.background);
                            placeholders.put(Rendered {
                                index: 0,
                                at: Instant::now(),
                                rgba: crate::placeholder::frame(
                                    size,
                                    bg,
                                    "NO CAMERA",
                                    &why,
                                ),
                                size,
                                placeholder: true,
                            });
                        }
                    }
                }
            }
            sup.shutdown();
        })
        .expect("spawning the capture thread")
}
