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
                let mut jpeg = Vec::new();
                let ok = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 85)
                    .encode(
                        &rgb,
                        r.size as u32,
                        r.size as u32,
                        image::ExtendedColorType::Rgb8,
                    )
                    .is_ok();
                if !ok {
                    continue;
                }
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
