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
    use volcap_engine::gpu::net::plan::ConvKernels;
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
        // Every layer within the tolerance; the worst (relative difference, layer).
        let compare = |layers: &[(String, Vec<usize>, Vec<f32>)], kernels: &str| {
            let mut worst = (0.0f32, String::new());
            for ((lname, shape, got), w) in layers.iter().zip(want.iter()) {
                let w = flat(w);
                assert_eq!(w.len(), got.len(), "{name} {lname}: shape {shape:?}");
                assert!(
                    got.iter().all(|v| v.is_finite()),
                    "{name} {lname} ({kernels}): non-finite on the GPU"
                );
                let d = scale_diff(&w, got);
                if d > worst.0 {
                    worst = (d, lname.clone());
                }
                assert!(
                    d <= LAYER_TOLERANCE,
                    "{name} {lname} {shape:?} ({kernels}): GPU vs tract {d:.2e} relative, over {LAYER_TOLERANCE:.0e}"
                );
            }
            worst
        };
        let worst = compare(&layers, "the adapter's convolution kernels");
        // The convolution kernels the adapter does not plan with by default (a GPU's split
        // ones on lavapipe, the rows-only and conv4-only baselines), every layer again.
        let default = gpu.conv_kernels();
        for k in [ConvKernels::Split, ConvKernels::Rows, ConvKernels::Conv4] {
            if k == default {
                continue;
            }
            gpu.set_conv_kernels(k);
            let other = volcap_engine::gpu::net::GpuNet::load(gpu.clone(), &path).unwrap();
            let all = other.run_all(&args).unwrap();
            gpu.set_conv_kernels(default);
            let all: Vec<_> = all
                .into_iter()
                .filter(|(n, _, _)| !n.contains('#') && !inputs.contains(&n.as_str()))
                .collect();
            compare(&all, &format!("{k:?}"));
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

/// One convolution's settings for [`convolutions_match_an_f64_reference_on_every_kernel`].
struct ConvCase {
    c: usize,
    hw: [usize; 2],
    m: usize,
    k: [usize; 2],
    stride: [usize; 2],
    /// Top, left, bottom, right.
    pads: [usize; 4],
    dilation: [usize; 2],
    group: usize,
    bias: bool,
    relu: bool,
}

/// A graph of one Conv (and a Relu after it, which the plan fuses), its weights and bias.
fn conv_graph(t: &ConvCase, w: &[f32], b: &[f32]) -> tract_onnx::pb::GraphProto {
    use tract_onnx::pb::{AttributeProto, GraphProto, NodeProto, TensorProto, ValueInfoProto};
    let ints = |name: &str, v: Vec<i64>| AttributeProto {
        name: name.into(),
        r#type: 7,
        ints: v,
        ..Default::default()
    };
    let tensor = |name: &str, dims: Vec<i64>, data: &[f32]| TensorProto {
        name: name.into(),
        dims,
        data_type: 1,
        float_data: data.to_vec(),
        ..Default::default()
    };
    let i64s = |v: &[usize]| v.iter().map(|&x| x as i64).collect::<Vec<_>>();
    let mut inputs = vec!["x".to_string(), "w".to_string()];
    let mut init = vec![tensor("w", i64s(&[t.m, t.c / t.group, t.k[0], t.k[1]]), w)];
    if t.bias {
        inputs.push("b".into());
        init.push(tensor("b", vec![t.m as i64], b));
    }
    let conv_out = if t.relu { "c" } else { "y" };
    let mut node = vec![NodeProto {
        input: inputs,
        output: vec![conv_out.into()],
        name: "conv".into(),
        op_type: "Conv".into(),
        attribute: vec![
            ints("kernel_shape", i64s(&t.k)),
            ints("strides", i64s(&t.stride)),
            ints("pads", i64s(&t.pads)),
            ints("dilations", i64s(&t.dilation)),
            AttributeProto {
                name: "group".into(),
                r#type: 2,
                i: t.group as i64,
                ..Default::default()
            },
        ],
        ..Default::default()
    }];
    if t.relu {
        node.push(NodeProto {
            input: vec!["c".into()],
            output: vec!["y".into()],
            name: "relu".into(),
            op_type: "Relu".into(),
            ..Default::default()
        });
    }
    let value = |name: &str| ValueInfoProto {
        name: name.into(),
        ..Default::default()
    };
    GraphProto {
        node,
        initializer: init,
        input: vec![value("x")],
        output: vec![value("y")],
        ..Default::default()
    }
}

/// The convolution in f64, NCHW (batch 1), zero padding.
fn conv_reference(t: &ConvCase, x: &[f32], w: &[f32], b: &[f32]) -> (Vec<usize>, Vec<f64>) {
    let [h, wd] = t.hw;
    let span = |i: usize| t.dilation[i] * (t.k[i] - 1) + 1;
    let oh = (h + t.pads[0] + t.pads[2] - span(0)) / t.stride[0] + 1;
    let ow = (wd + t.pads[1] + t.pads[3] - span(1)) / t.stride[1] + 1;
    let (cpg, mpg) = (t.c / t.group, t.m / t.group);
    let mut y = vec![0.0f64; t.m * oh * ow];
    for m in 0..t.m {
        let g = m / mpg;
        for oy in 0..oh {
            for ox in 0..ow {
                let mut acc = if t.bias { b[m] as f64 } else { 0.0 };
                for c in 0..cpg {
                    for ky in 0..t.k[0] {
                        for kx in 0..t.k[1] {
                            let iy =
                                (oy * t.stride[0] + ky * t.dilation[0]) as i64 - t.pads[0] as i64;
                            let ix =
                                (ox * t.stride[1] + kx * t.dilation[1]) as i64 - t.pads[1] as i64;
                            if iy < 0 || ix < 0 || iy >= h as i64 || ix >= wd as i64 {
                                continue;
                            }
                            let xv = x[((g * cpg + c) * h + iy as usize) * wd + ix as usize];
                            let wv = w[((m * cpg + c) * t.k[0] + ky) * t.k[1] + kx];
                            acc += xv as f64 * wv as f64;
                        }
                    }
                }
                y[(m * oh + oy) * ow + ox] = if t.relu { acc.max(0.0) } else { acc };
            }
        }
    }
    (vec![1, t.m, oh, ow], y)
}

/// Values in [-1, 1) from a hash of their index (no period an index error could hide in).
fn hashed(n: usize, seed: u64) -> Vec<f32> {
    (0..n as u64)
        .map(|i| {
            let mut z = (i + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ seed;
            z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            ((z >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}

/// Every convolution kernel (`conv`: grouped or under four outputs; `conv4`: narrow planes;
/// `conv_row`: four columns per invocation; `conv_split`: a workgroup per block) against an
/// f64 reference, over strides, dilations, asymmetric padding, widths that are not a
/// multiple of four, output counts that are not (the zero channels the plan pads with never
/// written), windows that reach past every border, with and without bias and a fused ReLU.
#[test]
fn convolutions_match_an_f64_reference_on_every_kernel() {
    use volcap_engine::gpu::net::GpuNet;
    use volcap_engine::gpu::net::plan::{ConvKernels, Kernel, Options, plan};
    let Some(gpu) = gpu() else { return };
    let case = |c, hw, m, k, stride, pads, dilation, group, bias, relu| ConvCase {
        c,
        hw,
        m,
        k,
        stride,
        pads,
        dilation,
        group,
        bias,
        relu,
    };
    // c, [h, w], m, kernel, stride, pads (top, left, bottom, right), dilation, group, bias, relu
    #[rustfmt::skip]
    let cases = [
        // conv_row: 3x3 same padding, width 13 (a partial last block), 5 outputs.
        case(3, [11, 13], 5, [3, 3], [1, 1], [1, 1, 1, 1], [1, 1], 1, true, true),
        // conv_row: stride 2, asymmetric padding, 31 outputs (the Fourier head's count).
        case(4, [17, 20], 31, [3, 3], [2, 2], [0, 1, 2, 0], [1, 1], 1, true, false),
        // conv_row: dilation 2, a 5x3 window, no bias, no padding.
        case(6, [12, 19], 8, [5, 3], [1, 1], [0, 0, 0, 0], [2, 2], 1, false, true),
        // conv_row: pointwise over 16 columns, 12 outputs.
        case(9, [4, 16], 12, [1, 1], [1, 1], [0, 0, 0, 0], [1, 1], 1, true, false),
        // conv_row: padding wider than the window reaches (every block at a border).
        case(2, [5, 9], 4, [3, 3], [1, 2], [3, 3, 3, 3], [1, 1], 1, true, false),
        // A bottleneck's few blocks and long sums: stride 2, asymmetric padding, 31 outputs;
        // and a squeeze-excitation's 1 x 1 plane.
        case(20, [6, 9], 31, [3, 3], [2, 2], [1, 0, 0, 2], [1, 1], 1, true, true),
        case(96, [1, 1], 24, [1, 1], [1, 1], [0, 0, 0, 0], [1, 1], 1, true, false),
        // conv4: 7 output columns, 6 outputs.
        case(5, [7, 7], 6, [3, 3], [1, 1], [1, 1, 1, 1], [1, 1], 1, true, true),
        // conv: depthwise 5x5, stride 2.
        case(8, [15, 18], 8, [5, 5], [2, 2], [2, 2, 2, 2], [1, 1], 8, true, false),
        // conv: grouped (2 groups), and under four outputs.
        case(4, [9, 10], 2, [3, 3], [1, 1], [1, 1, 1, 1], [1, 1], 2, true, true),
        case(3, [9, 12], 1, [3, 3], [1, 1], [1, 1, 1, 1], [1, 1], 1, true, false),
    ];
    // Each case planned with each set of kernels, so that every kernel meets strides,
    // dilations, padding and odd counts whichever the plan's thresholds would pick.
    let mut kernels = std::collections::HashSet::new();
    for ((i, t), ck) in cases
        .iter()
        .enumerate()
        .flat_map(|c| [ConvKernels::Conv4, ConvKernels::Rows, ConvKernels::Split].map(|k| (c, k)))
    {
        let x = hashed(t.c * t.hw[0] * t.hw[1], 1 + i as u64);
        let w = hashed(t.m * (t.c / t.group) * t.k[0] * t.k[1], 100 + i as u64);
        let b = hashed(t.m, 200 + i as u64);
        let graph = conv_graph(t, &w, &b);
        let shape = vec![1, t.c, t.hw[0], t.hw[1]];
        let opts = Options {
            conv_kernels: ck,
            ..Default::default()
        };
        let plan = plan(&graph, std::slice::from_ref(&shape), opts).unwrap();
        assert_eq!(plan.steps.len(), 1, "case {i}: one fused step");
        let kernel = plan.steps[0].kernel;
        kernels.insert(kernel);
        let (want_shape, want) = conv_reference(t, &x, &w, &b);
        assert_eq!(plan.output.1, want_shape, "case {i}: output shape");
        gpu.set_conv_kernels(ck);
        let net = GpuNet::from_graph(gpu.clone(), graph).unwrap();
        let got = net.run(&[(&shape, &x)]).unwrap();
        assert_eq!(got.len(), want.len(), "case {i}");
        let scale = want.iter().fold(1e-3f64, |a, v| a.max(v.abs()));
        let (at, worst) = got
            .iter()
            .zip(&want)
            .map(|(g, w)| (*g as f64 - w).abs())
            .enumerate()
            .fold((0, 0.0f64), |a, (j, d)| if d > a.1 { (j, d) } else { a });
        assert!(
            worst / scale <= 1e-5,
            "case {i} ({kernel:?}): value {at} off by {worst:.3e} (scale {scale:.3})"
        );
    }
    gpu.set_conv_kernels(ConvKernels::for_device_type(&gpu.adapter.device_type));
    for k in [
        Kernel::Conv,
        Kernel::Conv4,
        Kernel::ConvRow,
        Kernel::ConvSplit,
    ] {
        assert!(kernels.contains(&k), "{k:?} not exercised: {kernels:?}");
    }
}

/// Pooling whose window is the whole plane (`pool_plane`: global average and max, and the
/// squeeze-excitation's AveragePool with kernel = stride = the plane) against an f64
/// reference, on planes smaller than a workgroup, between one and four of its strides, and
/// as large as the segmentation's 128 x 128.
#[test]
fn pooling_over_the_whole_plane_matches_an_f64_reference() {
    use tract_onnx::pb::{AttributeProto, GraphProto, NodeProto, ValueInfoProto};
    use volcap_engine::gpu::net::{GpuNet, plan::Kernel};
    let Some(gpu) = gpu() else { return };
    let value = |name: &str| ValueInfoProto {
        name: name.into(),
        ..Default::default()
    };
    let ints = |name: &str, v: Vec<i64>| AttributeProto {
        name: name.into(),
        r#type: 7,
        ints: v,
        ..Default::default()
    };
    for (i, (op, c, h, w)) in [
        ("GlobalAveragePool", 3, 1, 1),
        ("GlobalMaxPool", 5, 7, 9),
        ("GlobalAveragePool", 4, 10, 20),
        ("GlobalMaxPool", 2, 16, 17),
        ("AveragePool", 16, 128, 128),
        ("GlobalMaxPool", 3, 128, 128),
    ]
    .into_iter()
    .enumerate()
    {
        let attribute = if op == "AveragePool" {
            vec![
                ints("kernel_shape", vec![h as i64, w as i64]),
                ints("strides", vec![h as i64, w as i64]),
            ]
        } else {
            vec![]
        };
        let graph = GraphProto {
            node: vec![NodeProto {
                input: vec!["x".into()],
                output: vec!["y".into()],
                name: "pool".into(),
                op_type: op.into(),
                attribute,
                ..Default::default()
            }],
            input: vec![value("x")],
            output: vec![value("y")],
            ..Default::default()
        };
        let shape = vec![1, c, h, w];
        // Values around 10 with a spread, so that a sum's rounding would show.
        let x: Vec<f32> = hashed(c * h * w, 300 + i as u64)
            .iter()
            .map(|v| 10.0 + 3.0 * v)
            .collect();
        let plan = volcap_engine::gpu::net::plan::plan(
            &graph,
            std::slice::from_ref(&shape),
            Default::default(),
        )
        .unwrap();
        assert_eq!(plan.steps[0].kernel, Kernel::PoolPlane, "{op} {shape:?}");
        let got = GpuNet::from_graph(gpu.clone(), graph)
            .unwrap()
            .run(&[(&shape, &x)])
            .unwrap();
        assert_eq!(got.len(), c);
        for (k, g) in got.iter().enumerate() {
            let p = &x[k * h * w..(k + 1) * h * w];
            let want = if op.contains("Max") {
                p.iter().fold(f64::MIN, |m, &v| m.max(v as f64))
            } else {
                p.iter().map(|&v| v as f64).sum::<f64>() / p.len() as f64
            };
            assert!(
                (*g as f64 - want).abs() <= 1e-6 * want.abs(),
                "{op} {shape:?} plane {k}: {g} against {want}"
            );
        }
    }
}
