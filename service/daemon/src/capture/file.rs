//! The `file` backend: replays a recorded session, either an MJPEG file (concatenated JPEG
//! frames, as `ffmpeg -f mjpeg` or a saved `/stream.mjpg` writes them) or a folder of images
//! (sorted by name), paced at a configured fps. Corrupt or truncated frames are skipped and
//! counted; the stream goes on.

use super::{Camera, Fault, Frame, Grab, Skip, decode};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Largest MJPEG file replayed from memory.
const MAX_FILE: u64 = 2 << 30;
const IMAGE_EXTS: [&str; 5] = ["jpg", "jpeg", "png", "ppm", "bmp"];

enum Source {
    Mjpeg {
        data: Vec<u8>,
        frames: Vec<(usize, usize)>,
    },
    Folder(Vec<PathBuf>),
}

pub struct FileCamera {
    path: PathBuf,
    period: Duration,
    looping: bool,
    source: Option<Source>,
    pos: usize,
    seq: u64,
    next_due: Option<Instant>,
}

impl FileCamera {
    pub fn new(path: PathBuf, fps: f32, looping: bool) -> Self {
        Self {
            path,
            period: Duration::from_secs_f64(1.0 / fps.max(0.1) as f64),
            looping,
            source: None,
            pos: 0,
            seq: 0,
            next_due: None,
        }
    }

    /// Number of frames (including ones that will turn out bad) once opened.
    pub fn frame_count(&self) -> usize {
        match &self.source {
            Some(Source::Mjpeg { frames, .. }) => frames.len(),
            Some(Source::Folder(f)) => f.len(),
            None => 0,
        }
    }
}

/// Split an MJPEG byte stream into frames: each frame starts at a JPEG start-of-image
/// (`FF D8 FF`) and runs to the next one.
pub fn split_mjpeg(data: &[u8]) -> Vec<(usize, usize)> {
    let starts: Vec<usize> = data
        .windows(3)
        .enumerate()
        .filter(|(_, w)| *w == [0xFF, 0xD8, 0xFF])
        .map(|(i, _)| i)
        .collect();
    starts
        .iter()
        .enumerate()
        .map(|(k, &s)| (s, starts.get(k + 1).copied().unwrap_or(data.len())))
        .collect()
}

/// Cut whatever follows a frame's last end-of-image marker (multipart headers, padding).
fn trim_to_eoi(seg: &[u8]) -> &[u8] {
    match seg.windows(2).rposition(|w| w == [0xFF, 0xD9]) {
        Some(i) => &seg[..i + 2],
        None => seg,
    }
}

fn list_images(dir: &Path) -> Result<Vec<PathBuf>, Fault> {
    let rd =
        std::fs::read_dir(dir).map_err(|e| Fault::NoDevice(format!("{}: {e}", dir.display())))?;
    let mut files: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| IMAGE_EXTS.contains(&e.to_ascii_lowercase().as_str()))
        })
        .collect();
    files.sort();
    Ok(files)
}

fn decode_image(p: &Path) -> Result<(Vec<u8>, usize, usize), Skip> {
    let bytes = std::fs::read(p).map_err(|e| Skip::Corrupt(format!("{}: {e}", p.display())))?;
    let is_jpeg = bytes.starts_with(&[0xFF, 0xD8]);
    if is_jpeg {
        return decode::mjpeg(&bytes).map_err(|s| match s {
            Skip::Truncated(m) => Skip::Truncated(format!("{}: {m}", p.display())),
            Skip::Corrupt(m) => Skip::Corrupt(format!("{}: {m}", p.display())),
        });
    }
    let mut r = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| Skip::Corrupt(format!("{}: {e}", p.display())))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(decode::MAX_SIDE);
    limits.max_image_height = Some(decode::MAX_SIDE);
    r.limits(limits);
    let img = r
        .decode()
        .map_err(|e| Skip::Corrupt(format!("{}: {e}", p.display())))?
        .to_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    Ok((img.into_raw(), w, h))
}

impl Camera for FileCamera {
    fn describe(&self) -> String {
        format!("file:{}", self.path.display())
    }

    fn open(&mut self) -> Result<(), Fault> {
        let meta = std::fs::metadata(&self.path)
            .map_err(|e| Fault::NoDevice(format!("{}: {e}", self.path.display())))?;
        let source = if meta.is_dir() {
            let files = list_images(&self.path)?;
            if files.is_empty() {
                return Err(Fault::NoDevice(format!(
                    "{}: no images ({}) in the folder",
                    self.path.display(),
                    IMAGE_EXTS.join(", ")
                )));
            }
            Source::Folder(files)
        } else {
            if meta.len() > MAX_FILE {
                return Err(Fault::Failed(format!(
                    "{}: {} bytes is more than the {} bytes replayed from memory; split the recording",
                    self.path.display(),
                    meta.len(),
                    MAX_FILE
                )));
            }
            let data = std::fs::read(&self.path)
                .map_err(|e| Fault::NoDevice(format!("{}: {e}", self.path.display())))?;
            let frames = split_mjpeg(&data);
            if frames.is_empty() {
                return Err(Fault::FormatRefused {
                    wanted: "MJPEG (concatenated JPEG frames)".into(),
                    offered: format!("{} bytes with no JPEG frame", data.len()),
                });
            }
            Source::Mjpeg { data, frames }
        };
        self.source = Some(source);
        if self.pos >= self.frame_count() {
            self.pos = 0;
        }
        Ok(())
    }

    fn next(&mut self) -> Result<Grab, Fault> {
        let Some(src) = &self.source else {
            return Err(Fault::Failed("read before open".into()));
        };
        let n = match src {
            Source::Mjpeg { frames, .. } => frames.len(),
            Source::Folder(f) => f.len(),
        };
        if self.pos >= n {
            if !self.looping {
                return Err(Fault::Ended(format!(
                    "{} ({n} frames)",
                    self.path.display()
                )));
            }
            self.pos = 0;
        }
        let due = *self.next_due.get_or_insert_with(Instant::now);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        self.next_due = Some(due.max(now - self.period) + self.period);
        let at = Instant::now();
        let k = self.pos;
        self.pos += 1;
        let decoded = match src {
            Source::Mjpeg { data, frames } => {
                let (a, b) = frames[k];
                decode::mjpeg(trim_to_eoi(&data[a..b])).map_err(|s| match s {
                    Skip::Truncated(m) => Skip::Truncated(format!("frame {k}: {m}")),
                    Skip::Corrupt(m) => Skip::Corrupt(format!("frame {k}: {m}")),
                })
            }
            Source::Folder(files) => decode_image(&files[k]),
        };
        match decoded {
            Ok((rgb, width, height)) => {
                self.seq += 1;
                Ok(Grab::Frame(Frame {
                    rgb,
                    width,
                    height,
                    seq: self.seq - 1,
                    at,
                    truth: None,
                }))
            }
            Err(s) => Ok(Grab::Skipped(s)),
        }
    }

    fn close(&mut self) {
        self.source = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jpeg(w: u32, h: u32, shade: u8) -> Vec<u8> {
        let img = image::RgbImage::from_pixel(w, h, image::Rgb([shade, 90, 40]));
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .encode_image(&img)
            .unwrap();
        out
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("volcapd-file-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn drain(cam: &mut FileCamera) -> (Vec<u64>, Vec<Skip>, Fault) {
        let (mut ok, mut bad) = (Vec::new(), Vec::new());
        loop {
            match cam.next() {
                Ok(Grab::Frame(f)) => ok.push(f.seq),
                Ok(Grab::Skipped(s)) => bad.push(s),
                Err(e) => return (ok, bad, e),
            }
        }
    }

    #[test]
    fn corrupt_and_truncated_frames_are_counted_and_skipped() {
        let d = tmp("mjpeg");
        let good = jpeg(24, 16, 200);
        let mut data = Vec::new();
        data.extend_from_slice(&good); // 0 good
        data.extend_from_slice(&good[..good.len() * 2 / 3]); // 1 truncated mid-scan
        data.extend_from_slice(&good); // 2 good
        let mut corrupt = good.clone(); // 3 corrupt header, markers intact
        for b in &mut corrupt[3..good.len() - 2] {
            if *b != 0xFF {
                *b = 0x13;
            }
        }
        data.extend_from_slice(&corrupt);
        // 4 good, followed by multipart headers as a saved /stream.mjpg has them.
        data.extend_from_slice(&good);
        data.extend_from_slice(b"\r\n--volcapframe\r\nContent-Type: image/jpeg\r\n\r\n");
        data.extend_from_slice(&good[..40]); // 5 truncated right after the header
        let p = d.join("rec.mjpg");
        std::fs::write(&p, &data).unwrap();
        let mut cam = FileCamera::new(p, 1000.0, false);
        cam.open().unwrap();
        assert_eq!(cam.frame_count(), 6);
        let (ok, bad, end) = drain(&mut cam);
        assert_eq!(
            ok,
            [0, 1, 2],
            "good frames get consecutive sequence numbers"
        );
        assert_eq!(bad.len(), 3, "{bad:?}");
        assert!(
            matches!(&bad[0], Skip::Truncated(m) if m.contains("frame 1")),
            "{bad:?}"
        );
        assert!(
            matches!(&bad[1], Skip::Corrupt(m) if m.contains("frame 3")),
            "{bad:?}"
        );
        assert!(
            matches!(&bad[2], Skip::Truncated(m) if m.contains("frame 5")),
            "{bad:?}"
        );
        assert!(matches!(end, Fault::Ended(_)));
        let _ = std::fs::remove_dir_all(d);
    }

    #[test]
    fn image_folder_replays_in_name_order_and_loops() {
        let d = tmp("folder");
        for (i, shade) in [(2, 30u8), (0, 230), (1, 130)] {
            std::fs::write(d.join(format!("f{i}.jpg")), jpeg(8, 8, shade)).unwrap();
        }
        std::fs::write(d.join("f3.png"), b"not a png").unwrap();
        std::fs::write(d.join("notes.txt"), b"ignored").unwrap();
        let mut cam = FileCamera::new(d.clone(), 1000.0, true);
        cam.open().unwrap();
        assert_eq!(cam.frame_count(), 4);
        let mut shades = Vec::new();
        let mut skipped = 0;
        while shades.len() < 6 {
            match cam.next().unwrap() {
                Grab::Frame(f) => shades.push(f.rgb[0]),
                Grab::Skipped(Skip::Corrupt(m)) => {
                    assert!(m.contains("f3.png"), "{m}");
                    skipped += 1;
                }
                Grab::Skipped(s) => panic!("{s:?}"),
            }
        }
        assert_eq!(skipped, 1);
        let near = |a: u8, b: u8| (a as i32 - b as i32).abs() < 8;
        for (got, want) in shades.iter().zip([230, 130, 30, 230, 130, 30]) {
            assert!(near(*got, want), "{shades:?}");
        }
        let _ = std::fs::remove_dir_all(d);
    }

    #[test]
    fn missing_or_empty_sources_are_typed_faults() {
        let mut cam = FileCamera::new("/nonexistent/rec.mjpg".into(), 10.0, false);
        assert!(
            matches!(cam.open(), Err(Fault::NoDevice(m)) if m.contains("/nonexistent/rec.mjpg"))
        );
        let d = tmp("empty");
        let mut cam = FileCamera::new(d.clone(), 10.0, false);
        assert!(matches!(cam.open(), Err(Fault::NoDevice(m)) if m.contains("no images")));
        let p = d.join("x.mjpg");
        std::fs::write(&p, b"plain text, no frames").unwrap();
        let mut cam = FileCamera::new(p, 10.0, false);
        assert!(matches!(cam.open(), Err(Fault::FormatRefused { .. })));
        let _ = std::fs::remove_dir_all(d);
    }
}
