//! The mesh-free renderer on the GPU backend's adapter (`gpu/render.rs`, `render.wgsl`,
//! `display.wgsl`) against the CPU renderer, on every analytic scene tabulated on the host:
//! Mesa's lavapipe here and in CI (`WGPU_BACKEND=vulkan`). Without an adapter the test fails
//! under CI and says so elsewhere.
#![cfg(feature = "wgpu")]

mod common;

use common::{analytic_tables, gpu};

/// The mesh-free renderer with its grid on the adapter (`Renderer::render_gpu`: localization
/// and the culled final level there) against the CPU renderer on every analytic scene, the
/// field tabulated on the host: the same hits (coarse and final), depths, images, evaluation
/// counts and culled nodes; lists too small at first (grown); the levels' rounds predicted
/// from the frame before (frames run again where that fell short); and the display image drawn
/// there within 1/255 of the CPU's on >= 99.9 % of channels, its depth within 1e-5 on >=
/// 99.9 % of pixels.
#[test]
fn the_renderer_on_the_adapter_matches_the_cpu_on_every_analytic_scene() {
    use volcap_engine::gpu::localize::GpuField;
    use volcap_engine::gpu::render::GpuRenderer;
    use volcap_engine::grid::GridSpec;
    use volcap_engine::localize::RoundWaits;
    use volcap_engine::render::{RenderOptions, Renderer};
    let Some(gpu) = gpu() else { return };
    let mut cpu = Renderer::new();
    let mut on_gpu = Renderer::new();
    let (mut close, mut channels) = (0usize, 0usize);
    let (mut antialiased, mut displays) = (0usize, 0usize);
    let timed0 = gpu.counters();
    let (mut depth_off, mut pixels) = (0usize, 0usize);
    // The last row tiles the grid's values over five bindings (as 513^3 on lavapipe): the
    // render's kernels and the display's read them through the tiles.
    // The last two rows predict the levels' conflict rounds from the frame before (one
    // read-back for the levels): the frames go scene after scene, some predictions fall
    // short (the frame run again), some hold; the same frames either way.
    let (per_round, per_frame) = (RoundWaits::PerRound, RoundWaits::PerFrame);
    let counted0 = gpu.counters();
    for (res, cap, tile, waits) in [
        (65, 1 << 18, 0, per_round),
        (129, 1 << 18, 0, per_round),
        (33, 16, 0, per_round),
        (65, 1 << 18, 1 << 16, per_round),
        (65, 1 << 18, 0, per_frame),
        (33, 16, 0, per_frame),
    ] {
        // At 129^3 the levels' conflict rounds go to the adapter 4 at a time (the rounds after
        // the loop converged run over empty lists): the same frames.
        let mut gr = GpuRenderer::new(gpu.clone())
            .unwrap()
            .with_list_capacity(cap)
            .with_rounds_per_wait(if res == 129 { 4 } else { 1 })
            .with_round_waits(waits);
        if tile > 0 {
            gr = gr.with_tile_floats(tile);
        }
        let spec = GridSpec::from_resolution(res).unwrap();
        let tables = analytic_tables(spec);
        // The second option set with the pass over the pieces apart from the body on (it
        // drops nothing here: two-bodies' second body is as large as the first; the next test
        // drops pieces).
        let option_sets = [(false, 3, None), (true, 2, Some(0.1))];
        let mut frames = Vec::new();
        if waits == per_round {
            for t in &tables {
                frames.extend(option_sets.map(|o| (t, o)));
            }
        } else {
            for o in option_sets {
                frames.extend(tables.iter().map(|t| (t, o)));
                frames.extend(tables.last().map(|t| (t, o)));
            }
        }
        for ((name, scene, table), (shade, coarse, apart)) in frames {
            let opts = RenderOptions {
                coarse_level: coarse,
                background: [0.1, 0.2, 0.3, 1.0],
                shade,
                drop_apart: apart,
            };
            let what = format!(
                "{name} {res}^3 shade {shade} from level {coarse}, tiles of {tile}, \
                 apart {apart:?}, waits {}",
                waits.name()
            );
            let want = cpu.render(scene, scene, spec, &opts).unwrap();
            let got = on_gpu
                .render_gpu(&mut gr, &GpuField::Table(table), scene, scene, spec, &opts)
                .unwrap();
            assert_eq!(got, want, "{what}: stats");
            assert_eq!(
                on_gpu.coarse_hits(),
                cpu.coarse_hits(),
                "{what}: coarse hits"
            );
            assert_eq!(on_gpu.hits(), cpu.hits(), "{what}: hits");
            let dz = on_gpu
                .depth()
                .iter()
                .zip(cpu.depth())
                .position(|(a, b)| a.to_bits() != b.to_bits());
            assert_eq!(dz, None, "{what}: depths");
            assert_eq!(on_gpu.rgba(), cpu.rgba(), "{what}: images");
            let size = 2 * res + 7;
            // The binary outline and the antialiased one (which differ where the outline
            // leaves partial pixels: not along a plate's grid-aligned sides).
            let mut binary = Vec::new();
            for aa in [false, true] {
                cpu.set_antialias(aa);
                on_gpu.set_antialias(aa);
                let a = cpu.render_display(size, opts.background).to_vec();
                let b = on_gpu
                    .render_display_gpu(&mut gr, size, opts.background)
                    .unwrap()
                    .to_vec();
                assert_eq!(a.len(), b.len());
                if aa {
                    antialiased += usize::from(a != binary);
                    displays += 1;
                } else {
                    binary.clone_from(&a);
                }
                close += a
                    .iter()
                    .zip(&b)
                    .filter(|(x, y)| x.abs_diff(**y) <= 1)
                    .count();
                channels += a.len();
                // The blend of four columns is summed on the adapter, which may fuse its
                // multiply-adds: where the blend lies within rounding of 0.5 (the noise
                // scene's field hovers there) a ray can stop one node earlier or later.
                let off = on_gpu
                    .display_depth()
                    .iter()
                    .zip(cpu.display_depth())
                    .filter(|(x, y)| (*x - *y).abs() > 1e-5)
                    .count();
                depth_off += off;
                pixels += size * size;
            }
            pixels += size * size;
        }
    }
    let counted = gpu.counters();
    let (predicted, reruns) = (
        counted.predicted - counted0.predicted,
        counted.reruns - counted0.reruns,
    );
    println!("{predicted} frames predicted, {reruns} run again");
    assert!(
        reruns > 0 && predicted > 2 * reruns,
        "predicted frames {predicted}, run again {reruns}"
    );
    // The adapter's clock on the localizations and renders and on the display images: it
    // ran where the adapter has timestamps (the timer's read-back in the counters' own),
    // and nothing is counted where it has none.
    let timed1 = gpu.counters();
    let (loc, disp) = (
        timed1.localize_gpu_ns - timed0.localize_gpu_ns,
        timed1.display_gpu_ns - timed0.display_gpu_ns,
    );
    println!(
        "on the adapter's clock: localization and render {:.1} ms, display {:.1} ms",
        loc as f64 / 1e6,
        disp as f64 / 1e6
    );
    assert_eq!(
        loc > 0,
        gpu.has_timestamps(),
        "localization timed: {loc} ns"
    );
    assert_eq!(disp > 0, gpu.has_timestamps(), "display timed: {disp} ns");
    println!("display depths within 1e-5 on all but {depth_off} of {pixels} pixels");
    assert!(
        depth_off as f64 <= 1e-3 * pixels as f64,
        "{depth_off} display depths differ"
    );
    let share = close as f64 / channels as f64;
    println!(
        "display images within 1/255 on {:.4} % of channels; {antialiased} of {displays} \
         antialiased ones with partial pixels",
        share * 100.0
    );
    assert!(2 * antialiased > displays, "{antialiased} of {displays}");
    assert!(share >= 0.999, "display images agree on {share}");
}
