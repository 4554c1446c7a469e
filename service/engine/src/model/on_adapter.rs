//! [`Models::encode_steady`] on the GPU backend for the Fourier family: the shape network's
//! maps stay on the adapter (`gpu::maps`), filtered there in time, and the frame's field
//! reads them there (its point queries, the localizer and the renderer). Frames with a
//! decode-time reading of the maps on the host (`peak_level`, `moment_fill`,
//! `interior_level`, `thin_level`) take the host path instead.

use super::field::{EncodeTimings, ShapeState};
use super::fourier::FourierNet;
use super::preprocess::{Crop, INPUT_SIZE};
use super::temporal::{MapLayout, Temporal};
use super::{FEATURE_SIZE, ModelError, ModelField, ModelView, Models};
use crate::gpu::maps::{FrameError, MapsHead, fourier_frame};
use std::time::Instant;

impl FourierNet {
    /// What this head's maps hold, when its frames can stay on the adapter: it runs on the
    /// GPU backend and no decode-time reading changes its maps on the host.
    pub fn adapter_head(&self) -> Option<MapsHead> {
        let plain = self.peak_level.is_none()
            && self.moment_fill.is_none()
            && self.interior_level.is_none()
            && self.thin_level.is_none();
        (plain && self.net.gpu_net().is_some()).then_some(MapsHead {
            k: self.k,
            size: self.size,
            basis: self.basis,
            zeta_scale: self.zeta_scale,
            iso_level: self.iso_level,
            smooth: self.smooth_passes,
        })
    }
}

impl Models {
    /// The frame's field with `net`'s maps made and kept on the adapter; `x` the encoder
    /// input, `mask_c` the cropped mask, `timings` with the input's time set.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn encode_on_adapter(
        &self,
        net: &FourierNet,
        head: MapsHead,
        x: &[f32],
        mask_c: Vec<f32>,
        crop: Crop,
        view: ModelView,
        temporal: Option<&mut Temporal>,
        mut timings: EncodeTimings,
    ) -> Result<ModelField, ModelError> {
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let run_err = |msg: String| ModelError::Run {
            path: net.net.path().display().to_string(),
            msg,
        };
        let (Some(gnet), Some(gpu)) = (net.net.gpu_net(), self.runtime.gpu()) else {
            return Err(run_err("not on the GPU backend".into()));
        };
        let s = INPUT_SIZE;
        // The colour encoder first (a turned view only): its features' weights come back
        // with the shape maps' filter.
        let t = Instant::now();
        let mut color_feat = if view.is_input_view() {
            None
        } else {
            Some(self.color.encoder.run(&[(&[1, 4, s, s], x)])?)
        };
        timings.color_ms = ms(t);
        let t = Instant::now();
        let input = (&[1, 4, s, s][..], x);
        let frame_err = |e: FrameError| match e {
            FrameError::NotFinite => run_err("non-finite Fourier coefficients".into()),
            FrameError::Backend(msg) => run_err(msg),
        };
        let maps = match temporal {
            Some(tm) => {
                let filter = tm
                    .adapter_filter(gpu, head, crop, color_feat.as_deref())
                    .map_err(run_err)?;
                let (maps, weights) =
                    fourier_frame(gnet, input, head, Some(filter)).map_err(frame_err)?;
                timings.shape_ms = ms(t);
                let t = Instant::now();
                let layout = MapLayout {
                    channels: self.color.channels,
                    size: FEATURE_SIZE,
                    interleaved: false,
                };
                tm.adapter_done(
                    crop,
                    weights,
                    color_feat.as_mut().map(|f| (layout, f.as_mut_slice())),
                );
                timings.temporal_ms = ms(t);
                maps
            }
            None => {
                let (maps, _) = fourier_frame(gnet, input, head, None).map_err(frame_err)?;
                timings.shape_ms = ms(t);
                maps
            }
        };
        let t = Instant::now();
        // The colour MLP's pixel input, as in training: the masked RGB back in [0, 1].
        let image: Vec<f32> = x[..3 * s * s].iter().map(|v| v * 0.5 + 0.5).collect();
        let mut field = ModelField::new(
            mask_c,
            ShapeState::FourierOnAdapter(Box::new(maps)),
            color_feat.map(|f| (self.color.clone(), f)),
            image,
            crop,
            view,
        )
        .on_gpu(gpu)?;
        timings.field_ms = ms(t);
        field.timings = timings;
        Ok(field)
    }
}
