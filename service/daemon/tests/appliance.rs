//! volcapd as an appliance service: D-Bus interface on a private bus, the D-Bus policy on a
//! system-like bus, the watchdog harness. Loopback and private buses only. (The unit file,
//! the install script and the board configs: packaging.rs.)

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{Proc, bin, have, root, skip};

/// These tests start daemons and buses: one at a time.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());
fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|p| p.into_inner())
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volcapd-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A private dbus-daemon with `config` (its `<listen>` is filled in); returns the address.
fn bus(dir: &Path, kind: &str, policy: &str) -> (Proc, String) {
    let sock = dir.join(format!("{kind}_bus"));
    let conf = dir.join(format!("{kind}.conf"));
    std::fs::write(
        &conf,
        format!(
            "<!DOCTYPE busconfig PUBLIC \"-//freedesktop//DTD D-Bus Bus Configuration 1.0//EN\"\n \"http://www.freedesktop.org/standards/dbus/1.0/busconfig.dtd\">\n<busconfig>\n<type>{kind}</type>\n<listen>unix:path={}</listen>\n<auth>EXTERNAL</auth>\n{policy}\n</busconfig>\n",
            sock.display()
        ),
    )
    .unwrap();
    let child = Command::new("dbus-daemon")
        .arg(format!("--config-file={}", conf.display()))
        .arg("--nofork")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while !sock.exists() {
        assert!(t.elapsed() < Duration::from_secs(10), "bus did not start");
        std::thread::sleep(Duration::from_millis(20));
    }
    (Proc(child), format!("unix:path={}", sock.display()))
}

/// Start volcapd (stderr kept); returns it and its HTTP address.
fn daemon(config: &Path, args: &[&str], env: &[(&str, &str)]) -> (Proc, String) {
    common::launch(config, args, env, true)
}

fn http_state(addr: &str) -> serde_json::Value {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    write!(
        s,
        "GET /state HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut buf = String::new();
    s.read_to_string(&mut buf).unwrap();
    serde_json::from_str(buf.split("\r\n\r\n").nth(1).unwrap()).unwrap()
}

fn busctl(address: &str, args: &[&str]) -> Output {
    Command::new("busctl")
        .arg(format!("--address={address}"))
        .args(args)
        .output()
        .unwrap()
}

const OBJ: [&str; 3] = [
    "org.volcap.Capture1",
    "/org/volcap/Capture1",
    "org.volcap.Capture1",
];

fn get(address: &str, prop: &str) -> String {
    let o = busctl(address, &[&["get-property"][..], &OBJ, &[prop]].concat());
    assert!(
        o.status.success(),
        "{prop}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).trim().to_string()
}

fn call(address: &str, method: &str, sig_args: &[&str]) -> Output {
    busctl(
        address,
        &[&["call"][..], &OBJ, &[method], sig_args].concat(),
    )
}

fn wait_until(what: &str, timeout: Duration, mut f: impl FnMut() -> bool) {
    let t = Instant::now();
    while !f() {
        assert!(t.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

const OPEN_POLICY: &str = "<policy context=\"default\"><allow send_destination=\"*\" eavesdrop=\"true\"/><allow eavesdrop=\"true\"/><allow own=\"*\"/><allow user=\"*\"/></policy>";

#[test]
fn dbus_properties_methods_errors_and_signals() {
    let _s = serial();
    if !have("dbus-daemon") || !have("busctl") || !have("dbus-monitor") {
        return;
    }
    let dir = tmp("dbus");
    let (_bus, addr) = bus(&dir, "session", OPEN_POLICY);
    let cfg = dir.join("b.toml");
    let scene = root().join("tests/scenes/front-walk.toml");
    let text = format!(
        "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nresolution = 65\nyaw = 0.0\n[dbus]\nbus = \"session\"\n",
        scene.display()
    );
    std::fs::write(&cfg, &text).unwrap();
    let mut monitor = Proc(
        // Line-buffered: the monitor is killed at the end, its output must be out by then.
        Command::new("stdbuf")
            .args(["-oL", "dbus-monitor", "--address", &addr])
            .arg("type='signal',interface='org.freedesktop.DBus.Properties',member='PropertiesChanged'")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let (_d, http) = daemon(&cfg, &[], &[("DBUS_SESSION_BUS_ADDRESS", &addr)]);
    wait_until("running over D-Bus", Duration::from_secs(30), || {
        busctl(&addr, &[&["get-property"][..], &OBJ, &["State"]].concat())
            .stdout
            .starts_with(b"s \"running\"")
    });
    assert_eq!(get(&addr, "Model"), "s \"oracle\"");
    assert_eq!(get(&addr, "Resolution"), "u 65");
    assert_eq!(get(&addr, "CameraConnected"), "b true");
    assert!(
        get(&addr, "Backend").contains("sim:"),
        "{}",
        get(&addr, "Backend")
    );
    wait_until("a frame rate", Duration::from_secs(10), || {
        get(&addr, "Fps")[2..].parse::<f64>().unwrap() > 0.5
    });

    // Arguments are validated; errors are D-Bus errors with messages.
    let o = call(&addr, "SetView", &["ddd", "10", "95", "0"]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("pitch 95") && e.contains("80"), "{e}");
    let o = call(&addr, "SetResolution", &["u", "12"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("5..=9"));
    assert!(
        call(&addr, "SetView", &["ddd", "45", "10", "3"])
            .status
            .success()
    );
    assert!(call(&addr, "SetResolution", &["u", "7"]).status.success());
    assert_eq!(get(&addr, "Resolution"), "u 129");
    // Changes are signalled once a second: let this one go out.
    std::thread::sleep(Duration::from_millis(1200));
    let s = http_state(&http);
    assert_eq!(s["view"]["yaw"], 45.0);
    assert_eq!(s["view"]["distance"], 3.0);

    // Pause / Resume.
    assert!(call(&addr, "Pause", &[]).status.success());
    wait_until("paused", Duration::from_secs(10), || {
        get(&addr, "State") == "s \"paused\""
    });
    assert!(call(&addr, "Resume", &[]).status.success());
    wait_until("running again", Duration::from_secs(10), || {
        get(&addr, "State") == "s \"running\""
    });

    // Snapshot returns PNG bytes.
    let o = call(&addr, "Snapshot", &[]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.starts_with("ay ") && out.contains(" 137 80 78 71 13 10 26 10 "),
        "{}",
        &out[..60.min(out.len())]
    );

    // Reload: a bad file keeps the running config and names the key.
    std::fs::write(&cfg, text.replace("resolution = 65", "resolution = 100")).unwrap();
    let o = call(&addr, "Reload", &[]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("b.toml") && e.contains("line 5") && e.contains("resolution"),
        "{e}"
    );
    assert_eq!(get(&addr, "Resolution"), "u 129", "nothing changed");
    // A good file applies live.
    std::fs::write(&cfg, text.replace("yaw = 0.0", "yaw = 90.0")).unwrap();
    let o = call(&addr, "Reload", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("applied: render"));
    assert_eq!(http_state(&http)["view"]["yaw"], 90.0);
    assert_eq!(get(&addr, "Resolution"), "u 65");
    // The networks are loaded at start: a changed [model] waits for a restart, and says so.
    let with_model = format!(
        "{}[model]\nthin_parts = \"moment-fill\"\n",
        text.replace("yaw = 0.0", "yaw = 90.0")
    );
    std::fs::write(&cfg, with_model).unwrap();
    let o = call(&addr, "Reload", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("needs a restart to take effect: model"),
        "{out}"
    );

    // PropertiesChanged was signalled for the changes above.
    std::thread::sleep(Duration::from_millis(1500));
    let _ = monitor.0.kill();
    let mut seen = String::new();
    monitor
        .0
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut seen)
        .unwrap();
    for p in ["\"State\"", "\"Resolution\"", "\"FramesProcessed\""] {
        assert!(seen.contains(p), "no PropertiesChanged for {p}: {seen}");
    }
    assert!(!seen.contains("\"Uptime\""), "Uptime is not signalled");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn without_a_bus_the_daemon_keeps_running() {
    let _s = serial();
    let cfg = root().join("board-config/sim.toml");
    let (mut d, http) = daemon(
        &cfg,
        &["--bus", "session"],
        &[("DBUS_SESSION_BUS_ADDRESS", "unix:path=/nonexistent/bus")],
    );
    let t = Instant::now();
    while http_state(&http)["frames_published"].as_u64() < Some(3) {
        assert!(t.elapsed() < Duration::from_secs(30));
        std::thread::sleep(Duration::from_millis(200));
    }
    let _ = d.0.kill();
    let mut err = String::new();
    d.0.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert_eq!(
        err.matches("D-Bus (Session bus) unavailable").count(),
        1,
        "{err}"
    );
}

#[test]
fn introspection_xml_is_generated_from_the_code() {
    let o = Command::new(bin())
        .current_dir(root())
        .args(["--print-introspection", "--config", "board-config/sim.toml"])
        .output()
        .unwrap();
    assert!(o.status.success());
    let generated = String::from_utf8(o.stdout).unwrap();
    let file = root().join("systemd/org.volcap.Capture1.xml");
    if std::env::var("VOLCAP_UPDATE_SNAPSHOTS").is_ok() {
        std::fs::write(&file, &generated).unwrap();
    }
    let committed = std::fs::read_to_string(&file).unwrap();
    assert_eq!(
        generated, committed,
        "the interface changed: run with VOLCAP_UPDATE_SNAPSHOTS=1 and commit systemd/org.volcap.Capture1.xml"
    );
    for m in [
        "SetView",
        "SetResolution",
        "Pause",
        "Resume",
        "Reload",
        "Snapshot",
        "LatencyP99Ms",
        "CameraConnected",
    ] {
        assert!(committed.contains(&format!("name=\"{m}\"")), "{m}");
    }
}

/// The policy on a system-like bus: only the service user owns the name; everyone reads
/// properties; control methods only for root and the volcap group. Needs root (to run
/// processes as other users) and the `volcap` user (`.ci/run` creates it from
/// systemd/volcap.sysusers).
#[test]
fn dbus_policy_on_a_system_like_bus() {
    let _s = serial();
    if !have("dbus-daemon") || !have("busctl") || !have("setpriv") {
        return;
    }
    let is_root = Command::new("id").arg("-u").output().unwrap().stdout == b"0\n";
    let has_user = Command::new("id")
        .arg("volcap")
        .output()
        .unwrap()
        .status
        .success();
    if !(is_root && has_user) {
        skip("needs root and the volcap user (systemd-sysusers systemd/volcap.sysusers)");
        return;
    }
    let dir = tmp("policy");
    let policy = std::fs::read_to_string(root().join("systemd/org.volcap.Capture1.conf")).unwrap();
    let inner = policy
        .split("<busconfig>")
        .nth(1)
        .and_then(|s| s.split("</busconfig>").next())
        .unwrap();
    // Debian's system.conf default policy, then ours.
    let system = format!(
        "<policy context=\"default\"><allow user=\"*\"/><deny own=\"*\"/><deny send_type=\"method_call\"/><allow send_type=\"signal\"/><allow send_requested_reply=\"true\" send_type=\"method_return\"/><allow send_requested_reply=\"true\" send_type=\"error\"/><allow receive_type=\"method_call\"/><allow receive_type=\"method_return\"/><allow receive_type=\"error\"/><allow receive_type=\"signal\"/><allow send_destination=\"org.freedesktop.DBus\" send_interface=\"org.freedesktop.DBus\"/><allow send_destination=\"org.freedesktop.DBus\" send_interface=\"org.freedesktop.DBus.Introspectable\"/><allow send_destination=\"org.freedesktop.DBus\" send_interface=\"org.freedesktop.DBus.Properties\"/></policy>\n{inner}"
    );
    let (_bus, addr) = bus(&dir, "system", &system);
    let sock = addr.trim_start_matches("unix:path=");
    Command::new("chmod").args(["0666", sock]).status().unwrap();
    Command::new("chmod")
        .args(["0755"])
        .arg(&dir)
        .status()
        .unwrap();
    // Files the other users run and read.
    std::fs::copy(bin(), dir.join("volcapd")).unwrap();
    std::fs::copy(
        root().join("tests/scenes/front-walk.toml"),
        dir.join("scene.toml"),
    )
    .unwrap();
    std::fs::write(
        dir.join("b.toml"),
        "[camera]\nbackend = \"sim\"\nscene = \"scene.toml\"\n[render]\nresolution = 33\ncoarse_level = 2\n[dbus]\nbus = \"system\"\n",
    )
    .unwrap();
    Command::new("chmod")
        .args(["0755"])
        .arg(dir.join("volcapd"))
        .status()
        .unwrap();
    Command::new("chmod")
        .args(["0644"])
        .arg(dir.join("b.toml"))
        .arg(dir.join("scene.toml"))
        .status()
        .unwrap();
    let run_as = |user: &str, group: &str, prog: &Path, args: &[&str]| {
        let mut c = Command::new("setpriv");
        c.arg(format!("--reuid={user}"))
            .arg(format!("--regid={group}"))
            .arg("--clear-groups")
            .arg(prog)
            .args(args)
            .env("DBUS_SYSTEM_BUS_ADDRESS", &addr);
        c
    };
    let cfg = dir.join("b.toml");
    let volcapd_as = |user: &str, group: &str, stderr: Stdio| {
        run_as(
            user,
            group,
            &dir.join("volcapd"),
            &["--config", cfg.to_str().unwrap(), "--http", "127.0.0.1:0"],
        )
        .stdout(Stdio::null())
        .stderr(stderr)
        .spawn()
        .unwrap()
    };
    // nobody cannot own the name: the daemon logs it and keeps serving HTTP.
    let mut intruder = volcapd_as("nobody", "nogroup", Stdio::piped());
    let mut line = String::new();
    let mut err = BufReader::new(intruder.stderr.take().unwrap());
    let t = Instant::now();
    while !line.contains("D-Bus") {
        line.clear();
        err.read_line(&mut line).unwrap();
        assert!(t.elapsed() < Duration::from_secs(30), "no D-Bus line");
    }
    let _ = intruder.kill();
    let _ = intruder.wait();
    println!("volcapd as nobody: {}", line.trim());
    assert!(
        line.contains("unavailable")
            && (line.contains("AccessDenied") || line.contains("not allowed")),
        "{line}"
    );
    // The service user owns it.
    let _owner = Proc(volcapd_as("volcap", "volcap", Stdio::null()));
    wait_until("name owned", Duration::from_secs(30), || {
        busctl(&addr, &[&["get-property"][..], &OBJ, &["State"]].concat())
            .status
            .success()
    });
    let busctl_bin = PathBuf::from("/usr/bin/busctl");
    let as_nobody = |args: &[&str]| {
        run_as(
            "nobody",
            "nogroup",
            &busctl_bin,
            &[&[format!("--address={addr}").as_str()][..], args].concat(),
        )
        .output()
        .unwrap()
    };
    // Everyone reads health.
    let o = as_nobody(&[&["get-property"][..], &OBJ, &["State"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Control is denied to an unauthorized uid...
    let o = as_nobody(&[&["call"][..], &OBJ, &["SetResolution", "u", "6"]].concat());
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("Access denied") || e.contains("AccessDenied") || e.contains("not allowed"),
        "{e}"
    );
    // ... and allowed to the volcap group and to root.
    let o = run_as(
        "nobody",
        "volcap",
        &busctl_bin,
        &[
            &[format!("--address={addr}").as_str()][..],
            &["call"],
            &OBJ,
            &["SetResolution", "u", "6"],
        ]
        .concat(),
    )
    .output()
    .unwrap();
    assert!(
        o.status.success(),
        "volcap group: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(call(&addr, "SetResolution", &["u", "5"]).status.success());
    assert_eq!(get(&addr, "Resolution"), "u 33");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn watchdog_pings_follow_pipeline_progress() {
    let _s = serial();
    let dir = tmp("watchdog");
    std::fs::write(
        dir.join("scene.toml"),
        "[camera]\nwidth = 96\nheight = 96\nfps = 15\n[[subject]]\nid = \"a\"\noutfit = \"male_casualsuit02\"\nmotion = { kind = \"procedural\", style = \"walk\" }\n[[effect]]\nhang = { at_frame = 45 }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("b.toml"),
        "[camera]\nbackend = \"sim\"\nscene = \"scene.toml\"\n[render]\nresolution = 33\ncoarse_level = 2\n[dbus]\nbus = \"none\"\n",
    )
    .unwrap();
    let sock_path = dir.join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let started = Instant::now();
    let (_d, http) = daemon(
        &dir.join("b.toml"),
        &[],
        &[
            ("NOTIFY_SOCKET", sock_path.to_str().unwrap()),
            ("WATCHDOG_USEC", "400000"),
        ],
    );
    let mut ready_at = None;
    let mut pings = Vec::new();
    let mut statuses = Vec::new();
    let mut buf = [0u8; 4096];
    let mut frames_at_ready = None;
    while started.elapsed() < Duration::from_secs(9) {
        let Ok(n) = sock.recv(&mut buf) else { continue };
        let msg = String::from_utf8_lossy(&buf[..n]).to_string();
        let t = started.elapsed().as_secs_f64();
        for line in msg.lines() {
            match line {
                "READY=1" => {
                    ready_at = Some(t);
                    frames_at_ready =
                        Some(http_state(&http)["frames_published"].as_u64().unwrap_or(0));
                }
                "WATCHDOG=1" => pings.push(t),
                l if l.starts_with("STATUS=") => statuses.push((t, l.to_string())),
                _ => {}
            }
        }
    }
    let ready = ready_at.expect("READY=1 was sent");
    assert!(
        frames_at_ready >= Some(1),
        "READY before the first frame: {frames_at_ready:?}"
    );
    println!("READY at {ready:.2} s; pings at {pings:.2?}");
    println!("statuses: {statuses:?}");
    // The hang is at frame 45 of a 15 fps scene: 3 s after the camera started.
    let before: Vec<f64> = pings.iter().copied().filter(|&t| t < ready + 2.0).collect();
    assert!(before.len() >= 6, "regular pings while running: {pings:?}");
    let gaps: Vec<f64> = before.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(
        gaps.iter().all(|&g| g < 0.5),
        "pings every ~0.2 s: {gaps:?}"
    );
    let last = *pings.last().unwrap();
    assert!(
        started.elapsed().as_secs_f64() - last > 3.0,
        "pings stopped after the stall (last at {last:.2} s)"
    );
    // The async runtime is alive (HTTP answers) but did not feed the dog.
    assert!(http_state(&http)["uptime_s"].as_f64().unwrap() > 5.0);
    assert!(
        statuses.iter().any(|(_, s)| s.contains("stalled: capture")),
        "{statuses:?}"
    );
    assert!(
        statuses
            .iter()
            .any(|(_, s)| s.starts_with("STATUS=running")),
        "{statuses:?}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
