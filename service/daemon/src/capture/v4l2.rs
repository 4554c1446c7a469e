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

pub use crate::config::FormatPref;

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
mod tests;
