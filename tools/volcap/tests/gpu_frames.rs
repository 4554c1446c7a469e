//! Whole frames on the GPU backend (feature `wgpu`) against the CPU path, on the real photos
//! (`tests/data/real/`): the same person mask (IoU >= 0.999), the same surface (Chamfer of
//! the meshes <= 1 mm), renders within 1/255 on >= 99.9 % of pixels, and hard frames (black,
//! white, noise, tiny, cut) finite; and `volcap reconstruct --backend wgpu` runs. On
//! whatever adapter opens (lavapipe here and in CI); without one: a failure under CI.
#![cfg(feature = "wgpu")]

use glam::DVec3;
use std::path::{Path, PathBuf};
use std::process::Command;
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{Localizer, Method, default_coarse};
use volcap_engine::mesh::marching_cubes;
use volcap_engine::metrics::chamfer;
use volcap_engine::model::{FrameError, FrameInfo, ModelView, Models, Precision, Runtime};
use volcap_engine::render::{RenderOptions, Renderer};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn gpu_runtime() -> Option<Runtime> {
    match volcap_engine::gpu::Gpu::open("auto") {
        Ok(g) => {
            println!("adapter: {}", g.adapter.label());
            Some(Runtime::Wgpu(g))
        }
        Err(e) if std::env::var_os("CI").is_some() => panic!("no GPU adapter under CI: {e}"),
        Err(e) => {
            println!("skipped: {e}");
            None
        }
    }
}

struct Frame {
    mask: Vec<f32>,
    grid: Grid,
    evaluations: u64,
    vertices: Vec<DVec3>,
    render: Vec<u8>,
}

/// The surface of `field` on a grid of `spec` (the paper's hierarchical method) and the
/// number of field evaluations it took.
fn localize(field: &volcap_engine::model::ModelField, spec: GridSpec) -> (Grid, u64) {
    let mut grid = Grid::new(spec);
    let stats = Localizer::new()
        .run(
            Method::Hierarchical,
            field,
            spec,
            default_coarse(spec),
            &mut grid,
        )
        .unwrap();
    (grid, stats.evaluations)
}

fn frame(models: &Models, rgb: &[u8], w: usize, h: usize, spec: GridSpec) -> Frame {
    let mut info = FrameInfo::default();
    let (img, mask, crop) = models.prepare(rgb, w, h, &mut info).expect("a person");
    let field = models
        .encode(&img, &mask, crop, ModelView::default())
        .unwrap();
    let (grid, evaluations) = localize(&field, spec);
    let mesh = marching_cubes(&grid);
    let mut r = Renderer::new();
    let opts = RenderOptions {
        background: [0.0; 4],
        shade: true,
        ..Default::default()
    };
    r.render(&field, &field, spec, &opts).unwrap();
    Frame {
        mask,
        grid,
        evaluations,
        vertices: mesh.vertices.iter().map(|v| v.as_dvec3()).collect(),
        render: r.rgba().to_vec(),
    }
}

#[test]
fn real_photos_give_the_cpu_paths_mask_surface_and_render() {
    let Some(gpu) = gpu_runtime() else { return };
    let dir = repo().join("models");
    let cpu = Models::load_on(&dir, "fourier-small", Precision::F32, &Runtime::Tract).unwrap();
    let gpu = Models::load_on(&dir, "fourier-small", Precision::F32, &gpu).unwrap();
    assert_eq!(gpu.seg.runtime(), "wgpu");
    let spec = GridSpec::from_resolution(129).unwrap();
    for photo in ["astronaut.jpg", "camera.png"] {
        let img = image::open(repo().join("tests/data/real").join(photo))
            .unwrap()
            .to_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let a = frame(&cpu, img.as_raw(), w, h, spec);
        let b = frame(&gpu, img.as_raw(), w, h, spec);
        let (mut inter, mut union) = (0usize, 0usize);
        for (p, q) in a.mask.iter().zip(&b.mask) {
            let (p, q) = (*p > 0.5, *q > 0.5);
            inter += (p && q) as usize;
            union += (p || q) as usize;
        }
        let iou = inter as f64 / union.max(1) as f64;
        let d = chamfer(&a.vertices, &b.vertices);
        let close = a
            .render
            .iter()
            .zip(&b.render)
            .filter(|(x, y)| x.abs_diff(**y) <= 1)
            .count() as f64
            / a.render.len() as f64;
        println!(
            "{photo}: mask IoU {iou:.5}, Chamfer {:.3} mm ({} / {} vertices), render within 1/255 on {:.3} % of channels",
            d * 1e3,
            a.vertices.len(),
            b.vertices.len(),
            close * 100.0
        );
        // Localization on the GPU's field: the same points evaluated, the same inside set
        // (a point within float rounding of the level could flip; none did on these photos).
        let grid_iou = volcap_engine::metrics::iou(&a.grid, &b.grid);
        println!(
            "{photo}: {} / {} evaluations, grid IoU {grid_iou:.6}",
            a.evaluations, b.evaluations
        );
        assert!(iou >= 0.999, "{photo}: mask IoU {iou}");
        assert_eq!(
            a.evaluations, b.evaluations,
            "{photo}: the evaluated point sets differ"
        );
        assert!(grid_iou >= 0.9999, "{photo}: grid IoU {grid_iou}");
        assert!(d <= 1e-3, "{photo}: Chamfer {d} m");
        assert!(close >= 0.999, "{photo}: renders agree on {close}");
    }
}

#[test]
fn hard_frames_stay_finite_on_the_gpu() {
    let Some(gpu) = gpu_runtime() else { return };
    let models = Models::load_on(
        &repo().join("models"),
        "fourier-small",
        Precision::F32,
        &gpu,
    )
    .unwrap();
    let (w, h) = (320usize, 240usize);
    let mut rng = 12345u32;
    let mut noise = vec![0u8; w * h * 3];
    for v in &mut noise {
        rng = rng.wrapping_mul(1664525).wrapping_add(1013904223);
        *v = (rng >> 24) as u8;
    }
    // A bright figure cut by the frame's lower edge (a close-range upper body).
    let mut cut = vec![30u8; w * h * 3];
    for y in 60..h {
        for x in 120..200 {
            cut[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[220, 180, 160]);
        }
    }
    let frames: Vec<(&str, Vec<u8>, usize, usize)> = vec![
        ("black", vec![0; w * h * 3], w, h),
        ("white", vec![255; w * h * 3], w, h),
        ("noise", noise, w, h),
        ("tiny", vec![128; 2 * 2 * 3], 2, 2),
        ("cut", cut, w, h),
    ];
    let spec = GridSpec::from_resolution(33).unwrap();
    for (name, rgb, fw, fh) in frames {
        let mut info = FrameInfo::default();
        match models.prepare(&rgb, fw, fh, &mut info) {
            Ok((img, mask, crop)) => {
                assert!(
                    mask.iter()
                        .all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
                    "{name}"
                );
                let field = models
                    .encode(&img, &mask, crop, ModelView::default())
                    .unwrap();
                let (grid, _) = localize(&field, spec);
                assert!(grid.values.iter().all(|v| v.is_finite()), "{name}");
                println!(
                    "{name}: a person found ({:.3} of the frame), localized",
                    info.mask_fraction
                );
            }
            Err(FrameError::NoPerson) => println!("{name}: no person"),
            Err(e) => println!("{name}: refused: {e}"),
        }
    }
}

#[test]
fn reconstruct_runs_on_the_gpu_backend() {
    if gpu_runtime().is_none() {
        return;
    }
    let out = std::env::temp_dir().join(format!("volcap-gpu-rec-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_volcap"))
        .current_dir(repo())
        .args([
            "reconstruct",
            "tests/data/real/camera.png",
            "--res",
            "65",
            "--json",
            "--backend",
            "wgpu",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let rep: serde_json::Value = serde_json::from_str(stdout.lines().next().unwrap()).unwrap();
    assert_eq!(rep["ok"], true, "{rep}");
    assert_eq!(rep["people"], 1, "{rep}");
    // Localization (the mesh) and the turntable renders ran on the adapter: the CPU path's
    // mesh size and images, within the networks' rounding.
    let cpu_out = out.join("cpu");
    let o = Command::new(env!("CARGO_BIN_EXE_volcap"))
        .current_dir(repo())
        .args([
            "reconstruct",
            "tests/data/real/camera.png",
            "--res",
            "65",
            "--json",
            "--out",
        ])
        .arg(&cpu_out)
        .output()
        .unwrap();
    assert!(o.status.success());
    let cpu: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&o.stdout).lines().next().unwrap()).unwrap();
    let (t_gpu, t_cpu) = (
        rep["triangles"].as_f64().unwrap(),
        cpu["triangles"].as_f64().unwrap(),
    );
    assert!(
        t_cpu > 100.0 && (t_gpu - t_cpu).abs() <= 0.01 * t_cpu,
        "{t_gpu} vs {t_cpu} triangles"
    );
    for yaw in ["000", "090"] {
        let name = format!("camera.yaw{yaw}.png");
        let a = image::open(out.join(&name)).unwrap().to_rgba8();
        let b = image::open(cpu_out.join(&name)).unwrap().to_rgba8();
        let close = a
            .as_raw()
            .iter()
            .zip(b.as_raw())
            .filter(|(x, y)| x.abs_diff(**y) <= 1)
            .count() as f64
            / a.as_raw().len() as f64;
        println!(
            "reconstruct {name}: adapter and CPU within 1/255 on {:.3} % of channels",
            close * 100.0
        );
        assert!(close >= 0.99, "{name}: {close}");
    }
    // An adapter that is not there: refused, naming the adapters found.
    let o = Command::new(env!("CARGO_BIN_EXE_volcap"))
        .current_dir(repo())
        .args([
            "reconstruct",
            "tests/data/real/camera.png",
            "--backend",
            "wgpu",
            "--adapter",
            "no-such-gpu",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no-such-gpu") && err.contains("adapter"),
        "{err}"
    );
}

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
/// turned 90 degrees, at 129^3 and 257^3, shaded: the same hits on >= 99.9 % of columns and
/// images within 1/255 on >= 99.9 % of channels, at the grid's size and at display size
/// (a point within rounding of 0.5 may land on the other side on an adapter that fuses
/// multiply-adds; on lavapipe they are equal).
#[test]
fn the_renderer_on_the_adapter_draws_the_cpus_frames_of_real_photos() {
    use volcap_engine::gpu::render::GpuRenderer;
    let Some(Runtime::Wgpu(gpu)) = gpu_runtime() else {
        return;
    };
    let dir = repo().join("models");
    let cpu = Models::load_on(&dir, "fourier-small", Precision::F32, &Runtime::Tract).unwrap();
    let mut gr = GpuRenderer::new(gpu.clone()).unwrap();
    let (mut a, mut b) = (Renderer::new(), Renderer::new());
    let opts = RenderOptions {
        background: [0.0, 0.0, 0.0, 1.0],
        shade: true,
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
    for (photo, yaw, field) in photo_fields(&cpu) {
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
                 hits equal on {:.4} % of columns, image within 1/255 on {:.4} %, \
                 display (512) on {:.4} % of channels",
                want.coarse_evaluations,
                want.final_evaluations,
                got.coarse_evaluations,
                got.final_evaluations,
                want.hits,
                got.hits,
                same_hits * 100.0,
                image * 100.0,
                display * 100.0
            );
            assert!(want.hits > 1000, "{photo}: a person drawn");
            assert!(same_hits >= 0.999, "{photo} yaw {yaw} {res}^3: hits");
            assert!(image >= 0.999, "{photo} yaw {yaw} {res}^3: image");
            assert!(display >= 0.999, "{photo} yaw {yaw} {res}^3: display");
        }
    }
}
