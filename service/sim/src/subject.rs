//! Subjects: shape the base mesh with the macro model, compute the skeleton, pose it with
//! linear blend skinning, fit garments to the posed body (MANIFEST 4.2-4.8).

use crate::assets::{GarmentKind, HumanAssets, TARGET_QUANTUM};
use glam::{Affine3A, Mat3, Mat3A, Vec3};
use serde::Deserialize;
use std::collections::HashSet;

/// A subject, all by name: body shape parameters (MakeHuman's macro model, each in [0, 1]),
/// outfit, shoes, hair, skin.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SubjectSpec {
    #[serde(default)]
    pub id: String,
    #[serde(default = "half")]
    pub gender: f32,
    #[serde(default = "half")]
    pub age: f32,
    #[serde(default = "half")]
    pub muscle: f32,
    #[serde(default = "half")]
    pub weight: f32,
    #[serde(default = "half")]
    pub height: f32,
    #[serde(default = "half")]
    pub proportions: f32,
    /// African, Asian, Caucasian shares (normalized).
    #[serde(default = "third3")]
    pub race: [f32; 3],
    pub outfit: Option<String>,
    pub shoes: Option<String>,
    pub hair: Option<String>,
    pub skin: Option<String>,
}

fn half() -> f32 {
    0.5
}
fn third3() -> [f32; 3] {
    [1.0 / 3.0; 3]
}

impl Default for SubjectSpec {
    fn default() -> Self {
        Self {
            id: String::new(),
            gender: 0.5,
            age: 0.5,
            muscle: 0.5,
            weight: 0.5,
            height: 0.5,
            proportions: 0.5,
            race: third3(),
            outfit: None,
            shoes: None,
            hair: None,
            skin: None,
        }
    }
}

/// Weights of the macro factors named by target file tokens (MANIFEST 4.2).
pub fn macro_factor(spec: &SubjectSpec, token: &str) -> Option<f32> {
    let (g, a) = (spec.gender, spec.age);
    let (old, young, child, baby) = if a < 0.5 {
        let young = ((a - 0.1875) * 3.2).max(0.0);
        (
            0.0,
            young,
            ((5.333 * a).min(1.0) - young).max(0.0),
            (1.0 - 5.333 * a).max(0.0),
        )
    } else {
        let old = (2.0 * a - 1.0).max(0.0);
        (old, 1.0 - old, 0.0, 0.0)
    };
    let tri = |x: f32| {
        let mx = (2.0 * x - 1.0).max(0.0);
        let mn = (1.0 - 2.0 * x).max(0.0);
        (mn, 1.0 - mx - mn, mx)
    };
    let rs: f32 = spec.race.iter().sum();
    let race = |i: usize| {
        if rs > 0.0 {
            spec.race[i] / rs
        } else {
            1.0 / 3.0
        }
    };
    let (mm, am, xm) = tri(spec.muscle);
    let (mw, aw, xw) = tri(spec.weight);
    Some(match token {
        "female" => 1.0 - g,
        "male" => g,
        "old" => old,
        "young" => young,
        "child" => child,
        "baby" => baby,
        "minmuscle" => mm,
        "averagemuscle" => am,
        "maxmuscle" => xm,
        "minweight" => mw,
        "averageweight" => aw,
        "maxweight" => xw,
        "maxheight" => (2.0 * spec.height - 1.0).max(0.0),
        "minheight" => (1.0 - 2.0 * spec.height).max(0.0),
        "idealproportions" => (2.0 * spec.proportions - 1.0).max(0.0),
        "uncommonproportions" => (1.0 - 2.0 * spec.proportions).max(0.0),
        "african" => race(0),
        "asian" => race(1),
        "caucasian" => race(2),
        _ => return None,
    })
}

/// Why a subject could not be built.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum SubjectError {
    #[error("subject '{id}': {field} = {value} is outside [0, 1]")]
    OutOfRange {
        id: String,
        field: &'static str,
        value: f32,
    },
    #[error("subject '{id}': unknown {what} '{name}' (available: {available})")]
    Unknown {
        id: String,
        what: &'static str,
        name: String,
        available: String,
    },
}

/// A shaped subject in its rest pose, ready to be posed frame after frame.
pub struct Subject {
    pub spec: SubjectSpec,
    /// Shaped rest positions of every base vertex (decimetres).
    pub rest: Vec<Vec3>,
    /// Rest head position of every bone.
    pub heads: Vec<Vec3>,
    /// Garments worn, by name, in drawing order.
    pub garments: Vec<String>,
    /// Body triangles drawn (those not hidden under garments) and their uv triangles.
    pub visible_body_tris: Vec<[u32; 3]>,
    pub visible_body_uv_tris: Vec<[u32; 3]>,
    /// Per-garment fit scales from the shaped rest mesh.
    garment_scales: Vec<Vec3>,
}

/// A posed subject in world units (metres, y up, feet on the floor before placement).
#[derive(Debug, Clone, Default)]
pub struct Posed {
    /// Every base vertex, posed.
    pub verts: Vec<Vec3>,
    /// Garment vertices, one list per worn garment (same order as `Subject::garments`).
    pub garments: Vec<Vec<Vec3>>,
}

impl Subject {
    pub fn new(assets: &HumanAssets, spec: &SubjectSpec) -> Result<Self, SubjectError> {
        let id = spec.id.clone();
        for (field, v) in [
            ("gender", spec.gender),
            ("age", spec.age),
            ("muscle", spec.muscle),
            ("weight", spec.weight),
            ("height", spec.height),
            ("proportions", spec.proportions),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(SubjectError::OutOfRange {
                    id,
                    field,
                    value: v,
                });
            }
        }
        for (i, v) in spec.race.iter().enumerate() {
            if !(0.0..=1.0).contains(v) {
                return Err(SubjectError::OutOfRange {
                    id,
                    field: ["race.african", "race.asian", "race.caucasian"][i],
                    value: *v,
                });
            }
        }
        let mut rest: Vec<Vec3> = assets.base.iter().map(|p| Vec3::from_array(*p)).collect();
        for (name, t) in &assets.targets {
            let file = name.rsplit('/').next().unwrap_or(name);
            let mut w = 1.0f32;
            for tok in file.split('-').filter(|t| *t != "universal") {
                w *= macro_factor(spec, tok).unwrap_or(0.0);
            }
            if w == 0.0 {
                continue;
            }
            for (&i, d) in t.idx.iter().zip(&t.delta) {
                rest[i as usize] +=
                    Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32) * (TARGET_QUANTUM * w);
            }
        }
        let joint_pos: Vec<Vec3> = assets
            .joints
            .iter()
            .map(|vs| vs.iter().map(|&i| rest[i as usize]).sum::<Vec3>() / vs.len().max(1) as f32)
            .collect();
        let heads = assets
            .bones
            .iter()
            .map(|b| joint_pos[b.head as usize])
            .collect();
        let pick = |what: &'static str,
                    name: &Option<String>,
                    kind: Option<GarmentKind>|
         -> Result<Option<String>, SubjectError> {
            let Some(n) = name else { return Ok(None) };
            match assets.garments.get(n) {
                Some(g) if kind.is_none_or(|k| g.kind == k) => Ok(Some(n.clone())),
                _ => Err(SubjectError::Unknown {
                    id: spec.id.clone(),
                    what,
                    name: n.clone(),
                    available: assets
                        .garments
                        .iter()
                        .filter(|(_, g)| kind.is_none_or(|k| g.kind == k))
                        .map(|(k, _)| k.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                }),
            }
        };
        let mut garments = Vec::new();
        garments.extend(pick("outfit", &spec.outfit, Some(GarmentKind::Outfit))?);
        garments.extend(pick("shoes", &spec.shoes, Some(GarmentKind::Shoes))?);
        garments.extend(pick("hair", &spec.hair, Some(GarmentKind::Hair))?);
        if let Some(s) = &spec.skin
            && !assets.skins.contains_key(s)
        {
            return Err(SubjectError::Unknown {
                id,
                what: "skin",
                name: s.clone(),
                available: assets.skins.keys().cloned().collect::<Vec<_>>().join(", "),
            });
        }
        let deleted: HashSet<u32> = garments
            .iter()
            .flat_map(|g| assets.garments[g].delete_verts.iter().copied())
            .collect();
        let (visible_body_tris, visible_body_uv_tris) = assets
            .body_tris
            .iter()
            .zip(&assets.body_uv_tris)
            .filter(|(t, _)| !t.iter().all(|i| deleted.contains(i)))
            .map(|(t, u)| (*t, *u))
            .unzip();
        let garment_scales = garments
            .iter()
            .map(|g| {
                let s = assets.garments[g].scale;
                let axis = |a: usize| {
                    let (i, j, d) = s[a];
                    (rest[i as usize][a] - rest[j as usize][a]).abs() / d
                };
                Vec3::new(axis(0), axis(1), axis(2))
            })
            .collect();
        Ok(Self {
            spec: spec.clone(),
            rest,
            heads,
            garments,
            visible_body_tris,
            visible_body_uv_tris,
            garment_scales,
        })
    }

    /// Pose with per-bone local rotations (mesh frame, parent-relative; identity = rest),
    /// giving world positions in metres with the lowest body vertex on the floor (y = 0).
    pub fn pose(&self, assets: &HumanAssets, rotations: &[Mat3], out: &mut Posed) {
        let nb = assets.bones.len();
        let mut d = vec![Mat3A::IDENTITY; nb];
        let mut head_p = vec![Vec3::ZERO; nb];
        let mut skin = vec![Affine3A::IDENTITY; nb];
        for (b, bone) in assets.bones.iter().enumerate() {
            let r = Mat3A::from(rotations.get(b).copied().unwrap_or(Mat3::IDENTITY));
            let head = self.heads[b];
            match bone.parent {
                Some(p) => {
                    let p = p as usize;
                    d[b] = d[p] * r;
                    head_p[b] = head_p[p] + d[p] * (head - self.heads[p]);
                }
                None => {
                    d[b] = r;
                    head_p[b] = head;
                }
            }
            // S_b = T(head'_b) . D_b . T(-head_b)
            skin[b] = Affine3A::from_mat3_translation(d[b].into(), head_p[b] - d[b] * head);
        }
        out.verts.clear();
        out.verts
            .extend(self.rest.iter().zip(&assets.weights).map(|(v, w)| {
                let mut acc = Vec3::ZERO;
                for &(b, wt) in w {
                    if wt > 0.0 {
                        acc += skin[b as usize].transform_point3(*v) * wt;
                    }
                }
                acc
            }));
        out.garments.resize_with(self.garments.len(), Vec::new);
        for ((g, scale), gv) in self
            .garments
            .iter()
            .zip(&self.garment_scales)
            .zip(&mut out.garments)
        {
            let def = &assets.garments[g];
            gv.clear();
            gv.extend(
                def.fit_idx
                    .iter()
                    .zip(&def.fit_w)
                    .zip(&def.fit_off)
                    .map(|((i, w), o)| {
                        out.verts[i[0] as usize] * w[0]
                            + out.verts[i[1] as usize] * w[1]
                            + out.verts[i[2] as usize] * w[2]
                            + Vec3::from_array(*o) * *scale
                    }),
            );
        }
        // Decimetres to metres, feet on the floor.
        let floor = assets
            .body_tris
            .iter()
            .flatten()
            .map(|&i| out.verts[i as usize].y)
            .fold(f32::INFINITY, f32::min);
        let shift = Vec3::new(0.0, -floor, 0.0);
        for v in out
            .verts
            .iter_mut()
            .chain(out.garments.iter_mut().flatten())
        {
            *v = (*v + shift) * 0.1;
        }
    }
}
