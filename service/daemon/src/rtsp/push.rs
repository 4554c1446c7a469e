//! The push (`rtsp.push`): `appsrc ! h264parse ! rtspclientsink` publishing the encoder's
//! access units to a media server by RTSP RECORD. A server that refuses, is missing or goes
//! away mid-stream is a state (`/state` `rtsp.push`), logged and retried with a doubling wait
//! up to `rtsp.push_retry_max_s`; the pipeline and the other clients never wait on it.

use super::Status;
use super::encode::{Targets, configure_target};
use crate::config::rtsp::redacted;
use crate::pipeline::Shared;
use gst::prelude::*;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// A connection that streamed this long resets the wait to 1 s.
const STEADY: Duration = Duration::from_secs(10);

pub(super) fn spawn(
    url: String,
    retry_max_s: u32,
    shared: Arc<Shared>,
    status: Arc<Status>,
    targets: Targets,
) -> Result<std::thread::JoinHandle<()>, String> {
    if gst::ElementFactory::find("rtspclientsink").is_none() {
        return Err(
            "rtsp.push: GStreamer has no `rtspclientsink` element here (install gstreamer1.0-rtsp)"
                .into(),
        );
    }
    std::thread::Builder::new()
        .name("rtsp-push".into())
        .spawn(move || run(url, retry_max_s, shared, status, targets))
        .map_err(|e| format!("[rtsp]: spawning the push thread: {e}"))
}

/// One connection: until the server fails or the daemon stops. Ok(()) when stopping.
fn connect(url: &str, shared: &Shared, status: &Status, targets: &Targets) -> Result<(), String> {
    let pipeline = gst::Pipeline::new();
    let make = |f: &str| {
        gst::ElementFactory::make(f)
            .build()
            .map_err(|e| format!("{f}: {e}"))
    };
    let src = gst_app::AppSrc::builder().build();
    configure_target(&src);
    let parse = make("h264parse")?;
    let sink = make("rtspclientsink")?;
    sink.set_property("location", url);
    sink.set_property("latency", 0u32);
    sink.set_property_from_str("protocols", "tcp");
    pipeline
        .add_many([src.upcast_ref(), &parse, &sink])
        .map_err(|e| e.to_string())?;
    gst::Element::link_many([src.upcast_ref(), &parse, &sink]).map_err(|e| e.to_string())?;
    let (id, sent) = targets.add(src);
    status.push_active.store(true, Ordering::SeqCst);
    status.want_keyframe.store(true, Ordering::SeqCst);
    let result = (|| {
        pipeline
            .set_state(gst::State::Playing)
            .map_err(|_| "the connection does not start".to_string())?;
        let bus = pipeline.bus().ok_or("no bus")?;
        let mut streaming = false;
        let mut last = 0u64;
        loop {
            if shared.stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            if let Some(m) = bus.timed_pop_filtered(
                gst::ClockTime::from_mseconds(200),
                &[gst::MessageType::Error, gst::MessageType::Eos],
            ) {
                return Err(match m.view() {
                    gst::MessageView::Error(e) => {
                        format!("{}", e.error())
                    }
                    _ => "the server ended the stream".into(),
                });
            }
            let n = sent.load(Ordering::Relaxed);
            status.update_push(|p| p.frames_sent += n - last);
            last = n;
            let (_, now, _) = pipeline.state(gst::ClockTime::ZERO);
            if !streaming && now == gst::State::Playing && n > 0 {
                streaming = true;
                tracing::info!("rtsp push: streaming to {}", redacted(url));
                status.update_push(|p| {
                    p.state = "streaming";
                    p.error = None;
                    p.retry_in_s = None;
                });
            }
        }
    })();
    targets.remove(id);
    status.push_active.store(false, Ordering::SeqCst);
    let _ = pipeline.set_state(gst::State::Null);
    result
}

fn run(url: String, retry_max_s: u32, shared: Arc<Shared>, status: Arc<Status>, targets: Targets) {
    let mut wait = Duration::from_secs(1);
    let max = Duration::from_secs(retry_max_s.into());
    while !shared.stop.load(Ordering::Relaxed) {
        status.update_push(|p| {
            p.state = "connecting";
            p.attempts += 1;
            p.retry_in_s = None;
        });
        let began = Instant::now();
        let err = match connect(&url, &shared, &status, &targets) {
            Ok(()) => break,
            Err(e) => e,
        };
        if began.elapsed() >= STEADY {
            wait = Duration::from_secs(1);
        }
        tracing::warn!(
            "rtsp push to {}: {err}; next attempt in {:.0} s",
            redacted(&url),
            wait.as_secs_f64()
        );
        status.update_push(|p| {
            p.state = "retrying";
            p.error = Some(err.clone());
            p.retry_in_s = Some(wait.as_secs_f64());
        });
        let until = Instant::now() + wait;
        while Instant::now() < until && !shared.stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(100));
        }
        wait = (wait * 2).min(max);
    }
    status.update_push(|p| p.state = "stopped");
}
