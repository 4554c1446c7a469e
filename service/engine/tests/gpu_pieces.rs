//! Pieces apart from the body in the adapter's render (`gpu/render/pieces.rs`) against the
//! CPU renderer's pass (`render.rs` step 1b), a field tabulated on the host. Lavapipe here and
//! in CI; without an adapter the test fails under CI and says so elsewhere.
#![cfg(feature = "wgpu")]

mod common;

use common::gpu;

/// Pieces apart from the body on the adapter (`RenderOptions::drop_apart`: the level `L - 1`
/// inside bits read back, the pieces found on the host, the dropped points sent up): a ball
/// floating in front of the body (and specks around it) leaves the frame as on the CPU (the
/// same stats, the points dropped among them, hits, depths and images), the body drawn
/// behind it and the hand a little apart kept; with lists too small at first (the pass runs
/// again with the grown lists) and over tiles; off, the floater is drawn by both, and a
/// renderer that ran the pass draws it on its next frame.
#[test]
fn pieces_apart_from_the_body_leave_the_adapters_render_as_the_cpus() {
    use glam::Vec3;
    use volcap_engine::field::{FnColor, FnField, OccupancyField, Seeded};
    use volcap_engine::gpu::localize::GpuField;
    use volcap_engine::gpu::render::GpuRenderer;
    use volcap_engine::grid::GridSpec;
    use volcap_engine::pieces::DEFAULT_GAP;
    use volcap_engine::render::{RenderOptions, Renderer};
    let Some(gpu) = gpu() else { return };
    // Gaps in NDC (the side is 2): hand 0.12 (6 % of the side), floater 0.35 (17.5 %).
    let (hand, floater) = (Vec3::new(0.6, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.85));
    let mut balls = vec![(Vec3::ZERO, 0.4), (hand, 0.08), (floater, 0.1)];
    // Specks far from the body, across the rows' words at 129^3.
    for i in 0..6 {
        balls.push((Vec3::new(-0.9 + 0.3 * i as f32, 0.8, -0.6), 0.07));
    }
    // A seed inside the floater off every lattice but level L's at 129^3 (z index 121), where
    // only the final level's seeds step reaches it: with the pass on, it must not list the
    // floater's nodes.
    let field = Seeded {
        field: FnField(move |p: Vec3| {
            let sdf = balls
                .iter()
                .map(|(c, r)| (p - *c).length() - r)
                .fold(f32::INFINITY, f32::min);
            (0.5 - sdf / 0.02).clamp(0.0, 1.0)
        }),
        seeds: vec![hand, floater + Vec3::new(0.0, 0.0, 0.04)],
    };
    let color = FnColor(|p: Vec3| {
        let c = p.clamp(Vec3::splat(-1.0), Vec3::ONE);
        [0.5 + 0.4 * c.x, 0.5, 0.5 + 0.4 * c.z]
    });
    for (res, cap, tile) in [(129, 1 << 18, 0), (65, 16, 0), (65, 1 << 18, 1 << 16)] {
        let spec = GridSpec::from_resolution(res).unwrap();
        let n = spec.n();
        let pts: Vec<Vec3> = (0..spec.len())
            .map(|q| spec.world(spec.unlinear(q)))
            .collect();
        let mut table = vec![0.0f32; spec.len()];
        field.occupancy(&pts, &mut table).unwrap();
        let mut gr = GpuRenderer::new(gpu.clone())
            .unwrap()
            .with_list_capacity(cap);
        if tile > 0 {
            gr = gr.with_tile_floats(tile);
        }
        let column = |p: Vec3| {
            let [i, j, _] = spec.index_of(p).unwrap();
            i + n * j
        };
        let mut on_gpu = Renderer::new();
        for apart in [Some(DEFAULT_GAP), None, Some(DEFAULT_GAP)] {
            let what = format!("{res}^3, lists of {cap}, tiles of {tile}, apart {apart:?}");
            let opts = RenderOptions {
                coarse_level: 4,
                drop_apart: apart,
                ..Default::default()
            };
            let mut cpu = Renderer::new();
            let want = cpu.render(&field, &color, spec, &opts).unwrap();
            let got = on_gpu
                .render_gpu(
                    &mut gr,
                    &GpuField::SeededTable(&table, field.seeds.clone()),
                    &field,
                    &color,
                    spec,
                    &opts,
                )
                .unwrap();
            assert_eq!(got, want, "{what}: stats");
            assert_eq!(got.dropped_apart > 0, apart.is_some(), "{what}: {got:?}");
            assert!(
                on_gpu.coarse_hits() == cpu.coarse_hits(),
                "{what}: coarse hits"
            );
            assert!(on_gpu.hits() == cpu.hits(), "{what}: hits");
            assert!(on_gpu.depth() == cpu.depth(), "{what}: depths");
            assert!(on_gpu.rgba() == cpu.rgba(), "{what}: images");
            // The floater's front (z = 0.95), or the body's behind it (z = 0.4); the hand.
            let z = on_gpu.depth()[column(floater)];
            let want_z = if apart.is_some() { 0.4 } else { 0.95 };
            assert!(
                (z - want_z).abs() < 0.05,
                "{what}: depth {z} at the floater"
            );
            let hand_z = on_gpu.depth()[column(hand)];
            assert!((hand_z - 0.08).abs() < 0.05, "{what}: hand at {hand_z}");
        }
    }
}
