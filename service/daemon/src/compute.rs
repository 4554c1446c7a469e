//! `[compute] backend`: the CPU, or an adapter of the GPU backend (feature `wgpu`) for the
//! stages that have kernels there (the networks today). What was chosen, on which adapter,
//! what runs there and how much work it did: `/state` `compute`, D-Bus `Compute`.

use crate::config::{ComputeBackend, ComputeConfig, ComputeFallback};
use volcap_engine::model::Runtime;

/// The work with a GPU kernel in this build (the rest runs on the CPU on either backend).
pub const ON_ADAPTER: &[&str] = &[
    "segment",
    "field: networks",
    "field: the Fourier maps' temporal filter",
    "localization: the grid, its bookkeeping and the Fourier series",
    "render: first hits, culling, display image",
];
/// What stays on the CPU with `backend = "wgpu"`.
pub const ON_CPU: &[&str] = &[
    "the surface's colour queries (the colour net runs on the adapter) and shading",
    "the temporal filter of the person mask and the crop (and of a turned view's colour features)",
    "encode",
];

type Counters = Box<dyn Fn() -> serde_json::Value + Send + Sync>;

/// What the daemon computes on.
pub struct ComputeStatus {
    /// "cpu" or "wgpu" (what runs, after any fallback).
    pub backend: &'static str,
    /// The adapter's name, driver, backend and type.
    pub adapter: Option<serde_json::Value>,
    pub adapter_label: Option<String>,
    /// Why a `wgpu` backend fell back to the CPU (`fallback = "cpu"`).
    pub note: Option<String>,
    /// Whether the stages of [`ON_ADAPTER`] run there (model mode on the adapter).
    pub networks_on_adapter: bool,
    /// Where the render stage draws the model's frames on the adapter, once it has opened
    /// its renderer: "shared" (the networks' device) or "own" (a second device,
    /// `compute.render_device`); unset where it renders on the CPU.
    pub render_device: std::sync::OnceLock<&'static str>,
    counters: Option<Counters>,
}

impl ComputeStatus {
    pub fn cpu(note: Option<String>) -> Self {
        ComputeStatus {
            backend: "cpu",
            adapter: None,
            adapter_label: None,
            note,
            networks_on_adapter: false,
            render_device: std::sync::OnceLock::new(),
            counters: None,
        }
    }

    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "backend": self.backend,
            "adapter": self.adapter,
            "note": self.note,
            "on_adapter": if self.networks_on_adapter { ON_ADAPTER } else { &[] },
            "on_cpu": if self.networks_on_adapter { ON_CPU } else { &["every stage"] },
            "render_device": self.render_device.get(),
            "adapter_work": self.counters.as_ref().map(|c| c()),
        })
    }

    /// Prometheus lines: the backend in use, and the adapter's work counters
    /// (`volcap_adapter_*_total`, the GPU's seconds from its timestamps).
    pub fn metrics(&self) -> String {
        let mut s = format!(
            "# HELP volcap_compute_backend the compute backend in use (1)
# TYPE volcap_compute_backend gauge
volcap_compute_backend{{backend=\"{}\"}} 1
",
            self.backend
        );
        if let Some(serde_json::Value::Object(c)) = self.counters.as_ref().map(|c| c()) {
            for (k, v) in &c {
                let v = v.as_u64().unwrap_or(0);
                // Nanoseconds on the adapter's clock as seconds: `gpu_ns` (the networks') as
                // `gpu_seconds`, `maps_gpu_ns` as `maps_gpu_seconds`, ...
                let (name, value) = match k.strip_suffix("_ns") {
                    Some(stem) => (format!("{stem}_seconds"), v as f64 / 1e9),
                    None => (k.to_string(), v as f64),
                };
                s.push_str(&format!(
                    "# TYPE volcap_adapter_{name}_total counter\nvolcap_adapter_{name}_total {value}\n"
                ));
            }
        }
        s
    }

    /// D-Bus `Compute`: `cpu`, `cpu (wgpu fell back: ...)` or
    /// `wgpu: ADAPTER; on the adapter: ...; on the CPU: ...`.
    pub fn summary(&self) -> String {
        match (&self.adapter_label, &self.note) {
            (Some(a), _) => format!(
                "wgpu: {a}; on the adapter: {}; on the CPU: {}",
                if self.networks_on_adapter {
                    ON_ADAPTER.join(", ")
                } else {
                    "nothing in this mode".into()
                },
                if self.networks_on_adapter {
                    ON_CPU.join(", ")
                } else {
                    "every stage".into()
                },
            ),
            (None, Some(n)) => format!("cpu (wgpu fell back: {n})"),
            (None, None) => "cpu".into(),
        }
    }
}

/// Open what `[compute]` asks for. `Ok((Some(runtime), status))`: the networks' runtime on
/// the adapter (model mode); `Ok((None, status))`: the CPU (the `runtime` setting then
/// picks tract or ONNX Runtime). `Err`: a configuration error for exit 2 (no adapter
/// matches and no fallback, or a build without the feature).
pub fn open(
    cfg: &ComputeConfig,
    model_mode: bool,
    int8: bool,
) -> Result<(Option<Runtime>, ComputeStatus), String> {
    match cfg.backend {
        ComputeBackend::Cpu => Ok((None, ComputeStatus::cpu(None))),
        ComputeBackend::Wgpu => {
            if int8 && model_mode {
                return Err("backend = \"wgpu\" runs the f32 networks: set [model] precision = \"f32\" (int8 is a CPU-runtime format)".into());
            }
            match open_gpu(&cfg.adapter) {
                Ok((rt, mut st)) => {
                    st.networks_on_adapter = model_mode;
                    Ok((model_mode.then_some(rt), st))
                }
                Err(e) if cfg.fallback == ComputeFallback::Cpu => {
                    tracing::warn!(why = %e, "compute.backend = wgpu: no adapter; running on the CPU (compute.fallback = cpu)");
                    Ok((None, ComputeStatus::cpu(Some(e))))
                }
                Err(e) => Err(e),
            }
        }
    }
}

#[cfg(feature = "wgpu")]
fn open_gpu(adapter: &str) -> Result<(Runtime, ComputeStatus), String> {
    let gpu = volcap_engine::gpu::Gpu::open(adapter)?;
    tracing::info!(adapter = %gpu.adapter.label(), "compute.backend = wgpu");
    let g = gpu.clone();
    let st = ComputeStatus {
        backend: "wgpu",
        adapter: serde_json::to_value(&gpu.adapter).ok(),
        adapter_label: Some(gpu.adapter.label()),
        note: None,
        networks_on_adapter: false,
        render_device: std::sync::OnceLock::new(),
        counters: Some(Box::new(move || {
            serde_json::to_value(g.counters()).unwrap_or_default()
        })),
    };
    Ok((Runtime::Wgpu(gpu), st))
}

#[cfg(not(feature = "wgpu"))]
fn open_gpu(_adapter: &str) -> Result<(Runtime, ComputeStatus), String> {
    Err(
        "backend = \"wgpu\": this volcapd is built without the GPU backend (cargo feature `wgpu`)"
            .into(),
    )
}
