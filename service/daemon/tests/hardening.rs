//! What a hostile LAN client, a stray signal or a bad file could do to volcapd (issue #14):
//! each test here failed on the daemon before its fix. Loopback only, bounded in count and
//! time.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

mod common;
use common::{
    alive, connect_from, launch, launch_publishing, proc_status, request, root, serial, signal,
    sim_config, state, tmp, trickling, wait_for,
};

/// #4: SIGHUP killed the daemon (exit 129, nothing logged, no restart); SIGUSR1 too.
#[test]
fn sighup_reloads_the_config_and_sigusr1_is_survived() {
    let _s = serial();
    let dir = tmp("hup");
    let cfg = sim_config(&dir, 65, "");
    let (mut p, addr) = launch_publishing(&cfg, 1);
    // A new resolution in the file, then SIGHUP: applied, still running.
    sim_config(&dir, 33, "");
    signal(&p, "HUP");
    wait_for(
        &addr,
        "the reloaded resolution",
        Duration::from_secs(20),
        |s| s["resolution"] == 33,
    );
    assert!(alive(&mut p), "SIGHUP must not end the daemon");
    // A broken file: refused, the running config kept, still serving.
    std::fs::write(&cfg, "[camera]\nbackend = \"nonsense\"\n").unwrap();
    signal(&p, "HUP");
    std::thread::sleep(Duration::from_millis(500));
    assert!(alive(&mut p));
    assert_eq!(state(&addr)["resolution"], 33);
    signal(&p, "USR1");
    signal(&p, "USR2");
    std::thread::sleep(Duration::from_millis(300));
    assert!(alive(&mut p), "SIGUSR1/2 must not end the daemon");
    let n = state(&addr)["frames_published"].as_u64().unwrap();
    wait_for(
        &addr,
        "frames after the signals",
        Duration::from_secs(20),
        |s| s["frames_published"].as_u64() > Some(n),
    );
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #1: `/mesh.glb` ran unbounded, one blocking thread per request, and kept running after
/// the client left (800 requests: 219 threads, 2.8 GB). Now one computation at a time, HEAD
/// computes nothing.
#[test]
fn mesh_requests_are_bounded_and_head_computes_nothing() {
    let _s = serial();
    let dir = tmp("mesh");
    let cfg = sim_config(&dir, 129, "[http]\nper_address_limit = 1000\n");
    let (p, addr) = launch_publishing(&cfg, 2);
    let fps = |secs: f64| {
        let a = state(&addr)["frames_published"].as_u64().unwrap();
        std::thread::sleep(Duration::from_secs_f64(secs));
        let b = state(&addr)["frames_published"].as_u64().unwrap();
        (b - a) as f64 / secs
    };
    let before = fps(3.0);
    let (threads0, rss0) = (proc_status(&p, "Threads:"), proc_status(&p, "VmRSS:"));
    // HEAD: an answer at once, no mesh.
    let t = Instant::now();
    let (st, head, body) = request(&addr, "HEAD", "/mesh.glb", "");
    assert_eq!(st, 200, "{head}");
    assert!(body.is_empty() && head.contains("model/gltf-binary"));
    assert!(
        t.elapsed() < Duration::from_millis(500),
        "HEAD took {:?}",
        t.elapsed()
    );
    // 60 requests sent and abandoned at once.
    for _ in 0..60 {
        let mut s = TcpStream::connect(&addr).unwrap();
        write!(s, "GET /mesh.glb HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
    }
    std::thread::sleep(Duration::from_millis(300));
    let (threads1, rss1) = (proc_status(&p, "Threads:"), proc_status(&p, "VmRSS:"));
    let during = fps(3.0);
    // While a mesh is being computed, another request is told to come back.
    let mut busy = 0;
    let mut ok = 0;
    for _ in 0..5 {
        let (st, head, body) = request(&addr, "GET", "/mesh.glb", "");
        match st {
            200 => {
                assert_eq!(&body[..4], b"glTF");
                ok += 1;
            }
            503 => {
                assert!(head.to_ascii_lowercase().contains("retry-after"), "{head}");
                busy += 1;
            }
            s => panic!("mesh: status {s}"),
        }
    }
    let after = fps(3.0);
    let rss2 = proc_status(&p, "VmRSS:");
    eprintln!(
        "mesh flood: threads {threads0} -> {threads1}; RSS {} -> {} -> {} MB; fps {before:.1} / {during:.1} / {after:.1}; later requests {ok} ok, {busy} busy",
        rss0 / 1024,
        rss1 / 1024,
        rss2 / 1024
    );
    assert!(
        threads1 <= threads0 + 2,
        "threads grew from {threads0} to {threads1}"
    );
    assert!(
        rss1.max(rss2) < rss0 + 400 * 1024,
        "RSS grew from {rss0} kB to {} kB",
        rss1.max(rss2)
    );
    assert!(ok >= 1, "a mesh is still served");
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #2: 80 trickling connections from one address made most legitimate `/state` requests
/// fail. Now an address holds at most `per_address_limit` connections.
#[test]
fn one_address_cannot_take_every_connection() {
    let _s = serial();
    let dir = tmp("peraddr");
    let cfg = sim_config(
        &dir,
        33,
        "[http]\nper_address_limit = 4\nheader_timeout_s = 30\n",
    );
    let (p, addr) = launch_publishing(&cfg, 0);
    // 100 connections from 127.0.0.2 trickling a request head (one byte, then nothing).
    let hog = trickling(&addr, "127.0.0.2", 100);
    for s in &hog {
        s.set_nonblocking(true).unwrap();
    }
    // Closed at accept: EOF, or a reset (the byte we sent was never read). An accepted
    // connection (or one still in the backlog) has nothing to read yet. Poll until the
    // server has gone through the backlog (bounded).
    let open = |hog: &[TcpStream]| {
        hog.iter()
            .filter(|s| {
                let mut b = [0u8; 1];
                matches!((&**s).read(&mut b), Err(e) if e.kind() == std::io::ErrorKind::WouldBlock)
            })
            .count()
    };
    let t = Instant::now();
    let mut held = open(&hog);
    while held > 4 && t.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(200));
        held = open(&hog);
    }
    let mut served = 0;
    for _ in 0..20 {
        let mut s = connect_from(&addr, "127.0.0.1", None).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        write!(
            s,
            "GET /state HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut buf = String::new();
        let _ = s.read_to_string(&mut buf);
        served += buf.starts_with("HTTP/1.1 200") as usize;
    }
    eprintln!(
        "per-address limit 4: {held} of 100 hog connections held; {served} of 20 /state served"
    );
    assert!(held <= 4, "{held} connections held by one address");
    assert_eq!(served, 20);
    drop(hog);
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #3: stream clients that never read held their slot forever. Now a write that makes no
/// progress for `write_timeout_s` ends the connection and frees the slot.
#[test]
fn stream_clients_that_never_read_are_dropped() {
    let _s = serial();
    let dir = tmp("wto");
    let cfg = sim_config(&dir, 129, "[http]\nclient_limit = 2\nwrite_timeout_s = 2\n");
    let (p, addr) = launch_publishing(&cfg, 1);
    let stuck: Vec<TcpStream> = (0..2)
        .map(|_| {
            let mut s = connect_from(&addr, "127.0.0.1", Some(4096)).unwrap();
            write!(s, "GET /stream.mjpg HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
            s
        })
        .collect();
    wait_for(&addr, "two stream clients", Duration::from_secs(10), |s| {
        s["clients"] == 2
    });
    assert_eq!(
        request(&addr, "GET", "/stream.mjpg", "").0,
        503,
        "at the limit"
    );
    let t = Instant::now();
    wait_for(
        &addr,
        "the stuck clients dropped",
        Duration::from_secs(60),
        |s| s["clients"] == 0,
    );
    eprintln!(
        "stuck stream clients freed after {:.1} s",
        t.elapsed().as_secs_f64()
    );
    // A new viewer gets frames.
    let mut v = connect_from(&addr, "127.0.0.1", None).unwrap();
    v.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(v, "GET /stream.mjpg HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
    let mut buf = vec![0u8; 4096];
    let n = v.read(&mut buf).unwrap();
    assert!(String::from_utf8_lossy(&buf[..n]).starts_with("HTTP/1.1 200"));
    drop(stuck);
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #12, #13: the `Host` allow-list (DNS rebinding), `/state` details only with the token,
/// and a per-address back-off on wrong tokens (1000 guesses took 0.8 s).
#[test]
fn host_allow_list_state_privacy_and_token_backoff() {
    let _s = serial();
    let dir = tmp("lan");
    let cfg = sim_config(
        &dir,
        33,
        "[http]\ntoken = \"s3cret-token\"\nallowed_hosts = [\"volcap.lan\"]\n",
    );
    let (p, addr) = launch_publishing(&cfg, 0);
    let port = addr.rsplit_once(':').unwrap().1;
    let with_host = |path: &str, host: &str| {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        write!(
            s,
            "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut buf = Vec::new();
        let _ = s.read_to_end(&mut buf);
        String::from_utf8_lossy(&buf)
            .split_whitespace()
            .nth(1)
            .unwrap_or("")
            .to_string()
    };
    for path in ["/state", "/snapshot.jpg", "/stream.mjpg", "/"] {
        assert_eq!(
            with_host(path, &format!("evil.example:{port}")),
            "421",
            "{path}"
        );
    }
    for host in [
        addr.clone(),
        format!("localhost:{port}"),
        format!("volcap.lan:{port}"),
    ] {
        assert_eq!(with_host("/state", &host), "200", "{host}");
    }
    // A stream client's address: hidden without the token, shown with it.
    let mut viewer = TcpStream::connect(&addr).unwrap();
    write!(
        viewer,
        "GET /stream.mjpg HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
    )
    .unwrap();
    let s = wait_for(&addr, "a stream client", Duration::from_secs(10), |s| {
        s["clients"] == 1
    });
    assert!(s["per_client"][0].get("peer").is_none(), "{s}");
    let auth = "Authorization: Bearer s3cret-token\r\n";
    let (_, _, body) = request(&addr, "GET", "/state", auth);
    let s: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert!(
        s["per_client"][0]["peer"]
            .as_str()
            .unwrap()
            .starts_with("127.0.0.1:"),
        "{s}"
    );
    drop(viewer);
    // Wrong tokens: five are answered 401, then the address waits (429 + Retry-After),
    // even with the right token, until the wait is over.
    let wrong = "Authorization: Bearer wrong-token\r\n";
    let codes: Vec<u16> = (0..8)
        .map(|_| request(&addr, "POST", "/view?yaw=0&pitch=0", wrong).0)
        .collect();
    assert_eq!(codes, [401, 401, 401, 401, 401, 429, 429, 429], "{codes:?}");
    let (st, head, _) = request(&addr, "POST", "/view?yaw=10&pitch=0", auth);
    assert_eq!(st, 429);
    let retry: u64 = head
        .lines()
        .find_map(|l| {
            l.to_ascii_lowercase()
                .strip_prefix("retry-after:")
                .map(|v| v.trim().parse().unwrap())
        })
        .unwrap();
    assert!((1..=60).contains(&retry), "{head}");
    std::thread::sleep(Duration::from_secs(retry) + Duration::from_millis(200));
    assert_eq!(request(&addr, "POST", "/view?yaw=10&pitch=0", auth).0, 200);
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #6: `/dev/zero` as the scene or the file backend's path passed the check and grew
/// memory by ~1 GB/s. Now refused at once by `--check-config`, naming the file.
#[test]
fn device_files_as_inputs_are_refused_by_the_check() {
    let dir = tmp("dev");
    for (camera, key) in [
        ("backend = \"sim\"\nscene = \"/dev/zero\"", "scene"),
        ("backend = \"file\"\npath = \"/dev/zero\"", "path"),
    ] {
        let cfg = dir.join("b.toml");
        std::fs::write(
            &cfg,
            format!("[camera]\n{camera}\n[render]\nfield = \"camera\"\n[dbus]\nbus = \"none\"\n"),
        )
        .unwrap();
        let t = Instant::now();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_volcapd"))
            .args(["--check-config", "--config"])
            .arg(&cfg)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{key}: {err}");
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "{key}: {:?}",
            t.elapsed()
        );
        assert!(
            err.contains("/dev/zero") && (err.contains("device") || err.contains("regular file")),
            "{key}: {err}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// #8: a folder where every image is bad left the state `starting` with no placeholder and
/// no READY. Now `degraded` with the reason, and a placeholder is published (READY follows
/// the first published frame).
#[test]
fn a_folder_of_bad_images_is_reported_degraded_with_a_placeholder() {
    let _s = serial();
    let dir = tmp("badfolder");
    let imgs = dir.join("imgs");
    std::fs::create_dir_all(&imgs).unwrap();
    for i in 0..3 {
        std::fs::write(
            imgs.join(format!("f{i}.jpg")),
            b"\xFF\xD8\xFFnot really a jpeg",
        )
        .unwrap();
    }
    let cfg = dir.join("b.toml");
    std::fs::write(
        &cfg,
        format!(
            "[camera]\nbackend = \"file\"\npath = \"{}\"\nfps = 20\n[render]\nfield = \"camera\"\n[dbus]\nbus = \"none\"\n",
            imgs.display()
        ),
    )
    .unwrap();
    let (p, addr) = launch(&cfg, &[], &[], false);
    // `showing_placeholder`: a placeholder is published (what READY waits for).
    let s = wait_for(
        &addr,
        "degraded with a reason",
        Duration::from_secs(20),
        |s| s["state"] == "degraded" && s["showing_placeholder"] == true,
    );
    let reason = s["reason"].as_str().unwrap();
    assert!(
        reason.contains("no decodable frame") && reason.contains("imgs"),
        "{s}"
    );
    let (st, _, jpg) = request(&addr, "GET", "/snapshot.jpg", "");
    assert_eq!(st, 200, "the placeholder is served");
    assert!(image::load_from_memory(&jpg).is_ok());
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #9: for a while after start, `/state` said `running` while the sim camera was lost (a
/// frame captured before the unplug was rendered afterwards and painted over the state).
#[test]
fn state_never_says_running_while_the_camera_is_lost() {
    let _s = serial();
    let dir = tmp("lost");
    let scene = std::fs::read_to_string(root().join("tests/scenes/unplug.toml"))
        .unwrap()
        .replace("at_frame = 10", "at_frame = 1");
    std::fs::write(dir.join("scene.toml"), scene).unwrap();
    let cfg = dir.join("b.toml");
    std::fs::write(
        &cfg,
        "[camera]\nbackend = \"sim\"\nscene = \"scene.toml\"\n[dbus]\nbus = \"none\"\n",
    )
    .unwrap();
    let (p, addr) = launch(&cfg, &[], &[], false);
    let t = Instant::now();
    let mut lost_seen = 0;
    while t.elapsed() < Duration::from_secs(5) {
        let s = state(&addr);
        if s["camera"]["state"] == "lost" {
            lost_seen += 1;
            assert_ne!(
                s["state"], "running",
                "running while the camera is lost: {s}"
            );
        }
        std::thread::sleep(Duration::from_millis(40));
    }
    assert!(lost_seen > 10, "the camera was lost for the test");
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}
