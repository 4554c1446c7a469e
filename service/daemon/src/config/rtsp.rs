//! `[rtsp]`: H.264 over RTSP like an IP camera, served (`bind`) and/or pushed to a media
//! server (`push`). Needs the `rtsp` build feature; the keys are checked in every build.

use serde::Deserialize;
use std::net::SocketAddr;

/// The H.264 encoder (both are GStreamer plugins that Debian ships).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Encoder {
    /// `x264enc` (gstreamer1.0-plugins-ugly, GPL-2+): zero-latency tuning, all profiles.
    #[default]
    X264,
    /// `openh264enc` (gstreamer1.0-plugins-bad, Cisco's BSD-2 codec): constrained baseline.
    Openh264,
}

impl Encoder {
    pub fn name(self) -> &'static str {
        match self {
            Encoder::X264 => "x264",
            Encoder::Openh264 => "openh264",
        }
    }
}

/// The H.264 profile sent to clients.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Profile {
    /// Constrained baseline: what every decoder, NVR and TV box plays.
    #[default]
    Baseline,
    Main,
    High,
}

impl Profile {
    /// The caps string GStreamer names it by.
    pub fn caps(self) -> &'static str {
        match self {
            Profile::Baseline => "constrained-baseline",
            Profile::Main => "main",
            Profile::High => "high",
        }
    }
}

/// RTP's lower transports the server offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Transport {
    Tcp,
    Udp,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RtspConfig {
    /// Serve RTSP on this address (e.g. "0.0.0.0:8554"; port 0 picks a free one); absent:
    /// no server.
    #[serde(default)]
    pub bind: Option<SocketAddr>,
    /// The stream's path on the server.
    #[serde(default = "d_path")]
    pub path: String,
    /// Publish the stream (RTSP RECORD) to a media server, e.g.
    /// "rtsp://nvr.lan:8554/volcap-1"; absent: no push.
    #[serde(default)]
    pub push: Option<String>,
    #[serde(default)]
    pub encoder: Encoder,
    /// Target bitrate, kbit/s.
    #[serde(default = "d_bitrate")]
    pub bitrate_kbps: u32,
    /// Frames between key frames (a new client also asks for one at once).
    #[serde(default = "d_gop")]
    pub gop: u32,
    #[serde(default)]
    pub profile: Profile,
    /// Lower transports offered to clients.
    #[serde(default = "d_transports")]
    pub transports: Vec<Transport>,
    /// Connected RTSP clients at most (a media server in front counts as one).
    #[serde(default = "d_client_limit")]
    pub client_limit: usize,
    /// Connected RTSP clients per address at most.
    #[serde(default = "d_per_address")]
    pub per_address_limit: usize,
    /// Push: the longest wait between reconnection attempts, seconds (the wait doubles from
    /// 1 s up to it).
    #[serde(default = "d_retry_max")]
    pub push_retry_max_s: u32,
    /// UDP ports the server sends RTP/RTCP from, `[first, last]` (first even, 1024 or more),
    /// for a firewall that must name them; absent: any free port.
    #[serde(default)]
    pub udp_ports: Option<[u16; 2]>,
}

fn d_path() -> String {
    "/live".into()
}
fn d_bitrate() -> u32 {
    2000
}
fn d_gop() -> u32 {
    30
}
fn d_transports() -> Vec<Transport> {
    vec![Transport::Tcp, Transport::Udp]
}
fn d_client_limit() -> usize {
    16
}
fn d_per_address() -> usize {
    4
}
fn d_retry_max() -> u32 {
    30
}

pub const BITRATE_KBPS: std::ops::RangeInclusive<u32> = 100..=50_000;
pub const GOP: std::ops::RangeInclusive<u32> = 1..=600;
pub const CLIENTS: std::ops::RangeInclusive<usize> = 1..=1000;
pub const RETRY_MAX_S: std::ops::RangeInclusive<u32> = 1..=3600;

impl Default for RtspConfig {
    fn default() -> Self {
        Self {
            bind: None,
            path: d_path(),
            push: None,
            encoder: Encoder::default(),
            bitrate_kbps: d_bitrate(),
            gop: d_gop(),
            profile: Profile::default(),
            transports: d_transports(),
            client_limit: d_client_limit(),
            per_address_limit: d_per_address(),
            push_retry_max_s: d_retry_max(),
            udp_ports: None,
        }
    }
}

impl RtspConfig {
    /// Whether the section asks for anything (a server or a push).
    pub fn enabled(&self) -> bool {
        self.bind.is_some() || self.push.is_some()
    }

    /// The first bad key (without the `rtsp.` prefix) and why.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        let range = |key, v: u64, lo: u64, hi: u64, unit: &str| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err((key, format!("{v} must be in {lo}..={hi}{unit}")))
            }
        };
        range(
            "bitrate_kbps",
            self.bitrate_kbps.into(),
            (*BITRATE_KBPS.start()).into(),
            (*BITRATE_KBPS.end()).into(),
            " (kbit/s)",
        )?;
        range(
            "gop",
            self.gop.into(),
            (*GOP.start()).into(),
            (*GOP.end()).into(),
            " (frames)",
        )?;
        for (key, v) in [
            ("client_limit", self.client_limit),
            ("per_address_limit", self.per_address_limit),
        ] {
            range(
                key,
                v as u64,
                *CLIENTS.start() as u64,
                *CLIENTS.end() as u64,
                "",
            )?;
        }
        range(
            "push_retry_max_s",
            self.push_retry_max_s.into(),
            (*RETRY_MAX_S.start()).into(),
            (*RETRY_MAX_S.end()).into(),
            " (seconds)",
        )?;
        let p = &self.path;
        if !p.starts_with('/')
            || p.len() < 2
            || p.len() > 64
            || !p[1..]
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_./".contains(c))
            || p.contains("..")
            || p.ends_with('/')
        {
            return Err((
                "path",
                format!(
                    "{p:?} must be '/' then 1-63 letters, digits, '-', '_', '.', '/' (e.g. \"/live\")"
                ),
            ));
        }
        if let Some([a, b]) = self.udp_ports
            && (a < 1024 || a % 2 != 0 || b <= a)
        {
            return Err((
                "udp_ports",
                format!(
                    "[{a}, {b}] must be [first, last] with first even and at least 1024, last above it (RTP and RTCP take a pair)"
                ),
            ));
        }
        if self.transports.is_empty() {
            return Err(("transports", "must name \"tcp\", \"udp\" or both".into()));
        }
        if self.encoder == Encoder::Openh264 && self.profile != Profile::Baseline {
            return Err((
                "profile",
                format!(
                    "{:?}: encoder \"openh264\" makes constrained baseline only; use \"baseline\" or encoder \"x264\"",
                    self.profile.caps()
                ),
            ));
        }
        if let Some(url) = &self.push {
            check_push_url(url).map_err(|e| ("push", e))?;
        }
        Ok(())
    }
}

/// `rtsp://HOST[:PORT]/PATH` (or `rtsps://`), printable ASCII, no credentials in a form we
/// would log (user:pass@ is allowed and hidden in `/state`).
fn check_push_url(url: &str) -> Result<(), String> {
    let rest = url
        .strip_prefix("rtsp://")
        .or_else(|| url.strip_prefix("rtsps://"))
        .ok_or_else(|| format!("{url:?} must start with rtsp:// (or rtsps://)"))?;
    if url.len() > 512 || !url.chars().all(|c| c.is_ascii_graphic()) {
        return Err(format!(
            "{url:?} must be at most 512 visible ASCII characters without spaces"
        ));
    }
    let host = rest.split('/').next().unwrap_or("");
    let host = host.rsplit('@').next().unwrap_or("");
    if host.is_empty() || host.starts_with(':') {
        return Err(format!("{url:?} names no host (rtsp://HOST[:PORT]/PATH)"));
    }
    Ok(())
}

/// The URL as shown in `/state` and logs: credentials replaced by `***`.
pub fn redacted(url: &str) -> String {
    match url.split_once("://") {
        Some((scheme, rest)) => {
            let (auth, tail) = rest.split_once('/').unwrap_or((rest, ""));
            match auth.rsplit_once('@') {
                Some((_, host)) => format!("{scheme}://***@{host}/{tail}"),
                None => url.to_string(),
            }
        }
        None => url.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<RtspConfig, String> {
        let c: RtspConfig = toml::from_str(text).map_err(|e| e.to_string())?;
        c.check().map_err(|(k, m)| format!("{k}: {m}"))?;
        Ok(c)
    }

    #[test]
    fn defaults_are_off_and_valid() {
        let c = parse("").unwrap();
        assert!(!c.enabled());
        assert_eq!(c.path, "/live");
        assert_eq!(c.transports, vec![Transport::Tcp, Transport::Udp]);
    }

    #[test]
    fn bounds_and_shapes_are_checked_and_named() {
        for (text, key) in [
            ("bitrate_kbps = 50", "bitrate_kbps"),
            ("bitrate_kbps = 60000", "bitrate_kbps"),
            ("gop = 0", "gop"),
            ("client_limit = 0", "client_limit"),
            ("per_address_limit = 5000", "per_address_limit"),
            ("push_retry_max_s = 0", "push_retry_max_s"),
            ("path = \"live\"", "path"),
            ("path = \"/\"", "path"),
            ("path = \"/a b\"", "path"),
            ("path = \"/../x\"", "path"),
            ("transports = []", "transports"),
            ("encoder = \"openh264\"\nprofile = \"high\"", "profile"),
            ("push = \"http://x/y\"", "push"),
            ("push = \"rtsp:///y\"", "push"),
            ("push = \"rtsp://a b/y\"", "push"),
            ("udp_ports = [5001, 5009]", "udp_ports"),
            ("udp_ports = [80, 90]", "udp_ports"),
            ("udp_ports = [5000, 5000]", "udp_ports"),
        ] {
            let e = parse(text).unwrap_err();
            assert!(e.starts_with(key), "{text}: {e}");
        }
        assert!(parse("encoder = \"h265\"").is_err());
        assert!(parse("transports = [\"sctp\"]").is_err());
        assert!(parse("frobnicate = 1").is_err());
        let c = parse("bind = \"127.0.0.1:0\"\npush = \"rtsp://u:p@127.0.0.1:8554/in\"").unwrap();
        assert!(c.enabled());
    }

    #[test]
    fn credentials_never_shown() {
        assert_eq!(
            redacted("rtsp://user:secret@nvr.lan:8554/cam/1"),
            "rtsp://***@nvr.lan:8554/cam/1"
        );
        assert_eq!(redacted("rtsp://nvr.lan/x"), "rtsp://nvr.lan/x");
    }
}
