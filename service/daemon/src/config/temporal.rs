//! `[temporal]`: the model mode's temporal filter settings.

use serde::Deserialize;

/// `[temporal]`: the model mode's temporal filter (`volcap_engine::model::temporal`): the
/// mask, crop and maps held steady while the person is still, let go when they move. On by
/// default; every key defaults to the engine's `TemporalSettings::default()`, chosen from
/// `volcap bench temporal` (docs/eval-video).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TemporalConfig {
    #[serde(default = "d_true")]
    pub enabled: bool,
    pub crop_min_cutoff_hz: Option<f32>,
    pub crop_beta: Option<f32>,
    pub crop_hold: Option<f32>,
    pub mask_low: Option<f32>,
    pub mask_high: Option<f32>,
    pub mask_motion: Option<f32>,
    pub mask_hold_frames: Option<u32>,
    pub mask_still_hold_frames: Option<u32>,
    pub mask_dead_band: Option<f32>,
    pub surface_dead_band: Option<f32>,
    pub map_min_cutoff_hz: Option<f32>,
    pub map_beta: Option<f32>,
    pub map_change_cutoff_hz: Option<f32>,
    pub map_motion_weight: Option<f32>,
    pub same_person_iou: Option<f32>,
    pub max_gap_s: Option<f32>,
}

fn d_true() -> bool {
    true
}

impl Default for TemporalConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            crop_min_cutoff_hz: None,
            crop_beta: None,
            crop_hold: None,
            mask_low: None,
            mask_high: None,
            mask_motion: None,
            mask_hold_frames: None,
            mask_still_hold_frames: None,
            mask_dead_band: None,
            surface_dead_band: None,
            map_min_cutoff_hz: None,
            map_beta: None,
            map_change_cutoff_hz: None,
            map_motion_weight: None,
            same_person_iou: None,
            max_gap_s: None,
        }
    }
}

impl TemporalConfig {
    /// The filter's settings (`None` when `enabled = false`): the engine's defaults with the
    /// keys given here.
    pub fn settings(&self) -> Option<volcap_engine::model::temporal::TemporalSettings> {
        self.enabled.then(|| self.values())
    }

    /// The settings whether enabled or not (checked either way: a bad value is never
    /// silently kept for later).
    pub fn values(&self) -> volcap_engine::model::temporal::TemporalSettings {
        let d = volcap_engine::model::temporal::TemporalSettings::default();
        volcap_engine::model::temporal::TemporalSettings {
            crop_min_cutoff_hz: self.crop_min_cutoff_hz.unwrap_or(d.crop_min_cutoff_hz),
            crop_beta: self.crop_beta.unwrap_or(d.crop_beta),
            crop_hold: self.crop_hold.unwrap_or(d.crop_hold),
            mask_low: self.mask_low.unwrap_or(d.mask_low),
            mask_high: self.mask_high.unwrap_or(d.mask_high),
            mask_motion: self.mask_motion.unwrap_or(d.mask_motion),
            mask_hold_frames: self.mask_hold_frames.unwrap_or(d.mask_hold_frames),
            mask_still_hold_frames: self
                .mask_still_hold_frames
                .unwrap_or(d.mask_still_hold_frames),
            mask_dead_band: self.mask_dead_band.unwrap_or(d.mask_dead_band),
            surface_dead_band: self.surface_dead_band.unwrap_or(d.surface_dead_band),
            map_min_cutoff_hz: self.map_min_cutoff_hz.unwrap_or(d.map_min_cutoff_hz),
            map_beta: self.map_beta.unwrap_or(d.map_beta),
            map_change_cutoff_hz: self.map_change_cutoff_hz.unwrap_or(d.map_change_cutoff_hz),
            map_motion_weight: self.map_motion_weight.unwrap_or(d.map_motion_weight),
            same_person_iou: self.same_person_iou.unwrap_or(d.same_person_iou),
            max_gap_s: self.max_gap_s.unwrap_or(d.max_gap_s),
        }
    }
}

/// The filter's settings as `/state` shows them (`temporal.settings`): every key of
/// `[temporal]` with the value in force, as the file writes it (0.3, not f32's
/// 0.30000001192092896).
pub fn settings_json(s: &volcap_engine::model::temporal::TemporalSettings) -> serde_json::Value {
    let f = |v: f32| v.to_string().parse::<f64>().unwrap_or(f64::NAN);
    serde_json::json!({
        "crop_min_cutoff_hz": f(s.crop_min_cutoff_hz),
        "crop_beta": f(s.crop_beta),
        "crop_hold": f(s.crop_hold),
        "mask_low": f(s.mask_low),
        "mask_high": f(s.mask_high),
        "mask_motion": f(s.mask_motion),
        "mask_hold_frames": s.mask_hold_frames,
        "mask_still_hold_frames": s.mask_still_hold_frames,
        "mask_dead_band": f(s.mask_dead_band),
        "surface_dead_band": f(s.surface_dead_band),
        "map_min_cutoff_hz": f(s.map_min_cutoff_hz),
        "map_beta": f(s.map_beta),
        "map_change_cutoff_hz": f(s.map_change_cutoff_hz),
        "map_motion_weight": f(s.map_motion_weight),
        "same_person_iou": f(s.same_person_iou),
        "max_gap_s": f(s.max_gap_s),
    })
}
