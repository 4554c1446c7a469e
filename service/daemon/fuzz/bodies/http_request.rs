//! The HTTP handlers we own (routing, query parsing, token check, view controls, state and
//! snapshots) on arbitrary requests: a response, never a panic.
//!
//! The body of the fuzz target of the same name (fuzz_targets/), shared with the replay test
//! (service/daemon/tests/fuzz_replay.rs) that CI runs.
use axum::body::Body;
use std::sync::{Arc, OnceLock};
use tower::ServiceExt;
use volcapd::{config::Config, http, pipeline};

fn app() -> Arc<http::App> {
    static APP: OnceLock<Arc<http::App>> = OnceLock::new();
    APP.get_or_init(|| {
        let cfg = Config::parse(
            "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n[http]\ntoken = \"fuzz-token-123\"\n",
            std::path::Path::new("fuzz.toml"),
        )
        .expect("fuzz config");
        let (tx, _) = tokio::sync::watch::channel(None);
        let shared = Arc::new(pipeline::Shared::new(&cfg, "fuzz".into(), tx));
        Arc::new(http::App::new(shared, 4, cfg.http.token.clone(), &[], true))
    })
    .clone()
}

pub fn run(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    // The parsers that see raw client text: the Host allow-list and the background list.
    static HOSTS: OnceLock<volcapd::netguard::HostAllow> = OnceLock::new();
    let _ = HOSTS
        .get_or_init(|| volcapd::netguard::HostAllow::new(&["volcap.lan".into()]))
        .allows(Some(&text));
    if let Ok(bg) = http::parse_background(&text) {
        assert!(bg.iter().all(|v| (0.0..=1.0).contains(v)));
    }
    let mut parts = text.splitn(3, '\n');
    let method = parts.next().unwrap_or("GET");
    let uri = parts.next().unwrap_or("/");
    let header = parts.next().unwrap_or("");
    let mut req = axum::http::Request::builder().method(method).uri(uri);
    if let Some((k, v)) = header.split_once(':') {
        req = req.header(k.trim(), v.trim());
    }
    let Ok(req) = req.body(Body::empty()) else {
        return;
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let resp = rt.block_on(http::router(app()).oneshot(req));
    let resp = resp.expect("infallible");
    assert!(resp.status().as_u16() >= 200);
}
