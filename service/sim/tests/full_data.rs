//! Checks against the full MakeHuman data (MANIFEST reference values). Skipped with a
//! message when `../shared/data/makehuman` is not beside the checkout.

use std::path::PathBuf;
use volcap_sim::assets::{HumanAssets, Selection};
use volcap_sim::subject::{Posed, Subject, SubjectSpec};

fn data() -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/makehuman");
    if p.join("3dobjs/base.obj").exists() {
        Some(p)
    } else {
        // CI has shared/ beside the checkout: there this is a failure. Elsewhere it is
        // said past the harness's capture, so the run's output shows the skip.
        assert!(
            std::env::var("CI").is_err(),
            "required in CI, but {} is not present",
            p.display()
        );
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr().lock(),
            "SKIPPED {}: {} not present",
            std::thread::current().name().unwrap_or("full_data"),
            p.display()
        );
        None
    }
}

fn body_height_and_volume(a: &HumanAssets, s: &Subject) -> (f64, f64) {
    let ys = a
        .body_tris
        .iter()
        .flatten()
        .map(|&i| s.rest[i as usize].y as f64);
    let (lo, hi) = ys.fold((f64::MAX, f64::MIN), |(l, h), y| (l.min(y), h.max(y)));
    let vol: f64 = a
        .body_tris
        .iter()
        .map(|t| {
            let [p, q, r] = t.map(|i| s.rest[i as usize].as_dvec3());
            p.dot(q.cross(r)) / 6.0
        })
        .sum();
    (hi - lo, vol)
}

#[test]
fn macro_model_reproduces_the_manifest_reference_shapes() {
    let Some(dir) = data() else { return };
    let sel = Selection {
        targets: |n| n.starts_with("macrodetails/"),
        ..Selection::runtime()
    };
    let a = HumanAssets::from_makehuman(&dir, &sel).unwrap();
    for (g, h_ref, v_ref) in [
        (0.5, 16.594, 54.906),
        (0.0, 15.898, 47.962),
        (1.0, 17.304, 63.320),
    ] {
        let s = Subject::new(
            &a,
            &SubjectSpec {
                gender: g,
                ..Default::default()
            },
        )
        .unwrap();
        let (h, v) = body_height_and_volume(&a, &s);
        assert!(
            (h - h_ref).abs() < 0.01,
            "gender {g}: height {h} vs {h_ref}"
        );
        assert!(
            (v - v_ref).abs() < 0.05,
            "gender {g}: volume {v} vs {v_ref}"
        );
    }
}

#[test]
fn tpose_puts_arms_along_x_and_the_runtime_pack_matches_the_full_data() {
    let Some(dir) = data() else { return };
    let full = HumanAssets::from_makehuman(&dir, &Selection::runtime()).unwrap();
    let embedded = HumanAssets::embedded().unwrap();
    assert_eq!(full.base.len(), embedded.base.len());
    assert_eq!(
        full.targets.keys().collect::<Vec<_>>(),
        embedded.targets.keys().collect::<Vec<_>>()
    );
    let s = Subject::new(&full, &SubjectSpec::default()).unwrap();
    let mut rot = Vec::new();
    volcap_sim::pose::static_pose(&full, "tpose", &mut rot).unwrap();
    let mut posed = Posed::default();
    s.pose(&full, &rot, &mut posed);
    // Wrists: far out along +-x at shoulder height.
    let find = |n: &str| full.bones.iter().position(|b| b.name == n).unwrap();
    let (wl, wr) = (find("wrist.L"), find("wrist.R"));
    let joint = |b: usize| {
        let vs = &full.joints[full.bones[b].head as usize];
        vs.iter()
            .map(|&i| posed.verts[i as usize])
            .sum::<glam::Vec3>()
            / vs.len() as f32
    };
    let (l, r) = (joint(wl), joint(wr));
    assert!(l.x > 0.6 && r.x < -0.6, "wrists at {l} {r}");
    assert!((l.y - r.y).abs() < 0.05 && l.y > 1.2, "wrists at {l} {r}");
}
