//! Whole frames on the GPU backend (feature `wgpu`) against the CPU path, on the real photos
//! (`tests/data/real/`): the same person mask (IoU >= 0.999), the same surface (Chamfer of
//! the meshes <= 1 mm), renders within 1/255 on >= 99.9 % of pixels, and hard frames (black,
//! white, noise, tiny, cut; the astronaut saturated, dark, noisy, halved, on its side) finite
//! through every stage on the adapter; and `volcap reconstruct --backend wgpu` runs. On
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

#[path = "gpu_frames/photos.rs"]
mod photos;

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
        drop_apart: None,
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
        // Localization on the GPU's field: the same points evaluated and the same inside set
        // up to rounding. The networks on the adapter add in other orders than tract (the
        // whole-plane pools reduce in a tree, pool_plane.wgsl), so their outputs differ by
        // rounding (within 3e-5 of each tensor's scale, service/engine/tests/gpu_nets.rs), and a
        // grid point that close to the level can land on the other side, pulling a few
        // different neighbours into the evaluated set (camera.png: 55051 / 55054): the bound
        // is 0.1 % of the evaluations, as on the adapter's localizer below.
        let grid_iou = volcap_engine::metrics::iou(&a.grid, &b.grid);
        println!(
            "{photo}: {} / {} evaluations, grid IoU {grid_iou:.6}",
            a.evaluations, b.evaluations
        );
        assert!(iou >= 0.999, "{photo}: mask IoU {iou}");
        assert!(
            a.evaluations.abs_diff(b.evaluations) as f64 <= 1e-3 * a.evaluations as f64,
            "{photo}: the evaluated point sets differ: {} / {}",
            a.evaluations,
            b.evaluations
        );
        assert!(grid_iou >= 0.9999, "{photo}: grid IoU {grid_iou}");
        assert!(d <= 1e-3, "{photo}: Chamfer {d} m");
        assert!(close >= 0.999, "{photo}: renders agree on {close}");
    }
}

/// Hard frames through every stage on the adapter (networks, localization, the culled
/// render): black, white, noise, tiny and a flat figure cut by the frame's edge (which the
/// segmentation may refuse: then the refusal must be an error, not a panic or a hang), and
/// the astronaut photo saturated (x3, clipped), nearly black (/12), drowned in noise, cut to
/// its upper half, and turned on its side (a rare pose), which the segmentation accepts, so
/// the finiteness checks bite: mask in [0, 1], every grid value and depth finite, the
/// adapter's localization on the same evaluated points as the CPU's on the same field; and
/// the same frames as one live stream through the maps' temporal filter on the adapter, its
/// maps finite whatever jump the crop makes.
#[test]
fn hard_frames_stay_finite_on_the_gpu() {
    use volcap_engine::gpu::localize::GpuLocalizer;
    use volcap_engine::gpu::render::GpuRenderer;
    use volcap_engine::localize::HierarchicalMode;
    let Some(rt) = gpu_runtime() else { return };
    let Runtime::Wgpu(gpu) = &rt else {
        unreachable!()
    };
    let models =
        Models::load_on(&repo().join("models"), "fourier-small", Precision::F32, &rt).unwrap();
    let (w, h) = (320usize, 240usize);
    let mut rng = 12345u32;
    let mut next = move || {
        rng = rng.wrapping_mul(1664525).wrapping_add(1013904223);
        (rng >> 24) as u8
    };
    let noise: Vec<u8> = (0..w * h * 3).map(|_| next()).collect();
    // A bright figure cut by the frame's lower edge (a close-range upper body).
    let mut cut = vec![30u8; w * h * 3];
    for y in 60..h {
        for x in 120..200 {
            cut[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[220, 180, 160]);
        }
    }
    let photo = image::open(repo().join("tests/data/real/astronaut.jpg"))
        .unwrap()
        .to_rgb8();
    let (pw, ph) = (photo.width() as usize, photo.height() as usize);
    let map = |f: &dyn Fn(u8) -> u8| photo.as_raw().iter().map(|&v| f(v)).collect::<Vec<u8>>();
    let noisy: Vec<u8> = photo
        .as_raw()
        .iter()
        .map(|&v| (v as i32 + next() as i32 / 2 - 64).clamp(0, 255) as u8)
        .collect();
    let upper = photo.as_raw()[..pw * (ph / 2) * 3].to_vec();
    let side = image::imageops::rotate90(&photo);
    let frames: Vec<(&str, Vec<u8>, usize, usize, bool)> = vec![
        ("black", vec![0; w * h * 3], w, h, false),
        ("white", vec![255; w * h * 3], w, h, false),
        ("noise", noise, w, h, false),
        ("tiny", vec![128; 2 * 2 * 3], 2, 2, false),
        ("cut", cut, w, h, false),
        ("photo x3", map(&|v| v.saturating_mul(3)), pw, ph, true),
        ("photo /12", map(&|v| v / 12), pw, ph, true),
        ("photo + noise", noisy, pw, ph, true),
        ("photo's upper half", upper, pw, ph / 2, true),
        ("photo on its side", side.as_raw().clone(), ph, pw, true),
    ];
    let spec = GridSpec::from_resolution(65).unwrap();
    let mut gl = GpuLocalizer::new(gpu.clone()).unwrap();
    let mut gr = GpuRenderer::new(gpu.clone()).unwrap();
    let mut r = Renderer::new();
    let opts = RenderOptions {
        background: [0.0, 0.0, 0.0, 1.0],
        shade: true,
        drop_apart: None,
        ..Default::default()
    };
    let mut accepted = 0;
    // The same frames as one live stream through the temporal filter on the adapter: each
    // frame's crop, size and content jump from the last one's (resampled, or started again).
    let mut temporal = volcap_engine::model::temporal::Temporal::new(Default::default());
    let mut streamed = 0;
    // The stream's frames rendered from their maps on the adapter, and on a second device of
    // the adapter from the maps read back (`compute.render_device = "own"`): the same frame.
    let own = gpu.sibling().unwrap();
    let (mut gr_shared, mut gr_own) = (
        GpuRenderer::new(gpu.clone()).unwrap(),
        GpuRenderer::new(own.clone()).unwrap(),
    );
    let (mut r_shared, mut r_own) = (Renderer::new(), Renderer::new());
    for (f, (name, rgb, fw, fh, from_photo)) in frames.into_iter().enumerate() {
        let mut info = FrameInfo::default();
        let (img, mask, crop) = match models.prepare(&rgb, fw, fh, &mut info) {
            Ok(p) => p,
            Err(FrameError::NoPerson) => {
                println!("{name}: no person");
                continue;
            }
            Err(e) => {
                println!("{name}: refused: {e}");
                continue;
            }
        };
        assert!(
            mask.iter()
                .all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
            "{name}: mask"
        );
        let field = models
            .encode(&img, &mask, crop, ModelView::default())
            .unwrap();
        let mut steady_mask = mask.clone();
        let t_s = f as f64 / 30.0;
        if let (Some(c), _) = temporal.steady_input(t_s, info.people, &mut steady_mask, crop) {
            let live = models
                .encode_steady(
                    &img,
                    &steady_mask,
                    c,
                    ModelView::default(),
                    Some(&mut temporal),
                )
                .unwrap();
            assert!(live.maps_on_adapter(), "{name}");
            let maps = live.fourier_maps().unwrap().expect("a Fourier head");
            assert!(
                maps.coefficients().iter().all(|v| v.is_finite()),
                "{name}: filtered maps"
            );
            let on_networks = live.gpu_field().expect("a Fourier head");
            let from_host = live.gpu_field_from_host().unwrap().expect("a Fourier head");
            let renders_before = gpu.counters().render_runs;
            let a = r_shared
                .render_gpu(&mut gr_shared, &on_networks, &live, &live, spec, &opts)
                .unwrap();
            let b = r_own
                .render_gpu(&mut gr_own, &from_host, &live, &live, spec, &opts)
                .unwrap();
            assert_eq!(a, b, "{name}: stats on the second device");
            assert_eq!(r_shared.hits(), r_own.hits(), "{name}: hits");
            assert!(
                r_shared
                    .depth()
                    .iter()
                    .zip(r_own.depth())
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "{name}: depths"
            );
            assert_eq!(r_shared.rgba(), r_own.rgba(), "{name}: images");
            // The second device counts into the first one's counters.
            assert_eq!(gpu.counters().render_runs, renders_before + 2, "{name}");
            assert_eq!(gpu.counters(), own.counters());
            streamed += 1;
        }
        let (cpu_grid, cpu_evals) = localize(&field, spec);
        assert!(
            cpu_grid.values.iter().all(|v| v.is_finite()),
            "{name}: CPU grid"
        );
        let on_gpu = field.gpu_field().expect("a Fourier head");
        let got = gl
            .run(&on_gpu, spec, default_coarse(spec), HierarchicalMode::Paper)
            .unwrap();
        let mut g = Grid::new(spec);
        gl.read_grid(&mut g).unwrap();
        assert!(
            g.values.iter().all(|v| v.is_finite()),
            "{name}: adapter grid"
        );
        let differ = (0..spec.len())
            .filter(|&q| cpu_grid.evaluated.get(q) != g.evaluated.get(q))
            .count();
        assert!(
            differ as f64 <= 1e-3 * cpu_evals as f64,
            "{name}: {differ} points differ"
        );
        let stats = r
            .render_gpu(&mut gr, &on_gpu, &field, &field, spec, &opts)
            .unwrap();
        assert!(r.depth().iter().all(|d| d.is_finite()), "{name}: depths");
        println!(
            "{name}: a person ({:.3} of the frame), {cpu_evals} / {} evaluations, {differ} differ, {} hits",
            info.mask_fraction, got.evaluations, stats.hits
        );
        if from_photo {
            assert!(stats.hits > 0, "{name}: nothing rendered");
            accepted += 1;
        }
    }
    // Most of the photo's hard versions are people to the segmentation: the checks above ran.
    assert!(
        accepted >= 3,
        "only {accepted} of the photo's hard frames found a person"
    );
    assert!(streamed >= accepted, "{streamed} frames through the filter");
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

/// A live stream on the GPU backend: the shape maps stay on the adapter from the network to
/// the field (nothing of them comes back or goes up again; a frame's read-backs are the
/// finiteness flag and, in a turned view, the colour encoder's features and the filter's
/// weights for them), filtered in time there: each frame's maps, read back, are the CPU
/// path's filtered maps (the astronaut moving across the frame, one view turned by 30
/// degrees), within the networks' own rounding.
#[test]
fn a_live_stream_filters_its_maps_on_the_adapter() {
    use volcap_engine::model::preprocess::INPUT_SIZE;
    use volcap_engine::model::temporal::{Temporal, TemporalSettings};
    let Some(rt) = gpu_runtime() else { return };
    let Runtime::Wgpu(adapter) = &rt else {
        unreachable!()
    };
    let adapter = adapter.clone();
    let dir = repo().join("models");
    let cpu = Models::load_on(&dir, "fourier-small", Precision::F32, &Runtime::Tract).unwrap();
    let gpu = Models::load_on(&dir, "fourier-small", Precision::F32, &rt).unwrap();
    let img = image::open(repo().join("tests/data/real/astronaut.jpg"))
        .unwrap()
        .to_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (mut t_cpu, mut t_gpu) = (
        Temporal::new(TemporalSettings::default()),
        Temporal::new(TemporalSettings::default()),
    );
    let mut maps_bytes = 0usize;
    for f in 0..6usize {
        // The person moves right by 4 pixels a frame (the crop follows, the maps are
        // resampled into it); frame 3 is seen from 30 degrees to the side.
        let dx = 4 * f;
        let mut rgb = vec![0u8; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let sx = x.saturating_sub(dx);
                let (o, i) = ((y * w + x) * 3, (y * w + sx) * 3);
                rgb[o..o + 3].copy_from_slice(&img.as_raw()[i..i + 3]);
            }
        }
        let view = ModelView {
            yaw_deg: if f == 3 { 30.0 } else { 0.0 },
            pitch_deg: 0.0,
            zoom: 1.0,
        };
        let t_s = f as f64 / 30.0;
        let steady = |models: &Models, t: &mut Temporal| {
            let mut info = FrameInfo::default();
            let (img, mut mask, crop) = models.prepare(&rgb, w, h, &mut info).expect("a person");
            let (crop, _) = t.steady_input(t_s, 1, &mut mask, crop);
            let crop = crop.expect("a person");
            let before = adapter.counters();
            let field = models
                .encode_steady(&img, &mask, crop, view, Some(t))
                .unwrap();
            let after = adapter.counters();
            (
                field,
                after.bytes_down - before.bytes_down,
                after.bytes_up - before.bytes_up,
            )
        };
        let (a, _, _) = steady(&cpu, &mut t_cpu);
        let (b, down, up) = steady(&gpu, &mut t_gpu);
        assert!(b.maps_on_adapter(), "frame {f}");
        assert!(!a.maps_on_adapter(), "frame {f}");
        let ma = a.fourier_maps().unwrap().expect("a Fourier head");
        let mb = b.fourier_maps().unwrap().expect("a Fourier head");
        maps_bytes = ma.coefficients().len() * 4;
        let scale = ma.coefficients().iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let d = ma
            .coefficients()
            .iter()
            .zip(mb.coefficients())
            .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
        println!(
            "frame {f}: maps within {d:e} of the CPU's (scale {scale}), {down} bytes down, {up} up"
        );
        assert!(
            d <= 1e-3 * scale,
            "frame {f}: maps differ by {d} (scale {scale})"
        );
        assert_eq!(b.has_color_features(), f == 3);
        // Down: the flag (and the network's timer); in the turned view the colour features
        // and the filter's weights for them. Up: the networks' input, nothing else.
        let limit = if f == 3 { maps_bytes / 2 } else { 1024 };
        assert!(down <= limit as u64, "frame {f}: {down} bytes came back");
        let input = (4 * INPUT_SIZE * INPUT_SIZE * 4) as u64;
        let nets = if f == 3 { 2 } else { 1 };
        assert!(up <= nets * input, "frame {f}: {up} bytes went up");
    }
    assert!(maps_bytes > 1 << 20, "{maps_bytes}");
}
