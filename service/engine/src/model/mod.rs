//! The trained networks (ONNX, run by tract) as engine fields.
//!
//! Per frame: [`Models::frame`] letterboxes the camera frame to 256x256, segments it, keeps
//! the most prominent person (the largest mask region; the others are counted), crops
//! around them with the shared rule ([`preprocess::Crop`]), runs the shape and colour
//! encoders once, and returns a [`ModelField`]: an [`OccupancyField`] + [`ColorField`] over
//! the render view's NDC cube. Each query point is mapped into crop NDC (the view rotation
//! about the crop centre, metric through the training camera's NDC extents), its feature is
//! sampled bilinearly ([`sample::bilinear`], PyTorch's `align_corners=True`, border), its depth
//! encoded (SoftZ or scalar, as the model's metadata says) and the point MLP runs on batches.
//!
//! Loading checks every file: it exists, parses as ONNX, has the `volcap.kind` expected, and
//! its input/output shapes match the contract; any mismatch is an error naming the file and
//! what differs. The ONNX files are the only source of the weights.

mod field;
pub mod fourier;
mod net;
pub mod runtime;
pub use net::{InputSpec, Net, NodeTime};
pub(crate) use net::{meta_of, meta_usize};
pub use runtime::{Runtime, RuntimeChoice};
pub mod mlp;
mod threads;
pub use threads::with_threads;
#[cfg(feature = "wgpu")]
mod on_adapter;
pub mod preprocess;
pub mod sample;
mod segment;
mod shape;
pub mod temporal;

use crate::field::FieldError;
use crate::softz::{SOFTZ_BINS, soft_z};
pub use field::{EncodeTimings, ModelField, ShapeState};
pub use fourier::{DepthFrame, FourierNet};
pub use segment::{
    FrameError, FrameInfo, SEGMENT_FULL_EVERY_MAX, SegmentTimings, SegmentTrack, Tracked,
};
pub use shape::{ShapeModel, trained_segment_passes};

use glam::Vec3;
use preprocess::{Crop, INPUT_SIZE};
use std::path::Path;
use std::sync::Arc;

/// Feature map side produced by the encoders.
pub const FEATURE_SIZE: usize = 64;

#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("{path}: {msg}")]
    File { path: String, msg: String },
    #[error("{path}: {what}: expected {expected}, found {found}")]
    Mismatch {
        path: String,
        what: String,
        expected: String,
        found: String,
    },
    #[error("{path}: running the network failed: {msg}")]
    Run { path: String, msg: String },
}

/// Which precision of the networks to load.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    F32,
    Int8,
}

impl Precision {
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "f32" => Ok(Self::F32),
            "int8" => Ok(Self::Int8),
            _ => Err(format!("precision {s:?} is not one of f32, int8")),
        }
    }
    pub(crate) fn suffix(self) -> &'static str {
        match self {
            Self::F32 => "",
            Self::Int8 => ".int8",
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::Int8 => "int8",
        }
    }
}

/// Depth encoding of a shape MLP.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZEncoding {
    SoftZ,
    Scalar,
}

impl ZEncoding {
    pub fn dim(self) -> usize {
        match self {
            Self::SoftZ => SOFTZ_BINS,
            Self::Scalar => 1,
        }
    }
}

/// The shape networks: encoder + point MLP.
pub struct ShapeNets {
    pub encoder: Net,
    pub mlp: Net,
    /// The same MLP as fused dense layers (f32 CBN files that agree with tract at load);
    /// `query` uses it when present.
    pub fused: Option<mlp::FusedCbnMlp>,
    pub channels: usize,
    pub z: ZEncoding,
}

/// The colour networks.
pub struct ColorNets {
    pub encoder: Net,
    pub mlp: Net,
    pub channels: usize,
}

/// Every network of the pipeline, loaded from a models folder.
pub struct Models {
    pub seg: Net,
    pub shape: ShapeModel,
    pub color: Arc<ColorNets>,
    pub name: String,
    pub precision: Precision,
    /// The shape model for close-range framing (`name`, model), used instead of `shape` on
    /// frames whose person the frame's lower edge cuts ([`preprocess::cut_by_frame`]); none:
    /// `shape` for every frame.
    pub close_range: Option<(String, ShapeModel)>,
    /// The runtime every network runs on.
    pub runtime: Runtime,
    /// How many times a frame is segmented ([`Models::person_mask`]): 1, the letterboxed
    /// frame; 2, then once more on the person's crop of it (thin parts the first pass loses,
    /// an arm, a hand, come back: `docs/eval/hands.md` section 8). Loaded as the shape
    /// model was trained ([`ShapeModel::trained_segment_passes`]); the daemon's `[model]
    /// segment_passes` and the tools' `--segment-passes` set it otherwise.
    pub segment_passes: u8,
}

/// The shape model a board or a tool runs unless told otherwise (the daemon's `[model] name`,
/// the tools' `--model`): `fourier-small-seg2` (`fourier-small`'s network trained on to run
/// (12) on two-pass masks: held-out 257^3 better than `fourier-small` with one segmentation
/// pass as with two, docs/eval/eval.md and docs/eval/hands.md sections 10-11), the fastest
/// accurate network; `fourier-medium` is more accurate for 1.4-1.8x its encoder
/// (docs/eval/knobs), and the boards that can afford it name it (the main job's sim.toml).
pub const DEFAULT_MODEL: &str = "fourier-small-seg2";

/// The counts [`Models::segment_passes`] takes (the daemon's `[model] segment_passes`, the
/// tools' `--segment-passes`).
pub const SEGMENT_PASSES: std::ops::RangeInclusive<u8> = 1..=2;

pub(crate) const IMG: [Option<usize>; 4] = [Some(1), Some(4), Some(INPUT_SIZE), Some(INPUT_SIZE)];

fn encoder(path: &Path, kind: &str, rt: &Runtime) -> Result<(Net, usize), ModelError> {
    let channels = meta_usize(path, &meta_of(path), "feature_channels")?;
    let net = Net::load_on(
        path,
        kind,
        &[InputSpec {
            name: "image",
            shape: &IMG,
        }],
        &[
            Some(1),
            Some(channels),
            Some(FEATURE_SIZE),
            Some(FEATURE_SIZE),
        ],
        rt,
    )?;
    Ok((net, channels))
}

impl ShapeNets {
    pub fn load(dir: &Path, name: &str, precision: Precision) -> Result<Self, ModelError> {
        Self::load_on(dir, name, precision, &Runtime::Tract)
    }

    pub fn load_on(
        dir: &Path,
        name: &str,
        precision: Precision,
        rt: &Runtime,
    ) -> Result<Self, ModelError> {
        let sfx = precision.suffix();
        let (encoder, channels) = encoder(
            &dir.join(format!("shape-{name}.encoder{sfx}.onnx")),
            "shape-encoder",
            rt,
        )?;
        let mpath = dir.join(format!("shape-{name}.mlp{sfx}.onnx"));
        let meta = meta_of(&mpath);
        let z = match meta.get("volcap.z_encoding").map(|s| s.as_str()) {
            Some("softz") => ZEncoding::SoftZ,
            Some("scalar") => ZEncoding::Scalar,
            other if mpath.is_file() => {
                return Err(ModelError::Mismatch {
                    path: mpath.display().to_string(),
                    what: "metadata volcap.z_encoding".into(),
                    expected: "softz or scalar".into(),
                    found: format!("{other:?}"),
                });
            }
            _ => ZEncoding::SoftZ,
        };
        let mlp = Net::load_on(
            &mpath,
            "shape-mlp",
            &[
                InputSpec {
                    name: "feat",
                    shape: &[None, Some(channels)],
                },
                InputSpec {
                    name: "z",
                    shape: &[None, Some(z.dim())],
                },
            ],
            &[None, Some(1)],
            rt,
        )?;
        let fused = if precision == Precision::F32 {
            mlp::FusedCbnMlp::from_onnx(&mpath).filter(|f| {
                f.dims() == (channels, z.dim()) && mlp::agrees(f, &mlp, channels, z.dim())
            })
        } else {
            None
        };
        Ok(ShapeNets {
            encoder,
            mlp,
            fused,
            channels,
            z,
        })
    }
}

impl ShapeNets {
    /// The feature map `[C, 64, 64]` of an encoder input `[4, S, S]`.
    pub fn features(&self, x: &[f32]) -> Result<Vec<f32>, ModelError> {
        let s = INPUT_SIZE;
        self.encoder.run(&[(&[1, 4, s, s], x)])
    }

    /// Occupancy at crop-NDC points given a feature map: sample, encode depth, run the MLP.
    pub fn query(&self, feat: &[f32], points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        let n = points.len();
        if n == 0 {
            return Ok(());
        }
        let (c, f, zd) = (self.channels, FEATURE_SIZE, self.z.dim());
        let mut fv = vec![0.0f32; n * c];
        let mut z = vec![0.0f32; n * zd];
        for (i, u) in points.iter().enumerate() {
            sample::bilinear(feat, c, f, f, u.x, u.y, &mut fv[i * c..(i + 1) * c]);
            match self.z {
                ZEncoding::SoftZ => {
                    // Non-finite depth is refused by SoftZ: reported with the point.
                    soft_z(u.z, &mut z[i * zd..(i + 1) * zd]).map_err(|_| {
                        FieldError::NonFinite {
                            index: None,
                            point: u.to_array(),
                            value: u.z,
                        }
                    })?;
                }
                ZEncoding::Scalar => {
                    if !u.z.is_finite() {
                        return Err(FieldError::NonFinite {
                            index: None,
                            point: u.to_array(),
                            value: u.z,
                        });
                    }
                    z[i] = u.z.clamp(-1.0, 1.0);
                }
            }
        }
        if let Some(fused) = &self.fused {
            fused.run(&fv, &z, &mut out[..n]);
            return Ok(());
        }
        let occ = self
            .mlp
            .run_rows(&[(&[n, c], &fv), (&[n, zd], &z)])
            .map_err(|e| FieldError::Backend(e.to_string()))?;
        if occ.len() != n {
            return Err(FieldError::Backend(format!(
                "{}: {} outputs for {n} points",
                self.mlp.path().display(),
                occ.len()
            )));
        }
        out[..n].copy_from_slice(&occ);
        Ok(())
    }
}

impl ColorNets {
    /// Colour stays f32 at every precision setting: it runs only on the visible surface
    /// points, off the shape path's cost.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        Self::load_on(dir, &Runtime::Tract)
    }

    /// [`ColorNets::load`] on `rt`.
    pub fn load_on(dir: &Path, rt: &Runtime) -> Result<Self, ModelError> {
        let (encoder, channels) = encoder(&dir.join("color.encoder.onnx"), "color-encoder", rt)?;
        let mlp = Net::load_on(
            &dir.join("color.mlp.onnx"),
            "color-mlp",
            &[
                InputSpec {
                    name: "feat",
                    shape: &[None, Some(channels)],
                },
                InputSpec {
                    name: "rgb",
                    shape: &[None, Some(3)],
                },
                InputSpec {
                    name: "z",
                    shape: &[None, Some(1)],
                },
            ],
            &[None, Some(3)],
            rt,
        )?;
        Ok(ColorNets {
            encoder,
            mlp,
            channels,
        })
    }
}

/// Whether every value of `d` is finite: branch-free within chunks of 64 (it vectorizes),
/// for the maps checked once a frame (`FourierMaps::from_planar`, the temporal filter).
pub(crate) fn all_finite(d: &[f32]) -> bool {
    d.chunks(64)
        .all(|c| c.iter().fold(true, |ok, v| ok & v.is_finite()))
}

/// The render view relative to the input camera: rotation about the crop centre (yaw about
/// the vertical axis, then pitch), and a zoom (1 = the crop).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelView {
    pub yaw_deg: f32,
    pub pitch_deg: f32,
    pub zoom: f32,
}

impl ModelView {
    /// The input camera's own view (no turn): the surface seen there takes the input pixel's
    /// colour (the paper's rule), so the colour networks have nothing to do.
    pub fn is_input_view(&self) -> bool {
        self.yaw_deg == 0.0 && self.pitch_deg == 0.0
    }
}

impl Default for ModelView {
    fn default() -> Self {
        Self {
            yaw_deg: 0.0,
            pitch_deg: 0.0,
            zoom: 1.0,
        }
    }
}

/// Half extents in metres of the input view's NDC cube for the training camera (weak
/// perspective 2.3 m image height, near/far 1.5 m from the subject): used only to make the
/// view rotation metric.
pub const NDC_HALF_EXTENT_M: Vec3 = Vec3::new(1.15, 1.15, 1.5);

impl Models {
    /// Load `seg.onnx`, `shape-NAME.*` and `color.*` (the shape files at `precision`) from
    /// `dir`, on tract.
    pub fn load(dir: &Path, name: &str, precision: Precision) -> Result<Self, ModelError> {
        Self::load_on(dir, name, precision, &Runtime::Tract)
    }

    /// [`Models::load`] with every network on `rt`.
    pub fn load_on(
        dir: &Path,
        name: &str,
        precision: Precision,
        rt: &Runtime,
    ) -> Result<Self, ModelError> {
        // The segmentation is f32 at every precision: its int8 form lost accuracy on real
        // photos and was slower (models/seg.md).
        let seg = Net::load_on(
            &dir.join("seg.onnx"),
            "seg",
            &[InputSpec {
                name: "image",
                shape: &[Some(1), Some(3), Some(INPUT_SIZE), Some(INPUT_SIZE)],
            }],
            &[Some(1), Some(1), Some(INPUT_SIZE), Some(INPUT_SIZE)],
            rt,
        )?;
        let shape = ShapeModel::load_on(dir, name, precision, rt)?;
        Ok(Models {
            seg,
            segment_passes: shape.trained_segment_passes(),
            shape,
            color: Arc::new(ColorNets::load_on(dir, rt)?),
            name: name.into(),
            precision,
            close_range: None,
            runtime: rt.clone(),
        })
    }

    /// Also load `shape-NAME.*` (at the same precision) as the close-range shape model: frames
    /// whose person the frame's lower edge cuts are encoded with it (`FrameInfo::close_range`
    /// says so). It must be of the same family as the main shape model's colour and crop
    /// contract, which every committed shape model shares. The frame is segmented before the
    /// cut is known, [`Self::segment_passes`] times (the main model's count unless set): the
    /// close-range model encodes that mask, whatever count it was trained with.
    pub fn with_close_range(mut self, dir: &Path, name: &str) -> Result<Self, ModelError> {
        let shape = ShapeModel::load_on(dir, name, self.precision, &self.runtime)?;
        self.close_range = Some((name.into(), shape));
        Ok(self)
    }

    /// Read thin parts from their moments ([`fourier::FourierMaps::with_moment_fill`]
    /// `(min_len, max_len, away)`) on every Fourier shape model (the main one and the
    /// close-range one), or not (`None`); other families have no series to fill. Returns how
    /// many models took it. A model already shared (an `Arc` cloned elsewhere) is left as
    /// it is: call this right after loading.
    pub fn with_moment_fill(mut self, fill: Option<(f32, f32, usize)>) -> (Self, usize) {
        let n = self.each_fourier(|f| f.moment_fill = fill);
        (self, n)
    }

    /// Apply `set` to every Fourier shape model (the main one and the close-range one) not
    /// yet shared; how many took it.
    fn each_fourier(&mut self, mut set: impl FnMut(&mut FourierNet)) -> usize {
        let mut n = 0;
        let shapes =
            std::iter::once(&mut self.shape).chain(self.close_range.as_mut().map(|(_, s)| s));
        for shape in shapes {
            if let ShapeModel::Fourier(f) = shape
                && let Some(f) = Arc::get_mut(f)
            {
                set(f);
                n += 1;
            }
        }
        n
    }

    /// Read every Fourier shape model's maps (the main one and the close-range one) with
    /// `passes` passes of [`fourier::FourierMaps::smoothed`] (0: as the network gives them;
    /// at most [`fourier::MAX_SMOOTH_PASSES`], more are taken as that). Returns how many
    /// models took it; a model already shared is left as it is (call this right after loading).
    pub fn with_map_smooth(mut self, passes: u8) -> (Self, usize) {
        let passes = passes.min(fourier::MAX_SMOOTH_PASSES);
        let n = self.each_fourier(|f| f.smooth_passes = passes);
        (self, n)
    }

    /// The passes of smoothing the main shape model's maps get ([`Self::with_map_smooth`]);
    /// `None` when it has no maps (the MLP family).
    pub fn map_smooth(&self) -> Option<u8> {
        match &self.shape {
            ShapeModel::Fourier(f) => Some(f.smooth_passes),
            _ => None,
        }
    }

    /// Segment, crop and encode one RGB8 frame (its most prominent person); the field over
    /// `view`.
    pub fn frame(
        &self,
        rgb: &[u8],
        width: usize,
        height: usize,
        view: ModelView,
    ) -> Result<(ModelField, FrameInfo), FrameError> {
        let mut info = FrameInfo::default();
        let (img, mask, crop) = self.prepare(rgb, width, height, &mut info)?;
        let t = std::time::Instant::now();
        let field = self.encode(&img, &mask, crop, view)?;
        info.encode_ms = t.elapsed().as_secs_f64() * 1e3;
        Ok((field, info))
    }

    /// The shape model for a crop: the close-range one when the frame cuts the person and
    /// one is loaded, the main one otherwise.
    pub fn shape_for(&self, crop: &Crop) -> &ShapeModel {
        match &self.close_range {
            Some((_, m)) if crop.cut_by_frame => m,
            _ => &self.shape,
        }
    }

    /// Encode a letterboxed image `[3, S, S]` with its mask `[S, S]` through `crop` (the
    /// shape model chosen by [`Models::shape_for`]).
    pub fn encode(
        &self,
        img: &[f32],
        mask: &[f32],
        crop: Crop,
        view: ModelView,
    ) -> Result<ModelField, ModelError> {
        self.encode_steady(img, mask, crop, view, None)
    }

    /// [`Models::encode`], the shape maps and colour features blended with the last frame's
    /// by `temporal` ([`temporal::Temporal::steady_maps`]; `mask` and `crop` are the ones its
    /// `steady_input` gave).
    pub fn encode_steady(
        &self,
        img: &[f32],
        mask: &[f32],
        crop: Crop,
        view: ModelView,
        temporal: Option<&mut temporal::Temporal>,
    ) -> Result<ModelField, ModelError> {
        let ms = |t: std::time::Instant| t.elapsed().as_secs_f64() * 1e3;
        let mut timings = EncodeTimings::default();
        let t = std::time::Instant::now();
        let s = INPUT_SIZE;
        let rgb_c = crop.apply(img, 3, s);
        let mask_c = crop.apply(mask, 1, s);
        let x = preprocess::encoder_input(&rgb_c, &mask_c, s);
        timings.input_ms = ms(t);
        #[cfg(feature = "wgpu")]
        if let ShapeModel::Fourier(net) = self.shape_for(&crop)
            && let Some(head) = net.adapter_head()
        {
            return self.encode_on_adapter(net, head, &x, mask_c, crop, view, temporal, timings);
        }
        let t = std::time::Instant::now();
        let mut shape = match self.shape_for(&crop) {
            ShapeModel::Mlp(nets) => ShapeState::Mlp {
                feat: nets.features(&x)?,
                nets: nets.clone(),
            },
            ShapeModel::Fourier(net) => ShapeState::Fourier(net.maps(&x)?),
        };
        timings.shape_ms = ms(t);
        let t = std::time::Instant::now();
        // In the input camera's view every visible point takes its input pixel's colour: the
        // colour encoder runs only for a turned view (its temporal state then starts again).
        let mut color_feat = if view.is_input_view() {
            None
        } else {
            Some(self.color.encoder.run(&[(&[1, 4, s, s], &x)])?)
        };
        timings.color_ms = ms(t);
        let t = std::time::Instant::now();
        if let Some(t) = temporal {
            let planar = |channels| temporal::MapLayout {
                channels,
                size: FEATURE_SIZE,
                interleaved: false,
            };
            let color = color_feat
                .as_mut()
                .map(|f| (planar(self.color.channels), f.as_mut_slice()));
            match &mut shape {
                ShapeState::Mlp { nets, feat } => {
                    let l = planar(nets.channels);
                    t.steady_maps(crop, (l, feat.as_mut_slice()), color);
                }
                ShapeState::Fourier(maps) => {
                    let l = temporal::MapLayout {
                        channels: 2 * maps.k() + 1,
                        size: maps.size(),
                        interleaved: true,
                    };
                    t.steady_maps(crop, (l, maps.coefficients_mut()), color);
                }
                // Made only by `encode_on_adapter`.
                #[cfg(feature = "wgpu")]
                ShapeState::FourierOnAdapter(_) => {}
            }
        }
        timings.temporal_ms = ms(t);
        let t = std::time::Instant::now();
        // The colour MLP's pixel input, as in training: the masked RGB back in [0, 1].
        let image: Vec<f32> = x[..3 * s * s].iter().map(|v| v * 0.5 + 0.5).collect();
        let mut field = ModelField::new(
            mask_c,
            shape,
            color_feat.map(|f| (self.color.clone(), f)),
            image,
            crop,
            view,
        );
        // On the GPU backend the Fourier series is evaluated where the maps were made.
        #[cfg(feature = "wgpu")]
        if let Some(g) = self.runtime.gpu() {
            field = field.on_gpu(g)?;
        }
        timings.field_ms = ms(t);
        field.timings = timings;
        Ok(field)
    }
}
