//! The framing of the evaluation's images and the truth as the frame shows it: the camera of
//! each framing, the map from a model's input NDC to the frame camera's ([`ToCamera`]: the body
//! depth frame and the training camera's proportions) and the oracle limited to the frame.

use super::Case;
use glam::Vec3;
use rand::Rng;
use volcap_engine::OccupancyField;
use volcap_engine::model::DepthFrame;

#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    Whole,
    Upper,
}

/// Top of the frame (metres above the floor) in the `upper` framing: above the tallest
/// subject's head.
pub(super) const UPPER_TOP_M: f32 = 1.95;
/// Metres the frame's height spans in the `upper` framing, drawn per pose: the lower edge
/// then lies 0.65 to 0.95 m above the floor.
pub(super) const UPPER_SPAN_M: (f32, f32) = (1.0, 1.3);

impl Framing {
    /// (metres spanned by the image height, look-at height) of one pose's camera.
    pub(super) fn camera(self, r: &mut impl Rng) -> (f32, f32) {
        match self {
            Framing::Whole => (
                volcap_sim::dataset::WHOLE_HEIGHT_M,
                volcap_sim::dataset::WHOLE_LOOK_AT_Y,
            ),
            Framing::Upper => {
                let h = r.random_range(UPPER_SPAN_M.0..UPPER_SPAN_M.1);
                (h, UPPER_TOP_M - 0.5 * h)
            }
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Framing::Whole => "whole",
            Framing::Upper => "upper",
        }
    }
}

/// Whether an input-NDC point lies inside the frame (the part of the world the image shows).
pub(super) fn in_frame(n: Vec3) -> bool {
    n.x.abs() <= 1.0 && n.y.abs() <= 1.0
}

/// Input-NDC depth by which the truth is moved into `frame`: the truth's mean occupied depth
/// (`RayIntervals::mean_depth`, the trainer's `fourier.body_depth_centre`) for `body`, 0 for
/// `camera`. Under a weak-perspective crop the image does not show where the camera stood
/// along depth; a body-frame model is judged on everything else.
pub(super) fn depth_shift(frame: DepthFrame, c: &Case) -> f32 {
    match frame {
        DepthFrame::Camera => 0.0,
        DepthFrame::Body => c.rays.mean_depth().unwrap_or(0.0),
    }
}

/// From a model's input NDC to the frame camera's NDC. A model's depth keeps the training
/// camera's proportions (`NDC_HALF_EXTENT_M`: 1.15 m across and 1.5 m deep per NDC unit, the
/// crop scaling all three alike); a frame spanning `h` metres has `h / 2` across per unit but
/// the same depth range, so the model's depth is scaled by `h / 2.3` (1 for the dataset's
/// framing), then moved by [`depth_shift`]. The ground-truth rows are already in the frame's
/// own NDC.
#[derive(Debug, Clone, Copy)]
pub(super) struct ToCamera {
    pub dz: f32,
    pub z_scale: f32,
}

impl ToCamera {
    pub(super) fn new(frame: DepthFrame, c: &Case, truth: bool) -> Self {
        Self {
            dz: depth_shift(frame, c),
            z_scale: if truth { 1.0 } else { c.z_scale },
        }
    }

    pub fn apply(self, n: Vec3) -> Vec3 {
        Vec3::new(n.x, n.y, n.z * self.z_scale + self.dz)
    }
}

/// The oracle's occupancy at frame-camera NDC points, empty outside the frame (the truth is
/// what the image shows).
pub(super) fn occupancy_in_frame(
    oracle: &volcap_sim::oracle::SceneField,
    points: &[Vec3],
    out: &mut [f32],
) -> Result<(), volcap_engine::FieldError> {
    oracle.occupancy(points, out)?;
    for (o, p) in out.iter_mut().zip(points) {
        if !in_frame(*p) {
            *o = 0.0;
        }
    }
    Ok(())
}

/// The model's crop-NDC grid, seen by the oracle: crop NDC -> input NDC -> world; empty
/// outside the frame (the truth is what the image shows).
pub(super) struct OracleInCrop<'a> {
    pub oracle: &'a volcap_sim::oracle::SceneField,
    pub crop: volcap_engine::model::preprocess::Crop,
    /// Model input NDC -> the frame camera's ([`ToCamera`]).
    pub to_cam: ToCamera,
}

impl OccupancyField for OracleInCrop<'_> {
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), volcap_engine::FieldError> {
        let moved: Vec<Vec3> = points
            .iter()
            .map(|p| self.to_cam.apply(self.crop.to_input(*p)))
            .collect();
        occupancy_in_frame(self.oracle, &moved, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;
    use std::sync::Arc;
    use volcap_engine::model::NDC_HALF_EXTENT_M;
    use volcap_sim::pose::Style;
    use volcap_sim::scene::Scene;
    use volcap_sim::sim::Simulator;

    const SUBJECT: &str = "[[subject]]\nid = \"t\"\noutfit = \"female_casualsuit01\"\nshoes = \"shoes01\"\nhair = \"ponytail01\"\nskin = \"young_caucasian_female2\"\n";

    /// The simulator's camera of one framing (dataset scene text, embedded assets).
    fn camera(height_m: f32, look_y: f32) -> volcap_sim::camera::Camera {
        let assets = Arc::new(volcap_sim::HumanAssets::embedded().unwrap());
        let text = volcap_sim::dataset::scene_text_framed(
            64,
            SUBJECT,
            volcap_sim::dataset::Motion::new(Style::ALL[0], 1),
            height_m,
            look_y,
            volcap_sim::dataset::STUDIO_LIGHTING,
        );
        let scene = Scene::parse(&text, Path::new("t.toml")).unwrap();
        Simulator::new(scene, assets)
            .unwrap()
            .render(0)
            .unwrap()
            .camera
    }

    /// A model's input NDC, read in the engine's metric (`NDC_HALF_EXTENT_M`), is the world up
    /// to one scale in every framing: equal steps in metres along x, y and depth stay equal
    /// once the frame camera's NDC is taken back through `ToCamera` (without its depth
    /// scale a closer framing would stretch depth, by 2 at half the dataset's span).
    #[test]
    fn model_depth_keeps_the_world_proportions_in_every_framing() {
        for (h, look_y) in [(2.3f32, 0.95f32), (1.15, 1.4), (1.0, 1.45), (1.3, 1.3)] {
            let cam = camera(h, look_y);
            let to = ToCamera {
                dz: 0.07,
                z_scale: h / volcap_sim::dataset::WHOLE_HEIGHT_M,
            };
            let model = |w: Vec3| {
                let n = cam.world_to_ndc(w);
                Vec3::new(n.x, n.y, (n.z - to.dz) / to.z_scale)
            };
            let o = Vec3::new(0.1, look_y - 0.1, 0.05);
            let step = |d: Vec3| ((model(o + d) - model(o)) * NDC_HALF_EXTENT_M).length();
            let (x, y, z) = (
                step(Vec3::X * 0.2),
                step(Vec3::Y * 0.2),
                step(Vec3::Z * 0.2),
            );
            assert!(x > 0.0, "h {h}");
            for v in [y, z] {
                assert!((v - x).abs() < 1e-3 * x, "h {h}: steps {x} {y} {z}");
            }
            // `apply` is the way back.
            let n = cam.world_to_ndc(o);
            assert!((to.apply(model(o)) - n).length() < 1e-5, "h {h}");
        }
    }
}
