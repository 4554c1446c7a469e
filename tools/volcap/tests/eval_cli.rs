//! `volcap eval` run as a user would, on the ground-truth series (`truth-k15` and the
//! half-range cosine `truth-cos31` of the same channel count; no trained model in the loop):
//! the whole scoring path (render, crop, field, localization, mesh, Chamfer / P2S / IoU and
//! the per-part distances against the truth) in both framings.

use std::process::Command;

/// A one-subject manifest whose assets are all in the embedded pack.
const MANIFEST: &str = r#"{"subject_tables": {"t000": "[[subject]]\nid = \"t000\"\ngender = 0.2\nmuscle = 0.5\nweight = 0.6\nheight = 0.55\nrace = [0, 0, 1]\noutfit = \"female_casualsuit01\"\nshoes = \"shoes01\"\nhair = \"ponytail01\"\nskin = \"young_caucasian_female2\"\n"}, "split": {"t000": "val"}}"#;

fn eval(framing: &str) -> Vec<serde_json::Value> {
    run_eval(
        framing,
        &[
            "--poses",
            "1",
            "--views",
            "2",
            "--res",
            "65",
            "--model",
            "truth-k15,truth-cos31",
            "--framing",
            framing,
        ],
    )
}

/// `volcap eval --subjects val --json ARGS` on the one-subject manifest: its JSON lines (the
/// report and plot written, then the folder removed).
fn run_eval(name: &str, args: &[&str]) -> Vec<serde_json::Value> {
    let dir = std::env::temp_dir().join(format!("volcap-eval-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let manifest = dir.join("manifest.json");
    std::fs::write(&manifest, MANIFEST).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_volcap"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .args(["eval", "--subjects", "val", "--json"])
        .args(args)
        .arg("--manifest")
        .arg(&manifest)
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("eval.md").exists() && dir.join("eval.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// Both bases' truth series score near zero distance and near-full IoU whether or not the
/// frame cuts the person: in the `upper` framing the truth is what the frame shows (were the
/// legs below the edge kept, the Chamfer distance would be tens of centimetres). Per part:
/// every part is scored in the whole framing, the feet are not in the upper one.
#[test]
fn both_framings_score_the_truth_as_near_exact() {
    for (framing, cut) in [("whole", false), ("upper", true)] {
        let rows = eval(framing);
        // Per model: two images, then its summary.
        assert_eq!(rows.len(), 6, "{framing}: {rows:?}");
        for m in rows.chunks(3) {
            for r in &m[..2] {
                assert_eq!(r["status"], "ok", "{framing}: {r}");
                assert_eq!(r["cut_by_frame"], cut, "{framing}: {r}");
                let (ch, p2s, iou) = (
                    r["chamfer_cm"].as_f64().unwrap(),
                    r["p2s_cm"].as_f64().unwrap(),
                    r["iou"].as_f64().unwrap(),
                );
                assert!(ch < 2.0 && p2s < 1.5, "{framing}: {r}");
                assert!(iou > 0.85, "{framing}: {r}");
                // The truth faces the right way: turned around in depth (front and back
                // swapped, the silhouette kept) it is clearly farther from itself.
                let reversed = r["reversed_chamfer_cm"].as_f64().unwrap();
                assert_eq!(r["facing_error"], false, "{framing}: {r}");
                assert!(reversed > ch + 1.0, "{framing}: {r}");
                let parts = r["part_cm"].as_array().unwrap();
                assert_eq!(parts.len(), 6);
                // head, torso, arms, hands, legs: shown in both framings, near the truth
                // (hands, 2-3 cm thick, are coarse on this test's 65^3 grid: the truth's
                // own series scores about 3 cm there, against under 1 cm for the rest).
                for (i, v) in parts[..5].iter().enumerate() {
                    let v = v.as_f64().unwrap_or(f64::NAN);
                    let bound = if i == 3 { 5.0 } else { 2.0 };
                    assert!(v.is_finite() && v < bound, "{framing}: part {i}: {r}");
                }
                // Feet: in the whole framing only.
                assert_eq!(parts[5].is_null(), cut, "{framing}: feet: {r}");
                // The share of each part within 2 cm: over 85 % of every part but the hands
                // for the truth's series (the hands, coarse at 65^3 as above, over 45 %); the
                // feet as above.
                let shown = r["part_shown"].as_array().unwrap();
                assert_eq!(shown.len(), 6);
                for (i, v) in shown[..5].iter().enumerate() {
                    let v = v.as_f64().unwrap_or(f64::NAN);
                    let least = if i == 3 { 0.45 } else { 0.85 };
                    assert!((least..=1.0).contains(&v), "{framing}: part {i} shown: {r}");
                }
                assert_eq!(shown[5].is_null(), cut, "{framing}: feet shown: {r}");
                // The parts' shares of the P2S are each non-negative and add up to it (a
                // part not shown has no reconstructed samples nearest it: 0).
                let shares: Vec<f64> = r["part_p2s_cm"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect();
                assert_eq!(shares.len(), 6);
                assert!(shares.iter().all(|v| *v >= 0.0), "{framing}: {r}");
                let sum: f64 = shares.iter().sum();
                assert!(
                    (sum - p2s).abs() < 1e-9 * p2s.max(1.0),
                    "{framing}: {sum} vs {p2s}"
                );
            }
            assert_eq!(m[2]["failed"], 0, "{framing}");
            assert_eq!(m[2]["facing_errors"], 0, "{framing}");
            // Every image faces right, so the means over those are the means.
            let right = m[2]["facing_right"].as_array().unwrap();
            assert_eq!(right[0].as_f64(), m[2]["chamfer_cm"].as_f64(), "{framing}");
            assert_eq!(right[1].as_f64(), m[2]["p2s_cm"].as_f64(), "{framing}");
        }
        assert!(rows[2]["model"].as_str().unwrap().starts_with("truth-k15"));
        assert!(
            rows[5]["model"]
                .as_str()
                .unwrap()
                .starts_with("truth-cos31")
        );
        assert!(
            rows[5]["family"].as_str().unwrap().contains("cosine"),
            "{}",
            rows[5]
        );
    }
}

/// The experimental decode knobs and the accuracy-against-time knobs (grid, coarse level,
/// method, backend) are refused by name when their values are off (before any image is
/// rendered).
#[test]
fn bad_decode_knobs_are_refused_by_name() {
    for (flag, value) in [
        ("--moment-fill", "0.02,0.01,4"),
        ("--moment-fill", "0.02,0.1"),
        ("--moment-fill", "0.02,0.1,2.5"),
        ("--moment-fill", "nan,0.1,4"),
        ("--peak-level", "1.5,0.2"),
        ("--peak-level", "0.5,0.2,1.5"),
        ("--peak-level", "0.5,0.2,0.5,1"),
        ("--interior-level", "0.5"),
        ("--interior-level", "1.2,2"),
        ("--interior-level", "0.5,2.5"),
        ("--thin-level", "0.45"),
        ("--thin-level", "0.45,0"),
        ("--thin-level", "0,2"),
        ("--segment-passes", "3"),
        ("--segment-passes", "1,0"),
        ("--colour-res", "20"),
        ("--res", "64"),
        ("--res", "33,64"),
        ("--res", "65,65"),
        ("--coarse-level", "3,3"),
        ("--method", "marching"),
        ("--coarse-level", "9"),
        ("--coarse-level", "0"),
        ("--backend", "tpu"),
        ("--backend", "cpu,cpu"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_volcap"))
            .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .args(["eval", "--model", "fourier-small", flag, value])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{flag} {value} accepted");
        assert!(err.contains(flag), "{flag} {value}: {err}");
    }
}

/// The committed manifest's held-out subjects wear outfits the embedded pack does not hold:
/// without `--data` the run stops at once, naming the subject, the manifest and the flag.
#[test]
fn held_out_subjects_without_their_wardrobe_ask_for_data() {
    let out = Command::new(env!("CARGO_BIN_EXE_volcap"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .args(["eval", "--poses", "1", "--views", "1", "--colour-res", "0"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("unknown outfit")
            && err.contains("models/dataset.json")
            && err.contains("--data"),
        "{err}"
    );
}

/// One image, one view, 33^3: the smallest run that still makes every row.
const TINY: [&str; 6] = ["--poses", "1", "--views", "1", "--res", "33"];

/// The models' summary rows of a run's JSON lines (the image rows left out), in order.
fn summaries(rows: &[serde_json::Value]) -> Vec<&serde_json::Value> {
    rows.iter().filter(|r| r.get("family").is_some()).collect()
}

/// The names of summary rows.
fn names<'a>(summaries: &[&'a serde_json::Value]) -> Vec<&'a str> {
    summaries
        .iter()
        .map(|r| r["model"].as_str().unwrap())
        .collect()
}

/// The models' summary rows' names of a [`TINY`] run with `args`, in order.
fn tiny_row_names(name: &str, args: &[&str]) -> Vec<String> {
    let rows = run_eval(name, &[&TINY[..], args].concat());
    names(&summaries(&rows))
        .into_iter()
        .map(String::from)
        .collect()
}

/// The knobs that trade accuracy for time in one run: a row per grid x method, each named
/// for what it changed and carrying its knobs; the finer grid evaluates more points; the
/// rows of one model share its networks' pooled ms (the same networks ran for each), so
/// their ms a frame differ by their localization alone.
#[test]
fn grid_and_method_rows_stand_side_by_side() {
    let rows = run_eval(
        "knobs",
        &[
            &TINY[..2],
            &[
                "--views",
                "1",
                "--colour-res",
                "0",
                "--model",
                "fourier-small",
            ],
            &["--res", "33,65", "--method", "hierarchical,mise"],
        ]
        .concat(),
    );
    let summaries = summaries(&rows);
    let names = names(&summaries);
    assert_eq!(
        names,
        [
            "fourier-small-f32-r33-hierarchical",
            "fourier-small-f32-r33-mise",
            "fourier-small-f32-r65-hierarchical",
            "fourier-small-f32-r65-mise",
        ]
    );
    let f = |r: &serde_json::Value, k: &str| r[k].as_f64().unwrap();
    for (r, (res, method)) in summaries.iter().zip([
        (33, "hierarchical"),
        (33, "mise"),
        (65, "hierarchical"),
        (65, "mise"),
    ]) {
        assert_eq!(r["res"], res, "{r}");
        assert_eq!(r["localization"], method, "{r}");
        assert_eq!(r["backend"], "tract", "{r}");
        assert_eq!(r["bound"], false, "{r}");
        assert!(f(r, "iou") > 0.5 && f(r, "chamfer_cm") < 5.0, "{r}");
        assert_eq!(f(r, "segment_ms"), f(summaries[0], "segment_ms"), "{r}");
        assert_eq!(f(r, "encode_ms"), f(summaries[0], "encode_ms"), "{r}");
        let sum = f(r, "segment_ms") + f(r, "encode_ms") + f(r, "localize_ms");
        assert!((f(r, "frame_ms") - sum).abs() < 1e-9, "{r}");
    }
    for m in 0..2 {
        assert!(
            f(summaries[m + 2], "evaluations") > 2.0 * f(summaries[m], "evaluations"),
            "{summaries:?}"
        );
    }
}

/// `--moment-fill` puts each Fourier model's filled row beside its row as predicted, in one
/// run; the ground-truth series (no network, nothing to fill) get one row.
#[test]
fn moment_fill_rows_stand_beside_the_plain_ones() {
    let summaries = tiny_row_names(
        "fill",
        &[
            "--model",
            "fourier-small,truth-k15",
            "--moment-fill",
            "0.02,0.1,4",
        ],
    );
    assert_eq!(
        summaries,
        [
            "fourier-small-f32",
            "fourier-small-f32-fill0.10x4",
            "truth-k15-f32"
        ],
        "{summaries:?}"
    );
}

/// `--interior-level` reads every Fourier model's row at that level inside the eroded mask
/// (named for it) and leaves the ground-truth series (no network) as they are.
#[test]
fn interior_level_rows_are_named_for_the_knob() {
    let summaries = tiny_row_names(
        "interior",
        &[
            "--model",
            "fourier-small,truth-k15",
            "--interior-level",
            "0.5,2",
        ],
    );
    assert_eq!(
        summaries,
        ["fourier-small-f32-in0.50e2", "truth-k15-f32"],
        "{summaries:?}"
    );
}

/// `--thin-level` reads every Fourier model's thin parts at that level (the row named for
/// it) and leaves the ground-truth series as they are.
#[test]
fn thin_level_rows_are_named_for_the_knob() {
    let summaries = tiny_row_names(
        "thin",
        &[
            "--model",
            "fourier-small,truth-k15",
            "--thin-level",
            "0.45,2",
        ],
    );
    assert_eq!(
        summaries,
        ["fourier-small-f32-thin0.45r2", "truth-k15-f32"],
        "{summaries:?}"
    );
}

/// `--segment-passes 1,2` gives every model a row per count, one pass first, each with a
/// mask IoU that found the person.
#[test]
fn segment_pass_rows_stand_beside_each_other() {
    let rows = run_eval(
        "passes",
        &[
            &TINY[..],
            &["--model", "fourier-small", "--segment-passes", "1,2"],
        ]
        .concat(),
    );
    let summaries = summaries(&rows);
    let names = names(&summaries);
    assert_eq!(names, ["fourier-small-f32", "fourier-small-f32-seg2"]);
    let passes: Vec<u64> = summaries
        .iter()
        .map(|r| r["segment_passes"].as_u64().unwrap())
        .collect();
    assert_eq!(passes, [1, 2]);
    for r in &summaries {
        let m = r["mask_iou"].as_f64().unwrap();
        assert!(m.is_finite() && m > 0.5, "{r}");
    }
}

/// Without `--segment-passes` each model is segmented as it was trained (its file's
/// `volcap.segment_passes`), as volcapd runs it: the default model twice, `fourier-small`
/// once; a count other than the model's own is named in the row.
#[test]
fn each_model_is_segmented_as_it_was_trained_unless_told() {
    let rows = run_eval(
        "own-passes",
        &[&TINY[..], &["--model", "fourier-small-seg2,fourier-small"]].concat(),
    );
    let row = |rows: &[serde_json::Value], name: &str| -> u64 {
        rows.iter()
            .find(|r| r.get("family").is_some() && r["model"] == name)
            .unwrap_or_else(|| panic!("no row {name}"))["segment_passes"]
            .as_u64()
            .unwrap()
    };
    assert_eq!(row(&rows, "fourier-small-seg2-f32"), 2);
    assert_eq!(row(&rows, "fourier-small-f32"), 1);
    let rows = run_eval(
        "one-pass",
        &[
            &TINY[..],
            &["--model", "fourier-small-seg2", "--segment-passes", "1"],
        ]
        .concat(),
    );
    assert_eq!(row(&rows, "fourier-small-seg2-f32-seg1"), 1);
}

/// The colour columns: a trained model's images get four colour errors (the input view, the
/// side, the back, the back in the input's own pixels), each a mean absolute RGB difference
/// in [0, 1]; the ground-truth rows (no colour networks) and `--colour-res 0` get none.
#[test]
fn colour_columns_are_bounded_and_only_where_measured() {
    let colour = |r: &serde_json::Value| -> Vec<Option<f64>> {
        r["colour_l1"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64())
            .collect()
    };
    let rows = run_eval(
        "colour",
        &[
            &TINY[..],
            &[
                "--model",
                "fourier-small-seg2,truth-k15",
                "--colour-res",
                "65",
            ],
        ]
        .concat(),
    );
    // Per model: one image, then its summary.
    assert_eq!(rows.len(), 4, "{rows:?}");
    for r in [&rows[0], &rows[1]] {
        let c = colour(r);
        assert_eq!(c.len(), 4, "{r}");
        assert!(
            c.iter()
                .all(|v| v.is_some_and(|v| (0.0..=1.0).contains(&v))),
            "{r}"
        );
    }
    for r in [&rows[2], &rows[3]] {
        assert!(colour(r).iter().all(Option::is_none), "{r}");
    }
    let off = run_eval(
        "colour-off",
        &[
            &TINY[..],
            &["--model", "fourier-small-seg2", "--colour-res", "0"],
        ]
        .concat(),
    );
    assert!(colour(&off[0]).iter().all(Option::is_none), "{:?}", off[0]);
}

/// `--truth-surface seen` measures against what a view can show: the ground-truth series
/// (which holds only the person's outer surface) is nearer that than the clothed mesh with
/// the body under the clothes (were nothing left out, the two would be equal).
#[test]
fn the_seen_truth_leaves_out_the_body_under_the_clothes() {
    let chamfer = |name: &str, surface: &str| -> f64 {
        let rows = run_eval(
            name,
            &[
                &TINY[..4],
                &[
                    "--res",
                    "65",
                    "--model",
                    "truth-k15",
                    "--truth-surface",
                    surface,
                ],
            ]
            .concat(),
        );
        rows[0]["chamfer_cm"].as_f64().unwrap()
    };
    let (clothed, seen) = (chamfer("clothed", "clothed"), chamfer("seen", "seen"));
    assert!(seen < clothed, "seen {seen} clothed {clothed}");
}

/// `--turntable-image N` turns image N of the set (its place in the per-image table), the
/// report says which, and an N past the set's end is refused by name before any model runs.
#[test]
fn the_turntable_turns_the_image_asked_for() {
    let dir = std::env::temp_dir().join(format!("volcap-eval-turn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let manifest = dir.join("manifest.json");
    std::fs::write(&manifest, MANIFEST).unwrap();
    let run = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_volcap"))
            .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .args(["eval", "--subjects", "val", "--poses", "1", "--views", "2"])
            .args(["--res", "33", "--colour-res", "0", "--turntable-res", "33"])
            .arg("--manifest")
            .arg(&manifest)
            .arg("--out")
            .arg(&dir)
            .args(extra)
            .output()
            .unwrap()
    };
    let out = run(&["--turntable", "--turntable-image", "2"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("--turntable-image 2") && err.contains("2 images"),
        "{err}"
    );
    // Without --turntable the option would do nothing: refused.
    let out = run(&["--turntable-image", "1"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--turntable"));
    let out = run(&["--turntable", "--turntable-image", "1"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let md = std::fs::read_to_string(dir.join("eval.md")).unwrap();
    assert!(md.contains("Image 1 of the per-image table's"), "{md}");
    let turntable = || {
        std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .find(|e| e.file_name().to_string_lossy().starts_with("turntable-"))
            .map(|e| std::fs::read(e.path()).unwrap())
            .expect("a turntable PNG")
    };
    let second = turntable();
    // The first image (the person seen from the front, not from behind) turns otherwise.
    let out = run(&["--turntable"]);
    assert!(out.status.success());
    assert!(
        std::fs::read_to_string(dir.join("eval.md"))
            .unwrap()
            .contains("The first image's reconstruction")
    );
    assert_ne!(turntable(), second);
    let _ = std::fs::remove_dir_all(&dir);
}
