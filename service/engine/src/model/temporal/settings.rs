//! The temporal filter's settings ([`TemporalSettings`], `[temporal]` in volcapd's config),
//! their defaults and their ranges.

/// The filter's settings (`[temporal]` in volcapd's config).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemporalSettings {
    /// The crop's cutoff when still, Hz (lower: steadier, slower to settle).
    pub crop_min_cutoff_hz: f32,
    /// How the crop's cutoff opens with its speed: Hz per crop-NDC unit per second.
    pub crop_beta: f32,
    /// The crop's play, a fraction of its half-side (`s`): the crop given out moves only
    /// where the filtered one pulls it farther than this (a backlash), so that the One Euro
    /// filter's slow wander under sensor noise (a third of a cell at 257^3 in a T-pose,
    /// whose box the fingertips set) does not shift a still person on the display (the
    /// display's frame is the crop), at the cost of this much lag when they move (0: off).
    pub crop_hold: f32,
    /// The mask's hysteresis band: a pixel turns person above `mask_high` and stops being
    /// one below `mask_low` (`0 < low <= 0.5 <= high < 1`).
    pub mask_low: f32,
    pub mask_high: f32,
    /// Motion in the mask: where more than this fraction of a [`MOTION_BLOCK`](super::MOTION_BLOCK)^2 block (or
    /// of a block beside it) changed side of 0.5 since the last frame, the person moves
    /// there and the mask follows the segmenter at once; elsewhere hysteresis holds the
    /// edge. Sensor noise flips scattered pixels along the outline; a raised arm flips a
    /// band of them.
    pub mask_motion: f32,
    /// Inside the band, a pixel whose segmenter value has stayed on the other side of 0.5
    /// for this many frames in a row follows it: tremor flips a pixel back and forth, a
    /// slow real change (an arm near the top of its swing) keeps it on one side.
    pub mask_hold_frames: u32,
    /// [`Self::mask_hold_frames`] while the crop given out stayed put from the frame before
    /// the last to the last (the person still as a whole; `crop_hold` holds the crop
    /// while they are): noise keeps flipping a still person's outline pixels two frames in a
    /// row now and then, and each flip moves the field's gate. Default 10: a still person's
    /// front view as displayed, T-pose worst consecutive IoU 0.9951 -> 0.9978, with the
    /// moving scenes' Chamfer and lag unchanged, where raising `mask_hold_frames` to 3
    /// already lags a slow arm raise by a frame (docs/bench/main-job-medium, "The outline of
    /// a still person").
    pub mask_still_hold_frames: u32,
    /// The mask's dead band: where the person does not move, a pixel that stays on its side
    /// of 0.5 and within this of the value given out last is given that value again (the
    /// mask's 0.5 contour gates the field: it then does not slide with sensor noise; 0: off).
    /// Default 0.1: a still person's worst side frame 0.9919 -> 0.9952 and front 0.9920 ->
    /// 0.9944 at no cost in moving Chamfer or lag (docs/bench/main-job-medium, "The mask's
    /// dead band").
    pub mask_dead_band: f32,
    /// The surface's dead band ([`crate::sides`], applied by the render stage's localization):
    /// while the crop and view stay put, a grid value within this of last frame's is given
    /// out as last frame's, and a side crossed by less than this is kept (0: off; at most
    /// [`crate::sides::MAX_BAND`]; docs/bench/main-job-medium, "The surface's dead band").
    pub surface_dead_band: f32,
    /// The maps' cutoff when still, Hz.
    pub map_min_cutoff_hz: f32,
    /// How a map pixel's cutoff opens with its change: Hz per unit of relative change per
    /// second (the change over the maps' mean magnitude).
    pub map_beta: f32,
    /// The least weight of the new maps where the mask moved (a map pixel in or beside a
    /// block where the segmenter's outline moved, `mask_motion`) while the crop given out
    /// moved too: there the person moves and the maps follow at once, as the mask does,
    /// instead of averaging a limb's two places (a swinging lower leg blended with where it
    /// was falls under the surface level and leaves a gap). A person still as a whole (the
    /// crop held) keeps the filter whole (0: off, the rate's weight alone; 1: this frame's
    /// maps where the mask moved). Default 1: the main job's walk showed its rear lower leg
    /// cut off or missing in about one frame in seven without it (a weight of 0.75 still
    /// did; the filter off, never); with it the moving scenes' Chamfer 1.542 -> 1.521 cm,
    /// IoU 0.768 -> 0.772, depth jitter about a third less (P2S 0.975 -> 1.009: the
    /// network's own misplaced parts come through), still people's flicker unchanged to the
    /// digit (docs/bench/main-job-medium, "The maps follow the mask's motion").
    pub map_motion_weight: f32,
    /// The cutoff of each map value's measured rate of change, Hz: tremor changes sign
    /// from frame to frame and averages out of the rate below this cutoff, so it does not
    /// open the filter; a real change keeps its sign and opens it within a frame or two.
    pub map_change_cutoff_hz: f32,
    /// Below this IoU between the steady mask and the new one, the frame shows another
    /// person (or the same one after a jump): the filter starts again.
    pub same_person_iou: f32,
    /// A longer gap between frames (seconds) starts again too.
    pub max_gap_s: f32,
}

/// `crop_hold`'s default: half a cell at 257^3 (a cell is `s / 128` there), a quarter at
/// 129^3, a cell at 513^3 (docs/bench/main-job-medium, "The crop's play").
pub const CROP_HOLD_DEFAULT: f32 = 0.004;

/// Chosen with `volcap bench temporal` (docs/eval-video/temporal.md): low cutoffs while
/// still (0.3 Hz); a map pixel's rate of change averaged below 0.7 Hz, so sensor noise
/// (which changes sign each frame) leaves the filter closed while a real change (a pixel
/// changing by its own size) passes at ~0.6 on its first frame and ~0.9 by its third; the
/// mask held where fewer than 8 % of a block's pixels change side, and for at most two
/// frames where they keep to their new side (ten while the crop stays put); the maps taken
/// as they are where the mask moved.
impl Default for TemporalSettings {
    fn default() -> Self {
        Self {
            crop_min_cutoff_hz: 0.3,
            crop_beta: 40.0,
            crop_hold: CROP_HOLD_DEFAULT,
            mask_low: 0.2,
            mask_high: 0.8,
            mask_motion: 0.08,
            mask_hold_frames: 2,
            mask_still_hold_frames: 10,
            mask_dead_band: 0.1,
            surface_dead_band: 0.06,
            map_min_cutoff_hz: 0.3,
            map_beta: 1.0,
            map_change_cutoff_hz: 0.7,
            map_motion_weight: 1.0,
            same_person_iou: 0.5,
            max_gap_s: 0.5,
        }
    }
}

impl TemporalSettings {
    /// Every setting in its range; the error is the setting's name and why its value is not.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        let within = |name: &'static str, v: f32, ok: bool, range: &str| {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err((name, format!("{name} = {v}: need a value in {range}")))
            }
        };
        for (name, v) in [
            ("crop_min_cutoff_hz", self.crop_min_cutoff_hz),
            ("map_min_cutoff_hz", self.map_min_cutoff_hz),
            ("map_change_cutoff_hz", self.map_change_cutoff_hz),
        ] {
            within(name, v, v > 0.0 && v <= 100.0, "(0, 100] Hz")?;
        }
        let g = self.max_gap_s;
        within("max_gap_s", g, g > 0.0 && g <= 60.0, "(0, 60] s")?;
        for (name, v) in [("crop_beta", self.crop_beta), ("map_beta", self.map_beta)] {
            within(name, v, (0.0..=10_000.0).contains(&v), "[0, 10000]")?;
        }
        let h = self.crop_hold;
        within(
            "crop_hold",
            h,
            (0.0..=0.05).contains(&h),
            "[0, 0.05] (of the crop's half-side)",
        )?;
        let (lo, hi) = (self.mask_low, self.mask_high);
        within("mask_low", lo, lo > 0.0 && lo <= 0.5, "(0, 0.5]")?;
        within("mask_high", hi, (0.5..1.0).contains(&hi), "[0.5, 1)")?;
        let mm = self.mask_motion;
        within(
            "mask_motion",
            mm,
            mm > 0.0 && mm <= 1.0,
            "(0, 1] (of a block's pixels)",
        )?;
        for (name, hold) in [
            ("mask_hold_frames", self.mask_hold_frames),
            ("mask_still_hold_frames", self.mask_still_hold_frames),
        ] {
            if !(1..=255).contains(&hold) {
                return Err((
                    name,
                    format!("{name} = {hold}: need a whole number of frames in [1, 255]"),
                ));
            }
        }
        let md = self.mask_dead_band;
        within("mask_dead_band", md, (0.0..=0.5).contains(&md), "[0, 0.5]")?;
        let (sd, max) = (self.surface_dead_band, crate::sides::MAX_BAND);
        let range = format!("[0, {max}]");
        within("surface_dead_band", sd, (0.0..=max).contains(&sd), &range)?;
        let mw = self.map_motion_weight;
        within("map_motion_weight", mw, (0.0..=1.0).contains(&mw), "[0, 1]")?;
        let iou = self.same_person_iou;
        within("same_person_iou", iou, (0.0..=1.0).contains(&iou), "[0, 1]")?;
        Ok(())
    }
}
