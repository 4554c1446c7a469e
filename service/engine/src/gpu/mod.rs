//! The GPU backend (feature `wgpu`): one adapter, its device and queue, the WGSL compute
//! pipelines (compiled once per process and kernel) and the counters of the work done on it.
//!
//! Adapters are Vulkan's (`WGPU_BACKEND` may narrow the search, as wgpu reads it): a board's
//! GPU, or Mesa's lavapipe, Vulkan on the CPU, which runs the same shaders here and in CI
//! for the parity tests (its times say nothing about a GPU). Default limits are asked for
//! except the two sizes of a buffer (`max_buffer_size`, `max_storage_buffer_binding_size`)
//! and the storage buffers per stage, which are the adapter's own where larger
//! ([`buffer_limits`]: a 513^3 grid's 540 MB of values is one binding on a GPU, over the
//! default 128 MiB; where a binding holds less, as on lavapipe, the values are tiled over
//! several bindings, `localize::Tiling`), and one optional feature where
//! the adapter has it: timestamp queries (the networks' time on the adapter,
//! `Counters::gpu_ns`); without it nothing is timed there.
//!
//! What runs here: [`net::GpuNet`], the ONNX networks (`model::runtime::Runtime::Wgpu`),
//! [`maps::GpuMaps`], a frame's Fourier maps kept here from the shape network on, with their
//! temporal filter ([`maps::GpuTemporal`]), [`fourier::GpuFourier`], the Fourier field at
//! points, and [`localize::GpuLocalizer`], the hierarchical localization with the grid on
//! the adapter.

pub mod fourier;
pub(crate) mod kit;
pub mod localize;
pub mod maps;
pub mod net;
pub mod render;

use std::collections::HashMap;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// One adapter as wgpu reports it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AdapterSummary {
    pub name: String,
    /// The driver's name and version ("llvmpipe", "NVIDIA 535.104", ...).
    pub driver: String,
    /// "vulkan", ...
    pub backend: String,
    /// "discrete", "integrated", "virtual", "cpu" or "other".
    pub device_type: String,
}

impl AdapterSummary {
    fn of(info: &wgpu::AdapterInfo) -> Self {
        let driver = if info.driver_info.is_empty() {
            info.driver.clone()
        } else {
            format!("{} {}", info.driver, info.driver_info)
        };
        AdapterSummary {
            name: info.name.clone(),
            driver,
            backend: info.backend.to_str().to_string(),
            device_type: match info.device_type {
                wgpu::DeviceType::DiscreteGpu => "discrete",
                wgpu::DeviceType::IntegratedGpu => "integrated",
                wgpu::DeviceType::VirtualGpu => "virtual",
                wgpu::DeviceType::Cpu => "cpu",
                wgpu::DeviceType::Other => "other",
            }
            .to_string(),
        }
    }

    /// "NVIDIA RTX A2000 (vulkan, discrete, NVIDIA 535.104)".
    pub fn label(&self) -> String {
        format!(
            "{} ({}, {}, {})",
            self.name, self.backend, self.device_type, self.driver
        )
    }
}

fn instance() -> wgpu::Instance {
    wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env())
}

/// Every adapter the instance finds (all backends built in; `WGPU_BACKEND` narrows them).
pub fn adapters() -> Vec<AdapterSummary> {
    let inst = instance();
    pollster::block_on(inst.enumerate_adapters(wgpu::Backends::all()))
        .iter()
        .map(|a| AdapterSummary::of(&a.get_info()))
        .collect()
}

/// The limits the device is opened with: wgpu's defaults (what every adapter has), except the
/// sizes of one buffer and of one storage binding, and the storage buffers per shader stage,
/// which are the adapter's (never below the defaults): the grid of a fine level fits in one
/// binding where the adapter allows, and in tiles of its own bindings where a binding is
/// smaller (`localize::Tiling`; every kernel fits the default eight when untiled).
pub fn buffer_limits(adapter: &wgpu::Limits) -> wgpu::Limits {
    let d = wgpu::Limits::default();
    wgpu::Limits {
        max_buffer_size: adapter.max_buffer_size.max(d.max_buffer_size),
        max_storage_buffer_binding_size: adapter
            .max_storage_buffer_binding_size
            .max(d.max_storage_buffer_binding_size),
        max_storage_buffers_per_shader_stage: adapter
            .max_storage_buffers_per_shader_stage
            .max(d.max_storage_buffers_per_shader_stage),
        ..d
    }
}

/// Preference of `auto`: a discrete GPU first, the CPU (lavapipe) last.
fn rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// What the work on the adapter amounted to since it was opened (monotonic counters).
#[derive(Debug, Default)]
pub struct Counters {
    /// Network runs on the adapter.
    pub net_runs: AtomicU64,
    /// Networks planned and made real on the adapter (buffers, weights, bind groups): once
    /// per network and input shape (a per-point network's row bucket), not per run.
    pub net_plans: AtomicU64,
    /// Fourier field batches evaluated on the adapter.
    pub field_runs: AtomicU64,
    /// Localizations with the grid on the adapter (each of a rendered frame's too).
    pub localize_runs: AtomicU64,
    /// Frames rendered on the adapter (their final level and display image).
    pub render_runs: AtomicU64,
    /// Frames (localizations and renders) recorded with each level's conflict rounds
    /// predicted, one read-back for the levels (`compute.round_waits = "per-frame"`), and
    /// those of them run again because a prediction fell short.
    pub predicted: AtomicU64,
    pub reruns: AtomicU64,
    /// Compute dispatches recorded.
    pub dispatches: AtomicU64,
    /// Read-backs the host waited for (a submission and a wait for the queue each: on a GPU
    /// each costs the round trip, whatever it reads).
    pub waits: AtomicU64,
    /// Bytes written from the host to the adapter's buffers (inputs, not the weights).
    pub bytes_up: AtomicU64,
    /// Bytes read back to the host.
    pub bytes_down: AtomicU64,
    /// Nanoseconds the networks' compute passes took on the adapter (timestamp queries; 0
    /// where the adapter has none).
    pub gpu_ns: AtomicU64,
    /// Nanoseconds on the adapter, as `gpu_ns`, of the frames' Fourier maps (interleaved
    /// and filtered in time, `maps::fourier_frame`), of the localizations and the renders'
    /// final levels (each submission from its first pass to its last), and of the display
    /// images.
    pub maps_gpu_ns: AtomicU64,
    pub localize_gpu_ns: AtomicU64,
    pub display_gpu_ns: AtomicU64,
}

/// A snapshot of [`Counters`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct CounterValues {
    pub net_runs: u64,
    pub net_plans: u64,
    pub field_runs: u64,
    pub localize_runs: u64,
    pub render_runs: u64,
    pub predicted: u64,
    pub reruns: u64,
    pub dispatches: u64,
    pub waits: u64,
    pub bytes_up: u64,
    pub bytes_down: u64,
    pub gpu_ns: u64,
    pub maps_gpu_ns: u64,
    pub localize_gpu_ns: u64,
    pub display_gpu_ns: u64,
}

/// An opened adapter: device, queue, compiled kernels, counters.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: AdapterSummary,
    /// Nanoseconds per timestamp tick, where the adapter has timestamp queries.
    timestamp_period: Option<f32>,
    /// Shared with the devices opened by [`Gpu::sibling`]: one count of the adapter's work.
    counters: Arc<Counters>,
    pipelines: Mutex<HashMap<&'static str, Arc<wgpu::ComputePipeline>>>,
    /// Frames' Fourier field buffers kept for the next frames ([`fourier::GpuFourier`]).
    pub(crate) field_pool: Mutex<Vec<fourier::FieldBuffers>>,
    /// Frames' coefficient-map buffers kept for the next frames ([`maps::GpuMaps`]).
    pub(crate) maps_pool: Mutex<Vec<maps::FrameBufs>>,
    /// The convolution kernels networks are planned with from now on
    /// ([`net::plan::ConvKernels`] as a number: [`Gpu::set_conv_kernels`]).
    conv_kernels: AtomicU8,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Gpu({})", self.adapter.label())
    }
}

impl Gpu {
    /// Open the adapter that `choice` names: `"auto"` (the most capable found: discrete,
    /// integrated, virtual, other, CPU) or a case-insensitive substring of its name or driver.
    /// Where none matches, the error lists the adapters found.
    pub fn open(choice: &str) -> Result<Arc<Gpu>, String> {
        let inst = instance();
        let mut found = pollster::block_on(inst.enumerate_adapters(wgpu::Backends::all()));
        let listing = |found: &[wgpu::Adapter]| {
            if found.is_empty() {
                "no adapter found (no Vulkan driver installed? on Debian: mesa-vulkan-drivers for the CPU's lavapipe, the GPU vendor's driver for a GPU)".to_string()
            } else {
                let names: Vec<String> = found
                    .iter()
                    .map(|a| AdapterSummary::of(&a.get_info()).label())
                    .collect();
                format!("adapters found: {}", names.join("; "))
            }
        };
        let want = choice.trim().to_lowercase();
        let picked = if want.is_empty() || want == "auto" {
            found.sort_by_key(|a| rank(a.get_info().device_type));
            if found.is_empty() {
                return Err(format!("adapter = \"auto\": {}", listing(&found)));
            }
            found.swap_remove(0)
        } else {
            let idx = found.iter().position(|a| {
                let i = a.get_info();
                i.name.to_lowercase().contains(&want)
                    || i.driver.to_lowercase().contains(&want)
                    || i.driver_info.to_lowercase().contains(&want)
            });
            match idx {
                Some(i) => found.swap_remove(i),
                None => {
                    return Err(format!(
                        "adapter = {choice:?} matches no adapter's name or driver; {}",
                        listing(&found)
                    ));
                }
            }
        };
        Self::on(picked, Arc::default())
    }

    /// A second device on this one's adapter, with a queue of its own, counting into the
    /// same counters (`compute.render_device = "own"`: the render stage's read-backs then
    /// wait for its own work only, not for the networks another stage submitted before them;
    /// `volcap bench queues` measures whether the adapter runs the two side by side).
    pub fn sibling(&self) -> Result<Arc<Gpu>, String> {
        let inst = instance();
        let found = pollster::block_on(inst.enumerate_adapters(wgpu::Backends::all()));
        let picked = found
            .into_iter()
            .find(|a| AdapterSummary::of(&a.get_info()) == self.adapter)
            .ok_or_else(|| format!("{}: not listed again", self.adapter.label()))?;
        let g = Self::on(picked, self.counters.clone())?;
        g.set_conv_kernels(self.conv_kernels());
        Ok(g)
    }

    fn on(picked: wgpu::Adapter, counters: Arc<Counters>) -> Result<Arc<Gpu>, String> {
        let adapter = AdapterSummary::of(&picked.get_info());
        // Timestamps where the adapter has them (the only optional feature; without it the
        // adapter's time is not measured, nothing else changes).
        let timestamps = picked.features() & wgpu::Features::TIMESTAMP_QUERY;
        let (device, queue) = pollster::block_on(picked.request_device(&wgpu::DeviceDescriptor {
            label: Some("volcap"),
            required_features: timestamps,
            required_limits: buffer_limits(&picked.limits()),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| format!("{}: cannot open the device: {e}", adapter.label()))?;
        let timestamp_period = (!timestamps.is_empty()).then(|| queue.get_timestamp_period());
        let default_kernels = net::plan::ConvKernels::for_device_type(&adapter.device_type);
        Ok(Arc::new(Gpu {
            device,
            queue,
            adapter,
            timestamp_period,
            counters,
            pipelines: Mutex::new(HashMap::new()),
            field_pool: Mutex::new(Vec::new()),
            maps_pool: Mutex::new(Vec::new()),
            conv_kernels: AtomicU8::new(default_kernels as u8),
        }))
    }

    /// Plan the networks of this device from now on with these convolution kernels (the
    /// default: the adapter's, [`net::plan::ConvKernels::for_device_type`]; the bench's
    /// baselines set others). Plans already made keep theirs.
    pub fn set_conv_kernels(&self, k: net::plan::ConvKernels) {
        self.conv_kernels.store(k as u8, Ordering::Relaxed);
    }

    /// The convolution kernels networks are planned with ([`Gpu::set_conv_kernels`]).
    pub fn conv_kernels(&self) -> net::plan::ConvKernels {
        use net::plan::ConvKernels as K;
        match self.conv_kernels.load(Ordering::Relaxed) {
            v if v == K::Conv4 as u8 => K::Conv4,
            v if v == K::Rows as u8 => K::Rows,
            _ => K::Split,
        }
    }

    /// The compute pipeline of a kernel (compiled on first use, then shared).
    pub(crate) fn pipeline(
        &self,
        name: &'static str,
        source: &str,
    ) -> Result<Arc<wgpu::ComputePipeline>, String> {
        let mut cache = self.pipelines.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(p) = cache.get(name) {
            return Ok(p.clone());
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = self
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
        let pipeline = self
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: None,
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!("kernel {name}: {e}"));
        }
        let p = Arc::new(pipeline);
        cache.insert(name, p.clone());
        Ok(p)
    }

    pub fn counters(&self) -> CounterValues {
        let c = &self.counters;
        CounterValues {
            net_runs: c.net_runs.load(Ordering::Relaxed),
            net_plans: c.net_plans.load(Ordering::Relaxed),
            field_runs: c.field_runs.load(Ordering::Relaxed),
            localize_runs: c.localize_runs.load(Ordering::Relaxed),
            render_runs: c.render_runs.load(Ordering::Relaxed),
            predicted: c.predicted.load(Ordering::Relaxed),
            reruns: c.reruns.load(Ordering::Relaxed),
            dispatches: c.dispatches.load(Ordering::Relaxed),
            waits: c.waits.load(Ordering::Relaxed),
            bytes_up: c.bytes_up.load(Ordering::Relaxed),
            bytes_down: c.bytes_down.load(Ordering::Relaxed),
            gpu_ns: c.gpu_ns.load(Ordering::Relaxed),
            maps_gpu_ns: c.maps_gpu_ns.load(Ordering::Relaxed),
            localize_gpu_ns: c.localize_gpu_ns.load(Ordering::Relaxed),
            display_gpu_ns: c.display_gpu_ns.load(Ordering::Relaxed),
        }
    }

    /// Whether the adapter's time is measured (timestamp queries).
    pub fn has_timestamps(&self) -> bool {
        self.timestamp_period.is_some()
    }

    /// A timer for one compute pass, where the adapter has timestamp queries.
    pub(crate) fn timer(&self) -> Option<Timer> {
        self.timestamp_period?;
        let buf = |label, usage| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        Some(Timer {
            queries: self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass time"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolved: buf("pass time", U::QUERY_RESOLVE | U::COPY_SRC),
        })
    }

    /// Timestamps for `passes` compute passes (a begin and an end each), where the adapter
    /// has timestamp queries and the count fits one query set.
    pub(crate) fn stamps(&self, passes: usize) -> Option<Stamps> {
        self.timestamp_period?;
        let count = u32::try_from(2 * passes)
            .ok()
            .filter(|c| *c >= 2 && *c <= wgpu::QUERY_SET_MAX_QUERIES)?;
        let bytes = 8 * count as u64;
        use wgpu::BufferUsages as U;
        let buf = |label, usage| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage,
                mapped_at_creation: false,
            })
        };
        Some(Stamps {
            queries: self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("step times"),
                ty: wgpu::QueryType::Timestamp,
                count,
            }),
            resolved: buf("step times", U::QUERY_RESOLVE | U::COPY_SRC),
            staging: buf("step times read-back", U::MAP_READ | U::COPY_DST),
            count,
        })
    }

    /// Submit `enc` (whose passes wrote `s`'s timestamps) and read each pass's nanoseconds.
    pub(crate) fn read_stamps(
        &self,
        mut enc: wgpu::CommandEncoder,
        s: &Stamps,
    ) -> Result<Vec<f64>, String> {
        let period = self
            .timestamp_period
            .ok_or("the adapter has no timestamp queries")?;
        enc.resolve_query_set(&s.queries, 0..s.count, &s.resolved, 0);
        enc.copy_buffer_to_buffer(&s.resolved, 0, &s.staging, 0, 8 * s.count as u64);
        let mut ticks = vec![0u64; s.count as usize];
        self.submit_and_read_bytes(enc, &s.staging, bytemuck::cast_slice_mut(&mut ticks))?;
        Ok(ticks
            .chunks_exact(2)
            .map(|t| t[1].saturating_sub(t[0]) as f64 * period as f64)
            .collect())
    }

    /// Add the span between two timestamps read back (`ticks`: begin, end, as
    /// [`Timer::end_into`] copied them) to `counter` in nanoseconds; nothing where the
    /// adapter has no timestamp queries.
    pub(crate) fn add_span(&self, counter: &AtomicU64, ticks: &[u8]) {
        let (Some(period), Some(b)) = (self.timestamp_period, ticks.get(..16)) else {
            return;
        };
        let at = |i: usize| b[i..i + 8].try_into().map(u64::from_le_bytes).unwrap_or(0);
        let ns = at(8).saturating_sub(at(0)) as f64 * period as f64;
        counter.fetch_add(ns as u64, Ordering::Relaxed);
    }

    pub(crate) fn count(&self) -> &Counters {
        &self.counters
    }

    /// Map the first `out.len()` bytes of each staging buffer (MAP_READ) for reading once
    /// submission `after` (and those before it on the one queue) is done: one wait for them
    /// all. The stages share the queue: waiting for one's own submission and not for what
    /// other stages' threads submitted after it keeps them from waiting on each other. The
    /// callbacks answer once each on one channel; where one fails, those that mapped are
    /// unmapped (the next read-back maps them again).
    fn map_read(
        &self,
        reads: &[(&wgpu::Buffer, &mut [u8])],
        after: wgpu::SubmissionIndex,
    ) -> Result<(), String> {
        debug_assert!(reads.len() <= 64, "a bit each in `mapped`");
        self.counters.waits.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = std::sync::mpsc::sync_channel(reads.len());
        for (i, (staging, out)) in reads.iter().enumerate() {
            let tx = tx.clone();
            staging.map_async(wgpu::MapMode::Read, 0..out.len() as u64, move |r| {
                let _ = tx.try_send((i, r));
            });
        }
        drop(tx);
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(after),
                timeout: None,
            })
            .map_err(|e| format!("the adapter did not finish: {e}"))?;
        let (mut mapped, mut failed) = (0u64, None);
        for _ in 0..reads.len() {
            match rx.recv() {
                Ok((i, Ok(()))) => mapped |= 1 << i,
                Ok((_, Err(e))) => {
                    failed = failed.or(Some(format!("cannot map the result: {e}")));
                }
                Err(_) => {
                    failed = failed.or(Some("the read-back was dropped".to_string()));
                    break;
                }
            }
        }
        if let Some(e) = failed {
            for (i, (staging, _)) in reads.iter().enumerate() {
                if mapped & (1 << i) != 0 {
                    staging.unmap();
                }
            }
            return Err(e);
        }
        Ok(())
    }

    /// Read `len` f32 from the start of `buf` back to the host ([`Gpu::submit_and_read_into`]).
    pub(crate) fn submit_and_read(
        &self,
        encoder: wgpu::CommandEncoder,
        buf: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        len: usize,
    ) -> Result<(Vec<f32>, wgpu::SubmissionIndex), String> {
        let mut out = vec![0.0f32; len];
        let index = self.submit_and_read_into(encoder, buf, staging, &mut out)?;
        Ok((out, index))
    }

    /// Submit `encoder`'s work and read `out.len()` f32 from the start of `buf` (COPY_SRC)
    /// into `out`, through `staging` (MAP_READ | COPY_DST, at least as large).
    pub(crate) fn submit_and_read_into(
        &self,
        mut encoder: wgpu::CommandEncoder,
        buf: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        out: &mut [f32],
    ) -> Result<wgpu::SubmissionIndex, String> {
        let bytes = std::mem::size_of_val(out) as u64;
        encoder.copy_buffer_to_buffer(buf, 0, staging, 0, bytes);
        self.submit_and_read_bytes(encoder, staging, bytemuck::cast_slice_mut(out))
    }

    /// Submit `encoder`'s work (which ends by copying into `staging`, MAP_READ | COPY_DST)
    /// and read the first `out.len()` bytes of `staging` into `out`.
    pub(crate) fn submit_and_read_bytes(
        &self,
        encoder: wgpu::CommandEncoder,
        staging: &wgpu::Buffer,
        out: &mut [u8],
    ) -> Result<wgpu::SubmissionIndex, String> {
        self.submit_and_read_many(encoder, &mut [(staging, out)])
    }

    /// [`Gpu::submit_and_read_bytes`] from several staging buffers, after one wait.
    pub(crate) fn submit_and_read_many(
        &self,
        encoder: wgpu::CommandEncoder,
        reads: &mut [(&wgpu::Buffer, &mut [u8])],
    ) -> Result<wgpu::SubmissionIndex, String> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let index = self.queue.submit([encoder.finish()]);
        let mapped = self.map_read(reads, index.clone());
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!("the adapter refused the work: {e}"));
        }
        mapped?;
        for (staging, out) in reads.iter_mut() {
            let bytes = out.len() as u64;
            {
                let view = staging
                    .get_mapped_range(0..bytes)
                    .map_err(|e| format!("cannot read the result: {e}"))?;
                out.copy_from_slice(&view);
            }
            staging.unmap();
            self.counters.bytes_down.fetch_add(bytes, Ordering::Relaxed);
        }
        Ok(index)
    }
}

/// Timestamps at the start and end of one compute pass ([`Gpu::timer`]).
pub(crate) struct Timer {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
}

/// Timestamps around many compute passes ([`Gpu::stamps`]): pass `i` writes `2 i` and
/// `2 i + 1`.
pub(crate) struct Stamps {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    staging: wgpu::Buffer,
    count: u32,
}

impl Stamps {
    pub(crate) fn writes(&self, pass: usize) -> wgpu::ComputePassTimestampWrites<'_> {
        let i = 2 * pass as u32;
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        }
    }
}

impl Timer {
    pub(crate) fn writes(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    /// After the pass: the two timestamps resolved ([`Self::copy_into`] brings them to a
    /// read-back).
    pub(crate) fn resolve(&self, enc: &mut wgpu::CommandEncoder) {
        enc.resolve_query_set(&self.queries, 0..2, &self.resolved, 0);
    }

    /// After [`Self::resolve`]: the two timestamps copied to `dst` (MAP_READ | COPY_DST) at
    /// `offset` too, read back with the pass's results ([`Gpu::add_span`]).
    pub(crate) fn copy_into(
        &self,
        enc: &mut wgpu::CommandEncoder,
        dst: &wgpu::Buffer,
        offset: u64,
    ) {
        enc.copy_buffer_to_buffer(&self.resolved, 0, dst, offset, 16);
    }

    /// The begin timestamp only, for the first of several passes.
    pub(crate) fn begin(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: None,
        }
    }

    /// Close a span begun by [`Self::begin`] on an earlier pass of `enc`: an empty pass that
    /// writes the end timestamp, then both timestamps copied to `dst` (MAP_READ | COPY_DST)
    /// at `offset` (16 bytes), read back with the span's other results ([`Gpu::add_span`]).
    pub(crate) fn end_into(&self, enc: &mut wgpu::CommandEncoder, dst: &wgpu::Buffer, offset: u64) {
        drop(enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                query_set: &self.queries,
                beginning_of_pass_write_index: None,
                end_of_pass_write_index: Some(1),
            }),
        }));
        enc.resolve_query_set(&self.queries, 0..2, &self.resolved, 0);
        enc.copy_buffer_to_buffer(&self.resolved, 0, dst, offset, 16);
    }
}

/// Workgroups for `count` invocations of a 64-wide kernel, spread over x and y when x alone
/// would pass the default limit (65535); kernels rebuild the index from `num_workgroups`.
pub fn groups(count: u32) -> (u32, u32) {
    let g = count.div_ceil(64).max(1);
    if g <= 65535 {
        (g, 1)
    } else {
        let y = g.div_ceil(65535);
        (g.div_ceil(y), y)
    }
}
