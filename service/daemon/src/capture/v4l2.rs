//! The `v4l2` backend: V4L2 webcams, and OAK (DepthAI) cameras in UVC mode, which are plain
//! V4L2 devices. Format negotiation, decoding and the mapping of driver errors to typed
//! faults live here and are tested against a fake device; the binding to real devices (the
//! `v4l` crate: ioctls and mmap streaming, needs libclang to build) is behind the `v4l2`
//! cargo feature.

use super::{Camera, DRIVER_TIMEOUT, Fault, Frame, Grab, decode};
use serde::Deserialize;
use std::io;
use std::path::PathBuf;
use std::time::Instant;

/// The pixel formats we decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PixelFormat {
    Mjpeg,
    Yuyv,
}

impl PixelFormat {
    pub fn fourcc(self) -> [u8; 4] {
        match self {
            PixelFormat::Mjpeg => *b"MJPG",
            PixelFormat::Yuyv => *b"YUYV",
        }
    }
    fn of(fourcc: [u8; 4]) -> Option<Self> {
        match &fourcc {
            b"MJPG" | b"JPEG" => Some(PixelFormat::Mjpeg),
            b"YUYV" => Some(PixelFormat::Yuyv),
            _ => None,
        }
    }
}

/// Which format to ask for: `auto` prefers MJPEG (a quarter of YUYV's USB bandwidth at the
/// same size), then YUYV.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum FormatPref {
    #[default]
    Auto,
    Mjpeg,
    Yuyv,
}

/// One format a device offers and its frame sizes (`None`: any size, stepwise).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Offered {
    pub fourcc: [u8; 4],
    pub sizes: Option<Vec<(u32, u32)>>,
}

fn fourcc_str(f: [u8; 4]) -> String {
    f.iter()
        .map(|&b| if b.is_ascii_graphic() { b as char } else { '?' })
        .collect()
}

fn describe_offers(offered: &[Offered]) -> String {
    if offered.is_empty() {
        return "no formats".into();
    }
    offered
        .iter()
        .map(|o| match &o.sizes {
            None => format!("{} (any size)", fourcc_str(o.fourcc)),
            Some(s) => format!(
                "{} ({})",
                fourcc_str(o.fourcc),
                s.iter()
                    .map(|(w, h)| format!("{w}x{h}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// Pick the format to stream at `size`: the preferred decodable format that offers the size.
pub fn negotiate(
    offered: &[Offered],
    pref: FormatPref,
    size: (u32, u32),
) -> Result<PixelFormat, Fault> {
    let order: &[PixelFormat] = match pref {
        FormatPref::Auto => &[PixelFormat::Mjpeg, PixelFormat::Yuyv],
        FormatPref::Mjpeg => &[PixelFormat::Mjpeg],
        FormatPref::Yuyv => &[PixelFormat::Yuyv],
    };
    for want in order {
        let fits = offered.iter().any(|o| {
            PixelFormat::of(o.fourcc) == Some(*want)
                && o.sizes.as_ref().is_none_or(|s| s.contains(&size))
        });
        if fits {
            return Ok(*want);
        }
    }
    Err(Fault::FormatRefused {
        wanted: format!(
            "{} at {}x{}",
            order
                .iter()
                .map(|f| fourcc_str(f.fourcc()))
                .collect::<Vec<_>>()
                .join(" or "),
            size.0,
            size.1
        ),
        offered: describe_offers(offered),
    })
}

/// Map a driver error to a typed fault. `streaming`: the error came while frames flowed.
pub fn fault_of(e: &io::Error, what: &str, streaming: bool) -> Fault {
    const ENOENT: i32 = 2;
    const EIO: i32 = 5;
    const ENXIO: i32 = 6;
    const EAGAIN: i32 = 11;
    const EACCES: i32 = 13;
    const EBUSY: i32 = 16;
    const ENODEV: i32 = 19;
    const EINVAL: i32 = 22;
    const EPIPE: i32 = 32;
    match (e.raw_os_error(), e.kind()) {
        (Some(ENOENT), _) | (_, io::ErrorKind::NotFound) => Fault::NoDevice(format!("{what}: {e}")),
        (Some(EACCES), _) | (_, io::ErrorKind::PermissionDenied) => Fault::NoDevice(format!(
            "{what}: permission denied (is the service user in the video group?)"
        )),
        (Some(EBUSY), _) => Fault::Busy(what.to_string()),
        (Some(ENODEV | ENXIO | EIO | EPIPE), _) if streaming => {
            Fault::Unplugged(format!("{what}: {e}"))
        }
        (Some(ENODEV | ENXIO), _) => Fault::NoDevice(format!("{what}: {e}")),
        (Some(EAGAIN), _) | (_, io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock) => {
            Fault::NoSignal(DRIVER_TIMEOUT.as_millis() as u64)
        }
        (Some(EINVAL), _) if !streaming => Fault::FormatRefused {
            wanted: what.to_string(),
            offered: format!("driver said: {e}"),
        },
        _ => Fault::Failed(format!("{what}: {e}")),
    }
}

/// How to find the camera.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceSpec {
    /// `/dev/video0`, `/dev/v4l/by-id/...`
    Path(PathBuf),
    /// `name:...`: the first capture device whose card name contains this text.
    Name(String),
}

impl DeviceSpec {
    pub fn parse(s: &str) -> Self {
        match s.strip_prefix("name:") {
            Some(n) => DeviceSpec::Name(n.to_string()),
            None => DeviceSpec::Path(PathBuf::from(s)),
        }
    }
}

/// What the V4L2 backend needs from a device; implemented over the `v4l` crate (feature
/// `v4l2`) and by a fake in the tests.
pub trait Device {
    /// Capture devices present: (node, card name).
    fn list(&self) -> Vec<(PathBuf, String)>;
    fn open(&mut self, path: &std::path::Path) -> io::Result<()>;
    fn formats(&mut self) -> io::Result<Vec<Offered>>;
    /// Ask for a format, size and fps; returns what the driver actually set.
    fn set_format(
        &mut self,
        fourcc: [u8; 4],
        size: (u32, u32),
        fps: u32,
    ) -> io::Result<([u8; 4], (u32, u32))>;
    /// Start streaming (mmap buffers).
    fn start(&mut self) -> io::Result<()>;
    /// Copy the next filled buffer into `out` (waits up to the driver timeout).
    fn dequeue(&mut self, out: &mut Vec<u8>) -> io::Result<()>;
    fn close(&mut self);
}

/// Stream settings from the board config.
#[derive(Debug, Clone)]
pub struct V4l2Settings {
    pub device: DeviceSpec,
    pub format: FormatPref,
    pub size: (u32, u32),
    pub fps: u32,
}

pub struct V4l2Camera<D: Device> {
    dev: D,
    settings: V4l2Settings,
    format: Option<PixelFormat>,
    node: String,
    buf: Vec<u8>,
    seq: u64,
}

impl<D: Device> V4l2Camera<D> {
    pub fn new(dev: D, settings: V4l2Settings) -> Self {
        let node = match &settings.device {
            DeviceSpec::Path(p) => p.display().to_string(),
            DeviceSpec::Name(n) => format!("name:{n}"),
        };
        Self {
            dev,
            settings,
            format: None,
            node,
            buf: Vec::new(),
            seq: 0,
        }
    }

    fn resolve(&self) -> Result<PathBuf, Fault> {
        match &self.settings.device {
            DeviceSpec::Path(p) => Ok(p.clone()),
            DeviceSpec::Name(n) => {
                let all = self.dev.list();
                all.iter()
                    .find(|(_, card)| card.contains(n.as_str()))
                    .map(|(p, _)| p.clone())
                    .ok_or_else(|| {
                        Fault::NoDevice(format!(
                            "no capture device named like {n:?} (present: {})",
                            if all.is_empty() {
                                "none".to_string()
                            } else {
                                all.iter()
                                    .map(|(p, c)| format!("{} {c:?}", p.display()))
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            }
                        ))
                    })
            }
        }
    }
}

impl<D: Device> Camera for V4l2Camera<D> {
    fn describe(&self) -> String {
        match self.format {
            Some(f) => format!(
                "v4l2:{} {} {}x{}@{}",
                self.node,
                fourcc_str(f.fourcc()),
                self.settings.size.0,
                self.settings.size.1,
                self.settings.fps
            ),
            None => format!("v4l2:{}", self.node),
        }
    }

    fn open(&mut self) -> Result<(), Fault> {
        let path = self.resolve()?;
        self.node = path.display().to_string();
        let what = self.node.clone();
        self.dev
            .open(&path)
            .map_err(|e| fault_of(&e, &what, false))?;
        let result = (|| {
            let offered = self.dev.formats().map_err(|e| fault_of(&e, &what, false))?;
            let fmt = negotiate(&offered, self.settings.format, self.settings.size)?;
            let (got, size) = self
                .dev
                .set_format(fmt.fourcc(), self.settings.size, self.settings.fps)
                .map_err(|e| fault_of(&e, &what, false))?;
            if PixelFormat::of(got) != Some(fmt) || size != self.settings.size {
                return Err(Fault::FormatRefused {
                    wanted: format!(
                        "{} at {}x{}",
                        fourcc_str(fmt.fourcc()),
                        self.settings.size.0,
                        self.settings.size.1
                    ),
                    offered: format!(
                        "the driver set {} at {}x{}",
                        fourcc_str(got),
                        size.0,
                        size.1
                    ),
                });
            }
            self.dev.start().map_err(|e| fault_of(&e, &what, false))?;
            Ok(fmt)
        })();
        match result {
            Ok(fmt) => {
                self.format = Some(fmt);
                Ok(())
            }
            Err(f) => {
                self.dev.close();
                Err(f)
            }
        }
    }

    fn next(&mut self) -> Result<Grab, Fault> {
        let Some(fmt) = self.format else {
            return Err(Fault::Failed("read before open".into()));
        };
        let what = self.node.clone();
        self.dev
            .dequeue(&mut self.buf)
            .map_err(|e| fault_of(&e, &what, true))?;
        let at = Instant::now();
        let (w, h) = (self.settings.size.0 as usize, self.settings.size.1 as usize);
        let decoded = match fmt {
            PixelFormat::Mjpeg => decode::mjpeg(&self.buf).and_then(|(rgb, dw, dh)| {
                if (dw, dh) == (w, h) {
                    Ok(rgb)
                } else {
                    Err(super::Skip::Corrupt(format!(
                        "JPEG of {dw}x{dh} in a {w}x{h} stream"
                    )))
                }
            }),
            PixelFormat::Yuyv => decode::yuyv(&self.buf, w, h),
        };
        Ok(match decoded {
            Ok(rgb) => {
                self.seq += 1;
                Grab::Frame(Frame {
                    rgb,
                    width: w,
                    height: h,
                    seq: self.seq - 1,
                    at,
                    truth: None,
                })
            }
            Err(s) => Grab::Skipped(s),
        })
    }

    fn close(&mut self) {
        self.dev.close();
        self.format = None;
    }
}

/// The real device, over the `v4l` crate.
#[cfg(feature = "v4l2")]
pub mod sys {
    use super::Offered;
    use std::io;
    use std::path::{Path, PathBuf};
    use v4l::io::traits::CaptureStream;
    use v4l::video::Capture;

    #[derive(Default)]
    pub struct V4lDevice {
        dev: Option<v4l::Device>,
        stream: Option<v4l::io::mmap::Stream<'static>>,
    }

    impl super::Device for V4lDevice {
        fn list(&self) -> Vec<(PathBuf, String)> {
            v4l::context::enum_devices()
                .into_iter()
                .filter_map(|n| Some((n.path().to_path_buf(), n.name()?)))
                .collect()
        }

        fn open(&mut self, path: &Path) -> io::Result<()> {
            self.close();
            self.dev = Some(v4l::Device::with_path(path)?);
            Ok(())
        }

        fn formats(&mut self) -> io::Result<Vec<Offered>> {
            let dev = self.dev.as_ref().ok_or(io::ErrorKind::NotConnected)?;
            let mut out = Vec::new();
            for d in dev.enum_formats()? {
                let mut sizes = Some(Vec::new());
                for fs in dev.enum_framesizes(d.fourcc)? {
                    match fs.size {
                        v4l::framesize::FrameSizeEnum::Discrete(s) => {
                            if let Some(v) = sizes.as_mut() {
                                v.push((s.width, s.height));
                            }
                        }
                        v4l::framesize::FrameSizeEnum::Stepwise(_) => sizes = None,
                    }
                }
                out.push(Offered {
                    fourcc: d.fourcc.repr,
                    sizes,
                });
            }
            Ok(out)
        }

        fn set_format(
            &mut self,
            fourcc: [u8; 4],
            size: (u32, u32),
            fps: u32,
        ) -> io::Result<([u8; 4], (u32, u32))> {
            let dev = self.dev.as_ref().ok_or(io::ErrorKind::NotConnected)?;
            let fmt = v4l::Format::new(size.0, size.1, v4l::FourCC::new(&fourcc));
            let got = dev.set_format(&fmt)?;
            dev.set_params(&v4l::video::capture::Parameters::with_fps(fps))?;
            Ok((got.fourcc.repr, (got.width, got.height)))
        }

        fn start(&mut self) -> io::Result<()> {
            let dev = self.dev.as_ref().ok_or(io::ErrorKind::NotConnected)?;
            let mut s =
                v4l::io::mmap::Stream::with_buffers(dev, v4l::buffer::Type::VideoCapture, 4)?;
            s.set_timeout(super::DRIVER_TIMEOUT);
            self.stream = Some(s);
            Ok(())
        }

        fn dequeue(&mut self, out: &mut Vec<u8>) -> io::Result<()> {
            let s = self.stream.as_mut().ok_or(io::ErrorKind::NotConnected)?;
            let (buf, meta) = s.next()?;
            let used = (meta.bytesused as usize).min(buf.len());
            out.clear();
            out.extend_from_slice(&buf[..used]);
            Ok(())
        }

        fn close(&mut self) {
            self.stream = None;
            self.dev = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Backoff, CameraState, Step, Supervisor};
    use super::*;
    use std::collections::VecDeque;
    use std::sync::{Arc, Mutex};
    use std::time::Duration;

    /// What the fake device does next; tests change it while the supervisor runs.
    #[derive(Clone, PartialEq)]
    enum Plug {
        Absent,
        Busy,
        Present,
    }

    struct World {
        plug: Plug,
        offered: Vec<Offered>,
        /// Frames waiting; an empty queue times out (no signal).
        frames: VecDeque<Vec<u8>>,
        /// Driver silently changes the size it is asked for.
        adjusts_to: Option<(u32, u32)>,
        opened: Option<PathBuf>,
    }

    #[derive(Clone)]
    struct Fake(Arc<Mutex<World>>);

    fn os(code: i32) -> io::Error {
        io::Error::from_raw_os_error(code)
    }

    impl Device for Fake {
        fn list(&self) -> Vec<(PathBuf, String)> {
            let w = self.0.lock().unwrap();
            if w.plug == Plug::Absent {
                vec![]
            } else {
                vec![
                    ("/dev/video0".into(), "Integrated IR Camera".into()),
                    ("/dev/video2".into(), "Luxonis OAK-D UVC".into()),
                ]
            }
        }
        fn open(&mut self, path: &std::path::Path) -> io::Result<()> {
            let mut w = self.0.lock().unwrap();
            match w.plug {
                Plug::Absent => Err(os(2)),
                Plug::Busy => Err(os(16)),
                Plug::Present => {
                    w.opened = Some(path.to_path_buf());
                    Ok(())
                }
            }
        }
        fn formats(&mut self) -> io::Result<Vec<Offered>> {
            Ok(self.0.lock().unwrap().offered.clone())
        }
        fn set_format(
            &mut self,
            f: [u8; 4],
            s: (u32, u32),
            _fps: u32,
        ) -> io::Result<([u8; 4], (u32, u32))> {
            Ok((f, self.0.lock().unwrap().adjusts_to.unwrap_or(s)))
        }
        fn start(&mut self) -> io::Result<()> {
            Ok(())
        }
        fn dequeue(&mut self, out: &mut Vec<u8>) -> io::Result<()> {
            let mut w = self.0.lock().unwrap();
            if w.plug != Plug::Present {
                return Err(os(19));
            }
            match w.frames.pop_front() {
                Some(f) => {
                    *out = f;
                    Ok(())
                }
                None => Err(io::Error::from(io::ErrorKind::TimedOut)),
            }
        }
        fn close(&mut self) {
            self.0.lock().unwrap().opened = None;
        }
    }

    fn yuyv_grey(w: usize, h: usize, y: u8) -> Vec<u8> {
        [y, 128].repeat(w * h)
    }

    fn world(offered: Vec<Offered>) -> Arc<Mutex<World>> {
        Arc::new(Mutex::new(World {
            plug: Plug::Absent,
            offered,
            frames: VecDeque::new(),
            adjusts_to: None,
            opened: None,
        }))
    }

    fn settings(device: &str, format: FormatPref) -> V4l2Settings {
        V4l2Settings {
            device: DeviceSpec::parse(device),
            format,
            size: (4, 2),
            fps: 30,
        }
    }

    #[test]
    fn negotiation_prefers_mjpeg_and_names_what_is_offered() {
        let both = vec![
            Offered {
                fourcc: *b"YUYV",
                sizes: Some(vec![(640, 480), (1280, 720)]),
            },
            Offered {
                fourcc: *b"MJPG",
                sizes: Some(vec![(1280, 720), (1920, 1080)]),
            },
        ];
        assert_eq!(
            negotiate(&both, FormatPref::Auto, (1280, 720)),
            Ok(PixelFormat::Mjpeg)
        );
        assert_eq!(
            negotiate(&both, FormatPref::Auto, (640, 480)),
            Ok(PixelFormat::Yuyv)
        );
        assert_eq!(
            negotiate(&both, FormatPref::Yuyv, (1280, 720)),
            Ok(PixelFormat::Yuyv)
        );
        match negotiate(&both, FormatPref::Mjpeg, (640, 480)) {
            Err(Fault::FormatRefused { wanted, offered }) => {
                assert_eq!(wanted, "MJPG at 640x480");
                assert!(offered.contains("YUYV (640x480, 1280x720)"), "{offered}");
                assert!(offered.contains("MJPG (1280x720, 1920x1080)"), "{offered}");
            }
            other => panic!("{other:?}"),
        }
        let odd = vec![Offered {
            fourcc: *b"GREY",
            sizes: None,
        }];
        assert!(matches!(
            negotiate(&odd, FormatPref::Auto, (640, 480)),
            Err(Fault::FormatRefused { .. })
        ));
        let stepwise = vec![Offered {
            fourcc: *b"YUYV",
            sizes: None,
        }];
        assert_eq!(
            negotiate(&stepwise, FormatPref::Auto, (320, 240)),
            Ok(PixelFormat::Yuyv)
        );
    }

    #[test]
    fn driver_errors_map_to_typed_faults() {
        assert!(matches!(
            fault_of(&os(2), "/dev/video0", false),
            Fault::NoDevice(_)
        ));
        assert!(
            matches!(fault_of(&os(13), "/dev/video0", false), Fault::NoDevice(m) if m.contains("video group"))
        );
        assert!(matches!(
            fault_of(&os(16), "/dev/video0", false),
            Fault::Busy(_)
        ));
        assert!(matches!(
            fault_of(&os(19), "/dev/video0", true),
            Fault::Unplugged(_)
        ));
        assert!(matches!(
            fault_of(&os(19), "/dev/video0", false),
            Fault::NoDevice(_)
        ));
        assert!(matches!(
            fault_of(&os(22), "/dev/video0", false),
            Fault::FormatRefused { .. }
        ));
        assert!(matches!(
            fault_of(&io::Error::from(io::ErrorKind::TimedOut), "x", true),
            Fault::NoSignal(_)
        ));
    }

    /// Unplugged at start -> busy -> running (YUYV decoded) -> no signal -> unplugged
    /// mid-stream -> replugged -> running again: every loss a typed state, never a crash.
    #[test]
    fn fake_device_lives_through_loss_and_replug() {
        let w = world(vec![Offered {
            fourcc: *b"YUYV",
            sizes: Some(vec![(4, 2)]),
        }]);
        let cam = V4l2Camera::new(Fake(w.clone()), settings("/dev/video0", FormatPref::Auto));
        let mut sup = Supervisor::new(
            Box::new(cam),
            Backoff {
                first: Duration::from_millis(2),
                max: Duration::from_millis(8),
            },
        );
        let mut seen = Vec::<String>::new();
        let step = |sup: &mut Supervisor<V4l2Camera<Fake>>, n: usize, seen: &mut Vec<String>| {
            for _ in 0..n {
                let s = match sup.step(Duration::from_millis(1)) {
                    Step::Frame(f) => {
                        assert_eq!((f.width, f.height, f.rgb.len()), (4, 2, 24));
                        format!("frame {}", f.rgb[0])
                    }
                    Step::Skipped(s) => format!("skip {s:?}"),
                    Step::State(CameraState::Lost { fault, .. }) => fault.kind().into(),
                    Step::State(s) => format!("{s:?}"),
                };
                if seen.last() != Some(&s) {
                    seen.push(s);
                }
            }
        };
        step(&mut sup, 3, &mut seen);
        w.lock().unwrap().plug = Plug::Busy;
        step(&mut sup, 12, &mut seen);
        {
            let mut g = w.lock().unwrap();
            g.plug = Plug::Present;
            g.frames
                .extend([yuyv_grey(4, 2, 235), yuyv_grey(4, 2, 16), vec![1, 2, 3]]);
        }
        step(&mut sup, 30, &mut seen);
        assert!(w.lock().unwrap().opened.is_none(), "closed after the loss");
        {
            let mut g = w.lock().unwrap();
            g.frames.extend((0..100).map(|_| yuyv_grey(4, 2, 235)));
        }
        step(&mut sup, 30, &mut seen);
        assert_eq!(*sup.state(), CameraState::Running);
        // The plug is pulled while frames flow: unplugged mid-stream, then no device.
        w.lock().unwrap().plug = Plug::Absent;
        step(&mut sup, 30, &mut seen);
        assert_eq!(
            seen,
            [
                "no-device",
                "busy",
                "frame 255",
                "frame 0",
                "skip Truncated(\"YUYV 4x2 needs 16 bytes, got 3\")",
                "no-signal",
                "frame 255",
                "unplugged",
                "no-device"
            ],
        );
        // Replug: back to running.
        w.lock().unwrap().plug = Plug::Present;
        let mut back = false;
        for _ in 0..40 {
            if let Step::Frame(_) = sup.step(Duration::from_millis(1)) {
                back = true;
                break;
            }
        }
        assert!(back, "running again after replug");
        assert_eq!(*sup.state(), CameraState::Running);
    }

    #[test]
    fn open_by_name_and_refused_sizes() {
        let w = world(vec![Offered {
            fourcc: *b"MJPG",
            sizes: Some(vec![(4, 2)]),
        }]);
        w.lock().unwrap().plug = Plug::Present;
        let mut cam = V4l2Camera::new(Fake(w.clone()), settings("name:OAK-D", FormatPref::Auto));
        cam.open().unwrap();
        assert_eq!(
            w.lock().unwrap().opened.as_deref(),
            Some(std::path::Path::new("/dev/video2"))
        );
        assert!(
            cam.describe().contains("/dev/video2 MJPG 4x2@30"),
            "{}",
            cam.describe()
        );
        // A frame whose JPEG is another size than the stream's is skipped, not published.
        let mut j = Vec::new();
        image::codecs::jpeg::JpegEncoder::new(&mut j)
            .encode(&[9u8; 8 * 8 * 3], 8, 8, image::ExtendedColorType::Rgb8)
            .unwrap();
        w.lock().unwrap().frames.push_back(j);
        assert!(matches!(
            cam.next(),
            Ok(Grab::Skipped(super::super::Skip::Corrupt(_)))
        ));
        cam.close();

        let mut cam = V4l2Camera::new(Fake(w.clone()), settings("name:Logitech", FormatPref::Auto));
        assert!(matches!(cam.open(), Err(Fault::NoDevice(m)) if m.contains("OAK-D UVC")));

        w.lock().unwrap().adjusts_to = Some((8, 6));
        let mut cam = V4l2Camera::new(Fake(w.clone()), settings("/dev/video0", FormatPref::Auto));
        match cam.open() {
            Err(Fault::FormatRefused { offered, .. }) => {
                assert!(offered.contains("8x6"), "{offered}")
            }
            other => panic!("{other:?}"),
        }
        assert!(
            w.lock().unwrap().opened.is_none(),
            "a refused device is closed again"
        );
    }
}
