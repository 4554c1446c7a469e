//! The GPU backend (feature `wgpu`) against the CPU path, on whatever adapter opens: Mesa's
//! lavapipe here and in CI (`WGPU_BACKEND=vulkan`), a board's GPU there. The device and its
//! limits, the Fourier field at points, the adapter's counters and localization (the
//! renderer: `gpu_render.rs`; the networks layer by layer: `gpu_nets.rs`; the pieces apart
//! from the body: `gpu_pieces.rs`). Without an adapter the tests fail
//! under CI and say so elsewhere.
#![cfg(feature = "wgpu")]

mod common;

use common::{Golden, analytic_tables, golden_input, gpu, models_dir, values};
use volcap_engine::gpu::Gpu;
use volcap_engine::model::Runtime;
use volcap_engine::model::preprocess::INPUT_SIZE;

/// The device is opened with the adapter's own buffer sizes and storage buffers per stage
/// where they are larger than wgpu's defaults (a GPU's binding holds a 513^3 grid; where a
/// binding is smaller, the grid's tiles take more bindings), everything else at the
/// defaults.
#[test]
fn the_device_takes_the_adapters_buffer_sizes_and_bindings_and_default_limits_otherwise() {
    let d = wgpu::Limits::default();
    let gpu_like = wgpu::Limits {
        max_buffer_size: 1 << 40,
        max_storage_buffer_binding_size: (1 << 32) - 1,
        max_compute_workgroup_size_x: 1024,
        max_storage_buffers_per_shader_stage: 64,
        ..d.clone()
    };
    let l = volcap_engine::gpu::buffer_limits(&gpu_like);
    assert_eq!(l.max_buffer_size, 1 << 40);
    assert_eq!(l.max_storage_buffer_binding_size, (1 << 32) - 1);
    assert_eq!(
        l.max_compute_workgroup_size_x,
        d.max_compute_workgroup_size_x
    );
    assert_eq!(l.max_storage_buffers_per_shader_stage, 64);
    // Never below the defaults (what every adapter must offer).
    let small = wgpu::Limits {
        max_storage_buffer_binding_size: 1 << 20,
        max_storage_buffers_per_shader_stage: 4,
        ..d.clone()
    };
    let l = volcap_engine::gpu::buffer_limits(&small);
    assert_eq!(
        l.max_storage_buffer_binding_size,
        d.max_storage_buffer_binding_size
    );
    assert_eq!(
        l.max_storage_buffers_per_shader_stage,
        d.max_storage_buffers_per_shader_stage
    );
    // The opened device has them: its adapter's, as the instance lists it.
    if let Some(gpu) = gpu() {
        let inst =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapters = pollster::block_on(inst.enumerate_adapters(wgpu::Backends::all()));
        let a = adapters
            .iter()
            .find(|a| a.get_info().name == gpu.adapter.name)
            .expect("the opened adapter is listed");
        let want = volcap_engine::gpu::buffer_limits(&a.limits());
        let got = gpu.device.limits();
        assert_eq!(
            got.max_storage_buffer_binding_size,
            want.max_storage_buffer_binding_size
        );
        assert_eq!(got.max_buffer_size, want.max_buffer_size);
        assert_eq!(
            got.max_storage_buffers_per_shader_stage,
            want.max_storage_buffers_per_shader_stage
        );
    }
}

#[test]
fn dispatch_groups_cover_every_invocation_within_the_default_limit() {
    for count in [
        1u32,
        63,
        64,
        65,
        64 * 65535,
        64 * 65535 + 1,
        513 * 513 * 513,
    ] {
        let (x, y) = volcap_engine::gpu::groups(count);
        assert!(x <= 65535 && y <= 65535, "{count}: {x} x {y}");
        assert!(
            x as u64 * y as u64 * 64 >= count as u64,
            "{count}: {x} x {y}"
        );
    }
}

#[test]
fn an_adapter_that_is_not_there_is_refused_with_the_list_of_adapters() {
    let e = Gpu::open("no-such-adapter-anywhere").unwrap_err();
    assert!(
        e.contains("no-such-adapter-anywhere")
            && (e.contains("adapters found") || e.contains("no adapter found")),
        "{e}"
    );
    println!("{e}");
}

#[test]
fn the_fourier_field_at_100k_points_matches_the_cpu_for_every_committed_model() {
    use volcap_engine::model::fourier::Basis;
    use volcap_engine::model::{FourierNet, Precision};
    let Some(gpu) = gpu() else { return };
    let (x, _) = golden_input(&Golden::load("color"));
    let mut models = common::models_of("fourier");
    models.sort();
    assert!(models.len() >= 3, "{models:?}");
    // 100k points over the crop and past it (|x|, |y| up to 1.2; zeta past the depth range),
    // the exact corners and ends, and non-finite ones.
    let mut rng = 0x9e3779b9u32;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 17;
        rng ^= rng << 5;
        rng as f32 / u32::MAX as f32
    };
    let mut pts: Vec<glam::Vec3> = (0..100_000)
        .map(|_| glam::Vec3::new(2.4 * next() - 1.2, 2.4 * next() - 1.2, 1.3 * next() - 0.65))
        .collect();
    for c in [-1.0f32, 1.0] {
        pts.push(glam::Vec3::new(c, -c, 0.0));
        pts.push(glam::Vec3::new(0.3, 0.1, c * 0.5));
    }
    pts.push(glam::Vec3::new(f32::NAN, 0.0, 0.0));
    pts.push(glam::Vec3::new(0.0, 0.0, f32::INFINITY));
    for name in models {
        let net =
            FourierNet::load_on(&models_dir(), &name, Precision::F32, &Runtime::Tract).unwrap();
        let maps = net.maps(&x).unwrap();
        for (label, maps) in [
            ("fourier", maps.clone()),
            ("cosine", maps.with_basis(Basis::Cosine)),
        ] {
            let mut cpu = vec![0.0f32; pts.len()];
            maps.occupancy(&pts, &mut cpu, &mut Vec::new());
            let field = volcap_engine::gpu::fourier::GpuFourier::new(gpu.clone(), &maps).unwrap();
            let mut got = vec![-1.0f32; pts.len()];
            let other = maps.clone().with_basis(if label == "fourier" {
                Basis::Cosine
            } else {
                Basis::Fourier
            });
            assert!(
                field.occupancy(&other, &pts, &mut got).is_err(),
                "{name}: maps other than the field's are refused"
            );
            let up = gpu.counters().bytes_up;
            field.occupancy(&maps, &pts, &mut got).unwrap();
            // The maps went up with the first query, and only then.
            let maps_bytes = std::mem::size_of_val(maps.coefficients()) as u64;
            assert!(gpu.counters().bytes_up - up >= maps_bytes);
            let up = gpu.counters().bytes_up;
            field.occupancy(&maps, &pts, &mut got).unwrap();
            assert!(
                gpu.counters().bytes_up - up < maps_bytes,
                "the maps went up twice"
            );
            let worst = cpu
                .iter()
                .zip(&got)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            let inside = cpu.iter().filter(|v| **v > 0.5).count();
            println!(
                "{name} ({label} basis): {} points ({inside} inside), max |gpu - cpu| {worst:.2e}",
                pts.len()
            );
            assert!(
                got.iter().all(|v| (0.0..=1.0).contains(v)),
                "{name}: out of [0, 1]"
            );
            assert!(worst <= 1e-4, "{name} ({label}): {worst}");
            assert!(inside > 100, "{name}: the points miss the person");
        }
    }
}

#[test]
fn the_adapter_counts_its_work_and_times_it_where_it_can() {
    let Some(gpu) = gpu() else { return };
    let net = volcap_engine::gpu::net::GpuNet::load(
        gpu.clone(),
        &models_dir().join("color.encoder.onnx"),
    )
    .unwrap();
    let s = INPUT_SIZE;
    let x = values(4 * s * s, 3);
    let before = gpu.counters();
    let out = net.run(&[(&[1, 4, s, s], &x)]).unwrap();
    let after = gpu.counters();
    assert_eq!(after.net_runs, before.net_runs + 1);
    assert_eq!(after.bytes_up - before.bytes_up, (x.len() * 4) as u64);
    // The output, and the pass's two timestamps with it where the adapter has them.
    let stamps = if gpu.has_timestamps() { 16 } else { 0 };
    assert_eq!(
        after.bytes_down - before.bytes_down,
        (out.len() * 4) as u64 + stamps
    );
    let planned = net.dispatches(&[vec![1, 4, s, s]]).unwrap() as u64;
    assert_eq!(after.dispatches - before.dispatches, planned);
    println!(
        "colour encoder: {planned} dispatches, timestamps {}: {:.2} ms on the adapter",
        gpu.has_timestamps(),
        (after.gpu_ns - before.gpu_ns) as f64 / 1e6
    );
    // One read-back: the output with the timestamps.
    assert_eq!(after.waits - before.waits, 1);
    if gpu.has_timestamps() {
        assert!(after.gpu_ns > before.gpu_ns, "a timed pass took no time");
    } else {
        assert_eq!(after.gpu_ns, before.gpu_ns);
    }
    // The per-step profile: one time per planned step, in plan order, each finite.
    match net.profile(&[(&[1, 4, s, s], &x)], 1) {
        Ok(steps) => {
            assert!(gpu.has_timestamps());
            assert_eq!(steps.len() as u64, planned);
            assert!(
                steps
                    .iter()
                    .all(|t| t.ms.is_finite() && t.ms >= 0.0 && !t.node.is_empty()),
                "{steps:?}"
            );
            assert!(steps.iter().map(|t| t.ms).sum::<f64>() > 0.0, "{steps:?}");
            assert!(
                steps.iter().any(|t| t.kernel.starts_with("conv")),
                "{steps:?}"
            );
        }
        Err(e) => {
            assert!(!gpu.has_timestamps(), "{e}");
            assert!(e.contains("timestamp"), "{e}");
        }
    }
}

/// The hierarchical localization with its grid on the adapter against the CPU's, on every
/// analytic scene (the field tabulated on the host, so both sides see the same values): the
/// same value at every grid point, the same evaluated set, evaluations and conflict rounds,
/// for the paper's method, its no-conflict variant and the tight one, from two coarse levels,
/// with lists too small at first (grown, the frame run again), and with the grid's values
/// tiled over several bindings (as where one binding cannot hold a grid: 513^3 on lavapipe)
/// in tiles of 2^16 and 2^12 floats; and with each level's rounds predicted from the frame
/// before (one read-back a frame), frames whose prediction fell short run again.
#[test]
fn hierarchical_localization_on_the_adapter_matches_the_cpu_on_every_analytic_scene() {
    use volcap_engine::gpu::localize::{GpuField, GpuLocalizer};
    use volcap_engine::grid::{Grid, GridSpec};
    use volcap_engine::localize::RoundWaits;
    use volcap_engine::localize::{HierarchicalMode, Localizer, Method};
    let Some(gpu) = gpu() else { return };
    let mut cpu_loc = Localizer::new();
    let mut checked = 0;
    // Conflict rounds one per read-back (the default), and in batches of up to 8 and 4 (the
    // empty rounds after the last one must change nothing; with tiny lists, overflowing).
    // Tiles: 65^3 in 5 of 2^16 floats, 33^3 in 9 of 2^12.
    let tiled = |gl: GpuLocalizer, tile: usize| {
        if tile > 0 {
            gl.with_tile_floats(tile)
        } else {
            gl
        }
    };
    let mut tiles_seen = Vec::new();
    // With the rounds predicted (one read-back a frame, the last rows), the frames go scene
    // after scene under one method and coarse level, each predicted from the one before:
    // some predictions fall short (the frame run again per round), some hold; both must
    // give the CPU's frame, and both must happen.
    let (per_round, per_frame) = (RoundWaits::PerRound, RoundWaits::PerFrame);
    let before = gpu.counters();
    for (res, cap, per_wait, tile, waits) in [
        (33, 1 << 18, 1, 0, per_round),
        (129, 1 << 18, 8, 0, per_round),
        (65, 64, 4, 0, per_round),
        (65, 1 << 18, 1, 1 << 16, per_round),
        (33, 1000, 2, 1 << 12, per_round),
        (65, 1 << 18, 1, 0, per_frame),
        (33, 64, 1, 1 << 12, per_frame),
    ] {
        let gl = GpuLocalizer::new(gpu.clone())
            .unwrap()
            .with_list_capacity(cap)
            .with_rounds_per_wait(per_wait)
            .with_round_waits(waits);
        let mut gl = tiled(gl, tile);
        let spec = GridSpec::from_resolution(res).unwrap();
        let tiling = gl.tiling(spec);
        if tile > 0 {
            assert_eq!(
                tiling.tiles as usize,
                spec.len().div_ceil(tile),
                "{res}^3 tiles"
            );
            tiles_seen.push(tiling.tiles);
        }
        let tables = analytic_tables(spec);
        let methods = [
            (Method::Hierarchical, HierarchicalMode::Paper),
            (Method::HierarchicalNoConflict, HierarchicalMode::NoConflict),
            (Method::HierarchicalTight, HierarchicalMode::Tight),
        ];
        let mut frames = Vec::new();
        if waits == per_round {
            for t in &tables {
                for &m in &methods {
                    frames.extend([2, 3].map(|c| (t, m, c)));
                }
            }
        } else {
            for &m in &methods {
                for c in [2, 3] {
                    frames.extend(tables.iter().map(|t| (t, m, c)));
                    // The last scene again: its own rounds, a prediction that holds.
                    frames.extend(tables.last().map(|t| (t, m, c)));
                }
            }
        }
        for ((name, scene, table), (method, mode), coarse) in frames {
            let mut cpu = Grid::new(spec);
            let want = cpu_loc.run(method, scene, spec, coarse, &mut cpu).unwrap();
            let got = gl.run(&GpuField::Table(table), spec, coarse, mode).unwrap();
            let mut g = Grid::new(spec);
            gl.read_grid(&mut g).unwrap();
            let what = format!(
                "{name} {res}^3 {} from level {coarse}, {per_wait} rounds per wait, \
                 {} tile(s), waits {}",
                method.name(),
                tiling.tiles,
                waits.name()
            );
            assert_eq!(got.evaluations, want.evaluations, "{what}: evaluations");
            assert_eq!(got.conflict_rounds, want.conflict_rounds, "{what}: rounds");
            assert_eq!(
                g.evaluated.count_ones(),
                cpu.evaluated.count_ones(),
                "{what}: evaluated points"
            );
            let set_differs = (0..spec.len()).find(|&q| g.evaluated.get(q) != cpu.evaluated.get(q));
            assert_eq!(set_differs, None, "{what}: evaluated sets differ");
            let value_differs =
                (0..spec.len()).find(|&q| g.values[q].to_bits() != cpu.values[q].to_bits());
            assert_eq!(
                value_differs.map(|q| (q, g.values[q], cpu.values[q])),
                None,
                "{what}: values differ"
            );
            checked += 1;
        }
        if cap < 1000 {
            assert!(gl.list_capacity() > cap, "the small lists grew");
        }
    }
    assert_eq!(tiles_seen, [5, 9, 9]);
    let after = gpu.counters();
    let (predicted, reruns) = (
        after.predicted - before.predicted,
        after.reruns - before.reruns,
    );
    assert!(
        reruns > 0 && predicted > 2 * reruns,
        "predicted frames {predicted}, run again {reruns}"
    );
    println!("{checked} runs equal to the CPU's ({predicted} predicted, {reruns} run again)");
}

/// A grid whose values do not fit one storage binding is tiled: 513^3 (540 MB of values)
/// takes as many bindings of the adapter's size as it needs (five of 128 MiB on lavapipe; one
/// on a GPU whose binding holds it). One whose tiles need more storage bindings than the
/// adapter has per stage is refused with the sizes named, before anything is allocated; and
/// one localizer moves between tilings as its grids change size, each run the CPU's.
#[test]
fn a_grid_over_one_binding_is_tiled_and_refused_only_past_the_adapters_bindings() {
    use volcap_engine::gpu::localize::{GpuField, GpuLocalizer};
    use volcap_engine::grid::{Grid, GridSpec};
    use volcap_engine::localize::{HierarchicalMode, Localizer, Method};
    let Some(gpu) = gpu() else { return };
    let limits = gpu.device.limits();
    let binding = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let per_stage = limits.max_storage_buffers_per_shader_stage;
    let gl = GpuLocalizer::new(gpu.clone()).unwrap();
    let spec = GridSpec::from_resolution(513).unwrap();
    let t = gl.tiling(spec);
    let bytes = spec.len() as u64 * 4;
    if bytes <= binding {
        assert_eq!(t.tiles, 1);
    } else {
        assert!(
            4u64 << t.shift <= binding && 8u64 << t.shift > binding,
            "{t:?}"
        );
        assert_eq!(t.tiles as u64, bytes.div_ceil(4 << t.shift), "{t:?}");
    }
    println!(
        "513^3 on {}: {} tile(s) of at most {} MiB; {per_stage} storage buffers per stage",
        gpu.adapter.label(),
        t.tiles,
        (4u64 << t.shift).min(bytes) >> 20
    );
    // Seven storage buffers besides the values' in the busiest kernels.
    assert_eq!(
        gl.check_size(spec).is_ok(),
        t.tiles + 7 <= per_stage,
        "{t:?}"
    );

    // One float a tile: more tiles than any adapter's bindings, refused with the sizes.
    let small = GridSpec::from_resolution(129).unwrap();
    let mut tiny = GpuLocalizer::new(gpu.clone()).unwrap().with_tile_floats(1);
    let tiles = small.len();
    assert_eq!(tiny.tiling(small).tiles as usize, tiles);
    if tiles as u64 + 7 > u64::from(per_stage) {
        let e = tiny
            .run(&GpuField::Table(&[]), small, 3, HierarchicalMode::Paper)
            .unwrap_err();
        assert!(
            e.contains("129^3") && e.contains(&format!("in {tiles} storage bindings")),
            "{e}"
        );
        assert!(e.contains(&format!("adapter's {per_stage} storage")), "{e}");
    }
    let e = GpuLocalizer::new(gpu.clone())
        .unwrap()
        .run(
            &GpuField::Table(&[0.0; 10]),
            GridSpec::from_resolution(33).unwrap(),
            3,
            HierarchicalMode::Paper,
        )
        .unwrap_err();
    assert!(e.contains("10 values"), "{e}");

    // 65^3 in five tiles, 33^3 in one (it fits 2^16 floats), 65^3 again: the kernels and
    // buffers follow the tiling, the values and evaluated sets stay the CPU's.
    let mut gl = gl.with_tile_floats(1 << 16);
    let mut cpu_loc = Localizer::new();
    for (res, tiles) in [(65, 5), (33, 1), (65, 5)] {
        let spec = GridSpec::from_resolution(res).unwrap();
        assert_eq!(gl.tiling(spec).tiles, tiles, "{res}^3");
        for (name, scene, table) in analytic_tables(spec).into_iter().take(3) {
            let mut cpu = Grid::new(spec);
            let want = cpu_loc
                .run(Method::Hierarchical, &scene, spec, 3, &mut cpu)
                .unwrap();
            let got = gl
                .run(&GpuField::Table(&table), spec, 3, HierarchicalMode::Paper)
                .unwrap();
            let mut g = Grid::new(spec);
            gl.read_grid(&mut g).unwrap();
            assert_eq!(got.evaluations, want.evaluations, "{name} {res}^3");
            assert!(
                (0..spec.len()).all(|q| g.evaluated.get(q) == cpu.evaluated.get(q)
                    && g.values[q].to_bits() == cpu.values[q].to_bits()),
                "{name} {res}^3 in {tiles} tile(s): the grid differs from the CPU's"
            );
        }
    }
}

/// Index lists grow (x4) while a frame overflows them, but never past what one storage
/// binding holds: a frame that needs more is refused with a clear error (volcapd then shows
/// the error and keeps serving), not a buffer that fails wgpu's validation (a panic). The
/// bound is made small here (64 entries) to reach it on a 33^3 noise field; without it the
/// same frames run.
#[test]
fn index_lists_stop_growing_at_one_binding_with_an_error_not_a_panic() {
    use volcap_engine::gpu::localize::{GpuField, GpuLocalizer};
    use volcap_engine::gpu::render::GpuRenderer;
    use volcap_engine::grid::GridSpec;
    use volcap_engine::localize::HierarchicalMode;
    let Some(gpu) = gpu() else { return };
    let spec = GridSpec::from_resolution(33).unwrap();
    let (_, _, table) = analytic_tables(spec)
        .into_iter()
        .find(|(name, _, _)| *name == "noise")
        .expect("the noise scene");
    let field = GpuField::Table(&table);
    let mut gl = GpuLocalizer::new(gpu.clone())
        .unwrap()
        .with_list_capacity(16)
        .with_max_list_entries(64);
    let e = gl
        .run(&field, spec, 2, HierarchicalMode::Paper)
        .unwrap_err();
    assert!(
        e.contains("33^3") && e.contains("more than 64 entries"),
        "{e}"
    );
    let mut gr = GpuRenderer::new(gpu.clone())
        .unwrap()
        .with_list_capacity(16)
        .with_max_list_entries(64);
    let e = gr.frame(&field, spec, 2, None).unwrap_err();
    assert!(e.contains("more than 64 entries"), "{e}");
    // The same frames within the adapter's own bound.
    let mut gl = GpuLocalizer::new(gpu.clone())
        .unwrap()
        .with_list_capacity(16);
    gl.run(&field, spec, 2, HierarchicalMode::Paper).unwrap();
    assert!(gl.list_capacity() > 64);
    let mut gr = GpuRenderer::new(gpu).unwrap().with_list_capacity(16);
    gr.frame(&field, spec, 2, None).unwrap();
}
