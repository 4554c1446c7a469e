//! The simulator: a scene over human assets, frame by frame, with ground truth.

use crate::assets::{GarmentKind, HumanAssets};
use crate::camera::{Camera, Projection};
use crate::effects::{self, BoxShape, FrameMeta, Hook, Image, Phase, Stage};
use crate::oracle::{ColorMesh, ColorOracle, Oracle, SceneField, WorldMesh};
use crate::pose::{Procedural, Rig, static_pose};
use crate::raster::{DrawMesh, Framebuffer, Rasterizer, Sh9, Texture, vertex_normals};
use crate::scene::{CameraModel, LightPreset, MotionSpec, Procedural as Bg, Scene, SceneError};
use crate::subject::{Posed, Subject, SubjectError};
use glam::{Mat3, Quat, Vec3};
use rand::{Rng, SeedableRng};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The scene's `unplug` effect: the camera is gone from this frame on.
    #[error("camera unplugged at frame {frame}")]
    Unplugged { frame: u64 },
    /// The scene's `hang` effect: the camera driver stops answering at this frame. The
    /// simulator returns at once; a camera built on it must then block, as a hung driver does.
    #[error("camera driver hung at frame {frame}")]
    Hung { frame: u64 },
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Subject(#[from] SubjectError),
    #[error("{0}")]
    Asset(String),
}

/// Default skin albedo where a subject has no skin texture.
const SKIN_RGB: [f32; 3] = [0.80, 0.62, 0.52];
/// Mask id of the occluder.
pub const OCCLUDER_ID: u8 = 255;

enum Motion {
    Static(Vec<Mat3>),
    Procedural(Procedural),
}

struct SubjectRt {
    subject: Subject,
    rig: Rig,
    motion: Motion,
    position: Vec3,
    yaw: f32,
    skin: Option<Arc<Texture>>,
    rot: Vec<Mat3>,
    posed: Posed,
    normals: Vec<Vec3>,
    garment_normals: Vec<Vec<Vec3>>,
}

/// One rendered frame with its ground truth.
#[derive(Debug, Clone)]
pub struct SimFrame {
    pub index: u64,
    pub time_s: f64,
    pub width: usize,
    pub height: usize,
    /// RGB8, row-major.
    pub rgb: Vec<u8>,
    /// Per pixel: 0 background, 1.. subject index + 1, 255 occluder.
    pub ids: Vec<u8>,
    /// Metres along the view direction; infinite where nothing was drawn.
    pub depth_m: Vec<f32>,
    pub camera: Camera,
    pub meta: FrameMeta,
}

impl SimFrame {
    /// The person mask: 255 where any subject is visible.
    pub fn person_mask(&self) -> Vec<u8> {
        self.ids
            .iter()
            .map(|&i| if i != 0 && i != OCCLUDER_ID { 255 } else { 0 })
            .collect()
    }
}

pub struct Simulator {
    scene: Scene,
    assets: Arc<HumanAssets>,
    subjects: Vec<SubjectRt>,
    stages: Vec<Box<dyn Stage>>,
    counts: BTreeMap<&'static str, u64>,
    textures: HashMap<String, Arc<Texture>>,
    raster: Rasterizer,
    fb: Framebuffer,
    background: Vec<[f32; 3]>,
    sh: Sh9,
    boxes: Vec<BoxShape>,
    camera: Camera,
}

fn decode(bytes: &[u8], what: &str) -> Result<Arc<Texture>, SimError> {
    Texture::decode(bytes)
        .map(Arc::new)
        .map_err(|e| SimError::Asset(format!("texture of {what}: {e}")))
}

/// The scene camera before per-frame effects.
pub fn scene_camera(scene: &Scene) -> Camera {
    let c = &scene.camera;
    let look = Vec3::new(c.look_at[0].0, c.look_at[1].0, c.look_at[2].0);
    let (yaw, pitch) = (c.yaw.0.to_radians(), c.pitch.0.to_radians());
    let dir = Vec3::new(
        yaw.sin() * pitch.cos(),
        pitch.sin(),
        yaw.cos() * pitch.cos(),
    );
    let d = c.distance.0;
    let (w, h) = (c.width.0, c.height.0);
    let projection = match c.model {
        CameraModel::WeakPerspective => Projection::WeakPerspective {
            height_m: c.height_m.0,
        },
        CameraModel::Pinhole => {
            let fy = 0.5 * h as f32 / (0.5 * c.fov_y.0.to_radians()).tan();
            Projection::Pinhole {
                fx: fy,
                fy,
                cx: 0.5 * (w as f32 - 1.0),
                cy: 0.5 * (h as f32 - 1.0),
            }
        }
    };
    Camera {
        width: w,
        height: h,
        eye: look + dir * d,
        target: look,
        projection,
        near: (d - 1.5).max(0.05),
        far: d + 1.5,
    }
}

fn lighting(scene: &Scene) -> Sh9 {
    if let Some(sh) = &scene.lighting.sh {
        let mut coeffs = [[0.0; 3]; 9];
        for (c, v) in coeffs.iter_mut().zip(sh) {
            *c = v.map(|x| x.0);
        }
        return Sh9 { coeffs };
    }
    match scene.lighting.preset.unwrap_or(LightPreset::Studio) {
        LightPreset::Studio => {
            let mut s = Sh9::ambient([0.38; 3]);
            s.add_directional(Vec3::new(-0.4, 0.6, 0.7), [0.75, 0.72, 0.68]);
            s.add_directional(Vec3::new(0.6, 0.2, 0.6), [0.2, 0.22, 0.25]);
            s
        }
        LightPreset::Side => {
            let mut s = Sh9::ambient([0.12; 3]);
            s.add_directional(Vec3::new(1.0, 0.25, 0.1), [1.15, 1.1, 1.0]);
            s
        }
        LightPreset::Back => {
            let mut s = Sh9::ambient([0.25; 3]);
            s.add_directional(Vec3::new(0.1, 0.5, -1.0), [0.9, 0.9, 0.95]);
            s
        }
        LightPreset::Flat => Sh9::ambient([1.0; 3]),
    }
}

fn background(scene: &Scene, w: usize, h: usize) -> Result<Vec<[f32; 3]>, SimError> {
    let b = &scene.background;
    if let Some(img) = &b.image {
        let p = scene.resolve(img.get_ref());
        let im = image::open(&p)
            .map_err(|e| SimError::Asset(format!("{}: background image: {e}", p.display())))?;
        let im = im
            .resize_exact(w as u32, h as u32, image::imageops::FilterType::Triangle)
            .to_rgb8();
        return Ok(im.pixels().map(|p| p.0.map(|v| v as f32 / 255.0)).collect());
    }
    let base = b.color.map(|c| c.map(|x| x.0)).unwrap_or([0.18, 0.2, 0.24]);
    let mut out = vec![base; w * h];
    match b.procedural {
        None => {}
        Some(Bg::Checker) => {
            for (i, px) in out.iter_mut().enumerate() {
                let (x, y) = (i % w, i / w);
                if ((x / 32) + (y / 32)) % 2 == 0 {
                    *px = px.map(|c| (c * 1.6).min(1.0));
                }
            }
        }
        Some(Bg::Gradient) => {
            for (i, px) in out.iter_mut().enumerate() {
                let t = (i / w) as f32 / h.max(2) as f32;
                *px = [
                    base[0] * (1.4 - t),
                    base[1] * (1.3 - 0.6 * t),
                    base[2] * (0.8 + 0.6 * t),
                ]
                .map(|c| c.clamp(0.0, 1.0));
            }
        }
        Some(Bg::Noise) => {
            let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(b.seed);
            let cells = 16;
            let lattice: Vec<f32> = (0..(cells + 1) * (cells + 1))
                .map(|_| r.random_range(0.6..1.4))
                .collect();
            for (i, px) in out.iter_mut().enumerate() {
                let (x, y) = (
                    (i % w) as f32 / w as f32 * cells as f32,
                    (i / w) as f32 / h as f32 * cells as f32,
                );
                let (x0, y0) = (x.floor() as usize, y.floor() as usize);
                let (fx, fy) = (x - x0 as f32, y - y0 as f32);
                let l = |a: usize, b: usize| lattice[a.min(cells) + (cells + 1) * b.min(cells)];
                let v = (l(x0, y0) * (1.0 - fx) + l(x0 + 1, y0) * fx) * (1.0 - fy)
                    + (l(x0, y0 + 1) * (1.0 - fx) + l(x0 + 1, y0 + 1) * fx) * fy;
                *px = px.map(|c| (c * v).clamp(0.0, 1.0));
            }
        }
    }
    Ok(out)
}

fn box_mesh(b: &BoxShape) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let h = b.size * 0.5;
    let v: Vec<Vec3> = (0..8)
        .map(|i| {
            b.center
                + Vec3::new(
                    if i & 1 == 1 { h.x } else { -h.x },
                    if i & 2 == 2 { h.y } else { -h.y },
                    if i & 4 == 4 { h.z } else { -h.z },
                )
        })
        .collect();
    // Outward counter-clockwise faces.
    let q = |a: u32, b: u32, c: u32, d: u32| [[a, b, c], [a, c, d]];
    let mut t = Vec::new();
    for f in [
        q(0, 2, 3, 1),
        q(4, 5, 7, 6),
        q(0, 1, 5, 4),
        q(2, 6, 7, 3),
        q(0, 4, 6, 2),
        q(1, 3, 7, 5),
    ] {
        t.extend(f);
    }
    (v, t)
}

impl Simulator {
    /// Build a simulator for `scene` on `assets`. Names are checked against the assets.
    pub fn new(scene: Scene, assets: Arc<HumanAssets>) -> Result<Self, SimError> {
        scene.check_names(&assets)?;
        let mut subjects = Vec::new();
        let mut textures = HashMap::new();
        for entry in &scene.subjects {
            let spec = entry.spec();
            let subject = Subject::new(&assets, &spec)?;
            for g in &subject.garments {
                if let Some(t) = &assets.garments[g].material.texture
                    && !textures.contains_key(g)
                {
                    textures.insert(g.clone(), decode(&t.bytes, g)?);
                }
            }
            let skin = match &spec.skin {
                Some(s) => assets.skins[s]
                    .texture
                    .as_ref()
                    .map(|t| decode(&t.bytes, s))
                    .transpose()?,
                None => None,
            };
            let rig = Rig::new(&assets, &subject.heads);
            let motion = match &entry.motion {
                MotionSpec::Static { pose: p } | MotionSpec::Clip { clip: p } => {
                    let mut rot = Vec::new();
                    if p == "rest" {
                        rot.resize(assets.bones.len(), Mat3::IDENTITY);
                    } else {
                        static_pose(&assets, p, &mut rot).map_err(SimError::Asset)?;
                    }
                    Motion::Static(rot)
                }
                MotionSpec::Procedural {
                    style,
                    seed,
                    period,
                    hands,
                } => {
                    Motion::Procedural(Procedural::new(*style, *seed, period.0).with_hands(*hands))
                }
            };
            subjects.push(SubjectRt {
                subject,
                rig,
                motion,
                position: Vec3::new(
                    entry.position[0].0,
                    entry.position[1].0,
                    entry.position[2].0,
                ),
                yaw: entry.yaw.0.to_radians(),
                skin,
                rot: Vec::new(),
                posed: Posed::default(),
                normals: Vec::new(),
                garment_normals: Vec::new(),
            });
        }
        let camera = scene_camera(&scene);
        let (w, h) = (camera.width, camera.height);
        Ok(Self {
            stages: effects::build(&scene.effects),
            counts: BTreeMap::new(),
            background: background(&scene, w, h)?,
            sh: lighting(&scene),
            fb: Framebuffer::new(w, h),
            raster: Rasterizer::default(),
            boxes: Vec::new(),
            textures,
            subjects,
            camera,
            scene,
            assets,
        })
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn assets(&self) -> &Arc<HumanAssets> {
        &self.assets
    }

    /// Orbit the camera to `yaw_deg` about the look-at point (datasets render many views).
    pub fn set_view_yaw(&mut self, yaw_deg: f32) {
        self.scene.camera.yaw = crate::scene::Angle(yaw_deg.rem_euclid(360.0));
    }

    /// How often each declared effect stage ran (undeclared effects never appear).
    pub fn stage_invocations(&self) -> &BTreeMap<&'static str, u64> {
        &self.counts
    }

    /// Time of frame `index` in seconds.
    pub fn time_of(&self, index: u64) -> f64 {
        index as f64 / self.scene.camera.fps.0 as f64
    }

    /// Pose every subject for time `t` (world metres), computing normals.
    fn pose_all(&mut self, t: f64) {
        let assets = &self.assets;
        for s in &mut self.subjects {
            match &s.motion {
                Motion::Static(r) => s.rot.clone_from(r),
                Motion::Procedural(p) => s.rig.rotations(&p.angles(t as f32), &mut s.rot),
            }
            s.subject.pose(assets, &s.rot, &mut s.posed);
            let q = Quat::from_rotation_y(s.yaw);
            for v in s
                .posed
                .verts
                .iter_mut()
                .chain(s.posed.garments.iter_mut().flatten())
            {
                *v = q * *v + s.position;
            }
            vertex_normals(&s.posed.verts, &assets.body_tris, &mut s.normals);
            s.garment_normals
                .resize_with(s.posed.garments.len(), Vec::new);
            for ((g, gv), gn) in s
                .subject
                .garments
                .iter()
                .zip(&s.posed.garments)
                .zip(&mut s.garment_normals)
            {
                vertex_normals(gv, &assets.garments[g].tris, gn);
            }
        }
    }

    fn run_stages(
        &mut self,
        phase: Phase,
        index: u64,
        t: f64,
        mut f: impl FnMut(&mut dyn Stage, u64, f64),
    ) {
        for s in self.stages.iter_mut().filter(|s| s.phase() == phase) {
            *self.counts.entry(s.kind()).or_default() += 1;
            f(s.as_mut(), index, t);
        }
    }

    /// Render frame `index`.
    pub fn render(&mut self, index: u64) -> Result<SimFrame, SimError> {
        let t = self.time_of(index);
        let (mut exists, mut hangs) = (true, false);
        self.run_stages(Phase::Source, index, t, |s, i, _| {
            exists &= s.frame_exists(i);
            hangs |= s.frame_hangs(i);
        });
        if hangs {
            return Err(SimError::Hung { frame: index });
        }
        if !exists {
            return Err(SimError::Unplugged { frame: index });
        }
        let mut cam = scene_camera(&self.scene);
        self.run_stages(Phase::Camera, index, t, |s, i, t| {
            s.apply(i, t, Hook::Camera(&mut cam))
        });
        self.camera = cam;
        self.pose_all(t);
        let mut boxes = std::mem::take(&mut self.boxes);
        boxes.clear();
        self.run_stages(Phase::Geometry, index, t, |s, i, t| {
            s.apply(i, t, Hook::Geometry(&mut boxes))
        });
        self.fb.clear(&self.background);
        let assets = &self.assets;
        for (si, s) in self.subjects.iter().enumerate() {
            let id = (si + 1).min(254) as u8;
            self.raster.draw(
                &mut self.fb,
                &cam,
                &self.sh,
                &DrawMesh {
                    verts: &s.posed.verts,
                    normals: &s.normals,
                    tris: &s.subject.visible_body_tris,
                    uv_tris: &s.subject.visible_body_uv_tris,
                    uvs: &assets.body_uvs,
                    texture: s.skin.as_deref(),
                    color: if s.skin.is_some() { [1.0; 3] } else { SKIN_RGB },
                    alpha_test: false,
                    cull_back: true,
                    id,
                },
            );
            for ((g, gv), gn) in s
                .subject
                .garments
                .iter()
                .zip(&s.posed.garments)
                .zip(&s.garment_normals)
            {
                let def = &assets.garments[g];
                self.raster.draw(
                    &mut self.fb,
                    &cam,
                    &self.sh,
                    &DrawMesh {
                        verts: gv,
                        normals: gn,
                        tris: &def.tris,
                        uv_tris: &def.uv_tris,
                        uvs: &def.uvs,
                        texture: self.textures.get(g).map(|t| t.as_ref()),
                        color: def.material.diffuse_color,
                        alpha_test: def.material.alpha || def.kind == GarmentKind::Hair,
                        cull_back: false,
                        id,
                    },
                );
            }
        }
        for b in &boxes {
            let (v, tris) = box_mesh(b);
            let mut n = Vec::new();
            vertex_normals(&v, &tris, &mut n);
            self.raster.draw(
                &mut self.fb,
                &cam,
                &self.sh,
                &DrawMesh {
                    verts: &v,
                    normals: &n,
                    tris: &tris,
                    uv_tris: &[],
                    uvs: &[],
                    texture: None,
                    color: b.color,
                    alpha_test: false,
                    cull_back: true,
                    id: OCCLUDER_ID,
                },
            );
        }
        self.boxes = boxes;
        let mut meta = FrameMeta::default();
        let (w, h) = (self.fb.width, self.fb.height);
        let mut color = std::mem::take(&mut self.fb.color);
        for phase in [
            Phase::Optics,
            Phase::Blur,
            Phase::Shutter,
            Phase::Exposure,
            Phase::Noise,
            Phase::Codec,
        ] {
            self.run_stages(phase, index, t, |s, i, t| {
                let mut img = Image {
                    width: w,
                    height: h,
                    rgb: &mut color,
                };
                s.apply(i, t, Hook::Image(&mut img, &mut meta));
            });
        }
        let rgb = volcap_engine::render::rgb8(&color);
        self.fb.color = color;
        Ok(SimFrame {
            index,
            time_s: t,
            width: w,
            height: h,
            rgb,
            ids: self.fb.id.clone(),
            depth_m: self.fb.depth.clone(),
            camera: cam,
            meta,
        })
    }

    /// The posed meshes of the last rendered frame, per subject: (closed solids, open shells).
    pub fn world_meshes(&self) -> Vec<(Vec<WorldMesh<'_>>, Vec<WorldMesh<'_>>)> {
        self.subjects
            .iter()
            .map(|s| {
                let closed = vec![
                    WorldMesh {
                        verts: &s.posed.verts,
                        tris: &self.assets.body_tris,
                        closed: true,
                    },
                    WorldMesh {
                        verts: &s.posed.verts,
                        tris: &self.assets.eye_tris,
                        closed: true,
                    },
                ];
                let open = s
                    .subject
                    .garments
                    .iter()
                    .zip(&s.posed.garments)
                    .map(|(g, gv)| WorldMesh {
                        verts: gv,
                        tris: &self.assets.garments[g].tris,
                        closed: false,
                    })
                    .collect();
                (closed, open)
            })
            .collect()
    }

    /// An owned copy of the last rendered frame's posed geometry and materials, to build the
    /// oracle elsewhere (e.g. on a compute thread while the simulator renders on).
    pub fn ground_truth(&self) -> GroundTruth {
        let mut closed = Vec::new();
        let mut open = Vec::new();
        let mut colors = Vec::new();
        for s in &self.subjects {
            let verts = Arc::new(s.posed.verts.clone());
            closed.push((verts.clone(), Arc::new(self.assets.body_tris.clone())));
            closed.push((verts.clone(), Arc::new(self.assets.eye_tris.clone())));
            colors.push(ColorMesh {
                verts: s.posed.verts.clone(),
                tris: s.subject.visible_body_tris.clone(),
                uv_tris: s.subject.visible_body_uv_tris.clone(),
                uvs: self.assets.body_uvs.clone(),
                texture: s.skin.clone(),
                color: if s.skin.is_some() { [1.0; 3] } else { SKIN_RGB },
            });
            for (g, gv) in s.subject.garments.iter().zip(&s.posed.garments) {
                let def = &self.assets.garments[g];
                open.push((Arc::new(gv.clone()), Arc::new(def.tris.clone())));
                colors.push(ColorMesh {
                    verts: gv.clone(),
                    tris: def.tris.clone(),
                    uv_tris: def.uv_tris.clone(),
                    uvs: def.uvs.clone(),
                    texture: self.textures.get(g).cloned(),
                    color: def.material.diffuse_color,
                });
            }
        }
        GroundTruth {
            closed,
            open,
            colors,
            camera: self.camera,
        }
    }

    /// The occupancy and colour oracle of the last rendered frame, as an engine field over
    /// that frame's render view. `voxel_m` is the voxel size (e.g. [`crate::oracle::DEFAULT_VOXEL_M`]).
    pub fn oracle(&self, voxel_m: f32) -> SceneField {
        let gt = self.ground_truth();
        let camera = gt.camera;
        gt.into_field(voxel_m, camera)
    }

    /// Subject ids and, for procedural motion, the joint angles at the last frame (for the
    /// per-frame JSON).
    pub fn subject_info(&self, t: f64) -> Vec<serde_json::Value> {
        self.scene
            .subjects
            .iter()
            .zip(&self.subjects)
            .map(|(e, s)| {
                let motion = match &s.motion {
                    Motion::Static(_) => serde_json::json!({"kind": "static"}),
                    Motion::Procedural(p) => {
                        let a = p.angles(t as f32);
                        serde_json::json!({"kind": "procedural", "style": p.style.name(), "root_yaw": a.root_yaw,
                            "hip_flex": a.hip_flex, "knee": a.knee, "shoulder_abd": a.shoulder_abd, "shoulder_flex": a.shoulder_flex,
                            "elbow": a.elbow, "spine_flex": a.spine_flex, "spine_side": a.spine_side,
                            "hands": p.hands().name(), "forearm_twist": a.forearm_twist, "wrist_flex": a.wrist_flex,
                            "wrist_dev": a.wrist_dev, "finger_curl": a.finger_curl})
                    }
                };
                serde_json::json!({"id": e.id, "outfit": s.subject.spec.outfit, "hair": s.subject.spec.hair,
                    "shoes": s.subject.spec.shoes, "skin": s.subject.spec.skin, "gender": s.subject.spec.gender, "motion": motion})
            })
            .collect()
    }
}

type SharedMesh = (Arc<Vec<Vec3>>, Arc<Vec<[u32; 3]>>);

/// Posed geometry and materials of one frame, owned (see [`Simulator::ground_truth`]).
pub struct GroundTruth {
    closed: Vec<SharedMesh>,
    open: Vec<SharedMesh>,
    colors: Vec<ColorMesh>,
    /// The camera the frame was rendered with.
    pub camera: Camera,
}

impl GroundTruth {
    /// The occupancy + colour oracle as an engine field over `view`'s render-view NDC cube.
    pub fn into_field(self, voxel_m: f32, view: Camera) -> SceneField {
        let meshes: Vec<WorldMesh> = self
            .closed
            .iter()
            .map(|(v, t)| WorldMesh {
                verts: v,
                tris: t,
                closed: true,
            })
            .chain(self.open.iter().map(|(v, t)| WorldMesh {
                verts: v,
                tris: t,
                closed: false,
            }))
            .collect();
        let oracle = Oracle::build(&meshes, voxel_m);
        SceneField {
            oracle,
            colors: ColorOracle::new(self.colors),
            camera: view,
        }
    }
}
