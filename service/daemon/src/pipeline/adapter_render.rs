//! The render stage's GPU side: the renderer on the adapter (`AdapterRenderer`) and the device
//! it draws on (`compute.render_device`, [`render_device`]).

use super::*;
#[cfg(feature = "wgpu")]
use render_stage::{finish_render, render_field};

/// The render stage's renderer on the GPU backend's adapter (`volcap_engine::gpu::render`):
/// the model's frames are localized, culled and drawn there, their colour and shading
/// queried from the host as on the CPU. A frame it cannot take (a grid over the adapter's
/// buffer limit, a field of the point-MLP family) is rendered on the CPU, and said once.
#[cfg(feature = "wgpu")]
pub(crate) struct AdapterRenderer {
    gpu: volcap_engine::gpu::render::GpuRenderer,
    /// The reason the last frame was drawn on the CPU, logged when it changes.
    cpu_because: Option<String>,
    /// On a device of its own (`compute.render_device = "own"`): the frame's maps come from
    /// the host (read back by the field stage), not from the networks' device.
    own_device: bool,
}

#[cfg(feature = "wgpu")]
impl AdapterRenderer {
    pub(crate) fn open(
        models: Option<&volcap_engine::model::Models>,
        mode: FieldMode,
        compute: &crate::config::ComputeConfig,
    ) -> Option<Self> {
        let device = compute.render_device;
        let volcap_engine::model::Runtime::Wgpu(g) = &models?.runtime else {
            return None;
        };
        if mode != FieldMode::Model {
            return None;
        }
        let mut own_device =
            device.resolve(Some(&g.adapter.device_type)) == crate::config::RenderDevice::Own;
        let g = if own_device {
            match g.sibling() {
                Ok(own) => {
                    tracing::info!(
                        "the render stage on a device of its own (compute.render_device = \"{}\")",
                        device.name()
                    );
                    own
                }
                // `auto` asked for a second device only because it usually pays: without
                // one the render stage shares the networks' (their maps stay on the adapter).
                Err(e) if device == crate::config::RenderDevice::Auto => {
                    tracing::warn!(
                        "the render stage shares the networks' device (compute.render_device = \"auto\"): no second device: {e}"
                    );
                    own_device = false;
                    g.clone()
                }
                Err(e) => {
                    tracing::warn!("the renderer stays on the CPU: no second device: {e}");
                    return None;
                }
            }
        } else {
            g.clone()
        };
        match volcap_engine::gpu::render::GpuRenderer::new(g) {
            Ok(gpu) => Some(AdapterRenderer {
                gpu: gpu
                    .with_rounds_per_wait(compute.rounds_per_wait)
                    .with_round_waits(compute.round_waits),
                cpu_because: None,
                own_device,
            }),
            Err(e) => {
                tracing::warn!("the renderer stays on the CPU: {e}");
                None
            }
        }
    }

    /// The device it draws on: "own" (a second device of the adapter) or "shared".
    pub(crate) fn device_name(&self) -> &'static str {
        if self.own_device { "own" } else { "shared" }
    }

    pub(crate) fn render(
        &mut self,
        renderer: &mut Renderer,
        sh: &Shared,
        field: &volcap_engine::model::ModelField,
        live: &Live,
    ) -> Option<Vec<u8>> {
        let spec = GridSpec::from_resolution(live.resolution).ok()?;
        // On a device of its own the maps come from the host (read back by the field stage;
        // here only if it did not): the networks' device's buffers are not this one's.
        let (on_gpu, why) = if self.own_device {
            match field.gpu_field_from_host() {
                Ok(f) => (f, None),
                Err(e) => (
                    None,
                    Some(format!("the maps from the networks' device: {e}")),
                ),
            }
        } else {
            (field.gpu_field(), None)
        };
        let why = why.or_else(|| match &on_gpu {
            None => Some("the shape model is not a Fourier head".to_string()),
            Some(_) => self.gpu.check_size(spec).err(),
        });
        if why != self.cpu_because {
            if let Some(w) = &why {
                tracing::warn!("rendering on the CPU: {w}");
            } else if self.cpu_because.is_some() {
                tracing::info!("rendering on the adapter again");
            }
            self.cpu_because.clone_from(&why);
        }
        let (Some(on_gpu), None) = (on_gpu, why) else {
            return render_field(renderer, sh, field, field, live);
        };
        let t = Instant::now();
        let opts = RenderOptions {
            coarse_level: live.coarse_level,
            background: live.background,
            shade: false,
            drop_apart: live.drop_apart(),
        };
        let r = renderer
            .render_gpu(&mut self.gpu, &on_gpu, field, field, spec, &opts)
            .map(|st| (st, renderer.last_times()))
            .map_err(|e| e.to_string());
        // The dead band refused on the adapter (a grid too large for its memory): said once
        // in the log, and in /state while it lasts.
        let refused = self.gpu.hold_refused().map(str::to_string);
        if let Ok(mut r) = sh.held_refused.lock()
            && *r != refused
        {
            if let Some(w) = &refused {
                tracing::warn!("{w}");
            }
            *r = refused;
        }
        let gpu = &mut self.gpu;
        renderer.set_antialias(live.antialias);
        finish_render(sh, t, live, r, |size| {
            if size == live.resolution && !live.antialias {
                Ok(renderer.rgba().to_vec())
            } else {
                renderer
                    .render_display_gpu(gpu, size, live.background)
                    .map(|px| px.to_vec())
            }
        })
    }
}

/// Without the `wgpu` feature nothing renders on an adapter: no value of this type exists.
#[cfg(not(feature = "wgpu"))]
pub(crate) enum AdapterRenderer {}

#[cfg(not(feature = "wgpu"))]
impl AdapterRenderer {
    pub(crate) fn open(
        _models: Option<&volcap_engine::model::Models>,
        _mode: FieldMode,
        _compute: &crate::config::ComputeConfig,
    ) -> Option<Self> {
        None
    }

    pub(crate) fn device_name(&self) -> &'static str {
        match *self {}
    }

    pub(crate) fn render(
        &mut self,
        _renderer: &mut Renderer,
        _sh: &Shared,
        _field: &volcap_engine::model::ModelField,
        _live: &Live,
    ) -> Option<Vec<u8>> {
        match *self {}
    }
}

/// The device the render stage asks for with `cfg` and these models: `compute.render_device`
/// resolved on the networks' adapter ([`crate::config::RenderDevice::resolve`]; `shared`
/// where the networks do not run on an adapter, where nothing renders on one).
pub fn render_device(
    cfg: &Config,
    models: Option<&volcap_engine::model::Models>,
) -> crate::config::RenderDevice {
    #[cfg(feature = "wgpu")]
    let device_type = models
        .and_then(|m| m.runtime.gpu())
        .map(|g| g.adapter.device_type.as_str());
    #[cfg(not(feature = "wgpu"))]
    let device_type = models.and(None::<&str>);
    cfg.compute.render_device.resolve(device_type)
}
