//! The daemon's configuration (one TOML per board under `board-config/`). Unknown keys and
//! bad values are errors naming the file, line and key.

mod compute;
mod live;
mod model;
pub mod rtsp;
mod temporal;
pub use compute::{
    ComputeBackend, ComputeConfig, ComputeFallback, DEFAULT_SEGMENT_THREAD_UP_TO, RENDER_WORKERS,
    RenderDevice, RoundWaits, SEGMENT_WORKERS, THREADS,
};
pub use live::{Live, LiveError};
pub use model::{
    CLOSE_RANGE_FRAMES, MAP_SMOOTH, ModelConfig, Precision, SEGMENT_FULL_EVERY, SEGMENT_PASSES,
    ThinParts,
};
pub use rtsp::RtspConfig;
pub use temporal::{TemporalConfig, settings_json as temporal_json};

use serde::Deserialize;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// The scene simulator (embedded default camera).
    Sim,
    /// Replay of an MJPEG file or an image folder.
    File,
    /// A V4L2 device (webcams; OAK cameras in UVC mode). Needs the `v4l2` build feature.
    V4l2,
    /// An OAK camera over DepthAI-Core. Needs the `depthai` build feature.
    Depthai,
}

impl Backend {
    pub fn name(self) -> &'static str {
        match self {
            Backend::Sim => "sim",
            Backend::File => "file",
            Backend::V4l2 => "v4l2",
            Backend::Depthai => "depthai",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FieldMode {
    /// Render the simulator's ground-truth field through the engine. A debugging mode, always
    /// labelled as such: it is not a reconstruction. Needs the `sim` backend.
    Oracle,
    /// Publish the camera frame itself (letterboxed): a labelled debugging view; no
    /// reconstruction.
    Camera,
    /// The product: the trained networks (`[model]`) segment, encode and give the occupancy
    /// and colour fields that the engine localizes and renders. The default for real cameras.
    Model,
}

impl FieldMode {
    pub fn name(self) -> &'static str {
        match self {
            FieldMode::Oracle => "oracle",
            FieldMode::Camera => "camera",
            FieldMode::Model => "model",
        }
    }
}

/// Which format to ask for: `auto` prefers MJPEG (a quarter of YUYV's USB bandwidth at the
/// same size), then YUYV.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum FormatPref {
    #[default]
    Auto,
    Mjpeg,
    Yuyv,
}

/// The camera section. Which keys apply depends on the backend; a key given for another
/// backend is an error, so a typo cannot silently do nothing.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    pub backend: Backend,
    /// `sim`: scene file, relative to the config file.
    pub scene: Option<PathBuf>,
    /// `file`: an MJPEG file or a folder of images, relative to the config file.
    pub path: Option<PathBuf>,
    /// `file`: start again at the end (default true); false ends the stream.
    #[serde(rename = "loop")]
    pub looping: Option<bool>,
    /// `v4l2`: a device node (`/dev/video0`, `/dev/v4l/by-id/...`) or `name:TEXT` to pick the
    /// first capture device whose name contains TEXT.
    pub device: Option<String>,
    /// `v4l2`: `auto` (MJPEG, else YUYV), `mjpeg` or `yuyv`.
    pub format: Option<FormatPref>,
    /// `v4l2`, `depthai`: frame size.
    pub width: Option<u32>,
    pub height: Option<u32>,
    /// `file`, `v4l2`, `depthai`: frames per second.
    pub fps: Option<f32>,
}

fn d_res() -> GridRes {
    GridRes(129)
}
fn d_coarse() -> u32 {
    3
}
fn d_voxel() -> f32 {
    0.008
}

/// The grid resolutions volcapd renders at: 2^L + 1 for L in 5..=9.
pub const GRID_RESOLUTIONS: [usize; 5] = [33, 65, 129, 257, 513];

/// Grid points per axis, 2^L + 1 between 33 and 513.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(try_from = "i64")]
pub struct GridRes(pub usize);
impl TryFrom<i64> for GridRes {
    type Error = String;
    fn try_from(v: i64) -> Result<Self, String> {
        if v > 0 && GRID_RESOLUTIONS.contains(&(v as usize)) {
            Ok(Self(v as usize))
        } else {
            Err(format!("{v} must be one of 33, 65, 129, 257, 513"))
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderConfig {
    #[serde(default = "d_res")]
    pub resolution: GridRes,
    #[serde(default = "d_coarse")]
    pub coarse_level: u32,
    /// View orbit about the scene's look-at point, degrees.
    #[serde(default)]
    pub yaw: f32,
    #[serde(default)]
    pub pitch: f32,
    /// Eye distance from the look-at point in metres; 0 keeps the scene camera's.
    #[serde(default)]
    pub distance: f32,
    /// RGBA in [0, 1]; alpha 0 gives transparent PNG snapshots.
    #[serde(default = "d_bg")]
    pub background: [f32; 4],
    /// Default: `oracle` with the `sim` backend, `camera` with the others.
    #[serde(default)]
    pub field: Option<FieldMode>,
    /// Oracle voxel size in metres.
    #[serde(default = "d_voxel")]
    pub oracle_voxel_m: f32,
    /// Side of the published image in pixels: the render at display resolution (more rays
    /// than grid columns, the localized field interpolated between them; no extra field
    /// evaluation), [`DISPLAY_SIZES`]; 0 publishes the grid's own `resolution` pixels.
    #[serde(default = "d_display")]
    pub display_size: usize,
    /// Inside pieces farther than this fraction of the grid's side from the largest (the
    /// body) are left out of the render and `/mesh.glb` (`volcap_engine::pieces`: a network's
    /// floaters, e.g. a rear leg placed where no limb reaches); 0 keeps them.
    #[serde(default = "d_drop_apart")]
    pub drop_apart: f32,
    /// Draw the person's outline with partial pixels, composited over the background
    /// (`volcap_engine::render::edge_coverage`): no staircase at the display's two pixels a
    /// cell, and a value crossing 0.5 fades an outline pixel instead of switching it; false:
    /// whole pixels (the grid image at `display_size = 0`).
    #[serde(default = "d_antialias")]
    pub antialias: bool,
}

fn d_antialias() -> bool {
    true
}

fn d_drop_apart() -> f32 {
    volcap_engine::pieces::DEFAULT_GAP
}

/// Accepted `render.display_size` values besides 0.
pub const DISPLAY_SIZES: std::ops::RangeInclusive<usize> = 64..=1024;

fn d_display() -> usize {
    512
}

fn d_bg() -> [f32; 4] {
    [0.12, 0.13, 0.16, 0.0]
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            resolution: d_res(),
            coarse_level: d_coarse(),
            yaw: 0.0,
            pitch: 0.0,
            distance: 0.0,
            background: d_bg(),
            field: None,
            oracle_voxel_m: d_voxel(),
            display_size: d_display(),
            drop_apart: d_drop_apart(),
            antialias: d_antialias(),
        }
    }
}

fn d_bind() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 8080))
}
fn d_limit() -> usize {
    16
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HttpConfig {
    #[serde(default = "d_bind")]
    pub bind: SocketAddr,
    /// Concurrent stream clients.
    #[serde(default = "d_limit")]
    pub client_limit: usize,
    /// Bearer token for state-changing endpoints; absent = those endpoints are off.
    pub token: Option<String>,
    /// Seconds a client has to send its request head before it is dropped
    /// ([`HEADER_TIMEOUT_S`]).
    #[serde(default = "d_header_timeout")]
    pub header_timeout_s: u64,
    /// Seconds a response write may make no progress (a client that stopped reading)
    /// before the connection is closed and its slot freed ([`WRITE_TIMEOUT_S`]).
    #[serde(default = "d_write_timeout")]
    pub write_timeout_s: u64,
    /// Open connections per client address ([`PER_ADDRESS`]); more are closed at accept.
    #[serde(default = "d_per_address")]
    pub per_address_limit: usize,
    /// Host names (besides IP literals, `localhost` and this machine's name) accepted in
    /// the `Host` header; any other name is refused (DNS rebinding).
    #[serde(default)]
    pub allowed_hosts: Vec<String>,
    /// Addresses for which [`RESERVED_CONNECTIONS`] of the server's connections are kept
    /// free: hosts on the LAN can fill the rest, never these (default: this machine itself,
    /// `127.0.0.1` and `::1`, so a local viewer and health checks always get in). Add a
    /// monitoring host's address here.
    #[serde(default = "d_reserved_for")]
    pub reserved_for: Vec<std::net::IpAddr>,
}

/// Connections kept for [`HttpConfig::reserved_for`].
pub const RESERVED_CONNECTIONS: usize = 8;

fn d_reserved_for() -> Vec<std::net::IpAddr> {
    vec![
        std::net::IpAddr::from([127, 0, 0, 1]),
        std::net::IpAddr::from(std::net::Ipv6Addr::LOCALHOST),
    ]
}

/// Largest config file read (a board config is a few kB).
pub const MAX_CONFIG_BYTES: u64 = 256 * 1024;

fn d_write_timeout() -> u64 {
    10
}
fn d_per_address() -> usize {
    8
}
/// Accepted range of `http.write_timeout_s`.
pub const WRITE_TIMEOUT_S: std::ops::RangeInclusive<u64> = 1..=300;
/// Accepted range of `http.per_address_limit`.
pub const PER_ADDRESS: std::ops::RangeInclusive<usize> = 1..=1000;

/// Accepted range of `http.header_timeout_s`.
pub const HEADER_TIMEOUT_S: std::ops::RangeInclusive<u64> = 1..=300;

fn d_header_timeout() -> u64 {
    10
}

impl Default for HttpConfig {
    fn default() -> Self {
        Self {
            bind: d_bind(),
            client_limit: d_limit(),
            token: None,
            header_timeout_s: d_header_timeout(),
            write_timeout_s: d_write_timeout(),
            per_address_limit: d_per_address(),
            allowed_hosts: Vec::new(),
            reserved_for: d_reserved_for(),
        }
    }
}

/// Which D-Bus bus to serve `org.volcap.Capture1` on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Bus {
    /// Development and tests.
    #[default]
    Session,
    /// Production (systemd service; the policy file in `systemd/` governs access).
    System,
    /// No D-Bus: health on HTTP only.
    None,
}

#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DbusConfig {
    #[serde(default)]
    pub bus: Bus,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Which board this file is for, and why its numbers were chosen.
    #[serde(default)]
    pub description: String,
    pub camera: CameraConfig,
    #[serde(default)]
    pub render: RenderConfig,
    #[serde(default)]
    pub http: HttpConfig,
    #[serde(default)]
    pub dbus: DbusConfig,
    #[serde(default)]
    pub model: ModelConfig,
    #[serde(default)]
    pub compute: ComputeConfig,
    #[serde(default)]
    pub temporal: TemporalConfig,
    #[serde(default)]
    pub rtsp: RtspConfig,
    #[serde(skip)]
    pub file: PathBuf,
}

/// A value that parsed but is not acceptable: the dotted key and why.
#[derive(Debug)]
pub struct Bad {
    pub key: String,
    pub msg: String,
}

fn bad<T>(key: impl Into<String>, msg: impl Into<String>) -> Result<T, Bad> {
    Err(Bad {
        key: key.into(),
        msg: msg.into(),
    })
}

/// `value` within `range`, or an error naming the key and the range ("N must be in A..=B").
fn in_range<T: PartialOrd + std::fmt::Display>(
    key: &str,
    value: T,
    range: &std::ops::RangeInclusive<T>,
    unit: &str,
) -> Result<(), Bad> {
    if range.contains(&value) {
        return Ok(());
    }
    bad(
        key,
        format!(
            "{value} must be in {}..={}{unit}",
            range.start(),
            range.end()
        ),
    )
}

/// The 1-based line where `key` of `[table]` is set, if it is set in the text.
pub fn line_of(text: &str, dotted: &str) -> Option<usize> {
    let (table, key) = dotted.rsplit_once('.').unwrap_or(("", dotted));
    let mut current = String::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if let Some(h) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            current = h.trim().to_string();
            continue;
        }
        if current == table
            && let Some((k, _)) = line.split_once('=')
            && k.trim().trim_matches('"') == key
        {
            return Some(i + 1);
        }
    }
    None
}

impl Config {
    pub fn parse(text: &str, file: &Path) -> Result<Self, String> {
        let mut c: Config = toml::from_str(text)
            .map_err(|e| format!("{}: {}", file.display(), e.to_string().trim_end()))?;
        c.file = file.to_path_buf();
        c.validate().map_err(|b| match line_of(text, &b.key) {
            Some(n) => format!("{}: line {n}: {}: {}", file.display(), b.key, b.msg),
            None => format!("{}: {}: {}", file.display(), b.key, b.msg),
        })?;
        Ok(c)
    }

    /// Read and parse a config file: a regular file of at most [`MAX_CONFIG_BYTES`], opened
    /// without blocking (a FIFO, a device or a huge file is refused at once, naming it).
    pub fn load(file: &Path) -> Result<Self, String> {
        let bytes = volcap_sim::files::read_regular(file, MAX_CONFIG_BYTES)
            .map_err(|e| format!("{}: {e}", file.display()))?;
        let text = String::from_utf8(bytes)
            .map_err(|e| format!("{}: not UTF-8 text: {e}", file.display()))?;
        Self::parse(&text, file)
    }

    /// Checks that serde cannot express: ranges, combinations, per-backend keys.
    pub fn validate(&self) -> Result<(), Bad> {
        self.check_camera()?;
        let r = &self.render;
        if self.field() == FieldMode::Oracle && self.camera.backend != Backend::Sim {
            return bad(
                "render.field",
                format!(
                    "\"oracle\" needs camera.backend = \"sim\" (only the simulator has ground truth); use \"camera\" with backend \"{}\"",
                    self.camera.backend.name()
                ),
            );
        }
        in_range(
            "http.client_limit",
            self.http.client_limit,
            &(1..=10_000),
            "",
        )?;
        in_range(
            "http.header_timeout_s",
            self.http.header_timeout_s,
            &HEADER_TIMEOUT_S,
            " (seconds)",
        )?;
        in_range("compute.threads", self.compute.threads, &THREADS, "")?;
        in_range(
            "compute.rounds_per_wait",
            self.compute.rounds_per_wait,
            &compute::ROUNDS_PER_WAIT,
            "",
        )?;
        in_range(
            "compute.render_workers",
            self.compute.render_workers,
            &compute::RENDER_WORKERS,
            "",
        )?;
        in_range(
            "compute.segment_workers",
            self.compute.segment_workers,
            &compute::SEGMENT_WORKERS,
            "",
        )?;
        if let Err((key, msg)) = self.temporal.values().check() {
            return bad(format!("temporal.{key}"), msg);
        }
        if let Err((key, msg)) = self.rtsp.check() {
            return bad(format!("rtsp.{key}"), msg);
        }
        if let Some(b) = self.rtsp.bind
            && b.port() != 0
            && b.port() == self.http.bind.port()
            && (b.ip() == self.http.bind.ip()
                || b.ip().is_unspecified()
                || self.http.bind.ip().is_unspecified())
        {
            return bad(
                "rtsp.bind",
                format!(
                    "{b} is the HTTP server's address (http.bind = {})",
                    self.http.bind
                ),
            );
        }
        in_range(
            "model.close_range_frames",
            self.model.close_range_frames,
            &CLOSE_RANGE_FRAMES,
            " (frames)",
        )?;
        if let Some(passes) = self.model.segment_passes {
            in_range("model.segment_passes", passes, &SEGMENT_PASSES, "")?;
        }
        in_range(
            "model.segment_full_every",
            self.model.segment_full_every,
            &SEGMENT_FULL_EVERY,
            " (frames)",
        )?;
        in_range(
            "model.map_smooth",
            self.model.map_smooth,
            &MAP_SMOOTH,
            " (passes)",
        )?;
        let split = self.compute.segment_thread_up_to;
        if split != 0 && !GRID_RESOLUTIONS.contains(&split) {
            return bad(
                "compute.segment_thread_up_to",
                format!("{split} must be 0 (never) or one of 33, 65, 129, 257, 513"),
            );
        }
        in_range(
            "http.write_timeout_s",
            self.http.write_timeout_s,
            &WRITE_TIMEOUT_S,
            " (seconds)",
        )?;
        in_range(
            "http.per_address_limit",
            self.http.per_address_limit,
            &PER_ADDRESS,
            "",
        )?;
        if let Some(h) = self.http.allowed_hosts.iter().find(|h| {
            h.trim().is_empty()
                || !h
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '.' || c == '-')
        }) {
            return bad(
                "http.allowed_hosts",
                format!("{h:?} is not a host name (letters, digits, '.', '-')"),
            );
        }
        if !(0.002..=0.05).contains(&r.oracle_voxel_m) {
            return bad(
                "render.oracle_voxel_m",
                format!("{} must be in [0.002, 0.05]", r.oracle_voxel_m),
            );
        }
        if let Err(e) = Live::from_config(self).check() {
            return bad(format!("render.{}", e.field), e.msg);
        }
        if let Some(t) = self.http.token.as_deref() {
            if let Some(c) = t.chars().find(|c| !c.is_ascii_graphic()) {
                return bad(
                    "http.token",
                    format!(
                        "contains {c:?}: a token is sent in an Authorization header, so it must be visible ASCII without spaces or line breaks"
                    ),
                );
            }
            if t.len() < 8 {
                return bad("http.token", "must be at least 8 characters");
            }
        }
        Ok(())
    }

    fn check_camera(&self) -> Result<(), Bad> {
        let c = &self.camera;
        let b = c.backend.name();
        let given: [(&str, bool, &[Backend]); 8] = [
            ("scene", c.scene.is_some(), &[Backend::Sim]),
            ("path", c.path.is_some(), &[Backend::File]),
            ("loop", c.looping.is_some(), &[Backend::File]),
            ("device", c.device.is_some(), &[Backend::V4l2]),
            ("format", c.format.is_some(), &[Backend::V4l2]),
            (
                "width",
                c.width.is_some(),
                &[Backend::V4l2, Backend::Depthai],
            ),
            (
                "height",
                c.height.is_some(),
                &[Backend::V4l2, Backend::Depthai],
            ),
            (
                "fps",
                c.fps.is_some(),
                &[Backend::File, Backend::V4l2, Backend::Depthai],
            ),
        ];
        for (key, present, applies) in given {
            if present && !applies.contains(&c.backend) {
                return bad(
                    format!("camera.{key}"),
                    format!(
                        "does not apply to backend \"{b}\" (it is for {})",
                        applies
                            .iter()
                            .map(|a| a.name())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                );
            }
        }
        let required: &[(&str, bool)] = match c.backend {
            Backend::Sim => &[("scene", c.scene.is_some())],
            Backend::File => &[("path", c.path.is_some())],
            Backend::V4l2 => &[
                ("device", c.device.is_some()),
                ("width", c.width.is_some()),
                ("height", c.height.is_some()),
                ("fps", c.fps.is_some()),
            ],
            Backend::Depthai => &[
                ("width", c.width.is_some()),
                ("height", c.height.is_some()),
                ("fps", c.fps.is_some()),
            ],
        };
        for (key, present) in required {
            if !present {
                return bad(
                    format!("camera.{key}"),
                    format!("is required for backend \"{b}\""),
                );
            }
        }
        for (key, v) in [("width", c.width), ("height", c.height)] {
            if let Some(v) = v
                && !(16..=8192).contains(&v)
            {
                return bad(format!("camera.{key}"), format!("{v} must be in 16..=8192"));
            }
        }
        if c.backend == Backend::V4l2
            && c.format == Some(FormatPref::Yuyv)
            && c.width.is_some_and(|w| !w.is_multiple_of(2))
        {
            return bad("camera.width", "must be even for format \"yuyv\"");
        }
        if let Some(f) = c.fps
            && !(f.is_finite() && (0.5..=240.0).contains(&f))
        {
            return bad("camera.fps", format!("{f} must be in [0.5, 240]"));
        }
        if c.device
            .as_deref()
            .is_some_and(|d| d.trim().is_empty() || d == "name:")
        {
            return bad("camera.device", "must name a device node or \"name:TEXT\"");
        }
        Ok(())
    }

    /// The field mode, defaulted by backend.
    pub fn field(&self) -> FieldMode {
        self.render.field.unwrap_or(match self.camera.backend {
            Backend::Sim => FieldMode::Oracle,
            _ => FieldMode::Model,
        })
    }

    /// A path from the config, resolved relative to the config file.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.file.parent().unwrap_or(Path::new(".")).join(p)
        }
    }

    /// The scene file of the `sim` backend, resolved relative to the config file.
    pub fn scene_path(&self) -> Option<PathBuf> {
        self.camera.scene.as_deref().map(|p| self.resolve(p))
    }
}

#[cfg(test)]
mod tests;
