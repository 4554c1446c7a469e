//! Training shards like the paper's data: for every rendered image, the image and person
//! mask plus sampled 3D points with occupancy labels and surface points with colours.
//!
//! Layout: `OUT/{train,val}/<subject>/<pose>_<view>.safetensors`, plus `OUT/dataset.json`
//! (the configuration, the subjects and their split). Each shard holds tensors
//! `image` u8 [H, W, 3], `mask` u8 [H, W], `points` f32 [N, 3] (render-view NDC, the
//! engine's convention), `occ` f32 [N] (1 inside, 0 outside), `surface` f32 [M, 3] (NDC: the
//! surface the view shows from the camera and from straight behind it, [`seen_surface`]),
//! `surface_rgb` f32 [M, 3] (its colours), the per-pixel inside intervals along each pixel's ray
//! (`ray_offsets` u32 [H * W + 1] into `ray_z` f32 [R, 2], render-view NDC z, see
//! [`crate::rays`]: the dense supervision of the Fourier head), and one metadata key `volcap` holding JSON (`camera`, `subject`,
//! `subject_table`, `style`, `time_s`, `yaw_deg`, `split`, and the `scene` text and `frame`
//! that reproduce the image). Points: half inside, half outside; near-surface samples with a
//! Gaussian offset (sigma, default 5 cm) plus uniform samples in the subject's box.
//! Everything is deterministic from the seed; the split is by subject identity. A pose seed
//! (`pose_seed`) keeps the seed's identities and split and draws new poses, views and points.
//!
//! Lighting ([`DatasetLighting`]): `studio` renders every image under the fixed studio rig;
//! `varied` draws a light rig per pose (ambient, a key light and maybe a fill, each with its
//! own direction, strength and tint: [`varied_lighting`]) from a random stream of its own, so
//! a varied dataset holds the same subjects, poses, views and labels as the studio one of the
//! same configuration and only the shading differs. The rig is written into the scene text
//! as its SH irradiance (with a comment naming the lights).
//!
//! Hands ([`Hands`], `hands.rs`): `rest` keeps every hand in the rest pose's (the scene text
//! without a `hands` key, so these datasets are what they were before the key existed);
//! `varied` draws forearm twists, wrist flexions and finger curls from a random stream of each
//! motion's seed of its own: the same subjects, bodies and views, only the hands and the points'
//! labels differ. (The labelled points come from the main stream, which sorts near-surface
//! samples inside and outside until both halves are full: where moved hands made that take
//! another round of draws, the later poses of the dataset would differ too. In DSF67H, docs/eval/
//! hands.md section 51, none did: every shard checked holds DSF67's scene text and the hands.)

use crate::assets::{GarmentKind, HumanAssets};
use crate::pose::{Hands, Style};
use crate::raster::Sh9;
use crate::scene::Scene;
use crate::shards::{self, ShardWriter, ViewJob};
use crate::sim::{SimError, Simulator};
use glam::{DVec3, Vec3};
use rand::seq::{IndexedRandom, SliceRandom};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::Arc;
use volcap_engine::mesh::Mesh;
use volcap_engine::metrics::sample_surface;

#[derive(Debug, Clone)]
pub struct DatasetConfig {
    pub subjects: usize,
    pub poses: usize,
    pub views: usize,
    /// Image side in pixels.
    pub size: usize,
    /// Labelled points per image (half inside, half outside).
    pub points: usize,
    /// Surface points with colours per image.
    pub surface_points: usize,
    /// Standard deviation of the near-surface offsets, metres.
    pub sigma_m: f32,
    /// Fraction of subject identities held out for validation.
    pub val_fraction: f32,
    pub voxel_m: f32,
    /// Threads writing the views' shards (0: every core); the files are the same on any
    /// number ([`crate::shards`]).
    pub threads: usize,
    pub seed: u64,
    /// Draw the poses, views, points and light rigs from this seed instead of `seed`: the
    /// same identities and split (those come from `seed`) in new poses.
    pub pose_seed: Option<u64>,
    pub lighting: DatasetLighting,
    /// How the procedural poses hold the hands (`hands.rs`): `Rest` draws the datasets of
    /// before 2026-12-02 byte for byte; `Varied` the same poses with drawn wrists and fingers.
    pub hands: Hands,
}

/// How a dataset's images are lit (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DatasetLighting {
    /// The fixed studio rig (`preset = "studio"`) for every image.
    #[default]
    Studio,
    /// A random rig per pose ([`varied_lighting`]).
    Varied,
}

impl DatasetLighting {
    pub const ALL: [DatasetLighting; 2] = [Self::Studio, Self::Varied];

    pub fn name(self) -> &'static str {
        match self {
            Self::Studio => "studio",
            Self::Varied => "varied",
        }
    }
}

impl std::str::FromStr for DatasetLighting {
    type Err = String;

    /// By [`DatasetLighting::name`]; anything else is refused naming the value and the choices.
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|l| l.name()).collect();
                format!("lighting {s:?}: expected one of {}", names.join(", "))
            })
    }
}

/// The studio rig's `[lighting]` table.
pub const STUDIO_LIGHTING: &str = "[lighting]\npreset = \"studio\"\n";

/// A random light rig as a scene's `[lighting]` table (explicit SH irradiance, a comment
/// naming the lights): grey ambient 0.08-0.5 (one pose in ten ambient only, 0.55-1.0, like
/// an overcast room); a key light from any azimuth, 15 degrees below to 75 above the
/// horizon, strength 0.35-1.1, warm to cool tint; seven times in ten a fill light, another
/// direction, strength 0.05-0.4. World directions (y up), so views around a pose see it
/// from their own sides.
pub fn varied_lighting(r: &mut impl Rng) -> String {
    let dir = |r: &mut dyn rand::RngCore, el_lo: f32, el_hi: f32| -> (f32, f32, Vec3) {
        let az: f32 = r.random_range(0.0..360.0);
        let el: f32 = r.random_range(el_lo..el_hi);
        let (a, e) = (az.to_radians(), el.to_radians());
        (
            az,
            el,
            Vec3::new(e.cos() * a.sin(), e.sin(), e.cos() * a.cos()),
        )
    };
    let tint = |r: &mut dyn rand::RngCore, s: f32| -> [f32; 3] {
        let t: f32 = r.random_range(-0.12..0.12);
        [s * (1.0 + t), s, s * (1.0 - t)]
    };
    let mut notes = Vec::new();
    let sh = if r.random_range(0..10) == 0 {
        let a: f32 = r.random_range(0.55..1.0);
        notes.push(format!("ambient only {a:.2}"));
        Sh9::ambient([a; 3])
    } else {
        let a: f32 = r.random_range(0.08..0.5);
        let mut sh = Sh9::ambient([a; 3]);
        let (az, el, d) = dir(r, -15.0, 75.0);
        let strength: f32 = r.random_range(0.35..1.1);
        sh.add_directional(d, tint(r, strength));
        notes.push(format!(
            "ambient {a:.2}, key az {az:.0} el {el:.0} strength {strength:.2}"
        ));
        if r.random_range(0..10) < 7 {
            let (az, el, d) = dir(r, -10.0, 60.0);
            let strength: f32 = r.random_range(0.05..0.4);
            sh.add_directional(d, tint(r, strength));
            notes.push(format!("fill az {az:.0} el {el:.0} strength {strength:.2}"));
        }
        sh
    };
    let triples: Vec<String> = sh
        .coeffs
        .iter()
        .map(|c| format!("[{:?}, {:?}, {:?}]", c[0], c[1], c[2]))
        .collect();
    format!(
        "[lighting]\n# varied rig: {}\nsh = [{}]\n",
        notes.join("; "),
        triples.join(", ")
    )
}

impl Default for DatasetConfig {
    fn default() -> Self {
        Self {
            subjects: 4,
            poses: 2,
            views: 36,
            size: 256,
            points: 8000,
            surface_points: 4000,
            sigma_m: 0.05,
            val_fraction: 0.25,
            voxel_m: 0.005,
            threads: 1,
            seed: 0,
            pose_seed: None,
            lighting: DatasetLighting::Studio,
            hands: Hands::Rest,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("{0}")]
    Config(String),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("{path}: {msg}")]
    Write { path: String, msg: String },
}

impl DatasetError {
    /// Writing `path` failed.
    pub fn write(path: &Path, e: &dyn std::fmt::Display) -> Self {
        Self::Write {
            path: path.display().to_string(),
            msg: e.to_string(),
        }
    }
}

/// The wardrobe that [`random_subject`] draws from: the names of the pack's outfits, shoes,
/// hair and skins. Recorded in the dataset's manifest: the embedded runtime pack holds 3 of
/// the 9 outfits (2 of 4 shoes, 3 of 8 hair, 4 skins) that `volcap eval --data
/// ../shared/data/makehuman` dresses its held-out subjects in, and a pack's `source` names the
/// folder it was cut from, not what it kept (hands.md section 28: ten training runs drew from
/// the runtime pack unnoticed).
pub fn wardrobe(assets: &HumanAssets) -> BTreeMap<&'static str, Vec<String>> {
    let mut w = BTreeMap::new();
    for (key, kind) in [
        ("outfits", GarmentKind::Outfit),
        ("shoes", GarmentKind::Shoes),
        ("hair", GarmentKind::Hair),
    ] {
        w.insert(key, assets.garment_names(kind).cloned().collect());
    }
    w.insert("skins", assets.skins.keys().cloned().collect());
    w
}

/// A subject identity drawn from the seed, as a scene `[[subject]]` table.
fn random_subject(assets: &HumanAssets, r: &mut ChaCha8Rng, id: &str) -> String {
    let gender: f32 = r.random();
    let pick = |r: &mut ChaCha8Rng, kind: GarmentKind, prefer: &str| -> Option<String> {
        let all: Vec<&String> = assets.garment_names(kind).collect();
        let pref: Vec<&String> = all
            .iter()
            .copied()
            .filter(|n| n.starts_with(prefer))
            .collect();
        let from = if pref.is_empty() { &all } else { &pref };
        from.choose(r).map(|s| s.to_string())
    };
    let prefer = if gender > 0.5 { "male" } else { "female" };
    let mut t = format!(
        "[[subject]]\nid = \"{id}\"\ngender = {gender}\nmuscle = {}\nweight = {}\nheight = {}\n",
        r.random_range(0.3..0.8f32),
        r.random_range(0.3..0.8f32),
        r.random_range(0.3..0.7f32)
    );
    let race = r.random_range(0..3usize);
    t.push_str(&format!(
        "race = [{}, {}, {}]\n",
        (race == 0) as u8,
        (race == 1) as u8,
        (race == 2) as u8
    ));
    for (key, kind, pref) in [
        ("outfit", GarmentKind::Outfit, prefer),
        ("shoes", GarmentKind::Shoes, ""),
        ("hair", GarmentKind::Hair, ""),
    ] {
        if let Some(n) = pick(r, kind, pref) {
            t.push_str(&format!("{key} = \"{n}\"\n"));
        }
    }
    let skins: Vec<&String> = assets.skins.keys().collect();
    if let Some(s) = skins.choose(r) {
        t.push_str(&format!("skin = \"{s}\"\n"));
    }
    t
}

/// The scene of one dataset (or evaluation) image: the training camera (weak perspective,
/// 2.3 m image height, looking at 0.95 m), studio light, one subject in a procedural pose.
pub fn scene_text(size: usize, subject_table: &str, style: Style, seed: u32) -> String {
    scene_text_framed(
        size,
        subject_table,
        Motion::new(style, seed),
        WHOLE_HEIGHT_M,
        WHOLE_LOOK_AT_Y,
        STUDIO_LIGHTING,
    )
}

/// The dataset's framing: metres of the world the image height spans, and the height of the
/// point the camera looks at (the whole person in the frame).
pub const WHOLE_HEIGHT_M: f32 = 2.3;
pub const WHOLE_LOOK_AT_Y: f32 = 0.95;

/// The procedural motion of a dataset's (or an evaluation's) scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Motion {
    pub style: Style,
    pub seed: u32,
    pub hands: Hands,
}

impl Motion {
    /// `style` at `seed` with the hands at rest.
    pub fn new(style: Style, seed: u32) -> Self {
        Self {
            style,
            seed,
            hands: Hands::Rest,
        }
    }

    pub fn with_hands(self, hands: Hands) -> Self {
        Self { hands, ..self }
    }

    /// The scene file's `motion` value (`hands` only when not at rest, so that a rest
    /// motion's text is what it was before the key existed).
    fn toml(&self) -> String {
        let hands = match self.hands {
            Hands::Rest => String::new(),
            h => format!(", hands = \"{}\"", h.name()),
        };
        format!(
            "{{ kind = \"procedural\", style = \"{}\", seed = {}{hands} }}",
            self.style.name(),
            self.seed
        )
    }
}

/// [`scene_text`] with another weak-perspective framing and light: the image height spans
/// `height_m` metres around a look-at point `look_at_y` metres above the floor (a smaller span
/// higher up is a person close to the camera, cut by the frame's lower edge), lit by the
/// `[lighting]` table `lighting` ([`STUDIO_LIGHTING`], [`varied_lighting`]).
pub fn scene_text_framed(
    size: usize,
    subject_table: &str,
    motion: Motion,
    height_m: f32,
    look_at_y: f32,
    lighting: &str,
) -> String {
    format!(
        "[camera]\nwidth = {size}\nheight = {size}\nheight_m = {height_m:?}\nlook_at = [0.0, {look_at_y:?}, 0.0]\n{lighting}{subject_table}\
         motion = {}\n",
        motion.toml()
    )
}

/// The clothed surface of the last rendered frame in world metres: each subject's body
/// (without the eyes) and its garments, as one mesh.
pub fn clothed_surface(sim: &Simulator) -> Mesh {
    let mut surf = Mesh::default();
    for (closed, open) in &sim.world_meshes() {
        for m in closed.iter().take(1).chain(open.iter()) {
            let base = surf.vertices.len() as u32;
            surf.vertices.extend_from_slice(m.verts);
            surf.triangles
                .extend(m.tris.iter().map(|t| t.map(|i| i + base)));
        }
    }
    surf
}

/// Generate the dataset into `out`; `progress(images_done)` is called as images are written.
pub fn generate(
    assets: Arc<HumanAssets>,
    cfg: &DatasetConfig,
    out: &Path,
    mut progress: impl FnMut(u64),
) -> Result<u64, DatasetError> {
    if cfg.subjects < 2 || cfg.poses == 0 || cfg.views == 0 || cfg.points < 2 {
        return Err(DatasetError::Config(
            "need at least 2 subjects, 1 pose, 1 view and 2 points".into(),
        ));
    }
    if !(0.0..1.0).contains(&cfg.val_fraction) {
        return Err(DatasetError::Config(format!(
            "val fraction {} must be in [0, 1)",
            cfg.val_fraction
        )));
    }
    let mut r = ChaCha8Rng::seed_from_u64(cfg.seed);
    // Light rigs come from a stream of their own: the main stream (subjects, poses, views,
    // points) is the same whatever the lighting.
    let pose_seed = cfg.pose_seed.unwrap_or(cfg.seed);
    let mut light_r = ChaCha8Rng::seed_from_u64(pose_seed ^ 0x6c69_6768_7473);
    let ids: Vec<String> = (0..cfg.subjects).map(|i| format!("s{i:03}")).collect();
    let tables: Vec<String> = ids
        .iter()
        .map(|id| random_subject(&assets, &mut r, id))
        .collect();
    let mut order: Vec<usize> = (0..cfg.subjects).collect();
    order.shuffle(&mut r);
    let n_val =
        ((cfg.subjects as f32 * cfg.val_fraction).round() as usize).clamp(1, cfg.subjects - 1);
    let val: Vec<bool> = (0..cfg.subjects)
        .map(|i| order[..n_val].contains(&i))
        .collect();
    if let Some(ps) = cfg.pose_seed {
        // Identities and split are drawn; everything after comes from the pose seed.
        r = ChaCha8Rng::seed_from_u64(ps);
    }
    let werr = DatasetError::write;
    std::fs::create_dir_all(out).map_err(|e| werr(out, &e))?;
    let manifest = serde_json::json!({
        "format": "volcap-sim-dataset/1",
        // `surface`/`surface_rgb` hold the surface the views show ([`seen_surface`]); datasets
        // without the key sampled the whole clothed surface, the body under the clothes too.
        "surface": "seen",
        "seed": cfg.seed, "subjects": cfg.subjects, "poses": cfg.poses, "views": cfg.views, "size": cfg.size,
        "points": cfg.points, "surface_points": cfg.surface_points, "sigma_m": cfg.sigma_m, "voxel_m": cfg.voxel_m,
        "lighting": cfg.lighting.name(), "pose_seed": cfg.pose_seed, "hands": cfg.hands.name(),
        "assets": assets.source,
        "wardrobe": wardrobe(&assets),
        "split": ids.iter().zip(&val).map(|(id, v)| (id.clone(), if *v { "val" } else { "train" })).collect::<HashMap<_, _>>(),
        "subject_tables": ids.iter().zip(&tables).map(|(id, t)| (id.clone(), t.clone())).collect::<HashMap<_, _>>(),
    });
    let mpath = out.join("dataset.json");
    std::fs::write(
        &mpath,
        serde_json::to_string_pretty(&manifest).unwrap_or_default(),
    )
    .map_err(|e| werr(&mpath, &e))?;
    let mut writer = ShardWriter::new(shards::threads(cfg.threads));
    for (si, table) in tables.iter().enumerate() {
        let split = if val[si] { "val" } else { "train" };
        let dir = out.join(split).join(&ids[si]);
        std::fs::create_dir_all(&dir).map_err(|e| werr(&dir, &e))?;
        for pi in 0..cfg.poses {
            let style = Style::ALL[r.random_range(0..Style::ALL.len())];
            let frame: u64 = r.random_range(0..60);
            let lighting = match cfg.lighting {
                DatasetLighting::Studio => STUDIO_LIGHTING.to_string(),
                DatasetLighting::Varied => varied_lighting(&mut light_r),
            };
            let text = scene_text_framed(
                cfg.size,
                table,
                Motion::new(style, r.random::<u32>()).with_hands(cfg.hands),
                WHOLE_HEIGHT_M,
                WHOLE_LOOK_AT_Y,
                &lighting,
            );
            let scene = Scene::parse(&text, Path::new("<dataset>"))
                .map_err(|e| DatasetError::Config(e.to_string()))?;
            let mut sim = Simulator::new(scene, assets.clone())?;
            sim.render(frame)?;
            let field = Arc::new(sim.oracle(cfg.voxel_m));
            // World-space samples shared by the views of this pose.
            let surf = clothed_surface(&sim);
            let (lo, hi) = surf
                .vertices
                .iter()
                .fold((Vec3::MAX, Vec3::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
            let pad = Vec3::splat(0.1);
            let half = cfg.points / 2;
            let (mut ins, mut outs): (Vec<Vec3>, Vec<Vec3>) =
                (Vec::with_capacity(half), Vec::with_capacity(half));
            let mut rounds = 0;
            while (ins.len() < half || outs.len() < half) && rounds < 50 {
                rounds += 1;
                let near = sample_surface(&surf, cfg.points, r.random());
                for (k, p) in near.iter().enumerate() {
                    let p = if k % 10 == 0 {
                        // 10% uniform in the padded box.
                        Vec3::new(
                            r.random_range(lo.x - pad.x..hi.x + pad.x),
                            r.random_range(lo.y - pad.y..hi.y + pad.y),
                            r.random_range(lo.z - pad.z..hi.z + pad.z),
                        )
                    } else {
                        let g = DVec3::new(gauss(&mut r), gauss(&mut r), gauss(&mut r))
                            * cfg.sigma_m as f64;
                        (*p + g).as_vec3()
                    };
                    if field.oracle.contains(p) {
                        if ins.len() < half {
                            ins.push(p);
                        }
                    } else if outs.len() < half {
                        outs.push(p);
                    }
                }
            }
            // The seed of the views' coloured surface samples (one draw, as ever: the poses,
            // views and light rigs of a seed stay what they were).
            let surface_seed: u64 = r.random();
            let labels: Arc<Vec<f32>> = Arc::new(
                std::iter::repeat_n(1.0f32, ins.len())
                    .chain(std::iter::repeat_n(0.0, outs.len()))
                    .collect(),
            );
            let world_pts: Arc<Vec<Vec3>> = Arc::new(ins.iter().chain(&outs).copied().collect());
            // Views evenly around the subject from a random phase per pose.
            let phase: f32 = r.random_range(0.0..360.0 / cfg.views as f32);
            for vi in 0..cfg.views {
                let yaw = phase + 360.0 * vi as f32 / cfg.views as f32;
                sim.set_view_yaw(yaw);
                let f = sim.render(frame)?;
                // One metadata key holding sorted JSON: byte-identical files for a seed.
                let info = serde_json::json!({
                    "camera": f.camera,
                    "subject": ids[si],
                    "subject_table": table,
                    "style": style.name(),
                    "time_s": f.time_s,
                    "yaw_deg": yaw,
                    "split": split,
                    "scene": text,
                    "frame": frame,
                });
                let job = ViewJob {
                    path: dir.join(format!("{pi:03}_{vi:02}.safetensors")),
                    frame: f,
                    field: field.clone(),
                    points: world_pts.clone(),
                    labels: labels.clone(),
                    surface_points: cfg.surface_points,
                    surface_seed: surface_seed ^ vi as u64,
                    info: info.to_string(),
                };
                writer.write(job, &mut progress)?;
            }
        }
    }
    writer.finish(&mut progress)
}

/// `count` points (world metres) of the surface a view's rays meet first and last, half
/// each, on pixels drawn uniformly among those whose ray holds anything: the surface seen
/// from the camera and from straight behind it, what the turned views show and what the
/// colour networks learn (`surface` / `surface_rgb`). Not samples of the whole clothed
/// surface: that holds the body under the clothes, whose nearest-triangle colour is skin
/// that no view shows (the colour networks trained on it painted turned views skin-grey,
/// docs/eval/hands.md section 30). Empty when no ray holds anything.
pub fn seen_surface(
    rays: &crate::rays::RayIntervals,
    view: &crate::camera::Projector,
    count: usize,
    seed: u64,
) -> Vec<Vec3> {
    let (w, h) = (rays.width, rays.height);
    let hit: Vec<usize> = (0..w * h)
        .filter(|p| rays.offsets[*p + 1] > rays.offsets[*p])
        .collect();
    if hit.is_empty() {
        return Vec::new();
    }
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|k| {
            let p = hit[r.random_range(0..hit.len())];
            let (i, j) = (p % w, p / w);
            let iv = rays.pixel(i, j);
            // Nearest the camera: the largest z; farthest: the smallest (`RayIntervals`).
            let z = if k % 2 == 0 {
                iv.iter().map(|v| v[1]).fold(f32::MIN, f32::max)
            } else {
                iv.iter().map(|v| v[0]).fold(f32::MAX, f32::min)
            };
            let x = -1.0 + 2.0 * i as f32 / (w.max(2) - 1) as f32;
            let y = -1.0 + 2.0 * j as f32 / (h.max(2) - 1) as f32;
            view.ndc_to_world(Vec3::new(x, y, z))
        })
        .collect()
}

fn gauss(r: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = r.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = r.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
