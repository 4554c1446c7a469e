//! Turntable sheets: a model's field rendered mesh-free at four yaws above the oracle's from
//! the same views.

use super::Case;
use super::framing::{ToCamera, occupancy_in_frame};
use anyhow::{Context, anyhow};
use glam::Vec3;
use std::path::Path;
use volcap_engine::OccupancyField;
use volcap_engine::grid::GridSpec;
use volcap_engine::model::{ModelView, Models};

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
