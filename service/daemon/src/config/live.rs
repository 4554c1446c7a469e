//! The settings that can change while running, validated in one place.

use super::Config;

/// What can be changed while running (HTTP view controls, D-Bus, config reload).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Live {
    /// Orbit about the scene's look-at point, degrees.
    pub yaw: f32,
    pub pitch: f32,
    /// Eye distance from the look-at point in metres; 0 keeps the camera's own.
    pub distance: f32,
    /// Grid points per axis (2^L + 1) = output size in pixels.
    pub resolution: usize,
    pub coarse_level: u32,
    /// RGBA in [0, 1]; alpha 0 gives transparent PNG snapshots.
    pub background: [f32; 4],
    pub paused: bool,
    /// Side of the published image (`render.display_size`; 0: the grid's `resolution`).
    pub display_size: usize,
    /// Inside pieces farther than this fraction of the grid's side from the body are left
    /// out of the render and the meshes (`render.drop_apart`, [`volcap_engine::pieces`]);
    /// 0: kept.
    pub drop_apart: f32,
    /// The outline drawn with partial pixels (`render.antialias`).
    pub antialias: bool,
}

impl Live {
    pub fn from_config(cfg: &Config) -> Self {
        Self {
            yaw: wrap_yaw(cfg.render.yaw),
            pitch: cfg.render.pitch,
            distance: cfg.render.distance,
            resolution: cfg.render.resolution.0,
            coarse_level: cfg.render.coarse_level,
            background: cfg.render.background,
            paused: false,
            display_size: cfg.render.display_size,
            drop_apart: cfg.render.drop_apart,
            antialias: cfg.render.antialias,
        }
    }

    /// The one validation of every live setting, whoever sets it (config, HTTP, D-Bus).
    pub fn check(&self) -> Result<(), LiveError> {
        let bad = |field, msg: String| Err(LiveError { field, msg });
        if !self.yaw.is_finite() {
            return bad("yaw", format!("yaw {}: need a finite value", self.yaw));
        }
        if !self.pitch.is_finite() || self.pitch.abs() > 80.0 {
            return bad(
                "pitch",
                format!(
                    "yaw {} / pitch {}: need finite values, |pitch| <= 80",
                    self.yaw, self.pitch
                ),
            );
        }
        if !(self.distance == 0.0 || (0.5..=10.0).contains(&self.distance)) {
            return bad(
                "distance",
                format!(
                    "distance {}: 0 (the camera's own) or 0.5..=10 metres",
                    self.distance
                ),
            );
        }
        if !super::GRID_RESOLUTIONS.contains(&self.resolution) {
            return bad(
                "resolution",
                format!(
                    "resolution {}: one of 33, 65, 129, 257, 513 (levels 5..=9)",
                    self.resolution
                ),
            );
        }
        let l = (self.resolution - 1).trailing_zeros();
        if self.coarse_level < 1 || self.coarse_level >= l {
            return bad(
                "coarse_level",
                format!(
                    "{} must be in 1..{l} for resolution {}",
                    self.coarse_level, self.resolution
                ),
            );
        }
        if self.display_size != 0 && !super::DISPLAY_SIZES.contains(&self.display_size) {
            return bad(
                "display_size",
                format!(
                    "display_size {}: 0 (the grid's resolution) or {}..={} pixels",
                    self.display_size,
                    super::DISPLAY_SIZES.start(),
                    super::DISPLAY_SIZES.end()
                ),
            );
        }
        if let Err(e) = volcap_engine::pieces::gap_setting(self.drop_apart) {
            return bad("drop_apart", format!("drop_apart {e}"));
        }
        if self.background.iter().any(|v| !(0.0..=1.0).contains(v)) {
            return bad("background", "values must be in [0, 1]".into());
        }
        Ok(())
    }

    /// The gap of [`volcap_engine::pieces`] as the renderer takes it (`None`: off).
    pub fn drop_apart(&self) -> Option<f32> {
        volcap_engine::pieces::gap_setting(self.drop_apart)
            .ok()
            .flatten()
    }

    /// Side of the published image in pixels.
    pub fn out_size(&self) -> usize {
        if self.display_size == 0 {
            self.resolution
        } else {
            self.display_size
        }
    }

    /// Set the yaw, wrapped into [0, 360) (a value that is not finite is kept as it is, for
    /// [`Live::check`] to refuse by its own name: `inf` stays `inf`, not NaN).
    pub fn set_yaw(&mut self, yaw: f32) {
        self.yaw = wrap_yaw(yaw);
    }

    /// Change the grid resolution, bringing the coarse level into range for it.
    pub fn set_resolution(&mut self, resolution: usize) {
        self.resolution = resolution;
        let levels = (resolution.max(2) - 1).trailing_zeros();
        self.coarse_level = self.coarse_level.min(levels.saturating_sub(1));
    }
}

fn wrap_yaw(yaw: f32) -> f32 {
    if yaw.is_finite() {
        yaw.rem_euclid(360.0)
    } else {
        yaw
    }
}

/// A live setting out of range: which one (the `render.` key in the config) and why.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveError {
    pub field: &'static str,
    pub msg: String,
}

impl std::fmt::Display for LiveError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.msg)
    }
}
