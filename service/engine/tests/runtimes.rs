//! Parity of the two runtimes: every committed network gives the same outputs on tract and
//! on ONNX Runtime (f32 within 1e-4 of the outputs' scale; int8 within the export's drift
//! limit on the golden occupancy). Needs ONNX Runtime's library (`tools/onnxruntime.sh`):
//! a failure under CI, a note elsewhere.

mod common;

use common::{Golden, golden_input, models_dir, models_of, points, runtimes};
use volcap_engine::model::preprocess::{INPUT_SIZE, letterbox};
use volcap_engine::model::{ColorNets, FourierNet, Net, Precision, Runtime, ShapeNets};

/// f32 outputs agree within this, relative to the largest output magnitude (at least 1).
const F32_TOLERANCE: f32 = 1e-4;
/// int8 occupancy at the golden points agrees within the export's drift limit
/// (`tools/train/volcap_train/export.py`, `INT8_MAX_DRIFT`).
const INT8_MAX_DRIFT: f32 = 0.025;

/// Max |a - b| over max(1, max |a|).
fn relative_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "outputs of different lengths");
    let scale = a.iter().fold(1.0f32, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
        / scale
}

fn check(what: &str, net: &str, a: &[f32], b: &[f32]) {
    assert!(
        a.iter().chain(b).all(|v| v.is_finite()),
        "{what} {net}: non-finite output"
    );
    let d = relative_diff(a, b);
    println!("{what} {net}: tract vs onnxruntime max |diff| / scale = {d:.2e}");
    assert!(
        d <= F32_TOLERANCE,
        "{what} {net}: tract and ONNX Runtime differ by {d:.2e} (relative), over {F32_TOLERANCE:.0e}"
    );
}

/// Deterministic inputs in [-1, 1].
fn values(n: usize, seed: usize) -> Vec<f32> {
    (0..n)
        .map(|i| (((i + seed) * 37 % 101) as f32 / 50.0) - 1.0)
        .collect()
}

/// Both runtimes, or none when ONNX Runtime is not installed here (outside CI).
fn pair() -> Option<(Runtime, Runtime)> {
    let mut r = runtimes();
    if r.len() < 2 {
        println!("skipped: ONNX Runtime is not installed (tools/onnxruntime.sh)");
        return None;
    }
    let ort = r.remove(1);
    Some((r.remove(0), ort))
}

/// A point MLP (`[N, c]` features and its other inputs) on 512 points.
fn mlp_inputs(widths: &[usize]) -> Vec<(Vec<usize>, Vec<f32>)> {
    let n = 512;
    widths
        .iter()
        .enumerate()
        .map(|(k, &w)| (vec![n, w], values(n * w, 11 * k)))
        .collect()
}

fn run_both(net_a: &Net, net_b: &Net, inputs: &[(Vec<usize>, Vec<f32>)]) -> (Vec<f32>, Vec<f32>) {
    let args: Vec<(&[usize], &[f32])> = inputs
        .iter()
        .map(|(s, d)| (s.as_slice(), d.as_slice()))
        .collect();
    (net_a.run(&args).unwrap(), net_b.run(&args).unwrap())
}

#[test]
fn every_committed_f32_network_agrees_between_runtimes() {
    let Some((tract, ort)) = pair() else { return };
    let dir = models_dir();
    let s = INPUT_SIZE;
    // The golden person as every encoder sees it.
    let (x, _) = golden_input(&Golden::load("color"));
    let x_in = vec![(vec![1, 4, s, s], x.clone())];
    // Segmentation, on the golden photo.
    let seg_img = letterbox(&Golden::load("seg").u8("image_u8"), s, s);
    let load_seg = |rt: &Runtime| {
        volcap_engine::model::Models::load_on(&dir, "fourier-small", Precision::F32, rt)
            .expect("committed models load")
    };
    let (ma, mb) = (load_seg(&tract), load_seg(&ort));
    assert_eq!(mb.seg.runtime(), "onnxruntime");
    let (a, b) = run_both(&ma.seg, &mb.seg, &[(vec![1, 3, s, s], seg_img)]);
    check("segmentation", "seg.onnx", &a, &b);
    // Colour encoder and point MLP.
    let (ca, cb) = (
        ColorNets::load_on(&dir, &tract).unwrap(),
        ColorNets::load_on(&dir, &ort).unwrap(),
    );
    let (a, b) = run_both(&ca.encoder, &cb.encoder, &x_in);
    check("colour encoder", "color.encoder.onnx", &a, &b);
    let (a, b) = run_both(&ca.mlp, &cb.mlp, &mlp_inputs(&[ca.channels, 3, 1]));
    check("colour MLP", "color.mlp.onnx", &a, &b);
    // Every shape model: the Fourier heads' maps, the MLP family's encoder and point MLP.
    for name in models_of("fourier") {
        let (fa, fb) = (
            FourierNet::load_on(&dir, &name, Precision::F32, &tract).unwrap(),
            FourierNet::load_on(&dir, &name, Precision::F32, &ort).unwrap(),
        );
        let (a, b) = run_both(&fa.net, &fb.net, &x_in);
        check("Fourier head", &name, &a, &b);
    }
    for name in models_of("mlp") {
        let (na, nb) = (
            ShapeNets::load_on(&dir, &name, Precision::F32, &tract).unwrap(),
            ShapeNets::load_on(&dir, &name, Precision::F32, &ort).unwrap(),
        );
        let (a, b) = run_both(&na.encoder, &nb.encoder, &x_in);
        check("shape encoder", &name, &a, &b);
        let inputs = mlp_inputs(&[na.channels, na.z.dim()]);
        let (a, b) = run_both(&na.mlp, &nb.mlp, &inputs);
        check("shape MLP", &name, &a, &b);
    }
}

#[test]
fn int8_networks_agree_between_runtimes_within_the_export_drift() {
    let Some((tract, ort)) = pair() else { return };
    let dir = models_dir();
    let mut checked = 0;
    for name in models_of("fourier").into_iter().chain(models_of("mlp")) {
        let g = Golden::load(&format!("shape-{name}"));
        let (x, _) = golden_input(&g);
        let pts = points(&g);
        let occupancy = |rt: &Runtime| -> Option<Vec<f32>> {
            let mut occ = vec![0.0f32; pts.len()];
            if FourierNet::path(&dir, &name, Precision::Int8).is_file() {
                let net = FourierNet::load_on(&dir, &name, Precision::Int8, rt).unwrap();
                net.maps(&x)
                    .unwrap()
                    .occupancy(&pts, &mut occ, &mut Vec::new());
            } else if dir
                .join(format!("shape-{name}.encoder.int8.onnx"))
                .is_file()
            {
                let nets = ShapeNets::load_on(&dir, &name, Precision::Int8, rt).unwrap();
                let f = nets.features(&x).unwrap();
                nets.query(&f, &pts, &mut occ).unwrap();
            } else {
                return None;
            }
            Some(occ)
        };
        let (Some(a), Some(b)) = (occupancy(&tract), occupancy(&ort)) else {
            continue;
        };
        checked += 1;
        assert!(
            a.iter()
                .chain(&b)
                .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
        );
        let worst = a
            .iter()
            .zip(&b)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0f32, f32::max);
        let mean = a.iter().zip(&b).map(|(p, q)| (p - q).abs()).sum::<f32>() / a.len() as f32;
        println!(
            "{name}@int8: tract vs onnxruntime occupancy max |diff| {worst:.4}, mean {mean:.4}"
        );
        assert!(
            mean <= INT8_MAX_DRIFT,
            "{name}@int8: the runtimes' occupancy differs by {mean:.4} on average, over the export's {INT8_MAX_DRIFT}"
        );
    }
    assert!(
        checked >= 2,
        "int8 files of at least two models are committed"
    );
}
