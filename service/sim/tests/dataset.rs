//! Dataset shards: deterministic, split by identity, balanced, readable.

use safetensors::SafeTensors;
use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;
use volcap_sim::HumanAssets;
use volcap_sim::dataset::{DatasetConfig, generate};

fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut v = Vec::new();
    for split in ["train", "val"] {
        for s in std::fs::read_dir(dir.join(split))
            .into_iter()
            .flatten()
            .flatten()
        {
            for f in std::fs::read_dir(s.path()).into_iter().flatten().flatten() {
                v.push(f.path());
            }
        }
    }
    v.sort();
    v
}

#[test]
fn tiny_dataset_is_deterministic_split_by_identity_and_balanced() {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let cfg = DatasetConfig {
        subjects: 3,
        poses: 1,
        views: 2,
        size: 64,
        points: 400,
        surface_points: 100,
        seed: 7,
        ..Default::default()
    };
    let base = std::env::temp_dir().join(format!("volcap-ds-{}", std::process::id()));
    let (a, b) = (base.join("a"), base.join("b"));
    assert_eq!(generate(assets.clone(), &cfg, &a, |_| {}).unwrap(), 6);
    generate(assets.clone(), &cfg, &b, |_| {}).unwrap();
    let fa = files(&a);
    assert_eq!(fa.len(), 6);
    for f in &fa {
        let g = b.join(f.strip_prefix(&a).unwrap());
        assert!(
            std::fs::read(f).unwrap() == std::fs::read(g).unwrap(),
            "not deterministic: {}",
            f.display()
        );
    }
    // Split by identity: no subject in both.
    let subjects = |split: &str| -> BTreeSet<String> {
        std::fs::read_dir(a.join(split))
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().to_string())
            .collect()
    };
    let (tr, va) = (subjects("train"), subjects("val"));
    assert!(!tr.is_empty() && !va.is_empty());
    assert!(tr.is_disjoint(&va));
    for f in &fa {
        let bytes = std::fs::read(f).unwrap();
        let st = SafeTensors::deserialize(&bytes).unwrap();
        assert_eq!(st.tensor("image").unwrap().shape(), &[64, 64, 3]);
        assert_eq!(st.tensor("mask").unwrap().shape(), &[64, 64]);
        let occ = st.tensor("occ").unwrap();
        let occ: Vec<f32> = occ
            .data()
            .chunks(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert_eq!(occ.len(), 400);
        assert_eq!(
            occ.iter().filter(|&&o| o == 1.0).count(),
            200,
            "balanced inside/outside"
        );
        let pts: Vec<f32> = st
            .tensor("points")
            .unwrap()
            .data()
            .chunks(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert!(pts.iter().all(|v| v.is_finite()));
        // Inside points project into the view, mostly onto the person mask.
        let mask = st.tensor("mask").unwrap().data().to_vec();
        let on_mask = pts
            .chunks(3)
            .zip(&occ)
            .filter(|(_, o)| **o == 1.0)
            .filter(|(p, _)| {
                let (x, y) = (
                    ((p[0] + 1.0) * 0.5 * 63.0).round() as usize,
                    ((p[1] + 1.0) * 0.5 * 63.0).round() as usize,
                );
                x < 64 && y < 64 && mask[y * 64 + x] > 0
            })
            .count();
        assert!(
            on_mask >= 170,
            "{}: only {on_mask} of 200 inside points on the mask",
            f.display()
        );
        let (_, meta) = SafeTensors::read_metadata(&bytes).unwrap();
        let md = meta.metadata().as_ref().unwrap();
        let info: serde_json::Value = serde_json::from_str(&md["volcap"]).unwrap();
        assert!(
            info["camera"]["width"] == 64 && (info["split"] == "train" || info["split"] == "val")
        );
    }
    std::fs::remove_dir_all(&base).ok();
}
