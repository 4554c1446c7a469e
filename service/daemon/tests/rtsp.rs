//! H.264 over RTSP (`rtsp` feature) with real clients on loopback: ffprobe / ffmpeg and
//! GStreamer's `rtspsrc` read the served stream over TCP and UDP; the client limits answer
//! 503; a token asks for credentials; the push publishes to a real RTSP server (the
//! `rtsp_relay` example, GStreamer's RTSP server in RECORD mode) that is killed and started
//! again mid-stream; 50 clients through that relay leave the daemon's rate as it was.
#![cfg(feature = "rtsp")]

mod common;
use common::*;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A sim config (oracle field, 65^3, 256-px display) with `[rtsp]` keys appended.
fn config(dir: &Path, rtsp: &str, extra: &str) -> PathBuf {
    sim_config(
        dir,
        65,
        &format!("{extra}\n[rtsp]\n{rtsp}\n").replace("[render]\n", ""),
    )
}

fn rtsp_url(addr: &str) -> String {
    wait_for(addr, "the RTSP server", Duration::from_secs(20), |s| {
        s["rtsp"]["url"].is_string()
    })["rtsp"]["url"]
        .as_str()
        .unwrap()
        .to_string()
}

fn tools() -> bool {
    have("ffprobe") && have("ffmpeg") && have("gst-launch-1.0")
}

/// ffprobe's decoded frames of `url` over `transport` for `secs` seconds: (key, pts) each.
/// The tests ask 8 frames of 5 s (3 s gave 6 through the relay once, both cores busy with
/// other work): the property is frames arriving in order from a key frame, not a rate.
/// A second ffprobe where the first read no stream at all: once (2026-12-04, the whole suite
/// on two cores) the first ffprobe through the relay, just after the push reported
/// `streaming`, printed nothing in its 40 s; one that fails twice fails the test.
fn probe_frames(url: &str, transport: &str, secs: u32) -> Vec<(bool, Option<i64>)> {
    let probe = || {
        Command::new("timeout")
            .args([
                "40",
                "ffprobe",
                "-v",
                "error",
                "-rtsp_transport",
                transport,
                "-select_streams",
                "v",
                "-show_entries",
                "frame=key_frame,pts:stream=codec_name,width,height",
                "-of",
                "csv",
                "-read_intervals",
                &format!("%+{secs}"),
                url,
            ])
            .output()
            .unwrap()
    };
    let mut out = probe();
    if !String::from_utf8_lossy(&out.stdout).contains("stream,h264") {
        eprintln!(
            "ffprobe over {transport} read no stream from {url} (exit {:?}: {}), once more",
            out.status.code(),
            String::from_utf8_lossy(&out.stderr)
        );
        out = probe();
    }
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("stream,h264"),
        "ffprobe over {transport} does not read h264 (twice): {text} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    text.lines()
        .filter_map(|l| l.strip_prefix("frame,"))
        .map(|l| {
            let mut f = l.split(',');
            let key = f.next() == Some("1");
            (key, f.next().and_then(|p| p.parse().ok()))
        })
        .collect()
}

/// Frames with a timestamp; asserts at least `min`, the first a key frame, strictly rising.
fn check_frames(frames: &[(bool, Option<i64>)], min: usize, what: &str) {
    let stamped: Vec<i64> = frames.iter().filter_map(|f| f.1).collect();
    assert!(
        stamped.len() >= min,
        "{what}: {} frames decoded, expected {min}",
        stamped.len()
    );
    assert!(frames[0].0, "{what}: the stream starts without a key frame");
    assert!(
        stamped.windows(2).all(|w| w[1] > w[0]),
        "{what}: timestamps do not rise: {stamped:?}"
    );
}

#[test]
fn serves_h264_over_tcp_and_udp_to_ffmpeg_and_gstreamer() {
    let _g = serial();
    if !tools() {
        return;
    }
    let dir = tmp("rtsp-serve");
    let cfg = config(&dir, "bind = \"127.0.0.1:0\"\ngop = 10", "");
    let (mut d, addr) = launch_publishing(&cfg, 2);
    let url = rtsp_url(&addr);
    assert!(url.ends_with("/live"), "{url}");
    // Nobody watching: nothing encoded.
    let s = state(&addr);
    assert_eq!(s["rtsp"]["encoding"], false, "{s}");
    let before = s["frames_published"].as_u64().unwrap();
    check_frames(&probe_frames(&url, "tcp", 5), 8, "ffprobe over TCP");
    check_frames(&probe_frames(&url, "udp", 5), 8, "ffprobe over UDP");
    // ffmpeg decodes the frames it is asked for.
    let ok = Command::new("timeout")
        .args([
            "40",
            "ffmpeg",
            "-v",
            "error",
            "-rtsp_transport",
            "tcp",
            "-i",
            &url,
        ])
        .args(["-frames:v", "15", "-f", "null", "-"])
        .status()
        .unwrap();
    assert!(ok.success(), "ffmpeg could not decode 15 frames");
    // GStreamer's client: rtspsrc, depayload, decode. Ten decoded frames end the stream at
    // the sink (EOS), which gst-launch reports before it shuts the pipeline down. Its exit
    // status is not the property: in one CI run rtspsrc's shutdown PAUSE, sent after the
    // frames, read end-of-file ("Could not send message. (Received end-of-file)"; not
    // reproduced here in 5 runs on a loaded CPU) and gst-launch exited 1. A failed shutdown is
    // printed, not failed.
    let out = Command::new("timeout")
        .args([
            "40",
            "gst-launch-1.0",
            "rtspsrc",
            &format!("location={url}"),
        ])
        .args(["!", "rtph264depay", "!", "h264parse", "!", "avdec_h264"])
        .args(["!", "fakesink", "num-buffers=10"])
        .output()
        .unwrap();
    let (gst_out, gst_err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    // (An error before the frames ends gst-launch's loop without the EOS line.)
    assert!(
        gst_out.contains("Got EOS from element \"pipeline0\""),
        "gst-launch rtspsrc could not decode 10 frames: {gst_out}\n{gst_err}"
    );
    if !out.status.success() {
        eprintln!("gst-launch decoded 10 frames, then its shutdown failed: {gst_err}");
    }
    let s = state(&addr);
    let r = &s["rtsp"];
    assert!(r["clients_total"].as_u64() >= Some(4), "{r}");
    assert!(r["frames_encoded"].as_u64() >= Some(20), "{r}");
    assert!(r["encode_ms"]["p50"].as_f64() > Some(0.0), "{r}");
    assert!(s["frames_published"].as_u64() > Some(before + 10));
    let (_, _, m) = request(&addr, "GET", "/metrics", "");
    let m = String::from_utf8_lossy(&m);
    assert!(m.contains("volcap_rtsp_frames_encoded_total"), "{m}");
    // The clients left: the encoder stops.
    wait_for(&addr, "the encoder to stop", Duration::from_secs(20), |s| {
        s["rtsp"]["clients"] == 0 && s["rtsp"]["encoding"] == false
    });
    assert!(alive(&mut d));
}

/// The picture itself: a still person at an odd display size (257 px, padded to 258 for
/// H.264) decoded from RTSP against the MJPEG snapshot of the same daemon: close (a wrong
/// row stride or padding would shear it), and the padding repeats the last row.
#[test]
fn the_rtsp_picture_is_the_published_render() {
    let _g = serial();
    if !tools() {
        return;
    }
    let dir = tmp("rtsp-picture");
    let scene = root().join("tests/scenes/still-rest.toml");
    let cfg = dir.join("p.toml");
    std::fs::write(
        &cfg,
        format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nresolution = 65\ndisplay_size = 257\n[dbus]\nbus = \"none\"\n[rtsp]\nbind = \"127.0.0.1:0\"\nbitrate_kbps = 8000\ngop = 10\n",
            scene.display()
        ),
    )
    .unwrap();
    let (_d, addr) = launch_publishing(&cfg, 2);
    let url = rtsp_url(&addr);
    let raw = dir.join("f.rgb");
    let ok = Command::new("timeout")
        .args([
            "40",
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-rtsp_transport",
            "tcp",
            "-i",
            &url,
        ])
        .args(["-frames:v", "3", "-f", "rawvideo", "-pix_fmt", "rgb24"])
        .arg(&raw)
        .status()
        .unwrap();
    assert!(ok.success(), "ffmpeg could not grab frames");
    let rgb = std::fs::read(&raw).unwrap();
    let side = 258;
    assert_eq!(rgb.len(), 3 * side * side * 3, "three 258x258 frames");
    let last = &rgb[2 * side * side * 3..];
    let (code, _, jpeg) = request(&addr, "GET", "/snapshot.jpg", "");
    assert_eq!(code, 200);
    let snap = image::load_from_memory(&jpeg).unwrap().to_rgb8();
    assert_eq!(snap.width(), 257);
    let mut se = 0.0f64;
    for y in 0..257usize {
        for x in 0..257usize {
            let p = snap.get_pixel(x as u32, y as u32);
            for c in 0..3 {
                let d = last[(y * side + x) * 3 + c] as f64 - p[c] as f64;
                se += d * d;
            }
        }
    }
    let psnr = 10.0 * (255.0f64.powi(2) / (se / (257.0 * 257.0 * 3.0))).log10();
    assert!(
        psnr > 28.0,
        "RTSP picture against the snapshot: {psnr:.1} dB"
    );
    // The padding column repeats column 256 (to within the codec's error).
    let pad: f64 = (0..257)
        .map(|y| {
            (0..3)
                .map(|c| {
                    (last[(y * side + 257) * 3 + c] as f64 - last[(y * side + 256) * 3 + c] as f64)
                        .abs()
                })
                .sum::<f64>()
        })
        .sum::<f64>()
        / (257.0 * 3.0);
    assert!(
        pad < 8.0,
        "the padding column differs by {pad:.1} on average"
    );
}

/// `rtsp.udp_ports`: a UDP client is sent RTP from a port in the configured range (what a
/// firewall rule names), and ffprobe reads the stream over UDP through it.
#[test]
fn udp_ports_stay_in_the_configured_range() {
    let _g = serial();
    if !tools() {
        return;
    }
    // An even first port, 20 ports, from this process id (tests run one at a time).
    let first = 40_000 + (std::process::id() % 1000) as u16 * 20;
    let dir = tmp("rtsp-udp");
    let cfg = config(
        &dir,
        &format!(
            "bind = \"127.0.0.1:0\"\ngop = 10\ntransports = [\"udp\"]\nudp_ports = [{first}, {}]",
            first + 19
        ),
        "",
    );
    let (_d, addr) = launch_publishing(&cfg, 2);
    let url = rtsp_url(&addr);
    let host = url
        .strip_prefix("rtsp://")
        .unwrap()
        .split('/')
        .next()
        .unwrap()
        .to_string();
    let mut s = TcpStream::connect(&host).unwrap();
    assert_eq!(rtsp_status(&mut s, "DESCRIBE", &url, 1, ""), 200);
    write!(
        s,
        "SETUP {url}/stream=0 RTSP/1.0\r\nCSeq: 2\r\nTransport: RTP/AVP;unicast;client_port=50100-50101\r\n\r\n"
    )
    .unwrap();
    let mut buf = [0u8; 2048];
    let n = s.read(&mut buf).unwrap();
    let head = String::from_utf8_lossy(&buf[..n]).to_string();
    let port: u16 = head
        .split("server_port=")
        .nth(1)
        .and_then(|p| p.split('-').next())
        .and_then(|p| p.trim().parse().ok())
        .unwrap_or_else(|| panic!("no server_port in {head}"));
    assert!(
        (first..=first + 19).contains(&port),
        "server port {port} outside [{first}, {}]",
        first + 19
    );
    drop(s);
    check_frames(
        &probe_frames(&url, "udp", 5),
        8,
        "ffprobe over UDP from the range",
    );
}

/// Write an RTSP request and read the status code of the response (0 if none).
fn rtsp_status(s: &mut TcpStream, method: &str, url: &str, cseq: u32, extra: &str) -> u16 {
    write!(
        s,
        "{method} {url} RTSP/1.0\r\nCSeq: {cseq}\r\nAccept: application/sdp\r\n{extra}\r\n"
    )
    .unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut buf = Vec::new();
    let mut b = [0u8; 4096];
    // The head, then the body by Content-Length.
    while !buf.windows(4).any(|w| w == b"\r\n\r\n") {
        match s.read(&mut b) {
            Ok(0) | Err(_) => break,
            Ok(n) => buf.extend_from_slice(&b[..n]),
        }
    }
    let text = String::from_utf8_lossy(&buf).to_string();
    text.split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0)
}

#[test]
fn client_limits_refuse_with_503_and_a_token_asks_for_credentials() {
    let _g = serial();
    if !tools() {
        return;
    }
    let dir = tmp("rtsp-limits");
    let token = "s3cret-token";
    let cfg = config(
        &dir,
        "bind = \"127.0.0.1:0\"\nclient_limit = 16\nper_address_limit = 3\ngop = 10",
        &format!("[http]\ntoken = \"{token}\""),
    );
    let (mut d, addr) = launch_publishing(&cfg, 2);
    let url = rtsp_url(&addr);
    let port = url.split(':').nth(2).unwrap().split('/').next().unwrap();
    let host = format!("127.0.0.1:{port}");
    // Without credentials: 401; ffprobe with them reads the stream.
    let mut s = TcpStream::connect(&host).unwrap();
    assert_eq!(rtsp_status(&mut s, "DESCRIBE", &url, 1, ""), 401);
    drop(s);
    let with = url.replace("rtsp://", &format!("rtsp://volcap:{token}@"));
    check_frames(&probe_frames(&with, "tcp", 2), 5, "ffprobe with the token");
    let bad = url.replace("rtsp://", "rtsp://volcap:wrong-token@");
    let out = Command::new("timeout")
        .args([
            "20",
            "ffprobe",
            "-v",
            "error",
            "-rtsp_transport",
            "tcp",
            &bad,
        ])
        .output()
        .unwrap();
    assert!(!out.status.success(), "a wrong token was let in");
    // 50 direct clients, each from its own address then four more from one: the first 16
    // are admitted (DESCRIBE 200), the rest get 503; per address at most 3.
    let auth = format!(
        "Authorization: Basic {}\r\n",
        base64(&format!("volcap:{token}"))
    );
    let mut kept = Vec::new();
    let mut codes = Vec::new();
    for i in 0..50 {
        let from = format!("127.0.0.{}", 10 + i);
        let mut s = connect_from(&host, &from, None).unwrap();
        codes.push(rtsp_status(&mut s, "DESCRIBE", &url, 1, &auth));
        kept.push(s);
    }
    assert!(codes[..16].iter().all(|&c| c == 200), "{codes:?}");
    assert!(codes[16..].iter().all(|&c| c == 503), "{codes:?}");
    let st = state(&addr);
    assert_eq!(st["rtsp"]["clients"], 16, "{}", st["rtsp"]);
    assert!(st["rtsp"]["refused"].as_u64() >= Some(34));
    drop(kept);
    wait_for(&addr, "the clients to go", Duration::from_secs(20), |s| {
        s["rtsp"]["clients"] == 0
    });
    // The shared media was torn down with its last client: one client from elsewhere
    // brings it back (a DESCRIBE during the teardown may get the server's own 503).
    let mut warm = None;
    for _ in 0..20 {
        let mut s = connect_from(&host, "127.0.0.201", None).unwrap();
        if rtsp_status(&mut s, "DESCRIBE", &url, 1, &auth) == 200 {
            warm = Some(s);
            break;
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    assert!(warm.is_some(), "the stream did not come back");
    let per: Vec<u16> = (0..4)
        .map(|_| {
            let mut s = connect_from(&host, "127.0.0.200", None).unwrap();
            let c = rtsp_status(&mut s, "DESCRIBE", &url, 1, &auth);
            std::mem::forget(s); // held open until the daemon is stopped
            c
        })
        .collect();
    assert_eq!(per, [200, 200, 200, 503], "per-address limit");
    assert!(alive(&mut d));
}

fn base64(s: &str) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let b = s.as_bytes();
    let mut out = String::new();
    for c in b.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for i in 0..4 {
            if i <= c.len() {
                out.push(T[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The relay example, built beside this test binary, on `port`.
fn relay(port: u16) -> Proc {
    let exe = std::env::current_exe().unwrap();
    let bin = exe
        .parent()
        .and_then(|d| d.parent())
        .unwrap()
        .join("examples/rtsp_relay");
    assert!(
        bin.exists(),
        "{} not built (cargo build --release -p volcapd --features rtsp --examples)",
        bin.display()
    );
    let p = Proc(
        Command::new(bin)
            .arg(port.to_string())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let t = Instant::now();
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "the relay does not listen"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    p
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The daemon's published fps over `secs` seconds (frames_published difference).
fn fps_over(addr: &str, secs: f64) -> f64 {
    let a = state(addr)["frames_published"].as_u64().unwrap();
    let t = Instant::now();
    std::thread::sleep(Duration::from_secs_f64(secs));
    let b = state(addr)["frames_published"].as_u64().unwrap();
    (b - a) as f64 / t.elapsed().as_secs_f64()
}

/// A client that plays `url` over TCP (interleaved) and reads what it is sent, or never
/// reads when `stalled`: RTSP by hand, no decoder, so 50 of them cost little CPU.
fn raw_player(url: &str, stalled: bool) -> Option<std::thread::JoinHandle<()>> {
    let host = url.strip_prefix("rtsp://")?.split('/').next()?.to_string();
    let mut s = connect_from(&host, "127.0.0.1", stalled.then_some(4096)).ok()?;
    if rtsp_status(&mut s, "DESCRIBE", url, 1, "") != 200 {
        return None;
    }
    // The session id from SETUP's response.
    write!(
        s,
        "SETUP {url}/stream=0 RTSP/1.0\r\nCSeq: 2\r\nTransport: RTP/AVP/TCP;unicast;interleaved=0-1\r\n\r\n"
    )
    .ok()?;
    let mut buf = [0u8; 2048];
    let n = s.read(&mut buf).ok()?;
    let head = String::from_utf8_lossy(&buf[..n]).to_string();
    let session = head
        .lines()
        .find_map(|l| l.strip_prefix("Session: "))?
        .split(';')
        .next()?
        .trim()
        .to_string();
    write!(
        s,
        "PLAY {url} RTSP/1.0\r\nCSeq: 3\r\nSession: {session}\r\nRange: npt=0-\r\n\r\n"
    )
    .ok()?;
    Some(std::thread::spawn(move || {
        if stalled {
            std::thread::sleep(Duration::from_secs(30));
            return;
        }
        let _ = s.set_read_timeout(Some(Duration::from_secs(5)));
        let mut buf = vec![0u8; 1 << 16];
        let t = Instant::now();
        while t.elapsed() < Duration::from_secs(30) {
            if !matches!(s.read(&mut buf), Ok(n) if n > 0) {
                break;
            }
        }
    }))
}

#[test]
fn push_survives_the_server_restarting_and_a_relay_fans_out_to_50_clients() {
    let _g = serial();
    if !tools() {
        return;
    }
    let port = free_port();
    let server = relay(port);
    let dir = tmp("rtsp-push");
    // A camera-paced daemon (the scene's rate at 33^3): its rate says whether RTSP work
    // reaches the pipeline.
    let cfg = sim_config(
        &dir,
        33,
        &format!(
            "[rtsp]\npush = \"rtsp://127.0.0.1:{port}/in\"\npush_retry_max_s = 2\ngop = 10\nbitrate_kbps = 500\nbind = \"127.0.0.1:0\"\n"
        ),
    );
    let (mut d, addr) = launch_publishing(&cfg, 2);
    wait_for(&addr, "the push to stream", Duration::from_secs(30), |s| {
        s["rtsp"]["push"]["state"] == "streaming"
    });
    let out = format!("rtsp://127.0.0.1:{port}/out");
    check_frames(&probe_frames(&out, "tcp", 5), 8, "through the relay");

    // The server goes away: a state, retried; MJPEG keeps going.
    drop(server);
    let s = wait_for(&addr, "the push to notice", Duration::from_secs(30), |s| {
        matches!(
            s["rtsp"]["push"]["state"].as_str(),
            Some("retrying" | "connecting")
        ) && s["rtsp"]["push"]["attempts"].as_u64() >= Some(2)
    });
    assert!(s["rtsp"]["push"]["error"].is_string(), "{}", s["rtsp"]);
    let (code, head, jpeg) = request(&addr, "GET", "/snapshot.jpg", "");
    assert_eq!(code, 200, "{head}");
    assert!(jpeg.starts_with(&[0xff, 0xd8]));
    assert!(
        fps_over(&addr, 2.0) > 1.0,
        "the pipeline stalled without its server"
    );
    // Back again: the push reconnects on its own.
    let _server = relay(port);
    wait_for(
        &addr,
        "the push to reconnect",
        Duration::from_secs(30),
        |s| s["rtsp"]["push"]["state"] == "streaming",
    );
    check_frames(
        &probe_frames(&out, "tcp", 5),
        8,
        "through the restarted relay",
    );

    // 50 clients through the relay, and one stalled client on the daemon itself: the daemon
    // keeps publishing. The relay and its 50 players run on the same two cores, so the rate
    // may dip by their CPU share (8.5 -> 7.4 fps seen once, 13 %; 14.1 -> 10.4 once under a
    // parallel build, 26 %, which failed a 25 % bound); a client that held the pipeline
    // would take it toward zero over the 8 s. The bound is half; the figures are printed.
    let alone = fps_over(&addr, 8.0);
    let players: Vec<_> = (0..50).filter_map(|_| raw_player(&out, false)).collect();
    assert_eq!(players.len(), 50, "the relay did not take 50 players");
    let direct = wait_for(&addr, "the RTSP URL", Duration::from_secs(5), |s| {
        s["rtsp"]["url"].is_string()
    })["rtsp"]["url"]
        .as_str()
        .unwrap()
        .to_string();
    let stalled = raw_player(&direct, true);
    assert!(stalled.is_some(), "the stalled client was not admitted");
    std::thread::sleep(Duration::from_secs(2));
    let with = fps_over(&addr, 8.0);
    let s = state(&addr);
    assert_eq!(s["rtsp"]["push"]["state"], "streaming", "{}", s["rtsp"]);
    assert!(
        with >= 0.5 * alone,
        "the daemon's rate fell from {alone:.1} to {with:.1} fps with 50 relay clients"
    );
    println!("fps alone {alone:.2}, with 50 relay clients and a stalled one {with:.2}");
    for p in players {
        let _ = p.join();
    }
    assert!(alive(&mut d));
}
