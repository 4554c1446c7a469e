//! A minimal RTSP relay on GStreamer's RTSP server: a publisher RECORDs H.264 to `/in`
//! (as `volcapd`'s `rtsp.push` does), any number of clients PLAY it from `/out` (one shared
//! media). What the push tests run as "the media server"; in production put MediaMTX or an
//! NVR there (README).
//!
//! `rtsp_relay [PORT]` (default 8554; 0 picks one). Prints `relay: rtsp://127.0.0.1:PORT`.

use gst::glib;
use gst::prelude::*;
use gst_rtsp_server::prelude::*;
use std::sync::{Arc, Mutex};

fn main() {
    let port: u16 = std::env::args()
        .nth(1)
        .and_then(|p| p.parse().ok())
        .unwrap_or(8554);
    gst::init().expect("GStreamer");
    let server = gst_rtsp_server::RTSPServer::new();
    server.set_address("127.0.0.1");
    server.set_service(&port.to_string());
    // Each client on a thread of its own: a player's DESCRIBE waits for the shared media to
    // prepare, which needs the publisher's data, which a TCP publisher delivers through its
    // client's thread.
    if let Some(p) = server.thread_pool() {
        p.set_max_threads(64);
    }
    let mounts = server.mount_points().expect("mount points");
    // The play side's appsrc (one shared media), fed by the record side.
    let out: Arc<Mutex<Option<gst_app::AppSrc>>> = Default::default();

    let play = gst_rtsp_server::RTSPMediaFactory::new();
    play.set_launch(
        "( appsrc name=src is-live=true format=time do-timestamp=true max-buffers=30 \
           ! h264parse ! video/x-h264,alignment=au ! rtph264pay name=pay0 pt=96 config-interval=-1 )",
    );
    play.set_shared(true);
    {
        let out = out.clone();
        play.connect_media_configure(move |_, media| {
            let src = media
                .element()
                .downcast::<gst::Bin>()
                .ok()
                .and_then(|b| b.by_name_recurse_up("src"))
                .and_then(|e| e.downcast::<gst_app::AppSrc>().ok());
            if let Some(src) = &src {
                src.set_caps(Some(
                    &gst::Caps::builder("video/x-h264")
                        .field("stream-format", "byte-stream")
                        .field("alignment", "au")
                        .build(),
                ));
                src.set_leaky_type(gst_app::AppLeakyType::Downstream);
            }
            *out.lock().unwrap() = src;
            let out = out.clone();
            media.connect_unprepared(move |_| *out.lock().unwrap() = None);
        });
    }
    mounts.add_factory("/out", play);

    let record = gst_rtsp_server::RTSPMediaFactory::new();
    record.set_transport_mode(gst_rtsp_server::RTSPTransportMode::RECORD);
    record.set_launch(
        "( rtph264depay name=depay0 ! h264parse ! video/x-h264,stream-format=byte-stream,alignment=au \
           ! appsink name=sink sync=false max-buffers=30 drop=true )",
    );
    {
        let out = out.clone();
        record.connect_media_configure(move |_, media| {
            let Some(sink) = media
                .element()
                .downcast::<gst::Bin>()
                .ok()
                .and_then(|b| b.by_name_recurse_up("sink"))
                .and_then(|e| e.downcast::<gst_app::AppSink>().ok())
            else {
                return;
            };
            let out = out.clone();
            sink.set_callbacks(
                gst_app::AppSinkCallbacks::builder()
                    .new_sample(move |s| {
                        let sample = s.pull_sample().map_err(|_| gst::FlowError::Eos)?;
                        if let (Some(b), Some(src)) =
                            (sample.buffer(), out.lock().unwrap().as_ref())
                        {
                            let mut b = b.copy();
                            let m = b.make_mut();
                            m.set_pts(gst::ClockTime::NONE);
                            m.set_dts(gst::ClockTime::NONE);
                            let _ = src.push_buffer(b);
                        }
                        Ok(gst::FlowSuccess::Ok)
                    })
                    .build(),
            );
        });
    }
    mounts.add_factory("/in", record);

    let ctx = glib::MainContext::default();
    let _id = server.attach(Some(&ctx)).expect("cannot listen");
    println!("relay: rtsp://127.0.0.1:{}", server.bound_port());
    let ml = glib::MainLoop::new(Some(&ctx), false);
    // Sessions of clients that vanished are removed every 2 s.
    let pool = server.session_pool();
    glib::timeout_add_seconds(2, move || {
        if let Some(p) = &pool {
            p.cleanup();
        }
        glib::ControlFlow::Continue
    });
    ml.run();
}
