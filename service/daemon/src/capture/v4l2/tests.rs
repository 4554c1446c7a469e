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
