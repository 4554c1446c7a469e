//! Dataset shards: deterministic, split by identity, balanced, readable.

use safetensors::SafeTensors;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
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
    // The views' shards written on three threads: the same files, byte for byte.
    let threaded = DatasetConfig {
        threads: 3,
        ..cfg.clone()
    };
    let mut seen = Vec::new();
    assert_eq!(
        generate(assets.clone(), &threaded, &b, |d| seen.push(d)).unwrap(),
        6
    );
    assert_eq!(
        seen.last(),
        Some(&6),
        "progress ends at the count: {seen:?}"
    );
    assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
    let fa = files(&a);
    assert_eq!(fa.len(), 6);
    assert_eq!(files(&b).len(), 6);
    for f in &fa {
        let g = b.join(f.strip_prefix(&a).unwrap());
        assert!(
            std::fs::read(f).unwrap() == std::fs::read(g).unwrap(),
            "not deterministic (one thread against three): {}",
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

fn tensor_bytes(path: &Path, name: &str) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    st.tensor(name).unwrap().data().to_vec()
}

/// The scene text a shard's metadata holds (what reproduces its image).
fn shard_scene(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap();
    let (_, meta) = SafeTensors::read_metadata(&bytes).unwrap();
    let info: serde_json::Value =
        serde_json::from_str(&meta.metadata().as_ref().unwrap()["volcap"]).unwrap();
    info["scene"].as_str().unwrap().to_string()
}

/// A small dataset configuration at 48 px.
fn tiny(subjects: usize, poses: usize, views: usize, seed: u64) -> DatasetConfig {
    DatasetConfig {
        subjects,
        poses,
        views,
        size: 48,
        points: 200,
        surface_points: 50,
        seed,
        ..Default::default()
    }
}

/// Two datasets from the embedded assets under a fresh temporary folder: (folder, a, b).
fn pair(tag: &str, a: &DatasetConfig, b: &DatasetConfig) -> (PathBuf, PathBuf, PathBuf) {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let base = std::env::temp_dir().join(format!("volcap-ds-{tag}-{}", std::process::id()));
    let (da, db) = (base.join("a"), base.join("b"));
    generate(assets.clone(), a, &da, |_| {}).unwrap();
    generate(assets, b, &db, |_| {}).unwrap();
    (base, da, db)
}

#[test]
fn varied_lighting_changes_only_the_shading() {
    use volcap_sim::dataset::DatasetLighting;
    let cfg = tiny(2, 2, 2, 3);
    let vcfg = DatasetConfig {
        lighting: DatasetLighting::Varied,
        ..cfg.clone()
    };
    let (base, studio, varied) = pair("light", &cfg, &vcfg);
    let fs = files(&studio);
    assert_eq!(fs.len(), 8);
    let mut scenes = BTreeSet::new();
    for f in &fs {
        let g = varied.join(f.strip_prefix(&studio).unwrap());
        // Same subjects, poses, views and labels...
        for name in ["mask", "points", "occ", "ray_offsets", "ray_z", "surface"] {
            assert!(
                tensor_bytes(f, name) == tensor_bytes(&g, name),
                "{name} differs in {}",
                g.display()
            );
        }
        // ...under another light.
        let (a, b) = (tensor_bytes(f, "image"), tensor_bytes(&g, "image"));
        let diff = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        assert!(
            diff > a.len() / 20,
            "{}: only {diff} bytes differ",
            g.display()
        );
        let scene = shard_scene(&g);
        assert!(
            scene.contains("# varied rig") && scene.contains("sh = ["),
            "{scene}"
        );
        scenes.insert(scene);
    }
    // One rig per pose: 2 subjects x 2 poses, the views of a pose share it.
    assert_eq!(scenes.len(), 4);
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(varied.join("dataset.json")).unwrap())
            .unwrap();
    assert_eq!(manifest["lighting"], "varied");
    std::fs::remove_dir_all(&base).ok();
}

#[test]
fn varied_rigs_are_bounded_never_black_and_come_from_all_sides() {
    use rand::SeedableRng;
    use volcap_sim::Scene;
    let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    // Normals on a Fibonacci sphere.
    let normals: Vec<glam::Vec3> = (0..200)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / 200.0;
            let a = i as f32 * 2.399_963;
            let s = (1.0 - y * y).sqrt();
            glam::Vec3::new(s * a.cos(), y, s * a.sin())
        })
        .collect();
    let (mut pos_x, mut neg_x, mut pos_z, mut neg_z) = (0, 0, 0, 0);
    for _ in 0..300 {
        let table = volcap_sim::dataset::varied_lighting(&mut r);
        // The table is a valid scene lighting table.
        let text = volcap_sim::dataset::scene_text_framed(
            32,
            "[[subject]]\nid = \"a\"\n",
            volcap_sim::dataset::Motion::new(volcap_sim::pose::Style::ALL[0], 1),
            2.3,
            0.95,
            &table,
        );
        let scene =
            Scene::parse(&text, Path::new("rig.toml")).unwrap_or_else(|e| panic!("{table}: {e}"));
        let sh = scene.lighting.sh.as_ref().expect("explicit SH");
        let coeffs: Vec<[f32; 3]> = sh.iter().map(|c| c.map(|x| x.0)).collect();
        let sh9 = volcap_sim::raster::Sh9 {
            coeffs: coeffs.clone().try_into().unwrap(),
        };
        let e: Vec<f32> = normals.iter().map(|n| sh9.irradiance(*n).x).collect();
        assert!(e.iter().all(|v| v.is_finite() && *v <= 2.5), "{table}");
        let mean = e.iter().sum::<f32>() / e.len() as f32;
        assert!(mean > 0.05, "{table}: mean irradiance {mean}");
        // Band-1 coefficients (y, z, x order) carry the light's direction.
        let (z, x) = (coeffs[2][1], coeffs[3][1]);
        pos_x += (x > 0.02) as u32;
        neg_x += (x < -0.02) as u32;
        pos_z += (z > 0.02) as u32;
        neg_z += (z < -0.02) as u32;
    }
    for (n, side) in [(pos_x, "+x"), (neg_x, "-x"), (pos_z, "+z"), (neg_z, "-z")] {
        assert!(n > 50, "only {n} of 300 rigs lit from {side}");
    }
}

#[test]
fn a_pose_seed_keeps_the_people_and_split_and_draws_new_poses() {
    let cfg = tiny(3, 1, 1, 9);
    let pcfg = DatasetConfig {
        pose_seed: Some(4),
        ..cfg.clone()
    };
    let (base, a, b) = pair("pose", &cfg, &pcfg);
    let manifest = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("dataset.json")).unwrap()).unwrap()
    };
    let (ma, mb) = (manifest(&a), manifest(&b));
    assert_eq!(ma["split"], mb["split"]);
    assert_eq!(ma["subject_tables"], mb["subject_tables"]);
    assert_eq!(mb["pose_seed"], 4);
    let fa = files(&a);
    assert_eq!(fa.len(), 3);
    for f in &fa {
        let g = b.join(f.strip_prefix(&a).unwrap());
        assert!(g.exists(), "{} missing: the split changed", g.display());
        assert!(
            tensor_bytes(f, "points") != tensor_bytes(&g, "points"),
            "{}: same points under another pose seed",
            g.display()
        );
    }
    std::fs::remove_dir_all(&base).ok();
}

/// The manifest records the wardrobe the identities were dressed from (the embedded pack's
/// three outfits here), and every subject wears only items of it.
#[test]
fn the_manifest_names_the_wardrobe_and_every_subject_is_dressed_from_it() {
    let cfg = tiny(12, 1, 1, 5);
    let (base, a, _) = pair("wardrobe", &cfg, &cfg);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("dataset.json")).unwrap()).unwrap();
    let assets = HumanAssets::embedded().unwrap();
    let listed = |k: &str| -> BTreeSet<String> {
        m["wardrobe"][k]
            .as_array()
            .unwrap_or_else(|| panic!("wardrobe.{k}: {m}"))
            .iter()
            .map(|v| v.as_str().unwrap().to_string())
            .collect()
    };
    let outfits = listed("outfits");
    let shoes = listed("shoes");
    assert_eq!(outfits.len(), 3, "{outfits:?}");
    assert_eq!(
        listed("skins"),
        assets.skins.keys().cloned().collect::<BTreeSet<_>>()
    );
    for k in ["outfits", "shoes", "hair"] {
        for n in listed(k) {
            assert!(assets.garments.contains_key(&n), "{k}: {n}");
        }
    }
    let mut worn = BTreeSet::new();
    for t in m["subject_tables"].as_object().unwrap().values() {
        for line in t.as_str().unwrap().lines() {
            let Some((key, v)) = line.split_once(" = ") else {
                continue;
            };
            let v = v.trim_matches('"').to_string();
            match key {
                "outfit" => assert!(outfits.contains(&v), "{v}"),
                "shoes" => assert!(shoes.contains(&v), "{v}"),
                _ => continue,
            }
            worn.insert(v);
        }
    }
    assert!(worn.len() >= 3, "12 people in at least 3 items: {worn:?}");
    std::fs::remove_dir_all(&base).ok();
}

#[test]
fn lighting_names_round_trip_and_others_are_refused_by_name() {
    use volcap_sim::dataset::DatasetLighting;
    for l in DatasetLighting::ALL {
        assert_eq!(l.name().parse::<DatasetLighting>(), Ok(l));
    }
    let err = "sunny".parse::<DatasetLighting>().unwrap_err();
    assert!(
        err.contains("\"sunny\"") && err.contains("studio, varied"),
        "{err}"
    );
}

/// The coloured surface samples (`surface`, `surface_rgb`: what the colour networks learn)
/// are on the surface a view shows: every even sample is where its pixel's ray first meets
/// the person, every odd one where it last leaves, so 1 cm nearer the camera (even) or
/// farther (odd) along that ray is outside the person. Samples of the whole clothed surface
/// failed this: the body under the clothes, coloured skin that no view shows.
#[test]
fn coloured_surface_samples_are_the_surface_a_view_shows() {
    use volcap_sim::{Scene, Simulator};
    let cfg = DatasetConfig {
        points: 100,
        surface_points: 200,
        ..tiny(2, 1, 2, 19)
    };
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let base = std::env::temp_dir().join(format!("volcap-ds-seen-{}", std::process::id()));
    generate(assets.clone(), &cfg, &base, |_| {}).unwrap();
    let fs = files(&base);
    assert_eq!(fs.len(), 4);
    for f in &fs {
        let bytes = std::fs::read(f).unwrap();
        let (_, meta) = SafeTensors::read_metadata(&bytes).unwrap();
        let info: serde_json::Value =
            serde_json::from_str(&meta.metadata().as_ref().unwrap()["volcap"]).unwrap();
        let scene = Scene::parse(info["scene"].as_str().unwrap(), Path::new("shard")).unwrap();
        let mut sim = Simulator::new(scene, assets.clone()).unwrap();
        sim.set_view_yaw(info["yaw_deg"].as_f64().unwrap() as f32);
        let frame = sim.render(info["frame"].as_u64().unwrap()).unwrap();
        let oracle = sim.oracle(cfg.voxel_m);
        let view = frame.camera.projector();
        let floats = |name: &str| -> Vec<f32> {
            tensor_bytes(f, name)
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        };
        let (surface, rgb) = (floats("surface"), floats("surface_rgb"));
        assert_eq!(surface.len(), 3 * cfg.surface_points, "{}", f.display());
        assert_eq!(rgb.len(), surface.len());
        assert!(rgb.iter().all(|c| c.is_finite() && (0.0..=1.0).contains(c)));
        for (k, p) in surface.chunks_exact(3).enumerate() {
            let ndc = glam::Vec3::new(p[0], p[1], p[2]);
            let on = view.ndc_to_world(ndc);
            // 1 cm along the ray toward the camera (even: larger z is nearer) or away.
            let dir = (view.ndc_to_world(ndc + glam::Vec3::Z) - on).normalize();
            let out = if k % 2 == 0 {
                on + dir * 0.01
            } else {
                on - dir * 0.01
            };
            assert!(
                oracle.oracle.occupancy(out) <= 0.5,
                "{} sample {k} at {on} (NDC {ndc}): inside 1 cm beyond it ({})",
                f.display(),
                oracle.oracle.occupancy(out)
            );
        }
    }
    std::fs::remove_dir_all(&base).ok();
}

/// A shard that cannot be written fails the whole dataset with the path named, on one
/// thread and on several (the workers' error reaches the caller; nothing hangs).
#[test]
fn a_shard_that_cannot_be_written_is_an_error_naming_it() {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    for threads in [1, 3] {
        let cfg = DatasetConfig {
            subjects: 2,
            poses: 1,
            views: 2,
            size: 48,
            points: 200,
            surface_points: 50,
            seed: 3,
            threads,
            ..Default::default()
        };
        let out =
            std::env::temp_dir().join(format!("volcap-ds-err-{}-{threads}", std::process::id()));
        // A folder (with a file in it) where each subject's second view would go: the
        // rename onto it fails.
        for split in ["train", "val"] {
            for s in ["s000", "s001"] {
                let blocker = out.join(split).join(s).join("000_01.safetensors");
                std::fs::create_dir_all(&blocker).unwrap();
                std::fs::write(blocker.join("keep"), b"x").unwrap();
            }
        }
        let err = generate(assets.clone(), &cfg, &out, |_| {}).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("000_01.safetensors"),
            "threads {threads}: {msg}"
        );
        std::fs::remove_dir_all(&out).unwrap();
    }
}

/// `hands: Varied` draws the same people, poses and views with drawn wrists and fingers: the
/// masks differ only around the hands, the scene text says so, a rest dataset's does not
/// (its scene text, and so its files, as before the key existed).
#[test]
fn varied_hands_keep_the_bodies_and_move_the_hands() {
    use volcap_sim::pose::Hands;
    let cfg = DatasetConfig {
        size: 96,
        ..tiny(2, 2, 2, 4)
    };
    let hcfg = DatasetConfig {
        hands: Hands::Varied,
        ..cfg.clone()
    };
    let (base, rest, varied) = pair("hands", &cfg, &hcfg);
    let fs = files(&rest);
    assert_eq!(fs.len(), 8);
    let mut changed = 0;
    for f in &fs {
        let g = varied.join(f.strip_prefix(&rest).unwrap());
        let (sr, sv) = (shard_scene(f), shard_scene(&g));
        assert!(!sr.contains("hands"), "{sr}");
        assert!(sv.contains("hands = \"varied\""), "{sv}");
        assert_eq!(
            sr,
            sv.replace(", hands = \"varied\"", ""),
            "only the hands key differs"
        );
        let (a, b) = (tensor_bytes(f, "mask"), tensor_bytes(&g, "mask"));
        let person = a.iter().filter(|x| **x != 0).count();
        let diff = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        assert!(
            diff * 8 < person,
            "{}: {diff} of the person's {person} mask values differ",
            g.display()
        );
        changed += diff;
    }
    assert!(changed > 0, "no mask changed with the hands");
    let hands_of = |d: &Path| -> serde_json::Value {
        serde_json::from_str::<serde_json::Value>(
            &std::fs::read_to_string(d.join("dataset.json")).unwrap(),
        )
        .unwrap()["hands"]
            .clone()
    };
    assert_eq!(hands_of(&rest), "rest");
    assert_eq!(hands_of(&varied), "varied");
    for h in Hands::ALL {
        assert_eq!(h.name().parse::<Hands>(), Ok(h));
    }
    let err = "fist".parse::<Hands>().unwrap_err();
    assert!(
        err.contains("\"fist\"") && err.contains("rest or varied"),
        "{err}"
    );
    std::fs::remove_dir_all(&base).ok();
}
