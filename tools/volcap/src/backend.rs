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

/// Host <-> adapter traffic, dispatches, the networks' nanoseconds on the adapter, the
/// read-backs waited for, the networks planned, and the nanoseconds on the adapter of the
/// frames' maps, of localization and rendering and of the display images, so far (zeros off
/// the GPU; the nanoseconds 0 where the adapter has no timestamps), then the frames whose
/// levels' conflict rounds were predicted and those of them run again.
pub fn adapter_work(rt: &Runtime) -> [u64; 11] {
    #[cfg(feature = "wgpu")]
    if let Some(g) = rt.gpu() {
        let c = g.counters();
        return [
            c.bytes_up,
            c.bytes_down,
            c.dispatches,
            c.gpu_ns,
            c.waits,
            c.net_plans,
            c.maps_gpu_ns,
            c.localize_gpu_ns,
            c.display_gpu_ns,
            c.predicted,
            c.reruns,
        ];
    }
    let _ = rt;
    [0; 11]
}

/// Localization and the mesh-free render of a frame's model field: with `--backend wgpu` on
/// the adapter (`GpuLocalizer`, `GpuRenderer`: the grid kept there, the localization's grid
/// read back for meshing), on the CPU otherwise or for a field the adapter cannot take (a
/// point-MLP head, a grid over its buffer limit).
pub struct Stages {
    /// The coarsest level of [`Stages::localize`] (`2^l + 1` points a side); none: the
    /// engine's default for the grid (`localize::default_coarse`).
    pub coarse_level: Option<u32>,
    cpu: volcap_engine::localize::Localizer,
    #[cfg(feature = "wgpu")]
    gpu: Option<(
        volcap_engine::gpu::localize::GpuLocalizer,
        volcap_engine::gpu::render::GpuRenderer,
    )>,
}

impl Stages {
    pub fn new(rt: &Runtime) -> anyhow::Result<Self> {
        #[cfg(feature = "wgpu")]
        if let Some(g) = rt.gpu() {
            use volcap_engine::gpu::{localize::GpuLocalizer, render::GpuRenderer};
            let loc = GpuLocalizer::new(g.clone()).map_err(|e| anyhow!("--backend wgpu: {e}"))?;
            let ren = GpuRenderer::new(g.clone()).map_err(|e| anyhow!("--backend wgpu: {e}"))?;
            return Ok(Stages {
                coarse_level: None,
                cpu: Default::default(),
                gpu: Some((loc, ren)),
            });
        }
        let _ = rt;
        Ok(Stages {
            coarse_level: None,
            cpu: Default::default(),
            #[cfg(feature = "wgpu")]
            gpu: None,
        })
    }

    /// The CPU's localizer (reference fields such as the oracle run there).
    pub fn cpu_localizer(&mut self) -> &mut volcap_engine::localize::Localizer {
        &mut self.cpu
    }

    /// The paper's hierarchical localization of `field` on `spec` into `grid` (the product's).
    pub fn localize(
        &mut self,
        field: &volcap_engine::model::ModelField,
        spec: volcap_engine::grid::GridSpec,
        grid: &mut volcap_engine::grid::Grid,
    ) -> anyhow::Result<volcap_engine::localize::LocalizeStats> {
        self.localize_with(
            volcap_engine::localize::Method::Hierarchical,
            field,
            spec,
            grid,
        )
    }

    /// [`Stages::localize`] with another method: on the adapter for the hierarchical family
    /// with the field's seeds (the product's, the tight variant, the one without the conflict
    /// loop), on the CPU's localizer for the others.
    pub fn localize_with(
        &mut self,
        method: volcap_engine::localize::Method,
        field: &volcap_engine::model::ModelField,
        spec: volcap_engine::grid::GridSpec,
        grid: &mut volcap_engine::grid::Grid,
    ) -> anyhow::Result<volcap_engine::localize::LocalizeStats> {
        use volcap_engine::localize::default_coarse;
        let coarse = self.coarse_level.unwrap_or_else(|| default_coarse(spec));
        #[cfg(feature = "wgpu")]
        if let (Some((loc, _)), Some(on_gpu), Some(mode)) =
            (self.gpu.as_mut(), field.gpu_field(), gpu_mode(method))
            && loc.check_size(spec).is_ok()
        {
            let stats = loc
                .run(&on_gpu, spec, coarse, mode)
                .map_err(|e| anyhow!("localization on the adapter: {e}"))?;
            loc.read_grid(grid)
                .map_err(|e| anyhow!("localization on the adapter: {e}"))?;
            return Ok(stats);
        }
        Ok(self.cpu.run(method, field, spec, coarse, grid)?)
    }

    /// Render `field` (its own colours) on `spec` into `r`.
    pub fn render(
        &mut self,
        r: &mut volcap_engine::render::Renderer,
        field: &volcap_engine::model::ModelField,
        spec: volcap_engine::grid::GridSpec,
        opts: &volcap_engine::render::RenderOptions,
    ) -> anyhow::Result<()> {
        #[cfg(feature = "wgpu")]
        if let (Some((_, ren)), Some(on_gpu)) = (self.gpu.as_mut(), field.gpu_field())
            && ren.check_size(spec).is_ok()
        {
            r.render_gpu(ren, &on_gpu, field, field, spec, opts)?;
            return Ok(());
        }
        r.render(field, field, spec, opts)?;
        Ok(())
    }
}

/// The GPU localizer's mode for `method`: the hierarchical methods that take the field's
/// seeds (the adapter's localizer always does); none for the others.
#[cfg(feature = "wgpu")]
fn gpu_mode(
    method: volcap_engine::localize::Method,
) -> Option<volcap_engine::localize::HierarchicalMode> {
    use volcap_engine::localize::{HierarchicalMode, Method};
    match method {
        Method::Hierarchical => Some(HierarchicalMode::Paper),
        Method::HierarchicalNoConflict => Some(HierarchicalMode::NoConflict),
        Method::HierarchicalTight => Some(HierarchicalMode::Tight),
        _ => None,
    }
}

/// `--segment-passes` of `eval` and `bench pipeline`: a list of counts, each in the engine's
/// range (`model::SEGMENT_PASSES`).
/// The values a comma-separated flag names (`flag`: its name for the error), each one of
/// `all` by `name`; an unknown one is refused with the names it may take.
pub fn by_names<T: Copy>(
    flag: &str,
    given: &[String],
    all: &[T],
    name: impl Fn(&T) -> &'static str,
) -> anyhow::Result<Vec<T>> {
    given
        .iter()
        .map(|g| {
            all.iter()
                .copied()
                .find(|v| name(v) == g.trim())
                .ok_or_else(|| {
                    let names: Vec<_> = all.iter().map(&name).collect();
                    anyhow!("{flag} {g:?}: one of {}", names.join(", "))
                })
        })
        .collect()
}

pub fn check_segment_passes(passes: &[u8]) -> anyhow::Result<()> {
    let range = volcap_engine::model::SEGMENT_PASSES;
    if passes.is_empty() || passes.iter().any(|p| !range.contains(p)) {
        anyhow::bail!(
            "--segment-passes {passes:?}: each {} or {}",
            range.start(),
            range.end()
        );
    }
    Ok(())
}
