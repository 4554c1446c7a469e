//! An ONNX network on the GPU: the file read at load (the same file tract or ONNX Runtime
//! would run: one source of weights), its graph planned once per input shape
//! ([`plan::plan`]) and realized as buffers, bind groups and one compute pass; each run
//! writes the inputs, records the pass and reads the output back once. Weights stay on the
//! adapter; activation buffers are reused from run to run.

pub mod plan;

use super::{Gpu, groups};
use plan::{Kernel, Plan};
use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use tract_onnx::pb::GraphProto;
use tract_onnx::prelude::Framework;
use wgpu::util::DeviceExt;

const COMMON: &str = include_str!("net/common.wgsl");

fn source(k: Kernel) -> (&'static str, &'static str) {
    match k {
        Kernel::Copy => ("copy", include_str!("net/copy.wgsl")),
        Kernel::Fill => ("fill", include_str!("net/fill.wgsl")),
        Kernel::Binary => ("binary", include_str!("net/binary.wgsl")),
        Kernel::Unary => ("unary", include_str!("net/unary.wgsl")),
        Kernel::Conv => ("conv", include_str!("net/conv.wgsl")),
        Kernel::Conv4 => ("conv4", include_str!("net/conv4.wgsl")),
        Kernel::ConvRow => ("conv_row", include_str!("net/conv_row.wgsl")),
        Kernel::ConvSplit => ("conv_split", include_str!("net/conv_split.wgsl")),
        Kernel::ConvTranspose => ("conv_transpose", include_str!("net/conv_transpose.wgsl")),
        Kernel::Pool => ("pool", include_str!("net/pool.wgsl")),
        Kernel::PoolPlane => ("pool_plane", include_str!("net/pool_plane.wgsl")),
        Kernel::Gemm => ("gemm", include_str!("net/gemm.wgsl")),
        Kernel::Gemm4 => ("gemm4", include_str!("net/gemm4.wgsl")),
        Kernel::Resize => ("resize", include_str!("net/resize.wgsl")),
    }
}

/// One step of a profile ([`GpuNet::profile`]).
#[derive(Debug, Clone)]
pub struct StepTime {
    /// The ONNX node it comes from.
    pub node: String,
    /// The kernel (`conv`, `conv4`, `resize`, ...).
    pub kernel: &'static str,
    /// Median over the runs, milliseconds on the adapter.
    pub ms: f64,
}

/// A tensor read back: its name in the graph, shape and values.
pub type Tensor = (String, Vec<usize>, Vec<f32>);

/// A planned step made real: its pipeline, bind group and workgroups.
type RealStep = (Arc<wgpu::ComputePipeline>, wgpu::BindGroup, (u32, u32));

/// A plan made real on the adapter.
struct Realized {
    shapes: Vec<Vec<usize>>,
    plan: Plan,
    buffers: Vec<wgpu::Buffer>,
    steps: Vec<RealStep>,
    staging: wgpu::Buffer,
    timer: Option<super::Timer>,
}

/// Plans made real kept per network, the most recently used first: the images' networks
/// keep one shape, the per-point networks cycle through a few row buckets ([`row_bucket`]).
const REALIZED: usize = 3;

/// The rows a per-point network is planned for when it runs `rows` ([`GpuNet::run_rows`]):
/// the next power of two, at least 1024. A frame's point count changes every frame (the
/// render's hits, a localization level's batch); planned for the exact count, every frame
/// would plan the graph and create its buffers, weights and bind groups again.
pub fn row_bucket(rows: usize) -> usize {
    rows.next_power_of_two().max(1024)
}

/// One network on one adapter.
pub struct GpuNet {
    gpu: Arc<Gpu>,
    graph: GraphProto,
    /// Plans made real for the input shapes last run, most recent first (at most
    /// [`REALIZED`]).
    realized: Mutex<Vec<Realized>>,
    /// Plans made real since load (a new input shape, or one evicted from the cache).
    plans: std::sync::atomic::AtomicU64,
}

impl GpuNet {
    /// Read `path` and check that every op has a kernel (the error names the op and node).
    pub fn load(gpu: Arc<Gpu>, path: &Path) -> Result<GpuNet, String> {
        let proto = tract_onnx::onnx()
            .proto_model_for_path(path)
            .map_err(|e| format!("not a readable ONNX model: {e}"))?;
        Self::from_graph(gpu, proto.graph.ok_or("no graph")?)
    }

    /// A network from a graph already read (the tests' hand-made graphs); its ops checked as
    /// [`GpuNet::load`] checks them.
    pub fn from_graph(gpu: Arc<Gpu>, graph: GraphProto) -> Result<GpuNet, String> {
        plan::check_ops(&graph)?;
        Ok(GpuNet {
            gpu,
            graph,
            realized: Mutex::new(Vec::new()),
            plans: std::sync::atomic::AtomicU64::new(0),
        })
    }

    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    fn realize(&self, shapes: &[Vec<usize>], keep_all: bool) -> Result<Realized, String> {
        let opts = plan::Options {
            keep_all,
            conv_kernels: self.gpu.conv_kernels(),
        };
        let plan = plan::plan(&self.graph, shapes, opts)?;
        let dev = &self.gpu.device;
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC;
        let limit = dev.limits().max_storage_buffer_binding_size as usize;
        let mut buffers = Vec::with_capacity(plan.buffers.len());
        for (i, b) in plan.buffers.iter().enumerate() {
            let bytes = b.len.max(1) * 4;
            if bytes > limit {
                return Err(format!(
                    "tensor buffer {i} needs {bytes} bytes, over the adapter's {limit} per binding"
                ));
            }
            buffers.push(match &b.init {
                Some(data) => dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: None,
                    contents: bytemuck::cast_slice(data),
                    usage,
                }),
                None => dev.create_buffer(&wgpu::BufferDescriptor {
                    label: None,
                    size: bytes as u64,
                    usage,
                    mapped_at_creation: false,
                }),
            });
        }
        let mut steps = Vec::with_capacity(plan.steps.len());
        for s in &plan.steps {
            let (name, src) = source(s.kernel);
            let pipeline = self.gpu.pipeline(name, &format!("{COMMON}\n{src}"))?;
            let params = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytemuck::cast_slice(&s.params),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let mut entries = vec![wgpu::BindGroupEntry {
                binding: 0,
                resource: params.as_entire_binding(),
            }];
            for (j, &b) in s.binds.iter().enumerate() {
                entries.push(wgpu::BindGroupEntry {
                    binding: j as u32 + 1,
                    resource: buffers[b].as_entire_binding(),
                });
            }
            let bg = dev.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            });
            steps.push((pipeline, bg, groups(s.params[0])));
        }
        let out_len = plan.output.1.iter().product::<usize>().max(1);
        let staging_len = if keep_all {
            plan.buffers.iter().map(|b| b.len).max().unwrap_or(1)
        } else {
            out_len
        };
        // The output, then the network's two timestamps (`run_planned`).
        let staging = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read-back"),
            size: (staging_len.max(1) * 4 + 16) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Realized {
            shapes: shapes.to_vec(),
            plan,
            buffers,
            steps,
            staging,
            timer: self.gpu.timer(),
        })
    }

    /// Write the inputs and record every dispatch; returns the encoder, not yet submitted.
    fn record(
        &self,
        r: &Realized,
        inputs: &[(&[usize], &[f32])],
    ) -> Result<wgpu::CommandEncoder, String> {
        self.record_with(r, inputs, None)
    }

    /// [`Self::record`]; with `per_step`, each step in a compute pass of its own with its
    /// timestamps (a profile), else one pass timed as a whole where the adapter can.
    fn record_with(
        &self,
        r: &Realized,
        inputs: &[(&[usize], &[f32])],
        per_step: Option<&super::Stamps>,
    ) -> Result<wgpu::CommandEncoder, String> {
        if r.plan.inputs.len() != inputs.len() {
            return Err(format!(
                "{} inputs given, the network takes {}",
                inputs.len(),
                r.plan.inputs.len()
            ));
        }
        for (i, (shape, data)) in inputs.iter().enumerate() {
            // The plan's input holds `data` (all of it, or a per-point network's first rows).
            let n = data.len();
            let room: usize = r.shapes.get(i).map_or(0, |s| s.iter().product());
            if n > room {
                return Err(format!(
                    "input {i}: {n} values for shape {shape:?}, the plan takes {room}"
                ));
            }
            let b = r.plan.inputs[i];
            self.gpu
                .queue
                .write_buffer(&r.buffers[b], 0, bytemuck::cast_slice(data));
            self.gpu
                .count()
                .bytes_up
                .fetch_add((n * 4) as u64, Ordering::Relaxed);
        }
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let dispatch = |pass: &mut wgpu::ComputePass<'_>, (pipeline, bg, (x, y)): &RealStep| {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bg, &[]);
            pass.dispatch_workgroups(*x, *y, 1);
        };
        if let Some(stamps) = per_step {
            for (i, step) in r.steps.iter().enumerate() {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: None,
                    timestamp_writes: Some(stamps.writes(i)),
                });
                dispatch(&mut pass, step);
            }
        } else {
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: None,
                    timestamp_writes: r.timer.as_ref().map(|t| t.writes()),
                });
                for step in &r.steps {
                    dispatch(&mut pass, step);
                }
            }
            if let Some(t) = &r.timer {
                t.resolve(&mut enc);
            }
        }
        let c = self.gpu.count();
        c.dispatches
            .fetch_add(r.steps.len() as u64, Ordering::Relaxed);
        c.net_runs.fetch_add(1, Ordering::Relaxed);
        Ok(enc)
    }

    /// Run on f32 inputs (shape, data) in the graph's input order; the first output.
    pub fn run(&self, inputs: &[(&[usize], &[f32])]) -> Result<Vec<f32>, String> {
        let shapes: Vec<Vec<usize>> = inputs.iter().map(|(s, _)| s.to_vec()).collect();
        for (i, ((shape, data), s)) in inputs.iter().zip(&shapes).enumerate() {
            if data.len() != s.iter().product::<usize>() {
                return Err(format!(
                    "input {i}: {} values for shape {shape:?}",
                    data.len()
                ));
            }
        }
        self.run_planned(&shapes, inputs, None)
    }

    /// Run a per-point network (every input's first axis the same point count, each row's
    /// output from its own row alone: the MLPs) on `rows` points, planned for
    /// [`row_bucket`]`(rows)` rows: only the `rows` points are written and read back; the
    /// plan's other rows hold earlier runs' inputs, which (rows being independent) reach
    /// only rows that are not read. The first output's first `rows` rows.
    pub fn run_rows(&self, inputs: &[(&[usize], &[f32])]) -> Result<Vec<f32>, String> {
        let rows = inputs
            .first()
            .and_then(|(s, _)| s.first().copied())
            .ok_or("run_rows: no input with a first axis")?;
        if rows == 0 {
            return Ok(Vec::new());
        }
        let cap = row_bucket(rows);
        let mut shapes = Vec::with_capacity(inputs.len());
        for (i, (shape, data)) in inputs.iter().enumerate() {
            if shape.first() != Some(&rows) || data.len() != shape.iter().product::<usize>() {
                return Err(format!(
                    "input {i}: shape {shape:?} with {} values, for {rows} rows",
                    data.len()
                ));
            }
            let mut s = shape.to_vec();
            s[0] = cap;
            shapes.push(s);
        }
        self.run_planned(&shapes, inputs, Some((rows, cap)))
    }

    /// Run the plan for `shapes` (made real when not cached) on `inputs`; with `rows`
    /// `(rows, cap)` the inputs fill the first `rows` of `cap` rows and the output's first
    /// `rows` rows come back.
    fn run_planned(
        &self,
        shapes: &[Vec<usize>],
        inputs: &[(&[usize], &[f32])],
        rows: Option<(usize, usize)>,
    ) -> Result<Vec<f32>, String> {
        self.with_plan(shapes, |r| {
            let (ob, oshape) = &r.plan.output;
            let mut len = oshape.iter().product::<usize>();
            if let Some((n, cap)) = rows {
                if oshape.first() != Some(&cap) {
                    return Err(format!(
                        "not a per-point network: {cap} rows in, output {oshape:?}"
                    ));
                }
                len = len / cap * n;
            }
            let mut enc = self.record(r, inputs)?;
            // The output and the timestamps (where timed) in one read-back.
            let bytes = (len * 4) as u64;
            enc.copy_buffer_to_buffer(&r.buffers[*ob], 0, &r.staging, 0, bytes);
            let stamps = if let Some(t) = &r.timer {
                t.copy_into(&mut enc, &r.staging, bytes);
                4
            } else {
                0
            };
            let mut out = vec![0.0f32; len + stamps];
            self.gpu
                .submit_and_read_bytes(enc, &r.staging, bytemuck::cast_slice_mut(&mut out))?;
            if stamps > 0 {
                let ticks: &[u8] = bytemuck::cast_slice(&out[len..]);
                self.gpu.add_span(&self.gpu.count().gpu_ns, ticks);
                out.truncate(len);
            }
            Ok(out)
        })
    }

    /// `f` on the plan for `shapes`, made real when not cached (the cache's most recent).
    fn with_plan<T>(
        &self,
        shapes: &[Vec<usize>],
        f: impl FnOnce(&Realized) -> Result<T, String>,
    ) -> Result<T, String> {
        let mut cache = self.realized.lock().unwrap_or_else(|p| p.into_inner());
        match cache.iter().position(|r| r.shapes.as_slice() == shapes) {
            Some(i) => {
                let r = cache.remove(i);
                cache.insert(0, r);
            }
            None => {
                let r = self.realize(shapes, false)?;
                self.plans.fetch_add(1, Ordering::Relaxed);
                self.gpu.count().net_plans.fetch_add(1, Ordering::Relaxed);
                cache.insert(0, r);
                cache.truncate(REALIZED);
            }
        }
        f(cache.first().ok_or("no plan")?)
    }

    /// Run on `inputs` (as [`Self::run`]) without bringing the output back: `then` gets the
    /// recorded encoder, the output's buffer on the adapter, its shape and the network's
    /// timer (where the adapter has timestamps: `then` reads it back with its own results,
    /// [`super::Timer::copy_into`], and adds it to the networks' time), records what reads
    /// the output, submits and waits. The output buffer is the plan's: the next run of this
    /// network overwrites it, so `then` copies out what it keeps.
    pub(crate) fn run_then<T>(
        &self,
        inputs: &[(&[usize], &[f32])],
        then: impl FnOnce(
            wgpu::CommandEncoder,
            &wgpu::Buffer,
            &[usize],
            Option<&super::Timer>,
        ) -> Result<T, String>,
    ) -> Result<T, String> {
        let shapes: Vec<Vec<usize>> = inputs.iter().map(|(s, _)| s.to_vec()).collect();
        for (i, ((shape, data), s)) in inputs.iter().zip(&shapes).enumerate() {
            if data.len() != s.iter().product::<usize>() {
                return Err(format!(
                    "input {i}: {} values for shape {shape:?}",
                    data.len()
                ));
            }
        }
        self.with_plan(&shapes, |r| {
            let (ob, oshape) = &r.plan.output;
            let enc = self.record(r, inputs)?;
            then(enc, &r.buffers[*ob], oshape, r.timer.as_ref())
        })
    }

    /// Plans made real since load: one per new input shape (a per-point network's row
    /// bucket), not one per run.
    pub fn plans_made(&self) -> u64 {
        self.plans.load(Ordering::Relaxed)
    }

    /// Run with every buffer kept and read back each tensor computed on the device (name,
    /// shape, values), in plan order: the per-layer parity check. Slow: one read per tensor.
    pub fn run_all(&self, inputs: &[(&[usize], &[f32])]) -> Result<Vec<Tensor>, String> {
        let shapes: Vec<Vec<usize>> = inputs.iter().map(|(s, _)| s.to_vec()).collect();
        let r = self.realize(&shapes, true)?;
        let enc = self.record(&r, inputs)?;
        self.gpu.queue.submit([enc.finish()]);
        let mut out = Vec::new();
        for (name, b, shape) in &r.plan.tensors {
            let len = shape.iter().product::<usize>();
            if len == 0 {
                continue;
            }
            let enc = self
                .gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
            let (v, _) = self
                .gpu
                .submit_and_read(enc, &r.buffers[*b], &r.staging, len)?;
            out.push((name.clone(), shape.clone(), v));
        }
        Ok(out)
    }

    /// A profile on the adapter: every step in a compute pass of its own with timestamps
    /// around it, `runs` times after one untimed run; per step, in plan order, the ONNX node,
    /// the kernel and the median milliseconds. A pass per step adds a little
    /// to each (the sum is near the whole pass's time, not equal to it). Refused where the
    /// adapter has no timestamp queries.
    pub fn profile(
        &self,
        inputs: &[(&[usize], &[f32])],
        runs: usize,
    ) -> Result<Vec<StepTime>, String> {
        let shapes: Vec<Vec<usize>> = inputs.iter().map(|(s, _)| s.to_vec()).collect();
        let r = self.realize(&shapes, false)?;
        let stamps = self.gpu.stamps(r.steps.len()).ok_or_else(|| {
            format!(
                "no per-step times on {}: no timestamp queries, or {} steps over one query set",
                self.gpu.adapter.label(),
                r.steps.len()
            )
        })?;
        let mut times: Vec<Vec<f64>> = vec![Vec::new(); r.steps.len()];
        for run in 0..=runs.max(1) {
            let enc = self.record_with(&r, inputs, Some(&stamps))?;
            let ns = self.gpu.read_stamps(enc, &stamps)?;
            if run > 0 {
                for (t, v) in times.iter_mut().zip(ns) {
                    t.push(v / 1e6);
                }
            }
        }
        Ok(r.plan
            .steps
            .iter()
            .zip(times)
            .map(|(s, mut t)| {
                t.sort_by(f64::total_cmp);
                StepTime {
                    node: s.node.clone(),
                    kernel: source(s.kernel).0,
                    ms: t.get(t.len() / 2).copied().unwrap_or(0.0),
                }
            })
            .collect())
    }

    /// The number of dispatches of the plan for `shapes` (planning only).
    pub fn dispatches(&self, shapes: &[Vec<usize>]) -> Result<usize, String> {
        let opts = plan::Options {
            conv_kernels: self.gpu.conv_kernels(),
            ..Default::default()
        };
        Ok(plan::plan(&self.graph, shapes, opts)?.steps.len())
    }
}
