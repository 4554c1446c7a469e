//! The GPU backend's networks (feature `wgpu`) against tract, on whatever adapter opens.
//! Every committed f32 network: each tensor the GPU computes within 1e-3 of tract's
//! (relative to the tensor's scale), the output within 2e-3; the per-point networks planned
//! once per row bucket; ops without a kernel refused at load naming op and node.
#![cfg(feature = "wgpu")]

mod common;

use common::{Golden, golden_input, gpu, models_dir, values};
use std::path::Path;
use tract_onnx::prelude::*;
use volcap_engine::model::Runtime;
use volcap_engine::model::preprocess::{INPUT_SIZE, letterbox};

/// Per tensor, max |gpu - tract| over max(1e-3, max |tract|).
const LAYER_TOLERANCE: f32 = 1e-3;
const OUTPUT_TOLERANCE: f32 = 2e-3;

fn flat(t: &TValue) -> Vec<f32> {
    let t = t.cast_to::<f32>().unwrap();
    t.to_plain_array_view::<f32>()
        .unwrap()
        .iter()
        .copied()
        .collect()
}

fn scale_diff(reference: &[f32], got: &[f32]) -> f32 {
    assert_eq!(reference.len(), got.len());
    let scale = reference.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
    reference
        .iter()
        .zip(got)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max)
        / scale
}

/// The graph's inputs (name, shape; a symbolic batch as 512 points).
fn inputs_of(path: &Path) -> Vec<(String, Vec<usize>)> {
    let proto = tract_onnx::onnx().proto_model_for_path(path).unwrap();
    let g = proto.graph.unwrap();
    let inits: Vec<&str> = g.initializer.iter().map(|t| t.name.as_str()).collect();
    g.input
        .iter()
        .filter(|i| !inits.contains(&i.name.as_str()))
        .map(|i| {
            let dims = match i.r#type.as_ref().and_then(|t| t.value.as_ref()) {
                Some(tract_onnx::pb::type_proto::Value::TensorType(t)) => t
                    .shape
                    .as_ref()
                    .map(|s| {
                        s.dim
                            .iter()
                            .map(|d| match d.value {
                                Some(
                                    tract_onnx::pb::tensor_shape_proto::dimension::Value::DimValue(
                                        v,
                                    ),
                                ) if v > 0 => v as usize,
                                _ => 512,
                            })
                            .collect()
                    })
                    .unwrap_or_default(),
                _ => vec![],
            };
            (i.name.clone(), dims)
        })
        .collect()
}

/// Realistic inputs where the shape is an image the product feeds (the golden person), else
/// deterministic values.
fn input_values(shape: &[usize], k: usize) -> Vec<f32> {
    let s = INPUT_SIZE;
    if shape == [1, 4, s, s] {
        golden_input(&Golden::load("color")).0
    } else if shape == [1, 3, s, s] {
        letterbox(&Golden::load("seg").u8("image_u8"), s, s)
    } else {
        values(shape.iter().product(), 11 * k)
    }
}

/// The committed f32 networks (every .onnx under models/ but the int8 files).
fn f32_networks() -> Vec<std::path::PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(models_dir())
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy().to_string();
            n.ends_with(".onnx") && !n.contains(".int8.")
        })
        .collect();
    v.sort();
    v
}

#[test]
fn every_layer_of_every_committed_network_matches_tract() {
    let Some(gpu) = gpu() else { return };
    let nets = f32_networks();
    assert!(nets.len() >= 10, "the committed networks: {nets:?}");
    for path in nets {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let specs = inputs_of(&path);
        let data: Vec<(Vec<usize>, Vec<f32>)> = specs
            .iter()
            .enumerate()
            .map(|(k, (_, s))| (s.clone(), input_values(s, k)))
            .collect();
        let args: Vec<(&[usize], &[f32])> = data
            .iter()
            .map(|(s, d)| (s.as_slice(), d.as_slice()))
            .collect();
        let net = volcap_engine::gpu::net::GpuNet::load(gpu.clone(), &path)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let layers = net.run_all(&args).unwrap_or_else(|e| panic!("{name}: {e}"));
        let inputs: Vec<&str> = specs.iter().map(|(n, _)| n.as_str()).collect();
        let layers: Vec<_> = layers
            .into_iter()
            .filter(|(n, _, _)| !n.contains('#') && !inputs.contains(&n.as_str()))
            .collect();
        // tract on the same file with every one of those tensors as an output.
        let mut model = tract_onnx::onnx().model_for_path(&path).unwrap();
        for (i, (s, _)) in data.iter().enumerate() {
            model = model.with_input_fact(i, f32::fact(s).into()).unwrap();
        }
        let model = model
            .with_outputs_by_name(layers.iter().map(|(n, _, _)| n.as_str()))
            .unwrap()
            .into_optimized()
            .unwrap()
            .into_runnable()
            .unwrap();
        let tv: TVec<TValue> = data
            .iter()
            .map(|(s, d)| Tensor::from_shape(s, d).unwrap().into_tvalue())
            .collect();
        let want = model.run(tv).unwrap();
        let mut worst = (0.0f32, String::new());
        for ((lname, shape, got), w) in layers.iter().zip(want.iter()) {
            let w = flat(w);
            assert_eq!(w.len(), got.len(), "{name} {lname}: shape {shape:?}");
            assert!(
                got.iter().all(|v| v.is_finite()),
                "{name} {lname}: non-finite on the GPU"
            );
            let d = scale_diff(&w, got);
            if d > worst.0 {
                worst = (d, lname.clone());
            }
            assert!(
                d <= LAYER_TOLERANCE,
                "{name} {lname} {shape:?}: GPU vs tract {d:.2e} relative, over {LAYER_TOLERANCE:.0e}"
            );
        }
        // The network's output through the planned (buffer-reusing) path.
        let out = net.run(&args).unwrap();
        let out_name = tract_onnx::onnx()
            .proto_model_for_path(&path)
            .unwrap()
            .graph
            .unwrap()
            .output[0]
            .name
            .clone();
        let at = layers
            .iter()
            .position(|(n, _, _)| *n == out_name)
            .unwrap_or_else(|| panic!("{name}: the output {out_name} is not among the tensors"));
        let d_out = scale_diff(&flat(&want[at]), &out);
        println!(
            "{name}: {} tensors, worst layer {:.2e} ({}), output {:.2e}",
            layers.len(),
            worst.0,
            worst.1,
            d_out
        );
        assert!(d_out <= OUTPUT_TOLERANCE, "{name}: output {d_out:.2e}");
    }
}

/// The per-point networks run a changing number of points every frame (the render's hits,
/// a level's batch): planned once per row bucket, not per run, with each run's rows exactly
/// what a plan for that count gives, whatever earlier runs left in the bucket's other rows.
#[test]
fn per_point_networks_keep_their_plans_across_point_counts() {
    use volcap_engine::gpu::net::{GpuNet, row_bucket};
    let Some(gpu) = gpu() else { return };
    // The colour MLP (the product's per-point network on the GPU backend) and the MLP
    // family's occupancy net.
    // (Lavapipe runs these at about a millisecond a point: small counts.)
    for (file, counts, buckets) in [
        (
            "color.mlp.onnx",
            &[900usize, 600, 1500, 2100, 900, 600][..],
            3,
        ),
        ("shape-compact.mlp.onnx", &[900, 600][..], 1),
    ] {
        let path = models_dir().join(file);
        let specs = inputs_of(&path);
        let net = GpuNet::load(gpu.clone(), &path).unwrap();
        let fresh = GpuNet::load(gpu.clone(), &path).unwrap();
        // Two counts in a row share a bucket (900 and 600: 1024): the second run's rows must
        // not see the first's; then two other buckets, then the first again, from the cache.
        for (k, &n) in counts.iter().enumerate() {
            let data: Vec<(Vec<usize>, Vec<f32>)> = specs
                .iter()
                .enumerate()
                .map(|(i, (_, s))| {
                    let mut s = s.clone();
                    s[0] = n;
                    let len = s.iter().product();
                    (s, values(len, 7 * k + i))
                })
                .collect();
            let args: Vec<(&[usize], &[f32])> = data
                .iter()
                .map(|(s, d)| (s.as_slice(), d.as_slice()))
                .collect();
            let rows = net.run_rows(&args).unwrap();
            // The same points through a plan for exactly n rows.
            let exact = fresh.run(&args).unwrap();
            assert_eq!(rows.len(), exact.len(), "{file} at {n} points");
            let d = rows
                .iter()
                .zip(&exact)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(d <= 1e-6, "{file} at {n} points: {d:e} from the exact plan");
            assert!(rows.iter().all(|v| v.is_finite()));
        }
        let distinct: std::collections::HashSet<usize> =
            counts.iter().map(|&n| row_bucket(n)).collect();
        assert_eq!(distinct.len(), buckets);
        assert_eq!(
            net.plans_made(),
            buckets as u64,
            "{file}: one plan per bucket"
        );
        // Planned for exact counts, every run plans again here (900 and 600 come back after
        // three other counts have pushed them out of the cache).
        assert_eq!(fresh.plans_made(), counts.len() as u64, "{file}");
    }
    // Inputs whose point counts disagree are refused, naming the input.
    let net = GpuNet::load(gpu, &models_dir().join("color.mlp.onnx")).unwrap();
    let (a, b, c) = (vec![0.0f32; 10 * 32], vec![0.0f32; 9 * 3], vec![0.0f32; 10]);
    let err = net
        .run_rows(&[(&[10, 32], &a), (&[9, 3], &b), (&[10, 1], &c)])
        .unwrap_err();
    assert!(err.contains("input 1"), "{err}");
}

#[test]
fn an_op_without_a_kernel_is_refused_at_load_naming_op_and_node() {
    // The int8 files quantize around their products (QuantizeLinear / DequantizeLinear): a
    // CPU-runtime format. Planning needs no adapter.
    let path = models_dir().join("shape-fourier-small.fourier.int8.onnx");
    let proto = tract_onnx::onnx().proto_model_for_path(&path).unwrap();
    let e = volcap_engine::gpu::net::plan::check_ops(proto.graph.as_ref().unwrap()).unwrap_err();
    assert!(
        e.contains("node \"") && e.contains("Linear") && e.contains("no GPU kernel"),
        "{e}"
    );
    // And through the runtime seam, the error names the file.
    let Some(gpu) = gpu() else { return };
    let e = match volcap_engine::model::FourierNet::load_on(
        &models_dir(),
        "fourier-small",
        volcap_engine::model::Precision::Int8,
        &Runtime::Wgpu(gpu),
    ) {
        Ok(_) => panic!("an int8 file loaded on the GPU backend"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("int8.onnx") && e.contains("GPU backend"), "{e}");
}
