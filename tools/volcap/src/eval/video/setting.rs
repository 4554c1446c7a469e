//! `bench temporal`'s `--setting` values: the temporal filter's keys and the segmentation's
//! track.

use anyhow::{anyhow, bail};
use volcap_engine::model::temporal::TemporalSettings;

/// A `--setting` value: its label, the filter (none: off), the segmentation's track
/// (`segment_full_every`, the daemon's `[model]` key: 1 segments every frame whole) and the
/// maps' smoothing (`map_smooth`, the daemon's `[model]` key: passes, 0 none).
#[derive(Debug, Clone, PartialEq)]
pub struct Setting {
    pub label: String,
    pub filter: Option<TemporalSettings>,
    pub segment_full_every: u32,
    pub map_smooth: u8,
}

/// Parse a `--setting`: `off`, `default`, or `+`-joined `KEY=VALUE`s over the defaults
/// (`[temporal]`'s keys, and `[model]`'s `segment_full_every` and `map_smooth`), optionally
/// with `off` among them (no filter: then only `[model]`'s keys may follow).
pub fn parse_setting(s: &str) -> anyhow::Result<Setting> {
    let s = s.trim();
    let mut t = TemporalSettings::default();
    let (mut off, mut filter_keys, mut full_every) = (false, false, 1u32);
    let mut smooth = volcap_engine::model::fourier::DEFAULT_SMOOTH_PASSES;
    for kv in s.split('+') {
        let kv = kv.trim();
        match kv {
            "off" => {
                off = true;
                continue;
            }
            "default" => continue,
            _ => {}
        }
        let (k, v) = kv
            .split_once('=')
            .ok_or_else(|| anyhow!("--setting {s}: '{kv}' is not KEY=VALUE (or off, default)"))?;
        let v: f32 = v
            .trim()
            .parse()
            .map_err(|_| anyhow!("--setting {s}: {k} = '{v}' is not a number"))?;
        let whole = |range: std::ops::RangeInclusive<f32>| {
            if v.fract() != 0.0 || !range.contains(&v) {
                bail!(
                    "--setting {s}: {k} = {v} is not a whole number in {}..={}",
                    range.start(),
                    range.end()
                );
            }
            Ok(v as u32)
        };
        match k.trim() {
            "segment_full_every" => {
                full_every = whole(1.0..=volcap_engine::model::SEGMENT_FULL_EVERY_MAX as f32)?;
                continue;
            }
            "map_smooth" => {
                let max = volcap_engine::model::fourier::MAX_SMOOTH_PASSES;
                smooth = whole(0.0..=f32::from(max))? as u8;
                continue;
            }
            "mask_hold_frames" => {
                t.mask_hold_frames = whole(0.0..=255.0)?;
                filter_keys = true;
                continue;
            }
            "mask_still_hold_frames" => {
                t.mask_still_hold_frames = whole(0.0..=255.0)?;
                filter_keys = true;
                continue;
            }
            _ => {}
        }
        let slot = match k.trim() {
            "crop_min_cutoff_hz" => &mut t.crop_min_cutoff_hz,
            "crop_beta" => &mut t.crop_beta,
            "crop_hold" => &mut t.crop_hold,
            "mask_low" => &mut t.mask_low,
            "mask_high" => &mut t.mask_high,
            "mask_motion" => &mut t.mask_motion,
            "mask_dead_band" => &mut t.mask_dead_band,
            "surface_dead_band" => &mut t.surface_dead_band,
            "map_min_cutoff_hz" => &mut t.map_min_cutoff_hz,
            "map_beta" => &mut t.map_beta,
            "map_change_cutoff_hz" => &mut t.map_change_cutoff_hz,
            "map_motion_weight" => &mut t.map_motion_weight,
            "same_person_iou" => &mut t.same_person_iou,
            other => bail!("--setting {s}: unknown key '{other}'"),
        };
        *slot = v;
        filter_keys = true;
    }
    if off && filter_keys {
        bail!("--setting {s}: 'off' (no filter) with the filter's keys");
    }
    t.check().map_err(|(_, e)| anyhow!("--setting {s}: {e}"))?;
    Ok(Setting {
        label: s.to_string(),
        filter: (!off).then_some(t),
        segment_full_every: full_every,
        map_smooth: smooth,
    })
}
