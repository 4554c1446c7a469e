//! The human assets the simulator runs on, in one in-memory form, whether loaded from the
//! full MakeHuman folder or from the compact runtime pack (a serialized subset of the same
//! struct, built by `volcap sim pack`, embedded in the binary so the product needs no
//! `../shared`).
//!
//! Units are MakeHuman's: decimetres, y up, the character faces +z, +x is its left.

use crate::makehuman::{self as mh, AssetError, Influences};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::Path;

/// Pack format version; bump when the struct changes.
pub const PACK_VERSION: u32 = 1;

/// The runtime pack compiled into the binary.
pub static EMBEDDED_PACK: &[u8] = include_bytes!("../assets/human-pack.bin.gz");

/// A sparse morph target, quantized: offsets in units of 1e-4 dm (0.01 mm).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Target {
    pub idx: Vec<u32>,
    pub delta: Vec<[i32; 3]>,
}

pub const TARGET_QUANTUM: f32 = 1e-4;

/// An encoded texture (JPEG or PNG bytes) as stored in the pack.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TextureBytes {
    pub bytes: Vec<u8>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct MaterialDef {
    pub diffuse_color: [f32; 3],
    pub texture: Option<TextureBytes>,
    /// Alpha-tested (hair cards).
    pub alpha: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum GarmentKind {
    Outfit,
    Shoes,
    Hair,
    Hat,
}

/// A garment fitted to the base mesh (MANIFEST 4.4).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GarmentDef {
    pub kind: GarmentKind,
    pub tris: Vec<[u32; 3]>,
    pub uv_tris: Vec<[u32; 3]>,
    pub uvs: Vec<[f32; 2]>,
    pub fit_idx: Vec<[u32; 3]>,
    pub fit_w: Vec<[f32; 3]>,
    pub fit_off: Vec<[f32; 3]>,
    pub scale: [(u32, u32, f32); 3],
    pub delete_verts: Vec<u32>,
    pub material: MaterialDef,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BoneDef {
    pub name: String,
    pub head: u32,
    pub tail: u32,
    pub parent: Option<u32>,
}

/// Everything needed to build, pose, dress and render subjects.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HumanAssets {
    pub version: u32,
    /// Where the data came from (for model cards and logs).
    pub source: String,
    /// All base-mesh vertices (body, helpers, joint cubes), rest pose.
    pub base: Vec<[f32; 3]>,
    pub body_tris: Vec<[u32; 3]>,
    pub body_uv_tris: Vec<[u32; 3]>,
    pub body_uvs: Vec<[f32; 2]>,
    /// Closed eye spheres (helper-l-eye, helper-r-eye), for occupancy.
    pub eye_tris: Vec<[u32; 3]>,
    /// Macro and modifier targets by path below `targets/` without extension,
    /// e.g. `macrodetails/caucasian-female-young`.
    pub targets: BTreeMap<String, Target>,
    pub joints: Vec<Vec<u32>>,
    pub joint_names: Vec<String>,
    pub bones: Vec<BoneDef>,
    pub weights: Vec<Influences>,
    pub garments: BTreeMap<String, GarmentDef>,
    pub skins: BTreeMap<String, MaterialDef>,
    /// Static poses: bone name -> rotation (mesh frame, column-major 3x3).
    pub poses: BTreeMap<String, BTreeMap<String, [f32; 9]>>,
}

/// What to take from the full data.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Target name filter (paths below `targets/` without extension).
    pub targets: fn(&str) -> bool,
    pub outfits: Vec<String>,
    pub shoes: Vec<String>,
    pub hair: Vec<String>,
    pub hats: Vec<String>,
    pub skins: Vec<String>,
    pub poses: Vec<String>,
    /// Longest texture side in the result (textures are downscaled to it).
    pub texture_px: u32,
}

/// Targets of young adults: race x gender, muscle x weight, height at average build.
pub fn runtime_targets(name: &str) -> bool {
    let Some(rest) = name.strip_prefix("macrodetails/") else {
        return false;
    };
    if let Some(h) = rest.strip_prefix("height/") {
        return h.contains("-young-averagemuscle-averageweight-");
    }
    !rest.contains('/') && rest.contains("-young")
}

impl Selection {
    /// The runtime pack: a few MB.
    pub fn runtime() -> Self {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect();
        Self {
            targets: runtime_targets,
            outfits: s(&[
                "male_casualsuit02",
                "female_casualsuit01",
                "male_casualsuit03",
            ]),
            shoes: s(&["shoes01", "shoes02"]),
            hair: s(&["short02", "bob02", "ponytail01"]),
            hats: vec![],
            skins: s(&[
                "young_caucasian_male",
                "young_caucasian_female2",
                "young_african_male",
                "young_asian_female",
            ]),
            poses: s(&["tpose", "benchmark"]),
            texture_px: 256,
        }
    }

    /// The runtime pack's bodies (its macro targets) in the whole wardrobe of the folder
    /// (every outfit, shoe, hair, hat and skin; textures at `texture_px`): a training set's
    /// clothes where the whole pack (about 38 MB) does not fit, as beside the checkout on a
    /// lent GPU machine (tools/train/recipe/make_bundle.sh --lean). The held-out evaluation
    /// dresses its subjects from the whole wardrobe (docs/eval/hands.md section 28).
    pub fn wardrobe(dir: &Path, texture_px: u32) -> Self {
        Self {
            targets: runtime_targets,
            texture_px,
            ..Self::everything(dir)
        }
    }

    /// Everything in the folder (training data generation).
    pub fn everything(dir: &Path) -> Self {
        let list = |sub: &str, f: &dyn Fn(&str) -> bool| -> Vec<String> {
            let mut v: Vec<String> = std::fs::read_dir(dir.join(sub))
                .into_iter()
                .flatten()
                .flatten()
                .filter(|e| e.path().is_dir())
                .map(|e| e.file_name().to_string_lossy().to_string())
                .filter(|n| f(n))
                .collect();
            v.sort();
            v
        };
        Self {
            targets: |n| n.starts_with("macrodetails/"),
            outfits: list("clothes", &|n| n.contains("suit")),
            shoes: list("clothes", &|n| n.starts_with("shoes")),
            hair: list("hair", &|_| true),
            hats: list("clothes", &|n| n.starts_with("fedora")),
            skins: list("skins", &|_| true),
            poses: vec!["tpose".into(), "benchmark".into()],
            texture_px: 512,
        }
    }
}

fn encode_texture(path: &Path, px: u32) -> Result<TextureBytes, AssetError> {
    let img = image::open(path).map_err(|e| AssetError::Invalid {
        path: path.into(),
        msg: e.to_string(),
    })?;
    let img = if img.width() > px || img.height() > px {
        img.resize(px, px, image::imageops::FilterType::Triangle)
    } else {
        img
    };
    let mut bytes = Vec::new();
    let has_alpha = img.color().has_alpha();
    if has_alpha {
        img.to_rgba8()
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .map_err(|e| AssetError::Invalid {
                path: path.into(),
                msg: e.to_string(),
            })?;
    } else {
        let rgb = img.to_rgb8();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 88)
            .encode_image(&rgb)
            .map_err(|e| AssetError::Invalid {
                path: path.into(),
                msg: e.to_string(),
            })?;
    }
    Ok(TextureBytes { bytes })
}

fn material(mhmat: &Path, px: u32, alpha: bool) -> Result<MaterialDef, AssetError> {
    let m = mh::read_mhmat(mhmat)?;
    let texture = match &m.diffuse_texture {
        Some(p) if p.exists() => Some(encode_texture(p, px)?),
        _ => None,
    };
    Ok(MaterialDef {
        diffuse_color: m.diffuse_color,
        texture,
        alpha: alpha || m.transparent,
    })
}

impl HumanAssets {
    /// The names of the garments of one kind, in name order (what a subject is dressed from).
    pub fn garment_names(&self, kind: GarmentKind) -> impl Iterator<Item = &String> {
        self.garments
            .iter()
            .filter(move |(_, g)| g.kind == kind)
            .map(|(n, _)| n)
    }

    /// Load from the full MakeHuman folder (`../shared/data/makehuman`).
    pub fn from_makehuman(dir: &Path, sel: &Selection) -> Result<Self, AssetError> {
        let obj = mh::read_obj(&dir.join("3dobjs/base.obj"))?;
        let nv = obj.positions.len();
        let (body_tris, body_uv_tris) = obj.triangles(|g| g == "body");
        let (eye_tris, _) = obj.triangles(|g| g == "helper-l-eye" || g == "helper-r-eye");
        let mut targets = BTreeMap::new();
        let tdir = dir.join("targets");
        let mut stack = vec![tdir.clone()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).map_err(|source| AssetError::Io {
                path: d.clone(),
                source,
            })? {
                let p = e
                    .map_err(|source| AssetError::Io {
                        path: d.clone(),
                        source,
                    })?
                    .path();
                if p.is_dir() {
                    stack.push(p);
                    continue;
                }
                let rel = p
                    .strip_prefix(&tdir)
                    .unwrap_or(&p)
                    .to_string_lossy()
                    .replace('\\', "/");
                let Some(name) = rel
                    .strip_suffix(".target.gz")
                    .or_else(|| rel.strip_suffix(".target"))
                else {
                    continue;
                };
                if !(sel.targets)(name) {
                    continue;
                }
                let t = mh::read_target(&p, nv)?;
                let delta = t
                    .delta
                    .iter()
                    .map(|d| (*d / TARGET_QUANTUM).round().as_ivec3().to_array())
                    .collect();
                targets.insert(name.to_string(), Target { idx: t.idx, delta });
            }
        }
        let skel = mh::read_mhskel(&dir.join("rigs/default.mhskel"))?;
        let bone_names: Vec<String> = skel.bones.iter().map(|b| b.0.clone()).collect();
        let weights = mh::read_mhw(&dir.join("rigs/default_weights.mhw"), &bone_names, nv)?;
        let mut garments = BTreeMap::new();
        let groups: [(&Vec<String>, &str, GarmentKind); 4] = [
            (&sel.outfits, "clothes", GarmentKind::Outfit),
            (&sel.shoes, "clothes", GarmentKind::Shoes),
            (&sel.hair, "hair", GarmentKind::Hair),
            (&sel.hats, "clothes", GarmentKind::Hat),
        ];
        for (names, sub, kind) in groups {
            for name in names {
                let folder = dir.join(sub).join(name);
                let clo_path = std::fs::read_dir(&folder)
                    .map_err(|source| AssetError::Io {
                        path: folder.clone(),
                        source,
                    })?
                    .flatten()
                    .map(|e| e.path())
                    .find(|p| p.extension().is_some_and(|e| e == "mhclo"))
                    .ok_or_else(|| AssetError::Invalid {
                        path: folder.clone(),
                        msg: "no .mhclo file".into(),
                    })?;
                let clo = mh::read_mhclo(&clo_path)?;
                let gobj = mh::read_obj(&folder.join(&clo.obj_file))?;
                if gobj.positions.len() != clo.verts.len() {
                    return Err(AssetError::Invalid {
                        path: clo_path,
                        msg: format!(
                            "{} fitting lines for {} obj vertices",
                            clo.verts.len(),
                            gobj.positions.len()
                        ),
                    });
                }
                let (tris, uv_tris) = gobj.triangles(|_| true);
                let mat = material(
                    &folder.join(&clo.material),
                    sel.texture_px,
                    kind == GarmentKind::Hair,
                )?;
                garments.insert(
                    name.clone(),
                    GarmentDef {
                        kind,
                        tris,
                        uv_tris,
                        uvs: gobj.uvs.iter().map(|u| u.to_array()).collect(),
                        fit_idx: clo.verts.iter().map(|v| v.0).collect(),
                        fit_w: clo.verts.iter().map(|v| v.1).collect(),
                        fit_off: clo.verts.iter().map(|v| v.2).collect(),
                        scale: clo.scale,
                        delete_verts: clo.delete_verts,
                        material: mat,
                    },
                );
            }
        }
        let mut skins = BTreeMap::new();
        for name in &sel.skins {
            let folder = dir.join("skins").join(name);
            skins.insert(
                name.clone(),
                material(&folder.join(format!("{name}.mhmat")), sel.texture_px, false)?,
            );
        }
        let mut poses = BTreeMap::new();
        for name in &sel.poses {
            let bvh = mh::read_bvh(&dir.join("poses").join(format!("{name}.bvh")))?;
            let rots = mh::bvh_rotations(&bvh, 0);
            let m: BTreeMap<String, [f32; 9]> = rots
                .into_iter()
                .filter(|(n, _)| bone_names.contains(n))
                .map(|(n, r)| (n, r.to_cols_array()))
                .collect();
            poses.insert(name.clone(), m);
        }
        let assets = Self {
            version: PACK_VERSION,
            source: format!("MakeHuman 1.x system assets (CC0) from {}", dir.display()),
            base: obj.positions.iter().map(|p| p.to_array()).collect(),
            body_tris,
            body_uv_tris,
            body_uvs: obj.uvs.iter().map(|u| u.to_array()).collect(),
            eye_tris,
            targets,
            joints: skel.joints,
            joint_names: skel.joint_names,
            bones: skel
                .bones
                .into_iter()
                .map(|(name, head, tail, parent)| BoneDef {
                    name,
                    head,
                    tail,
                    parent,
                })
                .collect(),
            weights,
            garments,
            skins,
            poses,
        };
        assets.validate().map_err(|msg| AssetError::Invalid {
            path: dir.to_path_buf(),
            msg,
        })?;
        Ok(assets)
    }

    /// Serialize as a gzip-compressed pack.
    pub fn write_pack(&self, w: impl Write) -> Result<(), String> {
        let bytes = postcard::to_stdvec(self).map_err(|e| e.to_string())?;
        let mut gz = flate2::write::GzEncoder::new(w, flate2::Compression::best());
        gz.write_all(&bytes).map_err(|e| e.to_string())?;
        gz.finish().map_err(|e| e.to_string())?;
        Ok(())
    }

    /// Read a pack written by [`Self::write_pack`]; `what` names it in errors.
    pub fn read_pack(bytes: &[u8], what: &str) -> Result<Self, String> {
        let mut raw = Vec::new();
        flate2::read::GzDecoder::new(bytes)
            .read_to_end(&mut raw)
            .map_err(|e| format!("{what}: not a gzip pack: {e}"))?;
        let a: Self =
            postcard::from_bytes(&raw).map_err(|e| format!("{what}: corrupt pack: {e}"))?;
        if a.version != PACK_VERSION {
            return Err(format!(
                "{what}: pack version {} but this build reads {PACK_VERSION}; rebuild it with `volcap sim pack`",
                a.version
            ));
        }
        a.validate().map_err(|e| format!("{what}: {e}"))?;
        Ok(a)
    }

    /// The embedded runtime pack.
    pub fn embedded() -> Result<Self, String> {
        Self::read_pack(EMBEDDED_PACK, "embedded human pack")
    }

    /// Load from a path: a pack file, or a MakeHuman folder (everything in it).
    pub fn load(path: &Path) -> Result<Self, String> {
        if path.is_dir() {
            Self::from_makehuman(path, &Selection::everything(path)).map_err(|e| e.to_string())
        } else {
            let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
            Self::read_pack(&bytes, &path.display().to_string())
        }
    }

    /// Index bounds and counts that the rest of the simulator relies on.
    pub fn validate(&self) -> Result<(), String> {
        let nv = self.base.len() as u32;
        let in_range = |t: &[[u32; 3]]| t.iter().all(|t| t.iter().all(|&i| i < nv));
        if !in_range(&self.body_tris) || !in_range(&self.eye_tris) {
            return Err("triangle index beyond the base mesh".into());
        }
        if self.weights.len() != self.base.len() {
            return Err(format!(
                "{} weight rows for {} vertices",
                self.weights.len(),
                self.base.len()
            ));
        }
        if self
            .weights
            .iter()
            .any(|w| w.iter().any(|(b, _)| *b as usize >= self.bones.len()))
        {
            return Err("weight for a bone index beyond the skeleton".into());
        }
        if self
            .bones
            .iter()
            .enumerate()
            .any(|(i, b)| b.parent.is_some_and(|p| p as usize >= i))
        {
            return Err("bones are not in parent-first order".into());
        }
        if self.joints.iter().flatten().any(|&i| i >= nv) {
            return Err("joint vertex beyond the base mesh".into());
        }
        for (n, g) in &self.garments {
            if g.fit_idx.iter().flatten().any(|&i| i >= nv)
                || g.tris
                    .iter()
                    .flatten()
                    .any(|&i| i as usize >= g.fit_idx.len())
            {
                return Err(format!("garment {n}: index out of range"));
            }
        }
        for (n, t) in &self.targets {
            if t.idx.iter().any(|&i| i >= nv) || t.idx.len() != t.delta.len() {
                return Err(format!("target {n}: index out of range"));
            }
        }
        Ok(())
    }
}
