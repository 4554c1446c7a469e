//! `volcap eval`'s surface distances: Chamfer and P2S of a reconstruction against the
//! ground-truth mesh where the frame shows them, and both split by body part.

use super::framing::{ToCamera, in_frame};
use glam::DVec3;
use volcap_engine::mesh::Mesh;
use volcap_engine::metrics::{TriangleIndex, chamfer, sample_surface};

/// A reconstruction's distances to the truth (cm), [`surface_distances`]'s answer.
#[derive(Debug, Clone, Copy)]
pub(super) struct Distances {
    pub chamfer_cm: f64,
    pub p2s_cm: f64,
    /// Per body part ([`super::ImageRow::part_cm`]); NaN without part labels.
    pub part_cm: [f64; 6],
    /// Per body part, the share of the P2S ([`super::ImageRow::part_p2s_cm`]).
    pub part_p2s_cm: [f64; 6],
    /// Per body part, the share of its true samples within [`SHOWN_WITHIN_M`] of the
    /// reconstruction ([`super::ImageRow::part_shown`]).
    pub part_shown: [f64; 6],
    /// The Chamfer distance of the reconstruction turned around in depth (its samples
    /// reflected through the plane across the view axis at their mean depth): the same
    /// silhouette with front and back swapped, i.e. for a near-symmetric body the person
    /// facing the other way. Lower than `chamfer_cm` on a *facing error*
    /// ([`super::ImageRow::facing_error`]).
    pub reversed_chamfer_cm: f64,
}

/// How near the reconstruction a true surface sample must be to count as shown
/// ([`Distances::part_shown`]): about a hand's thickness, so a hand reconstructed as a stub at
/// the wrist shows its wrist and not its fingers, and one in place shows nearly all of it.
pub(super) const SHOWN_WITHIN_M: f64 = 0.02;

/// Chamfer and point-to-surface distance (cm) of a mesh in the model's crop NDC against
/// the ground-truth world mesh, both where the frame shows them (10,000 samples each), and
/// with `parts`, per body part the mean distance from the true surface's samples of that
/// part to the mesh (cm, NaN for a part not shown) and the part's share of the P2S
/// ([`super::ImageRow::part_p2s_cm`]); the Chamfer distance of the reconstruction turned
/// around in depth ([`Distances::reversed_chamfer_cm`]); `None` for an empty surface.
pub(super) fn surface_distances(
    mut mesh: Mesh,
    crop: volcap_engine::model::preprocess::Crop,
    to_cam: ToCamera,
    oracle: &volcap_sim::oracle::SceneField,
    gt_mesh: &Mesh,
    parts: Option<&volcap_sim::parts::PartLabeler>,
) -> Option<Distances> {
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
    let (part_cm, part_shown) = match parts {
        Some(l) => completeness(&gt, &mesh, |p| part_of(l, p)),
        None => ([f64::NAN; 6], [f64::NAN; 6]),
    };
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
    let reversed = reversed_in_depth(&pred, &cam);
    Some(Distances {
        chamfer_cm: chamfer(&pred, &gt) * 100.0,
        p2s_cm: p2s_sum / n_pred * 100.0,
        part_cm,
        part_p2s_cm,
        part_shown,
        reversed_chamfer_cm: chamfer(&reversed, &gt) * 100.0,
    })
}

/// Per part (`part_of`: an index into `Part::ALL`), over the true samples `gt`: the mean
/// distance (cm) to `mesh` and the share within [`SHOWN_WITHIN_M`]; NaN for a part without
/// samples.
fn completeness(
    gt: &[DVec3],
    mesh: &Mesh,
    part_of: impl Fn(DVec3) -> usize,
) -> ([f64; 6], [f64; 6]) {
    let mut sum = [0.0f64; 6];
    let mut near = [0usize; 6];
    let mut n = [0usize; 6];
    let index = TriangleIndex::of_mesh(mesh);
    for p in gt {
        if let Some((_, _, _, d)) = index.nearest(*p) {
            let i = part_of(*p).min(5);
            sum[i] += d;
            near[i] += usize::from(d <= SHOWN_WITHIN_M);
            n[i] += 1;
        }
    }
    let per_sample = |v: [f64; 6], scale: f64| -> [f64; 6] {
        std::array::from_fn(|i| {
            if n[i] == 0 {
                f64::NAN
            } else {
                v[i] / n[i] as f64 * scale
            }
        })
    };
    (
        per_sample(sum, 100.0),
        per_sample(near.map(|c| c as f64), 1.0),
    )
}

/// How far beyond a true surface point [`seen_surface`] looks for the outside (metres).
pub(super) const SEEN_REACH_M: f32 = 0.01;

/// The part of the clothed ground-truth mesh a view can show: the triangles whose centroid
/// has the outside within [`SEEN_REACH_M`] along one of 14 directions (the axes and the
/// diagonals), read from the occupancy oracle. What it leaves out is the body under the
/// clothes (a garment shell closes the oracle's volume over it), which no camera sees and
/// `dataset::clothed_surface` holds; a body under cloth closer than the reach stays
/// (`volcap eval --truth-surface seen`).
pub(super) fn seen_surface(mut gt: Mesh, oracle: &volcap_sim::oracle::Oracle) -> Mesh {
    let d = 1.0 / 3f32.sqrt();
    let dirs: [glam::Vec3; 14] = [
        glam::Vec3::X,
        glam::Vec3::NEG_X,
        glam::Vec3::Y,
        glam::Vec3::NEG_Y,
        glam::Vec3::Z,
        glam::Vec3::NEG_Z,
        glam::Vec3::new(d, d, d),
        glam::Vec3::new(d, d, -d),
        glam::Vec3::new(d, -d, d),
        glam::Vec3::new(d, -d, -d),
        glam::Vec3::new(-d, d, d),
        glam::Vec3::new(-d, d, -d),
        glam::Vec3::new(-d, -d, d),
        glam::Vec3::new(-d, -d, -d),
    ];
    let vertices = &gt.vertices;
    gt.triangles.retain(|t| {
        let c = t
            .iter()
            .fold(glam::Vec3::ZERO, |s, i| s + vertices[*i as usize])
            / 3.0;
        dirs.iter()
            .any(|d| oracle.occupancy(c + *d * SEEN_REACH_M) <= 0.5)
    });
    gt
}

/// `points` reflected through the plane across the camera's view direction at their mean
/// depth: front and back swapped, the silhouette kept (exactly for the dataset's
/// weak-perspective camera; about the central ray for a pinhole one).
fn reversed_in_depth(points: &[DVec3], cam: &volcap_sim::camera::Projector) -> Vec<DVec3> {
    let forward = cam.forward().as_dvec3();
    let n = points.len().max(1) as f64;
    let mean = points.iter().fold(DVec3::ZERO, |s, p| s + *p) / n;
    let mean_depth = mean.dot(forward);
    points
        .iter()
        .map(|p| *p - 2.0 * (p.dot(forward) - mean_depth) * forward)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use volcap_sim::camera::{Camera, Projection};

    /// A camera looking along an oblique horizontal direction (not an axis), weak perspective.
    fn camera() -> volcap_sim::camera::Projector {
        Camera {
            width: 256,
            height: 256,
            eye: glam::Vec3::new(2.0, 1.0, 3.0),
            target: glam::Vec3::new(0.1, 1.0, 0.2),
            projection: Projection::WeakPerspective { height_m: 2.3 },
            near: 0.5,
            far: 8.0,
        }
        .projector()
    }

    /// A person-like point set with a front: a slab with a nose on one side only.
    fn asymmetric(cam: &volcap_sim::camera::Projector) -> Vec<DVec3> {
        let mut p = vec![];
        for i in 0..20 {
            for j in 0..20 {
                let (x, y) = (-0.3 + 0.03 * i as f32, -0.5 + 0.05 * j as f32);
                for z in [0.0f32, 0.04] {
                    p.push(cam.ndc_to_world(glam::Vec3::new(x, y, 0.3 + z)).as_dvec3());
                }
            }
        }
        for k in 0..100 {
            let z = 0.04 + 0.001 * k as f32;
            p.push(
                cam.ndc_to_world(glam::Vec3::new(0.0, 0.2, 0.3 + z))
                    .as_dvec3(),
            );
        }
        p
    }

    /// A hand that is half there: its samples within 2 cm count as shown, the far half
    /// does not, and the mean distance is led by the far half; a part with no samples is NaN.
    #[test]
    fn completeness_counts_a_part_as_shown_where_it_lies_within_two_centimetres() {
        let mesh = Mesh {
            vertices: vec![
                glam::Vec3::new(-1.0, -1.0, 0.0),
                glam::Vec3::new(1.0, -1.0, 0.0),
                glam::Vec3::new(0.0, 1.0, 0.0),
            ],
            triangles: vec![[0, 1, 2]],
            colors: None,
        };
        // Torso (1): on the surface; hands (3): half at 1 cm, half at 10 cm.
        let mut gt = vec![];
        for i in 0..40 {
            let x = -0.4 + 0.02 * i as f64;
            gt.push(DVec3::new(x, 0.0, 0.0));
            gt.push(DVec3::new(x, -0.2, if i < 20 { 0.01 } else { 0.10 }));
        }
        let part = |p: DVec3| if p.y < -0.1 { 3 } else { 1 };
        let (cm, shown) = completeness(&gt, &mesh, part);
        assert!(
            cm[1].abs() < 1e-9 && (shown[1] - 1.0).abs() < 1e-12,
            "{cm:?} {shown:?}"
        );
        assert!((cm[3] - 5.5).abs() < 1e-6, "{cm:?}");
        assert!((shown[3] - 0.5).abs() < 1e-12, "{shown:?}");
        for i in [0, 2, 4, 5] {
            assert!(
                cm[i].is_nan() && shown[i].is_nan(),
                "part {i}: {cm:?} {shown:?}"
            );
        }
    }

    #[test]
    fn reversing_in_depth_keeps_the_silhouette_and_the_mean_depth_and_undoes_itself() {
        let cam = camera();
        let p = asymmetric(&cam);
        let r = reversed_in_depth(&p, &cam);
        let mean_z = |v: &[DVec3]| {
            v.iter()
                .map(|q| cam.world_to_ndc(q.as_vec3()).z as f64)
                .sum::<f64>()
                / v.len() as f64
        };
        assert!((mean_z(&p) - mean_z(&r)).abs() < 1e-5);
        let mut moved = 0;
        for (a, b) in p.iter().zip(&r) {
            let (na, nb) = (cam.world_to_ndc(a.as_vec3()), cam.world_to_ndc(b.as_vec3()));
            assert!(
                (na.x - nb.x).abs() < 1e-4 && (na.y - nb.y).abs() < 1e-4,
                "{na} {nb}"
            );
            moved += ((na.z - nb.z).abs() > 1e-3) as usize;
        }
        assert!(moved > p.len() / 2, "front and back swapped: {moved}");
        let back = reversed_in_depth(&r, &cam);
        for (a, b) in p.iter().zip(&back) {
            assert!((*a - *b).length() < 1e-5, "{a} {b}");
        }
    }

    #[test]
    fn a_reconstruction_facing_the_other_way_is_nearer_the_truth_reversed() {
        let cam = camera();
        let truth = asymmetric(&cam);
        let turned = reversed_in_depth(&truth, &cam);
        // Turned around: far as it is, at zero reversed.
        assert!(chamfer(&turned, &truth) > 1e-3);
        assert!(chamfer(&reversed_in_depth(&turned, &cam), &truth) < 1e-6);
        // Facing right: the reversal only moves it away.
        assert!(chamfer(&reversed_in_depth(&truth, &cam), &truth) > chamfer(&truth, &truth));
    }
}
