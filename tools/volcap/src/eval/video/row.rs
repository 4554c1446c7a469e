//! `bench temporal`'s row: one scene under one setting.

use super::{edges, parts};
use serde::Serialize;

/// One (scene, setting) row.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct VideoRow {
    pub scene: String,
    /// "still" (every subject static) or "moving".
    pub kind: String,
    pub setting: String,
    pub frames: usize,
    /// Frames without a reconstruction (no person found).
    pub failed: usize,
    /// Consecutive-frame silhouette IoU as displayed, front and side: mean and worst.
    pub front_iou_mean: f64,
    pub front_iou_min: f64,
    pub side_iou_mean: f64,
    pub side_iou_min: f64,
    /// Mean |change| of the displayed first-hit depth where both frames hit, cm.
    pub front_depth_change_cm: f64,
    pub side_depth_change_cm: f64,
    pub chamfer_cm: f64,
    pub p2s_cm: f64,
    pub iou: f64,
    /// Camera frame: the model's mean |depth change| minus the oracle's, cm (front, side).
    pub front_jitter_cm: f64,
    pub side_jitter_cm: f64,
    /// Frames by which the silhouettes trail the unfiltered run's (best alignment of 0..=4;
    /// against the truth's when `off` was not measured; 0 for `off` itself).
    pub lag_frames: usize,
    /// Filter resets over the run (the first frame is one).
    pub resets: u64,
    /// The segmented person mask (before the filter) against the truth's, IoU in the
    /// networks' letterboxed input (mean over the frames with a person).
    #[serde(default)]
    pub mask_iou: f64,
    /// The segment stage's wall ms per frame (mean; letterbox, networks, person).
    #[serde(default)]
    pub segment_ms: f64,
    /// Frames segmented in the last frame's crop alone, and frames where the track lost the
    /// person and both passes followed (`segment_full_every` > 1).
    #[serde(default)]
    pub tracked_frames: usize,
    #[serde(default)]
    pub lost_frames: usize,
    /// Flicker by body part (`volcap_sim::parts::Part::ALL`'s order: head, torso, arms,
    /// hands, legs, feet), front and side together ([`parts`]): consecutive-frame IoU of
    /// the pixels showing the part, mean and worst (none: the part never shown), and the
    /// part's share of the pixels shown in one frame of a pair only.
    #[serde(default)]
    pub part_iou_mean: [Option<f64>; parts::PARTS],
    #[serde(default)]
    pub part_iou_min: [Option<f64>; parts::PARTS],
    #[serde(default)]
    pub part_change_share: [Option<f64>; parts::PARTS],
    /// In the pair of the worst side IoU (`side_iou_min`), each part's share of the side
    /// pixels that pair changed.
    #[serde(default)]
    pub part_worst_side_share: [Option<f64>; parts::PARTS],
    /// The worst side pair's first frame (from the scene's frame 0).
    #[serde(default)]
    pub worst_side_frame: Option<usize>,
    /// In that pair, per part, the shares of its changed side pixels on the silhouette's
    /// near edge, far edge, inside and apart ([`edges`]), and its changed runs' mean depth
    /// (cm along the camera's axis).
    #[serde(default)]
    pub part_worst_side_edges: [Option<[f64; edges::CLASSES]>; parts::PARTS],
    #[serde(default)]
    pub part_worst_side_run_cm: [Option<f64>; parts::PARTS],
    /// Each part's share of the first frame's side outline in that pair (the change's
    /// yardstick: a part with half the outline and half the change flickers no more than
    /// the rest).
    #[serde(default)]
    pub part_worst_side_outline: [Option<f64>; parts::PARTS],
    /// The pair of the worst front IoU (`front_iou_min`): its first frame, and each part's
    /// share of the front pixels it changed.
    #[serde(default)]
    pub worst_front_frame: Option<usize>,
    #[serde(default)]
    pub part_worst_front_share: [Option<f64>; parts::PARTS],
    /// How far the crop (the display's frame) moved between consecutive frames, in cells
    /// of the grid (the largest of its shift across, its shift down and its scale's move of
    /// the cube's edge; [`compare::crop_move_cells`]): mean and largest over the pairs, and
    /// in the worst side and worst front pairs.
    #[serde(default)]
    pub crop_move_cells: Option<(f64, f64)>,
    #[serde(default)]
    pub worst_side_crop_move: Option<f64>,
    #[serde(default)]
    pub worst_front_crop_move: Option<f64>,
    /// Still scenes: consecutive-frame silhouette IoU as displayed ([`display`], at
    /// `--display-size`), front and side: mean and worst (none: not drawn).
    #[serde(default)]
    pub front_display_iou: Option<(f64, f64)>,
    #[serde(default)]
    pub side_display_iou: Option<(f64, f64)>,
    /// The same with the outline antialiased (`render.antialias`): the overlap of
    /// consecutive coverage maps ([`display::soft_iou`]).
    #[serde(default)]
    pub front_display_aa_iou: Option<(f64, f64)>,
    #[serde(default)]
    pub side_display_aa_iou: Option<(f64, f64)>,
    /// Grid points held on last frame's side per frame (`surface_dead_band`, mean).
    #[serde(default)]
    pub held_sides: f64,
}
