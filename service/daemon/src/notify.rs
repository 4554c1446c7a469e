//! systemd integration (sd_notify): `READY=1` once the first frame is published, `STATUS=`
//! lines that say what the daemon is doing, and watchdog pings fed by the pipeline's own
//! progress. Every pipeline thread bumps a heartbeat each loop turn (idle turns included);
//! a ping goes out only when every heartbeat moved since the last check, so a stalled
//! thread (a hung camera driver, a render that never returns) stops the pings while the
//! async runtime and HTTP server, alive or not, cannot keep the dog fed.
//!
//! Without `NOTIFY_SOCKET` (not under systemd) every call is a no-op.

use crate::pipeline::{Shared, THREADS};
use sd_notify::NotifyState;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Pings go out at half the watchdog period; without a watchdog the status still updates.
pub fn spawn(shared: Arc<Shared>) -> std::io::Result<std::thread::JoinHandle<()>> {
    let watchdog = sd_notify::watchdog_enabled();
    let tick = watchdog.map_or(Duration::from_secs(2), |w| {
        (w / 2).max(Duration::from_millis(50))
    });
    std::thread::Builder::new()
        .name("notify".into())
        .spawn(move || {
            let mut ready = false;
            let mut last_beats = Beats::default();
            let mut last_status = String::new();
            let mut stalled_logged = false;
            while !shared.stop.load(Ordering::Relaxed) {
                std::thread::sleep(tick);
                if !ready && shared.published.borrow().is_some() {
                    ready = true;
                    let _ = sd_notify::notify(&[NotifyState::Ready]);
                    tracing::info!("first frame published: READY");
                }
                let stalled = stalled_threads(&shared, &mut last_beats);
                let status = if stalled.is_empty() {
                    stalled_logged = false;
                    if watchdog.is_some() {
                        let _ = sd_notify::notify(&[NotifyState::Watchdog]);
                    }
                    status_line(&shared)
                } else {
                    if !stalled_logged {
                        tracing::error!(
                            "pipeline stalled ({} thread); watchdog pings stop",
                            stalled.join(", ")
                        );
                        stalled_logged = true;
                    }
                    format!("stalled: {} thread not progressing", stalled.join(", "))
                };
                if status != last_status {
                    let _ = sd_notify::notify(&[NotifyState::Status(&status)]);
                    last_status = status;
                }
            }
            let _ = sd_notify::notify(&[NotifyState::Stopping]);
        })
}

/// The pipeline's heartbeats at the last check.
#[derive(Default)]
struct Beats {
    threads: [u64; THREADS.len()],
    /// The stages' further workers (`render-2`, ..., `segment-2`, ...).
    workers: Vec<u64>,
}

/// The running pipeline threads whose heartbeat has not moved since `last` (which becomes
/// now): [`THREADS`] by name, and the stages' further workers as `render-2`, ...,
/// `segment-2`, ...
fn stalled_threads(shared: &Shared, last: &mut Beats) -> Vec<String> {
    let beats = shared.beats.each_ref().map(|b| b.load(Ordering::Relaxed));
    let mut stalled: Vec<String> = THREADS
        .iter()
        .enumerate()
        .zip(beats.iter().zip(&last.threads))
        .filter(|((i, _), (now, before))| {
            crate::pipeline::thread_runs(*i, shared.mode) && now == before
        })
        .map(|((_, name), _)| name.to_string())
        .collect();
    let workers = shared.worker_beats();
    last.workers.resize(workers.len(), 0);
    stalled.extend(
        workers
            .iter()
            .zip(&last.workers)
            .filter(|((_, now), before)| now == *before)
            .map(|((name, _), _)| name.clone()),
    );
    last.threads = beats;
    last.workers = workers.into_iter().map(|(_, b)| b).collect();
    stalled
}

/// Running without a published frame this long is reported as stalled.
pub const STALL_AFTER: Duration = Duration::from_secs(2);

/// One line for `systemctl status`.
pub fn status_line(shared: &Shared) -> String {
    let (state, reason) = shared
        .state
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .name_reason();
    let (p50, _) = shared.e2e.percentiles();
    let fps = shared.e2e.recent_fps();
    let quiet = shared.e2e.since_last().filter(|d| *d >= STALL_AFTER);
    if state == "running"
        && let Some(quiet) = quiet
        && !shared.live().paused
    {
        // Threads may be turning (no watchdog stall) while no frame comes out.
        return format!(
            "stalled: no frame published for {:.1} s ({})",
            quiet.as_secs_f64(),
            shared.mode
        );
    }
    if reason.is_empty() {
        format!(
            "{state}: {fps:.1} fps, latency p50 {p50:.0} ms ({})",
            shared.mode
        )
    } else {
        format!("{state}: {reason}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::PipelineState;

    /// Hardening round two, #5: STATUS said "running: 0.0 fps" while no frame came out
    /// (threads turning, so no watchdog stall). Now it says stalled, and for how long.
    #[test]
    fn running_without_frames_is_reported_as_stalled() {
        let cfg = crate::config::Config::parse(
            "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n[dbus]\nbus = \"none\"\n",
            std::path::Path::new("t.toml"),
        )
        .unwrap();
        let (tx, _) = tokio::sync::watch::channel(None);
        let shared = Shared::new(&cfg, "test".into(), tx);
        shared.set_state(PipelineState::Running);
        shared.e2e.record(10.0);
        shared.e2e.record(10.0);
        assert!(
            status_line(&shared).starts_with("running: "),
            "{}",
            status_line(&shared)
        );
        std::thread::sleep(STALL_AFTER + Duration::from_millis(100));
        let s = status_line(&shared);
        assert!(s.starts_with("stalled: no frame published for 2."), "{s}");
        shared.e2e.record(10.0);
        assert!(status_line(&shared).starts_with("running: "));
    }

    #[test]
    fn a_stalled_render_worker_is_named_even_while_the_others_turn() {
        let cfg = crate::config::Config::parse(
            "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n[dbus]\nbus = \"none\"\n\
             [compute]\nrender_workers = 3\n",
            std::path::Path::new("t.toml"),
        )
        .unwrap();
        let (tx, _) = tokio::sync::watch::channel(None);
        let shared = Shared::new(&cfg, "test".into(), tx);
        assert_eq!(shared.render.count(), 3);
        let mut last = Beats::default();
        // Nothing has beaten yet: every thread of the oracle mode, and both further workers.
        let all = stalled_threads(&shared, &mut last);
        assert_eq!(all, ["capture", "render", "encode", "render-2", "render-3"]);
        // Every thread but the third render worker turns.
        let turn = |skip: Option<&str>| {
            for (i, b) in shared.beats.iter().enumerate() {
                if Some(THREADS[i]) != skip {
                    b.fetch_add(1, Ordering::Relaxed);
                }
            }
            for (i, b) in shared.render.beats.iter().enumerate() {
                if Some(format!("render-{}", i + 2).as_str()) != skip {
                    b.fetch_add(1, Ordering::Relaxed);
                }
            }
        };
        turn(Some("render-3"));
        assert_eq!(stalled_threads(&shared, &mut last), ["render-3"]);
        turn(None);
        assert!(stalled_threads(&shared, &mut last).is_empty());
        turn(Some("render"));
        assert_eq!(stalled_threads(&shared, &mut last), ["render"]);
    }

    #[test]
    fn a_stalled_segment_worker_is_named_in_model_mode() {
        let cfg = crate::config::Config::parse(
            "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n[dbus]\nbus = \"none\"\n\
             [render]\nfield = \"model\"\n[compute]\nsegment_workers = 2\n",
            std::path::Path::new("t.toml"),
        )
        .unwrap();
        let (tx, _) = tokio::sync::watch::channel(None);
        let shared = Shared::new(&cfg, "test".into(), tx);
        let mut last = Beats::default();
        assert_eq!(
            stalled_threads(&shared, &mut last),
            [
                "capture",
                "render",
                "encode",
                "field",
                "segment",
                "segment-2"
            ]
        );
        for b in &shared.beats {
            b.fetch_add(1, Ordering::Relaxed);
        }
        assert_eq!(stalled_threads(&shared, &mut last), ["segment-2"]);
        shared.segment.beats[0].fetch_add(1, Ordering::Relaxed);
        for b in &shared.beats {
            b.fetch_add(1, Ordering::Relaxed);
        }
        assert!(stalled_threads(&shared, &mut last).is_empty());
    }
}
