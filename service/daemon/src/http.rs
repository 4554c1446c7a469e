//! LAN publishing over HTTP (axum). Every stream client reads the latest published frame
//! through a `watch` channel: a slow client skips frames and never stalls the pipeline or
//! other clients; a disconnected client's slot is freed when its body is dropped.

use crate::netguard::{Backoff, HostAllow, PerAddress, WriteTimeout};
use crate::pipeline::Shared;
use axum::Router;
use axum::body::Body;
use axum::extract::{ConnectInfo, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use mesh::{mesh_glb, mesh_head};
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
    /// Names accepted in the `Host` header besides IP literals.
    pub hosts: HostAllow,
    /// Wrong-token back-off per address.
    pub backoff: Backoff,
    /// The server listens on a loopback address only: without a token, the view controls
    /// are open to this machine's own clients (the local user), see [`App::controls`].
    pub loopback_bind: bool,
    /// One mesh computation at a time ([`MESH_CONCURRENCY`]); others get 503.
    /// Shared with the computation, whose permit is released only when it ends.
    pub mesh_gate: Arc<tokio::sync::Semaphore>,
    /// The last mesh: its field (a `Weak` keeps the allocation, so a new frame's field can
    /// never share its address), resolution, coarse level, and the bytes.
    pub mesh_cache: Mutex<Option<MeshCache>>,
    /// The thread that computes meshes, and its counts.
    pub mesh_worker: MeshWorker,
    /// RTSP's figures (`[rtsp]`; off unless the daemon sets them after `new`).
    pub rtsp: Arc<crate::rtsp::Status>,
}

pub use mesh::{MESH_CONCURRENCY, MESH_NICE, MeshCache, MeshSettings, MeshWorker};

impl App {
    pub fn new(
        shared: Arc<Shared>,
        client_limit: usize,
        token: Option<String>,
        allowed_hosts: &[String],
        loopback_bind: bool,
    ) -> Self {
        Self {
            shared,
            clients: AtomicUsize::new(0),
            client_limit: AtomicUsize::new(client_limit),
            token: Mutex::new(token),
            table: Mutex::new(BTreeMap::new()),
            next_id: AtomicU64::new(1),
            hosts: HostAllow::new(allowed_hosts),
            backoff: Backoff::default(),
            loopback_bind,
            mesh_gate: mesh::mesh_gate(),
            mesh_cache: Mutex::new(None),
            mesh_worker: MeshWorker::default(),
            rtsp: Default::default(),
        }
    }

    /// The cached mesh of `field` made with `set`, if it is the one in the cache.
    fn cached_mesh(
        &self,
        field: &Arc<dyn crate::pipeline::MeshField>,
        set: MeshSettings,
    ) -> Option<axum::body::Bytes> {
        self.mesh_cache
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .filter(|(k, s, _)| std::ptr::addr_eq(k.as_ptr(), Arc::as_ptr(field)) && *s == set)
            .map(|(_, _, b)| b.clone())
    }

    /// Who may use the view controls: `token` (a token is configured: whoever sends it),
    /// `local` (no token, the server bound to loopback: only this machine can reach it, and
    /// its user may turn the view) or `off` (no token on a LAN bind).
    pub fn controls(&self) -> &'static str {
        if self
            .token
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .is_some()
        {
            "token"
        } else if self.loopback_bind {
            "local"
        } else {
            "off"
        }
    }

    /// Whether the request carries the configured token (no token configured: never).
    fn authorized(&self, headers: &HeaderMap) -> bool {
        let expected = self.token.lock().unwrap_or_else(|p| p.into_inner()).clone();
        expected.is_some_and(|t| token_ok(&t, headers))
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
        .route("/mesh.glb", get(mesh_glb).head(mesh_head))
        .route("/state", get(state))
        .route("/metrics", get(metrics))
        .route("/view", post(set_view))
        .layer(axum::middleware::from_fn_with_state(
            app.clone(),
            check_host,
        ))
        .with_state(app)
}

/// Refuse requests whose `Host` names another site (DNS rebinding: a page on the LAN
/// resolving its own name to this appliance), and requests whose host is ambiguous: two
/// `Host` headers, none on HTTP/1.1 (RFC 9112 3.2: 400), or an absolute-form target naming
/// a host that is not this appliance's (its authority is the request's host then, and the
/// `Host` header is checked as well).
async fn check_host(
    State(app): State<Arc<App>>,
    req: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    match host_verdict(&app.hosts, &req) {
        Ok(()) => next.run(req).await,
        Err((status, why)) => (status, why).into_response(),
    }
}

/// The `Host` rule of [`check_host`] on a request: `Err((status, message))` when refused.
pub fn host_verdict<B>(
    hosts: &HostAllow,
    req: &axum::http::Request<B>,
) -> Result<(), (StatusCode, String)> {
    let mut all = req.headers().get_all(header::HOST).iter();
    let host = all.next().map(|h| h.to_str().unwrap_or("\u{fffd}"));
    if all.next().is_some() {
        return Err((
            StatusCode::BAD_REQUEST,
            "more than one Host header\n".into(),
        ));
    }
    if host.is_none() && req.version() >= axum::http::Version::HTTP_11 {
        return Err((
            StatusCode::BAD_REQUEST,
            "HTTP/1.1 request without a Host header\n".into(),
        ));
    }
    let refuse = |what: &str, name: &str| {
        Err((
            StatusCode::MISDIRECTED_REQUEST,
            format!(
                "{what} {name:?} is not this appliance's (allowed: IP addresses, {}; config http.allowed_hosts)\n",
                hosts.names().join(", ")
            ),
        ))
    };
    if let Some(authority) = req.uri().authority() {
        let name = authority.host();
        let name = match authority.port_u16() {
            Some(p) => format!("{name}:{p}"),
            None => name.to_string(),
        };
        if !hosts.allows(Some(&name)) {
            return refuse("target host", &name);
        }
    }
    if !hosts.allows(host) {
        return refuse("host", host.unwrap_or_default());
    }
    Ok(())
}

mod mesh;
mod report;
#[cfg(test)]
use report::state_json;
use report::{metrics, state};

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

fn peer_ip(peer: &Option<axum::Extension<ConnectInfo<SocketAddr>>>) -> Option<std::net::IpAddr> {
    peer.as_ref().map(|axum::Extension(ConnectInfo(a))| a.ip())
}

/// The bearer token, with the per-address back-off: `None` when it is right (or not needed:
/// controls `local` and a loopback client); else the refusal: 403 when controls are off, 429
/// (Retry-After) while the address must wait, 401 on a wrong token.
fn token_refusal(app: &App, headers: &HeaderMap, ip: Option<std::net::IpAddr>) -> Option<Response> {
    match app.controls() {
        "local" if ip.is_some_and(|ip| ip.to_canonical().is_loopback()) => return None,
        "token" => {}
        _ => {
            return Some(
                (
                    StatusCode::FORBIDDEN,
                    "controls are off: set http.token in the config (or bind to loopback only for local control)\n",
                )
                    .into_response(),
            );
        }
    }
    if let Some(wait) = ip
        .and_then(|ip| app.backoff.wait(ip))
        .or_else(|| app.backoff.global_wait())
    {
        let secs = wait.as_secs_f64().ceil().max(1.0) as u64;
        return Some(
            (
                StatusCode::TOO_MANY_REQUESTS,
                [(header::RETRY_AFTER, secs.to_string())],
                format!("too many wrong tokens; retry in {secs} s\n"),
            )
                .into_response(),
        );
    }
    if app.authorized(headers) {
        if let Some(ip) = ip {
            app.backoff.succeeded(ip);
        }
        None
    } else {
        app.backoff.failed(ip);
        Some((StatusCode::UNAUTHORIZED, "bad or missing bearer token\n").into_response())
    }
}

/// The token of an `Authorization: Bearer TOKEN` header (the scheme is case-insensitive,
/// RFC 9110 11.1), or `""`.
fn bearer(headers: &HeaderMap) -> &str {
    headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().split_once(' '))
        .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
        .map(|(_, t)| t.trim())
        .unwrap_or("")
}

/// Constant-time comparison of the bearer token.
fn token_ok(expected: &str, headers: &HeaderMap) -> bool {
    let (a, b) = (expected.as_bytes(), bearer(headers).as_bytes());
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
    peer: Option<axum::Extension<ConnectInfo<SocketAddr>>>,
    q: Result<Query<ViewQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    if let Some(r) = token_refusal(&app, &headers, peer_ip(&peer)) {
        return r;
    }
    let q = match q {
        Ok(Query(q)) => q,
        // The rejection names the parameter and what was wrong with it ("yaw: invalid float
        // literal", "missing field `pitch`").
        Err(e) => {
            return (
                StatusCode::BAD_REQUEST,
                format!(
                    "{}: need ?yaw=DEG&pitch=DEG[&distance=M][&resolution=N][&background=r,g,b,a] (numbers)\n",
                    e.body_text()
                ),
            )
                .into_response();
        }
    };
    let background = match q.background.as_deref().map(parse_background) {
        None => None,
        Some(Ok(bg)) => Some(bg),
        Some(Err(e)) => return (StatusCode::BAD_REQUEST, format!("{e}\n")).into_response(),
    };
    match app.shared.update_live(|l| {
        if let Some(bg) = background {
            l.background = bg;
        }
        l.set_yaw(q.yaw);
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

/// `r,g,b,a`: exactly four finite numbers in [0, 1], nothing else; the error quotes the
/// value given.
pub fn parse_background(text: &str) -> Result<[f32; 4], String> {
    let fail = |why: String| {
        Err(format!(
            "background {text:?}: {why} (expected four numbers r,g,b,a in [0, 1])"
        ))
    };
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() != 4 {
        return fail(format!("{} values", parts.len()));
    }
    let mut out = [0.0f32; 4];
    for (o, p) in out.iter_mut().zip(&parts) {
        let p = p.trim();
        match p.parse::<f32>() {
            Ok(v) if v.is_finite() && (0.0..=1.0).contains(&v) => *o = v,
            Ok(_) => return fail(format!("{p:?} is not in [0, 1]")),
            Err(_) => return fail(format!("{p:?} is not a number")),
        }
    }
    Ok(out)
}

/// Limits of the HTTP server: it binds only the configured address (the caller's listener).
#[derive(Debug, Clone)]
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
    /// Open connections per client address.
    pub per_address: usize,
    /// A response write that makes no progress this long ends the connection.
    pub write_timeout: std::time::Duration,
    /// Kernel send buffer per connection: small, so that a slow stream client skips frames
    /// (latest wins) instead of queueing seconds of them, and stalls show up as such.
    pub send_buffer_bytes: usize,
    /// Addresses that may open [`Limits::reserved`] connections past `max_connections`.
    pub reserved_for: Vec<std::net::IpAddr>,
    pub reserved: usize,
}

impl Limits {
    pub fn new(http: &crate::config::HttpConfig) -> Self {
        Self {
            header_timeout: std::time::Duration::from_secs(http.header_timeout_s),
            max_header_bytes: 16 * 1024,
            max_connections: http.client_limit + 64,
            max_body_bytes: 4096,
            per_address: http.per_address_limit,
            write_timeout: std::time::Duration::from_secs(http.write_timeout_s),
            send_buffer_bytes: 256 * 1024,
            reserved_for: http.reserved_for.clone(),
            reserved: crate::config::RESERVED_CONNECTIONS,
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
    // Everyone shares `max_connections`; the reserved addresses also have `reserved` more,
    // which nobody else can take (LAN hosts filling the server leave them a way in).
    let permits = Arc::new(tokio::sync::Semaphore::new(limits.max_connections));
    let reserve = Arc::new(tokio::sync::Semaphore::new(limits.reserved));
    let per_address = Arc::new(PerAddress::default());
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
        // One address cannot hold more than its share (the rest stay for everyone else).
        let Some(slot) = per_address.enter(peer.ip(), limits.per_address) else {
            drop(stream);
            continue;
        };
        let permit = match permits.clone().try_acquire_owned() {
            Ok(p) => p,
            Err(_) if limits.reserved_for.contains(&peer.ip().to_canonical()) => {
                match reserve.clone().try_acquire_owned() {
                    Ok(p) => p,
                    Err(_) => {
                        drop(stream);
                        continue;
                    }
                }
            }
            Err(_) => {
                drop(stream);
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        let _ = socket2::SockRef::from(&stream).set_send_buffer_size(limits.send_buffer_bytes);
        let svc = router.clone().layer(axum::Extension(ConnectInfo(peer)));
        let svc = hyper_util::service::TowerToHyperService::new(svc);
        let io = WriteTimeout::new(stream, limits.write_timeout);
        let (header_timeout, max_header_bytes) = (limits.header_timeout, limits.max_header_bytes);
        tokio::spawn(async move {
            let conn = hyper::server::conn::http1::Builder::new()
                .timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(header_timeout)
                .max_buf_size(max_header_bytes.max(8192))
                .max_headers(64)
                .serve_connection(hyper_util::rt::TokioIo::new(io), svc);
            let _ = conn.await;
            drop(permit);
            drop(slot);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn app(token: Option<&str>, loopback_bind: bool) -> App {
        let cfg = crate::config::Config::parse(
            "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n[dbus]\nbus = \"none\"\n",
            std::path::Path::new("t.toml"),
        )
        .unwrap();
        let (tx, _) = tokio::sync::watch::channel(None);
        let shared = Arc::new(Shared::new(&cfg, "test".into(), tx));
        App::new(shared, 4, token.map(String::from), &[], loopback_bind)
    }

    /// Issue #37, item 1: the main job's view could not be turned (403 without a token). On
    /// a loopback bind the local user may; on a LAN bind the token rule stays.
    #[test]
    fn view_controls_are_local_on_loopback_and_need_the_token_elsewhere() {
        let lo: std::net::IpAddr = "127.0.0.1".parse().unwrap();
        let lo6: std::net::IpAddr = "::ffff:127.0.0.1".parse().unwrap();
        let lan: std::net::IpAddr = "192.168.1.7".parse().unwrap();
        let none = HeaderMap::new();
        let a = app(None, true);
        assert_eq!(a.controls(), "local");
        assert!(token_refusal(&a, &none, Some(lo)).is_none());
        assert!(token_refusal(&a, &none, Some(lo6)).is_none());
        let status = |r: Option<Response>| r.map(|r| r.status().as_u16());
        assert_eq!(status(token_refusal(&a, &none, Some(lan))), Some(403));
        let a = app(None, false);
        assert_eq!(a.controls(), "off");
        assert_eq!(status(token_refusal(&a, &none, Some(lo))), Some(403));
        let a = app(Some("the-token-1"), true);
        assert_eq!(a.controls(), "token");
        assert_eq!(status(token_refusal(&a, &none, Some(lo))), Some(401));
        let mut h = HeaderMap::new();
        h.insert(header::AUTHORIZATION, "Bearer the-token-1".parse().unwrap());
        assert!(token_refusal(&a, &h, Some(lan)).is_none());
        assert_eq!(state_json(&a, false)["controls"], "token");
    }

    /// Hardening #14: loose lists were accepted as something else; `inf` was reported as NaN.
    #[test]
    fn background_parses_strictly_and_quotes_the_value() {
        assert_eq!(parse_background("0, 0.5,1,0"), Ok([0.0, 0.5, 1.0, 0.0]));
        for (bad, says) in [
            ("0,x,0,0,0", "5 values"),
            ("0,0,0,0,,,,", "8 values"),
            ("0,x,0,0", "\"x\" is not a number"),
            ("0,0,0", "3 values"),
            ("inf,0,0,1", "\"inf\" is not in [0, 1]"),
            ("NaN,0,0,1", "\"NaN\" is not in [0, 1]"),
            ("0,0,0,2", "\"2\" is not in [0, 1]"),
            ("", "1 values"),
        ] {
            let e = parse_background(bad).unwrap_err();
            assert!(
                e.contains(&format!("{bad:?}")) && e.contains(says),
                "{bad}: {e}"
            );
        }
    }

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
        // The scheme is case-insensitive (RFC 9110 11.1); the token is not.
        for ok in [
            "bearer secret-token",
            "BEARER secret-token",
            "Bearer  secret-token",
        ] {
            h.insert(header::AUTHORIZATION, ok.parse().unwrap());
            assert!(token_ok("secret-token", &h), "{ok}");
        }
        for bad in [
            "Basic secret-token",
            "Bearersecret-token",
            "secret-token",
            "Bearer",
        ] {
            h.insert(header::AUTHORIZATION, bad.parse().unwrap());
            assert!(!token_ok("secret-token", &h), "{bad}");
        }
    }
}
