//! The real photos' fields localized and rendered with the grid on the adapter against the
//! CPU's (part of `gpu_frames.rs`).

use super::*;

/// The real photos' fields through the CPU's networks, from the input view and turned 90
/// degrees: (photo, yaw, field).
fn photo_fields(cpu: &Models) -> Vec<(&'static str, f32, volcap_engine::model::ModelField)> {
    let mut out = Vec::new();
    for photo in ["astronaut.jpg", "camera.png"] {
        let img = image::open(repo().join("tests/data/real").join(photo))
            .unwrap()
            .to_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let mut info = FrameInfo::default();
        let (input, mask, crop) = cpu.prepare(img.as_raw(), w, h, &mut info).unwrap();
        for yaw in [0.0, 90.0] {
            let view = ModelView {
                yaw_deg: yaw,
                ..Default::default()
            };
            out.push((photo, yaw, cpu.encode(&input, &mask, crop, view).unwrap()));
        }
    }
    out
}

/// The hierarchical localization with its grid, the person mask and the Fourier series all on
/// the adapter (`GpuLocalizer`), against the CPU's localizer on the CPU's field, on the real
/// photos' fields (the same maps: the CPU's networks), from the input view and turned 90
/// degrees, at 129^3 and 257^3, in the paper's and the tight mode. The series and the mask's
/// taps are the CPU's formulas in f32, but the adapter may fuse multiply-adds, so a point
/// within rounding of 0.5 can land on the other side and pull a few different neighbours
/// into the evaluated set: the bound is 0.1 % of the evaluated points and a grid IoU of
/// 0.999 (the figures are printed; on lavapipe they are equal).
#[test]
fn localization_on_the_adapter_finds_the_cpus_surface_on_real_photos() {
    use volcap_engine::gpu::localize::GpuLocalizer;
    use volcap_engine::localize::HierarchicalMode;
    let Some(Runtime::Wgpu(gpu)) = gpu_runtime() else {
        return;
    };
    let dir = repo().join("models");
    let cpu = Models::load_on(&dir, "fourier-small", Precision::F32, &Runtime::Tract).unwrap();
    let mut gl = GpuLocalizer::new(gpu.clone()).unwrap();
    let mut loc = Localizer::new();
    let before = gpu.counters();
    for (photo, yaw, field) in photo_fields(&cpu) {
        let on_gpu = field.gpu_field().expect("a Fourier head");
        for res in [129, 257] {
            let spec = GridSpec::from_resolution(res).unwrap();
            for (method, mode) in [
                (Method::Hierarchical, HierarchicalMode::Paper),
                (Method::HierarchicalTight, HierarchicalMode::Tight),
            ] {
                let coarse = default_coarse(spec);
                let mut a = Grid::new(spec);
                let want = loc.run(method, &field, spec, coarse, &mut a).unwrap();
                let got = gl.run(&on_gpu, spec, coarse, mode).unwrap();
                let mut b = Grid::new(spec);
                gl.read_grid(&mut b).unwrap();
                let differ = (0..spec.len())
                    .filter(|&q| a.evaluated.get(q) != b.evaluated.get(q))
                    .count();
                let grid_iou = volcap_engine::metrics::iou(&a, &b);
                println!(
                    "{photo} yaw {yaw} {res}^3 {}: {} / {} evaluations, {differ} points \
                     evaluated on one side only, grid IoU {grid_iou:.6}",
                    method.name(),
                    want.evaluations,
                    got.evaluations
                );
                assert!(want.evaluations > 1000, "{photo}: a surface was found");
                assert!(
                    differ as f64 <= 1e-3 * want.evaluations as f64,
                    "{photo} yaw {yaw} {res}^3 {}: {differ} points differ",
                    method.name()
                );
                assert!(grid_iou >= 0.999, "{photo}: grid IoU {grid_iou}");
            }
        }
    }
    let after = gpu.counters();
    assert!(
        after.dispatches > before.dispatches && after.localize_runs >= before.localize_runs + 16
    );
}

/// The mesh-free renderer on the adapter (`Renderer::render_gpu`: localization, the culled
/// final level and the display image there; the Fourier series and the person mask in the
/// kernels) against the CPU renderer on the real photos' fields, from the input view and
/// turned 90 degrees, at 129^3 and 257^3, shaded, the pieces apart from the body dropped at
/// the product's gap (`render.drop_apart`): the same hits on >= 99.9 % of columns and
/// images within 1/255 on >= 99.9 % of channels, at the grid's size and at display size
/// (a point within rounding of 0.5 may land on the other side on an adapter that fuses
/// multiply-adds; on lavapipe they are equal); with the levels' conflict rounds predicted
/// (`compute.round_waits = "per-frame"`), the adapter's own frames exactly.
#[test]
fn the_renderer_on_the_adapter_draws_the_cpus_frames_of_real_photos() {
    use volcap_engine::gpu::render::GpuRenderer;
    let Some(Runtime::Wgpu(gpu)) = gpu_runtime() else {
        return;
    };
    let dir = repo().join("models");
    let cpu = Models::load_on(&dir, "fourier-small", Precision::F32, &Runtime::Tract).unwrap();
    let mut gr = GpuRenderer::new(gpu.clone()).unwrap();
    // The levels' rounds predicted from the frame before (one read-back for them): the
    // same frames, drawn twice each (the second time the prediction is the frame's own).
    let mut predicted = GpuRenderer::new(gpu.clone())
        .unwrap()
        .with_round_waits(volcap_engine::localize::RoundWaits::PerFrame);
    let counted0 = gpu.counters();
    let (mut a, mut b, mut c) = (Renderer::new(), Renderer::new(), Renderer::new());
    let opts = RenderOptions {
        background: [0.0, 0.0, 0.0, 1.0],
        shade: true,
        drop_apart: Some(volcap_engine::pieces::DEFAULT_GAP),
        ..Default::default()
    };
    let agree = |x: &[u8], y: &[u8]| {
        assert_eq!(x.len(), y.len());
        x.iter()
            .zip(y)
            .filter(|(p, q)| p.abs_diff(**q) <= 1)
            .count() as f64
            / x.len() as f64
    };
    let fields = photo_fields(&cpu);
    let frames = fields.len() as u64 * 2;
    for (photo, yaw, field) in fields {
        let on_gpu = field.gpu_field().expect("a Fourier head");
        for res in [129, 257] {
            let spec = GridSpec::from_resolution(res).unwrap();
            let want = a.render(&field, &field, spec, &opts).unwrap();
            let got = b
                .render_gpu(&mut gr, &on_gpu, &field, &field, spec, &opts)
                .unwrap();
            let same_hits = a
                .hits()
                .iter()
                .zip(b.hits())
                .filter(|(x, y)| x == y)
                .count() as f64
                / a.hits().len() as f64;
            let image = agree(a.rgba(), b.rgba());
            let da = a.render_display(512, opts.background).to_vec();
            let db = b
                .render_display_gpu(&mut gr, 512, opts.background)
                .unwrap()
                .to_vec();
            let display = agree(&da, &db);
            println!(
                "{photo} yaw {yaw} {res}^3: {} + {} / {} + {} evaluations, {} / {} hits, \
                 {} / {} points dropped apart, hits equal on {:.4} % of columns, image within 1/255 on {:.4} %, \
                 display (512) on {:.4} % of channels",
                want.coarse_evaluations,
                want.final_evaluations,
                got.coarse_evaluations,
                got.final_evaluations,
                want.hits,
                got.hits,
                want.dropped_apart,
                got.dropped_apart,
                same_hits * 100.0,
                image * 100.0,
                display * 100.0
            );
            assert!(want.hits > 1000, "{photo}: a person drawn");
            assert!(same_hits >= 0.999, "{photo} yaw {yaw} {res}^3: hits");
            assert!(image >= 0.999, "{photo} yaw {yaw} {res}^3: image");
            assert!(display >= 0.999, "{photo} yaw {yaw} {res}^3: display");
            for _ in 0..2 {
                let again = c
                    .render_gpu(&mut predicted, &on_gpu, &field, &field, spec, &opts)
                    .unwrap();
                assert_eq!(again, got, "{photo} yaw {yaw} {res}^3: rounds predicted");
                assert!(
                    c.hits() == b.hits() && c.rgba() == b.rgba(),
                    "{photo} {res}^3"
                );
            }
        }
    }
    let counted = gpu.counters();
    let (runs, reruns) = (
        counted.predicted - counted0.predicted,
        counted.reruns - counted0.reruns,
    );
    println!("rounds predicted for {runs} frames, {reruns} of them run again");
    assert!(runs >= frames, "{runs} predicted");
}
