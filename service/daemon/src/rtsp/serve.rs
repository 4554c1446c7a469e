//! The RTSP server (`rtsp.bind`, `rtsp.path`): GStreamer's RTSP server on a GLib main loop of
//! its own thread, one shared media (`appsrc ! h264parse ! rtph264pay`) fed by the encoder
//! through [`Targets`]; the client limits (total, per address) applied at DESCRIBE and SETUP
//! with `503 Service Unavailable`; RTSP basic and digest auth (user `volcap`, the password
//! `http.token`) where a token is set.

use super::Status;
use super::encode::{Targets, configure_target};
use crate::config::Config;
use crate::config::rtsp::Transport;
use crate::pipeline::Shared;
use gst::glib;
use gst::prelude::*;
use gst_rtsp_server::prelude::*;
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The user name RTSP clients give with `http.token` as the password.
pub const USER: &str = "volcap";

/// Admitted clients per address (the limits' bookkeeping).
#[derive(Default)]
struct Admitted {
    total: usize,
    per_address: HashMap<IpAddr, usize>,
}

/// The peer address of an RTSP client (not bound by the Rust crate).
fn client_ip(client: &gst_rtsp_server::RTSPClient) -> Option<IpAddr> {
    use gst::glib::translate::ToGlibPtr;
    // SAFETY: `client` is a live GstRTSPClient; the connection it returns (transfer none)
    // lives as long as the client, and its IP string as long as the connection; both are
    // read here, under the client's reference, and copied out.
    unsafe {
        let conn = gst_rtsp_server::ffi::gst_rtsp_client_get_connection(client.to_glib_none().0);
        if conn.is_null() {
            return None;
        }
        let ip = gst_rtsp::ffi::gst_rtsp_connection_get_ip(conn);
        if ip.is_null() {
            return None;
        }
        std::ffi::CStr::from_ptr(ip).to_str().ok()?.parse().ok()
    }
}

/// Bind and start serving; returns the stream's URL and the main loop's thread.
pub(super) fn start(
    cfg: &Config,
    bind: SocketAddr,
    shared: Arc<Shared>,
    status: Arc<Status>,
    targets: Targets,
) -> Result<(String, std::thread::JoinHandle<()>), String> {
    let r = &cfg.rtsp;
    let server = gst_rtsp_server::RTSPServer::new();
    server.set_address(&bind.ip().to_string());
    server.set_service(&bind.port().to_string());
    // Clients on a few threads: one client's DESCRIBE waiting for the media to prepare does
    // not hold up the others.
    if let Some(p) = server.thread_pool() {
        p.set_max_threads(8);
    }
    let factory = gst_rtsp_server::RTSPMediaFactory::new();
    factory.set_launch(
        "( appsrc name=src ! h264parse ! video/x-h264,alignment=au ! rtph264pay name=pay0 pt=96 config-interval=-1 )",
    );
    factory.set_shared(true);
    let mut lower = gst_rtsp::RTSPLowerTrans::empty();
    for t in &r.transports {
        lower |= match t {
            Transport::Tcp => gst_rtsp::RTSPLowerTrans::TCP,
            Transport::Udp => gst_rtsp::RTSPLowerTrans::UDP,
        };
    }
    factory.set_protocols(lower);
    if let Some([first, last]) = r.udp_ports {
        let pool = gst_rtsp_server::RTSPAddressPool::new();
        pool.add_range(
            gst_rtsp_server::RTSP_ADDRESS_POOL_ANY_IPV4,
            gst_rtsp_server::RTSP_ADDRESS_POOL_ANY_IPV4,
            first,
            last,
            0,
        )
        .map_err(|e| format!("rtsp.udp_ports = [{first}, {last}]: {e}"))?;
        factory.set_address_pool(Some(&pool));
    }
    {
        let targets = targets.clone();
        factory.connect_media_configure(move |_, media| {
            let Some(src) = media
                .element()
                .downcast::<gst::Bin>()
                .ok()
                .and_then(|b| b.by_name_recurse_up("src"))
                .and_then(|e| e.downcast::<gst_app::AppSrc>().ok())
            else {
                tracing::error!("rtsp: the media has no appsrc");
                return;
            };
            configure_target(&src);
            let (id, _) = targets.add(src);
            let targets = targets.clone();
            media.connect_unprepared(move |_| targets.remove(id));
        });
    }
    if let Some(token) = cfg.http.token.as_deref() {
        let auth = gst_rtsp_server::RTSPAuth::new();
        let role = gst_rtsp_server::RTSPToken::builder()
            .field(gst_rtsp_server::RTSP_TOKEN_MEDIA_FACTORY_ROLE, "volcap")
            .build();
        auth.add_basic(
            gst_rtsp_server::RTSPAuth::make_basic(USER, token).as_str(),
            &role,
        );
        auth.add_digest(USER, token, &role);
        // Both methods: a bitmask in C, an enum in the binding, so set through the C call.
        {
            use gst::glib::translate::ToGlibPtr;
            // SAFETY: `auth` is a live GstRTSPAuth; the call only stores the mask.
            unsafe {
                gst_rtsp_server::ffi::gst_rtsp_auth_set_supported_methods(
                    auth.to_glib_none().0,
                    gst_rtsp::ffi::GST_RTSP_AUTH_BASIC | gst_rtsp::ffi::GST_RTSP_AUTH_DIGEST,
                );
            }
        }
        server.set_auth(Some(&auth));
        factory.add_role_from_structure(
            &gst::Structure::builder("volcap")
                .field(gst_rtsp_server::RTSP_PERM_MEDIA_FACTORY_ACCESS, true)
                .field(gst_rtsp_server::RTSP_PERM_MEDIA_FACTORY_CONSTRUCT, true)
                .build(),
        );
    }
    server
        .mount_points()
        .ok_or("[rtsp]: the server has no mount points")?
        .add_factory(&r.path, factory);
    let admitted = Arc::new(Mutex::new(Admitted::default()));
    let (limit, per_limit) = (r.client_limit, r.per_address_limit);
    {
        let status = status.clone();
        server.connect_client_connected(move |_, client| {
            let ip = client_ip(client);
            let mine = Arc::new(std::sync::atomic::AtomicBool::new(false));
            // Admit at the first DESCRIBE or SETUP while under both limits; refuse with 503.
            let admit = {
                let (admitted, status, mine) = (admitted.clone(), status.clone(), mine.clone());
                move |what: &str| -> gst_rtsp::RTSPStatusCode {
                    if mine.load(Ordering::SeqCst) {
                        return gst_rtsp::RTSPStatusCode::Ok;
                    }
                    let mut a = admitted.lock().unwrap_or_else(|p| p.into_inner());
                    let here = ip.map(|ip| *a.per_address.get(&ip).unwrap_or(&0)).unwrap_or(0);
                    if a.total >= limit || here >= per_limit {
                        status.refused.fetch_add(1, Ordering::Relaxed);
                        tracing::info!(
                            peer = ?ip,
                            "rtsp: {what} refused (503): {} of rtsp.client_limit {limit} admitted, {here} of rtsp.per_address_limit {per_limit} from this address",
                            a.total
                        );
                        return gst_rtsp::RTSPStatusCode::ServiceUnavailable;
                    }
                    a.total += 1;
                    if let Some(ip) = ip {
                        *a.per_address.entry(ip).or_default() += 1;
                    }
                    mine.store(true, Ordering::SeqCst);
                    status.clients.store(a.total, Ordering::SeqCst);
                    status.clients_total.fetch_add(1, Ordering::Relaxed);
                    gst_rtsp::RTSPStatusCode::Ok
                }
            };
            let admit = Arc::new(admit);
            let a2 = admit.clone();
            client.connect_pre_describe_request(move |_, _| a2("DESCRIBE"));
            let a3 = admit.clone();
            client.connect_pre_setup_request(move |_, _| a3("SETUP"));
            {
                let status = status.clone();
                client.connect_pre_play_request(move |_, _| {
                    // A client joining the shared stream starts at a key frame.
                    status.want_keyframe.store(true, Ordering::SeqCst);
                    gst_rtsp::RTSPStatusCode::Ok
                });
            }
            let (admitted, status) = (admitted.clone(), status.clone());
            client.connect_closed(move |_| {
                if !mine.swap(false, Ordering::SeqCst) {
                    return;
                }
                let mut a = admitted.lock().unwrap_or_else(|p| p.into_inner());
                a.total = a.total.saturating_sub(1);
                if let Some(ip) = ip
                    && let Some(n) = a.per_address.get_mut(&ip)
                {
                    *n = n.saturating_sub(1);
                    if *n == 0 {
                        a.per_address.remove(&ip);
                    }
                }
                status.clients.store(a.total, Ordering::SeqCst);
            });
        });
    }
    let ctx = glib::MainContext::new();
    let source = server.attach(Some(&ctx)).map_err(|e| {
        format!(
            "rtsp.bind = \"{bind}\" in {}: cannot listen there: {e}",
            cfg.file.display()
        )
    })?;
    let port = server.bound_port();
    if port <= 0 {
        return Err(format!(
            "rtsp.bind = \"{bind}\" in {}: the server did not bind",
            cfg.file.display()
        ));
    }
    let host = match bind.ip() {
        ip if ip.is_unspecified() => "127.0.0.1".to_string(),
        IpAddr::V6(ip) => format!("[{ip}]"),
        ip => ip.to_string(),
    };
    let url = format!("rtsp://{host}:{port}{}", r.path);
    let main_loop = glib::MainLoop::new(Some(&ctx), false);
    let t = std::thread::Builder::new()
        .name("rtsp-server".into())
        .spawn(move || {
            // Sessions that time out are removed by the server's pool, checked every 2 s.
            let pool = server.session_pool();
            let stopper = {
                let (ml, shared) = (main_loop.clone(), shared.clone());
                let pool = pool.clone();
                glib::timeout_source_new(
                    Duration::from_secs(2),
                    None,
                    glib::Priority::DEFAULT,
                    move || {
                        if let Some(p) = &pool {
                            p.cleanup();
                        }
                        if shared.stop.load(Ordering::Relaxed) {
                            ml.quit();
                            return glib::ControlFlow::Break;
                        }
                        glib::ControlFlow::Continue
                    },
                )
            };
            stopper.attach(Some(&ctx));
            let _ = ctx.with_thread_default(|| main_loop.run());
            // (`SourceId::remove` panics on a source the loop already dropped.)
            if let Some(s) = ctx.find_source_by_id(&source) {
                s.destroy();
            }
            drop(server);
        })
        .map_err(|e| format!("[rtsp]: spawning the server thread: {e}"))?;
    Ok((url, t))
}
