//! LAN publishing over HTTP (axum). Every stream client reads the latest published frame
//! through a `watch` channel: a slow client skips frames and never stalls the pipeline or
//! other clients; a disconnected client's slot is freed when its body is dropped.

use crate::pipeline::{STAGES, Shared};
use axum::Router;
use axum::body::Body;
use axum::extract::{ConnectInfo, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

pub struct App {
    pub shared: Arc<Shared>,
    pub clients: AtomicUsize,
    /// Both reloadable (D-Bus `Reload`).
    pub client_limit: AtomicUsize,
    pub token: Mutex<Option<String>>,
    /// Connected stream clients, for per-client figures in `/state`.
    pub table: Mutex<BTreeMap<u64, Arc<ClientStat>>>,
    pub next_id: AtomicU64,
}

impl App {
    pub fn new(shared: Arc<Shared>, client_limit: usize, token: Option<String>) -> Self {
        Self {
            shared,
            clients: AtomicUsize::new(0),
            client_limit: AtomicUsize::new(client_limit),
            token: Mutex::new(token),
            table: Mutex::new(BTreeMap::new()),
            next_id: AtomicU64::new(1),
        }
    }
}

/// One stream client: frames sent, frames it skipped (published while it was still
/// writing an earlier one), since when.
pub struct ClientStat {
    pub peer: String,
    pub since: Instant,
    pub sent: AtomicU64,
    pub skipped: AtomicU64,
}

pub fn router(app: Arc<App>) -> Router {
    Router::new()
        .route("/", get(viewer))
        .route("/stream.mjpg", get(stream))
        .route("/snapshot.jpg", get(snapshot_jpg))
        .route("/snapshot.png", get(snapshot_png))
        .route("/mesh.glb", get(mesh_glb))
        .route("/state", get(state))
        .route("/metrics", get(metrics))
        .route("/view", post(set_view))
        .with_state(app)
}

const BOUNDARY: &str = "volcapframe";

async fn viewer(State(app): State<Arc<App>>) -> Html<String> {
    Html(include_str!("viewer.html").replace("{{MODE}}", app.shared.mode))
}

/// Frees a client slot when the stream body is dropped (client gone).
struct ClientGuard(Arc<App>, u64, Arc<ClientStat>);
impl Drop for ClientGuard {
    fn drop(&mut self) {
        self.0
            .table
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&self.1);
        self.0.clients.fetch_sub(1, Ordering::SeqCst);
    }
}

async fn stream(
    State(app): State<Arc<App>>,
    peer: Option<axum::Extension<ConnectInfo<SocketAddr>>>,
) -> Response {
    let prev = app.clients.fetch_add(1, Ordering::SeqCst);
    let limit = app.client_limit.load(Ordering::SeqCst);
    if prev >= limit {
        app.clients.fetch_sub(1, Ordering::SeqCst);
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            format!("client limit of {limit} reached\n"),
        )
            .into_response();
    }
    let id = app.next_id.fetch_add(1, Ordering::Relaxed);
    let stat = Arc::new(ClientStat {
        peer: peer
            .map(|axum::Extension(ConnectInfo(a))| a.to_string())
            .unwrap_or_default(),
        since: Instant::now(),
        sent: AtomicU64::new(0),
        skipped: AtomicU64::new(0),
    });
    app.table
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(id, stat.clone());
    let guard = ClientGuard(app.clone(), id, stat);
    let mut rx = app.shared.published.subscribe();
    rx.mark_changed();
    let body = futures_util::stream::unfold(
        (rx, guard, None::<u64>),
        |(mut rx, guard, mut last)| async move {
            loop {
                if rx.changed().await.is_err() {
                    return None;
                }
                let frame = rx.borrow_and_update().clone();
                if let Some(f) = frame {
                    if let Some(prev) = last
                        && f.index > prev + 1
                        && !f.placeholder
                    {
                        guard
                            .2
                            .skipped
                            .fetch_add(f.index - prev - 1, Ordering::Relaxed);
                    }
                    if !f.placeholder {
                        last = Some(f.index);
                    }
                    guard.2.sent.fetch_add(1, Ordering::Relaxed);
                    let mut part = format!(
                    "--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\nX-Frame-Index: {}\r\nX-Latency-Ms: {:.1}\r\n\r\n",
                    f.jpeg.len(),
                    f.index,
                    f.latency_ms
                )
                .into_bytes();
                    part.extend_from_slice(&f.jpeg);
                    part.extend_from_slice(b"\r\n");
                    return Some((Ok::<_, std::io::Error>(part), (rx, guard, last)));
                }
            }
        },
    );
    Response::builder()
        .header(
            header::CONTENT_TYPE,
            format!("multipart/x-mixed-replace; boundary={BOUNDARY}"),
        )
        .header(header::CACHE_CONTROL, "no-cache, no-store")
        .header(header::CONNECTION, "close")
        .body(Body::from_stream(body))
        .unwrap_or_else(|_| StatusCode::INTERNAL_SERVER_ERROR.into_response())
}

fn latest(app: &App) -> Option<Arc<crate::pipeline::Published>> {
    app.shared.published.borrow().clone()
}

async fn snapshot_jpg(State(app): State<Arc<App>>) -> Response {
    match latest(&app) {
        Some(f) => ([(header::CONTENT_TYPE, "image/jpeg")], f.jpeg.clone()).into_response(),
        None => (StatusCode::SERVICE_UNAVAILABLE, "no frame yet\n").into_response(),
    }
}

async fn snapshot_png(State(app): State<Arc<App>>) -> Response {
    let Some(f) = latest(&app) else {
        return (StatusCode::SERVICE_UNAVAILABLE, "no frame yet\n").into_response();
    };
    let png = tokio::task::spawn_blocking(move || f.to_png().ok())
        .await
        .ok()
        .flatten();
    match png {
        Some(p) => ([(header::CONTENT_TYPE, "image/png")], p).into_response(),
        None => (StatusCode::INTERNAL_SERVER_ERROR, "png encoding failed\n").into_response(),
    }
}

/// The current frame as a coloured mesh: hierarchical localization at the render
/// resolution, marching cubes, glTF binary. Slower than a frame (hundreds of ms); runs off
/// the async runtime.
async fn mesh_glb(State(app): State<Arc<App>>) -> Response {
    let field = app
        .shared
        .latest_field
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .clone();
    let Some(field) = field else {
        return (StatusCode::SERVICE_UNAVAILABLE, "no frame yet\n").into_response();
    };
    let live = app.shared.live();
    let (res, coarse) = (live.resolution, live.coarse_level);
    let glb = tokio::task::spawn_blocking(move || -> Result<Vec<u8>, String> {
        let spec =
            volcap_engine::grid::GridSpec::from_resolution(res).map_err(|e| e.to_string())?;
        let mut grid = volcap_engine::grid::Grid::new(spec);
        volcap_engine::localize::Localizer::new()
            .run(
                volcap_engine::localize::Method::Hierarchical,
                field.as_ref(),
                spec,
                coarse,
                &mut grid,
            )
            .map_err(|e| e.to_string())?;
        let mut mesh = volcap_engine::mesh::marching_cubes(&grid);
        mesh.paint(field.as_ref()).map_err(|e| e.to_string())?;
        Ok(mesh.to_glb())
    })
    .await;
    match glb {
        Ok(Ok(b)) => ([(header::CONTENT_TYPE, "model/gltf-binary")], b).into_response(),
        Ok(Err(e)) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("mesh failed: {e}\n"),
        )
            .into_response(),
        Err(_) => (StatusCode::INTERNAL_SERVER_ERROR, "mesh task failed\n").into_response(),
    }
}

fn state_json(app: &App) -> serde_json::Value {
    let sh = &app.shared;
    let st = sh.state.lock().unwrap_or_else(|p| p.into_inner()).clone();
    let (state, reason) = st.name_reason();
    let stages: serde_json::Map<String, serde_json::Value> = STAGES
        .iter()
        .zip(&sh.stats)
        .map(|(n, s)| {
            let (p50, p99) = s.percentiles();
            (n.to_string(), serde_json::json!({"p50_ms": p50, "p99_ms": p99, "frames": s.frames.load(Ordering::Relaxed), "dropped": s.dropped.load(Ordering::Relaxed)}))
        })
        .collect();
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
            serde_json::json!({
                "id": id, "peer": c.peer, "connected_s": secs, "frames_sent": sent,
                "frames_skipped": c.skipped.load(Ordering::Relaxed),
                "fps": if secs > 0.0 { sent as f64 / secs } else { 0.0 },
            })
        })
        .collect();
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
        "resolution": live.resolution,
        "paused": live.paused,
        "frames_published": published,
        "fps": if up > 0.0 { published as f64 / up } else { 0.0 },
        "latency_ms": {"p50": l50, "p99": l99},
        "stages": stages,
        "camera": camera,
        "showing_placeholder": sh.published.borrow().as_ref().is_some_and(|f| f.placeholder),
        "clients": app.clients.load(Ordering::SeqCst),
        "per_client": per_client,
        "client_limit": app.client_limit.load(Ordering::SeqCst),
        "view": {"yaw": live.yaw, "pitch": live.pitch, "distance": live.distance},
        "uptime_s": up,
    })
}

async fn state(State(app): State<Arc<App>>) -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        state_json(&app).to_string(),
    )
        .into_response()
}

async fn metrics(State(app): State<Arc<App>>) -> Response {
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
    s.push_str("# TYPE volcap_stage_dropped_total counter\n");
    for (n, st) in STAGES.iter().zip(&sh.stats) {
        s.push_str(&format!(
            "volcap_stage_dropped_total{{stage=\"{n}\"}} {}\n",
            st.dropped.load(Ordering::Relaxed)
        ));
    }
    let (l50, l99) = sh.e2e.percentiles();
    s.push_str(&format!("# TYPE volcap_latency_ms summary\nvolcap_latency_ms{{quantile=\"0.5\"}} {l50}\nvolcap_latency_ms{{quantile=\"0.99\"}} {l99}\n"));
    s.push_str(&format!(
        "# TYPE volcap_clients gauge\nvolcap_clients {}\n",
        app.clients.load(Ordering::SeqCst)
    ));
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], s).into_response()
}

/// Constant-time comparison of the bearer token.
fn token_ok(expected: &str, headers: &HeaderMap) -> bool {
    let got = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .unwrap_or("");
    let (a, b) = (expected.as_bytes(), got.as_bytes());
    let mut diff = (a.len() ^ b.len()) as u8;
    for (i, x) in a.iter().enumerate() {
        diff |= x ^ b.get(i).copied().unwrap_or(0);
    }
    diff == 0 && a.len() == b.len()
}

#[derive(serde::Deserialize)]
struct ViewQuery {
    yaw: f32,
    pitch: f32,
    distance: Option<f32>,
    resolution: Option<usize>,
    /// `r,g,b,a` in [0, 1]; alpha 0 = transparent PNG snapshots.
    background: Option<String>,
}

async fn set_view(
    State(app): State<Arc<App>>,
    headers: HeaderMap,
    q: Result<Query<ViewQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    let expected = app.token.lock().unwrap_or_else(|p| p.into_inner()).clone();
    let Some(expected) = expected else {
        return (
            StatusCode::FORBIDDEN,
            "view controls are off: set http.token in the config\n",
        )
            .into_response();
    };
    if !token_ok(&expected, &headers) {
        return (StatusCode::UNAUTHORIZED, "bad or missing bearer token\n").into_response();
    }
    let Ok(Query(q)) = q else {
        return (
            StatusCode::BAD_REQUEST,
            "need ?yaw=DEG&pitch=DEG[&distance=M][&resolution=N][&background=r,g,b,a] (numbers)\n",
        )
            .into_response();
    };
    let background = match q.background.as_deref().map(|b| {
        let v: Vec<f32> = b.split(',').filter_map(|x| x.trim().parse().ok()).collect();
        <[f32; 4]>::try_from(v)
    }) {
        None => None,
        Some(Ok(bg)) => Some(bg),
        Some(Err(_)) => {
            return (
                StatusCode::BAD_REQUEST,
                "background: four numbers r,g,b,a in [0, 1]\n",
            )
                .into_response();
        }
    };
    match app.shared.update_live(|l| {
        if let Some(bg) = background {
            l.background = bg;
        }
        l.yaw = q.yaw.rem_euclid(360.0);
        l.pitch = q.pitch;
        if let Some(d) = q.distance {
            l.distance = d;
        }
        if let Some(r) = q.resolution {
            l.set_resolution(r);
        }
    }) {
        Ok(_) => (StatusCode::OK, "ok\n").into_response(),
        Err(e) => (StatusCode::BAD_REQUEST, format!("{e}\n")).into_response(),
    }
}

/// Limits of the HTTP server: it binds only the configured address (the caller's listener).
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Time for a client to send its request head; slower clients are dropped.
    pub header_timeout: std::time::Duration,
    /// Largest request head (request line + headers) we buffer.
    pub max_header_bytes: usize,
    /// Open connections at once; more are closed at accept (stream clients have their own
    /// limit on top).
    pub max_connections: usize,
    /// Request bodies (no endpoint takes one).
    pub max_body_bytes: usize,
}

impl Limits {
    pub fn new(client_limit: usize, header_timeout_s: u64) -> Self {
        Self {
            header_timeout: std::time::Duration::from_secs(header_timeout_s),
            max_header_bytes: 16 * 1024,
            max_connections: client_limit + 64,
            max_body_bytes: 4096,
        }
    }
}

/// Serve `app` on `listener` with `limits` until `shutdown` resolves.
pub async fn serve(
    listener: tokio::net::TcpListener,
    app: Arc<App>,
    limits: Limits,
    shutdown: impl std::future::Future<Output = ()>,
) -> std::io::Result<()> {
    let router = router(app).layer(axum::extract::DefaultBodyLimit::max(limits.max_body_bytes));
    let permits = Arc::new(tokio::sync::Semaphore::new(limits.max_connections));
    tokio::pin!(shutdown);
    loop {
        let (stream, peer) = tokio::select! {
            _ = &mut shutdown => return Ok(()),
            r = listener.accept() => match r {
                Ok(x) => x,
                Err(e) => {
                    // Out of descriptors and the like: back off, keep serving.
                    tracing::warn!("accept failed: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                    continue;
                }
            },
        };
        let Ok(permit) = permits.clone().try_acquire_owned() else {
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let svc = router.clone().layer(axum::Extension(ConnectInfo(peer)));
        let svc = hyper_util::service::TowerToHyperService::new(svc);
        tokio::spawn(async move {
            let conn = hyper::server::conn::http1::Builder::new()
                .timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(limits.header_timeout)
                .max_buf_size(limits.max_header_bytes.max(8192))
                .max_headers(64)
                .serve_connection(hyper_util::rt::TokioIo::new(stream), svc);
            let _ = conn.await;
            drop(permit);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn token_compare() {
        let mut h = HeaderMap::new();
        assert!(!token_ok("secret-token", &h));
        h.insert(
            header::AUTHORIZATION,
            "Bearer secret-token".parse().unwrap(),
        );
        assert!(token_ok("secret-token", &h));
        h.insert(
            header::AUTHORIZATION,
            "Bearer secret-tokeN".parse().unwrap(),
        );
        assert!(!token_ok("secret-token", &h));
        h.insert(
            header::AUTHORIZATION,
            "Bearer secret-token-longer".parse().unwrap(),
        );
        assert!(!token_ok("secret-token", &h));
    }
}
