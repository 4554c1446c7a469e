//! Shared by the engine's model tests: the committed models, PyTorch's golden vectors, and
//! the runtimes to run them on.
#![allow(dead_code)]

use glam::Vec3;
use safetensors::SafeTensors;
use std::path::{Path, PathBuf};
use volcap_engine::model::preprocess::{Crop, INPUT_SIZE, encoder_input, letterbox};
use volcap_engine::model::{Runtime, RuntimeChoice};

pub fn models_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

/// Shape models of `models.json` of one family ("mlp" when the card names none).
pub fn models_of(family: &str) -> Vec<String> {
    let text =
        std::fs::read_to_string(models_dir().join("models.json")).expect("models/models.json");
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let mut names: Vec<String> = v
        .as_object()
        .unwrap()
        .iter()
        .filter(|(_, c)| c["family"].as_str().unwrap_or("mlp") == family)
        .filter_map(|(k, _)| k.strip_prefix("shape-").map(str::to_string))
        .collect();
    names.sort();
    names
}

pub fn shape_models() -> Vec<String> {
    let names = models_of("mlp");
    assert!(
        names.contains(&"compact".to_string()),
        "the compact default is committed"
    );
    names
}

pub struct Golden {
    bytes: Vec<u8>,
}

/// A golden file's safetensors bytes: `NAME.safetensors.gz` (gzipped by the export,
/// `volcap_train.golden`: the image and mask are mostly background).
pub fn read_golden(p: &Path) -> Vec<u8> {
    use std::io::Read;
    let file = std::fs::File::open(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let mut bytes = Vec::new();
    flate2::read::GzDecoder::new(file)
        .read_to_end(&mut bytes)
        .unwrap_or_else(|e| panic!("{}: not gzip: {e}", p.display()));
    bytes
}

impl Golden {
    pub fn load(name: &str) -> Self {
        let p = models_dir()
            .join("golden")
            .join(format!("{name}.safetensors.gz"));
        Golden {
            bytes: read_golden(&p),
        }
    }
    pub fn f32(&self, key: &str) -> Vec<f32> {
        let st = SafeTensors::deserialize(&self.bytes).unwrap();
        let t = st.tensor(key).unwrap();
        t.data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect()
    }
    pub fn i32(&self, key: &str) -> Vec<i32> {
        let st = SafeTensors::deserialize(&self.bytes).unwrap();
        let t = st.tensor(key).unwrap();
        t.data()
            .chunks_exact(4)
            .map(|b| i32::from_le_bytes(b.try_into().unwrap()))
            .collect()
    }
    pub fn u8(&self, key: &str) -> Vec<u8> {
        let st = SafeTensors::deserialize(&self.bytes).unwrap();
        st.tensor(key).unwrap().data().to_vec()
    }
}

/// The encoder input and crop of the golden image, through the engine's preprocessing.
pub fn golden_input(g: &Golden) -> (Vec<f32>, Crop) {
    let s = INPUT_SIZE;
    let img = letterbox(&g.u8("image_u8"), s, s);
    let mask: Vec<f32> = g.u8("mask_u8").iter().map(|&m| m as f32 / 255.0).collect();
    let crop = Crop::from_mask(&mask, s).expect("golden image has a person");
    let want = g.f32("crop");
    assert!(
        (crop.s - want[0]).abs() < 1e-5
            && (crop.tx - want[1]).abs() < 1e-5
            && (crop.ty - want[2]).abs() < 1e-5,
        "crop rule differs from training: engine {crop:?}, PyTorch {want:?}"
    );
    let rgb_c = crop.apply(&img, 3, s);
    let mask_c = crop.apply(&mask, 1, s);
    (encoder_input(&rgb_c, &mask_c, s), crop)
}

pub fn points(g: &Golden) -> Vec<Vec3> {
    g.f32("points")
        .chunks_exact(3)
        .map(|p| Vec3::new(p[0], p[1], p[2]))
        .collect()
}

/// The runtimes to test on: tract, and ONNX Runtime where its library is installed
/// (`tools/onnxruntime.sh`). Under CI its absence is a failure (CI tests both runtimes);
/// elsewhere the test says that it ran on tract alone.
pub fn runtimes() -> Vec<Runtime> {
    let mut out = vec![Runtime::Tract];
    match Runtime::open(RuntimeChoice::OnnxRuntime, None) {
        Ok(o) => out.push(o.runtime),
        Err(e) if std::env::var_os("CI").is_some() => {
            panic!("CI runs the networks on both runtimes, but ONNX Runtime is missing: {e}")
        }
        Err(e) => println!("on tract alone: {e}"),
    }
    out
}

/// The adapter `auto` opens for the GPU backend's tests (Mesa's lavapipe here and in CI,
/// `WGPU_BACKEND=vulkan`); without one the tests fail under CI and say so elsewhere.
#[cfg(feature = "wgpu")]
pub fn gpu() -> Option<std::sync::Arc<volcap_engine::gpu::Gpu>> {
    match volcap_engine::gpu::Gpu::open("auto") {
        Ok(g) => {
            println!("adapter: {}", g.adapter.label());
            Some(g)
        }
        Err(e) if std::env::var_os("CI").is_some() => {
            panic!("no GPU adapter under CI (install mesa-vulkan-drivers): {e}")
        }
        Err(e) => {
            println!("skipped: {e}");
            None
        }
    }
}

/// Deterministic inputs in [-1, 1].
pub fn values(n: usize, seed: usize) -> Vec<f32> {
    (0..n)
        .map(|i| (((i + seed) * 37 % 101) as f32 / 50.0) - 1.0)
        .collect()
}

/// Every analytic scene with its values at every point of `spec`'s grid (evaluated on the
/// host: the table field the adapter's localizer and renderer read).
pub fn analytic_tables(
    spec: volcap_engine::grid::GridSpec,
) -> Vec<(
    &'static str,
    volcap_engine::analytic::AnalyticScene,
    Vec<f32>,
)> {
    use volcap_engine::field::OccupancyField;
    let pts: Vec<glam::Vec3> = (0..spec.len())
        .map(|q| spec.world(spec.unlinear(q)))
        .collect();
    volcap_engine::analytic::SCENES
        .iter()
        .map(|&name| {
            let scene = volcap_engine::analytic::AnalyticScene::by_name(name).unwrap();
            let mut table = vec![0.0f32; spec.len()];
            scene.occupancy(&pts, &mut table).unwrap();
            (name, scene, table)
        })
        .collect()
}

/// A box of half-side `half` (faces on grid planes of the 65^3 grid for multiples of
/// 1/32), occupancy a steep logistic of its signed distance, plus noise of amplitude
/// `noise` drawn per point and frame.
pub fn noisy_box(half: f32, noise: f32, frame: u32) -> impl Fn(Vec3) -> f32 + Sync {
    move |p: Vec3| {
        let q = p.abs() - Vec3::splat(half);
        let d = q.max(Vec3::ZERO).length() + q.max_element().min(0.0);
        let base = 1.0 / (1.0 + (d / 0.02).exp());
        let mut h = p.x.to_bits() ^ p.y.to_bits().rotate_left(11) ^ p.z.to_bits().rotate_left(22);
        h ^= frame.wrapping_mul(0x9e37_79b9);
        h = h.wrapping_mul(0x85eb_ca6b);
        h ^= h >> 13;
        h = h.wrapping_mul(0xc2b2_ae35);
        h ^= h >> 16;
        let n = (h >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0;
        (base + noise * n).clamp(0.0, 1.0)
    }
}
