//! The encode stage: the latest render composited over the background, JPEG-encoded and
//! published to every client through the `watch` channel (placeholders are not counted in
//! the pipeline's figures).

use super::*;

/// Spawn the encode thread: take the latest render, encode, publish.
pub(super) fn spawn(sh: Arc<Shared>, input: Arc<Slot<Rendered>>) -> std::thread::JoinHandle<()> {
    std::thread::Builder::new()
        .name("encode".into())
        .spawn(move || {
            // Reused across frames: the JPEG input (RGBA composited over the background).
            let mut rgb: Vec<u8> = Vec::new();
            while !sh.stop.load(Ordering::Relaxed) {
                sh.beat(2);
                let Some(r) = input.take(Duration::from_millis(200)) else {
                    continue;
                };
                let bg = sh.live().background;
                let t = Instant::now();
                // JPEG has no alpha: composite over the background colour.
                composite_over(&r.rgba, bg, false, &mut rgb);
                let Some(jpeg) = encode_jpeg(&rgb, r.size) else {
                    continue;
                };
                let latency_ms = r.at.elapsed().as_secs_f64() * 1e3;
                // Placeholders are not frames of the pipeline: not in its figures.
                if !r.placeholder {
                    sh.stats[stage::ENCODE].record(t.elapsed().as_secs_f64() * 1e3);
                    sh.e2e.record(latency_ms);
                }
                sh.published.send_replace(Some(Arc::new(Published {
                    jpeg,
                    rgba: r.rgba,
                    size: r.size,
                    index: r.index,
                    latency_ms,
                    placeholder: r.placeholder,
                })));
            }
        })
        .expect("spawning the encode thread")
}

/// A published frame's JPEG (quality 85, chroma at full resolution, as the `image` crate's
/// encoder made them before) from its RGB pixels, `size x size`; `None` if the encoder
/// refuses them (a side over 65,535 pixels or a short buffer).
pub(super) fn encode_jpeg(rgb: &[u8], size: usize) -> Option<Vec<u8>> {
    let side = u16::try_from(size).ok()?;
    if rgb.len() < size * size * 3 {
        return None;
    }
    let mut jpeg = Vec::with_capacity(size * size / 4);
    let mut enc = jpeg_encoder::Encoder::new(&mut jpeg, 85);
    enc.set_sampling_factor(jpeg_encoder::SamplingFactor::R_4_4_4);
    enc.encode(
        &rgb[..size * size * 3],
        side,
        side,
        jpeg_encoder::ColorType::Rgb,
    )
    .ok()?;
    Some(jpeg)
}

#[cfg(test)]
mod tests {
    use super::encode_jpeg;

    /// PSNR (dB) of `jpeg` decoded against `rgb`, checking its size.
    fn psnr(jpeg: &[u8], rgb: &[u8], size: usize) -> f64 {
        let img = image::load_from_memory_with_format(jpeg, image::ImageFormat::Jpeg)
            .expect("decodes")
            .to_rgb8();
        assert_eq!((img.width() as usize, img.height() as usize), (size, size));
        let se: f64 = img
            .as_raw()
            .iter()
            .zip(rgb)
            .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
            .sum();
        10.0 * (255.0f64 * 255.0 / (se / rgb.len() as f64).max(1e-9)).log10()
    }

    /// A published frame decodes to its size and its pixels about as well as through the
    /// `image` crate's encoder at the same quality (which published them before: within
    /// 1.5 dB of its PSNR, and over 30 dB on frames of render size), on a smooth picture with
    /// hard edges, as renders have; a buffer shorter than the frame or a side JPEG cannot
    /// hold is refused, not encoded.
    #[test]
    fn published_jpeg_decodes_to_the_frame() {
        for size in [2usize, 17, 257, 512] {
            let rgb: Vec<u8> = (0..size * size)
                .flat_map(|p| {
                    let (x, y) = (p % size, p / size);
                    let edge = if x > size / 2 { 200 } else { 30 };
                    [(x * 255 / size) as u8, (y * 255 / size) as u8, edge]
                })
                .collect();
            let ours = psnr(&encode_jpeg(&rgb, size).expect("encodes"), &rgb, size);
            let mut theirs = Vec::new();
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut theirs, 85)
                .encode(
                    &rgb,
                    size as u32,
                    size as u32,
                    image::ExtendedColorType::Rgb8,
                )
                .expect("encodes");
            let theirs = psnr(&theirs, &rgb, size);
            assert!(
                ours > theirs - 1.5,
                "size {size}: {ours:.1} vs {theirs:.1} dB"
            );
            assert!(size < 257 || ours > 30.0, "size {size}: PSNR {ours:.1} dB");
        }
        assert!(encode_jpeg(&[0u8; 10], 4).is_none());
        assert!(encode_jpeg(&[], 70_000).is_none());
    }
}
