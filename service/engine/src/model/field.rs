//! [`ModelField`]: the networks' occupancy and colour over the render view's NDC cube for one
//! frame (either shape family), made by [`super::Models::encode`].

use super::fourier::FourierMaps;
use super::preprocess::{Crop, INPUT_SIZE};
use super::{ColorNets, FEATURE_SIZE, ModelError, ModelView, NDC_HALF_EXTENT_M, ShapeNets, sample};
use crate::field::{ColorField, FieldError, OccupancyField};
use glam::{Mat3, Vec3};
use std::sync::Arc;

/// The per-frame state of the shape model: the feature map for the point MLP, or the
/// Fourier coefficient maps.
pub enum ShapeState {
    Mlp {
        nets: Arc<ShapeNets>,
        feat: Vec<f32>,
    },
    Fourier(FourierMaps),
    /// The Fourier maps on the GPU backend's adapter (made there by the shape network and
    /// filtered there; `GpuMaps::host` brings them back when a caller needs them).
    #[cfg(feature = "wgpu")]
    FourierOnAdapter(Box<crate::gpu::maps::GpuMaps>),
}

/// The networks' occupancy and colour over the render view's NDC cube for one frame.
pub struct ModelField {
    /// The cropped soft person mask `[S, S]`: points whose projection falls outside it
    /// (< 0.5) are outside the person (the silhouette bounds the body under the input view)
    /// and are not sent to the MLP.
    mask: Vec<f32>,
    shape: ShapeState,
    /// The colour networks and this frame's colour features; without them (geometry-only
    /// fields in tests) every point takes the input pixel it projects to.
    color: Option<(Arc<ColorNets>, Vec<f32>)>,
    /// The cropped, masked input image `[3, S, S]`, RGB in [0, 1] (0.5 off the person).
    image: Vec<f32>,
    pub crop: Crop,
    /// Render NDC -> crop NDC.
    to_crop: Mat3,
    identity_view: bool,
    /// The Fourier maps on the GPU backend's adapter: the point queries run there.
    #[cfg(feature = "wgpu")]
    gpu_fourier: Option<crate::gpu::fourier::GpuFourier>,
    /// Where its encoding spent its time ([`super::Models::encode`] sets it).
    pub(super) timings: EncodeTimings,
}

/// Where one frame's encoding spent its time (wall ms on the encoding thread): the parts the
/// pipeline bench splits the field stage into.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EncodeTimings {
    /// The image and mask cropped to the networks' input and normalized.
    pub input_ms: f64,
    /// The shape network, its maps or features back on the host (on the GPU backend's
    /// Fourier frames: the network, its maps interleaved and filtered in time on the
    /// adapter, in one submission; the maps stay there).
    pub shape_ms: f64,
    /// The colour encoder.
    pub color_ms: f64,
    /// The temporal filter of the maps (0 when it is off; on the GPU backend's Fourier
    /// frames only the colour features' blend, the maps' filter being in `shape_ms`).
    pub temporal_ms: f64,
    /// The field made from them: the colour MLP's pixel input, and on the GPU backend the
    /// Fourier maps' buffers on the adapter.
    pub field_ms: f64,
}

impl ModelField {
    pub fn new(
        mask: Vec<f32>,
        shape: ShapeState,
        color: Option<(Arc<ColorNets>, Vec<f32>)>,
        image: Vec<f32>,
        crop: Crop,
        view: ModelView,
    ) -> Self {
        let d = Mat3::from_diagonal(NDC_HALF_EXTENT_M);
        let r = Mat3::from_rotation_y(view.yaw_deg.to_radians())
            * Mat3::from_rotation_x(view.pitch_deg.to_radians());
        let zoom = if view.zoom.is_finite() && view.zoom > 0.0 {
            view.zoom
        } else {
            1.0
        };
        // Render NDC p -> metric (D p) -> rotate back into the input view -> crop NDC.
        let to_crop = d.inverse() * r.transpose() * d * (1.0 / zoom);
        let identity_view = view.is_input_view();
        Self {
            mask,
            shape,
            color,
            image,
            crop,
            to_crop,
            identity_view,
            #[cfg(feature = "wgpu")]
            gpu_fourier: None,
            timings: EncodeTimings::default(),
        }
    }

    /// The same field without its colour networks: every view takes the input pixel each
    /// point projects to (the paper's rule for the input view, applied to turned views too:
    /// the baseline `volcap eval`'s colour columns measure the networks against).
    pub fn without_color_nets(mut self) -> Self {
        self.color = None;
        self
    }

    /// Whether the colour encoder's features came with the field (a turned view; the
    /// camera's own view takes the input's colours without them).
    pub fn has_color_features(&self) -> bool {
        self.color.is_some()
    }

    /// What puts a render-grid point at the same place in this field: the render view's
    /// transform into the input view and the crop, hashed bit for bit. Two frames with the
    /// same key (the temporal filter holds the crop while the person is still, and the view
    /// was not turned) sample their maps at the same pixels and depths for every grid point,
    /// which the surface's dead band needs ([`crate::sides`]).
    pub fn alignment_key(&self) -> u64 {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        for v in self.to_crop.to_cols_array() {
            v.to_bits().hash(&mut h);
        }
        for v in [self.crop.s, self.crop.tx, self.crop.ty] {
            v.to_bits().hash(&mut h);
        }
        h.finish()
    }

    /// Where this field's encoding spent its time (all zero for a field not made by
    /// [`super::Models::encode`]).
    pub fn timings(&self) -> EncodeTimings {
        self.timings
    }

    /// Evaluate the Fourier maps' point queries on `gpu` (the maps written there by the first
    /// query, once; the MLP family stays as it is).
    #[cfg(feature = "wgpu")]
    pub fn on_gpu(mut self, gpu: &Arc<crate::gpu::Gpu>) -> Result<Self, ModelError> {
        let g = match &self.shape {
            ShapeState::Fourier(maps) => crate::gpu::fourier::GpuFourier::new(gpu.clone(), maps),
            ShapeState::FourierOnAdapter(maps) => crate::gpu::fourier::GpuFourier::on_adapter(maps),
            ShapeState::Mlp { .. } => return Ok(self),
        };
        let g = g.map_err(|msg| ModelError::Run {
            path: "(Fourier maps)".into(),
            msg,
        })?;
        self.gpu_fourier = Some(g);
        Ok(self)
    }

    /// Whether the shape maps stayed on the adapter (the GPU backend's Fourier frames).
    #[cfg(feature = "wgpu")]
    pub fn maps_on_adapter(&self) -> bool {
        matches!(self.shape, ShapeState::FourierOnAdapter(_))
    }

    /// The Fourier maps on the host (read back from the adapter once for a frame made
    /// there), or `None` for the point-MLP family.
    pub fn fourier_maps(&self) -> Result<Option<&FourierMaps>, ModelError> {
        match &self.shape {
            ShapeState::Fourier(maps) => Ok(Some(maps)),
            #[cfg(feature = "wgpu")]
            ShapeState::FourierOnAdapter(maps) => {
                maps.host().map(Some).map_err(|msg| ModelError::Run {
                    path: "(Fourier maps)".into(),
                    msg,
                })
            }
            ShapeState::Mlp { .. } => Ok(None),
        }
    }

    /// The field as the GPU localizer evaluates it on the adapter (the Fourier family: its
    /// maps, the person mask and the view's transform), or `None` for the point-MLP family.
    #[cfg(feature = "wgpu")]
    pub fn gpu_field(&self) -> Option<crate::gpu::localize::GpuField<'_>> {
        use crate::gpu::localize::MapsRef;
        match &self.shape {
            ShapeState::Fourier(maps) => Some(self.gpu_fourier(MapsRef::Host(maps))),
            ShapeState::FourierOnAdapter(maps) => Some(self.gpu_fourier(MapsRef::Adapter(maps))),
            ShapeState::Mlp { .. } => None,
        }
    }

    /// [`Self::gpu_field`] with the maps from the host ([`Self::fourier_maps`]: read back
    /// once where the frame made them on the adapter), for a localizer or renderer on
    /// another device than the networks' (`compute.render_device = "own"`), which cannot
    /// read the networks' device's buffers.
    #[cfg(feature = "wgpu")]
    pub fn gpu_field_from_host(
        &self,
    ) -> Result<Option<crate::gpu::localize::GpuField<'_>>, ModelError> {
        Ok(self
            .fourier_maps()?
            .map(|m| self.gpu_fourier(crate::gpu::localize::MapsRef::Host(m))))
    }

    /// The Fourier field over the render view with `maps`.
    #[cfg(feature = "wgpu")]
    fn gpu_fourier<'a>(
        &'a self,
        maps: crate::gpu::localize::MapsRef<'a>,
    ) -> crate::gpu::localize::GpuField<'a> {
        crate::gpu::localize::GpuField::Fourier {
            maps,
            mask: &self.mask,
            mask_size: INPUT_SIZE,
            to_crop: self.to_crop,
            seeds: self.seeds(),
        }
    }

    /// Crop NDC of a render-view NDC point.
    pub fn to_crop(&self, p: Vec3) -> Vec3 {
        self.to_crop * p
    }

    fn gather(&self, points: &[Vec3], feat: &[f32], c: usize, out: &mut Vec<f32>) -> Vec<Vec3> {
        let f = FEATURE_SIZE;
        out.clear();
        out.resize(points.len() * c, 0.0);
        let mut q = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            let u = self.to_crop(*p);
            sample::bilinear(feat, c, f, f, u.x, u.y, &mut out[i * c..(i + 1) * c]);
            q.push(u);
        }
        q
    }

    /// The Fourier series at crop-NDC points: on the adapter when the maps are there
    /// ([`Self::on_gpu`]), else on the CPU.
    fn fourier(&self, maps: &FourierMaps, q: &[Vec3], occ: &mut [f32]) -> Result<(), FieldError> {
        #[cfg(feature = "wgpu")]
        if let Some(g) = &self.gpu_fourier {
            return g.occupancy(maps, q, occ).map_err(FieldError::Backend);
        }
        maps.occupancy(q, occ, &mut Vec::new());
        Ok(())
    }

    fn field_err(e: ModelError) -> FieldError {
        FieldError::Backend(e.to_string())
    }
}

impl OccupancyField for ModelField {
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        let s = INPUT_SIZE;
        let mut idx = Vec::with_capacity(points.len());
        let mut q = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            // A non-finite point is refused wherever it falls (inside or outside the
            // silhouette, either shape family): a NaN is never encoded or read as "outside".
            if !p.is_finite() {
                return Err(FieldError::NonFinite {
                    index: None,
                    point: p.to_array(),
                    value: p
                        .to_array()
                        .into_iter()
                        .find(|v| !v.is_finite())
                        .unwrap_or(f32::NAN),
                });
            }
            let u = self.to_crop(*p);
            // Outside the crop's square first: the mask is not read there.
            let outside_cube = u.x.abs() > 1.0 || u.y.abs() > 1.0;
            if outside_cube || sample::bilinear1(&self.mask, s, s, u.x, u.y) < 0.5 {
                out[i] = 0.0;
            } else {
                idx.push(i);
                q.push(u);
            }
        }
        if q.is_empty() {
            return Ok(());
        }
        let mut occ = vec![0.0f32; q.len()];
        match &self.shape {
            ShapeState::Mlp { nets, feat } => nets.query(feat, &q, &mut occ)?,
            ShapeState::Fourier(maps) => self.fourier(maps, &q, &mut occ)?,
            #[cfg(feature = "wgpu")]
            ShapeState::FourierOnAdapter(maps) => match &self.gpu_fourier {
                Some(g) => g
                    .occupancy_on_adapter(&q, &mut occ)
                    .map_err(FieldError::Backend)?,
                None => {
                    let m = maps.host().map_err(FieldError::Backend)?;
                    m.occupancy(&q, &mut occ, &mut Vec::new());
                }
            },
        }
        for (k, &i) in idx.iter().enumerate() {
            out[i] = occ[k];
        }
        Ok(())
    }

    /// The Fourier maps' seeds ([`FourierMaps::seeds`]) in the render view, those on the
    /// person's mask (elsewhere the field is 0); none for the point-MLP family. Maps made on
    /// the adapter are read back for them once ([`Self::fourier_maps`]: 31 x 128 x 128
    /// floats a frame; a read-back that fails gives no seeds, the paper's method).
    fn seeds(&self) -> Vec<Vec3> {
        let Ok(Some(maps)) = self.fourier_maps() else {
            return Vec::new();
        };
        let from_crop = self.to_crop.inverse();
        if !from_crop.is_finite() {
            return Vec::new();
        }
        let s = INPUT_SIZE;
        let gate = super::fourier::mask_gate(&self.mask, s, maps.size(), 0.5);
        maps.seeds_in(Some(&gate))
            .into_iter()
            .filter(|u| sample::bilinear1(&self.mask, s, s, u.x, u.y) >= 0.5)
            .map(|u| from_crop * u)
            .filter(|p| p.abs().max_element() <= 1.0)
            .collect()
    }
}

impl ColorField for ModelField {
    fn color(&self, points: &[Vec3], out: &mut [[f32; 3]]) -> Result<(), FieldError> {
        if points.is_empty() {
            return Ok(());
        }
        let s = INPUT_SIZE;
        let mut px = [0.0f32; 3];
        let Some((color, color_feat)) = self.color.as_ref().filter(|_| !self.identity_view) else {
            // The render view is the input view: the first hit is visible in the input, so it
            // takes the input pixel's colour directly (the paper's rule). Without colour
            // networks every view does so (a geometry-only field).
            for (o, p) in out.iter_mut().zip(points) {
                let u = self.to_crop(*p);
                sample::bilinear(&self.image, 3, s, s, u.x, u.y, &mut px);
                *o = px;
            }
            return Ok(());
        };
        let c = color.channels;
        let mut feat = Vec::new();
        let q = self.gather(points, color_feat, c, &mut feat);
        let n = points.len();
        let mut rgb = vec![0.0f32; n * 3];
        let mut z = vec![0.0f32; n];
        for (i, u) in q.iter().enumerate() {
            sample::bilinear(&self.image, 3, s, s, u.x, u.y, &mut rgb[i * 3..i * 3 + 3]);
            z[i] = if u.z.is_finite() {
                u.z.clamp(-1.0, 1.0)
            } else {
                0.0
            };
        }
        let col = color
            .mlp
            .run_rows(&[(&[n, c], &feat), (&[n, 3], &rgb), (&[n, 1], &z)])
            .map_err(Self::field_err)?;
        for (i, o) in out.iter_mut().take(n).enumerate() {
            *o = [col[i * 3], col[i * 3 + 1], col[i * 3 + 2]];
        }
        Ok(())
    }
}
