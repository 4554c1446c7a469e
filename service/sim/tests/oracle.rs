//! The occupancy oracle against the watertight body alone, and the clothed oracle as an
//! engine field.

use glam::{DVec3, Vec3};
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::sync::Arc;
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{Localizer, Method};
use volcap_engine::metrics::{TriangleIndex, iou};
use volcap_sim::oracle::{Oracle, WorldMesh, winding_number};
use volcap_sim::scene::Scene;
use volcap_sim::subject::{Posed, Subject, SubjectSpec};
use volcap_sim::{HumanAssets, Simulator};

fn posed_body(assets: &HumanAssets, pose: &str) -> Vec<Vec3> {
    let s = Subject::new(assets, &SubjectSpec::default()).unwrap();
    let mut rot = Vec::new();
    if pose == "rest" {
        rot.resize(assets.bones.len(), glam::Mat3::IDENTITY);
    } else {
        volcap_sim::pose::static_pose(assets, pose, &mut rot).unwrap();
    }
    let mut p = Posed::default();
    s.pose(assets, &rot, &mut p);
    p.verts
}

#[test]
fn body_oracle_agrees_with_winding_numbers_and_mesh_volume() {
    let assets = HumanAssets::embedded().unwrap();
    for pose in ["rest", "benchmark"] {
        let verts = posed_body(&assets, pose);
        let tris = &assets.body_tris;
        let oracle = Oracle::build(
            &[WorldMesh {
                verts: &verts,
                tris,
                closed: true,
            }],
            0.005,
        );
        let mesh_vol: f64 = tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| verts[i as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        let rel = (oracle.volume_m3() - mesh_vol).abs() / mesh_vol;
        assert!(
            mesh_vol > 0.04 && mesh_vol < 0.09,
            "{pose}: body volume {mesh_vol} m^3"
        );
        assert!(
            rel < 0.02,
            "{pose}: oracle volume {} vs mesh {mesh_vol} ({:.2}%)",
            oracle.volume_m3(),
            rel * 100.0
        );
        // Random points away from the surface: oracle sign == winding-number sign.
        let index = TriangleIndex::new(
            tris.iter()
                .map(|t| t.map(|i| verts[i as usize].as_dvec3()))
                .collect(),
        );
        let (lo, hi) = verts
            .iter()
            .fold((Vec3::MAX, Vec3::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (mut checked, mut inside) = (0, 0);
        while checked < 600 {
            let p = Vec3::new(
                rng.random_range(lo.x..hi.x),
                rng.random_range(lo.y..hi.y),
                rng.random_range(lo.z..hi.z),
            );
            if index.nearest(p.as_dvec3()).unwrap().3 < 0.012 {
                continue;
            }
            let w = winding_number(p.as_dvec3(), &verts, tris);
            assert!(
                (w - w.round()).abs() < 1e-6,
                "{pose}: winding {w} not integral off the surface"
            );
            assert_eq!(oracle.contains(p), w > 0.5, "{pose}: point {p} winding {w}");
            assert_eq!(
                oracle.occupancy(p) > 0.5,
                w > 0.5,
                "{pose}: smooth occupancy at {p}"
            );
            inside += (w > 0.5) as usize;
            checked += 1;
        }
        assert!(inside > 5, "{pose}: only {inside} interior samples");
        eprintln!(
            "{pose}: oracle volume {:.5} m^3 vs mesh {mesh_vol:.5} m^3 ({:+.2}%), {checked}/{checked} off-surface points agree with winding numbers ({inside} inside)",
            oracle.volume_m3(),
            (oracle.volume_m3() / mesh_vol - 1.0) * 100.0
        );
        assert!(!oracle.contains(DVec3::new(5.0, 5.0, 5.0).as_vec3()));
    }
}

#[test]
fn clothed_oracle_contains_the_body_and_adds_the_garments() {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let scene = Scene::parse(
        "[[subject]]\nid = \"a\"\noutfit = \"male_casualsuit02\"\nhair = \"short02\"\nshoes = \"shoes01\"\n\
         motion = { kind = \"static\", pose = \"rest\" }\n",
        Path::new("t.toml"),
    )
    .unwrap();
    let mut sim = Simulator::new(scene, assets.clone()).unwrap();
    sim.render(0).unwrap();
    let meshes = sim.world_meshes();
    let (closed, _) = &meshes[0];
    let body_only = Oracle::build(&closed[..1], 0.005);
    let field = sim.oracle(0.005);
    assert!(
        field.oracle.volume_m3() > body_only.volume_m3() * 1.05,
        "garments add volume"
    );
    let verts = closed[0].verts;
    let index = TriangleIndex::new(
        closed[0]
            .tris
            .iter()
            .map(|t| t.map(|i| verts[i as usize].as_dvec3()))
            .collect(),
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let (lo, hi) = verts
        .iter()
        .fold((Vec3::MAX, Vec3::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
    for _ in 0..20000 {
        let p = Vec3::new(
            rng.random_range(lo.x..hi.x),
            rng.random_range(lo.y..hi.y),
            rng.random_range(lo.z..hi.z),
        );
        // Away from the surface (the two grids are aligned differently within a voxel).
        if body_only.contains(p) && index.nearest(p.as_dvec3()).unwrap().3 > 0.012 {
            assert!(
                field.oracle.contains(p),
                "body point {p} outside the clothed solid"
            );
        }
    }
}

#[test]
fn human_oracle_runs_through_the_engine_exactly() {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let scene = Scene::parse(
        "[[subject]]\nid = \"a\"\noutfit = \"female_casualsuit01\"\nhair = \"bob02\"\n\
         motion = { kind = \"procedural\", style = \"arms-raised\", seed = 2 }\n",
        Path::new("t.toml"),
    )
    .unwrap();
    let mut sim = Simulator::new(scene, assets).unwrap();
    sim.render(0).unwrap();
    let field = sim.oracle(0.006);
    let spec = GridSpec::new(7).unwrap();
    let mut dense = Grid::new(spec);
    let mut loc = Localizer::new();
    loc.run(Method::Dense, &field, spec, 3, &mut dense).unwrap();
    let inside = dense.binarized().count_ones();
    assert!(
        inside > 5000,
        "the person fills part of the view ({inside} points)"
    );
    // The clothed oracle has features below one grid spacing (hair-card fragments, gaps
    // between fingers): what any coarse-to-fine method may miss is limited to those.
    for coarse in [3, 5] {
        let mut g = Grid::new(spec);
        let st = loc
            .run(Method::Hierarchical, &field, spec, coarse, &mut g)
            .unwrap();
        let i = iou(&g, &dense);
        let comps = volcap_engine::metrics::components(spec, &dense.binarized());
        let got = g.binarized();
        let lost: Vec<usize> = comps
            .iter()
            .filter(|c| !c.iter().any(|&x| got.get(x as usize)))
            .map(|c| c.len())
            .collect();
        eprintln!(
            "coarse {coarse}: iou {i}, {} evaluations of {}, {} components, lost sizes {lost:?}",
            st.evaluations,
            spec.len(),
            comps.len()
        );
        assert!(st.evaluations * 10 < spec.len() as u64);
        assert!(i > 0.999, "{i}");
        assert!(
            lost.iter().all(|&n| n <= 2),
            "lost a component larger than a grid point: {lost:?}"
        );
    }
}

#[test]
fn colour_oracle_returns_the_rendered_surface_colour() {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let scene = Scene::parse(
        "[[subject]]\nid = \"a\"\noutfit = \"male_casualsuit02\"\nskin = \"young_caucasian_male\"\n\
         motion = { kind = \"static\", pose = \"rest\" }\n",
        Path::new("t.toml"),
    )
    .unwrap();
    let mut sim = Simulator::new(scene, assets.clone()).unwrap();
    sim.render(0).unwrap();
    let field = sim.oracle(0.005);
    let meshes = sim.world_meshes();
    let body = &meshes[0].0[0];
    let skin = volcap_sim::raster::Texture::decode(
        &assets.skins["young_caucasian_male"]
            .texture
            .as_ref()
            .unwrap()
            .bytes,
    )
    .unwrap();
    // Face triangles (highest body vertices, not under any garment): the oracle's colour at a
    // triangle centroid is the skin texture at the centroid's uv.
    let mut checked = 0;
    for (t, uvt) in assets.body_tris.iter().zip(&assets.body_uv_tris) {
        let c = t.map(|i| body.verts[i as usize]);
        let centroid = (c[0] + c[1] + c[2]) / 3.0;
        if centroid.y < 1.55 || centroid.z < 0.05 {
            continue;
        }
        let uv = uvt.map(|i| glam::Vec2::from_array(assets.body_uvs[i as usize]));
        let want = skin.sample((uv[0] + uv[1] + uv[2]) / 3.0);
        let got = field.colors.color(centroid);
        for k in 0..3 {
            assert!(
                (got[k] - want[k]).abs() < 1e-3,
                "face colour {got:?} vs texture {want:?}"
            );
        }
        checked += 1;
        if checked == 50 {
            break;
        }
    }
    assert_eq!(checked, 50);
}
