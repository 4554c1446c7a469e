//! What the daemon reports over HTTP: `/state` (JSON; stream clients' addresses only with
//! the token) and `/metrics` (Prometheus text).

use super::{App, peer_ip, token_refusal};
use crate::pipeline::{STAGES, part};
use axum::extract::{ConnectInfo, State};
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// What `superseded` counts, said where it is shown (`/state`, `/metrics`).
pub(super) const SUPERSEDED_NOTE: &str = "frames replaced by a newer one before the next stage needed them (latest frame wins: nothing queues, the next stage takes the newest), or, with several workers in a stage (render, segment), finished after a newer one; not lost";

/// `/state`; stream clients' addresses only with the token (`details`), counts to anyone.
pub(super) fn state_json(app: &App, details: bool) -> serde_json::Value {
    let sh = &app.shared;
    let st = sh.state.lock().unwrap_or_else(|p| p.into_inner()).clone();
    let (state, reason) = st.name_reason();
    let stages: serde_json::Map<String, serde_json::Value> = STAGES
        .iter()
        .zip(&sh.stats)
        .map(|(n, s)| {
            let (p50, p99) = s.percentiles();
            (n.to_string(), serde_json::json!({"p50_ms": p50, "p99_ms": p99, "frames": s.frames.load(Ordering::Relaxed), "superseded": s.superseded.load(Ordering::Relaxed), "lost": s.lost.load(Ordering::Relaxed)}))
        })
        .collect();
    // Model mode: where the field and render stages' time goes (`pipeline::part`).
    let parts: serde_json::Map<String, serde_json::Value> = if sh.mode == "model" {
        part::NAMES
            .iter()
            .zip(&sh.parts)
            .map(|(n, s)| {
                let (p50, p99) = s.percentiles();
                (
                    n.to_string(),
                    serde_json::json!({"p50_ms": p50, "p99_ms": p99}),
                )
            })
            .collect()
    } else {
        serde_json::Map::new()
    };
    let (l50, l99) = sh.e2e.percentiles();
    let published = sh.e2e.frames.load(Ordering::Relaxed);
    let up = sh.started.elapsed().as_secs_f64();
    let live = sh.live();
    let camera = sh.camera.lock().unwrap_or_else(|p| p.into_inner()).clone();
    let per_client: Vec<serde_json::Value> = app
        .table
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .iter()
        .map(|(id, c)| {
            let secs = c.since.elapsed().as_secs_f64();
            let sent = c.sent.load(Ordering::Relaxed);
            let mut v = serde_json::json!({
                "id": id, "connected_s": secs, "frames_sent": sent,
                "frames_skipped": c.skipped.load(Ordering::Relaxed),
                "fps": if secs > 0.0 { sent as f64 / secs } else { 0.0 },
            });
            if details {
                v["peer"] = c.peer.clone().into();
            }
            v
        })
        .collect();
    let mut compute = sh.compute.to_json();
    compute["render_workers"] = sh.render.count().into();
    compute["render_worker_frames"] = sh.render.frame_counts().into();
    if sh.mode == "model" {
        compute["segment_workers"] = sh.segment.count().into();
        compute["segment_worker_frames"] = sh.segment.frame_counts().into();
    }
    serde_json::json!({
        "state": state, "reason": reason, "mode": sh.mode,
        "mode_note": match sh.mode {
            "oracle" => "ground-truth field rendered through the engine: not a reconstruction",
            "camera" => "the camera frame itself: no reconstruction",
            "model" => "reconstruction by the trained networks (segmentation, shape, colour; see models/)",
            _ => "",
        },
        "people": match sh.people.load(Ordering::Relaxed) {
            usize::MAX => serde_json::Value::Null,
            n => n.into(),
        },
        "field": sh.field_label,
        "runtime": (!sh.runtime.is_empty()).then(|| serde_json::json!({
            "name": sh.runtime,
            "note": sh.runtime_note,
        })),
        "compute": compute,
        "close_range": sh.close_range_model.then(|| sh.close_range.load(Ordering::Relaxed)),
        "temporal": sh.temporal.as_ref().map(|settings| serde_json::json!({
            "resets": sh.temporal_resets.load(Ordering::Relaxed),
            "settings": crate::config::temporal_json(settings),
            "held_sides": {
                "points": sh.held_sides.load(Ordering::Relaxed),
                "frames": sh.held_frames.load(Ordering::Relaxed),
                "adapter_refused": sh.held_refused.lock().map(|r| r.clone()).unwrap_or(None),
                "note": "temporal.surface_dead_band: grid points given out as in the last frame (their occupancy moved by less than the band, or crossed the level by less than it, while the crop was held and the view not turned), in all, and the rendered frames with any (on the CPU and on the GPU backend's adapter alike, by the same rule); adapter_refused: why the adapter's last frame was not held (its grid's memory, four bytes a point, does not fit one storage binding there), else null",
            },
        })),
        "segment_track": segment_track(sh),
        "drop_apart": {
            // As the file gives it (0.1, not f32's 0.10000000149).
            "gap": live.drop_apart.to_string().parse::<f64>().unwrap_or(0.0),
            "frames": sh.apart_frames.load(Ordering::Relaxed),
            "points": sh.apart_points.load(Ordering::Relaxed),
            "note": "render.drop_apart: inside pieces farther than this fraction of the grid's side from the body are left out of the render and /mesh.glb (0: kept); frames: rendered frames that left some out, points: the level L-1 grid points left out in all",
        },
        "resolution": live.resolution,
        "display_size": live.out_size(),
        "antialias": live.antialias,
        "paused": live.paused,
        "frames_published": published,
        "fps": if up > 0.0 { published as f64 / up } else { 0.0 },
        "latency_ms": {"p50": l50, "p99": l99},
        "stages": stages,
        "stage_parts": parts,
        "stage_notes": {
            "superseded": SUPERSEDED_NOTE,
            "lost": "frames a stage failed on (an error): frames lost",
        },
        "camera": camera,
        "showing_placeholder": sh.published.borrow().as_ref().is_some_and(|f| f.placeholder),
        "clients": app.clients.load(Ordering::SeqCst),
        "per_client": per_client,
        "client_limit": app.client_limit.load(Ordering::SeqCst),
        "rtsp": app.rtsp.to_json(),
        "controls": app.controls(),
        "view": {"yaw": live.yaw, "pitch": live.pitch, "distance": live.distance},
        "uptime_s": up,
    })
}

/// Model mode with two segmentation passes and `[model] segment_full_every` > 1: the track's
/// setting and how its frames went (null otherwise).
fn segment_track(sh: &crate::pipeline::Shared) -> serde_json::Value {
    let Some(full_every) = sh.segment_tracking() else {
        return serde_json::Value::Null;
    };
    let [full, crop, lost] = [0, 1, 2].map(|i| sh.segment_tracked[i].load(Ordering::Relaxed));
    serde_json::json!({
        "full_every": full_every,
        "whole_frames": full,
        "crop_frames": crop,
        "lost_frames": lost,
        "note": "model.segment_full_every: the whole frame segmented every this many frames, the frames between only the last person's crop (crop_frames; the whole frame once where that crop would magnify nothing); lost_frames: the person reached the crop's edge and the whole frame followed",
    })
}

pub(super) async fn state(
    State(app): State<Arc<App>>,
    headers: HeaderMap,
    peer: Option<axum::Extension<ConnectInfo<SocketAddr>>>,
) -> Response {
    // A wrong token here counts like one on /view (no free guessing through /state).
    let details = headers.contains_key(header::AUTHORIZATION)
        && match token_refusal(&app, &headers, peer_ip(&peer)) {
            None => true,
            Some(r) => return r,
        };
    (
        [(header::CONTENT_TYPE, "application/json")],
        state_json(&app, details).to_string(),
    )
        .into_response()
}

pub(super) async fn metrics(State(app): State<Arc<App>>) -> Response {
    let sh = &app.shared;
    let mut s = String::new();
    s.push_str("# TYPE volcap_frames_published_total counter\n");
    s.push_str(&format!(
        "volcap_frames_published_total {}\n",
        sh.e2e.frames.load(Ordering::Relaxed)
    ));
    s.push_str("# TYPE volcap_stage_ms summary\n");
    for (n, st) in STAGES.iter().zip(&sh.stats) {
        let (p50, p99) = st.percentiles();
        s.push_str(&format!("volcap_stage_ms{{stage=\"{n}\",quantile=\"0.5\"}} {p50}\nvolcap_stage_ms{{stage=\"{n}\",quantile=\"0.99\"}} {p99}\n"));
    }
    if sh.mode == "model" {
        s.push_str("# HELP volcap_stage_part_ms the field and render stages' parts (model mode)\n# TYPE volcap_stage_part_ms summary\n");
        for (n, st) in part::NAMES.iter().zip(&sh.parts) {
            let (p50, p99) = st.percentiles();
            s.push_str(&format!("volcap_stage_part_ms{{part=\"{n}\",quantile=\"0.5\"}} {p50}\nvolcap_stage_part_ms{{part=\"{n}\",quantile=\"0.99\"}} {p99}\n"));
        }
    }
    s.push_str(&format!(
        "# HELP volcap_stage_superseded_total {SUPERSEDED_NOTE}\n# TYPE volcap_stage_superseded_total counter\n"
    ));
    for (n, st) in STAGES.iter().zip(&sh.stats) {
        s.push_str(&format!(
            "volcap_stage_superseded_total{{stage=\"{n}\"}} {}\n",
            st.superseded.load(Ordering::Relaxed)
        ));
    }
    s.push_str("# HELP volcap_stage_lost_total frames a stage failed on (an error)\n# TYPE volcap_stage_lost_total counter\n");
    for (n, st) in STAGES.iter().zip(&sh.stats) {
        s.push_str(&format!(
            "volcap_stage_lost_total{{stage=\"{n}\"}} {}\n",
            st.lost.load(Ordering::Relaxed)
        ));
    }
    let (l50, l99) = sh.e2e.percentiles();
    s.push_str(&format!("# TYPE volcap_latency_ms summary\nvolcap_latency_ms{{quantile=\"0.5\"}} {l50}\nvolcap_latency_ms{{quantile=\"0.99\"}} {l99}\n"));
    s.push_str(&format!(
        "# TYPE volcap_clients gauge\nvolcap_clients {}\n",
        app.clients.load(Ordering::SeqCst)
    ));
    let w = &app.mesh_worker;
    s.push_str(&format!(
        "# HELP volcap_mesh_busy /mesh.glb computations running\n# TYPE volcap_mesh_busy gauge\nvolcap_mesh_busy {}\n\
         # HELP volcap_mesh_total /mesh.glb computations ended: a mesh, stopped because the client left, failed\n# TYPE volcap_mesh_total counter\n\
         volcap_mesh_total{{result=\"done\"}} {}\nvolcap_mesh_total{{result=\"cancelled\"}} {}\nvolcap_mesh_total{{result=\"failed\"}} {}\n",
        super::MESH_CONCURRENCY.saturating_sub(app.mesh_gate.available_permits()),
        w.done.load(Ordering::Relaxed),
        w.cancelled.load(Ordering::Relaxed),
        w.failed.load(Ordering::Relaxed)
    ));
    s.push_str(&format!(
        "# HELP volcap_render_apart_frames_total rendered frames that left pieces apart from the body out (render.drop_apart)\n# TYPE volcap_render_apart_frames_total counter\nvolcap_render_apart_frames_total {}\n\
         # HELP volcap_render_apart_points_total level L-1 grid points of pieces apart from the body left out\n# TYPE volcap_render_apart_points_total counter\nvolcap_render_apart_points_total {}\n",
        sh.apart_frames.load(Ordering::Relaxed),
        sh.apart_points.load(Ordering::Relaxed)
    ));
    if sh.temporal.is_some() {
        s.push_str(&format!(
            "# HELP volcap_render_held_frames_total rendered frames with grid points held by temporal.surface_dead_band\n# TYPE volcap_render_held_frames_total counter\nvolcap_render_held_frames_total {}\n\
             # HELP volcap_render_held_points_total grid points given out as in the last frame (temporal.surface_dead_band)\n# TYPE volcap_render_held_points_total counter\nvolcap_render_held_points_total {}\n",
            sh.held_frames.load(Ordering::Relaxed),
            sh.held_sides.load(Ordering::Relaxed)
        ));
    }
    if sh.segment_tracking().is_some() {
        s.push_str("# HELP volcap_segment_track_frames_total frames segmented with model.segment_full_every's track: whole (the whole frame too), crop (the last person's crop alone), lost (the person reached the crop's edge)\n# TYPE volcap_segment_track_frames_total counter\n");
        for (i, kind) in ["whole", "crop", "lost"].iter().enumerate() {
            s.push_str(&format!(
                "volcap_segment_track_frames_total{{kind=\"{kind}\"}} {}\n",
                sh.segment_tracked[i].load(Ordering::Relaxed)
            ));
        }
    }
    s.push_str(&app.rtsp.metrics());
    s.push_str(&sh.compute.metrics());
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], s).into_response()
}
