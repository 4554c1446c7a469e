//! The Fourier files' `volcap.*` metadata through the engine: each key checked at load (a bad
//! value refused naming the file and the key) and applied.

mod common;

use common::{Golden, golden_input, models_dir, points};
use std::path::{Path, PathBuf};
use volcap_engine::model::{FourierNet, Models, Precision};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volcap-meta-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The committed `fourier` file written to `dir` with its metadata `key` set to `value`.
fn with_meta(key: &str, value: &str, dir: &Path) {
    use prost::Message;
    use tract_onnx::prelude::Framework;
    let src = FourierNet::path(&models_dir(), "fourier", Precision::F32);
    let mut m = tract_onnx::onnx().proto_model_for_path(&src).unwrap();
    m.metadata_props.retain(|p| p.key != key);
    let mut p = m.metadata_props[0].clone();
    p.key = key.into();
    p.value = value.into();
    m.metadata_props.push(p);
    std::fs::write(
        FourierNet::path(dir, "fourier", Precision::F32),
        m.encode_to_vec(),
    )
    .unwrap();
}

/// `volcap.iso_level`: a value outside (0, 1) or not a number is refused naming the file and
/// the key; a valid one is what the maps read as the surface (decoded values move by
/// `0.5 - level` against the same maps read at 0.5).
#[test]
fn fourier_surface_level_metadata_is_checked_and_applied() {
    let with_level = |value: &str, dir: &Path| with_meta("volcap.iso_level", value, dir);
    let dir = tmp("iso");
    for bad in ["0", "1", "-0.2", "NaN", "inf", "half"] {
        with_level(bad, &dir);
        let e = FourierNet::load(&dir, "fourier", Precision::F32)
            .err()
            .unwrap_or_else(|| panic!("iso level {bad:?} was accepted"))
            .to_string();
        assert!(
            e.contains("shape-fourier.fourier.onnx") && e.contains("volcap.iso_level"),
            "{bad}: {e}"
        );
    }
    with_level("0.35", &dir);
    let mut low = FourierNet::load(&dir, "fourier", Precision::F32).unwrap();
    assert_eq!(low.iso_level, 0.35);
    let mut plain = FourierNet::load(&models_dir(), "fourier", Precision::F32).unwrap();
    plain.iso_level = 0.5;
    // The network's own maps on both sides: the smoothing gives rays back by the level they
    // are read at (`FourierMaps::smoothed`), which this test does not compare.
    (plain.smooth_passes, low.smooth_passes) = (0, 0);
    let g = Golden::load("shape-fourier");
    let (x, _) = golden_input(&g);
    let (a, b) = (plain.maps(&x).unwrap(), low.maps(&x).unwrap());
    assert_eq!(b.iso_level(), 0.35);
    let pts = points(&g);
    let (mut oa, mut ob) = (vec![0.0; pts.len()], vec![0.0; pts.len()]);
    a.occupancy(&pts, &mut oa, &mut Vec::new());
    b.occupancy(&pts, &mut ob, &mut Vec::new());
    let mut moved = 0;
    for (u, v) in oa.iter().zip(&ob) {
        assert!(v.is_finite() && (0.0..=1.0).contains(v));
        if *u > 0.0 && *u < 0.85 && *v < 1.0 {
            assert!((v - u - 0.15).abs() < 1e-5, "{u} -> {v}");
            moved += 1;
        }
    }
    assert!(moved > 10, "only {moved} points inside the clamp range");
    std::fs::remove_dir_all(&dir).ok();
}

/// `volcap.segment_passes`: the passes a Fourier model was trained on are the ones it is
/// loaded with (`Models::segment_passes`, the daemon's `[model] segment_passes` unset), read
/// the same without building a network (`trained_segment_passes`, for the tools); absent
/// reads 1, and a count outside the engine's range is refused naming the file and the key.
#[test]
fn fourier_segment_passes_metadata_is_checked_and_loaded() {
    use volcap_engine::model::trained_segment_passes;
    // The committed files: the default model was trained on two-pass masks, fourier-small on one.
    let dir = models_dir();
    for (name, want) in [
        ("fourier-small-seg2", 2),
        ("fourier-small", 1),
        ("compact", 1),
    ] {
        for prec in [Precision::F32, Precision::Int8] {
            assert_eq!(
                trained_segment_passes(&dir, name, prec).unwrap(),
                want,
                "{name}"
            );
        }
        let m = Models::load(&dir, name, Precision::F32).unwrap();
        assert_eq!(m.segment_passes, want, "{name}");
        assert_eq!(m.shape.trained_segment_passes(), want, "{name}");
    }
    assert_eq!(
        trained_segment_passes(&dir, volcap_engine::model::DEFAULT_MODEL, Precision::F32).unwrap(),
        2
    );
    let with_passes = |value: &str, dir: &Path| with_meta("volcap.segment_passes", value, dir);
    let dir = tmp("passes");
    for bad in ["0", "3", "-1", "two", ""] {
        with_passes(bad, &dir);
        for e in [
            FourierNet::load(&dir, "fourier", Precision::F32)
                .err()
                .unwrap_or_else(|| panic!("segment passes {bad:?} was accepted"))
                .to_string(),
            trained_segment_passes(&dir, "fourier", Precision::F32)
                .unwrap_err()
                .to_string(),
        ] {
            assert!(
                e.contains("shape-fourier.fourier.onnx")
                    && e.contains("volcap.segment_passes")
                    && e.contains("1..=2"),
                "{bad}: {e}"
            );
        }
    }
    with_passes("2", &dir);
    assert_eq!(
        FourierNet::load(&dir, "fourier", Precision::F32)
            .unwrap()
            .segment_passes,
        2
    );
    assert_eq!(
        trained_segment_passes(&dir, "fourier", Precision::F32).unwrap(),
        2
    );
    std::fs::remove_dir_all(&dir).ok();
}
