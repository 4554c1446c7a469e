//! The one H.264 encoder: the latest published frame (composited over the background, as
//! the JPEG is) into `appsrc ! videoconvert ! x264enc|openh264enc ! h264parse ! appsink`,
//! each access unit handed to every target (the server's media, the pusher).

use super::Status;
use crate::config::rtsp::{Encoder as Kind, RtspConfig};
use crate::pipeline::Shared;
use gst::prelude::*;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Frames pushed into the encoder and not out yet, at most: past it a new frame is skipped
/// (the encoder is still busy; the next newest frame goes in when it is free).
const IN_FLIGHT: usize = 2;
/// A frame in the encoder this long is taken as dropped by it.
const STALE: Duration = Duration::from_secs(1);
/// Access units a target's hand-off queue holds before it drops its oldest.
pub(super) const TARGET_QUEUE: u64 = 30;

/// Where the access units go: the server's shared media and the pusher (each an `appsrc`
/// with a leaky queue), with the units each has been given. A target takes units only while
/// its pipeline plays (a paused pipeline would stamp them all with one time) and starts at a
/// key frame (asked for when it starts playing), so every client's stream begins decodable.
#[derive(Clone)]
pub(super) struct Targets {
    list: Arc<Mutex<Vec<Target>>>,
    status: Arc<Status>,
}

struct Target {
    id: u64,
    src: gst_app::AppSrc,
    sent: Arc<AtomicU64>,
    /// Playing and given a key frame: takes every unit.
    started: bool,
}

impl Targets {
    pub(super) fn new(status: Arc<Status>) -> Self {
        Self {
            list: Default::default(),
            status,
        }
    }
    pub(super) fn add(&self, src: gst_app::AppSrc) -> (u64, Arc<AtomicU64>) {
        static NEXT: AtomicU64 = AtomicU64::new(1);
        let id = NEXT.fetch_add(1, Ordering::Relaxed);
        let sent = Arc::new(AtomicU64::new(0));
        self.lock().push(Target {
            id,
            src,
            sent: sent.clone(),
            started: false,
        });
        (id, sent)
    }
    pub(super) fn remove(&self, id: u64) {
        self.lock().retain(|t| t.id != id);
    }
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Target>> {
        self.list.lock().unwrap_or_else(|p| p.into_inner())
    }
    fn send(&self, au: &gst::Buffer) {
        let key = !au.flags().contains(gst::BufferFlags::DELTA_UNIT);
        for t in self.lock().iter_mut() {
            if t.src.current_state() != gst::State::Playing {
                t.started = false;
                continue;
            }
            if !t.started {
                if !key {
                    self.status.want_keyframe.store(true, Ordering::SeqCst);
                    continue;
                }
                t.started = true;
            }
            // Each target's pipeline stamps the unit on arrival (`do-timestamp`).
            let mut b = au.copy();
            {
                let b = b.make_mut();
                b.set_pts(gst::ClockTime::NONE);
                b.set_dts(gst::ClockTime::NONE);
            }
            if t.src.push_buffer(b).is_ok() {
                t.sent.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// An `appsrc` that takes access units from [`Targets`]: live, stamped on arrival, a
/// leaky queue of [`TARGET_QUEUE`] units (a target that does not keep up loses its oldest
/// units, never holds up the encoder).
pub(super) fn configure_target(src: &gst_app::AppSrc) {
    src.set_caps(Some(
        &gst::Caps::builder("video/x-h264")
            .field("stream-format", "byte-stream")
            .field("alignment", "au")
            .build(),
    ));
    src.set_is_live(true);
    src.set_format(gst::Format::Time);
    src.set_do_timestamp(true);
    src.set_max_buffers(TARGET_QUEUE);
    src.set_leaky_type(gst_app::AppLeakyType::Downstream);
    src.set_block(false);
}

/// The encoder's element and properties, as a `gst-launch` fragment.
pub fn encoder_launch(c: &RtspConfig) -> String {
    match c.encoder {
        Kind::X264 => format!(
            "x264enc name=enc tune=zerolatency threads=1 rc-lookahead=0 bframes=0 speed-preset=ultrafast bitrate={} key-int-max={} ! video/x-h264,profile={},stream-format=byte-stream,alignment=au",
            c.bitrate_kbps,
            c.gop,
            c.profile.caps()
        ),
        Kind::Openh264 => format!(
            "openh264enc name=enc bitrate={} gop-size={} complexity=low rate-control=bitrate ! video/x-h264,stream-format=byte-stream,alignment=au",
            c.bitrate_kbps as u64 * 1000,
            c.gop
        ),
    }
}

/// H.264 in 4:2:0 needs even sides: an odd-sided frame (a 257-px render) gets its last
/// column and row repeated once. Writes `px` (4-byte pixels, side `size`) into `out`;
/// returns the side. (4-byte pixels: GStreamer's rows of 3-byte RGB are padded to 4 bytes,
/// so a 258-px RGB row is not what it expects.)
pub fn even_sided(px: &[u8], size: usize, out: &mut Vec<u8>) -> usize {
    let side = size + size % 2;
    out.clear();
    out.reserve(side * side * 4);
    for y in 0..side {
        let row = &px[y.min(size - 1) * size * 4..][..size * 4];
        out.extend_from_slice(row);
        if side > size {
            out.extend_from_slice(&row[(size - 1) * 4..]);
        }
    }
    side
}

/// The plugin package that has the encoder, for the error when it is missing.
fn package(k: Kind) -> &'static str {
    match k {
        Kind::X264 => "gstreamer1.0-plugins-ugly",
        Kind::Openh264 => "gstreamer1.0-plugins-bad",
    }
}

pub(super) struct Encoder {
    pipeline: gst::Pipeline,
    src: gst_app::AppSrc,
    sink: gst_app::AppSink,
    /// When each frame inside the encoder went in, oldest first.
    in_flight: Arc<Mutex<VecDeque<Instant>>>,
    targets: Targets,
}

impl Encoder {
    pub(super) fn new(c: &RtspConfig, targets: Targets) -> Result<Self, String> {
        let enc = match c.encoder {
            Kind::X264 => "x264enc",
            Kind::Openh264 => "openh264enc",
        };
        if gst::ElementFactory::find(enc).is_none() {
            return Err(format!(
                "rtsp.encoder = \"{}\": GStreamer has no `{enc}` element here (install {})",
                c.encoder.name(),
                package(c.encoder)
            ));
        }
        let launch = format!(
            "appsrc name=src is-live=true format=time do-timestamp=false block=false max-buffers=4 \
             ! videoconvert ! {} \
             ! appsink name=sink sync=false max-buffers=8 drop=true",
            encoder_launch(c)
        );
        let pipeline = gst::parse::launch(&launch)
            .map_err(|e| format!("[rtsp]: the encoder pipeline: {e} ({launch})"))?
            .downcast::<gst::Pipeline>()
            .map_err(|_| "[rtsp]: the encoder pipeline is not a pipeline".to_string())?;
        let get = |name: &str| {
            pipeline
                .by_name(name)
                .ok_or_else(|| format!("[rtsp]: no element {name} in the encoder pipeline"))
        };
        let src = get("src")?
            .downcast::<gst_app::AppSrc>()
            .map_err(|_| "[rtsp]: src is not an appsrc".to_string())?;
        let sink = get("sink")?
            .downcast::<gst_app::AppSink>()
            .map_err(|_| "[rtsp]: sink is not an appsink".to_string())?;
        Ok(Self {
            pipeline,
            src,
            sink,
            in_flight: Default::default(),
            targets,
        })
    }

    pub(super) fn spawn(
        self,
        shared: Arc<Shared>,
        status: Arc<Status>,
    ) -> Result<std::thread::JoinHandle<()>, String> {
        let in_flight = self.in_flight.clone();
        let targets = self.targets.clone();
        let st = status.clone();
        self.sink.set_callbacks(
            gst_app::AppSinkCallbacks::builder()
                .new_sample(move |sink| {
                    let sample = sink.pull_sample().map_err(|_| gst::FlowError::Eos)?;
                    let Some(au) = sample.buffer_owned() else {
                        return Ok(gst::FlowSuccess::Ok);
                    };
                    // One access unit per frame, in order (the encoders run without
                    // look-ahead or frame skipping; x264 re-bases the timestamps).
                    if let Some(at) = in_flight
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .pop_front()
                    {
                        st.encode.record(at.elapsed().as_secs_f64() * 1e3);
                    }
                    st.bytes.fetch_add(au.size() as u64, Ordering::Relaxed);
                    targets.send(&au);
                    Ok(gst::FlowSuccess::Ok)
                })
                .build(),
        );
        self.pipeline
            .set_state(gst::State::Playing)
            .map_err(|e| format!("[rtsp]: the encoder does not start: {e}"))?;
        std::thread::Builder::new()
            .name("rtsp-encode".into())
            .spawn(move || self.run(shared, status))
            .map_err(|e| format!("[rtsp]: spawning the encoder thread: {e}"))
    }

    fn run(self, shared: Arc<Shared>, status: Arc<Status>) {
        let mut rx = shared.published.subscribe();
        let start = Instant::now();
        let bus = self.pipeline.bus();
        // The composite over the background, then at even sides (what goes in).
        let mut composite: Vec<u8> = Vec::new();
        let mut rgb: Vec<u8> = Vec::new();
        let mut size = 0usize;
        let mut encoding = false;
        while !shared.stop.load(Ordering::Relaxed) {
            if let Some(bus) = &bus {
                while let Some(m) = bus.pop_filtered(&[gst::MessageType::Error]) {
                    if let gst::MessageView::Error(e) = m.view() {
                        tracing::error!(
                            "rtsp encoder: {} ({:?}); restarting it",
                            e.error(),
                            e.debug()
                        );
                        let _ = self.pipeline.set_state(gst::State::Null);
                        self.in_flight
                            .lock()
                            .unwrap_or_else(|p| p.into_inner())
                            .clear();
                        let _ = self.pipeline.set_state(gst::State::Playing);
                        size = 0;
                    }
                }
            }
            if !status.demand() {
                // Nobody to encode for: no CPU spent.
                rx.mark_unchanged();
                encoding = false;
                std::thread::sleep(Duration::from_millis(20));
                continue;
            }
            if !encoding {
                encoding = true;
                status.want_keyframe.store(true, Ordering::SeqCst);
            }
            match rx.has_changed() {
                Ok(true) => {}
                Ok(false) => {
                    std::thread::sleep(Duration::from_millis(2));
                    continue;
                }
                Err(_) => break,
            }
            let Some(frame) = rx.borrow_and_update().clone() else {
                continue;
            };
            let busy = {
                let mut q = self.in_flight.lock().unwrap_or_else(|p| p.into_inner());
                // A frame the encoder dropped (rate control) never comes out: forget it.
                while q.front().is_some_and(|t| t.elapsed() > STALE) {
                    q.pop_front();
                }
                q.len() >= IN_FLIGHT
            };
            if busy {
                status.skipped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            let bg = shared.live().background;
            crate::pipeline::composite_over(&frame.rgba, bg, true, &mut composite);
            if frame.size == 0 || composite.len() != frame.size * frame.size * 4 {
                continue;
            }
            let side = even_sided(&composite, frame.size, &mut rgb);
            if side != size {
                size = side;
                self.src.set_caps(Some(
                    &gst::Caps::builder("video/x-raw")
                        .field("format", "RGBx")
                        .field("width", size as i32)
                        .field("height", size as i32)
                        // Nominal: the timestamps are the frames' own. A variable rate
                        // (0/1) makes x264enc hold every frame until the next one.
                        .field("framerate", gst::Fraction::new(30, 1))
                        .build(),
                ));
                status.want_keyframe.store(true, Ordering::SeqCst);
            }
            if status.want_keyframe.swap(false, Ordering::SeqCst) {
                let ev = gst_video::UpstreamForceKeyUnitEvent::builder()
                    .all_headers(true)
                    .build();
                self.sink.send_event(ev);
            }
            let pts = start.elapsed().as_nanos() as u64;
            let mut buf = gst::Buffer::from_mut_slice(std::mem::take(&mut rgb));
            if let Some(b) = buf.get_mut() {
                b.set_pts(gst::ClockTime::from_nseconds(pts));
                b.set_dts(gst::ClockTime::from_nseconds(pts));
            }
            self.in_flight
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .push_back(Instant::now());
            if let Err(e) = self.src.push_buffer(buf) {
                tracing::warn!("rtsp encoder refused a frame: {e:?}");
            }
            rgb = Vec::with_capacity(size * size * 4);
        }
        let _ = self.src.end_of_stream();
        let _ = self.pipeline.set_state(gst::State::Null);
    }
}
