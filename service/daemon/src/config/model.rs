//! `[model]`: which networks the board runs, at which precision, the close-range model and
//! how thin parts are read.

use serde::Deserialize;
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Precision {
    #[default]
    F32,
    Int8,
}

/// The networks: which size and precision the board runs (`render.field = "model"`, the
/// default for real cameras). Files: `DIR/seg[.int8].onnx`, `DIR/shape-NAME.{encoder,mlp}[.int8].onnx`,
/// `DIR/color.*.onnx`; checked at start (and by `--check-config`) with errors naming the file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    /// The shape model: `fourier-small-seg2` (the default, the fastest of the accurate ones:
    /// [`volcap_engine::model::DEFAULT_MODEL`]), `fourier-medium` (the most accurate, 1.4-1.8x
    /// the encoder: the main job's and the x86-cpu board's) or another committed variant
    /// (`models/models.json`).
    #[serde(default = "d_model")]
    pub name: String,
    #[serde(default)]
    pub precision: Precision,
    /// Folder with the ONNX files and model cards, relative to the config file.
    #[serde(default = "d_model_dir")]
    pub dir: PathBuf,
    /// A second shape model for close-range framing (e.g. `fourier-small-upper`): frames
    /// whose person the frame's lower edge cuts (an upper body at a desk) are encoded with it;
    /// unset: `name` for every frame.
    #[serde(default)]
    pub close_range: Option<String>,
    /// Consecutive frames that must agree before the shape model changes between `name` and
    /// `close_range` (a person at the frame's lower edge would otherwise flip models frame
    /// by frame: `volcap_engine::model::preprocess::CloseRangeSwitch`); 1 follows every frame.
    #[serde(default = "d_close_range_frames")]
    pub close_range_frames: u32,
    /// How a Fourier model's thin parts are read: `series` (as the network predicts them;
    /// the default, the most precise surface) or `moment-fill` (a ray that holds inside
    /// but whose blurred series stays under the surface level, a hand or a wrist, is
    /// read as one interval of its own length at its own depth: the hands show, at a cost
    /// of about 0.2 cm P2S on held-out subjects; docs/eval/hands.md section 5).
    #[serde(default)]
    pub thin_parts: ThinParts,
    /// How many times each frame is segmented: 1 (the letterboxed frame) or 2 (then the
    /// person's crop of it once more, an arm or a hand the first pass lost taken back: one
    /// more segmentation a frame; docs/eval/hands.md section 8). Unset: as the shape model
    /// was trained (its file's `volcap.segment_passes`: 2 for the default
    /// `fourier-small-seg2`, 1 for `fourier-small`).
    #[serde(default)]
    pub segment_passes: Option<u8>,
    /// With two passes: the whole frame is segmented every this many frames, the frames
    /// between segment only the last frame's person's crop (one network run instead of
    /// two; at once the whole frame again when the person reaches the crop's edge:
    /// `volcap_engine::model::SegmentTrack`). 1 segments every frame whole. A person
    /// walking in is counted at the next whole frame.
    #[serde(default = "d_segment_full_every")]
    pub segment_full_every: u32,
    /// Passes of smoothing across the map pixels of a Fourier model's frame (0 to 4; each a
    /// 3x3 binomial mean among the pixels of the person's thick parts, hands and other parts
    /// narrower than 7 map pixels left as they are: the network predicts each pixel's ray on
    /// its own, and its row-to-row noise shows in a turned view as a serrated outline and
    /// streaked sides; `volcap_engine::model::fourier::FourierMaps::smoothed`). Default 2
    /// (docs/bench/map-smooth: Chamfer / P2S 1.521 / 1.009 -> 1.510 / 0.954 cm on the main
    /// job's moving scenes, hands shown on held-out images 53.8 -> 52.6 %); 0 reads the maps
    /// as the network gives them.
    #[serde(default = "d_map_smooth")]
    pub map_smooth: u8,
}

/// `model.map_smooth`: the engine's range.
pub const MAP_SMOOTH: std::ops::RangeInclusive<u8> =
    0..=volcap_engine::model::fourier::MAX_SMOOTH_PASSES;

fn d_map_smooth() -> u8 {
    volcap_engine::model::fourier::DEFAULT_SMOOTH_PASSES
}

/// `model.thin_parts`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ThinParts {
    #[default]
    Series,
    MomentFill,
}

impl ThinParts {
    /// The engine's `(min_len, max_len, away)` for `FourierMaps::with_moment_fill`: the
    /// setting measured in docs/eval/hands.md (0.02, at most 0.1, 4 map pixels away).
    pub fn moment_fill(self) -> Option<(f32, f32, usize)> {
        match self {
            Self::Series => None,
            Self::MomentFill => Some((0.02, 0.1, 4)),
        }
    }
}

/// `model.segment_passes`: the engine's range.
pub use volcap_engine::model::SEGMENT_PASSES;

/// `model.segment_full_every`: from every frame to once a second at 30 fps.
pub const SEGMENT_FULL_EVERY: std::ops::RangeInclusive<u32> =
    1..=volcap_engine::model::SEGMENT_FULL_EVERY_MAX;

fn d_segment_full_every() -> u32 {
    1
}

/// About a quarter of a second at the sim's frame rate, a few frames on a webcam.
fn d_close_range_frames() -> u32 {
    5
}

/// The best model measured (docs/eval): [`volcap_engine::model::DEFAULT_MODEL`].
fn d_model() -> String {
    volcap_engine::model::DEFAULT_MODEL.into()
}
fn d_model_dir() -> PathBuf {
    PathBuf::from("../models")
}

impl Default for ModelConfig {
    fn default() -> Self {
        Self {
            name: d_model(),
            precision: Precision::F32,
            dir: d_model_dir(),
            close_range: None,
            close_range_frames: d_close_range_frames(),
            thin_parts: ThinParts::Series,
            segment_passes: None,
            segment_full_every: d_segment_full_every(),
            map_smooth: d_map_smooth(),
        }
    }
}

/// `model.close_range_frames`: up to ten seconds at 30 fps.
pub const CLOSE_RANGE_FRAMES: std::ops::RangeInclusive<u32> = 1..=300;
