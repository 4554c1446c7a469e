//! What H.264 over RTSP costs and saves against the MJPEG stream, on the daemon's own
//! renders (the simulator's front-walk scene, oracle field, published at 257 and 513 px):
//! encode ms per frame, bitrate against MJPEG at equal quality (PSNR of the decoded frame
//! against the raw render, both codecs 4:2:0), and glass-to-glass latency on loopback (a
//! frame index drawn into the frame when it is published, read back by a decoding client:
//! GStreamer's `rtspsrc ! avdec_h264` for RTSP, an HTTP client decoding `/stream.mjpg`).
//!
//! `cargo run --release -p volcapd --features rtsp --example rtsp_bench -- [--frames N]
//! [--out docs/bench/rtsp.md]`

use gst::prelude::*;
use std::io::{Read, Write};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use volcapd::config::Config;
use volcapd::pipeline::{Published, Shared};

const SIZES: [usize; 2] = [257, 513];
const BITRATES: [u32; 5] = [250, 500, 1000, 2000, 4000];
const FPS: u32 = 30;

fn config(display: usize, extra: &str) -> Config {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = format!(
        "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nresolution = 129\ndisplay_size = {display}\nfield = \"oracle\"\n[dbus]\nbus = \"none\"\n{extra}",
        root.join("tests/scenes/front-walk.toml").display()
    );
    Config::parse(&text, std::path::Path::new("rtsp_bench.toml")).expect("config")
}

/// `n` consecutive renders (RGB over the background) from the daemon's pipeline.
fn renders(display: usize, n: usize) -> Vec<Vec<u8>> {
    let cfg = config(display, "");
    let (factory, source) = volcapd::capture::factory(&cfg).expect("camera");
    let (tx, _rx) = tokio::sync::watch::channel(None);
    let shared = Arc::new(Shared::new(&cfg, source, tx));
    let threads = volcapd::pipeline::start(&cfg, factory, shared.clone(), None);
    let mut rx = shared.published.subscribe();
    let mut out = Vec::new();
    let bg = cfg.render.background;
    let bar = indicatif::ProgressBar::new(n as u64).with_message(format!("renders {display} px"));
    while out.len() < n {
        if !rx.has_changed().unwrap_or(false) {
            std::thread::sleep(Duration::from_millis(2));
            continue;
        }
        let f = rx.borrow_and_update().clone();
        if let Some(f) = f.filter(|f| !f.placeholder) {
            let mut rgb = Vec::new();
            volcapd::pipeline::composite_over(&f.rgba, bg, false, &mut rgb);
            out.push(rgb);
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    shared.stop.store(true, Ordering::Relaxed);
    for t in threads {
        let _ = t.join();
    }
    out
}

fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (255.0f64 * 255.0 / mse.max(1e-12)).log10()
}

fn jpeg(rgb: &[u8], size: usize) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 85)
        .encode(
            rgb,
            size as u32,
            size as u32,
            image::ExtendedColorType::Rgb8,
        )
        .expect("jpeg");
    out
}

struct Row {
    codec: String,
    size: usize,
    kbps: f64,
    psnr: f64,
    ms_p50: f64,
    ms_p95: f64,
}

fn pct(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// A pipeline from `launch` with an `appsrc` named src and an `appsink` named sink, playing.
fn app_pipeline(launch: &str) -> (gst::Pipeline, gst_app::AppSrc, gst_app::AppSink) {
    let p = gst::parse::launch(launch)
        .unwrap_or_else(|e| panic!("{launch}: {e}"))
        .downcast::<gst::Pipeline>()
        .unwrap();
    let src = p
        .by_name("src")
        .unwrap()
        .downcast::<gst_app::AppSrc>()
        .unwrap();
    let sink = p
        .by_name("sink")
        .unwrap()
        .downcast::<gst_app::AppSink>()
        .unwrap();
    p.set_state(gst::State::Playing).unwrap();
    (p, src, sink)
}

/// Frame `i` (RGB) as the daemon feeds its encoder: RGBx, stamped at 30 fps.
fn rgbx_buffer(rgb: &[u8], i: usize) -> gst::Buffer {
    let x: Vec<u8> = rgb
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    let mut b = gst::Buffer::from_slice(x);
    b.get_mut().unwrap().set_pts(gst::ClockTime::from_nseconds(
        i as u64 * 1_000_000_000 / FPS as u64,
    ));
    b
}

/// GStreamer's RGB rows (padded to 4 bytes) as tight `size x size` RGB.
fn unpadded_rgb(b: &[u8], size: usize) -> Vec<u8> {
    let stride = b.len() / size;
    (0..size)
        .flat_map(|y| b[y * stride..y * stride + size * 3].to_vec())
        .collect()
}

/// PSNR of the RGB -> I420 (limited range, as the encoders take it) -> RGB round trip
/// alone: the ceiling of any H.264 stream's PSNR against the RGB render.
fn yuv_ceiling(frames: &[Vec<u8>], size: usize) -> f64 {
    let (p, src, sink) = app_pipeline(&format!(
        "appsrc name=src format=time caps=video/x-raw,format=RGBx,width={size},height={size},framerate={FPS}/1 \
         ! videoconvert ! video/x-raw,format=I420 ! videoconvert ! video/x-raw,format=RGB \
         ! appsink name=sink sync=false"
    ));
    let mut sum = 0.0;
    for (i, f) in frames.iter().enumerate() {
        src.push_buffer(rgbx_buffer(f, i)).unwrap();
        let s = sink
            .try_pull_sample(gst::ClockTime::from_seconds(5))
            .expect("a frame");
        let b = s.buffer().unwrap().map_readable().unwrap();
        sum += psnr(f, &unpadded_rgb(&b, size));
    }
    p.set_state(gst::State::Null).unwrap();
    sum / frames.len() as f64
}

/// Encode `frames` with `enc_launch`, decode them back: (kbit/s at 30 fps, mean PSNR, ms).
fn h264(frames: &[Vec<u8>], size: usize, enc_launch: &str) -> (f64, f64, Vec<f64>) {
    let (enc, src, sink) = app_pipeline(&format!(
        "appsrc name=src format=time caps=video/x-raw,format=RGBx,width={size},height={size},framerate={FPS}/1 \
         ! videoconvert ! {enc_launch} ! appsink name=sink sync=false"
    ));
    let mut aus = Vec::new();
    let mut ms = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let b = rgbx_buffer(f, i);
        let t = Instant::now();
        src.push_buffer(b).unwrap();
        // A frame the encoder's rate control skipped gives no access unit.
        if let Some(s) = sink.try_pull_sample(gst::ClockTime::from_mseconds(500)) {
            ms.push(t.elapsed().as_secs_f64() * 1e3);
            aus.push(s.buffer_owned().unwrap());
        }
    }
    let _ = src.end_of_stream();
    enc.set_state(gst::State::Null).unwrap();
    let bytes: usize = aus.iter().map(|b| b.size()).sum();
    let kbps = bytes as f64 * 8.0 / 1000.0 / (frames.len() as f64 / FPS as f64);
    // Decode.
    let (dec, src, sink) = app_pipeline(
        "appsrc name=src format=time caps=video/x-h264,stream-format=byte-stream,alignment=au \
         ! h264parse ! avdec_h264 ! videoconvert ! video/x-raw,format=RGB ! appsink name=sink sync=false",
    );
    for b in aus {
        src.push_buffer(b).unwrap();
    }
    let _ = src.end_of_stream();
    // Decoded frames by index (from their timestamps); a skipped frame shows the last one.
    // (x264 adds 1000 h to every timestamp: indices count from the first frame's.)
    let mut decoded: Vec<Option<Vec<u8>>> = vec![None; frames.len()];
    let mut first = None;
    while let Some(s) = sink.try_pull_sample(gst::ClockTime::from_seconds(2)) {
        let buf = s.buffer().unwrap();
        let pts = buf.pts().unwrap().nseconds();
        let t0 = *first.get_or_insert(pts);
        let i = ((pts - t0) as f64 * FPS as f64 / 1e9).round() as usize;
        let b = buf.map_readable().unwrap();
        if let Some(d) = decoded.get_mut(i) {
            *d = Some(unpadded_rgb(&b, size));
        }
    }
    dec.set_state(gst::State::Null).unwrap();
    let mut p = Vec::new();
    let mut last: Option<&Vec<u8>> = None;
    for (f, d) in frames.iter().zip(&decoded) {
        last = d.as_ref().or(last);
        if let Some(l) = last {
            p.push(psnr(f, l));
        }
    }
    assert!(
        p.len() + 2 >= frames.len(),
        "decoded {} of {}",
        p.len(),
        frames.len()
    );
    (kbps, p.iter().sum::<f64>() / p.len() as f64, ms)
}

const CELL: usize = 16;
const BITS: usize = 12;

/// Draw `index` as 12 black/white cells of 16 px on the top row.
fn stamp(rgb: &mut [u8], size: usize, index: u64) {
    for bit in 0..BITS {
        let v = if index >> bit & 1 == 1 { 255 } else { 0 };
        for y in 0..CELL {
            for x in bit * CELL..(bit + 1) * CELL {
                let o = (y * size + x) * 3;
                rgb[o..o + 3].fill(v);
            }
        }
    }
}

fn read_stamp(rgb: &[u8], size: usize, stride: usize) -> u64 {
    let _ = size;
    (0..BITS)
        .map(|bit| {
            let o = (CELL / 2) * stride + (bit * CELL + CELL / 2) * 3;
            u64::from(rgb[o] > 128) << bit
        })
        .sum()
}

/// Glass-to-glass on loopback: frames published at 30 fps by this process into a daemon's
/// HTTP and RTSP servers (in this process too, one clock); (RTSP ms, MJPEG ms) per frame.
fn latency(frames: &[Vec<u8>], size: usize, secs: u64) -> (Vec<f64>, Vec<f64>) {
    let cfg = config(size, "[rtsp]\nbind = \"127.0.0.1:0\"\ngop = 30\n");
    let (tx, _rx) = tokio::sync::watch::channel(None);
    let shared = Arc::new(Shared::new(&cfg, "bench".into(), tx));
    let status = Arc::new(volcapd::rtsp::Status::new(&cfg));
    let mut app = volcapd::http::App::new(shared.clone(), 16, None, &[], true);
    app.rtsp = status.clone();
    let app = Arc::new(app);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let http = listener.local_addr().unwrap();
    let limits = volcapd::http::Limits::new(&cfg.http);
    rt.spawn(volcapd::http::serve(
        listener,
        app,
        limits,
        std::future::pending(),
    ));
    let rtsp = volcapd::rtsp::start(&cfg, shared.clone(), status.clone()).unwrap();
    let url = status.url().unwrap();
    let sent: Arc<Mutex<std::collections::HashMap<u64, Instant>>> = Default::default();
    let publisher = {
        let (shared, sent, frames) = (shared.clone(), sent.clone(), frames.to_vec());
        std::thread::spawn(move || {
            let mut i = 0u64;
            let t0 = Instant::now();
            while !shared.stop.load(Ordering::Relaxed) {
                let mut rgb = frames[i as usize % frames.len()].clone();
                stamp(&mut rgb, size, i % (1 << BITS));
                let at = Instant::now();
                sent.lock().unwrap().insert(i % (1 << BITS), at);
                // The encode stage's work for MJPEG clients, then publish (RGBA for RTSP).
                let jpeg = jpeg(&rgb, size);
                let rgba = rgb
                    .chunks_exact(3)
                    .flat_map(|p| [p[0], p[1], p[2], 255])
                    .collect();
                shared.published.send_replace(Some(Arc::new(Published {
                    jpeg,
                    rgba,
                    size,
                    index: i,
                    latency_ms: 0.0,
                    placeholder: false,
                })));
                i += 1;
                let next = t0 + Duration::from_secs_f64(i as f64 / FPS as f64);
                std::thread::sleep(next.saturating_duration_since(Instant::now()));
            }
        })
    };
    // RTSP client.
    let rtsp_ms = {
        let p = gst::parse::launch(&format!(
            "rtspsrc location={url} latency=0 buffer-mode=none protocols=tcp ! rtph264depay ! avdec_h264 ! videoconvert \
             ! video/x-raw,format=RGB ! appsink name=sink sync=false"
        ))
        .unwrap()
        .downcast::<gst::Pipeline>()
        .unwrap();
        let sink = p
            .by_name("sink")
            .unwrap()
            .downcast::<gst_app::AppSink>()
            .unwrap();
        p.set_state(gst::State::Playing).unwrap();
        let mut ms = Vec::new();
        let t = Instant::now();
        while t.elapsed() < Duration::from_secs(secs) {
            let Some(s) = sink.try_pull_sample(gst::ClockTime::from_seconds(5)) else {
                break;
            };
            let now = Instant::now();
            let b = s.buffer().unwrap().map_readable().unwrap();
            let idx = read_stamp(&b, size, b.len() / size);
            if let Some(at) = sent.lock().unwrap().get(&idx) {
                ms.push(now.duration_since(*at).as_secs_f64() * 1e3);
            }
        }
        p.set_state(gst::State::Null).unwrap();
        ms
    };
    // MJPEG client.
    let mjpeg_ms = {
        let mut s = std::net::TcpStream::connect(http).unwrap();
        write!(s, "GET /stream.mjpg HTTP/1.1\r\nHost: {http}\r\n\r\n").unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let mut buf: Vec<u8> = Vec::new();
        let mut chunk = vec![0u8; 1 << 16];
        let mut ms = Vec::new();
        let t = Instant::now();
        while t.elapsed() < Duration::from_secs(secs) {
            let Ok(n) = s.read(&mut chunk) else { break };
            if n == 0 {
                break;
            }
            buf.extend_from_slice(&chunk[..n]);
            // Complete JPEGs in the buffer: SOI .. EOI.
            while let Some(a) = buf.windows(2).position(|w| w == [0xff, 0xd8]) {
                let Some(e) = buf[a..].windows(2).position(|w| w == [0xff, 0xd9]) else {
                    break;
                };
                let now = Instant::now();
                let jpg = buf[a..a + e + 2].to_vec();
                buf.drain(..a + e + 2);
                if let Ok(img) = image::load_from_memory(&jpg) {
                    let rgb = img.to_rgb8();
                    let idx = read_stamp(rgb.as_raw(), size, size * 3);
                    if let Some(at) = sent.lock().unwrap().get(&idx) {
                        ms.push(now.duration_since(*at).as_secs_f64() * 1e3);
                    }
                }
            }
        }
        ms
    };
    shared.stop.store(true, Ordering::Relaxed);
    let _ = publisher.join();
    for t in rtsp.threads {
        let _ = t.join();
    }
    rt.shutdown_timeout(Duration::from_millis(200));
    (rtsp_ms, mjpeg_ms)
}

/// The frames at even sides, as the daemon's encoder takes them (RGB).
fn even(frames: &[Vec<u8>], size: usize) -> (Vec<Vec<u8>>, usize) {
    let mut side = size;
    let out = frames
        .iter()
        .map(|f| {
            let x: Vec<u8> = f
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect();
            let mut o = Vec::new();
            side = volcapd::rtsp::even_sided(&x, size, &mut o);
            o.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect()
        })
        .collect();
    (out, side)
}

/// PSNR over bitrate, one panel per size: a line per H.264 encoder, MJPEG q85 a point.
fn plot(rows: &[Row], path: &std::path::Path) -> Result<(), String> {
    use plotters::prelude::*;
    static FONT: &[u8] = include_bytes!("../../../tools/volcap/assets/DejaVuSansMono.ttf");
    let _ = plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, FONT);
    let e = |e: &dyn std::fmt::Display| e.to_string();
    let root = BitMapBackend::new(path, (1100, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let (l, r) = root.split_horizontally(550);
    for (area, size) in [&l, &r].into_iter().zip(SIZES) {
        let sub: Vec<&Row> = rows.iter().filter(|r| r.size == size).collect();
        let kmax = sub.iter().map(|r| r.kbps).fold(1000.0, f64::max) * 1.3;
        let (pmin, pmax) = sub.iter().fold((f64::MAX, f64::MIN), |(a, b), r| {
            (a.min(r.psnr), b.max(r.psnr))
        });
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("{size} px: quality over bitrate"),
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d((150.0..kmax).log_scale(), (pmin - 1.0)..(pmax + 1.0))
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_desc("kbit/s at 30 fps")
            .y_desc("PSNR vs the render, dB")
            .draw()
            .map_err(|x| e(&x))?;
        for (i, name) in ["x264", "openh264"].into_iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            let pts: Vec<(f64, f64)> = sub
                .iter()
                .filter(|r| r.codec.contains(name))
                .map(|r| (r.kbps, r.psnr))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                .map_err(|x| e(&x))?
                .label(format!("H.264 {name}"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color));
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
                .map_err(|x| e(&x))?;
        }
        let mj: Vec<(f64, f64)> = sub
            .iter()
            .filter(|r| r.codec.starts_with("MJPEG"))
            .map(|r| (r.kbps, r.psnr))
            .collect();
        chart
            .draw_series(
                mj.iter()
                    .map(|&p| TriangleMarker::new(p, 6, BLACK.filled())),
            )
            .map_err(|x| e(&x))?
            .label("MJPEG q85 (the HTTP stream)")
            .legend(|(x, y)| TriangleMarker::new((x + 8, y), 5, BLACK.filled()));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))
}

fn main() {
    let mut n = 90usize;
    let mut out = std::path::PathBuf::from("docs/bench/rtsp.md");
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--frames" => n = args[i + 1].parse().expect("--frames N"),
            "--out" => out = args[i + 1].clone().into(),
            a => panic!("unknown argument {a} (--frames N, --out FILE)"),
        }
        i += 2;
    }
    gst::init().unwrap();
    let mut rows = Vec::new();
    let mut lat = Vec::new();
    for size in SIZES {
        // Encoded at even sides (258, 514), reported by the render's size.
        let (frames, side) = even(&renders(size, n), size);
        // MJPEG as the daemon makes it (quality 85).
        let mut ms = Vec::new();
        let mut bytes = 0usize;
        let mut p = 0.0;
        for f in &frames {
            let t = Instant::now();
            let j = jpeg(f, side);
            ms.push(t.elapsed().as_secs_f64() * 1e3);
            bytes += j.len();
            let d = image::load_from_memory(&j).unwrap().to_rgb8();
            p += psnr(f, d.as_raw());
        }
        rows.push(Row {
            codec: "MJPEG q85".into(),
            size,
            kbps: bytes as f64 * 8.0 / 1000.0 / (n as f64 / FPS as f64),
            psnr: p / n as f64,
            ms_p50: pct(&mut ms.clone(), 0.5),
            ms_p95: pct(&mut ms, 0.95),
        });
        rows.push(Row {
            codec: "I420 round trip, no codec (H.264's ceiling)".into(),
            size,
            kbps: f64::NAN,
            psnr: yuv_ceiling(&frames, side),
            ms_p50: f64::NAN,
            ms_p95: f64::NAN,
        });
        let bar = indicatif::ProgressBar::new((BITRATES.len() * 2) as u64)
            .with_message(format!("H.264 at {size} px"));
        for (enc, name) in [
            (volcapd::config::rtsp::Encoder::X264, "x264"),
            (volcapd::config::rtsp::Encoder::Openh264, "openh264"),
        ] {
            for kbps in BITRATES {
                let c = volcapd::config::RtspConfig {
                    encoder: enc,
                    bitrate_kbps: kbps,
                    gop: 30,
                    ..Default::default()
                };
                let (k, p, mut ms) = h264(&frames, side, &volcapd::rtsp::encoder_launch(&c));
                rows.push(Row {
                    codec: format!("H.264 {name} {kbps} kbit/s"),
                    size,
                    kbps: k,
                    psnr: p,
                    ms_p50: pct(&mut ms.clone(), 0.5),
                    ms_p95: pct(&mut ms, 0.95),
                });
                bar.inc(1);
            }
        }
        bar.finish_and_clear();
        let (mut r, mut m) = latency(&frames, side, 8);
        lat.push((
            size,
            r.len(),
            pct(&mut r.clone(), 0.5),
            pct(&mut r, 0.95),
            m.len(),
            pct(&mut m.clone(), 0.5),
            pct(&mut m, 0.95),
        ));
    }
    let mut md = String::from(
        "# H.264 over RTSP against MJPEG\n\nGenerated by `cargo run --release -p volcapd --features rtsp --example rtsp_bench`\n\
         on the daemon's own renders (front-walk scene, oracle field, 129^3 grid, published at\n\
         257 and 513 px), this machine (2 cores, no GPU). Bitrates are at 30 fps; PSNR is the\n\
         decoded frame against the raw render (RGB, mean over frames); encode ms is one frame\n\
         in, its access unit out (x264: ultrafast, zero-latency, 1 thread; openh264: low\n\
         complexity), MJPEG the daemon's JPEG (quality 85) alone.\n\n\
         | codec | px | kbit/s | PSNR dB | encode ms p50 | p95 |\n|---|---|---|---|---|---|\n",
    );
    let num = |v: f64, d: usize| {
        if v.is_finite() {
            format!("{v:.d$}")
        } else {
            "-".into()
        }
    };
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {} | {:.2} | {} | {} |\n",
            r.codec,
            r.size,
            num(r.kbps, 0),
            r.psnr,
            num(r.ms_p50, 2),
            num(r.ms_p95, 2)
        ));
    }
    md.push_str(
        "\n**Equal quality.** H.264 goes through 8-bit limited-range 4:2:0 YUV (what players expect), JPEG\n\
         through full-range YCbCr: the round trip alone (the `I420 round trip` rows) caps H.264's PSNR\n\
         against the RGB render below MJPEG's, so \"equal\" is read as each encoder's plateau: the lowest\n\
         bitrate within 0.3 dB of the best this encoder reaches in the table, against MJPEG q85:\n\n\
         | px | MJPEG kbit/s (PSNR) | x264 | openh264 |\n|---|---|---|---|\n",
    );
    for size in SIZES {
        let mj = rows
            .iter()
            .find(|r| r.size == size && r.codec.starts_with("MJPEG"))
            .unwrap();
        let best = |name: &str| {
            let of: Vec<&Row> = rows
                .iter()
                .filter(|r| r.size == size && r.codec.contains(name))
                .collect();
            let top = of.iter().map(|r| r.psnr).fold(f64::MIN, f64::max);
            of.iter()
                .filter(|r| r.psnr >= top - 0.3)
                .min_by(|a, b| a.kbps.total_cmp(&b.kbps))
                .map(|r| {
                    format!(
                        "{:.0} kbit/s ({:.2} dB): {:.1}x less",
                        r.kbps,
                        r.psnr,
                        mj.kbps / r.kbps
                    )
                })
                .unwrap_or_default()
        };
        md.push_str(&format!(
            "| {size} | {:.0} ({:.2} dB) | {} | {} |\n",
            mj.kbps,
            mj.psnr,
            best("x264"),
            best("openh264")
        ));
    }
    md.push_str("\n**Glass-to-glass on loopback** (frame published -> decoded by the client, ms; a frame index drawn\ninto each frame; the daemon's servers in this process, frames published at 30 fps; RTSP:\nx264 2000 kbit/s through GStreamer's `rtspsrc latency=0 ! avdec_h264`; MJPEG: the JPEG encode, HTTP, a JPEG decode):\n\n| px | RTSP frames | RTSP p50 | p95 | MJPEG frames | MJPEG p50 | p95 |\n|---|---|---|---|---|---|---|\n");
    for (size, rn, r50, r95, mn, m50, m95) in &lat {
        md.push_str(&format!(
            "| {size} | {rn} | {r50:.1} | {r95:.1} | {mn} | {m50:.1} | {m95:.1} |\n"
        ));
    }
    print!("{md}");
    if let Some(d) = out.parent() {
        let _ = std::fs::create_dir_all(d);
    }
    let png = out.with_extension("png");
    md.push_str(&format!(
        "\n![PSNR over bitrate]({})\n",
        png.file_name()
            .map(|f| f.to_string_lossy().to_string())
            .unwrap_or_default()
    ));
    std::fs::write(&out, md).expect("writing the report");
    plot(&rows, &png).expect("writing the plot");
    eprintln!("wrote {} and {}", out.display(), png.display());
}
