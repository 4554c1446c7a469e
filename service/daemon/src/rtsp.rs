//! H.264 over RTSP, like an IP camera (`[rtsp]`, the `rtsp` build feature): one encoder fed
//! from the published frames' latest-frame slot (the `watch` channel the MJPEG clients read;
//! never a queue), its access units handed to the RTSP server's shared media (`bind`: every
//! client of `path` reads the one encoder) and to a pusher that publishes them to a media
//! server by RTSP RECORD (`push`; a server that goes away is a state, retried with back-off).
//! The encoder runs only while a client is admitted or the push is on. Handing an access
//! unit to a slow client or server never waits: each hand-off is a leaky queue of a few
//! frames, and GStreamer's RTSP server drops what a slow TCP client cannot take.
//!
//! [`Status`] (always built) is what `/state`, `/metrics` and D-Bus report.

#[cfg(feature = "rtsp")]
mod encode;
#[cfg(feature = "rtsp")]
pub use encode::{encoder_launch, even_sided};
#[cfg(feature = "rtsp")]
mod push;
#[cfg(feature = "rtsp")]
mod serve;

use crate::config::Config;
use crate::pipeline::StageStats;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// The push's connection, as `/state` shows it.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct PushStatus {
    /// The media server's URL, credentials hidden.
    pub target: String,
    /// `connecting`, `streaming`, `retrying` (waiting before the next attempt) or `stopped`.
    pub state: &'static str,
    /// The last error, kept while retrying.
    pub error: Option<String>,
    /// Connection attempts so far.
    pub attempts: u64,
    /// Seconds until the next attempt (while `retrying`).
    pub retry_in_s: Option<f64>,
    /// Access units handed to the push since the daemon started.
    pub frames_sent: u64,
}

/// RTSP figures shared with `/state`, `/metrics` and D-Bus.
#[derive(Default)]
pub struct Status {
    /// Whether `[rtsp]` serves or pushes at all.
    pub enabled: bool,
    /// e.g. `x264 2000 kbit/s, GOP 30, constrained-baseline`.
    pub encoder: String,
    /// Where clients read the stream (`rtsp://ADDR:PORT/PATH`), once the server is bound.
    pub url: Mutex<Option<String>>,
    /// Clients admitted now (counted against `client_limit`) and since start.
    pub clients: AtomicUsize,
    pub clients_total: AtomicU64,
    /// Requests refused with 503 for a client limit.
    pub refused: AtomicU64,
    /// Frames encoded and their time (push to access unit out), and the bytes made.
    pub encode: StageStats,
    pub bytes: AtomicU64,
    /// Frames the encoder skipped because it was still busy with an older one.
    pub skipped: AtomicU64,
    /// Set by the server or the pusher: the encoder's next frame is a key frame.
    pub want_keyframe: AtomicBool,
    /// Whether the pusher wants frames now (connecting or streaming).
    pub push_active: AtomicBool,
    pub push: Mutex<Option<PushStatus>>,
}

impl Status {
    pub fn new(cfg: &Config) -> Self {
        let r = &cfg.rtsp;
        Self {
            enabled: r.enabled(),
            encoder: format!(
                "{} {} kbit/s, GOP {}, {}",
                r.encoder.name(),
                r.bitrate_kbps,
                r.gop,
                r.profile.caps()
            ),
            push: Mutex::new(r.push.as_ref().map(|u| PushStatus {
                target: crate::config::rtsp::redacted(u),
                state: "connecting",
                ..Default::default()
            })),
            ..Default::default()
        }
    }

    /// Whether the encoder has anyone to encode for.
    pub fn demand(&self) -> bool {
        self.clients.load(Ordering::SeqCst) > 0 || self.push_active.load(Ordering::SeqCst)
    }

    pub fn push_status(&self) -> Option<PushStatus> {
        self.push.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    pub fn update_push(&self, f: impl FnOnce(&mut PushStatus)) {
        if let Some(p) = self.push.lock().unwrap_or_else(|p| p.into_inner()).as_mut() {
            f(p);
        }
    }

    pub fn url(&self) -> Option<String> {
        self.url.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// `/state`'s `rtsp` object (null when `[rtsp]` is off).
    pub fn to_json(&self) -> serde_json::Value {
        if !self.enabled {
            return serde_json::Value::Null;
        }
        let (p50, p99) = self.encode.percentiles();
        serde_json::json!({
            "url": self.url(),
            "encoder": self.encoder,
            "clients": self.clients.load(Ordering::SeqCst),
            "clients_total": self.clients_total.load(Ordering::Relaxed),
            "refused": self.refused.load(Ordering::Relaxed),
            "frames_encoded": self.encode.frames.load(Ordering::Relaxed),
            "frames_skipped": self.skipped.load(Ordering::Relaxed),
            "bytes_encoded": self.bytes.load(Ordering::Relaxed),
            "encode_ms": {"p50": p50, "p99": p99},
            "encoding": self.demand(),
            "push": self.push_status(),
        })
    }

    /// One line for D-Bus `Rtsp` and the STATUS line.
    pub fn summary(&self) -> String {
        if !self.enabled {
            return "off".into();
        }
        let mut parts = Vec::new();
        if let Some(u) = self.url() {
            parts.push(format!(
                "serving {u} ({} clients)",
                self.clients.load(Ordering::SeqCst)
            ));
        }
        if let Some(p) = self.push_status() {
            parts.push(format!(
                "push {} {}{}",
                p.target,
                p.state,
                p.error.map(|e| format!(": {e}")).unwrap_or_default()
            ));
        }
        parts.push(self.encoder.clone());
        parts.join("; ")
    }

    /// Prometheus lines.
    pub fn metrics(&self) -> String {
        if !self.enabled {
            return String::new();
        }
        let (p50, p99) = self.encode.percentiles();
        let pushing = self.push_status().map(|p| u8::from(p.state == "streaming"));
        let mut s = format!(
            "# TYPE volcap_rtsp_clients gauge\nvolcap_rtsp_clients {}\n\
             # TYPE volcap_rtsp_clients_total counter\nvolcap_rtsp_clients_total {}\n\
             # HELP volcap_rtsp_refused_total requests refused for a client limit (503)\n\
             # TYPE volcap_rtsp_refused_total counter\nvolcap_rtsp_refused_total {}\n\
             # TYPE volcap_rtsp_frames_encoded_total counter\nvolcap_rtsp_frames_encoded_total {}\n\
             # TYPE volcap_rtsp_bytes_encoded_total counter\nvolcap_rtsp_bytes_encoded_total {}\n\
             # TYPE volcap_rtsp_encode_ms summary\nvolcap_rtsp_encode_ms{{quantile=\"0.5\"}} {p50}\n\
             volcap_rtsp_encode_ms{{quantile=\"0.99\"}} {p99}\n",
            self.clients.load(Ordering::SeqCst),
            self.clients_total.load(Ordering::Relaxed),
            self.refused.load(Ordering::Relaxed),
            self.encode.frames.load(Ordering::Relaxed),
            self.bytes.load(Ordering::Relaxed),
        );
        if let Some(p) = pushing {
            s.push_str(&format!(
                "# TYPE volcap_rtsp_push_streaming gauge\nvolcap_rtsp_push_streaming {p}\n"
            ));
        }
        s
    }
}

/// The build feature `[rtsp]` needs and this build lacks, if any.
pub fn missing_feature(cfg: &Config) -> Option<&'static str> {
    (cfg.rtsp.enabled() && !cfg!(feature = "rtsp")).then_some("rtsp")
}

/// What runs RTSP; dropping it does not stop the threads (they end with `Shared::stop`).
pub struct Running {
    pub threads: Vec<std::thread::JoinHandle<()>>,
}

/// Start the encoder, the server (`bind`) and the pusher (`push`) as `[rtsp]` says; nothing
/// when the section is off. An error (no GStreamer plugin, the address taken) names the key.
#[cfg(feature = "rtsp")]
pub fn start(
    cfg: &Config,
    shared: Arc<crate::pipeline::Shared>,
    status: Arc<Status>,
) -> Result<Running, String> {
    if !cfg.rtsp.enabled() {
        return Ok(Running { threads: vec![] });
    }
    gst::init().map_err(|e| format!("[rtsp]: GStreamer does not start: {e}"))?;
    let targets = encode::Targets::new(status.clone());
    let mut threads = Vec::new();
    let enc = encode::Encoder::new(&cfg.rtsp, targets.clone())?;
    if let Some(bind) = cfg.rtsp.bind {
        let (url, t) = serve::start(cfg, bind, shared.clone(), status.clone(), targets.clone())?;
        *status.url.lock().unwrap_or_else(|p| p.into_inner()) = Some(url);
        threads.push(t);
    }
    if let Some(url) = &cfg.rtsp.push {
        threads.push(push::spawn(
            url.clone(),
            cfg.rtsp.push_retry_max_s,
            shared.clone(),
            status.clone(),
            targets.clone(),
        )?);
    }
    threads.push(enc.spawn(shared, status)?);
    Ok(Running { threads })
}

#[cfg(not(feature = "rtsp"))]
pub fn start(
    cfg: &Config,
    _shared: Arc<crate::pipeline::Shared>,
    _status: Arc<Status>,
) -> Result<Running, String> {
    if cfg.rtsp.enabled() {
        return Err("[rtsp]: this volcapd was built without RTSP; rebuild with `--features rtsp` (needs libgstreamer1.0-dev, libgstrtspserver-1.0-dev)".into());
    }
    Ok(Running { threads: vec![] })
}
