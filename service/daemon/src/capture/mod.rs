//! Camera capture: one trait for every backend, typed faults, and the supervisor state
//! machine that turns device loss into a state (with retry and backoff) instead of a crash.
//!
//! Backends: `sim` (the scene simulator, paced at the scene's fps), `file` (an MJPEG file or
//! an image folder, replayed), `v4l2` (V4L2 webcams and OAK cameras in UVC mode; the device
//! binding is behind the `v4l2` cargo feature, the negotiation/decoding/error logic is always
//! built and tested with a fake device) and `depthai` (behind the `depthai` feature).

pub mod decode;
#[cfg(any(feature = "depthai", feature = "depthai-typecheck"))]
pub mod depthai;
pub mod file;
pub mod replay;
pub mod sim;
pub mod v4l2;

use std::time::{Duration, Instant};

/// How long a device read waits before the camera counts as giving no signal.
pub const DRIVER_TIMEOUT: Duration = Duration::from_secs(2);

/// Ground truth that only the simulator can attach to a frame (oracle mode).
pub struct SimTruth {
    pub gt: volcap_sim::sim::GroundTruth,
    /// Subjects covering a visible area of the frame.
    pub people: usize,
}

/// One decoded camera frame, RGB8 row-major.
pub struct Frame {
    pub rgb: Vec<u8>,
    pub width: usize,
    pub height: usize,
    /// Backend's frame counter.
    pub seq: u64,
    /// When the frame was captured (start of the end-to-end latency).
    pub at: Instant,
    pub truth: Option<SimTruth>,
}

/// Why the camera is not delivering frames. Every variant is a state the daemon reports,
/// never a crash.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Fault {
    #[error("no device: {0}")]
    NoDevice(String),
    #[error("device busy (another program has it open): {0}")]
    Busy(String),
    #[error("no signal: no frame within {0} ms")]
    NoSignal(u64),
    #[error("camera unplugged mid-stream: {0}")]
    Unplugged(String),
    #[error("format refused: wanted {wanted}, device offers {offered}")]
    FormatRefused { wanted: String, offered: String },
    #[error("end of recording: {0}")]
    Ended(String),
    #[error("capture failed: {0}")]
    Failed(String),
}

impl Fault {
    /// Faults a retry cannot cure (the recording is over).
    pub fn is_terminal(&self) -> bool {
        matches!(self, Fault::Ended(_))
    }

    /// Short machine-readable name of the reason.
    pub fn kind(&self) -> &'static str {
        match self {
            Fault::NoDevice(_) => "no-device",
            Fault::Busy(_) => "busy",
            Fault::NoSignal(_) => "no-signal",
            Fault::Unplugged(_) => "unplugged",
            Fault::FormatRefused { .. } => "format-refused",
            Fault::Ended(_) => "ended",
            Fault::Failed(_) => "failed",
        }
    }
}

/// A frame the backend received but could not use; the stream goes on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Skip {
    /// The frame ended before its end-of-image marker.
    Truncated(String),
    /// The frame did not decode.
    Corrupt(String),
}

/// What one `next` call gives.
pub enum Grab {
    Frame(Frame),
    Skipped(Skip),
}

/// A camera backend. `next` blocks at most about one frame period (plus a driver timeout).
pub trait Camera {
    /// Backend and device, for logs, `/state` and D-Bus.
    fn describe(&self) -> String;
    /// Open (or re-open after a fault) the device and start streaming.
    fn open(&mut self) -> Result<(), Fault>;
    /// The next frame; a `Fault` means the stream is lost and the camera will be closed.
    fn next(&mut self) -> Result<Grab, Fault>;
    /// Release the device (called after a fault and on shutdown).
    fn close(&mut self);
}

/// The camera's state as the daemon reports it.
#[derive(Debug, Clone, PartialEq)]
pub enum CameraState {
    Opening,
    Running,
    /// Open, but what arrives does not decode: frames skipped `in_a_row` (from the start,
    /// or [`SKIPPING_AFTER`] in a row after frames came), the last one's reason.
    Skipping {
        in_a_row: u64,
        last: String,
    },
    /// Lost with a typed reason; the next attempt is `retry_in` away.
    Lost {
        fault: Fault,
        retry_in: Duration,
    },
    /// A terminal fault (end of a recording without loop).
    Stopped(Fault),
}

/// Skipped frames in a row after which a running camera is said to be skipping.
pub const SKIPPING_AFTER: u64 = 5;

/// What one supervisor step produced.
pub enum Step {
    Frame(Frame),
    Skipped(Skip),
    /// No frame: the camera is away (the state says why and when the next try is).
    State(CameraState),
}

/// Retry with exponential backoff: `first`, doubling, capped at `max`; reset by a frame.
#[derive(Debug, Clone, Copy)]
pub struct Backoff {
    pub first: Duration,
    pub max: Duration,
}

impl Default for Backoff {
    fn default() -> Self {
        Self {
            first: Duration::from_millis(250),
            max: Duration::from_secs(5),
        }
    }
}

/// Drives a [`Camera`] through open -> running -> lost -> retry -> running.
pub struct Supervisor<C: Camera + ?Sized> {
    cam: Box<C>,
    backoff: Backoff,
    delay: Duration,
    state: CameraState,
    open: bool,
    /// Attempts to open, frames delivered, frames skipped, faults seen.
    pub opens: u64,
    pub frames: u64,
    pub skipped: u64,
    pub faults: u64,
    skips_in_a_row: u64,
}

impl<C: Camera + ?Sized> Supervisor<C> {
    pub fn new(cam: Box<C>, backoff: Backoff) -> Self {
        Self {
            cam,
            backoff,
            delay: backoff.first,
            state: CameraState::Opening,
            open: false,
            opens: 0,
            frames: 0,
            skipped: 0,
            faults: 0,
            skips_in_a_row: 0,
        }
    }

    pub fn state(&self) -> &CameraState {
        &self.state
    }

    pub fn describe(&self) -> String {
        self.cam.describe()
    }

    fn lose(&mut self, fault: Fault) -> Step {
        self.faults += 1;
        if self.open {
            self.cam.close();
            self.open = false;
        }
        self.state = if fault.is_terminal() {
            CameraState::Stopped(fault)
        } else {
            let retry_in = self.delay;
            self.delay = (self.delay * 2).min(self.backoff.max);
            CameraState::Lost { fault, retry_in }
        };
        Step::State(self.state.clone())
    }

    /// One step. While lost it sleeps out the backoff (in slices of at most `max_sleep`, so
    /// a caller can stop promptly) and then tries to open again.
    pub fn step(&mut self, max_sleep: Duration) -> Step {
        match &mut self.state {
            CameraState::Stopped(_) => {
                std::thread::sleep(max_sleep);
                return Step::State(self.state.clone());
            }
            CameraState::Lost { retry_in, .. } if !retry_in.is_zero() => {
                let nap = (*retry_in).min(max_sleep);
                std::thread::sleep(nap);
                *retry_in -= nap;
                if !retry_in.is_zero() {
                    return Step::State(self.state.clone());
                }
            }
            _ => {}
        }
        if !self.open {
            self.opens += 1;
            match self.cam.open() {
                Ok(()) => self.open = true,
                Err(f) => return self.lose(f),
            }
        }
        match self.cam.next() {
            Ok(Grab::Frame(f)) => {
                self.frames += 1;
                self.skips_in_a_row = 0;
                self.delay = self.backoff.first;
                self.state = CameraState::Running;
                Step::Frame(f)
            }
            Ok(Grab::Skipped(s)) => {
                self.skipped += 1;
                self.skips_in_a_row += 1;
                let opening = matches!(
                    self.state,
                    CameraState::Opening | CameraState::Skipping { .. }
                );
                if opening || self.skips_in_a_row >= SKIPPING_AFTER {
                    self.state = CameraState::Skipping {
                        in_a_row: self.skips_in_a_row,
                        last: match &s {
                            Skip::Truncated(m) | Skip::Corrupt(m) => m.clone(),
                        },
                    };
                }
                Step::Skipped(s)
            }
            Err(f) => self.lose(f),
        }
    }

    pub fn shutdown(&mut self) {
        if self.open {
            self.cam.close();
            self.open = false;
        }
    }
}

use crate::config::{Backend, Config};

/// Builds the camera on the capture thread (DepthAI handles cannot move between threads).
pub type CameraFactory = Box<dyn FnOnce() -> Result<Box<dyn Camera>, String> + Send>;
use std::sync::Arc;

/// The configured camera backend, checked as far as it can be before the thread starts (the
/// scene parses, the recording exists, the backend is built in). Returns the factory that
/// builds it on the capture thread and a description.
pub fn factory(cfg: &Config) -> Result<(CameraFactory, String), String> {
    match cfg.camera.backend {
        Backend::Sim => {
            let scene_path = cfg.scene_path().ok_or("camera.scene is required")?;
            let assets = volcap_sim::HumanAssets::embedded().map_err(|e| e.to_string())?;
            let sim = volcap_sim::Scene::load(&scene_path)
                .map_err(|e| format!("scene error: {e}"))
                .and_then(|s| {
                    volcap_sim::Simulator::new(s, Arc::new(assets))
                        .map_err(|e| format!("scene error: {e}"))
                })?;
            let with_truth = cfg.field() == crate::config::FieldMode::Oracle;
            let cam = sim::SimCamera::new(sim, scene_path.display().to_string(), with_truth);
            let source = cam.describe();
            Ok((
                Box::new(move || Ok(Box::new(cam) as Box<dyn Camera>)),
                source,
            ))
        }
        Backend::File => {
            let path = cfg
                .camera
                .path
                .as_deref()
                .map(|p| cfg.resolve(p))
                .ok_or("camera.path is required")?;
            match std::fs::metadata(&path) {
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    return Err(format!("camera.path: {} does not exist", path.display()));
                }
                Err(e) => return Err(format!("camera.path: {}: {e}", path.display())),
                Ok(m) if !(m.is_file() || m.is_dir()) => {
                    return Err(format!(
                        "camera.path: {} is neither a regular file (MJPEG) nor a folder of images",
                        path.display()
                    ));
                }
                Ok(_) => {}
            }
            let cam = file::FileCamera::new(
                path,
                cfg.camera.fps.unwrap_or(15.0),
                cfg.camera.looping.unwrap_or(true),
            );
            let source = cam.describe();
            Ok((
                Box::new(move || Ok(Box::new(cam) as Box<dyn Camera>)),
                source,
            ))
        }
        Backend::V4l2 => v4l2_factory(cfg),
        Backend::Depthai => depthai_factory(cfg),
    }
}

/// The build feature `backend` needs and this build lacks, if any: `--check-config` checks
/// such a config whole and names the feature in a note instead of failing.
pub fn missing_feature(backend: Backend) -> Option<&'static str> {
    match backend {
        Backend::V4l2 if !cfg!(feature = "v4l2") => Some("v4l2"),
        Backend::Depthai if !cfg!(feature = "depthai") => Some("depthai"),
        _ => None,
    }
}

#[cfg(feature = "v4l2")]
pub(crate) fn v4l2_factory(cfg: &Config) -> Result<(CameraFactory, String), String> {
    use v4l2::{DeviceSpec, V4l2Camera, V4l2Settings, sys::V4lDevice};
    let c = &cfg.camera;
    let settings = V4l2Settings {
        device: DeviceSpec::parse(c.device.as_deref().unwrap_or("/dev/video0")),
        format: c.format.unwrap_or_default(),
        size: (c.width.unwrap_or(640), c.height.unwrap_or(480)),
        fps: c.fps.unwrap_or(30.0).round() as u32,
    };
    let cam = V4l2Camera::new(V4lDevice::default(), settings);
    let source = Camera::describe(&cam);
    Ok((
        Box::new(move || Ok(Box::new(cam) as Box<dyn Camera>)),
        source,
    ))
}

#[cfg(not(feature = "v4l2"))]
pub(crate) fn v4l2_factory(_: &Config) -> Result<(CameraFactory, String), String> {
    Err("this volcapd was built without V4L2 support; rebuild with `--features v4l2` (needs libclang-dev)".into())
}

#[cfg(feature = "depthai")]
pub(crate) fn depthai_factory(cfg: &Config) -> Result<(CameraFactory, String), String> {
    let c = &cfg.camera;
    let (size, fps) = (
        (c.width.unwrap_or(640), c.height.unwrap_or(400)),
        c.fps.unwrap_or(30.0),
    );
    let source = format!("depthai:CAM_A {}x{}@{fps}", size.0, size.1);
    Ok((
        Box::new(move || {
            Ok(Box::new(self::depthai::DepthaiCamera::new(size, fps)) as Box<dyn Camera>)
        }),
        source,
    ))
}

#[cfg(not(feature = "depthai"))]
pub(crate) fn depthai_factory(_: &Config) -> Result<(CameraFactory, String), String> {
    Err("this volcapd was built without DepthAI support; rebuild with `--features depthai`, or run an OAK camera in UVC mode with backend \"v4l2\"".into())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::collections::VecDeque;

    /// A scripted camera: each open/next pops its next scripted answer.
    pub struct Scripted {
        pub opens: VecDeque<Result<(), Fault>>,
        pub nexts: VecDeque<Result<Option<Skip>, Fault>>,
        pub closes: usize,
    }

    pub fn frame(seq: u64) -> Frame {
        Frame {
            rgb: vec![0; 12],
            width: 2,
            height: 2,
            seq,
            at: Instant::now(),
            truth: None,
        }
    }

    impl Camera for Scripted {
        fn describe(&self) -> String {
            "scripted".into()
        }
        fn open(&mut self) -> Result<(), Fault> {
            self.opens.pop_front().unwrap_or(Ok(()))
        }
        fn next(&mut self) -> Result<Grab, Fault> {
            match self.nexts.pop_front() {
                Some(Ok(None)) | None => Ok(Grab::Frame(frame(0))),
                Some(Ok(Some(s))) => Ok(Grab::Skipped(s)),
                Some(Err(f)) => Err(f),
            }
        }
        fn close(&mut self) {
            self.closes += 1;
        }
    }

    fn backoff() -> Backoff {
        Backoff {
            first: Duration::from_millis(4),
            max: Duration::from_millis(16),
        }
    }

    #[test]
    fn lost_device_is_a_state_with_backoff_and_recovers() {
        let cam = Scripted {
            opens: VecDeque::from([
                Err(Fault::NoDevice("/dev/video0".into())),
                Err(Fault::Busy("/dev/video0".into())),
                Ok(()),
                Err(Fault::NoDevice("/dev/video0".into())),
                Err(Fault::NoDevice("/dev/video0".into())),
                Err(Fault::NoDevice("/dev/video0".into())),
                Ok(()),
            ]),
            nexts: VecDeque::from([
                Ok(None),
                Ok(Some(Skip::Corrupt("bad huffman".into()))),
                Ok(None),
                Err(Fault::Unplugged("ENODEV".into())),
                Ok(None),
            ]),
            closes: 0,
        };
        let mut s = Supervisor::new(Box::new(cam), backoff());
        let mut log = Vec::new();
        for _ in 0..200 {
            match s.step(Duration::from_millis(1)) {
                Step::Frame(_) => log.push("frame".to_string()),
                Step::Skipped(_) => log.push("skip".into()),
                Step::State(CameraState::Lost { fault, retry_in }) => {
                    if log.last().map(String::as_str) != Some(fault.kind()) {
                        log.push(fault.kind().into());
                        // Backoff doubles and is capped.
                        assert!(retry_in <= Duration::from_millis(16), "{retry_in:?}");
                    }
                }
                Step::State(st) => panic!("unexpected state {st:?}"),
            }
            if s.frames == 4 {
                break;
            }
        }
        assert_eq!(
            log,
            [
                "no-device",
                "busy",
                "frame",
                "skip",
                "frame",
                "unplugged",
                "no-device",
                "frame",
                "frame"
            ]
        );
        assert_eq!(*s.state(), CameraState::Running);
        assert_eq!(s.skipped, 1);
        assert_eq!(s.faults, 6);
    }

    #[test]
    fn backoff_doubles_to_the_cap_and_resets_after_a_frame() {
        let cam = Scripted {
            opens: VecDeque::from(vec![Err(Fault::NoDevice("x".into())); 5]),
            nexts: VecDeque::new(),
            closes: 0,
        };
        let mut s = Supervisor::new(Box::new(cam), backoff());
        let mut delays = Vec::new();
        while delays.len() < 5 {
            if let Step::State(CameraState::Lost { retry_in, .. }) = s.step(Duration::from_secs(1))
            {
                delays.push(retry_in.as_millis());
            }
        }
        assert_eq!(delays, [4, 8, 16, 16, 16]);
        // Open succeeds now: a frame, and the next fault starts from the first delay again.
        assert!(matches!(s.step(Duration::from_secs(1)), Step::Frame(_)));
        assert_eq!(*s.state(), CameraState::Running);
        assert_eq!(s.delay, Duration::from_millis(4));
    }

    #[test]
    fn end_of_recording_is_terminal_and_closes_once() {
        let cam = Scripted {
            opens: VecDeque::new(),
            nexts: VecDeque::from([Ok(None), Err(Fault::Ended("x.mjpg".into()))]),
            closes: 0,
        };
        let mut s = Supervisor::new(Box::new(cam), backoff());
        assert!(matches!(s.step(Duration::ZERO), Step::Frame(_)));
        assert!(matches!(
            s.step(Duration::ZERO),
            Step::State(CameraState::Stopped(Fault::Ended(_)))
        ));
        assert!(matches!(
            s.step(Duration::ZERO),
            Step::State(CameraState::Stopped(_))
        ));
        assert_eq!(s.opens, 1);
        assert_eq!(s.cam.closes, 1);
    }
}
