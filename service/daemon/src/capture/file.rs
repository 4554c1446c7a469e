//! The `file` backend: replays a recorded session, either an MJPEG file (concatenated JPEG
//! frames, as `ffmpeg -f mjpeg` or a saved `/stream.mjpg` writes them) or a folder of images
//! (sorted by name), paced at a configured fps. Corrupt or truncated frames are skipped and
//! counted; the stream goes on.

use super::{Camera, Fault, Frame, Grab, Skip, decode};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Largest MJPEG file replayed from memory.
const MAX_FILE: u64 = 2 << 30;
/// Largest image file in a folder.
const MAX_IMAGE_FILE: u64 = 64 << 20;
/// Shortest frame of an MJPEG stream: a `FF D8 FF` closer than this to the previous one is
/// part of that frame (no JPEG is this small), so the index holds at most one entry per
/// this many bytes whatever the file contains.
pub const MIN_FRAME_BYTES: usize = 128;
/// Most frames indexed in one MJPEG file (9.7 hours at 30 fps; an index of 16 MB).
pub const MAX_FRAMES: usize = 1 << 20;
/// Image files picked up in a folder (all decoded by the `image` crate).
const IMAGE_EXTS: [&str; 6] = ["jpg", "jpeg", "png", "ppm", "pnm", "bmp"];

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
/// (`FF D8 FF`) at least [`MIN_FRAME_BYTES`] after the previous start and runs to the
/// next one. `None` when there would be more than `max_frames`.
pub fn split_mjpeg(data: &[u8], max_frames: usize) -> Option<Vec<(usize, usize)>> {
    let mut frames: Vec<(usize, usize)> = Vec::new();
    let mut i = 0;
    while i + 3 <= data.len() {
        if data[i..i + 3] == [0xFF, 0xD8, 0xFF] {
            if let Some(last) = frames.last_mut() {
                last.1 = i;
            }
            if frames.len() == max_frames {
                return None;
            }
            frames.push((i, data.len()));
            i += MIN_FRAME_BYTES;
        } else {
            i += 1;
        }
    }
    Some(frames)
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
        // Regular files only (symlinks followed): a FIFO or device named like an image is
        // not a frame (and is checked again at read time, without blocking).
        .filter(|p| std::fs::metadata(p).is_ok_and(|m| m.is_file()))
        .collect();
    files.sort();
    Ok(files)
}

fn decode_image(p: &Path) -> Result<(Vec<u8>, usize, usize), Skip> {
    let bytes = volcap_sim::files::read_regular(p, MAX_IMAGE_FILE)
        .map_err(|e| Skip::Corrupt(format!("{}: {e}", p.display())))?;
    let is_jpeg = bytes.starts_with(&[0xFF, 0xD8]);
    if is_jpeg {
        return decode::mjpeg(&bytes).map_err(|s| match s {
            Skip::Truncated(m) => Skip::Truncated(format!("{}: {m}", p.display())),
            Skip::Corrupt(m) => Skip::Corrupt(format!("{}: {m}", p.display())),
        });
    }
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(&bytes))
            .with_guessed_format()
            .map_err(|e| Skip::Corrupt(format!("{}: {e}", p.display())))
    };
    let (w, h) = reader()?
        .into_dimensions()
        .map_err(|e| Skip::Corrupt(format!("{}: {e}", p.display())))?;
    decode::check_size(w as u64, h as u64).map_err(|s| match s {
        Skip::Truncated(m) | Skip::Corrupt(m) => Skip::Corrupt(format!("{}: {m}", p.display())),
    })?;
    let mut r = reader()?;
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
            // A regular file only (a device such as /dev/zero would be read without end),
            // read up to the limit whatever its size claims.
            let data = volcap_sim::files::read_regular(&self.path, MAX_FILE)
                .map_err(|e| Fault::Failed(format!("{}: {e}", self.path.display())))?;
            let frames = split_mjpeg(&data, MAX_FRAMES).ok_or_else(|| Fault::FormatRefused {
                wanted: format!("an MJPEG file of at most {MAX_FRAMES} frames"),
                offered: format!(
                    "{} bytes with more JPEG start markers than that",
                    data.len()
                ),
            })?;
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

    /// Hardening #7: 30 MB of repeated `FF D8 FF` built a 286 MB frame index.
    #[test]
    fn the_mjpeg_index_is_bounded_by_bytes_and_frames() {
        let junk: Vec<u8> = [0xFF, 0xD8, 0xFF].repeat(10_000_000);
        let frames = split_mjpeg(&junk, MAX_FRAMES).unwrap();
        let index_bytes = frames.len() * std::mem::size_of::<(usize, usize)>();
        assert!(
            frames.len() <= junk.len() / MIN_FRAME_BYTES + 1,
            "{}",
            frames.len()
        );
        assert!(
            index_bytes < 4 << 20,
            "index of {index_bytes} bytes for 30 MB"
        );
        assert!(
            split_mjpeg(&junk, 1000).is_none(),
            "more frames than allowed: refused"
        );
        // Real frames are unaffected.
        let good = jpeg(24, 16, 200);
        let two = [good.clone(), good.clone()].concat();
        assert_eq!(
            split_mjpeg(&two, MAX_FRAMES).unwrap(),
            vec![(0, good.len()), (good.len(), 2 * good.len())]
        );
    }

    /// Hardening #6 and #11: a FIFO in an image folder blocked the capture thread forever,
    /// `/dev/zero` as the MJPEG path grew memory by 1 GB/s, and `.ppm`/`.bmp` files were
    /// picked up but never decoded.
    #[test]
    fn fifos_devices_are_refused_and_ppm_bmp_decode() {
        let d = tmp("special");
        std::fs::write(d.join("a.jpg"), jpeg(8, 8, 200)).unwrap();
        let img = image::RgbImage::from_pixel(6, 4, image::Rgb([10, 250, 30]));
        img.save(d.join("b.ppm")).unwrap();
        img.save(d.join("c.bmp")).unwrap();
        let fifo = d.join("d.jpg");
        let fifo_made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .is_ok_and(|s| s.success());
        let mut cam = FileCamera::new(d.clone(), 1000.0, false);
        cam.open().unwrap();
        assert_eq!(cam.frame_count(), 3, "the FIFO is not listed");
        let t = Instant::now();
        let (ok, bad, end) = drain(&mut cam);
        assert!(t.elapsed() < Duration::from_secs(2));
        assert_eq!(ok.len(), 3, "jpg, ppm and bmp decode: {bad:?}");
        assert!(matches!(end, Fault::Ended(_)));
        if fifo_made {
            // Swapped in after the listing: refused at read time, without blocking.
            let e = decode_image(&fifo).unwrap_err();
            assert!(
                matches!(&e, Skip::Corrupt(m) if m.contains("FIFO")),
                "{e:?}"
            );
        }
        let mut cam = FileCamera::new("/dev/zero".into(), 10.0, false);
        let t = Instant::now();
        let e = cam.open().unwrap_err();
        assert!(t.elapsed() < Duration::from_secs(1));
        assert!(format!("{e}").contains("device"), "{e}");
        let _ = std::fs::remove_dir_all(d);
    }
}
