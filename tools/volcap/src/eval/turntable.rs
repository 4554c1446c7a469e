//! Turntable sheets: a model's field rendered mesh-free at four yaws above the oracle's from
//! the same views; the colour error of the turned views against the oracle's.

use super::Case;
use super::framing::{ToCamera, occupancy_in_frame};
use anyhow::{Context, anyhow};
use glam::Vec3;
use std::path::Path;
use volcap_engine::OccupancyField;
use volcap_engine::grid::GridSpec;
use volcap_engine::model::{ModelField, ModelView, Models};

/// The oracle (occupancy and colour) seen through a model field's render view: render NDC
/// -> the field's crop NDC -> input NDC -> world. Renders the truth from the same views.
struct OracleInView<'a> {
    oracle: &'a volcap_sim::oracle::SceneField,
    field: &'a volcap_engine::model::ModelField,
    /// Model input NDC -> the frame camera's (the truth moved into the model's depth frame
    /// and proportions; see `eval::ToCamera`).
    to_cam: ToCamera,
}

impl OracleInView<'_> {
    fn moved(&self, points: &[Vec3]) -> Vec<Vec3> {
        points
            .iter()
            .map(|p| {
                self.to_cam
                    .apply(self.field.crop.to_input(self.field.to_crop(*p)))
            })
            .collect()
    }
}

impl OccupancyField for OracleInView<'_> {
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), volcap_engine::FieldError> {
        // What the frame shows (the truth the reconstruction is scored against).
        occupancy_in_frame(self.oracle, &self.moved(points), out)
    }
}

impl volcap_engine::ColorField for OracleInView<'_> {
    fn color(
        &self,
        points: &[Vec3],
        out: &mut [[f32; 3]],
    ) -> Result<(), volcap_engine::FieldError> {
        self.oracle.color(&self.moved(points), out)
    }
}

/// Turntable yaws.
pub const TURNTABLE_YAWS: [f32; 4] = [0.0, 90.0, 180.0, 270.0];

/// A sheet of mesh-free renders (shaded, grey background) of one case: the model's field at
/// yaw 0/90/180/270 above the oracle's from the same views (the oracle where the frame shows
/// it, seen through `to_cam`: the model's depth frame and proportions).
pub(super) fn turntable(
    models: &Models,
    c: &Case,
    res: usize,
    to_cam: ToCamera,
    apart: Option<f32>,
    path: &Path,
) -> anyhow::Result<()> {
    use volcap_engine::render::{RenderOptions, Renderer};
    let spec = GridSpec::from_resolution(res)?;
    let s = c.size;
    let mut info = volcap_engine::model::FrameInfo::default();
    let (img, prob, crop) = models
        .prepare(&c.rgb, s, s, &mut info)
        .map_err(|e| anyhow!("the turntable image: {e}"))?;
    let opts = RenderOptions {
        background: [0.85, 0.85, 0.85, 1.0],
        shade: true,
        drop_apart: apart,
        ..Default::default()
    };
    let n = spec.n() as u32;
    let mut sheet = image::RgbaImage::new(n * TURNTABLE_YAWS.len() as u32, 2 * n);
    let mut r = Renderer::new();
    for (col, yaw) in TURNTABLE_YAWS.iter().enumerate() {
        let view = ModelView {
            yaw_deg: *yaw,
            ..Default::default()
        };
        let field = models.encode(&img, &prob, crop, view)?;
        let truth = OracleInView {
            oracle: &c.oracle,
            field: &field,
            to_cam,
        };
        for (row, (occ, colors)) in [
            (
                &field as &dyn OccupancyField,
                &field as &dyn volcap_engine::ColorField,
            ),
            (&truth, &truth),
        ]
        .into_iter()
        .enumerate()
        {
            r.render(occ, colors, spec, &opts)?;
            let tile = image::RgbaImage::from_raw(n, n, r.rgba().to_vec())
                .ok_or_else(|| anyhow!("render buffer size"))?;
            image::imageops::overlay(
                &mut sheet,
                &tile,
                (col as u32 * n) as i64,
                (row as u32 * n) as i64,
            );
        }
    }
    sheet
        .save(path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Yaws of the colour columns: the input view first (where every model takes the input's
/// pixels: the floor that the input's lighting and the surfaces' misfit leave), the side and
/// the back.
pub const COLOUR_YAWS: [f32; 3] = [0.0, 90.0, 180.0];

/// Per channel, the least-squares gain `g` with `g * truth ~ model` over the pixels both
/// renders show (the input's exposure and light tint over the oracle's albedo, read at the
/// input view), clamped to [0.05, 20]; 1 where no pixel is shared.
fn exposure_gain(
    model: &volcap_engine::render::Renderer,
    truth: &volcap_engine::render::Renderer,
) -> [f64; 3] {
    let (mut mt, mut tt) = ([0.0f64; 3], [0.0f64; 3]);
    for (i, (hm, ht)) in model.hits().iter().zip(truth.hits()).enumerate() {
        if *hm >= 0 && *ht >= 0 {
            for ch in 0..3 {
                let (m, t) = (
                    f64::from(model.rgba()[i * 4 + ch]),
                    f64::from(truth.rgba()[i * 4 + ch]),
                );
                mt[ch] += m * t;
                tt[ch] += t * t;
            }
        }
    }
    std::array::from_fn(|ch| {
        if tt[ch] > 0.0 {
            (mt[ch] / tt[ch]).clamp(0.05, 20.0)
        } else {
            1.0
        }
    })
}

/// Mean absolute RGB difference (0-1, the three channels averaged) between a model's
/// unshaded render and the truth's at `gain` ([`exposure_gain`]; capped at white) over the
/// pixels where both show a surface; NaN where none does.
fn l1_where_both(
    model: &volcap_engine::render::Renderer,
    truth: &volcap_engine::render::Renderer,
    gain: [f64; 3],
) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0u64);
    for (i, (hm, ht)) in model.hits().iter().zip(truth.hits()).enumerate() {
        if *hm >= 0 && *ht >= 0 {
            for (ch, g) in gain.iter().enumerate() {
                let t = (f64::from(truth.rgba()[i * 4 + ch]) * g).min(255.0);
                sum += (f64::from(model.rgba()[i * 4 + ch]) - t).abs();
            }
            n += 3;
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        sum / (255.0 * n as f64)
    }
}

/// The colour error of a model's views (`volcap eval`'s colour columns): the field encoded
/// over yaw 0, 90 and 180 ([`COLOUR_YAWS`]) and rendered mesh-free, unshaded, at `res`,
/// against the oracle's colours from the same views, on the pixels both show: `[front, side,
/// back, back with the input's colours]`, the last the same back view with every point
/// taking the input pixel it projects to (no colour networks: the baseline they must beat).
/// The oracle's colours are albedo and the input is lit: the truth is compared at the
/// input's exposure, its albedo times the per-channel gain that best maps it onto the input
/// view's pixels ([`exposure_gain`]), the colour the back would have in the input's light on
/// average (the front's error is then what the light's shading and the surfaces' misfit
/// leave). Colour errors where the two surfaces differ (a missing hand) count as they look.
/// `front` is the frame's field over the input view (as `volcap eval` scored it); the turned
/// ones are encoded from the frame as `Models::prepare` gives it: the letterboxed image, the
/// person's mask and its crop.
pub(super) fn colour_errors(
    models: &Models,
    c: &Case,
    front: &ModelField,
    (img, prob, crop): (&[f32], &[f32], volcap_engine::model::preprocess::Crop),
    res: usize,
    to_cam: ToCamera,
    apart: Option<f32>,
) -> anyhow::Result<[f64; 4]> {
    use volcap_engine::render::{RenderOptions, Renderer};
    let spec = GridSpec::from_resolution(res)?;
    let opts = RenderOptions {
        shade: false,
        drop_apart: apart,
        ..Default::default()
    };
    let (mut model, mut truth) = (Renderer::new(), Renderer::new());
    // The field and the oracle seen through its view, both rendered.
    let both =
        |field: &ModelField, model: &mut Renderer, truth: &mut Renderer| -> anyhow::Result<()> {
            let oracle = OracleInView {
                oracle: &c.oracle,
                field,
                to_cam,
            };
            truth.render(&oracle, &oracle, spec, &opts)?;
            model.render(field, field, spec, &opts)?;
            Ok(())
        };
    let mut out = [f64::NAN; 4];
    both(front, &mut model, &mut truth)?;
    let gain = exposure_gain(&model, &truth);
    out[0] = l1_where_both(&model, &truth, gain);
    for (i, yaw) in COLOUR_YAWS.iter().enumerate().skip(1) {
        let view = ModelView {
            yaw_deg: *yaw,
            ..Default::default()
        };
        let field = models.encode(img, prob, crop, view)?;
        both(&field, &mut model, &mut truth)?;
        out[i] = l1_where_both(&model, &truth, gain);
        if i + 1 == COLOUR_YAWS.len() {
            let plain = field.without_color_nets();
            model.render(&plain, &plain, spec, &opts)?;
            out[3] = l1_where_both(&model, &truth, gain);
        }
    }
    Ok(out)
}
