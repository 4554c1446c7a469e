//! One ONNX network, checked at load (kind, inputs, output shape: with tract, whichever
//! runtime then runs it) with errors that name the file and what differs, and run by tract
//! or ONNX Runtime ([`super::runtime`]); the `volcap.*` metadata readers.

use super::ModelError;
use super::runtime::Runtime;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tract_onnx::prelude::*;

type Plan = Arc<TypedRunnableModel>;

/// What runs a network.
enum Backend {
    Tract(Plan),
    #[cfg(feature = "onnxruntime")]
    Ort(super::runtime::ort_backend::OrtNet),
    #[cfg(feature = "wgpu")]
    Wgpu(Box<crate::gpu::net::GpuNet>),
}

/// One ONNX network, shape-checked at load.
pub struct Net {
    path: PathBuf,
    backend: Backend,
    meta: HashMap<String, String>,
}

/// An input of a network: name and shape, `None` for the dynamic batch dimension.
pub struct InputSpec<'a> {
    pub name: &'a str,
    pub shape: &'a [Option<usize>],
}

impl Net {
    /// Load `path` on tract ([`Net::load_on`]).
    pub fn load(
        path: &Path,
        kind: &str,
        inputs: &[InputSpec],
        output: &[Option<usize>],
    ) -> Result<Net, ModelError> {
        Self::load_on(path, kind, inputs, output, &Runtime::Tract)
    }

    /// Load `path` to run on `runtime`, check `volcap.kind == kind`, the inputs (names,
    /// shapes; `None` is the dynamic batch dimension) and the output's shape.
    pub fn load_on(
        path: &Path,
        kind: &str,
        inputs: &[InputSpec],
        output: &[Option<usize>],
        runtime: &Runtime,
    ) -> Result<Net, ModelError> {
        let p = path.display().to_string();
        let file = |msg: String| ModelError::File {
            path: p.clone(),
            msg,
        };
        let mismatch = |what: &str, expected: String, found: String| ModelError::Mismatch {
            path: p.clone(),
            what: what.into(),
            expected,
            found,
        };
        if !path.is_file() {
            return Err(file(
                "model file not found (models are committed under models/; train with tools/train/train_all.sh)".into(),
            ));
        }
        let onnx = tract_onnx::onnx();
        let proto = onnx
            .proto_model_for_path(path)
            .map_err(|e| file(format!("not a readable ONNX model: {e}")))?;
        let meta: HashMap<String, String> = proto
            .metadata_props
            .iter()
            .map(|e| (e.key.clone(), e.value.clone()))
            .collect();
        let found_kind = meta.get("volcap.kind").cloned().unwrap_or_default();
        if found_kind != kind {
            return Err(mismatch(
                "metadata volcap.kind",
                kind.into(),
                format!("{found_kind:?}"),
            ));
        }
        let graph = proto
            .graph
            .as_ref()
            .ok_or_else(|| file("no graph".into()))?;
        // Weights that are NaN or infinite make any output meaningless, and saturating
        // activations (sigmoid, hard-swish) can hide them from an output check: refuse them.
        for t in &graph.initializer {
            let bad = if t.data_type == 1 {
                if t.raw_data.is_empty() {
                    t.float_data.iter().find(|v| !v.is_finite()).copied()
                } else {
                    t.raw_data
                        .chunks_exact(4)
                        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                        .find(|v| !v.is_finite())
                }
            } else {
                None
            };
            if let Some(v) = bad {
                return Err(file(format!(
                    "weight {:?} holds a non-finite value ({v}): broken weights",
                    t.name
                )));
            }
        }
        let names: Vec<String> = graph.input.iter().map(|i| i.name.clone()).collect();
        let want: Vec<String> = inputs.iter().map(|i| i.name.to_string()).collect();
        if names != want {
            return Err(mismatch(
                "inputs",
                format!("{want:?}"),
                format!("{names:?}"),
            ));
        }
        let mut model = onnx
            .model_for_proto_model(&proto)
            .map_err(|e| file(format!("cannot build the graph: {e}")))?;
        let n = model.sym("n");
        for (i, spec) in inputs.iter().enumerate() {
            let dims: TVec<TDim> = spec
                .shape
                .iter()
                .map(|d| d.map(|d| d.to_dim()).unwrap_or_else(|| n.clone().into()))
                .collect();
            model = model
                .with_input_fact(i, f32::fact(dims).into())
                .map_err(|e| {
                    mismatch(
                        &format!("input {}", spec.name),
                        format!("{:?}", spec.shape),
                        e.to_string(),
                    )
                })?;
        }
        let typed = model.into_typed().map_err(|e| {
            let want: Vec<String> = inputs
                .iter()
                .map(|i| format!("{} {:?}", i.name, i.shape))
                .collect();
            file(format!(
                "the graph does not accept the expected inputs ({}; None = batch): {e:#}",
                want.join(", ")
            ))
        })?;
        let fact = typed
            .output_fact(0)
            .map_err(|e| file(format!("no output: {e}")))?;
        let shape: Vec<Option<usize>> = fact
            .shape
            .iter()
            .map(|d| d.as_i64().and_then(|v| usize::try_from(v).ok()))
            .collect();
        if shape != output {
            return Err(mismatch(
                "output shape",
                format!("{output:?}"),
                format!("{shape:?}"),
            ));
        }
        let backend = match runtime {
            Runtime::Tract => Backend::Tract(
                typed
                    .into_optimized()
                    .and_then(|m| m.into_runnable())
                    .map_err(|e| file(format!("cannot optimize: {e:#}")))?,
            ),
            #[cfg(feature = "onnxruntime")]
            Runtime::OnnxRuntime(rt) => {
                Backend::Ort(super::runtime::ort_backend::OrtNet::load(rt, path).map_err(file)?)
            }
            #[cfg(feature = "wgpu")]
            Runtime::Wgpu(gpu) => Backend::Wgpu(Box::new(
                crate::gpu::net::GpuNet::load(gpu.clone(), path)
                    .map_err(|e| file(format!("the GPU backend cannot run it: {e}")))?,
            )),
        };
        let net = Net {
            path: path.to_path_buf(),
            backend,
            meta,
        };
        net.probe(inputs)?;
        Ok(net)
    }

    /// Run once on a fixed probe input (0.5 everywhere, batch 1): a file whose weights are
    /// broken (NaN, infinities) gives non-finite output for any input and is refused here,
    /// at load, instead of publishing garbage as "running".
    fn probe(&self, inputs: &[InputSpec]) -> Result<(), ModelError> {
        let shapes: Vec<Vec<usize>> = inputs
            .iter()
            .map(|i| i.shape.iter().map(|d| d.unwrap_or(1)).collect())
            .collect();
        let data: Vec<Vec<f32>> = shapes
            .iter()
            .map(|s| vec![0.5f32; s.iter().product()])
            .collect();
        let args: Vec<(&[usize], &[f32])> = shapes
            .iter()
            .zip(&data)
            .map(|(s, d)| (s.as_slice(), d.as_slice()))
            .collect();
        let out = self.run(&args)?;
        if let Some((i, v)) = out.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(ModelError::File {
                path: self.path.display().to_string(),
                msg: format!(
                    "the probe input (0.5 everywhere) gives a non-finite output ({v} at element {i} of {}): broken weights",
                    out.len()
                ),
            });
        }
        Ok(())
    }

    pub fn meta(&self, key: &str) -> Option<&str> {
        self.meta.get(&format!("volcap.{key}")).map(|s| s.as_str())
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A failed run of this network: the file and why.
    fn run_error(&self, msg: String) -> ModelError {
        ModelError::Run {
            path: self.path.display().to_string(),
            msg,
        }
    }

    /// The runtime that runs it: "tract" or "onnxruntime".
    pub fn runtime(&self) -> &'static str {
        match self.backend {
            Backend::Tract(_) => "tract",
            #[cfg(feature = "onnxruntime")]
            Backend::Ort(_) => "onnxruntime",
            #[cfg(feature = "wgpu")]
            Backend::Wgpu(_) => "wgpu",
        }
    }

    /// The GPU backend's network, when it runs there (its per-layer read-back).
    #[cfg(feature = "wgpu")]
    pub fn gpu_net(&self) -> Option<&crate::gpu::net::GpuNet> {
        match &self.backend {
            Backend::Wgpu(n) => Some(n),
            _ => None,
        }
    }

    /// [`Self::run`] for a per-point network (each input's first axis the point count, each
    /// row's output from its own row: the MLPs): on the GPU backend planned for a bucket of
    /// rows ([`crate::gpu::net::GpuNet::run_rows`]) so that a changing point count does not
    /// plan the network again every frame; elsewhere as `run`.
    pub fn run_rows(&self, inputs: &[(&[usize], &[f32])]) -> Result<Vec<f32>, ModelError> {
        #[cfg(feature = "wgpu")]
        if let Backend::Wgpu(net) = &self.backend {
            return net.run_rows(inputs).map_err(|m| self.run_error(m));
        }
        self.run(inputs)
    }

    /// Run on f32 inputs (shape, data); the first output as a flat vector.
    pub fn run(&self, inputs: &[(&[usize], &[f32])]) -> Result<Vec<f32>, ModelError> {
        let err = |msg: String| self.run_error(msg);
        let plan = match &self.backend {
            Backend::Tract(plan) => plan,
            #[cfg(feature = "onnxruntime")]
            Backend::Ort(net) => return net.run(inputs).map_err(err),
            #[cfg(feature = "wgpu")]
            Backend::Wgpu(net) => return net.run(inputs).map_err(err),
        };
        let mut tv: TVec<TValue> = tvec![];
        for (shape, data) in inputs {
            let t = Tensor::from_shape(shape, data).map_err(|e| err(e.to_string()))?;
            tv.push(t.into_tvalue());
        }
        let out = plan.run(tv).map_err(|e| err(format!("{e:#}")))?;
        let v = out[0]
            .to_plain_array_view::<f32>()
            .map_err(|e| err(e.to_string()))?;
        Ok(v.iter().copied().collect())
    }
}

/// One node of a network's optimized tract plan, timed ([`Net::profile`]).
#[derive(Debug, Clone)]
pub struct NodeTime {
    pub name: String,
    /// The op's kind (tract's name for it: `Conv`, `EinSum`, `OptMatMul`, ...).
    pub op: String,
    /// Median over the runs, milliseconds.
    pub ms: f64,
}

impl Net {
    /// Run `runs` times (after one untimed run) timing every node of tract's optimized plan,
    /// or every step of the GPU backend's plan on the adapter (timestamps): per node the
    /// median milliseconds, in plan order (not on ONNX Runtime).
    pub fn profile(
        &self,
        inputs: &[(&[usize], &[f32])],
        runs: usize,
    ) -> Result<Vec<NodeTime>, ModelError> {
        let err = |msg: String| self.run_error(msg);
        let plan = match &self.backend {
            Backend::Tract(plan) => plan,
            #[cfg(feature = "onnxruntime")]
            Backend::Ort(_) => return Err(err("per-node times are tract's only".into())),
            #[cfg(feature = "wgpu")]
            Backend::Wgpu(net) => {
                // The adapter's own times per step (timestamps): the op is the kernel.
                return net
                    .profile(inputs, runs)
                    .map(|steps| {
                        steps
                            .into_iter()
                            .map(|s| NodeTime {
                                name: s.node,
                                op: s.kernel.to_string(),
                                ms: s.ms,
                            })
                            .collect()
                    })
                    .map_err(err);
            }
        };
        let model = plan.model();
        let mut times: Vec<Vec<f64>> = vec![Vec::new(); model.nodes().len()];
        let mut state = tract_onnx::tract_core::plan::SimpleState::new(plan)
            .map_err(|e| err(format!("{e:#}")))?;
        for run in 0..=runs.max(1) {
            let mut tv: TVec<TValue> = tvec![];
            for (shape, data) in inputs {
                let t = Tensor::from_shape(shape, data).map_err(|e| err(e.to_string()))?;
                tv.push(t.into_tvalue());
            }
            state
                .run_plan_with_eval(tv, |ctx, st, node, input| {
                    let t = std::time::Instant::now();
                    let out = tract_onnx::tract_core::plan::eval(ctx, st, node, input);
                    if run > 0 {
                        times[node.id].push(t.elapsed().as_secs_f64() * 1e3);
                    }
                    out
                })
                .map_err(|e| err(format!("{e:#}")))?;
        }
        Ok(model
            .eval_order()
            .map_err(|e| err(format!("{e:#}")))?
            .into_iter()
            .filter_map(|id| {
                let node = model.node(id);
                let mut t = std::mem::take(&mut times[id]);
                if t.is_empty() {
                    return None;
                }
                t.sort_by(f64::total_cmp);
                Some(NodeTime {
                    name: node.name.clone(),
                    op: node.op.name().to_string(),
                    ms: t[t.len() / 2],
                })
            })
            .collect())
    }
}

/// The `volcap.*` metadata of an ONNX file (empty when it cannot be read: loading the
/// network then reports why).
pub(crate) fn meta_of(path: &Path) -> HashMap<String, String> {
    tract_onnx::onnx()
        .proto_model_for_path(path)
        .map(|p| {
            p.metadata_props
                .iter()
                .map(|e| (e.key.clone(), e.value.clone()))
                .collect()
        })
        .unwrap_or_default()
}

/// A positive integer metadata value, or an error naming the file and key.
pub(crate) fn meta_usize(
    path: &Path,
    meta: &HashMap<String, String>,
    key: &str,
) -> Result<usize, ModelError> {
    if !path.is_file() {
        return Err(ModelError::File {
            path: path.display().to_string(),
            msg: "model file not found (models are committed under models/; train with tools/train/train_all.sh)".into(),
        });
    }
    meta.get(&format!("volcap.{key}"))
        .and_then(|v| v.parse::<usize>().ok())
        .filter(|v| *v > 0)
        .ok_or_else(|| ModelError::Mismatch {
            path: path.display().to_string(),
            what: format!("metadata volcap.{key}"),
            expected: "a positive integer".into(),
            found: format!("{:?}", meta.get(&format!("volcap.{key}"))),
        })
}
