//! Marching cubes on localized grids, PLY and GLB export read back.

use volcap_engine::analytic::AnalyticScene;
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{Localizer, Method};
use volcap_engine::mesh::{Mesh, marching_cubes};
use volcap_engine::metrics::{chamfer, point_to_surface, sample_surface};

fn mesh_of(name: &str, level: u32, m: Method) -> (AnalyticScene, Mesh) {
    let scene = AnalyticScene::by_name(name).unwrap();
    let spec = GridSpec::new(level).unwrap();
    let mut g = Grid::new(spec);
    Localizer::new().run(m, &scene, spec, 3, &mut g).unwrap();
    (scene, marching_cubes(&g))
}

#[test]
fn hierarchical_mesh_is_closed_and_on_the_surface() {
    for name in ["torus", "two-bodies", "capsule-human"] {
        let (scene, m) = mesh_of(name, 7, Method::Hierarchical);
        assert_eq!(m.boundary_edges(), 0, "{name}");
        assert!(m.volume() > 0.0, "{name}: inward-facing");
        // Vertices lie on the analytic surface to a fraction of a voxel.
        let worst = m
            .vertices
            .iter()
            .map(|v| scene.sdf(v.as_dvec3()).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 0.5 * GridSpec::new(7).unwrap().spacing() as f64,
            "{name}: {worst}"
        );
    }
}

#[test]
fn chamfer_and_p2s_between_hierarchical_and_dense_meshes_are_tiny() {
    let (_, a) = mesh_of("capsule-human", 7, Method::Hierarchical);
    let (_, b) = mesh_of("capsule-human", 7, Method::Dense);
    let pa = sample_surface(&a, 4000, 1);
    let pb = sample_surface(&b, 4000, 2);
    // Against the sampling noise floor: two samplings of the same (dense) mesh.
    let pb2 = sample_surface(&b, 4000, 3);
    let floor = chamfer(&pb, &pb2);
    let got = chamfer(&pa, &pb);
    assert!(got < 1.2 * floor, "chamfer {got} vs sampling floor {floor}");
    assert!(
        point_to_surface(&pa, &b) < 1e-4,
        "identical binarization and evaluated values near the surface"
    );
    // A shifted mesh is measured as shifted.
    let mut c = b.clone();
    for v in &mut c.vertices {
        v.z += 0.05;
    }
    let d = point_to_surface(&pa, &c);
    assert!(d > 0.005 && d < 0.05, "{d}");
}

#[test]
fn glb_reads_back_with_the_gltf_crate() {
    let (scene, mut m) = mesh_of("sphere", 5, Method::Hierarchical);
    m.paint(&scene).unwrap();
    let glb = m.to_glb();
    let g = gltf::Gltf::from_slice(&glb).expect("valid glb");
    let blob = g.blob.clone().expect("binary chunk");
    let mesh = g.meshes().next().unwrap();
    let prim = mesh.primitives().next().unwrap();
    let reader = prim.reader(|_| Some(&blob));
    let pos: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
    assert_eq!(pos.len(), m.vertices.len());
    // Exported y is up: y flipped.
    assert_eq!(pos[0], [m.vertices[0].x, -m.vertices[0].y, m.vertices[0].z]);
    let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
    assert_eq!(idx.len(), m.triangles.len() * 3);
    assert!(idx.iter().all(|&i| (i as usize) < pos.len()));
    let cols: Vec<[u8; 4]> = reader.read_colors(0).unwrap().into_rgba_u8().collect();
    assert_eq!(cols.len(), pos.len());
}

#[test]
fn ply_header_and_body_sizes_match() {
    let (scene, mut m) = mesh_of("torus", 5, Method::Hierarchical);
    m.paint(&scene).unwrap();
    let mut buf = Vec::new();
    m.write_ply(&mut buf).unwrap();
    let end = buf.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let head = std::str::from_utf8(&buf[..end]).unwrap();
    assert!(head.contains(&format!("element vertex {}", m.vertices.len())));
    assert!(head.contains(&format!("element face {}", m.triangles.len())));
    assert_eq!(
        buf.len() - end,
        m.vertices.len() * 15 + m.triangles.len() * 13
    );
    // First vertex reads back (y flipped).
    let x = f32::from_le_bytes(buf[end..end + 4].try_into().unwrap());
    let y = f32::from_le_bytes(buf[end + 4..end + 8].try_into().unwrap());
    assert_eq!((x, y), (m.vertices[0].x, -m.vertices[0].y));
}

/// A body, a hand a little apart from it and a floater far from it: the mesh outputs' pass
/// (`pieces::DEFAULT_GAP`) leaves the floater out of the mesh and keeps the body and the hand,
/// through localization and marching cubes.
#[test]
fn the_mesh_outputs_leave_a_floater_out_and_keep_a_hand() {
    use glam::Vec3;
    use volcap_engine::field::{FieldError, OccupancyField};
    use volcap_engine::pieces::{DEFAULT_GAP, drop_apart, gap_points};
    struct Balls(Vec<(Vec3, f32)>);
    impl OccupancyField for Balls {
        fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
            for (o, p) in out.iter_mut().zip(points) {
                let sdf = self
                    .0
                    .iter()
                    .map(|(c, r)| (*p - *c).length() - r)
                    .fold(f32::INFINITY, f32::min);
                *o = (0.5 - sdf / 0.02).clamp(0.0, 1.0);
            }
            Ok(())
        }
    }
    let (hand, floater) = (Vec3::new(0.6, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.88));
    // Gaps in NDC (the side is 2): hand 0.15 (7.5 % of the side), floater 0.42 (21 %).
    let field = Balls(vec![(Vec3::ZERO, 0.4), (hand, 0.05), (floater, 0.06)]);
    let spec = GridSpec::new(6).unwrap();
    let mut g = Grid::new(spec);
    Localizer::new()
        .run(Method::Dense, &field, spec, 3, &mut g)
        .unwrap();
    let near = |m: &Mesh, c: Vec3| m.vertices.iter().any(|v| (*v - c).length() < 0.1);
    let before = marching_cubes(&g);
    assert!(near(&before, hand) && near(&before, floater));
    let s = drop_apart(&mut g, [gap_points(spec, DEFAULT_GAP); 3]);
    assert_eq!((s.components, s.dropped), (3, 1));
    let after = marching_cubes(&g);
    assert!(near(&after, hand), "the hand is kept");
    assert!(!near(&after, floater), "the floater is left out");
    assert_eq!(after.boundary_edges(), 0);
    let lost = before.volume() - after.volume();
    let ball = 4.0 / 3.0 * std::f64::consts::PI * 0.06f64.powi(3);
    assert!((lost - ball).abs() < 0.3 * ball, "{lost} vs {ball}");
}
