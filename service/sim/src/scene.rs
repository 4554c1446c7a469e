//! Declarative scene files (TOML). A scene declares subjects with their motion, a camera,
//! lighting, a background and an `effect` list; the simulator builds exactly the declared
//! effect stages and nothing else.
//!
//! Unknown keys and bad values are errors naming the file, line and key: parse and range
//! errors come from `toml` with the value's span; names (garments, skins, poses) are checked
//! against the assets and reported with their line.

use crate::assets::HumanAssets;
use crate::pose::Style;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// Largest scene file accepted (scenes are a few kB of TOML).
pub const MAX_SCENE_BYTES: u64 = 1 << 20;

/// What one frame of a scene may cost, checked at load (the byte cap above does not bound
/// the work: 1,000 subjects fit in 217 kB). Subjects are posed, skinned, rasterized and
/// (oracle mode) given an occupancy field each frame, ~0.1 s a subject on one core.
pub const MAX_SUBJECTS: usize = 4;
/// Effects a scene may declare (each runs once per frame).
pub const MAX_EFFECTS: usize = 16;
/// Pixels of the camera image (width x height): 2048 x 2048.
pub const MAX_PIXELS: usize = 2048 * 2048;
/// Longest motion blur, pixels (its cost per pixel grows with the length).
pub const MAX_BLUR_PX: f32 = 64.0;

/// A scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{file}: {source}")]
    Io {
        file: PathBuf,
        source: std::io::Error,
    },
    #[error("{file}: {message}")]
    Parse { file: PathBuf, message: String },
    #[error("{file}:{line}: {key}: {message}")]
    Value {
        file: PathBuf,
        line: usize,
        key: String,
        message: String,
    },
}

macro_rules! checked_f32 {
    ($name:ident, $doc:literal, |$v:ident| $ok:expr, $what:literal) => {
        #[doc = $doc]
        #[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
        #[serde(try_from = "f64")]
        pub struct $name(pub f32);
        impl TryFrom<f64> for $name {
            type Error = String;
            fn try_from($v: f64) -> Result<Self, String> {
                if $v.is_finite() && $ok {
                    Ok(Self($v as f32))
                } else {
                    Err(format!("{} must be {}", $v, $what))
                }
            }
        }
    };
}

checked_f32!(
    Unit,
    "A finite value in [0, 1].",
    |v| (0.0..=1.0).contains(&v),
    "in [0, 1]"
);
checked_f32!(
    Positive,
    "A finite value > 0.",
    |v| v > 0.0,
    "finite and > 0"
);
checked_f32!(
    NonNeg,
    "A finite value >= 0.",
    |v| v >= 0.0,
    "finite and >= 0"
);
checked_f32!(
    Finite,
    "A finite value.",
    |v| v.abs() < 1e6,
    "finite (|x| < 1e6)"
);
checked_f32!(
    Angle,
    "Degrees in [-360, 360].",
    |v| (-360.0..=360.0).contains(&v),
    "an angle in [-360, 360] degrees"
);

/// JPEG quality 1..=100.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(try_from = "i64")]
pub struct Quality(pub u8);
impl TryFrom<i64> for Quality {
    type Error = String;
    fn try_from(v: i64) -> Result<Self, String> {
        if (1..=100).contains(&v) {
            Ok(Self(v as u8))
        } else {
            Err(format!("{v} must be a JPEG quality in 1..=100"))
        }
    }
}

/// Image size in pixels, 16..=4096.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(try_from = "i64")]
pub struct Pixels(pub usize);
impl TryFrom<i64> for Pixels {
    type Error = String;
    fn try_from(v: i64) -> Result<Self, String> {
        if (16..=4096).contains(&v) {
            Ok(Self(v as usize))
        } else {
            Err(format!("{v} must be between 16 and 4096 pixels"))
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CameraModel {
    WeakPerspective,
    Pinhole,
}

fn d_model() -> CameraModel {
    CameraModel::WeakPerspective
}
fn d_px() -> Pixels {
    Pixels(512)
}
fn d_fps() -> Positive {
    Positive(30.0)
}
fn d_distance() -> Positive {
    Positive(3.0)
}
fn d_look_at() -> [Finite; 3] {
    [Finite(0.0), Finite(0.9), Finite(0.0)]
}
fn d_height_m() -> Positive {
    Positive(2.1)
}
fn d_fov() -> Positive {
    Positive(40.0)
}
fn zero_angle() -> Angle {
    Angle(0.0)
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    #[serde(default = "d_model")]
    pub model: CameraModel,
    #[serde(default = "d_px")]
    pub width: Pixels,
    #[serde(default = "d_px")]
    pub height: Pixels,
    #[serde(default = "d_fps")]
    pub fps: Positive,
    /// Metres from the look-at point.
    #[serde(default = "d_distance")]
    pub distance: Positive,
    /// Degrees around the vertical; 0 = in front of the subjects (+z), 180 = behind.
    #[serde(default = "zero_angle")]
    pub yaw: Angle,
    /// Degrees; positive looks down.
    #[serde(default = "zero_angle")]
    pub pitch: Angle,
    #[serde(default = "d_look_at")]
    pub look_at: [Finite; 3],
    /// Weak perspective: metres of the world spanned by the image height.
    #[serde(default = "d_height_m")]
    pub height_m: Positive,
    /// Pinhole: vertical field of view in degrees (square pixels, centred principal point),
    /// unless the intrinsics below are given.
    #[serde(default = "d_fov")]
    pub fov_y: Positive,
    /// Pinhole intrinsics in pixels (override `fov_y`): focal lengths and principal point.
    pub fx: Option<Positive>,
    pub fy: Option<Positive>,
    pub cx: Option<Finite>,
    pub cy: Option<Finite>,
}

impl Default for CameraSpec {
    fn default() -> Self {
        toml::from_str("").unwrap_or_else(|_| unreachable!("empty camera table has defaults"))
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LightPreset {
    Studio,
    Side,
    Back,
    Flat,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct LightingSpec {
    pub preset: Option<LightPreset>,
    /// Second-order SH irradiance coefficients, 9 RGB triples (overrides the preset).
    pub sh: Option<Vec<[Finite; 3]>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Procedural {
    Checker,
    Gradient,
    Noise,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct BackgroundSpec {
    pub color: Option<[Unit; 3]>,
    pub procedural: Option<Procedural>,
    /// Image file, relative to the scene file.
    pub image: Option<Spanned<String>>,
    #[serde(default)]
    pub seed: u64,
}

fn d_period() -> Positive {
    Positive(1.2)
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MotionSpec {
    /// A static pose: `rest` or a pose of the assets (`tpose`, `benchmark`).
    Static { pose: String },
    /// A clip of the assets (the pack's clips are single-frame poses).
    Clip { clip: String },
    /// The seeded procedural generator.
    Procedural {
        style: Style,
        #[serde(default)]
        seed: u64,
        #[serde(default = "d_period")]
        period: Positive,
        /// `rest` (the default) or `varied`: seeded wrist, forearm and finger poses.
        #[serde(default)]
        hands: crate::hands::Hands,
    },
}

fn d_half() -> Unit {
    Unit(0.5)
}
fn d_race() -> [Unit; 3] {
    [Unit(1.0 / 3.0); 3]
}
fn d_pos() -> [Finite; 3] {
    [Finite(0.0); 3]
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SubjectEntry {
    pub id: String,
    #[serde(default = "d_half")]
    pub gender: Unit,
    #[serde(default = "d_half")]
    pub age: Unit,
    #[serde(default = "d_half")]
    pub muscle: Unit,
    #[serde(default = "d_half")]
    pub weight: Unit,
    #[serde(default = "d_half")]
    pub height: Unit,
    #[serde(default = "d_half")]
    pub proportions: Unit,
    #[serde(default = "d_race")]
    pub race: [Unit; 3],
    pub outfit: Option<Spanned<String>>,
    pub shoes: Option<Spanned<String>>,
    pub hair: Option<Spanned<String>>,
    pub skin: Option<Spanned<String>>,
    /// Metres on the floor plane (x, y, z); y is normally 0.
    #[serde(default = "d_pos")]
    pub position: [Finite; 3],
    /// Degrees about the vertical; 0 faces the default camera.
    #[serde(default = "zero_angle")]
    pub yaw: Angle,
    pub motion: MotionSpec,
}

impl SubjectEntry {
    pub fn spec(&self) -> crate::subject::SubjectSpec {
        let s = |x: &Option<Spanned<String>>| x.as_ref().map(|v| v.get_ref().clone());
        crate::subject::SubjectSpec {
            id: self.id.clone(),
            gender: self.gender.0,
            age: self.age.0,
            muscle: self.muscle.0,
            weight: self.weight.0,
            height: self.height.0,
            proportions: self.proportions.0,
            race: self.race.map(|u| u.0),
            outfit: s(&self.outfit),
            shoes: s(&self.shoes),
            hair: s(&self.hair),
            skin: s(&self.skin),
        }
    }
}

/// The effects a scene can declare, one per `[[effect]]` table, named by its single key:
/// `[[effect]]` then `jpeg = { quality = 75 }`. Only declared effects are built and run.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum EffectSpec {
    /// Shot noise (std `shot * sqrt(x)`) plus read noise (std `read`), x in [0, 1].
    SensorNoise {
        shot: NonNeg,
        read: NonNeg,
        #[serde(default)]
        seed: u64,
    },
    /// Linear motion blur of `length_px` along `angle_deg` (0 = to the right, 90 = down).
    MotionBlur {
        length_px: Positive,
        angle_deg: Angle,
    },
    /// Exposure gain `1 + amplitude * sin(2 pi t / period_s)`.
    ExposureDrift { amplitude: Unit, period_s: Positive },
    /// Red gain `1 + a sin`, blue gain `1 - a sin` over `period_s`.
    WhiteBalanceDrift { amplitude: Unit, period_s: Positive },
    /// Re-compress as JPEG at `quality`.
    Jpeg { quality: Quality },
    /// Rows read out over time: the last row is shifted `skew_px` relative to the first.
    RollingShutter { skew_px: Finite },
    /// Radial falloff: corners darkened by `strength`.
    Vignetting { strength: Unit },
    /// A box in the world (metres) in front of or around the subjects.
    Occluder {
        center: [Finite; 3],
        size: [Positive; 3],
        #[serde(default = "grey")]
        color: [Unit; 3],
    },
    /// Random smooth rotation of the camera about the look-at point.
    CameraShake {
        amplitude_deg: NonNeg,
        #[serde(default)]
        seed: u64,
    },
    /// The camera disappears at frame `at_frame` (fault tests), for `for_frames` frames or
    /// for good when absent.
    Unplug {
        at_frame: u64,
        for_frames: Option<u64>,
    },
    /// The camera driver stops answering at frame `at_frame` (watchdog tests): the read of
    /// that frame never returns.
    Hang { at_frame: u64 },
}

fn grey() -> [Unit; 3] {
    [Unit(0.45); 3]
}

impl EffectSpec {
    pub fn kind(&self) -> &'static str {
        match self {
            EffectSpec::SensorNoise { .. } => "sensor-noise",
            EffectSpec::MotionBlur { .. } => "motion-blur",
            EffectSpec::ExposureDrift { .. } => "exposure-drift",
            EffectSpec::WhiteBalanceDrift { .. } => "white-balance-drift",
            EffectSpec::Jpeg { .. } => "jpeg",
            EffectSpec::RollingShutter { .. } => "rolling-shutter",
            EffectSpec::Vignetting { .. } => "vignetting",
            EffectSpec::Occluder { .. } => "occluder",
            EffectSpec::CameraShake { .. } => "camera-shake",
            EffectSpec::Unplug { .. } => "unplug",
            EffectSpec::Hang { .. } => "hang",
        }
    }

    /// Every effect kind, for documentation and benchmarks.
    pub const KINDS: [&'static str; 11] = [
        "sensor-noise",
        "motion-blur",
        "exposure-drift",
        "white-balance-drift",
        "jpeg",
        "rolling-shutter",
        "vignetting",
        "occluder",
        "camera-shake",
        "unplug",
        "hang",
    ];
}

fn d_frames() -> u64 {
    30
}

/// A whole scene.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    #[serde(default)]
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Frames `sim render` writes unless told otherwise.
    #[serde(default = "d_frames")]
    pub frames: u64,
    #[serde(default)]
    pub camera: CameraSpec,
    #[serde(default)]
    pub lighting: LightingSpec,
    #[serde(default)]
    pub background: BackgroundSpec,
    #[serde(rename = "subject", default)]
    pub subjects: Vec<SubjectEntry>,
    #[serde(rename = "effect", default)]
    pub effects: Vec<EffectSpec>,
    /// Where the scene was read from (for relative paths and error messages).
    #[serde(skip)]
    pub file: PathBuf,
    #[serde(skip)]
    source: String,
}

fn line_of(src: &str, offset: usize) -> usize {
    src.as_bytes()[..offset.min(src.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

impl Scene {
    /// Parse `text` (from `file`, used in errors and for relative paths).
    pub fn parse(text: &str, file: &Path) -> Result<Self, SceneError> {
        let mut s: Scene = toml::from_str(text).map_err(|e| SceneError::Parse {
            file: file.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        s.file = file.to_path_buf();
        s.source = text.to_string();
        if s.name.is_empty() {
            s.name = file
                .file_stem()
                .map(|x| x.to_string_lossy().to_string())
                .unwrap_or_default();
        }
        s.check_budget()?;
        if let Some(sh) = &s.lighting.sh
            && sh.len() != 9
        {
            return Err(SceneError::Parse {
                file: s.file.clone(),
                message: format!("lighting.sh has {} triples, needs 9", sh.len()),
            });
        }
        Ok(s)
    }

    /// Load a scene file: a regular file of at most [`MAX_SCENE_BYTES`] (a FIFO, a device
    /// or a huge file is refused, never read without end).
    pub fn load(file: &Path) -> Result<Self, SceneError> {
        let bytes =
            crate::files::read_regular(file, MAX_SCENE_BYTES).map_err(|source| SceneError::Io {
                file: file.to_path_buf(),
                source,
            })?;
        let text = String::from_utf8(bytes).map_err(|e| SceneError::Parse {
            file: file.to_path_buf(),
            message: format!("not UTF-8 text: {e}"),
        })?;
        Self::parse(&text, file)
    }

    /// The line of the `n`th (0-based) occurrence of `header` in the source (1 when absent).
    fn line_of_nth(&self, header: &str, n: usize) -> usize {
        let at = self
            .source
            .match_indices(header)
            .nth(n)
            .map_or(0, |(i, _)| i);
        line_of(&self.source, at)
    }

    /// Refuse scenes whose per-frame work is beyond what a frame can afford
    /// ([`MAX_SUBJECTS`], [`MAX_EFFECTS`], [`MAX_PIXELS`], [`MAX_BLUR_PX`]), naming the key.
    fn check_budget(&self) -> Result<(), SceneError> {
        let value = |line, key: &str, message: String| SceneError::Value {
            file: self.file.clone(),
            line,
            key: key.to_string(),
            message,
        };
        if self.subjects.len() > MAX_SUBJECTS {
            return Err(value(
                self.line_of_nth("[[subject]]", MAX_SUBJECTS),
                "subject",
                format!(
                    "{} subjects; a scene may have at most {MAX_SUBJECTS} (each is posed, rasterized and given ground truth every frame)",
                    self.subjects.len()
                ),
            ));
        }
        if self.effects.len() > MAX_EFFECTS {
            return Err(value(
                self.line_of_nth("[[effect]]", MAX_EFFECTS),
                "effect",
                format!(
                    "{} effects; a scene may declare at most {MAX_EFFECTS}",
                    self.effects.len()
                ),
            ));
        }
        let (w, h) = (self.camera.width.0, self.camera.height.0);
        if w * h > MAX_PIXELS {
            return Err(value(
                self.line_of_nth("width", 0),
                "camera.width",
                format!(
                    "{w} x {h} = {} pixels; at most {MAX_PIXELS} (2048 x 2048) a frame",
                    w * h
                ),
            ));
        }
        for (i, e) in self.effects.iter().enumerate() {
            if let EffectSpec::MotionBlur { length_px, .. } = e
                && length_px.0 > MAX_BLUR_PX
            {
                return Err(value(
                    self.line_of_nth("length_px", 0),
                    &format!("effect[{i}].motion-blur.length_px"),
                    format!("{} px; at most {MAX_BLUR_PX}", length_px.0),
                ));
            }
        }
        Ok(())
    }

    fn value_err(&self, span: std::ops::Range<usize>, key: String, message: String) -> SceneError {
        SceneError::Value {
            file: self.file.clone(),
            line: line_of(&self.source, span.start),
            key,
            message,
        }
    }

    /// Check every name against the assets; errors give file, line and key.
    pub fn check_names(&self, assets: &HumanAssets) -> Result<(), SceneError> {
        use crate::assets::GarmentKind as G;
        for (i, s) in self.subjects.iter().enumerate() {
            let garment =
                |v: &Option<Spanned<String>>, key: &str, kind: G| -> Result<(), SceneError> {
                    let Some(v) = v else { return Ok(()) };
                    match assets.garments.get(v.get_ref()) {
                        Some(g) if g.kind == kind => Ok(()),
                        _ => Err(self.value_err(
                            v.span(),
                            format!("subject[{i}].{key}"),
                            format!(
                                "unknown {key} '{}' (available: {})",
                                v.get_ref(),
                                assets
                                    .garments
                                    .iter()
                                    .filter(|(_, g)| g.kind == kind)
                                    .map(|(n, _)| n.as_str())
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        )),
                    }
                };
            garment(&s.outfit, "outfit", G::Outfit)?;
            garment(&s.shoes, "shoes", G::Shoes)?;
            garment(&s.hair, "hair", G::Hair)?;
            if let Some(v) = &s.skin
                && !assets.skins.contains_key(v.get_ref())
            {
                return Err(self.value_err(
                    v.span(),
                    format!("subject[{i}].skin"),
                    format!(
                        "unknown skin '{}' (available: {})",
                        v.get_ref(),
                        assets.skins.keys().cloned().collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
            let pose = match &s.motion {
                MotionSpec::Static { pose } => Some((pose, "motion.pose")),
                MotionSpec::Clip { clip } => Some((clip, "motion.clip")),
                MotionSpec::Procedural { .. } => None,
            };
            if let Some((p, key)) = pose
                && p != "rest"
                && !assets.poses.contains_key(p)
            {
                // Tagged enums lose spans in serde: locate the quoted name in the source.
                let at = self.source.find(&format!("\"{p}\"")).unwrap_or(0);
                return Err(self.value_err(
                    at..at,
                    format!("subject[{i}].{key}"),
                    format!(
                        "unknown pose '{p}' (available: rest, {})",
                        assets.poses.keys().cloned().collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
        }
        if let Some(img) = &self.background.image {
            let p = self.resolve(img.get_ref());
            if !p.exists() {
                return Err(self.value_err(
                    img.span(),
                    "background.image".into(),
                    format!("{} does not exist", p.display()),
                ));
            }
        }
        Ok(())
    }

    /// A path relative to the scene file.
    pub fn resolve(&self, rel: &str) -> PathBuf {
        self.file.parent().unwrap_or(Path::new(".")).join(rel)
    }

    /// The same scene without any effect (the pure render).
    pub fn without_effects(&self) -> Self {
        let mut s = self.clone();
        s.effects.clear();
        s
    }
}

#[cfg(test)]
mod tests;
