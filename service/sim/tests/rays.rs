//! Ray intervals (the Fourier head's dense supervision) against the dense clothed oracle:
//! along every ray, "inside an interval" must equal `occupancy > 0.5` except within one march
//! step of a transition, at several views of a clothed subject in a procedural pose.

use glam::Vec3;
use std::path::Path;
use std::sync::Arc;
use volcap_sim::oracle::{BRICK, BrickState};
use volcap_sim::rays::{DEFAULT_STEP_M, ray_intervals, ray_intervals_marched};
use volcap_sim::scene::Scene;
use volcap_sim::{HumanAssets, Simulator};

/// A clothed subject in a procedural pose rendered at `size` pixels (frame 5), and its
/// clothed occupancy oracle.
fn clothed_subject(size: usize) -> (Simulator, volcap_sim::oracle::SceneField) {
    let assets = Arc::new(HumanAssets::embedded().unwrap());
    let text = volcap_sim::dataset::scene_text(
        size,
        "[[subject]]\nid = \"a\"\noutfit = \"female_casualsuit01\"\nhair = \"bob02\"\nshoes = \"shoes02\"\n",
        volcap_sim::pose::Style::ALL[1],
        7,
    );
    let scene = Scene::parse(&text, Path::new("t.toml")).unwrap();
    let mut sim = Simulator::new(scene, assets).unwrap();
    sim.render(5).unwrap();
    let field = sim.oracle(0.005);
    (sim, field)
}

#[test]
fn intervals_match_the_dense_oracle_along_rays() {
    let (mut sim, field) = clothed_subject(48);
    let (mut checked, mut inside_pts, mut wrong) = (0usize, 0usize, 0usize);
    let mut max_per_ray = 0;
    for yaw in [0.0f32, 90.0, 210.0] {
        sim.set_view_yaw(yaw);
        let f = sim.render(5).unwrap();
        let rays = ray_intervals(&field.oracle, &f.camera, DEFAULT_STEP_M);
        assert_eq!(rays.offsets.len(), 48 * 48 + 1);
        max_per_ray = max_per_ray.max(rays.max_per_ray());
        let view = f.camera.projector();
        // z step of one march step in NDC (metres per NDC unit along the ray).
        let per_ndc =
            (view.ndc_to_world(Vec3::new(0.0, 0.0, 1.0)) - view.ndc_to_world(Vec3::ZERO)).length();
        let tol = 1.5 * DEFAULT_STEP_M / per_ndc;
        for j in 0..48 {
            for i in 0..48 {
                let iv = rays.pixel(i, j);
                for w in iv {
                    assert!(w[0] < w[1], "empty or reversed interval {w:?}");
                    assert!(w[0].is_finite() && w[1].is_finite());
                }
                for w in iv.windows(2) {
                    assert!(w[0][1] < w[1][0], "intervals overlap or unsorted: {iv:?}");
                }
                let (x, y) = (-1.0 + 2.0 * i as f32 / 47.0, -1.0 + 2.0 * j as f32 / 47.0);
                for k in 0..400 {
                    let z = -1.0 + 2.0 * (k as f32 + 0.5) / 400.0;
                    let truth = field
                        .oracle
                        .occupancy(view.ndc_to_world(Vec3::new(x, y, z)))
                        > 0.5;
                    let near_edge = iv
                        .iter()
                        .any(|w| (w[0] - z).abs() < tol || (w[1] - z).abs() < tol);
                    checked += 1;
                    inside_pts += truth as usize;
                    if !near_edge && truth != rays.inside(i, j, z) {
                        wrong += 1;
                    }
                }
            }
        }
    }
    println!(
        "checked {checked} ray samples, {inside_pts} inside, {wrong} wrong, max {max_per_ray} intervals on a ray"
    );
    assert!(inside_pts > 10_000, "the subject is in view: {inside_pts}");
    assert!(
        (wrong as f64) < 1e-4 * checked as f64,
        "{wrong} of {checked} samples disagree with the oracle"
    );
    assert!(max_per_ray >= 2, "limbs give several intervals per ray");
}

/// The rays agree with the rendered image, not only with the oracle: where the render drew
/// the subject, the nearest inside interval starts at the rendered depth (the visible
/// surface), so the image and its depth supervision describe the same side of the body.
#[test]
fn the_nearest_interval_starts_at_the_rendered_surface() {
    let (mut sim, field) = clothed_subject(64);
    for yaw in [0.0f32, 90.0, 210.0] {
        sim.set_view_yaw(yaw);
        let f = sim.render(5).unwrap();
        let rays = ray_intervals(&field.oracle, &f.camera, DEFAULT_STEP_M);
        let view = f.camera.projector();
        let (mut n, mut far, mut sum) = (0usize, 0usize, 0.0f64);
        for j in 0..64 {
            for i in 0..64 {
                let p = j * 64 + i;
                if f.ids[p] == 0 || f.ids[p] == 255 || !f.depth_m[p].is_finite() {
                    continue;
                }
                let iv = rays.pixel(i, j);
                let Some(near) = iv.iter().map(|w| w[1]).reduce(f32::max) else {
                    continue;
                };
                // Metres along the view direction of the interval's near end.
                let (x, y) = (-1.0 + 2.0 * i as f32 / 63.0, -1.0 + 2.0 * j as f32 / 63.0);
                let d = view
                    .to_screen(view.ndc_to_world(Vec3::new(x, y, near)))
                    .depth;
                let err = (d - f.depth_m[p]).abs();
                n += 1;
                sum += err as f64;
                far += (err > 0.03) as usize;
            }
        }
        println!(
            "yaw {yaw}: {n} drawn pixels, mean |ray entry - rendered depth| {:.4} m, {far} over 3 cm",
            sum / n as f64
        );
        assert!(n > 200);
        assert!(
            (far as f64) < 0.05 * n as f64,
            "yaw {yaw}: {far} of {n} pixels disagree by > 3 cm"
        );
    }
}

/// The march passes the oracle's empty and full bricks without reading them: the intervals
/// are the plain march's bit for bit, from every side, at the dataset's step and a coarse
/// one, and on the close framing where rays graze the grid's edges.
#[test]
fn passing_uniform_bricks_changes_no_interval() {
    let (mut sim, field) = clothed_subject(64);
    let mut intervals = 0;
    for yaw in [0.0f32, 37.0, 90.0, 180.0, 293.0] {
        sim.set_view_yaw(yaw);
        let f = sim.render(5).unwrap();
        for step in [DEFAULT_STEP_M, 0.013] {
            let fast = ray_intervals(&field.oracle, &f.camera, step);
            let plain = ray_intervals_marched(&field.oracle, &f.camera, step);
            assert_eq!(fast, plain, "yaw {yaw}, step {step}");
            intervals += fast.z.len();
        }
    }
    assert!(
        intervals > 2_000,
        "the subject is in view: {intervals} intervals"
    );
}

/// A brick called empty reads 0 and a full one 1 at every point of its closed box (the
/// voxels one beyond it included); all three states occur on a clothed subject.
#[test]
fn bricks_read_what_their_state_says() {
    let (_sim, field) = clothed_subject(16);
    let o = &field.oracle;
    let (lo, hi) = o.bounds();
    let bricks = o.bricks();
    let mut seen = [0usize; 3];
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut unit = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 40) as f32 / (1u64 << 24) as f32
    };
    let voxel = o.voxel_m();
    for _ in 0..200_000 {
        let p = lo + (hi - lo) * Vec3::new(unit(), unit(), unit());
        let u = o.voxel_coords(p);
        let Some(state) = bricks.state_at(u) else {
            continue;
        };
        // A point of the brick's box, on its faces and corners too.
        let b = (u / BRICK as f32).floor();
        let mut snap = |c: f32, b: f32| match (unit() * 4.0) as u32 {
            0 => b * BRICK as f32,
            1 => (b + 1.0) * BRICK as f32,
            _ => c,
        };
        let q = Vec3::new(snap(u.x, b.x), snap(u.y, b.y), snap(u.z, b.z));
        let occ = o.occupancy(lo + q * voxel);
        match state {
            BrickState::Empty => assert_eq!(occ, 0.0, "empty brick reads {occ} at {q}"),
            BrickState::Full => assert!(occ > 0.999, "full brick reads {occ} at {q}"),
            BrickState::Mixed => {}
        }
        seen[state as usize] += 1;
    }
    assert!(
        seen.iter().all(|&n| n > 100),
        "empty / full / mixed seen {seen:?}"
    );
}
