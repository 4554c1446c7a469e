//! The temporal filter of the shape maps on the GPU backend's adapter: the host keeps what
//! decides a step (the time step, the crop filter, the settings, the last crop) and works
//! out each frame's [`TemporalStep`]; the maps, their rates and the blend stay on the
//! adapter (`gpu::maps::GpuTemporal`, the rule of [`Temporal::steady_maps`]). The colour
//! features, which the host's colour MLP reads, are blended here with the shape maps'
//! weights brought back for them, as [`Temporal::steady_maps`] blends them.

use super::warp::{Taps, blend, moved, resampled};
use super::{Crop, MapLayout, OneEuro, Temporal, all_finite, one_euro_alpha, weights_at};
use crate::gpu::Gpu;
use crate::gpu::maps::{FrameFilter, GpuTemporal, MapsHead, TemporalStep};
use std::sync::Arc;

pub(super) struct AdapterMaps {
    state: GpuTemporal,
    /// The crop of the last frame whose maps the state holds (`None`: none since a reset).
    last: Option<Crop>,
    color: Option<(MapLayout, Vec<f32>)>,
    color_taps: Taps,
    spare_color: Vec<f32>,
}

impl AdapterMaps {
    /// The next frame starts again (its maps as they are).
    pub(super) fn forget(&mut self) {
        self.last = None;
        self.color = None;
    }
}

impl Temporal {
    /// This frame's part of the maps' filter on the adapter (`head`: what the maps hold,
    /// made through `crop`, the crop [`Self::steady_input`] gave), to hand to
    /// `gpu::maps::fourier_frame`; `color` the frame's colour features, when it has them
    /// (their weights are asked for then). After the frame, [`Self::adapter_done`].
    pub fn adapter_filter(
        &mut self,
        gpu: &Arc<Gpu>,
        head: MapsHead,
        crop: Crop,
        color: Option<&[f32]>,
    ) -> Result<FrameFilter<'_>, String> {
        // Frames filtered on the host before (another model) start again here.
        self.maps = None;
        if self.adapter.as_ref().is_none_or(|a| a.state.head() != head) {
            self.adapter = Some(AdapterMaps {
                state: GpuTemporal::new(gpu.clone(), head)?,
                last: None,
                color: None,
                color_taps: Taps::default(),
                spare_color: Vec::new(),
            });
        }
        let (dt, s) = (self.dt, self.settings);
        let floor = self.crop.iter().map(OneEuro::alpha).fold(0.0f32, f32::max);
        let color_ok = color.is_none_or(all_finite);
        let a = self.adapter.as_mut().ok_or("no filter state")?;
        let step = match a.last {
            // Colour features that are not finite start the filter again, as on the host.
            Some(from) if dt > 0.0 && color_ok => Some(TemporalStep {
                moved: moved(head.size, from, crop),
                a: one_euro_alpha(s.map_change_cutoff_hz, dt),
                min_cutoff_hz: s.map_min_cutoff_hz,
                beta: s.map_beta,
                dt,
                floor,
                from,
                to: crop,
            }),
            _ => None,
        };
        if !color_ok {
            a.color = None;
        }
        let motion = match step {
            Some(_) => self
                .motion_pixels(head.size, crop)
                .map(|m| (s.map_motion_weight, m)),
            None => None,
        };
        let a = self.adapter.as_mut().ok_or("no filter state")?;
        Ok(FrameFilter {
            state: &mut a.state,
            step,
            motion,
            weights: color.is_some(),
        })
    }

    /// The frame of [`Self::adapter_filter`] went through (its maps filtered on the
    /// adapter, `weights` the per-pixel weights when asked for): its crop is the next
    /// frame's last one, and the colour features are blended with the last ones (in place).
    pub fn adapter_done(
        &mut self,
        crop: Crop,
        weights: Option<Vec<f32>>,
        color: Option<(MapLayout, &mut [f32])>,
    ) {
        let Some(a) = self.adapter.as_mut() else {
            return;
        };
        let from = a.last.replace(crop);
        let shape = a.state.head().size;
        // Weights come back only for a frame that continued from the last one.
        match (from, weights, &mut a.color, color) {
            (Some(from), Some(w), Some((llast, lc)), Some((lcol, d)))
                if *llast == lcol && all_finite(d) =>
            {
                let w = if lcol.size == shape {
                    w
                } else {
                    weights_at(&w, shape, lcol.size)
                };
                let moved = a.color_taps.set(lcol.size, from, crop);
                let (old, valid) = resampled(&a.color_taps, moved, lcol, lc, &mut a.spare_color);
                blend(old, valid, lcol, d, &w);
                lc.copy_from_slice(d);
            }
            // Colour features again (the view turned away from the camera's), of another
            // layout, or after a reset: they start from this frame.
            (.., Some((lcol, d))) if all_finite(d) => {
                a.color = Some((lcol, d.to_vec()));
                a.color_taps = Taps::default();
            }
            // None this frame (the camera's own view takes the input's colours): forgotten.
            _ => a.color = None,
        }
    }
}
