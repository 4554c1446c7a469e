//! `volcap eval`'s surface distances: Chamfer and P2S of a reconstruction against the
//! ground-truth mesh where the frame shows them, and both split by body part.

use super::framing::{ToCamera, in_frame};
use volcap_engine::mesh::Mesh;
use volcap_engine::metrics::{TriangleIndex, chamfer, sample_surface};

/// Chamfer and point-to-surface distance (cm) of a mesh in the model's crop NDC against
/// the ground-truth world mesh, both where the frame shows them (10,000 samples each), and
/// with `parts`, per body part the mean distance from the true surface's samples of that
/// part to the mesh (cm, NaN for a part not shown) and the part's share of the P2S
/// ([`super::ImageRow::part_p2s_cm`]); `None` for an empty surface.
pub(super) fn surface_distances(
    mut mesh: Mesh,
    crop: volcap_engine::model::preprocess::Crop,
    to_cam: ToCamera,
    oracle: &volcap_sim::oracle::SceneField,
    gt_mesh: &Mesh,
    parts: Option<&volcap_sim::parts::PartLabeler>,
) -> Option<(f64, f64, [f64; 6], [f64; 6])> {
    if mesh.triangles.is_empty() {
        return None;
    }
    let cam = oracle.camera.projector();
    for v in &mut mesh.vertices {
        *v = cam.ndc_to_world(to_cam.apply(crop.to_input(*v)));
    }
    // Both surfaces where the frame shows them (a no-op for a person wholly in the frame).
    let shown = |p: &glam::DVec3| in_frame(cam.world_to_ndc(p.as_vec3()));
    let pred: Vec<_> = sample_surface(&mesh, 10_000, 1)
        .into_iter()
        .filter(shown)
        .collect();
    let gt: Vec<_> = sample_surface(gt_mesh, 10_000, 2)
        .into_iter()
        .filter(shown)
        .collect();
    if pred.is_empty() {
        return None;
    }
    // The index of a sample's part in `Part::ALL` (torso for an unknown one).
    let part_of = |l: &volcap_sim::parts::PartLabeler, p: glam::DVec3| {
        let part = l.label(p);
        volcap_sim::parts::Part::ALL
            .iter()
            .position(|x| *x == part)
            .unwrap_or(1)
    };
    // Completeness per part: each true sample's distance to the reconstruction.
    let mut sum = [0.0f64; 6];
    let mut n = [0usize; 6];
    if let Some(l) = parts {
        let index = TriangleIndex::of_mesh(&mesh);
        for p in &gt {
            if let Some((_, _, _, d)) = index.nearest(*p) {
                let i = part_of(l, *p);
                sum[i] += d;
                n[i] += 1;
            }
        }
    }
    let part_cm = std::array::from_fn(|i| {
        if n[i] == 0 {
            f64::NAN
        } else {
            sum[i] / n[i] as f64 * 100.0
        }
    });
    // Accuracy per part: each reconstructed sample's distance to the true surface, summed
    // by the part of the body vertex nearest it (over all samples: the shares add up to
    // the P2S).
    let truth_index = TriangleIndex::of_mesh(gt_mesh);
    let mut p2s_sum = 0.0f64;
    let mut share = [0.0f64; 6];
    for p in &pred {
        let d = truth_index.nearest(*p).map_or(f64::INFINITY, |n| n.3);
        p2s_sum += d;
        if let Some(l) = parts {
            share[part_of(l, *p)] += d;
        }
    }
    let n_pred = pred.len() as f64;
    let part_p2s_cm = share.map(|v| {
        if parts.is_some() {
            v / n_pred * 100.0
        } else {
            f64::NAN
        }
    });
    Some((
        chamfer(&pred, &gt) * 100.0,
        p2s_sum / n_pred * 100.0,
        part_cm,
        part_p2s_cm,
    ))
}
