//! Frame decoders: MJPEG (one JPEG per frame) and packed YUYV 4:2:2, both to RGB8.

use super::Skip;

/// Largest frame side we decode; bigger headers are refused before any allocation.
pub use volcap_engine::model::preprocess::MAX_FRAME_SIDE as MAX_SIDE;

/// A frame's size against the limits shared with `volcap reconstruct` (side and pixels in
/// all): a larger frame is `Corrupt`, refused before it is decoded.
pub fn check_size(w: u64, h: u64) -> Result<(), Skip> {
    volcap_engine::model::preprocess::check_frame_size(w, h).map_err(Skip::Corrupt)
}

/// Decode one MJPEG frame. A frame without its end-of-image marker is `Truncated` (drivers
/// may pad with zero bytes after it, which is allowed); one that does not decode is `Corrupt`.
pub fn mjpeg(buf: &[u8]) -> Result<(Vec<u8>, usize, usize), Skip> {
    if buf.len() < 4 || buf[0] != 0xFF || buf[1] != 0xD8 {
        return Err(Skip::Corrupt(format!(
            "{} bytes without a JPEG start-of-image marker",
            buf.len()
        )));
    }
    let end = buf.len() - buf.iter().rev().take_while(|&&b| b == 0).count();
    if end < 4 || buf[end - 2] != 0xFF || buf[end - 1] != 0xD9 {
        return Err(Skip::Truncated(format!(
            "{} bytes without a JPEG end-of-image marker",
            buf.len()
        )));
    }
    let reader = || {
        image::ImageReader::with_format(std::io::Cursor::new(&buf[..end]), image::ImageFormat::Jpeg)
    };
    let (w, h) = reader()
        .into_dimensions()
        .map_err(|e| Skip::Corrupt(format!("JPEG header does not decode: {e}")))?;
    check_size(w as u64, h as u64)?;
    let mut reader = reader();
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_SIDE);
    limits.max_image_height = Some(MAX_SIDE);
    limits.max_alloc = Some(512 << 20);
    reader.limits(limits);
    let img = reader
        .decode()
        .map_err(|e| Skip::Corrupt(format!("JPEG does not decode: {e}")))?
        .to_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w == 0 || h == 0 {
        return Err(Skip::Corrupt("JPEG of zero size".into()));
    }
    Ok((img.into_raw(), w, h))
}

/// BT.601 limited-range YUV to RGB, integer arithmetic (the usual 8-bit fixed point).
#[inline]
pub fn yuv_to_rgb(y: u8, u: u8, v: u8) -> [u8; 3] {
    let c = 298 * (y as i32 - 16);
    let d = u as i32 - 128;
    let e = v as i32 - 128;
    let clip = |x: i32| ((x + 128) >> 8).clamp(0, 255) as u8;
    [
        clip(c + 409 * e),
        clip(c - 100 * d - 208 * e),
        clip(c + 516 * d),
    ]
}

/// Packed YUYV (Y0 U Y1 V per two pixels) to RGB8. The buffer must hold exactly
/// `width * height * 2` bytes (drivers may pad after that); a short buffer is `Truncated`.
pub fn yuyv(buf: &[u8], width: usize, height: usize) -> Result<Vec<u8>, Skip> {
    if width == 0 || height == 0 || !width.is_multiple_of(2) {
        return Err(Skip::Corrupt(format!(
            "YUYV needs an even, non-zero width; got {width}x{height}"
        )));
    }
    check_size(width as u64, height as u64)?;
    let need = width * height * 2;
    if buf.len() < need {
        return Err(Skip::Truncated(format!(
            "YUYV {width}x{height} needs {need} bytes, got {}",
            buf.len()
        )));
    }
    let mut out = Vec::with_capacity(width * height * 3);
    for q in buf[..need].chunks_exact(4) {
        out.extend_from_slice(&yuv_to_rgb(q[0], q[1], q[3]));
        out.extend_from_slice(&yuv_to_rgb(q[2], q[1], q[3]));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f64 reference of BT.601 limited range.
    fn reference(y: u8, u: u8, v: u8) -> [f64; 3] {
        let (y, u, v) = (y as f64 - 16.0, u as f64 - 128.0, v as f64 - 128.0);
        let k = 255.0 / 219.0;
        [
            k * y + 1.402 * (255.0 / 224.0) * v,
            k * y - 0.344136 * (255.0 / 224.0) * u - 0.714136 * (255.0 / 224.0) * v,
            k * y + 1.772 * (255.0 / 224.0) * u,
        ]
        .map(|c| c.clamp(0.0, 255.0))
    }

    #[test]
    fn yuyv_known_vectors() {
        // (Y, U, V) of BT.601 limited-range black, white, primaries, 75% grey.
        let cases: [([u8; 3], [u8; 3]); 6] = [
            ([16, 128, 128], [0, 0, 0]),
            ([235, 128, 128], [255, 255, 255]),
            ([81, 90, 240], [255, 0, 0]),
            ([145, 54, 34], [0, 255, 0]),
            ([41, 240, 110], [0, 0, 255]),
            ([180, 128, 128], [191, 191, 191]),
        ];
        for ([y, u, v], rgb) in cases {
            let got = yuv_to_rgb(y, u, v);
            for c in 0..3 {
                assert!(
                    (got[c] as i32 - rgb[c] as i32).abs() <= 2,
                    "YUV {y},{u},{v}: got {got:?}, want {rgb:?}"
                );
            }
        }
        // Two pixels sharing chroma: Y0 U Y1 V.
        let px = yuyv(&[16, 128, 235, 128], 2, 1).unwrap();
        assert_eq!(px, [0, 0, 0, 255, 255, 255]);
    }

    #[test]
    fn yuyv_matches_the_f64_reference_everywhere() {
        let mut worst = 0.0f64;
        for y in (0..=255u16).step_by(3) {
            for u in (0..=255u16).step_by(5) {
                for v in (0..=255u16).step_by(5) {
                    let got = yuv_to_rgb(y as u8, u as u8, v as u8);
                    let want = reference(y as u8, u as u8, v as u8);
                    for c in 0..3 {
                        worst = worst.max((got[c] as f64 - want[c]).abs());
                    }
                }
            }
        }
        println!("YUYV: worst channel error against the f64 reference {worst:.3}");
        assert!(worst <= 1.5, "worst channel error {worst}");
    }

    #[test]
    fn yuyv_rejects_short_and_odd_buffers() {
        assert!(matches!(yuyv(&[0; 7], 2, 2), Err(Skip::Truncated(_))));
        assert!(matches!(yuyv(&[0; 6], 3, 1), Err(Skip::Corrupt(_))));
        // Padding after the image is allowed.
        assert_eq!(yuyv(&[16, 128, 16, 128, 9, 9], 2, 1).unwrap().len(), 6);
    }

    fn jpeg(w: u32, h: u32) -> Vec<u8> {
        let img =
            image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 8) as u8, (y * 8) as u8, 200]));
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .encode_image(&img)
            .unwrap();
        out
    }

    #[test]
    fn mjpeg_decodes_and_classifies_bad_frames() {
        let j = jpeg(32, 16);
        let (rgb, w, h) = mjpeg(&j).unwrap();
        assert_eq!((w, h, rgb.len()), (32, 16, 32 * 16 * 3));
        assert!((rgb[3 * 31] as i32 - 248).abs() < 12, "{}", rgb[3 * 31]);
        // Driver padding after EOI is fine.
        let mut padded = j.clone();
        padded.extend_from_slice(&[0; 64]);
        assert!(mjpeg(&padded).is_ok());
        // Cut mid-scan: truncated.
        assert!(matches!(mjpeg(&j[..j.len() / 2]), Err(Skip::Truncated(_))));
        // Not a JPEG at all.
        assert!(matches!(mjpeg(b"hello world"), Err(Skip::Corrupt(_))));
        // Header destroyed (SOF/DQT region zeroed) but markers kept: corrupt.
        let mut broken = j.clone();
        for b in &mut broken[2..j.len() - 2] {
            *b = 0x55;
        }
        assert!(matches!(mjpeg(&broken), Err(Skip::Corrupt(_))));
        // A header claiming a huge image is refused by the limits, not allocated.
        let mut huge = j.clone();
        let sof = huge.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
        huge[sof + 5..sof + 9].copy_from_slice(&[0xFF, 0xFF, 0xFF, 0xFF]);
        assert!(mjpeg(&huge).is_err());
    }
}
