//! The GPU backend (feature `wgpu`): one adapter, its device and queue, the WGSL compute
//! pipelines (compiled once per process and kernel) and the counters of the work done on it.
//!
//! Adapters are Vulkan's (`WGPU_BACKEND` may narrow the search, as wgpu reads it): a board's
//! GPU, or Mesa's lavapipe, Vulkan on the CPU, which runs the same shaders here and in CI
//! for the parity tests (its times say nothing about a GPU). Only default limits and no
//! optional features are asked for, so any Vulkan 1.1 adapter opens.
//!
//! What runs here: [`net::GpuNet`], the ONNX networks (`model::runtime::Runtime::Wgpu`), and
//! [`fourier::GpuFourier`], the Fourier field at points.

pub mod fourier;
pub mod net;

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
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
    /// Fourier field batches evaluated on the adapter.
    pub field_runs: AtomicU64,
    /// Compute dispatches recorded.
    pub dispatches: AtomicU64,
    /// Bytes written from the host to the adapter's buffers (inputs, not the weights).
    pub bytes_up: AtomicU64,
    /// Bytes read back to the host.
    pub bytes_down: AtomicU64,
}

/// A snapshot of [`Counters`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct CounterValues {
    pub net_runs: u64,
    pub field_runs: u64,
    pub dispatches: u64,
    pub bytes_up: u64,
    pub bytes_down: u64,
}

/// An opened adapter: device, queue, compiled kernels, counters.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: AdapterSummary,
    counters: Counters,
    pipelines: Mutex<HashMap<&'static str, Arc<wgpu::ComputePipeline>>>,
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
        let adapter = AdapterSummary::of(&picked.get_info());
        let (device, queue) = pollster::block_on(picked.request_device(&wgpu::DeviceDescriptor {
            label: Some("volcap"),
            required_features: wgpu::Features::empty(),
            required_limits: wgpu::Limits::default(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| format!("{}: cannot open the device: {e}", adapter.label()))?;
        Ok(Arc::new(Gpu {
            device,
            queue,
            adapter,
            counters: Counters::default(),
            pipelines: Mutex::new(HashMap::new()),
        }))
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
            field_runs: c.field_runs.load(Ordering::Relaxed),
            dispatches: c.dispatches.load(Ordering::Relaxed),
            bytes_up: c.bytes_up.load(Ordering::Relaxed),
            bytes_down: c.bytes_down.load(Ordering::Relaxed),
        }
    }

    pub(crate) fn count(&self) -> &Counters {
        &self.counters
    }

    /// Read `len` f32 from the start of `buf` (which must have COPY_SRC) back to the host,
    /// through `staging` (MAP_READ | COPY_DST, at least as large), after `encoder`'s work.
    pub(crate) fn submit_and_read(
        &self,
        mut encoder: wgpu::CommandEncoder,
        buf: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        len: usize,
    ) -> Result<Vec<f32>, String> {
        let bytes = (len * 4) as u64;
        encoder.copy_buffer_to_buffer(buf, 0, staging, 0, bytes);
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        self.queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, 0..bytes, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| format!("the adapter did not finish: {e}"))?;
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!("the adapter refused the work: {e}"));
        }
        rx.recv()
            .map_err(|_| "the read-back was dropped".to_string())?
            .map_err(|e| format!("cannot map the result: {e}"))?;
        let out = {
            let view = staging
                .get_mapped_range(0..bytes)
                .map_err(|e| format!("cannot read the result: {e}"))?;
            bytemuck::cast_slice::<u8, f32>(&view).to_vec()
        };
        staging.unmap();
        self.counters.bytes_down.fetch_add(bytes, Ordering::Relaxed);
        Ok(out)
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
