//! Helpers shared by the daemon's integration tests.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The volcapd built for these tests.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_volcapd")
}

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A child process killed and reaped when dropped.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Start volcapd on a free loopback port with `config`, extra arguments and environment;
/// returns it and the HTTP address it printed. Its stderr is piped when `keep_stderr`.
pub fn launch(
    config: &Path,
    args: &[&str],
    env: &[(&str, &str)],
    keep_stderr: bool,
) -> (Proc, String) {
    // Kept in a file unless piped, so that a daemon that dies mid-test says why ([`request`]).
    let (err, log) = if keep_stderr {
        (Stdio::piped(), None)
    } else {
        stderr_log()
    };
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_volcapd"));
    cmd.current_dir(root())
        .arg("--config")
        .arg(config)
        .args(["--http", "127.0.0.1:0"])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(err);
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|s| s.split('/').next())
        .unwrap_or_else(|| panic!("no URL in {line:?}"))
        .to_string();
    if let Some(log) = log {
        LOGS.lock().unwrap().push((addr.clone(), child.id(), log));
    }
    (Proc(child), addr)
}

/// The stderr file of every daemon launched: (HTTP address, pid, file).
static LOGS: std::sync::Mutex<Vec<(String, u32, PathBuf)>> = std::sync::Mutex::new(Vec::new());

fn stderr_log() -> (Stdio, Option<PathBuf>) {
    static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("volcapd-test-{}-{n}.stderr", std::process::id()));
    match std::fs::File::create(&path) {
        Ok(f) => (f.into(), Some(path)),
        Err(_) => (Stdio::null(), None),
    }
}

/// What is known of the daemon launched at `addr`: whether its process is still there and
/// the end of its stderr (for a connection it refused).
fn daemon_note(addr: &str) -> String {
    let logs = LOGS.lock().unwrap();
    let Some((_, pid, log)) = logs.iter().rev().find(|(a, _, _)| a == addr) else {
        return String::new();
    };
    // /proc/PID/stat after the command's ")": field 3 the state, the last (52) the exit
    // code as waitpid reports it, readable while the process is a zombie.
    let state = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            let rest = s.rsplit(") ").next()?.to_string();
            let state = rest.chars().next()?;
            let code: Option<i32> = rest.split_whitespace().last()?.parse().ok();
            Some((state, code))
        })
        .map(|(c, code)| match (c, code) {
            ('Z', Some(code)) if code & 0x7f != 0 => {
                format!("was killed by signal {} (not yet reaped)", code & 0x7f)
            }
            ('Z', Some(code)) => format!("has exited with status {}", (code >> 8) & 0xff),
            ('Z', None) => "has exited (not yet reaped)".to_string(),
            (c, _) => format!("is running (state {c})"),
        })
        .unwrap_or_else(|| "is gone".into());
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let tail: Vec<&str> = text.lines().rev().take(30).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    format!(
        "; volcapd (pid {pid}) {state}; the end of its stderr ({}):\n{}",
        log.display(),
        tail.join("\n")
    )
}

/// A tool a test needs: on the PATH, or the test is skipped ([`skip`]: a failure in CI).
pub fn have(tool: &str) -> bool {
    let ok = Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        skip(&format!("{tool} is not installed (.ci/run installs it)"));
    }
    ok
}

/// A test whose prerequisite is missing: under `CI` a failure; elsewhere it says so on
/// the terminal, past the test harness's capture (which would hide an `eprintln!` of a
/// passing test), so that the run's output shows what was not tested. The caller returns.
pub fn skip(why: &str) {
    let name = std::thread::current()
        .name()
        .unwrap_or("this test")
        .to_string();
    assert!(
        std::env::var("CI").is_err(),
        "{name}: required in CI, but {why}"
    );
    let _ = writeln!(std::io::stderr().lock(), "SKIPPED {name}: {why}");
}

/// Minimal HTTP/1.1 request on loopback: (status, head, body; chunked bodies joined). A
/// connection closed without a response head gives status 0.
pub fn request(addr: &str, method: &str, path: &str, extra: &str) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr)
        .unwrap_or_else(|e| panic!("connecting to volcapd at {addr}: {e}{}", daemon_note(addr)));
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: 0\r\n{extra}\r\n"
    )
    .unwrap();
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    let Some(split) = buf.windows(4).position(|w| w == b"\r\n\r\n") else {
        return (0, String::new(), buf);
    };
    let head = String::from_utf8_lossy(&buf[..split]).to_string();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let mut body = buf[split + 4..].to_vec();
    if head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        body = dechunk(&body);
    }
    (status, head, body)
}

pub fn state(addr: &str) -> serde_json::Value {
    let (st, _, body) = request(addr, "GET", "/state", "");
    assert_eq!(st, 200, "{}", String::from_utf8_lossy(&body));
    serde_json::from_slice(&body).unwrap()
}

pub fn wait_for(
    addr: &str,
    what: &str,
    timeout: Duration,
    f: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let t = Instant::now();
    loop {
        let s = state(addr);
        if f(&s) {
            return s;
        }
        assert!(t.elapsed() < timeout, "timed out waiting for {what}: {s}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    while let Some(p) = b.windows(2).position(|w| w == b"\r\n") {
        let n =
            usize::from_str_radix(std::str::from_utf8(&b[..p]).unwrap().trim(), 16).unwrap_or(0);
        if n == 0 {
            break;
        }
        out.extend_from_slice(&b[p + 2..p + 2 + n]);
        b = &b[p + 2 + n + 2..];
    }
    out
}

/// A running daemon and its HTTP address.
pub struct Daemon {
    pub child: Proc,
    pub addr: String,
}

pub fn start(config: &Path) -> Daemon {
    let (child, addr) = launch(config, &[], &[], false);
    Daemon { child, addr }
}

/// Daemon tests of one test binary run one at a time: they measure rates on a 2-core machine.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

pub fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|p| p.into_inner())
}
pub fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volcapd-hard-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A sim config at `resolution` with `extra` TOML appended, written to `dir/b.toml`.
pub fn sim_config(dir: &Path, resolution: usize, extra: &str) -> PathBuf {
    let scene = root().join("tests/scenes/front-walk.toml");
    let p = dir.join("b.toml");
    std::fs::write(
        &p,
        format!(
            "[camera]\nbackend = \"sim\"\nscene = \"{}\"\n[render]\nresolution = {resolution}\n[dbus]\nbus = \"none\"\n{extra}",
            scene.display()
        ),
    )
    .unwrap();
    p
}

pub fn signal(p: &Proc, sig: &str) {
    let ok = std::process::Command::new("kill")
        .args([&format!("-{sig}"), &p.0.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -{sig}");
}

pub fn alive(p: &mut Proc) -> bool {
    p.0.try_wait().unwrap().is_none()
}

pub fn proc_status(p: &Proc, key: &str) -> u64 {
    std::fs::read_to_string(format!("/proc/{}/status", p.0.id()))
        .unwrap()
        .lines()
        .find(|l| l.starts_with(key))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap()
}

/// A TCP connection to `addr` from the loopback address `from` (127.0.0.x), with a small
/// receive buffer when `rcvbuf` is given.
pub fn connect_from(addr: &str, from: &str, rcvbuf: Option<usize>) -> std::io::Result<TcpStream> {
    use socket2::{Domain, Socket, Type};
    let to: std::net::SocketAddr = addr.parse().unwrap();
    let s = Socket::new(Domain::IPV4, Type::STREAM, None)?;
    if let Some(n) = rcvbuf {
        s.set_recv_buffer_size(n)?;
    }
    let local: std::net::SocketAddr = format!("{from}:0").parse().unwrap();
    s.bind(&local.into())?;
    s.connect_timeout(&to.into(), Duration::from_secs(2))?;
    Ok(s.into())
}

/// [`launch`] with no extra arguments, then wait (30 s at most) until more than `frames`
/// frames were published.
pub fn launch_publishing(config: &Path, frames: u64) -> (Proc, String) {
    let (p, addr) = launch(config, &[], &[], false);
    wait_for(&addr, "frames", Duration::from_secs(30), |s| {
        s["frames_published"].as_u64() > Some(frames)
    });
    (p, addr)
}

/// `n` connections from `from` to `addr`, each having sent one byte of a request head and
/// nothing more (a trickling client); those the server refused are left out.
pub fn trickling(addr: &str, from: &str, n: usize) -> Vec<TcpStream> {
    (0..n)
        .filter_map(|_| {
            let mut s = connect_from(addr, from, None).ok()?;
            s.write_all(b"G").ok()?;
            Some(s)
        })
        .collect()
}

/// `volcapd --check-config --config PATH`: the exit code and stderr.
pub fn check_config(path: &std::path::Path) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_volcapd"))
        .args(["--check-config", "--config"])
        .arg(path)
        .output()
        .unwrap();
    (
        o.status.code(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&o.stderr),
            String::from_utf8_lossy(&o.stdout)
        ),
    )
}
