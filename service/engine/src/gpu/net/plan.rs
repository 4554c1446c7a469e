//! An ONNX graph planned for the GPU kernels, once per set of input shapes and without a
//! device: shapes inferred, constants folded (shape arithmetic, Constant nodes), batch-norm
//! folded into the convolution before it, activations fused into the convolution or Gemm
//! they follow, views (Reshape, Flatten, (Un)Squeeze, Identity) left as aliases of their
//! input's buffer, and buffers reused once their last reader has run. An op outside the set
//! is refused naming the op and the node.

mod ops;
mod shifts;

use std::collections::HashMap;
use tract_onnx::pb::{AttributeProto, GraphProto, NodeProto, TensorProto};

/// Ranks up to this many axes (the kernels' index arithmetic is unrolled to it).
pub const MAX_RANK: usize = 6;

/// The kernels (each a `.wgsl` file beside this module).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kernel {
    Copy,
    Fill,
    Binary,
    Unary,
    Conv,
    /// Four output channels per invocation (ungrouped convolutions of 4 outputs or more).
    Conv4,
    /// Four output channels by four output columns per invocation (the same convolutions
    /// over rows of at least 8 columns: `ops/layers.rs`).
    ConvRow,
    /// A workgroup per block of four channels at one pixel, the sum split over its
    /// invocations (the same convolutions where few blocks have long sums).
    ConvSplit,
    ConvTranspose,
    Pool,
    /// A window over the whole plane: a workgroup per plane, reduced in workgroup memory.
    PoolPlane,
    Gemm,
    /// A constant weight, four outputs of a row per invocation (the MLPs' layers).
    Gemm4,
    Resize,
}

/// A buffer of the plan: its size in f32 and, for weights and constants, its contents.
#[derive(Debug, Clone)]
pub struct BufSpec {
    pub len: usize,
    pub init: Option<Vec<f32>>,
}

/// One dispatch: the kernel, its parameters (p[0] = invocations) and its buffers in binding
/// order after the parameters (inputs, then the output last).
#[derive(Debug, Clone)]
pub struct Step {
    pub kernel: Kernel,
    pub params: Vec<u32>,
    pub binds: Vec<usize>,
    /// The ONNX node it comes from (for errors and profiles).
    pub node: String,
}

/// A planned network.
#[derive(Debug, Clone)]
pub struct Plan {
    pub buffers: Vec<BufSpec>,
    pub steps: Vec<Step>,
    /// The buffers the inputs are written to, in the graph's input order.
    pub inputs: Vec<usize>,
    /// The first output: its buffer and shape.
    pub output: (usize, Vec<usize>),
    /// Every tensor computed on the device (name, buffer, shape), in order; with `keep_all`
    /// no buffer is reused, so each holds its tensor after a run.
    pub tensors: Vec<(String, usize, Vec<usize>)>,
}

#[derive(Debug, Clone)]
enum Val {
    /// Known at plan time (weights, folded shape arithmetic); integers kept exact.
    Const { shape: Vec<usize>, data: Data },
    /// On the device: a buffer holding the tensor contiguously from its start.
    Dev { buf: usize, shape: Vec<usize> },
}

#[derive(Debug, Clone)]
enum Data {
    F(Vec<f32>),
    I(Vec<i64>),
}

impl Data {
    fn floats(&self) -> Vec<f32> {
        match self {
            Data::F(v) => v.clone(),
            Data::I(v) => v.iter().map(|&x| x as f32).collect(),
        }
    }
    fn ints(&self) -> Vec<i64> {
        match self {
            Data::I(v) => v.clone(),
            Data::F(v) => v.iter().map(|&x| x as i64).collect(),
        }
    }
    fn len(&self) -> usize {
        match self {
            Data::F(v) => v.len(),
            Data::I(v) => v.len(),
        }
    }
}

impl Val {
    fn shape(&self) -> &[usize] {
        match self {
            Val::Const { shape, .. } | Val::Dev { shape, .. } => shape,
        }
    }
}

fn numel(shape: &[usize]) -> usize {
    shape.iter().product()
}

/// Row-major strides of `shape`.
fn strides(shape: &[usize]) -> Vec<usize> {
    let mut s = vec![1; shape.len()];
    for d in (0..shape.len().saturating_sub(1)).rev() {
        s[d] = s[d + 1] * shape[d + 1];
    }
    s
}

/// A rank-`MAX_RANK` copy of (shape, strides), padded at the front with size-1 axes.
fn pad6(shape: &[usize], st: &[i64]) -> ([u32; MAX_RANK], [u32; MAX_RANK]) {
    let mut a = [1u32; MAX_RANK];
    let mut b = [0u32; MAX_RANK];
    let off = MAX_RANK - shape.len();
    for d in 0..shape.len() {
        a[off + d] = shape[d] as u32;
        b[off + d] = st[d] as i32 as u32;
    }
    (a, b)
}

fn tensor_data(t: &TensorProto) -> Result<(Vec<usize>, Data), String> {
    let shape: Vec<usize> = t.dims.iter().map(|&d| d.max(0) as usize).collect();
    let n = numel(&shape);
    let data = match t.data_type {
        1 => Data::F(if t.raw_data.is_empty() {
            t.float_data.clone()
        } else {
            t.raw_data
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect()
        }),
        7 => Data::I(if t.raw_data.is_empty() {
            t.int64_data.clone()
        } else {
            t.raw_data
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect()
        }),
        6 => Data::I(if t.raw_data.is_empty() {
            t.int32_data.iter().map(|&v| v as i64).collect()
        } else {
            t.raw_data
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as i64)
                .collect()
        }),
        other => {
            return Err(format!(
                "tensor {:?}: element type {other} (only float32, int64 and int32 run on the GPU)",
                t.name
            ));
        }
    };
    if data.len() != n {
        return Err(format!(
            "tensor {:?}: {} values for shape {shape:?} (external data is not supported)",
            t.name,
            data.len()
        ));
    }
    Ok((shape, data))
}

struct Attrs<'a>(&'a [AttributeProto]);

impl Attrs<'_> {
    fn get(&self, name: &str) -> Option<&AttributeProto> {
        self.0.iter().find(|a| a.name == name)
    }
    fn int(&self, name: &str, default: i64) -> i64 {
        self.get(name).map(|a| a.i).unwrap_or(default)
    }
    fn float(&self, name: &str, default: f32) -> f32 {
        self.get(name).map(|a| a.f).unwrap_or(default)
    }
    fn ints(&self, name: &str) -> Option<Vec<i64>> {
        self.get(name).map(|a| a.ints.clone())
    }
    fn string(&self, name: &str, default: &str) -> String {
        self.get(name)
            .map(|a| String::from_utf8_lossy(&a.s).to_string())
            .unwrap_or_else(|| default.to_string())
    }
}

/// What the planner knows while it walks the graph.
struct Planner {
    buffers: Vec<BufSpec>,
    steps: Vec<Step>,
    vals: HashMap<String, Val>,
    /// Readers left per value name (node inputs to come, graph outputs count as one).
    uses: HashMap<String, usize>,
    /// Readers left per device buffer (over every value aliasing it).
    buf_uses: Vec<usize>,
    free: Vec<usize>,
    keep_all: bool,
    conv_kernels: ConvKernels,
    /// Constants uploaded, by value name.
    uploaded: HashMap<String, usize>,
    tensors: Vec<(String, usize, Vec<usize>)>,
    node: String,
}

impl Planner {
    fn err(&self, msg: impl std::fmt::Display) -> String {
        format!("node {:?}: {msg}", self.node)
    }

    fn get(&self, name: &str) -> Result<&Val, String> {
        self.vals
            .get(name)
            .ok_or_else(|| self.err(format!("input {name:?} is not produced by any node")))
    }

    fn konst(&self, name: &str) -> Result<(Vec<usize>, Data), String> {
        match self.get(name)? {
            Val::Const { shape, data } => Ok((shape.clone(), data.clone())),
            Val::Dev { .. } => Err(self.err(format!(
                "input {name:?} must be a constant (computed on the device)"
            ))),
        }
    }

    /// A device buffer of `len` floats: a free one large enough, else a new one.
    fn alloc(&mut self, len: usize) -> usize {
        if !self.keep_all {
            let best = self
                .free
                .iter()
                .enumerate()
                .filter(|(_, b)| self.buffers[**b].len >= len)
                .min_by_key(|(_, b)| self.buffers[**b].len)
                .map(|(i, _)| i);
            if let Some(i) = best {
                return self.free.swap_remove(i);
            }
        }
        self.buffers.push(BufSpec { len, init: None });
        self.buf_uses.push(0);
        self.buffers.len() - 1
    }

    /// The device buffer holding value `name` (a constant is uploaded once).
    fn dev(&mut self, name: &str) -> Result<(usize, Vec<usize>), String> {
        match self.get(name)?.clone() {
            Val::Dev { buf, shape } => Ok((buf, shape)),
            Val::Const { shape, data } => {
                if let Some(&b) = self.uploaded.get(name) {
                    return Ok((b, shape));
                }
                self.buffers.push(BufSpec {
                    len: data.len(),
                    init: Some(data.floats()),
                });
                self.buf_uses.push(usize::MAX);
                let b = self.buffers.len() - 1;
                self.uploaded.insert(name.to_string(), b);
                Ok((b, shape))
            }
        }
    }

    fn upload(&mut self, data: Vec<f32>) -> usize {
        self.buffers.push(BufSpec {
            len: data.len().max(1),
            init: Some(if data.is_empty() { vec![0.0] } else { data }),
        });
        self.buf_uses.push(usize::MAX);
        self.buffers.len() - 1
    }

    /// Define `name` as a device value in `buf` (counting its readers on the buffer).
    fn define_dev(&mut self, name: &str, buf: usize, shape: Vec<usize>) {
        let u = self.uses.get(name).copied().unwrap_or(0);
        if self.buf_uses[buf] != usize::MAX {
            self.buf_uses[buf] += u;
        }
        self.tensors.push((name.to_string(), buf, shape.clone()));
        self.vals.insert(name.to_string(), Val::Dev { buf, shape });
    }

    /// Define `name` as a constant known at plan time.
    fn define_const(&mut self, name: &str, shape: Vec<usize>, data: Data) {
        self.vals
            .insert(name.to_string(), Val::Const { shape, data });
    }

    /// One reader of `name` is done: free its buffer when nothing else reads it.
    fn release(&mut self, name: &str) {
        if let Some(Val::Dev { buf, .. }) = self.vals.get(name) {
            let b = *buf;
            if self.buf_uses[b] != usize::MAX && self.buf_uses[b] > 0 {
                self.buf_uses[b] -= 1;
                if self.buf_uses[b] == 0 && !self.keep_all {
                    self.free.push(b);
                }
            }
        }
    }

    fn step(&mut self, kernel: Kernel, params: Vec<u32>, binds: Vec<usize>) {
        self.steps.push(Step {
            kernel,
            params,
            binds,
            node: self.node.clone(),
        });
    }

    /// Strided copy of `shape` from `src` (offset, strides) to `dst` (offset, strides).
    #[allow(clippy::too_many_arguments)]
    fn copy(
        &mut self,
        src: usize,
        in_off: i64,
        in_st: &[i64],
        dst: usize,
        out_off: usize,
        out_st: &[usize],
        shape: &[usize],
    ) {
        let n = numel(shape);
        if n == 0 {
            return;
        }
        let (sh, ist) = pad6(shape, in_st);
        let ost: Vec<i64> = out_st.iter().map(|&s| s as i64).collect();
        let (_, ost) = pad6(shape, &ost);
        let mut p = vec![n as u32, in_off as u32, out_off as u32];
        p.extend(sh);
        p.extend(ist);
        p.extend(ost);
        self.step(Kernel::Copy, p, vec![src, dst]);
    }
}

/// The activation a node applies (the codes of common.wgsl), if it is one.
fn activation(n: &NodeProto) -> Option<(u32, f32, f32)> {
    let a = Attrs(&n.attribute);
    match n.op_type.as_str() {
        "Relu" => Some((1, 0.0, 0.0)),
        "LeakyRelu" => Some((2, a.float("alpha", 0.01), 0.0)),
        "HardSwish" => Some((3, 0.0, 0.0)),
        "Sigmoid" => Some((4, 0.0, 0.0)),
        "Tanh" => Some((5, 0.0, 0.0)),
        "HardSigmoid" => Some((7, a.float("alpha", 0.2), a.float("beta", 0.5))),
        _ => None,
    }
}

/// The ops the planner takes (the others are refused at load).
pub const OPS: &[&str] = &[
    "Add",
    "AveragePool",
    "BatchNormalization",
    "Cast",
    "Clip",
    "Concat",
    "Constant",
    "Conv",
    "ConvTranspose",
    "Div",
    "Flatten",
    "Gather",
    "Gemm",
    "GlobalAveragePool",
    "GlobalMaxPool",
    "HardSigmoid",
    "HardSwish",
    "Identity",
    "LeakyRelu",
    "MatMul",
    "Max",
    "MaxPool",
    "Min",
    "Mul",
    "Pad",
    "Relu",
    "Reshape",
    "Resize",
    "Shape",
    "Sigmoid",
    "Slice",
    "Squeeze",
    "Sub",
    "Tanh",
    "Transpose",
    "Unsqueeze",
];

/// Refuse a graph with an op outside [`OPS`], naming the op and the node.
pub fn check_ops(graph: &GraphProto) -> Result<(), String> {
    for n in &graph.node {
        if !OPS.contains(&n.op_type.as_str()) {
            return Err(format!(
                "node {:?}: op {} has no GPU kernel (the GPU backend runs {})",
                n.name,
                n.op_type,
                OPS.join(", ")
            ));
        }
    }
    Ok(())
}

/// How a graph is planned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Options {
    /// No buffer reuse, so that every tensor can be read after a run (the per-layer parity
    /// test).
    pub keep_all: bool,
    /// The kernels of ungrouped convolutions ([`super::super::Gpu::set_conv_kernels`]).
    pub conv_kernels: ConvKernels,
}

/// Which kernels the ungrouped convolutions of four outputs or more are planned with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ConvKernels {
    /// [`Kernel::Conv4`] only: one pixel and four channels an invocation (the bench's
    /// baseline, `wgpu-conv4`).
    Conv4,
    /// [`Kernel::ConvRow`] over rows of 8 columns or more, else [`Kernel::Conv4`]
    /// (`wgpu-rows`).
    Rows,
    /// As `Rows`, and [`Kernel::ConvSplit`] where a layer has few blocks and long sums.
    #[default]
    Split,
}

impl ConvKernels {
    /// What an adapter of `device_type` ([`super::super::AdapterSummary::device_type`])
    /// plans with unless told otherwise: a GPU splits the long sums of layers with few
    /// blocks over workgroups (its multiprocessors would idle while each invocation adds
    /// hundreds of terms); a CPU adapter (lavapipe) does not, where the split costs 2.3x on
    /// fourier-medium's encoder (docs/bench/conv-rows/nets.md).
    pub fn for_device_type(device_type: &str) -> Self {
        if device_type == "cpu" {
            ConvKernels::Rows
        } else {
            ConvKernels::Split
        }
    }
}

/// Plan `graph` for inputs of `shapes` (the graph's non-initializer inputs, in order).
pub fn plan(graph: &GraphProto, shapes: &[Vec<usize>], opts: Options) -> Result<Plan, String> {
    check_ops(graph)?;
    let keep_all = opts.keep_all;
    let mut pl = Planner {
        conv_kernels: opts.conv_kernels,
        buffers: Vec::new(),
        steps: Vec::new(),
        vals: HashMap::new(),
        uses: HashMap::new(),
        buf_uses: Vec::new(),
        free: Vec::new(),
        keep_all,
        uploaded: HashMap::new(),
        tensors: Vec::new(),
        node: String::new(),
    };
    for t in &graph.initializer {
        let (shape, data) = tensor_data(t)?;
        pl.vals.insert(t.name.clone(), Val::Const { shape, data });
    }
    for n in &graph.node {
        for i in n.input.iter().filter(|i| !i.is_empty()) {
            *pl.uses.entry(i.clone()).or_default() += 1;
        }
    }
    let output_name = graph
        .output
        .first()
        .map(|o| o.name.clone())
        .ok_or("the graph has no output")?;
    for o in &graph.output {
        *pl.uses.entry(o.name.clone()).or_default() += 1;
    }
    let inputs: Vec<&str> = graph
        .input
        .iter()
        .map(|i| i.name.as_str())
        .filter(|n| !pl.vals.contains_key(*n))
        .collect();
    if inputs.len() != shapes.len() {
        return Err(format!(
            "{} input shapes given, the graph takes {} inputs",
            shapes.len(),
            inputs.len()
        ));
    }
    let mut input_bufs = Vec::new();
    for (name, shape) in inputs.iter().zip(shapes) {
        let b = pl.alloc(numel(shape));
        pl.buf_uses[b] = usize::MAX; // written by the host every run: never reused
        pl.define_dev(name, b, shape.clone());
        input_bufs.push(b);
    }
    // Consumers per value, to fuse an activation into its producer.
    let mut consumers: HashMap<&str, Vec<usize>> = HashMap::new();
    for (i, n) in graph.node.iter().enumerate() {
        for x in &n.input {
            consumers.entry(x.as_str()).or_default().push(i);
        }
    }
    let is_output = |name: &str| graph.output.iter().any(|o| o.name == name);
    let mut skip = vec![false; graph.node.len()];
    let shifts = shifts::Finder::new(graph);
    for (idx, n) in graph.node.iter().enumerate() {
        if skip[idx] {
            continue;
        }
        pl.node = if n.name.is_empty() {
            format!("{}#{idx}", n.op_type)
        } else {
            n.name.clone()
        };
        // Export's shifted-sum upsampling (30 nodes): one Resize step.
        if let Some(g) = shifts.at(idx, &pl.vals) {
            ops::bilinear_x2(&mut pl, &g.input, &g.output)?;
            for &i in &g.nodes {
                skip[i] = true;
                for x in graph.node[i].input.iter().filter(|x| **x == g.input) {
                    pl.release(x);
                }
            }
            continue;
        }
        // A single-reader follower that can be fused: batch-norm into a convolution, an
        // activation into a convolution or Gemm.
        let follower = |out: &str, pred: &dyn Fn(&NodeProto) -> bool| -> Option<usize> {
            let c = consumers.get(out)?;
            (c.len() == 1 && !is_output(out) && pred(&graph.node[c[0]]) && !keep_all)
                .then_some(c[0])
        };
        let mut out_name = n.output.first().cloned().unwrap_or_default();
        let mut fused_act = (0u32, 0.0f32, 0.0f32);
        let mut bn: Option<&NodeProto> = None;
        if matches!(n.op_type.as_str(), "Conv" | "ConvTranspose" | "Gemm") {
            if n.op_type == "Conv"
                && let Some(j) = follower(&out_name, &|m| m.op_type == "BatchNormalization")
            {
                bn = Some(&graph.node[j]);
                skip[j] = true;
                out_name = graph.node[j].output[0].clone();
            }
            if let Some(j) = follower(&out_name, &|m| activation(m).is_some()) {
                fused_act = activation(&graph.node[j]).unwrap_or((0, 0.0, 0.0));
                skip[j] = true;
                out_name = graph.node[j].output[0].clone();
            }
        }
        ops::node(&mut pl, n, &out_name, fused_act, bn)?;
        for x in n.input.iter().filter(|x| !x.is_empty()) {
            pl.release(x);
        }
    }
    let (obuf, oshape) = match pl.get(&output_name)?.clone() {
        Val::Dev { buf, shape } => (buf, shape),
        Val::Const { shape, data } => {
            // A constant output: computed at plan time, copied into a buffer of its own.
            let b = pl.upload(data.floats());
            (b, shape)
        }
    };
    Ok(Plan {
        buffers: pl.buffers,
        steps: pl.steps,
        inputs: input_bufs,
        output: (obuf, oshape),
        tensors: pl.tensors,
    })
}
