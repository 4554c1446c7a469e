//! The surface's dead band on the GPU backend's adapter (`gpu/localize/hold.rs`,
//! `localize_eval.wgsl` `held`) against the CPU's (`volcap_engine::sides`): a still, noisy
//! box whose faces lie on grid planes, tabulated on the host each frame, rendered and
//! localized on both. Mesa's lavapipe here and in CI (`WGPU_BACKEND=vulkan`); without an
//! adapter the test fails under CI and says so elsewhere.
#![cfg(feature = "wgpu")]

mod common;

use common::{gpu, noisy_box};
use volcap_engine::field::{FnColor, FnField, OccupancyField};
use volcap_engine::gpu::localize::{GpuField, GpuLocalizer};
use volcap_engine::gpu::render::GpuRenderer;
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{HierarchicalMode, Localizer, Method, RoundWaits};
use volcap_engine::render::{RenderOptions, Renderer};
use volcap_engine::sides::JUST_INSIDE;

const BAND: f32 = 0.06;

/// The noisy box of frame `f` at every point of `spec` (the table the adapter reads): noise
/// of 0.05, so that values move by more than the band too (over the level: the side kept).
fn table(spec: GridSpec, f: u32) -> (FnField<impl Fn(glam::Vec3) -> f32 + Sync>, Vec<f32>) {
    sized_table(spec, f, 0.5)
}

/// [`table`] of a box of half-side `half`.
fn sized_table(
    spec: GridSpec,
    f: u32,
    half: f32,
) -> (FnField<impl Fn(glam::Vec3) -> f32 + Sync>, Vec<f32>) {
    let field = FnField(noisy_box(half, 0.05, f));
    let pts: Vec<glam::Vec3> = (0..spec.len())
        .map(|q| spec.world(spec.unlinear(q)))
        .collect();
    let mut t = vec![0.0; spec.len()];
    field.occupancy(&pts, &mut t).unwrap();
    (field, t)
}

/// Frame by frame the adapter's renderer gives out what the CPU's does with the band: the
/// same stats (held points counted alike), hits and depths bit for bit, the same image.
/// Frames held from the second on; a frame of another alignment, a frame drawn on the CPU in
/// between and a frame without a key forget; with the values tiled over bindings (lavapipe's
/// 513^3) nothing is held and the adapter says why.
#[test]
fn the_adapters_renderer_holds_the_sides_as_the_cpus() {
    let Some(gpu) = gpu() else { return };
    let spec = GridSpec::new(6).unwrap();
    let colors = FnColor(|_| [0.5, 0.5, 0.5]);
    let opts = RenderOptions::default();
    let mut gr = GpuRenderer::new(gpu.clone()).unwrap();
    let (mut cpu, mut on) = (Renderer::new(), Renderer::new());
    // (key, drawn on the CPU, held on the adapter)
    let plan: [(Option<u64>, bool, bool); 10] = [
        (Some(1), false, false),
        (Some(1), false, true),
        (Some(1), false, true),
        (Some(1), true, false),
        (Some(1), false, false),
        (Some(1), false, true),
        (Some(2), false, false),
        (Some(2), false, true),
        (None, false, false),
        (Some(2), false, false),
    ];
    let mut moved = 0;
    for (f, &(key, on_cpu, holds)) in plan.iter().enumerate() {
        let (field, t) = table(spec, f as u32);
        // The CPU's reference forgets where the adapter must: a CPU frame between holds
        // nothing (its memory was forgotten by the frame before on the adapter), and the
        // frame after it starts the adapter's memory afresh.
        let ref_key = if on_cpu { None } else { key };
        cpu.hold_sides(BAND, ref_key);
        on.hold_sides(BAND, key);
        let want = cpu.render(&field, &colors, spec, &opts).unwrap();
        let got = if on_cpu {
            on.render(&field, &colors, spec, &opts).unwrap()
        } else {
            on.render_gpu(&mut gr, &GpuField::Table(&t), &field, &colors, spec, &opts)
                .unwrap()
        };
        assert_eq!(got, want, "frame {f}: stats");
        assert_eq!(got.held_sides > 0, holds, "frame {f}: {got:?}");
        assert_eq!(on.hits(), cpu.hits(), "frame {f}: hits");
        let dz = on
            .depth()
            .iter()
            .zip(cpu.depth())
            .position(|(a, b)| a.to_bits() != b.to_bits());
        assert_eq!(dz, None, "frame {f}: depths");
        assert_eq!(on.rgba(), cpu.rgba(), "frame {f}: images");
        assert_eq!(gr.hold_refused(), None);
        if f == 2 {
            // The held frame is the last one; unheld, the noise moves the box's faces.
            let mut free = Renderer::new();
            free.render(&field, &colors, spec, &opts).unwrap();
            moved = free
                .hits()
                .iter()
                .zip(cpu.hits())
                .filter(|(a, b)| a != b)
                .count();
        }
    }
    eprintln!("columns an unheld frame moves: {moved}");
    assert!(moved > 0, "the noise does not move the test box");

    // Tiled values: not held, and said so; the frames are the unheld CPU's.
    let mut tiled = GpuRenderer::new(gpu.clone())
        .unwrap()
        .with_tile_floats(1 << 16);
    let mut on = Renderer::new();
    for f in 0..3 {
        let (field, t) = table(spec, f);
        on.hold_sides(BAND, Some(1));
        let got = on
            .render_gpu(
                &mut tiled,
                &GpuField::Table(&t),
                &field,
                &colors,
                spec,
                &opts,
            )
            .unwrap();
        let want = cpu.render(&field, &colors, spec, &opts).unwrap();
        assert_eq!(got, want, "tiled frame {f}");
        assert_eq!(on.hits(), cpu.hits(), "tiled frame {f}: hits");
        let why = tiled.hold_refused().expect("a tiled frame held");
        assert!(why.contains("65^3") && why.contains("not held"), "{why}");
    }
}

/// The adapter's localizer holds as the CPU's (`Localizer::hold_sides`): the same values
/// bit for bit and the same count held, with the paper's method and the tight variant, with
/// lists large enough and with lists that overflow (frames run again), and across the
/// memory's clearing when its stamps run out.
#[test]
fn the_adapters_localizer_holds_the_sides_as_the_cpus() {
    let Some(gpu) = gpu() else { return };
    let spec = GridSpec::new(6).unwrap();
    let mut loc = Localizer::new();
    let (mut cpu, mut got) = (Grid::new(spec), Grid::new(spec));
    let (mut held, mut sided, mut first_cap) = (0, 0, 0);
    // Lists of 64 entries at first, the first frame's box smaller: the lists grow on the
    // second frame too, the frame run again (the memory carried into the new buffers, and
    // what the attempt before wrote read as this frame's). Each level's rounds predicted
    // from the frame before: the same values.
    let (per_round, per_frame) = (RoundWaits::PerRound, RoundWaits::PerFrame);
    for ((method, mode), cap, waits) in [
        (Method::Hierarchical, HierarchicalMode::Paper),
        (Method::HierarchicalTight, HierarchicalMode::Tight),
    ]
    .into_iter()
    .flat_map(|m| {
        [
            (m, 1 << 18, per_round),
            (m, 64, per_round),
            (m, 1 << 18, per_frame),
        ]
    }) {
        let mut gl = GpuLocalizer::new(gpu.clone())
            .unwrap()
            .with_list_capacity(cap)
            .with_round_waits(waits);
        loc.forget_sides();
        for f in 0..5 {
            // Lists of 64: the stamps run out at frame 3, which clears the memory. Frame 4's
            // box is frame 0's again: the points of its surface, last written under frame
            // 0's stamp, which frame 4 follows, are read as last frame's were they not
            // cleared.
            let wraps = cap == 64;
            let half = if f == 0 || (wraps && f == 4) {
                0.25
            } else {
                0.5
            };
            let (field, t) = sized_table(spec, f, half);
            if wraps && f == 2 {
                // A jump of the stamps forgets (the CPU's reference with it); frame 2 takes
                // the last stamp, frame 3 clears and forgets again.
                gl.set_hold_stamp(0xfffe);
            }
            if wraps && (f == 2 || f == 3) {
                loc.forget_sides();
            }
            loc.hold_sides(BAND, Some(7));
            gl.hold_sides(BAND, Some(7));
            let want = loc.run(method, &field, spec, 3, &mut cpu).unwrap();
            let st = gl.run(&GpuField::Table(&t), spec, 3, mode).unwrap();
            gl.read_grid(&mut got).unwrap();
            let what = format!("{mode:?} lists of {cap}, waits {}, frame {f}", waits.name());
            assert_eq!(st.evaluations, want.evaluations, "{what}: evaluations");
            assert_eq!(gl.held_sides(), loc.held_sides(), "{what}: held");
            assert!(
                (0..spec.len()).all(|q| got.evaluated.get(q) == cpu.evaluated.get(q)),
                "{what}: evaluated set"
            );
            let v = got
                .values
                .iter()
                .zip(&cpu.values)
                .position(|(a, b)| a.to_bits() != b.to_bits());
            assert_eq!(v, None, "{what}: values");
            let forgot = f == 0 || (wraps && (f == 2 || f == 3));
            assert_eq!(!forgot, loc.held_sides() > 0, "{what}");
            held += gl.held_sides();
            // Points over the level by less than the band, kept inside (`JUST_INSIDE`).
            sided += got.values.iter().filter(|&&v| v == JUST_INSIDE).count();
            if f == 0 {
                first_cap = gl.list_capacity();
            }
        }
        if cap == 64 {
            assert!(
                gl.list_capacity() > first_cap,
                "the lists did not grow on a held frame"
            );
        }
    }
    eprintln!("points held on the adapter over 30 frames: {held}, kept inside: {sided}");
    assert!(sided > 0, "no point crossed the level within the band");
}
