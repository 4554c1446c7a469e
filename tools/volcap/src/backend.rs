//! `--backend cpu|wgpu`: where the networks run (the daemon's `[compute] backend`). On the
//! CPU, `--runtime` picks tract or ONNX Runtime; `wgpu` runs them in the GPU backend's
//! kernels on the adapter `--adapter` names (built with the `wgpu` feature).

use anyhow::anyhow;
use volcap_engine::model::{Runtime, RuntimeChoice};

/// The networks' runtime for `backend` ("cpu" or "wgpu"), `runtime` (tract, onnxruntime,
/// auto: the CPU's) and `adapter` ("auto" or a name substring); the note says why `auto`
/// fell back to tract.
pub fn open(
    backend: &str,
    runtime: &str,
    adapter: &str,
) -> anyhow::Result<(Runtime, Option<String>)> {
    match backend.trim() {
        "cpu" => {
            let choice =
                RuntimeChoice::parse(runtime.trim()).map_err(|e| anyhow!("--runtime: {e}"))?;
            let o = Runtime::open(choice, None).map_err(|e| anyhow!("--runtime {runtime}: {e}"))?;
            Ok((o.runtime, o.fallback))
        }
        "wgpu" => gpu(adapter).map(|r| (r, None)),
        other => Err(anyhow!("--backend {other:?}: one of cpu, wgpu")),
    }
}

#[cfg(feature = "wgpu")]
fn gpu(adapter: &str) -> anyhow::Result<Runtime> {
    let g = volcap_engine::gpu::Gpu::open(adapter).map_err(|e| anyhow!("--backend wgpu: {e}"))?;
    eprintln!("--backend wgpu: {}", g.adapter.label());
    Ok(Runtime::Wgpu(g))
}

#[cfg(not(feature = "wgpu"))]
fn gpu(_adapter: &str) -> anyhow::Result<Runtime> {
    Err(anyhow!(
        "--backend wgpu: this volcap is built without the GPU backend (cargo feature `wgpu`: cargo run --release -p volcap --features wgpu -- ...)"
    ))
}

/// Host <-> adapter traffic, dispatches and the networks' nanoseconds on the adapter so far
/// (zeros off the GPU; the last 0 where the adapter has no timestamps).
pub fn adapter_work(rt: &Runtime) -> [u64; 4] {
    #[cfg(feature = "wgpu")]
    if let Some(g) = rt.gpu() {
        let c = g.counters();
        return [c.bytes_up, c.bytes_down, c.dispatches, c.gpu_ns];
    }
    let _ = rt;
    [0; 4]
}
