//! The Fourier field's seeds (`OccupancyField::seeds`) through the whole localization and
//! render path, on the CPU and (where an adapter is found: lavapipe here) on the adapter: a
//! thin part apart from the body, which no sample of a 33^3 start falls in, is found by the
//! seeds, and the adapter's localizer and renderer find exactly what the CPU's do.

#[cfg(feature = "wgpu")]
mod common;

use volcap_engine::field::{OccupancyField, Seeded};
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{Localizer, Method};
use volcap_engine::model::fourier::{Basis, FourierMaps};
use volcap_engine::model::preprocess::{Crop, INPUT_SIZE};
use volcap_engine::model::{ModelField, ModelView, ShapeState};
use volcap_engine::render::{RenderOptions, Renderer};

const K: usize = 15;
const N: usize = 128;

/// 128 x 128 maps (depth scale 2: zeta = 2 u_z): a body, and apart from it a hand-like part
/// two map pixels high and 0.06 of zeta deep (`[0.40, 0.46]`: between the 33^3 and 65^3
/// samples' depths but for one 65^3 plane), as an arm seen edge-on whose wrist the network
/// blurred away.
fn field(yaw_deg: f32) -> ModelField {
    let c = 2 * K + 1;
    let mut data = vec![0.0f32; N * N * c];
    for (p, px) in data.chunks_exact_mut(c).enumerate() {
        let (i, j) = (p % N, p / N);
        let iv = if (40..80).contains(&i) && (20..110).contains(&j) {
            [-0.3, 0.3]
        } else if (92..120).contains(&i) && (61..63).contains(&j) {
            [0.40, 0.46]
        } else {
            continue;
        };
        for (v, x) in px.iter_mut().zip(Basis::Fourier.interval_coeffs(&[iv], K)) {
            *v = x as f32;
        }
    }
    let maps = FourierMaps::from_interleaved(data, K, N, 2.0).unwrap();
    let s = INPUT_SIZE;
    let crop = Crop {
        s: 1.0,
        tx: 0.0,
        ty: 0.0,
        cut_by_frame: false,
    };
    let view = ModelView {
        yaw_deg,
        ..ModelView::default()
    };
    ModelField::new(
        vec![1.0; s * s],
        ShapeState::Fourier(maps),
        None,
        vec![0.5; 3 * s * s],
        crop,
        view,
    )
}

/// Grid points inside whose x lies right of the body (render NDC x > 0.35: the part).
fn part_points(g: &Grid) -> usize {
    let spec = g.spec();
    g.binarized()
        .iter_ones()
        .filter(|&q| spec.coord(spec.unlinear(q)[0]) > 0.35)
        .count()
}

fn localize(f: &dyn OccupancyField, spec: GridSpec, coarse: u32) -> (Grid, u64) {
    let mut g = Grid::new(spec);
    let st = Localizer::new()
        .run(Method::Hierarchical, f, spec, coarse, &mut g)
        .unwrap();
    (g, st.evaluations)
}

#[test]
fn seeds_find_a_thin_part_between_the_coarse_samples_as_dense_does() {
    let f = field(0.0);
    let seeds = f.seeds();
    assert!(!seeds.is_empty());
    assert!(
        seeds.iter().any(|p| p.x > 0.35),
        "no seed on the part: {seeds:?}"
    );
    let spec = GridSpec::from_resolution(129).unwrap();
    let (dense, _) = localize(&f, spec, 7);
    let want = part_points(&dense);
    assert!(want > 20, "the part holds {want} grid points");
    let unseeded = Seeded {
        field: &f,
        seeds: Vec::new(),
    };
    let (lost, _) = localize(&unseeded, spec, 5);
    assert_eq!(part_points(&lost), 0, "found without seeds");
    let (found, n) = localize(&f, spec, 5);
    assert_eq!(part_points(&found), want);
    assert_eq!(volcap_engine::metrics::iou(&found, &dense), 1.0);
    assert!(n < (129 * 129 * 129) as u64 / 10, "{n} evaluations");
}

/// The render from the input view and turned 40 degrees (the seeds go through the view's
/// transform): the part is drawn with seeds and not without.
#[test]
fn seeds_bring_the_part_into_the_render_from_any_view() {
    let spec = GridSpec::from_resolution(129).unwrap();
    for yaw in [0.0, 40.0] {
        let f = field(yaw);
        let mut cpu = Renderer::new();
        let unseeded = Seeded {
            field: &f,
            seeds: Vec::new(),
        };
        cpu.render(&unseeded, &f, spec, &OPTS).unwrap();
        assert_eq!(drawn_right(&cpu, spec), 0, "yaw {yaw}: drawn without seeds");
        cpu.render(&f, &f, spec, &OPTS).unwrap();
        let d = drawn_right(&cpu, spec);
        assert!(d > 20, "yaw {yaw}: {d} pixels of the part drawn");
    }
}

const OPTS: RenderOptions = RenderOptions {
    coarse_level: 5,
    background: [0.0; 4],
    shade: false,
    drop_apart: None,
};

/// Pixels drawn right of the body (the part).
fn drawn_right(r: &Renderer, spec: GridSpec) -> usize {
    let n = spec.n();
    (0..n * n)
        .filter(|c| r.hits()[*c] >= 0 && spec.coord(c % n) > 0.35)
        .count()
}

/// On the adapter, from both views: the localization's evaluated set and the render's
/// stats and hits are the CPU's (seeds included: the part is there).
#[cfg(feature = "wgpu")]
#[test]
fn the_adapter_takes_the_same_seeds_as_the_cpu() {
    use volcap_engine::gpu::localize::GpuLocalizer;
    use volcap_engine::gpu::render::GpuRenderer;
    use volcap_engine::localize::HierarchicalMode;
    let Some(g) = common::gpu() else { return };
    let spec = GridSpec::from_resolution(129).unwrap();
    let mut gl = GpuLocalizer::new(g.clone()).unwrap();
    let mut gr = GpuRenderer::new(g.clone()).unwrap();
    for yaw in [0.0, 40.0] {
        let f = field(yaw);
        let gf = f.gpu_field().expect("a Fourier field");
        let (a, n) = localize(&f, spec, 5);
        let st = gl.run(&gf, spec, 5, HierarchicalMode::Paper).unwrap();
        assert_eq!(st.evaluations, n, "yaw {yaw}: evaluations");
        let mut b = Grid::new(spec);
        gl.read_grid(&mut b).unwrap();
        let differ = (0..spec.len())
            .filter(|&q| a.evaluated.get(q) != b.evaluated.get(q))
            .count();
        assert_eq!(differ, 0, "yaw {yaw}: evaluated sets");
        assert!(part_points(&b) > 20, "yaw {yaw}: the part on the adapter");
        assert_eq!(part_points(&b), part_points(&a), "yaw {yaw}");
        let mut cpu = Renderer::new();
        let want = cpu.render(&f, &f, spec, &OPTS).unwrap();
        let mut on_gpu = Renderer::new();
        let got = on_gpu
            .render_gpu(&mut gr, &gf, &f, &f, spec, &OPTS)
            .unwrap();
        assert_eq!(got, want, "yaw {yaw}: stats");
        assert_eq!(on_gpu.hits(), cpu.hits(), "yaw {yaw}: hits");
        assert!(drawn_right(&on_gpu, spec) > 20, "yaw {yaw}");
    }
}
