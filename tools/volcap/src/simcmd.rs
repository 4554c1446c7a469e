//! `volcap sim ...`: pack, render, bench, dataset.

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use volcap_sim::assets::{HumanAssets, Selection};
use volcap_sim::scene::Scene;
use volcap_sim::{SimError, Simulator};

#[derive(Subcommand)]
pub enum SimCmd {
    /// Build the compact runtime asset pack from the full MakeHuman data.
    Pack(PackArgs),
    /// Render a scene: PNG frames, person mask, depth, and a JSON per frame.
    Render(RenderArgs),
    /// Frames per second with no effects and the cost of each effect.
    Bench(BenchArgs),
    /// One frame of a scene as a (small) PNG, e.g. for docs/sim/.
    Snapshot(SnapshotArgs),
    /// Training shards: images, masks, labelled 3D points, surface colours (safetensors).
    Dataset(DatasetArgs),
}

#[derive(Args)]
pub struct DatasetArgs {
    /// Subject identities (split into train/validation by identity).
    #[arg(long, default_value_t = 4)]
    pub subjects: usize,
    /// Poses per subject.
    #[arg(long, default_value_t = 2)]
    pub poses: usize,
    /// Views per pose, evenly around the subject.
    #[arg(long, default_value_t = 36)]
    pub views: usize,
    /// Image side in pixels.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Labelled points per image.
    #[arg(long, default_value_t = 8000)]
    pub points: usize,
    #[arg(long, default_value_t = 0.25)]
    pub val_fraction: f32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Draw poses, views, points and light rigs from this seed: the identities and split of
    /// `--seed` in new poses (another dataset of the same people).
    #[arg(long)]
    pub pose_seed: Option<u64>,
    /// `studio`: every image under the fixed studio rig; `varied`: a random light rig per
    /// pose (same subjects, poses and labels as the studio dataset of the same options).
    #[arg(long, default_value = "studio")]
    pub lighting: volcap_sim::dataset::DatasetLighting,
    /// `rest`: every hand in the rest pose's (open, the wrist straight); `varied`: the same
    /// poses with drawn forearm twists, wrist flexions and finger curls (open hand to fist).
    #[arg(long, default_value = "rest")]
    pub hands: volcap_sim::pose::Hands,
    /// Threads writing the views' shards (0: every core; the files are the same on any
    /// number; the poses' oracles and labelled points stay on one thread, in order).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub assets: AssetArgs,
}

#[derive(Args)]
pub struct SnapshotArgs {
    pub scene: PathBuf,
    #[arg(long, default_value_t = 0)]
    pub frame: u64,
    /// Longest side of the written PNG in pixels.
    #[arg(long, default_value_t = 256)]
    pub size: u32,
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub assets: AssetArgs,
}

#[derive(Args)]
pub struct PackArgs {
    /// The MakeHuman data folder.
    #[arg(long, default_value = "../shared/data/makehuman")]
    pub from: PathBuf,
    #[arg(long, default_value = "service/sim/assets/human-pack.bin.gz")]
    pub out: PathBuf,
    /// Everything in the folder (every outfit, hair, skin, macro target; textures at 512
    /// px) as the datasets use it: the training recipe's pack (tools/train/recipe/), so a
    /// machine without `../shared` generates the same data. Default: the runtime pack.
    #[arg(long)]
    pub everything: bool,
    /// The runtime pack's bodies in the whole wardrobe of the folder (every outfit, shoe,
    /// hair and skin; textures at this many px): the lean training recipe's pack, small
    /// enough to travel beside the checkout (`Selection::wardrobe`).
    #[arg(long, value_name = "TEXTURE_PX", conflicts_with = "everything")]
    pub wardrobe: Option<u32>,
}

#[derive(Args, Clone)]
pub struct AssetArgs {
    /// Human assets: a pack file or a MakeHuman folder (default: the embedded pack).
    #[arg(long)]
    pub assets: Option<PathBuf>,
}

impl AssetArgs {
    pub fn load(&self) -> anyhow::Result<Arc<HumanAssets>> {
        Ok(Arc::new(match &self.assets {
            Some(p) => HumanAssets::load(p).map_err(anyhow::Error::msg)?,
            None => HumanAssets::embedded().map_err(anyhow::Error::msg)?,
        }))
    }
}

#[derive(Args)]
pub struct RenderArgs {
    /// The scene file (TOML).
    pub scene: PathBuf,
    /// Frames to render (default: the scene's `frames`).
    #[arg(long)]
    pub frames: Option<u64>,
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the posed clothed meshes of every frame (`NNNNNN_mesh.ply`, world metres,
    /// y up; body, eyes and garments as separate pieces of one file).
    #[arg(long)]
    pub meshes: bool,
    #[command(flatten)]
    pub assets: AssetArgs,
}

#[derive(Args)]
pub struct BenchArgs {
    /// Scene to measure (default: tests/scenes/front-walk.toml).
    #[arg(long, default_value = "tests/scenes/front-walk.toml")]
    pub scene: PathBuf,
    /// Frames per measurement.
    #[arg(long, default_value_t = 60)]
    pub frames: u64,
    #[command(flatten)]
    pub assets: AssetArgs,
}

pub fn run(cmd: SimCmd) -> anyhow::Result<()> {
    match cmd {
        SimCmd::Pack(a) => pack(&a),
        SimCmd::Render(a) => render(&a),
        SimCmd::Bench(a) => bench(&a),
        SimCmd::Snapshot(a) => snapshot(&a),
        SimCmd::Dataset(a) => dataset(&a),
    }
}

fn pack(a: &PackArgs) -> anyhow::Result<()> {
    if !a.from.join("3dobjs/base.obj").exists() {
        bail!(
            "{}: not a MakeHuman data folder (no 3dobjs/base.obj)",
            a.from.display()
        );
    }
    let t = Instant::now();
    let sel = match (a.everything, a.wardrobe) {
        (true, _) => Selection::everything(&a.from),
        (false, Some(px)) => {
            if !(16..=4096).contains(&px) {
                bail!("--wardrobe {px}: texture size must be 16 to 4096 px");
            }
            Selection::wardrobe(&a.from, px)
        }
        (false, None) => Selection::runtime(),
    };
    let assets = HumanAssets::from_makehuman(&a.from, &sel)?;
    let mut f =
        std::fs::File::create(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    assets.write_pack(&mut f).map_err(anyhow::Error::msg)?;
    drop(f);
    let size = std::fs::metadata(&a.out)?.len();
    println!(
        "wrote {} ({:.2} MB) in {:.1} s: {} vertices, {} targets, {} garments, {} skins, {} poses",
        a.out.display(),
        size as f64 / 1e6,
        t.elapsed().as_secs_f64(),
        assets.base.len(),
        assets.targets.len(),
        assets.garments.len(),
        assets.skins.len(),
        assets.poses.len()
    );
    Ok(())
}

pub fn load_scene(path: &Path, assets: Arc<HumanAssets>) -> anyhow::Result<Simulator> {
    let scene = Scene::load(path)?;
    Ok(Simulator::new(scene, assets)?)
}

fn bar(len: u64) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    pb
}

fn render(a: &RenderArgs) -> anyhow::Result<()> {
    let assets = a.assets.load()?;
    let mut sim = load_scene(&a.scene, assets)?;
    let frames = a.frames.unwrap_or(sim.scene().frames);
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let pb = bar(frames);
    for i in 0..frames {
        match sim.render(i) {
            Ok(f) => {
                write_frame(&a.out, &f, &sim)?;
                if a.meshes {
                    write_meshes(&a.out, f.index, &sim)?;
                }
            }
            Err(e @ (SimError::Unplugged { frame } | SimError::Hung { frame })) => {
                pb.finish_and_clear();
                println!(
                    "{e} (scene effect); wrote {frame} frames to {}",
                    a.out.display()
                );
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    println!("wrote {frames} frames to {}", a.out.display());
    Ok(())
}

/// Write `NNNNNN.png` (RGB), `NNNNNN_mask.png`, `NNNNNN_depth.png` (16-bit millimetres, 0 =
/// nothing) and `NNNNNN.json` (camera, subjects, pose).
pub fn write_frame(dir: &Path, f: &volcap_sim::SimFrame, sim: &Simulator) -> anyhow::Result<()> {
    let stem = dir.join(format!("{:06}", f.index));
    let (w, h) = (f.width as u32, f.height as u32);
    image::RgbImage::from_raw(w, h, f.rgb.clone())
        .context("frame buffer size")?
        .save(stem.with_extension("png"))
        .with_context(|| format!("writing {}.png", stem.display()))?;
    image::GrayImage::from_raw(w, h, f.person_mask())
        .context("mask size")?
        .save(format!("{}_mask.png", stem.display()))?;
    let depth: Vec<u16> = f
        .depth_m
        .iter()
        .map(|d| {
            if d.is_finite() {
                (d * 1000.0).round().clamp(1.0, 65535.0) as u16
            } else {
                0
            }
        })
        .collect();
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, depth)
        .context("depth size")?
        .save(format!("{}_depth.png", stem.display()))?;
    let json = serde_json::json!({
        "frame": f.index,
        "time_s": f.time_s,
        "scene": sim.scene().name,
        "camera": f.camera,
        "subjects": sim.subject_info(f.time_s),
        "jpeg_bytes": f.meta.jpeg_bytes,
        "depth_png": "millimetres along the view direction, 0 = background",
    });
    std::fs::write(
        stem.with_extension("json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    Ok(())
}

fn bench(a: &BenchArgs) -> anyhow::Result<()> {
    let assets = a.assets.load()?;
    let base = Scene::load(&a.scene)?.without_effects();
    let measure = |scene: Scene| -> anyhow::Result<f64> {
        let mut sim = Simulator::new(scene, assets.clone())?;
        sim.render(0)?; // warm-up (allocations, textures)
        // Best of three passes over the same frames: the least disturbed measurement.
        let mut best = f64::INFINITY;
        for _ in 0..3 {
            let t = Instant::now();
            for i in 1..=a.frames {
                sim.render(i)?;
            }
            best = best.min(t.elapsed().as_secs_f64());
        }
        Ok(a.frames as f64 / best)
    };
    let fps = measure(base.clone())?;
    println!(
        "scene {} ({}x{}, {} subject(s)), best of 3 passes of {} frames per row, one core",
        a.scene.display(),
        base.camera.width.0,
        base.camera.height.0,
        base.subjects.len(),
        a.frames
    );
    println!("| effects | frames/s | ms/frame | effect cost ms |");
    println!("|---|---:|---:|---:|");
    println!("| none | {fps:.1} | {:.2} | - |", 1000.0 / fps);
    let examples = effect_examples();
    let pb = bar(examples.len() as u64);
    let mut rows = Vec::new();
    for (kind, toml_snippet) in examples {
        let text = format!("[[effect]]\n{toml_snippet}\n");
        let extra = Scene::parse(&text, Path::new("<bench>"))?;
        let mut s = base.clone();
        s.effects = extra.effects;
        let f = measure(s)?;
        rows.push((kind, f));
        pb.inc(1);
    }
    pb.finish_and_clear();
    for (kind, f) in rows {
        println!(
            "| {kind} | {f:.1} | {:.2} | {:+.2} |",
            1000.0 / f,
            1000.0 / f - 1000.0 / fps
        );
    }
    Ok(())
}

/// One representative declaration of each effect (unplug is excluded: it stops frames).
pub fn effect_examples() -> Vec<(&'static str, &'static str)> {
    vec![
        (
            "sensor-noise",
            "sensor-noise = { shot = 0.02, read = 0.01 }",
        ),
        (
            "motion-blur",
            "motion-blur = { length_px = 9, angle_deg = 0 }",
        ),
        (
            "exposure-drift",
            "exposure-drift = { amplitude = 0.2, period_s = 3 }",
        ),
        (
            "white-balance-drift",
            "white-balance-drift = { amplitude = 0.1, period_s = 5 }",
        ),
        ("jpeg", "jpeg = { quality = 75 }"),
        ("rolling-shutter", "rolling-shutter = { skew_px = 12 }"),
        ("vignetting", "vignetting = { strength = 0.4 }"),
        (
            "occluder",
            "occluder = { center = [0.3, 1.0, 0.6], size = [0.3, 0.5, 0.1] }",
        ),
        ("camera-shake", "camera-shake = { amplitude_deg = 1.5 }"),
    ]
}

fn snapshot(a: &SnapshotArgs) -> anyhow::Result<()> {
    let mut sim = load_scene(&a.scene, a.assets.load()?)?;
    let f = sim.render(a.frame)?;
    let img = image::RgbImage::from_raw(f.width as u32, f.height as u32, f.rgb)
        .context("frame buffer size")?;
    let img = image::DynamicImage::ImageRgb8(img).resize(
        a.size,
        a.size,
        image::imageops::FilterType::Triangle,
    );
    img.save(&a.out)
        .with_context(|| format!("writing {}", a.out.display()))?;
    println!(
        "wrote {} ({}x{}, frame {})",
        a.out.display(),
        img.width(),
        img.height(),
        a.frame
    );
    Ok(())
}

fn dataset(a: &DatasetArgs) -> anyhow::Result<()> {
    let cfg = volcap_sim::dataset::DatasetConfig {
        subjects: a.subjects,
        poses: a.poses,
        views: a.views,
        size: a.size,
        points: a.points,
        val_fraction: a.val_fraction,
        seed: a.seed,
        pose_seed: a.pose_seed,
        lighting: a.lighting,
        hands: a.hands,
        threads: a.threads,
        ..Default::default()
    };
    let assets = a.assets.load()?;
    // What the identities are dressed from (also in dataset.json's `wardrobe`): the embedded
    // runtime pack is a third of the outfits the held-out evaluation uses.
    let w = volcap_sim::dataset::wardrobe(&assets);
    let count = |k: &str| w.get(k).map_or(0, Vec::len);
    let from = match a.assets.assets {
        Some(_) => "--assets",
        None => {
            "the embedded runtime pack; for training, pass --assets ../shared/data/makehuman: \
             `volcap eval --data` dresses its held-out subjects from the whole wardrobe"
        }
    };
    eprintln!(
        "wardrobe: {} outfits, {} shoes, {} hair, {} skins ({from})",
        count("outfits"),
        count("shoes"),
        count("hair"),
        count("skins"),
    );
    let total = (a.subjects * a.poses * a.views) as u64;
    let pb = bar(total);
    let t = Instant::now();
    let n = volcap_sim::dataset::generate(assets, &cfg, &a.out, |d| pb.set_position(d))?;
    pb.finish_and_clear();
    let secs = t.elapsed().as_secs_f64();
    println!(
        "wrote {n} images to {} in {secs:.1} s ({:.1} images/s, {} shard writer thread(s))",
        a.out.display(),
        n as f64 / secs,
        volcap_sim::shards::threads(a.threads),
    );
    Ok(())
}

/// The posed clothed meshes of the last frame as one PLY in world metres (y up).
fn write_meshes(dir: &Path, index: u64, sim: &Simulator) -> anyhow::Result<()> {
    let mut m = volcap_engine::mesh::Mesh::default();
    for (closed, open) in sim.world_meshes() {
        for w in closed.iter().chain(open.iter()) {
            let base = m.vertices.len() as u32;
            m.vertices.extend_from_slice(w.verts);
            m.triangles
                .extend(w.tris.iter().map(|t| t.map(|i| i + base)));
        }
    }
    let path = dir.join(format!("{index:06}_mesh.ply"));
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?,
    );
    m.write_ply_as_is(&mut f)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
