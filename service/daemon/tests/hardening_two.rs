//! Hardening, round two (issue #36): what a black-box probe of the daemon still found. Each
//! test failed on the daemon before its fix. Loopback only, bounded in count and time.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::os::unix::net::UnixDatagram;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

mod common;
use common::{
    alive, connect_from, launch, launch_publishing, proc_status, request, serial, signal,
    sim_config, state, tmp, trickling, wait_for,
};

/// `volcapd` threads whose name is `name` (`/proc/PID/task/*/comm`).
/// The niceness of each of `pid`'s threads named `name` (field 19 of `/proc/PID/task/TID/stat`,
/// counted after the `(comm)` field, which may hold spaces).
fn nice_of_threads(pid: u32, name: &str) -> Vec<i64> {
    let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return Vec::new();
    };
    dir.filter_map(|e| e.ok())
        .filter(|e| std::fs::read_to_string(e.path().join("comm")).is_ok_and(|c| c.trim() == name))
        .filter_map(|e| {
            let stat = std::fs::read_to_string(e.path().join("stat")).ok()?;
            // After "pid (comm) ": state is field 3, nice field 19.
            let rest = &stat[stat.rfind(')')? + 2..];
            rest.split_whitespace().nth(16)?.parse().ok()
        })
        .collect()
}

fn threads_named(pid: u32, name: &str) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/task"))
        .map(|d| {
            d.filter_map(|e| e.ok())
                .filter(|e| {
                    std::fs::read_to_string(e.path().join("comm")).is_ok_and(|c| c.trim() == name)
                })
                .count()
        })
        .unwrap_or(0)
}

/// Frames published per second over `secs`.
fn fps(addr: &str, secs: f64) -> f64 {
    let a = state(addr)["frames_published"].as_u64().unwrap();
    std::thread::sleep(Duration::from_secs_f64(secs));
    let b = state(addr)["frames_published"].as_u64().unwrap();
    (b - a) as f64 / secs
}

/// `n` requests for `/mesh.glb`, each abandoned `after` its head was sent, from one address;
/// meanwhile the peak RSS (kB), the most mesh threads seen at once, the most threads and the
/// most computations running at once (`volcap_mesh_busy`).
fn abandon_meshes(addr: &str, pid: u32, n: usize, after: Duration) -> (u64, usize, u64, u64) {
    let (mut rss, mut mesh, mut threads, mut busy) = (0u64, 0usize, 0u64, 0u64);
    let status = |key: &str| -> u64 {
        std::fs::read_to_string(format!("/proc/{pid}/status"))
            .unwrap_or_default()
            .lines()
            .find(|l| l.starts_with(key))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    for _ in 0..n {
        let mut s = TcpStream::connect(addr).unwrap();
        write!(s, "GET /mesh.glb HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
        std::thread::sleep(after);
        drop(s);
        rss = rss.max(status("VmRSS:"));
        threads = threads.max(status("Threads:"));
        mesh = mesh.max(threads_named(pid, "volcap-mesh"));
        busy = busy.max(mesh_metric(addr, "volcap_mesh_busy"));
    }
    (rss, mesh, threads, busy)
}

/// A line of `/metrics` (`NAME VALUE`), as an integer.
fn mesh_metric(addr: &str, name: &str) -> u64 {
    let (st, _, body) = request(addr, "GET", "/metrics", "");
    assert_eq!(st, 200);
    String::from_utf8_lossy(&body)
        .lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
        .unwrap_or_else(|| panic!("/metrics has no {name}"))
}

/// Collects `WATCHDOG=1` times and `STATUS=` lines from a NOTIFY_SOCKET until dropped.
struct Notify {
    pings: Arc<Mutex<Vec<Instant>>>,
    statuses: Arc<Mutex<Vec<String>>>,
    stop: Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Notify {
    fn bind(path: &std::path::Path) -> Self {
        let sock = UnixDatagram::bind(path).unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
        let pings: Arc<Mutex<Vec<Instant>>> = Arc::default();
        let statuses: Arc<Mutex<Vec<String>>> = Arc::default();
        let stop: Arc<std::sync::atomic::AtomicBool> = Arc::default();
        let (p, st, halt) = (pings.clone(), statuses.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while !halt.load(std::sync::atomic::Ordering::Relaxed) {
                let Ok(n) = sock.recv(&mut buf) else { continue };
                for line in String::from_utf8_lossy(&buf[..n]).lines() {
                    if line == "WATCHDOG=1" {
                        p.lock().unwrap().push(Instant::now());
                    } else if let Some(s) = line.strip_prefix("STATUS=") {
                        st.lock().unwrap().push(s.to_string());
                    }
                }
            }
        });
        Self {
            pings,
            statuses,
            stop,
            thread: Some(thread),
        }
    }

    /// The longest gap between pings since `from` (or from `from` to the first/last ping).
    fn longest_gap(&self, from: Instant) -> Duration {
        let mut t: Vec<Instant> = self
            .pings
            .lock()
            .unwrap()
            .iter()
            .copied()
            .filter(|&t| t >= from)
            .collect();
        t.insert(0, from);
        t.push(Instant::now());
        t.windows(2).map(|w| w[1] - w[0]).max().unwrap_or_default()
    }
}

impl Drop for Notify {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// #1 (HIGH): the `/mesh.glb` permit was released when the client left while the
/// computation went on, so abandoned requests stacked computations: 300 at 257^3 from one
/// address took RSS to 1.2 GB, 93 threads, 4 frames in 40 s and a 10 s watchdog gap. Now the
/// permit lives as long as the computation, leaving cancels it, and it runs at a lower
/// priority on one thread of its own. Times are measured against yardsticks of the same run
/// (a whole mesh, the frame rate before), not wall-clock constants: CI's shared vCPUs and a
/// machine busy beside the test stretch both sides alike.
#[test]
fn abandoned_mesh_requests_neither_stack_nor_starve_the_pipeline() {
    let _s = serial();
    let dir = tmp("mesh2");
    let cfg = sim_config(
        &dir,
        257,
        "[http]\nper_address_limit = 1000\ntoken = \"mesh-test-token\"\n",
    );
    let sock = dir.join("notify.sock");
    let notify = Notify::bind(&sock);
    let (mut p, addr) = launch(
        &cfg,
        &[],
        &[
            ("NOTIFY_SOCKET", sock.to_str().unwrap()),
            ("WATCHDOG_USEC", "2000000"),
        ],
        false,
    );
    let pid = p.0.id();
    wait_for(&addr, "frames", Duration::from_secs(60), |s| {
        s["frames_published"].as_u64() > Some(3)
    });
    let before = fps(&addr, 3.0);
    let (threads0, rss0) = (proc_status(&p, "Threads:"), proc_status(&p, "VmRSS:"));
    // The yardstick of "stops early": one whole mesh at 257^3 under the same load (the
    // pipeline running beside it, the mesh thread at its lower priority).
    let t = Instant::now();
    let (st, head, glb) = request(&addr, "GET", "/mesh.glb", "");
    assert_eq!(st, 200, "{head}");
    assert_eq!(&glb[..4], b"glTF");
    let whole = t.elapsed();
    // One request kept open: a mesh is computed on one thread, and a second request
    // meanwhile is told to come back. Abandoned, the computation stops (the worker is free
    // again well before a 257^3 mesh would be done) and no second one ever runs beside it.
    // On a fast machine the kept mesh can end before the client leaves (CI saw done 2,
    // cancelled 0): such a try proves nothing and is made again on a newer frame; a try
    // counts only when the mesh was still running just before the client left.
    let mut own_thread = 0;
    let mut cancelled_in = None;
    let mut raced = 0;
    for _try in 0..5 {
        // A new frame, so that the request computes instead of reading the cache.
        let n = state(&addr)["frames_published"].as_u64().unwrap();
        wait_for(&addr, "a new frame", Duration::from_secs(30), |s| {
            s["frames_published"].as_u64() > Some(n)
        });
        let done0 = mesh_metric(&addr, "volcap_mesh_total{result=\"done\"}");
        let ended = |addr: &str| mesh_metric(addr, "volcap_mesh_total{result=\"done\"}") > done0;
        let mut a = TcpStream::connect(&addr).unwrap();
        write!(a, "GET /mesh.glb HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
        let t = Instant::now();
        while mesh_metric(&addr, "volcap_mesh_busy") == 0
            && !ended(&addr)
            && t.elapsed() < Duration::from_secs(5)
        {
            std::thread::sleep(Duration::from_millis(5));
        }
        own_thread = threads_named(pid, "volcap-mesh");
        let (st, head, _) = request(&addr, "GET", "/mesh.glb", "");
        if ended(&addr) {
            raced += 1;
            drop(a);
            continue;
        }
        assert_eq!(st, 503, "a second mesh beside the first: {head}");
        drop(a);
        let t = Instant::now();
        while mesh_metric(&addr, "volcap_mesh_busy") > 0 && t.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(20));
        }
        cancelled_in = Some(t.elapsed());
        break;
    }
    let cancelled_in = cancelled_in.unwrap_or_else(|| {
        panic!("every kept mesh ended before its client left ({whole:?} a mesh)")
    });
    assert_eq!(
        mesh_metric(&addr, "volcap_mesh_total{result=\"cancelled\"}"),
        1,
        "the kept mesh was still running when its client left, {cancelled_in:?} before it was free"
    );
    assert_eq!(
        mesh_metric(&addr, "volcap_mesh_total{result=\"done\"}"),
        1 + raced
    );
    let from = Instant::now();
    let frames0 = state(&addr)["frames_published"].as_u64().unwrap();
    let (rss, mesh, threads, busy) = abandon_meshes(&addr, pid, 300, Duration::from_millis(20));
    std::thread::sleep(Duration::from_secs(3));
    // Frames a second over the storm and the three seconds after it.
    let during = (state(&addr)["frames_published"].as_u64().unwrap() - frames0) as f64
        / from.elapsed().as_secs_f64();
    let gap = notify.longest_gap(from);
    let nice = nice_of_threads(pid, "volcap-mesh");
    eprintln!(
        "257^3: a whole mesh in {whole:?}, an abandoned one cancelled in {cancelled_in:?} (tries where the mesh ended first: {raced}); 300 abandoned: RSS {} -> peak {} MB, threads {threads0} -> {threads}, \
         mesh threads at once {mesh}, fps {before:.1} -> {during:.1}, longest watchdog gap {gap:?}",
        rss0 / 1024,
        rss / 1024
    );
    assert!(threads <= threads0 + 2, "threads {threads0} -> {threads}");
    assert!(rss < 600 * 1024, "peak RSS {} MB", rss / 1024);
    // Not starved: the pipeline goes on publishing. The bug this guards against took it to
    // 4 frames in 40 s; a quarter of the rate before leaves room for a shared CI machine's
    // noise (a vCPU's steal time is not ours to measure), while the mesh thread's niceness
    // below is the deterministic half of the property.
    assert!(during >= before / 4.0, "fps {before:.1} -> {during:.1}");
    assert_eq!(
        nice,
        vec![i64::from(volcapd::http::MESH_NICE)],
        "the mesh thread runs at a lower priority than the pipeline"
    );
    assert!(gap < Duration::from_secs(5), "watchdog gap {gap:?}");
    assert_eq!(own_thread, 1, "the mesh runs on its own thread");
    assert!(mesh <= 1, "{mesh} mesh threads at once");
    assert!(busy <= 1, "{busy} mesh computations at once");
    assert!(
        cancelled_in < whole / 2,
        "an abandoned mesh ran on for {cancelled_in:?}, a whole one takes {whole:?}"
    );
    assert!(
        !notify
            .statuses
            .lock()
            .unwrap()
            .iter()
            .any(|s| s.starts_with("stalled")),
        "{:?}",
        notify.statuses.lock().unwrap()
    );
    // 513^3 (set live, as a LAN client with the token could): bounded too.
    let auth = "Authorization: Bearer mesh-test-token\r\n";
    let (st, _, body) = request(&addr, "POST", "/view?yaw=0&pitch=0&resolution=513", auth);
    assert_eq!(st, 200, "{}", String::from_utf8_lossy(&body));
    wait_for(&addr, "513^3 frames", Duration::from_secs(60), |s| {
        s["resolution"] == 513
    });
    let rss513 = proc_status(&p, "VmRSS:");
    let (peak, mesh, _, busy) = abandon_meshes(&addr, pid, 100, Duration::from_millis(50));
    eprintln!(
        "513^3: 100 abandoned: RSS {} -> peak {} MB, mesh threads at once {mesh}, computations at once {busy}",
        rss513 / 1024,
        peak / 1024
    );
    assert!(
        mesh <= 1 && busy <= 1,
        "{mesh} mesh threads, {busy} computations at once"
    );
    // One mesh grid at 513^3 is 540 MB: at most one beside the render's own memory.
    assert!(
        peak < rss513 + 900 * 1024,
        "RSS {} -> {} MB",
        rss513 / 1024,
        peak / 1024
    );
    assert!(alive(&mut p));
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #3 (LOW): the config file skipped the checks that scenes get: `/dev/zero` was read until
/// memory ran out, a FIFO hung `--check-config`, and a live config replaced by a FIFO made
/// every SIGHUP block for good (a thread leaked per attempt, later reloads never ran).
#[test]
fn the_config_file_is_read_like_a_scene_file() {
    let _s = serial();
    let dir = tmp("cfgfile");
    let fifo = dir.join("fifo.toml");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    for (cfg, says) in [
        (std::path::PathBuf::from("/dev/zero"), "device"),
        (fifo.clone(), "FIFO"),
    ] {
        let t = Instant::now();
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_volcapd"))
            .args(["--check-config", "--config"])
            .arg(&cfg)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        while child.try_wait().unwrap().is_none() && t.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(20));
        }
        let done = child.try_wait().unwrap();
        if done.is_none() {
            let _ = child.kill();
        }
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(done.and_then(|s| s.code()), Some(2), "{cfg:?}: {err}");
        assert!(
            t.elapsed() < Duration::from_secs(2),
            "{cfg:?}: {:?}",
            t.elapsed()
        );
        assert!(
            err.contains(&cfg.display().to_string()) && err.contains(says),
            "{cfg:?}: {err}"
        );
    }
    // A running daemon whose config file becomes a FIFO: reloads are refused at once, and
    // the next good file is applied.
    let cfg = sim_config(&dir, 65, "");
    let (mut p, addr) = launch_publishing(&cfg, 0);
    let threads0 = proc_status(&p, "Threads:");
    std::fs::remove_file(&cfg).unwrap();
    std::fs::rename(&fifo, &cfg).unwrap();
    for _ in 0..5 {
        signal(&p, "HUP");
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(300));
    let threads1 = proc_status(&p, "Threads:");
    std::fs::remove_file(&cfg).unwrap();
    sim_config(&dir, 33, "");
    signal(&p, "HUP");
    wait_for(
        &addr,
        "the good file applied after the FIFO",
        Duration::from_secs(10),
        |s| s["resolution"] == 33,
    );
    assert!(alive(&mut p));
    assert!(
        threads1 <= threads0 + 1,
        "threads {threads0} -> {threads1} after reloads of a FIFO"
    );
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// The status line of a raw HTTP/1.x request `text` (sent as is, answer read to the end).
fn raw(addr: &str, text: &str) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(text.as_bytes()).unwrap();
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    String::from_utf8_lossy(&buf)
        .lines()
        .next()
        .unwrap_or("")
        .to_string()
}

/// #4 (LOW): only the first `Host` was checked, HTTP/1.1 without `Host` was served, and an
/// absolute-form target naming another host was served. #5: `bearer` in lower case was
/// refused, `yaw=inf` was reported as NaN, `HEAD /mesh.glb` claimed a length of 0.
#[test]
fn host_rules_bearer_scheme_yaw_and_mesh_head() {
    let _s = serial();
    let dir = tmp("host2");
    let cfg = sim_config(&dir, 33, "[http]\ntoken = \"host-test-token\"\n");
    let (p, addr) = launch_publishing(&cfg, 0);
    let code = |text: &str| {
        raw(&addr, text)
            .split_whitespace()
            .nth(1)
            .unwrap_or("")
            .to_string()
    };
    let cases = [
        (
            "GET /state HTTP/1.1\r\nHost: 127.0.0.1\r\nHost: evil.example\r\nConnection: close\r\n\r\n",
            "400",
        ),
        (
            "GET /state HTTP/1.1\r\nHost: 127.0.0.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n",
            "400",
        ),
        ("GET /state HTTP/1.1\r\nConnection: close\r\n\r\n", "400"),
        ("GET /state HTTP/1.0\r\n\r\n", "200"),
        (
            "GET http://evil.example/state HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n",
            "421",
        ),
        (
            "GET http://127.0.0.1/state HTTP/1.1\r\nHost: evil.example\r\nConnection: close\r\n\r\n",
            "421",
        ),
        (
            "GET http://127.0.0.1/state HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n",
            "200",
        ),
        (
            "GET /state HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n",
            "200",
        ),
    ];
    for (text, want) in cases {
        assert_eq!(code(text), want, "{text:?}");
    }
    for scheme in ["bearer", "BEARER", "Bearer"] {
        let auth = format!("Authorization: {scheme} host-test-token\r\n");
        let (st, _, body) = request(&addr, "POST", "/view?yaw=10&pitch=0", &auth);
        assert_eq!(st, 200, "{scheme}: {}", String::from_utf8_lossy(&body));
    }
    let auth = "Authorization: Bearer host-test-token\r\n";
    let (st, _, body) = request(&addr, "POST", "/view?yaw=inf&pitch=0", auth);
    let body = String::from_utf8_lossy(&body);
    assert_eq!(st, 400, "{body}");
    assert!(body.contains("yaw inf") && !body.contains("NaN"), "{body}");
    let (st, head, _) = request(&addr, "HEAD", "/mesh.glb", "");
    assert_eq!(st, 200, "{head}");
    assert!(
        !head.to_ascii_lowercase().contains("content-length: 0"),
        "a HEAD that claims an empty mesh: {head}"
    );
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #5 (LOW): tokens that can never be sent (whitespace only, CR/LF) were accepted in the
/// config.
#[test]
fn unsendable_tokens_are_refused_by_the_check() {
    let dir = tmp("token2");
    for token in ["\"          \"", "\"abc\\r\\ndefghij\"", "\"has a space\""] {
        let cfg = sim_config(&dir, 33, &format!("[http]\ntoken = {token}\n"));
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_volcapd"))
            .args(["--check-config", "--config"])
            .arg(&cfg)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{token}: {err}");
        assert!(
            err.contains("line 9") && err.contains("http.token") && err.contains("visible ASCII"),
            "{token}: {err}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// #5 (LOW): the daemon accepted a 40+ MP frame that `volcap reconstruct` refuses (one
/// limit for both now), and said the camera was "opening" while every frame was skipped.
#[test]
fn oversized_frames_are_refused_and_the_camera_says_skipping() {
    let _s = serial();
    let dir = tmp("bigframe");
    let imgs = dir.join("imgs");
    std::fs::create_dir_all(&imgs).unwrap();
    // 7000 x 6000 = 42 MP (every side under 8192): grey, so the file stays small.
    image::GrayImage::new(7000, 6000)
        .save(imgs.join("big.png"))
        .unwrap();
    let cfg = dir.join("b.toml");
    std::fs::write(
        &cfg,
        format!(
            "[camera]\nbackend = \"file\"\npath = \"{}\"\nfps = 5\n[render]\nfield = \"camera\"\n[dbus]\nbus = \"none\"\n",
            imgs.display()
        ),
    )
    .unwrap();
    let (p, addr) = launch(&cfg, &[], &[], false);
    let s = wait_for(&addr, "the camera skipping", Duration::from_secs(30), |s| {
        s["camera"]["state"] == "skipping"
    });
    let reason = s["camera"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("7000x6000") && reason.contains("40 MP"),
        "{s}"
    );
    assert_eq!(s["camera"]["frames"], 0, "{s}");
    assert_ne!(s["state"], "running", "{s}");
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}

/// #6 (design): 10 addresses could fill the 80 connections, leaving nothing for a local
/// viewer or health check; wrong tokens spread over 100 addresses got 500 guesses in
/// 0.04 s. Now connections are kept for this machine (`http.reserved_for`) and wrong tokens
/// from all addresses spend one budget.
#[test]
fn a_reserve_for_this_machine_and_one_guess_budget() {
    let _s = serial();
    let dir = tmp("reserve");
    let cfg = sim_config(
        &dir,
        33,
        "[http]\nper_address_limit = 8\nclient_limit = 16\nheader_timeout_s = 60\ntoken = \"reserve-token\"\n",
    );
    let (p, addr) = launch_publishing(&cfg, 0);
    // 10 LAN hosts (127.0.0.2..=11 stand in) x 8 trickling connections = the 80 of the cap.
    let hog: Vec<TcpStream> = (2..12)
        .flat_map(|h| trickling(&addr, &format!("127.0.0.{h}"), 8))
        .collect();
    assert_eq!(hog.len(), 80);
    // Another LAN host finds the server full (once the server has taken in the hogs).
    let state_from = |from: &str| {
        let Ok(mut s) = connect_from(&addr, from, None) else {
            return false;
        };
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let _ = write!(
            s,
            "GET /state HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
        );
        let mut buf = String::new();
        let _ = s.read_to_string(&mut buf);
        buf.starts_with("HTTP/1.1 200")
    };
    let t = Instant::now();
    while state_from("127.0.0.40") {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "the cap never held for other hosts"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    // ...this machine still gets in.
    let served = (0..5).filter(|_| state_from("127.0.0.1")).count();
    eprintln!(
        "{} hog connections; this machine served {served} of 5",
        hog.len()
    );
    assert_eq!(served, 5);
    drop(hog);
    std::thread::sleep(Duration::from_millis(300));
    // Wrong tokens from 100 addresses, 5 each (each under its own back-off's free five).
    let t = Instant::now();
    let mut checked = 0;
    let mut refused = 0;
    for h in 0..100u32 {
        let from = format!("127.0.1.{}", h + 1);
        for _ in 0..5 {
            let mut s = connect_from(&addr, &from, None).unwrap();
            s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
            write!(
                s,
                "POST /view?yaw=0&pitch=0 HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer wrong-{h}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
            )
            .unwrap();
            let mut buf = String::new();
            let _ = s.read_to_string(&mut buf);
            match buf.split_whitespace().nth(1) {
                Some("401") => checked += 1,
                Some("429") => refused += 1,
                other => panic!("{other:?}: {buf}"),
            }
        }
    }
    let secs = t.elapsed().as_secs_f64();
    eprintln!(
        "500 wrong tokens from 100 addresses in {secs:.2} s: {checked} checked, {refused} refused"
    );
    assert!(
        (checked as f64) <= 30.0 + secs * 1.0 + 2.0,
        "{checked} guesses checked in {secs:.2} s"
    );
    drop(p);
    std::fs::remove_dir_all(&dir).ok();
}
