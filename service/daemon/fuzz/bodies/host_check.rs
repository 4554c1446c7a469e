//! The `Host` rule on arbitrary request heads: any number of `Host` headers, any version,
//! any request target (origin, absolute or authority form). A request whose host (header or
//! absolute-form authority) names a site that is not this appliance's is never let through,
//! and nothing panics.
//!
//! The body of the fuzz target of the same name (fuzz_targets/), shared with the replay test
//! (service/daemon/tests/fuzz_replay.rs) that CI runs.
use axum::http::{Request, Version, header};
use std::sync::OnceLock;
use volcapd::netguard::HostAllow;

fn hosts() -> &'static HostAllow {
    static HOSTS: OnceLock<HostAllow> = OnceLock::new();
    HOSTS.get_or_init(|| HostAllow::new(&["volcap.lan".into()]))
}

pub fn run(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let mut lines = text.split('\n');
    let Some(first) = lines.next() else { return };
    let (version, target) = match first.split_once(' ') {
        Some(("0", t)) => (Version::HTTP_10, t),
        Some((_, t)) => (Version::HTTP_11, t),
        None => (Version::HTTP_11, first),
    };
    let mut req = Request::builder().version(version).uri(target);
    let mut host_values = Vec::new();
    for l in lines.take(8) {
        host_values.push(l.to_string());
        req = req.header(header::HOST, l);
    }
    let Ok(req) = req.body(()) else { return };
    let verdict = volcapd::http::host_verdict(hosts(), &req);
    if verdict.is_ok() {
        let given = req.headers().get_all(header::HOST).iter().count();
        assert!(given <= 1, "two Host headers let through");
        if given == 0 {
            assert!(
                version == Version::HTTP_10,
                "HTTP/1.1 without Host let through"
            );
        }
        for h in req.headers().get_all(header::HOST) {
            assert!(hosts().allows(Some(h.to_str().unwrap_or("\u{fffd}"))));
        }
        if let Some(a) = req.uri().authority() {
            let name = match a.port_u16() {
                Some(p) => format!("{}:{p}", a.host()),
                None => a.host().to_string(),
            };
            assert!(
                hosts().allows(Some(&name)),
                "absolute-form {name} let through"
            );
        }
    }
}
