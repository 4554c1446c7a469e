//! `volcap eval` run as a user would, on the ground-truth Fourier field (`truth-k15`, no
//! trained model in the loop): the whole scoring path (render, crop, field, localization,
//! mesh, Chamfer / P2S / IoU against the truth) in both framings.

use std::process::Command;

/// A one-subject manifest whose assets are all in the embedded pack.
const MANIFEST: &str = r#"{"subject_tables": {"t000": "[[subject]]\nid = \"t000\"\ngender = 0.2\nmuscle = 0.5\nweight = 0.6\nheight = 0.55\nrace = [0, 0, 1]\noutfit = \"female_casualsuit01\"\nshoes = \"shoes01\"\nhair = \"ponytail01\"\nskin = \"young_caucasian_female2\"\n"}, "split": {"t000": "val"}}"#;

fn eval(framing: &str) -> Vec<serde_json::Value> {
    let dir = std::env::temp_dir().join(format!("volcap-eval-{framing}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let manifest = dir.join("manifest.json");
    std::fs::write(&manifest, MANIFEST).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_volcap"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .args([
            "eval",
            "--subjects",
            "val",
            "--poses",
            "1",
            "--views",
            "2",
            "--res",
            "65",
            "--model",
            "truth-k15",
            "--json",
            "--framing",
            framing,
            "--manifest",
        ])
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

/// The truth's own series scores near zero distance and near-full IoU whether or not the frame
/// cuts the person: in the `upper` framing the truth is what the frame shows (were the legs
/// below the edge kept, the Chamfer distance would be tens of centimetres).
#[test]
fn both_framings_score_the_truth_as_near_exact() {
    for (framing, cut) in [("whole", false), ("upper", true)] {
        let rows = eval(framing);
        // Two images, then the model's summary.
        assert_eq!(rows.len(), 3, "{framing}: {rows:?}");
        for r in &rows[..2] {
            assert_eq!(r["status"], "ok", "{framing}: {r}");
            assert_eq!(r["cut_by_frame"], cut, "{framing}: {r}");
            let (ch, p2s, iou) = (
                r["chamfer_cm"].as_f64().unwrap(),
                r["p2s_cm"].as_f64().unwrap(),
                r["iou"].as_f64().unwrap(),
            );
            assert!(ch < 2.0 && p2s < 1.5, "{framing}: {r}");
            assert!(iou > 0.85, "{framing}: {r}");
        }
        assert_eq!(rows[2]["failed"], 0, "{framing}");
    }
}
