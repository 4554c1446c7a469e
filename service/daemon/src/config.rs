//! The daemon's configuration (one TOML per board under `board-config/`). Unknown keys and
//! bad values are errors naming the file, line and key.

use serde::Deserialize;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// The scene simulator (embedded default camera).
    Sim,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FieldMode {
    /// Render the simulator's ground-truth field through the engine. A debugging mode, always
    /// labelled as such: it is not a reconstruction.
    Oracle,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    pub backend: Backend,
    /// Scene file for the `sim` backend, relative to the config file.
    pub scene: PathBuf,
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

/// Grid points per axis, 2^L + 1 between 33 and 513.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(try_from = "i64")]
pub struct GridRes(pub usize);
impl TryFrom<i64> for GridRes {
    type Error = String;
    fn try_from(v: i64) -> Result<Self, String> {
        if [33, 65, 129, 257, 513].contains(&v) {
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
    /// RGBA in [0, 1]; alpha 0 gives transparent PNG snapshots.
    #[serde(default = "d_bg")]
    pub background: [f32; 4],
    #[serde(default = "d_field")]
    pub field: FieldMode,
    /// Oracle voxel size in metres.
    #[serde(default = "d_voxel")]
    pub oracle_voxel_m: f32,
}

fn d_bg() -> [f32; 4] {
    [0.12, 0.13, 0.16, 0.0]
}
fn d_field() -> FieldMode {
    FieldMode::Oracle
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            resolution: d_res(),
            coarse_level: d_coarse(),
            yaw: 0.0,
            pitch: 0.0,
            background: d_bg(),
            field: d_field(),
            oracle_voxel_m: d_voxel(),
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
}

impl Default for HttpConfig {
    fn default() -> Self {
        Self {
            bind: d_bind(),
            client_limit: d_limit(),
            token: None,
        }
    }
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
    #[serde(skip)]
    pub file: PathBuf,
}

impl Config {
    pub fn parse(text: &str, file: &Path) -> Result<Self, String> {
        let mut c: Config = toml::from_str(text)
            .map_err(|e| format!("{}: {}", file.display(), e.to_string().trim_end()))?;
        c.file = file.to_path_buf();
        if c.http.client_limit == 0 || c.http.client_limit > 10_000 {
            return Err(format!(
                "{}: http.client_limit = {} must be in 1..=10000",
                file.display(),
                c.http.client_limit
            ));
        }
        if !(0.002..=0.05).contains(&c.render.oracle_voxel_m) {
            return Err(format!(
                "{}: render.oracle_voxel_m = {} must be in [0.002, 0.05]",
                file.display(),
                c.render.oracle_voxel_m
            ));
        }
        let l = (c.render.resolution.0 - 1).trailing_zeros();
        if c.render.coarse_level < 1 || c.render.coarse_level >= l {
            return Err(format!(
                "{}: render.coarse_level = {} must be in 1..{l} for resolution {}",
                file.display(),
                c.render.coarse_level,
                c.render.resolution.0
            ));
        }
        if c.render.background.iter().any(|v| !(0.0..=1.0).contains(v)) {
            return Err(format!(
                "{}: render.background values must be in [0, 1]",
                file.display()
            ));
        }
        if c.http.token.as_deref().is_some_and(|t| t.len() < 8) {
            return Err(format!(
                "{}: http.token must be at least 8 characters",
                file.display()
            ));
        }
        Ok(c)
    }

    pub fn load(file: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
        Self::parse(&text, file)
    }

    /// The scene file, resolved relative to the config file.
    pub fn scene_path(&self) -> PathBuf {
        if self.camera.scene.is_absolute() {
            self.camera.scene.clone()
        } else {
            self.file
                .parent()
                .unwrap_or(Path::new("."))
                .join(&self.camera.scene)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_sim_config_parses() {
        let p = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../board-config/sim.toml"
        ));
        let c = Config::load(p).unwrap();
        assert_eq!(c.camera.backend, Backend::Sim);
        assert!(c.http.bind.ip().is_loopback());
        assert!(c.scene_path().exists(), "{}", c.scene_path().display());
    }

    #[test]
    fn errors_name_file_line_and_key() {
        let e = Config::parse(
            "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\n[render]\nresolution = 100\n",
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(
            e.contains("b.toml")
                && e.contains("line 5")
                && e.contains("resolution")
                && e.contains("257"),
            "{e}"
        );
        let e = Config::parse(
            "[camera]\nbackend = \"sim\"\nscene = \"x.toml\"\nfps = 3\n",
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(e.contains("line 4") && e.contains("fps"), "{e}");
        let e = Config::parse(
            "[camera]\nbackend = \"v4l9\"\nscene = \"x\"\n",
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(e.contains("v4l9"), "{e}");
        let e = Config::parse(
            "[camera]\nbackend = \"sim\"\nscene = \"x\"\n[http]\ntoken = \"abc\"\n",
            Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(e.contains("token"), "{e}");
    }
}
