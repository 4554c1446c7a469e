//! What keeps one LAN client from taking the HTTP server down: a per-address connection
//! count, a write-progress timeout on every connection, the `Host` allow-list against DNS
//! rebinding, and a per-address back-off after wrong tokens. Pure mechanisms; `http.rs`
//! applies them.

use std::collections::HashMap;
use std::net::IpAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// Open connections per client address.
#[derive(Default)]
pub struct PerAddress {
    open: Mutex<HashMap<IpAddr, usize>>,
}

/// One counted connection; the count drops with it.
pub struct AddressSlot(Arc<PerAddress>, IpAddr);

impl PerAddress {
    /// A slot for `ip`, or `None` when it already holds `limit` connections.
    pub fn enter(self: &Arc<Self>, ip: IpAddr, limit: usize) -> Option<AddressSlot> {
        let mut m = self.open.lock().unwrap_or_else(|p| p.into_inner());
        let n = m.entry(ip).or_insert(0);
        if *n >= limit {
            return None;
        }
        *n += 1;
        Some(AddressSlot(self.clone(), ip))
    }

    pub fn open(&self, ip: IpAddr) -> usize {
        let m = self.open.lock().unwrap_or_else(|p| p.into_inner());
        m.get(&ip).copied().unwrap_or(0)
    }
}

impl Drop for AddressSlot {
    fn drop(&mut self) {
        let mut m = self.0.open.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = m.get_mut(&self.1) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                m.remove(&self.1);
            }
        }
    }
}

/// An I/O stream whose writes fail with `TimedOut` when a write makes no progress for
/// `timeout` (a client that stopped reading): the connection ends and its slot is freed.
/// Reads are untouched (the header timeout governs them).
pub struct WriteTimeout<S> {
    inner: S,
    timeout: Duration,
    stalled: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl<S> WriteTimeout<S> {
    pub fn new(inner: S, timeout: Duration) -> Self {
        Self {
            inner,
            timeout,
            stalled: None,
        }
    }

    fn pending<T>(&mut self, cx: &mut Context<'_>) -> Poll<std::io::Result<T>> {
        let timeout = self.timeout;
        let sleep = self
            .stalled
            .get_or_insert_with(|| Box::pin(tokio::time::sleep(timeout)));
        match sleep.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                format!("no write progress for {timeout:?}: client not reading"),
            ))),
            Poll::Pending => Poll::Pending,
        }
    }
}

use std::future::Future;

impl<S: AsyncRead + Unpin> AsyncRead for WriteTimeout<S> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for WriteTimeout<S> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        match Pin::new(&mut self.inner).poll_write(cx, buf) {
            Poll::Pending => self.pending(cx),
            r => {
                self.stalled = None;
                r
            }
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        match Pin::new(&mut self.inner).poll_flush(cx) {
            Poll::Pending => self.pending(cx),
            r => {
                self.stalled = None;
                r
            }
        }
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        match Pin::new(&mut self.inner).poll_write_vectored(cx, bufs) {
            Poll::Pending => self.pending(cx),
            r => {
                self.stalled = None;
                r
            }
        }
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
}

/// The `Host` header check against DNS rebinding: an IP literal (any port) is accepted (a
/// page can only reach it under that same origin), as are `localhost`, this machine's host
/// name (and `NAME.local`) and the configured names; any other name is refused. No `Host`
/// at all passes here (HTTP/1.0 tools); `http::host_verdict` refuses it on HTTP/1.1, and
/// refuses two `Host` headers.
pub struct HostAllow {
    names: Vec<String>,
}

impl HostAllow {
    pub fn new(extra: &[String]) -> Self {
        let mut names = vec!["localhost".to_string()];
        if let Some(h) = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .map(|h| h.trim().to_ascii_lowercase())
            .filter(|h| !h.is_empty())
        {
            names.push(format!("{h}.local"));
            names.push(h);
        }
        names.extend(extra.iter().map(|e| e.trim().to_ascii_lowercase()));
        Self { names }
    }

    pub fn allows(&self, host: Option<&str>) -> bool {
        let Some(host) = host else { return true };
        let host = host.trim().to_ascii_lowercase();
        // [v6]:port, v4:port, name:port, or bare.
        let name = if let Some(rest) = host.strip_prefix('[') {
            match rest.split_once(']') {
                Some((ip, _)) => return ip.parse::<std::net::Ipv6Addr>().is_ok(),
                None => return false,
            }
        } else {
            host.rsplit_once(':')
                .filter(|(_, port)| port.chars().all(|c| c.is_ascii_digit()))
                .map(|(n, _)| n)
                .unwrap_or(&host)
        };
        let name = name.trim_end_matches('.');
        name.parse::<IpAddr>().is_ok() || self.names.iter().any(|n| n == name)
    }

    pub fn names(&self) -> &[String] {
        &self.names
    }
}

/// Back-off after wrong tokens. Per address: from the [`FREE_FAILURES`]th failure on, the
/// address waits 2^(n - FREE_FAILURES) seconds (at most [`MAX_BACKOFF`]) before any token of
/// its is checked again; a right token clears its record. For all addresses together: a
/// budget of [`GLOBAL_BURST`] wrong tokens, refilled at [`GLOBAL_PER_S`] a second; while it
/// is spent no token is checked (so guesses spread over many addresses gain nothing: 500
/// take minutes, not milliseconds).
pub struct Backoff {
    failures: Mutex<HashMap<IpAddr, (u32, Instant)>>,
    /// Guesses left in the global budget, and when it was last refilled.
    global: Mutex<(f64, Instant)>,
}

impl Default for Backoff {
    fn default() -> Self {
        Self {
            failures: Mutex::default(),
            global: Mutex::new((GLOBAL_BURST, Instant::now())),
        }
    }
}

/// Wrong tokens from all addresses together before the global budget runs dry.
pub const GLOBAL_BURST: f64 = 30.0;
/// Wrong tokens a second the global budget allows after that.
pub const GLOBAL_PER_S: f64 = 1.0;

/// Wrong tokens an address may send before it has to wait.
pub const FREE_FAILURES: u32 = 5;
/// Longest wait.
pub const MAX_BACKOFF: Duration = Duration::from_secs(60);
/// Addresses remembered at most (oldest forgotten first): the table is bounded.
const MAX_TRACKED: usize = 4096;

impl Backoff {
    /// `Some(wait)` while `ip` must wait before its token is checked.
    pub fn wait(&self, ip: IpAddr) -> Option<Duration> {
        let m = self.failures.lock().unwrap_or_else(|p| p.into_inner());
        let (n, last) = *m.get(&ip)?;
        if n < FREE_FAILURES {
            return None;
        }
        let wait = Duration::from_secs(1u64 << (n - FREE_FAILURES).min(6)).min(MAX_BACKOFF);
        let since = last.elapsed();
        (since < wait).then(|| wait - since)
    }

    /// `Some(wait)` while the global budget of wrong tokens is spent.
    pub fn global_wait(&self) -> Option<Duration> {
        let mut g = self.global.lock().unwrap_or_else(|p| p.into_inner());
        Self::refill(&mut g);
        (g.0 < 1.0).then(|| Duration::from_secs_f64((1.0 - g.0) / GLOBAL_PER_S))
    }

    fn refill(g: &mut (f64, Instant)) {
        let now = Instant::now();
        g.0 = (g.0 + (now - g.1).as_secs_f64() * GLOBAL_PER_S).min(GLOBAL_BURST);
        g.1 = now;
    }

    /// A wrong token (from `ip` where known): counted for the address and the global budget.
    pub fn failed(&self, ip: impl Into<Option<IpAddr>>) {
        {
            let mut g = self.global.lock().unwrap_or_else(|p| p.into_inner());
            Self::refill(&mut g);
            g.0 = (g.0 - 1.0).max(0.0);
        }
        let Some(ip) = ip.into() else { return };
        let mut m = self.failures.lock().unwrap_or_else(|p| p.into_inner());
        if m.len() >= MAX_TRACKED
            && !m.contains_key(&ip)
            && let Some(oldest) = m.iter().min_by_key(|(_, (_, t))| *t).map(|(k, _)| *k)
        {
            m.remove(&oldest);
        }
        let e = m.entry(ip).or_insert((0, Instant::now()));
        e.0 = e.0.saturating_add(1);
        e.1 = Instant::now();
    }

    pub fn succeeded(&self, ip: IpAddr) {
        self.failures
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&ip);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_ip_literals_and_local_names_pass_other_names_do_not() {
        let h = HostAllow::new(&["volcap.lan".into()]);
        for ok in [
            "127.0.0.1:8080",
            "192.168.1.20",
            "[::1]:8080",
            "localhost:8080",
            "LOCALHOST",
            "volcap.lan:80",
            "volcap.lan.",
        ] {
            assert!(h.allows(Some(ok)), "{ok}");
        }
        assert!(h.allows(None));
        for bad in [
            "evil.example",
            "evil.example:8080",
            "127.0.0.1.evil.example",
            "[::1",
            "localhost.evil.example",
        ] {
            assert!(!h.allows(Some(bad)), "{bad}");
        }
    }

    #[test]
    fn per_address_slots_are_counted_and_released() {
        let p = Arc::new(PerAddress::default());
        let a: IpAddr = "127.0.0.2".parse().unwrap();
        let b: IpAddr = "127.0.0.3".parse().unwrap();
        let s1 = p.enter(a, 2).unwrap();
        let _s2 = p.enter(a, 2).unwrap();
        assert!(p.enter(a, 2).is_none(), "third from the same address");
        assert!(p.enter(b, 2).is_some(), "another address is not affected");
        drop(s1);
        assert_eq!(p.open(a), 1);
        assert!(p.enter(a, 2).is_some());
    }

    #[test]
    fn backoff_starts_after_free_failures_and_clears_on_success() {
        let b = Backoff::default();
        let ip: IpAddr = "10.0.0.9".parse().unwrap();
        for _ in 0..FREE_FAILURES - 1 {
            b.failed(ip);
            assert!(b.wait(ip).is_none());
        }
        b.failed(ip);
        let w = b.wait(ip).expect("waits after the free failures");
        assert!(w <= Duration::from_secs(1) && w > Duration::from_millis(500));
        for _ in 0..20 {
            b.failed(ip);
        }
        assert!(b.wait(ip).unwrap() <= MAX_BACKOFF);
        b.succeeded(ip);
        assert!(b.wait(ip).is_none());
    }

    #[test]
    fn wrong_tokens_from_many_addresses_spend_one_global_budget() {
        let b = Backoff::default();
        assert!(b.global_wait().is_none());
        // One wrong token from each of many addresses: no address reaches its own limit,
        // yet the budget runs dry after about GLOBAL_BURST of them.
        let mut checked = 0;
        for i in 0..200u32 {
            if b.global_wait().is_some() {
                continue;
            }
            checked += 1;
            b.failed(IpAddr::from(std::net::Ipv4Addr::from(0x0a00_0000 + i)));
        }
        assert!(
            (GLOBAL_BURST as usize..=GLOBAL_BURST as usize + 2).contains(&checked),
            "{checked} checked"
        );
        let w = b.global_wait().expect("the budget is spent");
        assert!(w <= Duration::from_secs_f64(1.0 / GLOBAL_PER_S) && w > Duration::ZERO);
        std::thread::sleep(w + Duration::from_millis(20));
        assert!(b.global_wait().is_none(), "refilled with time");
    }
}
