//! `bench temporal`'s settings.

use super::*;
use volcap_engine::model::temporal::TemporalSettings;

/// `--setting`: the filter's keys and the segmentation's track, `off` with the track
/// only, and bad values named.
#[test]
fn settings_parse_the_filter_and_the_track() {
    let s = parse_setting("off").unwrap();
    assert_eq!((s.filter, s.segment_full_every), (None, 1));
    let s = parse_setting("default").unwrap();
    assert_eq!(s.filter, Some(TemporalSettings::default()));
    let s = parse_setting("off+segment_full_every=8").unwrap();
    assert_eq!((s.filter, s.segment_full_every), (None, 8));
    let s = parse_setting("default+segment_full_every=30").unwrap();
    assert_eq!(s.filter, Some(TemporalSettings::default()));
    assert_eq!(s.segment_full_every, 30);
    let s = parse_setting("mask_hold_frames=3+crop_beta=0.5").unwrap();
    let f = s.filter.unwrap();
    assert_eq!((f.mask_hold_frames, f.crop_beta), (3, 0.5));
    assert_eq!(s.label, "mask_hold_frames=3+crop_beta=0.5");
    assert_eq!(
        s.map_smooth,
        volcap_engine::model::fourier::DEFAULT_SMOOTH_PASSES
    );
    let s = parse_setting("off+map_smooth=0").unwrap();
    assert_eq!((s.filter, s.map_smooth), (None, 0));
    let s = parse_setting("default+map_smooth=4").unwrap();
    assert_eq!(s.map_smooth, 4);
    for (bad, says) in [
        ("map_smooth=5", "0..=4"),
        ("map_smooth=1.5", "whole number"),
        ("segment_full_every=0", "segment_full_every = 0"),
        ("segment_full_every=31", "1..=30"),
        ("segment_full_every=2.5", "whole number"),
        ("off+crop_beta=0.5", "'off'"),
        ("nokey=1", "unknown key 'nokey'"),
        ("crop_beta", "KEY=VALUE"),
    ] {
        let e = parse_setting(bad).unwrap_err().to_string();
        assert!(e.contains(says) && e.contains(bad), "{bad}: {e}");
    }
}
