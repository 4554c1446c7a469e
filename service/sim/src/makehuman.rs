//! Readers for the MakeHuman 1.x CC0 data pack (`../shared/data/makehuman`, see its
//! MANIFEST.md): OBJ, `.target(.gz)`, `.mhskel`, `.mhw`, `.mhclo`, `.mhmat`, BVH.
//!
//! Used by `volcap sim pack` (to build the compact runtime pack) and by dataset generation;
//! the product itself loads the pack. Every error names the file and, for text formats, the
//! line.

use glam::{Mat3, Vec2, Vec3};
use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

/// An asset file could not be read or parsed.
#[derive(Debug, thiserror::Error)]
pub enum AssetError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}:{line}: {msg}")]
    Parse {
        path: PathBuf,
        line: usize,
        msg: String,
    },
    #[error("{path}: {msg}")]
    Invalid { path: PathBuf, msg: String },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> AssetError + '_ {
    move |source| AssetError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn parse_err(path: &Path, line: usize, msg: impl Into<String>) -> AssetError {
    AssetError::Parse {
        path: path.to_path_buf(),
        line,
        msg: msg.into(),
    }
}

fn invalid(path: &Path, msg: impl Into<String>) -> AssetError {
    AssetError::Invalid {
        path: path.to_path_buf(),
        msg: msg.into(),
    }
}

/// Read a text file, gunzipping `.gz`.
pub fn read_text(path: &Path) -> Result<String, AssetError> {
    let bytes = std::fs::read(path).map_err(io(path))?;
    if path.extension().is_some_and(|e| e == "gz") {
        let mut s = String::new();
        flate2::read::GzDecoder::new(&bytes[..])
            .read_to_string(&mut s)
            .map_err(io(path))?;
        Ok(s)
    } else {
        String::from_utf8(bytes).map_err(|e| invalid(path, format!("not UTF-8: {e}")))
    }
}

/// Lines with their 1-based numbers, trailing `\r` stripped, comments and blanks skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.split('\n').enumerate().filter_map(|(i, l)| {
        let l = l.strip_suffix('\r').unwrap_or(l).trim();
        if l.is_empty() || l.starts_with('#') || l.starts_with("//") {
            None
        } else {
            Some((i + 1, l))
        }
    })
}

fn num<T: std::str::FromStr>(
    path: &Path,
    line: usize,
    tok: Option<&str>,
    what: &str,
) -> Result<T, AssetError> {
    let t = tok.ok_or_else(|| parse_err(path, line, format!("missing {what}")))?;
    t.parse()
        .map_err(|_| parse_err(path, line, format!("bad {what} '{t}'")))
}

/// A polygon mesh from an OBJ file: positions, texture coordinates, faces (triangles or
/// quads) with their `vt` indices and group.
#[derive(Debug, Clone, Default)]
pub struct ObjMesh {
    pub positions: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    /// Vertex indices per face (3 or 4), 0-based.
    pub faces: Vec<Vec<u32>>,
    /// `vt` indices per face corner, 0-based (empty when the file has none).
    pub face_uvs: Vec<Vec<u32>>,
    /// Group index per face into `groups`.
    pub face_group: Vec<u16>,
    pub groups: Vec<String>,
}

impl ObjMesh {
    /// Triangles (fan split of quads: (0,1,2) + (0,2,3)) of the faces accepted by `keep`,
    /// with their uv-index triangles.
    pub fn triangles(&self, keep: impl Fn(&str) -> bool) -> (Vec<[u32; 3]>, Vec<[u32; 3]>) {
        let mut tris = Vec::new();
        let mut uvt = Vec::new();
        for (fi, f) in self.faces.iter().enumerate() {
            if !keep(&self.groups[self.face_group[fi] as usize]) {
                continue;
            }
            let fu = self.face_uvs.get(fi).filter(|u| u.len() == f.len());
            for k in 1..f.len() - 1 {
                tris.push([f[0], f[k], f[k + 1]]);
                if let Some(u) = fu {
                    uvt.push([u[0], u[k], u[k + 1]]);
                } else {
                    uvt.push([0, 0, 0]);
                }
            }
        }
        (tris, uvt)
    }
}

pub fn read_obj(path: &Path) -> Result<ObjMesh, AssetError> {
    let text = read_text(path)?;
    let mut m = ObjMesh::default();
    let mut group_ids: HashMap<String, u16> = HashMap::new();
    let mut current = 0u16;
    m.groups.push("default".into());
    group_ids.insert("default".into(), 0);
    for (ln, l) in data_lines(&text) {
        let mut it = l.split_whitespace();
        match it.next() {
            Some("v") => {
                let x = num(path, ln, it.next(), "x")?;
                let y = num(path, ln, it.next(), "y")?;
                let z = num(path, ln, it.next(), "z")?;
                m.positions.push(Vec3::new(x, y, z));
            }
            Some("vt") => {
                let u = num(path, ln, it.next(), "u")?;
                let v = num(path, ln, it.next(), "v")?;
                m.uvs.push(Vec2::new(u, v));
            }
            Some("g") => {
                let name = it.next().unwrap_or("default").to_string();
                let next = group_ids.len() as u16;
                current = *group_ids.entry(name.clone()).or_insert_with(|| {
                    m.groups.push(name);
                    next
                });
            }
            Some("f") => {
                let mut vs = Vec::with_capacity(4);
                let mut us = Vec::with_capacity(4);
                for tok in it {
                    let mut parts = tok.split('/');
                    let v: i64 = num(path, ln, parts.next(), "face vertex")?;
                    if v < 1 || v as usize > m.positions.len() {
                        return Err(parse_err(path, ln, format!("face vertex {v} out of range")));
                    }
                    vs.push((v - 1) as u32);
                    if let Some(t) = parts.next().filter(|t| !t.is_empty()) {
                        let t: i64 = num(path, ln, Some(t), "face uv")?;
                        if t < 1 {
                            return Err(parse_err(path, ln, format!("face uv {t} out of range")));
                        }
                        us.push((t - 1) as u32);
                    }
                }
                if vs.len() < 3 {
                    return Err(parse_err(path, ln, "face with fewer than 3 vertices"));
                }
                m.faces.push(vs);
                m.face_uvs.push(us);
                m.face_group.push(current);
            }
            _ => {}
        }
    }
    for (fi, us) in m.face_uvs.iter().enumerate() {
        if us.iter().any(|&u| u as usize >= m.uvs.len()) {
            return Err(invalid(
                path,
                format!(
                    "face {fi} uses a uv index beyond the {} vt lines",
                    m.uvs.len()
                ),
            ));
        }
    }
    Ok(m)
}

/// A sparse morph target: vertex indices and their offsets (decimetres).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TargetData {
    pub idx: Vec<u32>,
    pub delta: Vec<Vec3>,
}

pub fn read_target(path: &Path, vertex_count: usize) -> Result<TargetData, AssetError> {
    let text = read_text(path)?;
    let mut t = TargetData::default();
    for (ln, l) in data_lines(&text) {
        let mut it = l.split_whitespace();
        let i: u32 = num(path, ln, it.next(), "vertex index")?;
        if i as usize >= vertex_count {
            return Err(parse_err(
                path,
                ln,
                format!("vertex index {i} beyond the base mesh's {vertex_count}"),
            ));
        }
        let d = Vec3::new(
            num(path, ln, it.next(), "dx")?,
            num(path, ln, it.next(), "dy")?,
            num(path, ln, it.next(), "dz")?,
        );
        t.idx.push(i);
        t.delta.push(d);
    }
    Ok(t)
}

/// The skeleton: joints (base-mesh vertex sets) and bones in breadth-first order.
#[derive(Debug, Clone)]
pub struct SkeletonData {
    pub joint_names: Vec<String>,
    pub joints: Vec<Vec<u32>>,
    /// (name, head joint, tail joint, parent bone index) in breadth-first order (parents first).
    pub bones: Vec<(String, u32, u32, Option<u32>)>,
}

pub fn read_mhskel(path: &Path) -> Result<SkeletonData, AssetError> {
    #[derive(serde::Deserialize)]
    struct BoneJ {
        head: String,
        tail: String,
        parent: Option<String>,
    }
    #[derive(serde::Deserialize)]
    struct SkelJ {
        joints: HashMap<String, Vec<u32>>,
        bones: HashMap<String, BoneJ>,
    }
    let text = read_text(path)?;
    let s: SkelJ =
        serde_json::from_str(&text).map_err(|e| parse_err(path, e.line(), e.to_string()))?;
    let mut joint_names: Vec<String> = s.joints.keys().cloned().collect();
    joint_names.sort();
    let jidx: HashMap<&str, u32> = joint_names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i as u32))
        .collect();
    let joints = joint_names.iter().map(|n| s.joints[n].clone()).collect();
    // Breadth-first from the roots, children in name order (deterministic).
    let mut children: HashMap<Option<&str>, Vec<&str>> = HashMap::new();
    for (name, b) in &s.bones {
        children
            .entry(b.parent.as_deref())
            .or_default()
            .push(name.as_str());
    }
    for v in children.values_mut() {
        v.sort();
    }
    let mut order: Vec<&str> = Vec::new();
    let mut queue: std::collections::VecDeque<&str> =
        children.get(&None).cloned().unwrap_or_default().into();
    while let Some(b) = queue.pop_front() {
        order.push(b);
        if let Some(c) = children.get(&Some(b)) {
            queue.extend(c.iter().copied());
        }
    }
    if order.len() != s.bones.len() {
        return Err(invalid(
            path,
            format!(
                "{} bones unreachable from a root",
                s.bones.len() - order.len()
            ),
        ));
    }
    let bidx: HashMap<&str, u32> = order
        .iter()
        .enumerate()
        .map(|(i, n)| (*n, i as u32))
        .collect();
    let mut bones = Vec::with_capacity(order.len());
    for name in &order {
        let b = &s.bones[*name];
        let j = |n: &str| {
            jidx.get(n)
                .copied()
                .ok_or_else(|| invalid(path, format!("bone {name} names unknown joint {n}")))
        };
        bones.push((
            name.to_string(),
            j(&b.head)?,
            j(&b.tail)?,
            b.parent.as_deref().map(|p| bidx[p]),
        ));
    }
    Ok(SkeletonData {
        joint_names,
        joints,
        bones,
    })
}

/// Up to four (bone, weight) influences per vertex, normalized as MakeHuman does: divide by
/// the per-vertex sum, drop weights <= 1e-4, keep the 4 largest, renormalize.
pub type Influences = [(u16, f32); 4];

pub fn read_mhw(
    path: &Path,
    bone_names: &[String],
    vertex_count: usize,
) -> Result<Vec<Influences>, AssetError> {
    #[derive(serde::Deserialize)]
    struct W {
        weights: HashMap<String, Vec<(u32, f32)>>,
    }
    let text = read_text(path)?;
    let w: W = serde_json::from_str(&text).map_err(|e| parse_err(path, e.line(), e.to_string()))?;
    let bidx: HashMap<&str, u16> = bone_names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i as u16))
        .collect();
    let mut per: Vec<Vec<(u16, f32)>> = vec![Vec::new(); vertex_count];
    for (bone, list) in &w.weights {
        let b = *bidx
            .get(bone.as_str())
            .ok_or_else(|| invalid(path, format!("weights for unknown bone {bone}")))?;
        for &(v, wt) in list {
            let slot = per
                .get_mut(v as usize)
                .ok_or_else(|| invalid(path, format!("bone {bone}: vertex {v} out of range")))?;
            slot.push((b, wt));
        }
    }
    let mut out = Vec::with_capacity(vertex_count);
    for (v, mut inf) in per.into_iter().enumerate() {
        // The file's bones come in hash-map order, different in every process: sum in bone
        // order so that a vertex's weights (and everything posed from them) are the same
        // to the bit from run to run.
        inf.sort_by_key(|x| x.0);
        let sum: f32 = inf.iter().map(|x| x.1).sum();
        if sum <= 0.0 {
            return Err(invalid(path, format!("vertex {v} has no bone weight")));
        }
        for x in &mut inf {
            x.1 /= sum;
        }
        inf.retain(|x| x.1 > 1e-4);
        inf.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        inf.truncate(4);
        let s: f32 = inf.iter().map(|x| x.1).sum();
        let mut arr = [(0u16, 0.0f32); 4];
        for (a, x) in arr.iter_mut().zip(&inf) {
            *a = (x.0, x.1 / s);
        }
        out.push(arr);
    }
    Ok(out)
}

/// A garment/hair/eyes fitting file.
#[derive(Debug, Clone, Default)]
pub struct MhcloData {
    pub name: String,
    pub obj_file: String,
    pub material: String,
    /// (i, j, d) per axis x, y, z.
    pub scale: [(u32, u32, f32); 3],
    pub verts: Vec<([u32; 3], [f32; 3], [f32; 3])>,
    pub delete_verts: Vec<u32>,
}

pub fn read_mhclo(path: &Path) -> Result<MhcloData, AssetError> {
    let text = read_text(path)?;
    let mut m = MhcloData::default();
    #[derive(PartialEq)]
    enum Sec {
        Head,
        Verts,
        Delete,
    }
    let mut sec = Sec::Head;
    let mut have_scale = [false; 3];
    for (ln, l) in data_lines(&text) {
        let mut it = l.split_whitespace();
        let first = it.next().unwrap_or("");
        let is_num = first.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '.');
        if !is_num {
            match first {
                "name" => m.name = it.next().unwrap_or("").to_string(),
                "obj_file" => m.obj_file = it.next().unwrap_or("").to_string(),
                "material" => m.material = it.collect::<Vec<_>>().join(" "),
                "x_scale" | "y_scale" | "z_scale" => {
                    let a = match first {
                        "x_scale" => 0,
                        "y_scale" => 1,
                        _ => 2,
                    };
                    m.scale[a] = (
                        num(path, ln, it.next(), "scale i")?,
                        num(path, ln, it.next(), "scale j")?,
                        num(path, ln, it.next(), "scale d")?,
                    );
                    have_scale[a] = true;
                }
                "verts" => sec = Sec::Verts,
                "delete_verts" => sec = Sec::Delete,
                _ => {}
            }
            continue;
        }
        let toks: Vec<&str> = l.split_whitespace().collect();
        match sec {
            Sec::Verts => {
                if toks.len() == 9 {
                    let mut v = ([0u32; 3], [0f32; 3], [0f32; 3]);
                    for k in 0..3 {
                        v.0[k] = num(path, ln, Some(toks[k]), "vertex index")?;
                        v.1[k] = num(path, ln, Some(toks[3 + k]), "weight")?;
                        v.2[k] = num(path, ln, Some(toks[6 + k]), "offset")?;
                    }
                    m.verts.push(v);
                } else if toks.len() == 1 {
                    let i = num(path, ln, Some(toks[0]), "vertex index")?;
                    m.verts.push(([i, i, i], [1.0, 0.0, 0.0], [0.0; 3]));
                } else {
                    return Err(parse_err(
                        path,
                        ln,
                        format!("vertex line with {} numbers (need 9 or 1)", toks.len()),
                    ));
                }
            }
            Sec::Delete => {
                let mut k = 0;
                while k < toks.len() {
                    let a: u32 = num(path, ln, Some(toks[k]), "deleted vertex")?;
                    if toks.get(k + 1) == Some(&"-") {
                        let b: u32 = num(path, ln, toks.get(k + 2).copied(), "range end")?;
                        m.delete_verts.extend(a..=b);
                        k += 3;
                    } else {
                        m.delete_verts.push(a);
                        k += 1;
                    }
                }
            }
            Sec::Head => return Err(parse_err(path, ln, "numbers before 'verts'")),
        }
    }
    if have_scale.iter().any(|h| !h) {
        return Err(invalid(path, "missing x_scale, y_scale or z_scale"));
    }
    Ok(m)
}

/// The parts of an `.mhmat` the renderer uses.
#[derive(Debug, Clone, Default)]
pub struct MhmatData {
    pub diffuse_color: [f32; 3],
    pub diffuse_texture: Option<PathBuf>,
    pub transparent: bool,
}

pub fn read_mhmat(path: &Path) -> Result<MhmatData, AssetError> {
    let text = read_text(path)?;
    let mut m = MhmatData {
        diffuse_color: [1.0; 3],
        ..Default::default()
    };
    for (ln, l) in data_lines(&text) {
        let mut it = l.split_whitespace();
        match it.next() {
            Some("diffuseColor") => {
                for c in &mut m.diffuse_color {
                    *c = num(path, ln, it.next(), "diffuseColor")?;
                }
            }
            Some("diffuseTexture") => {
                let f = it.collect::<Vec<_>>().join(" ");
                m.diffuse_texture = Some(path.parent().unwrap_or(Path::new(".")).join(f));
            }
            Some("transparent") => {
                m.transparent = it.next().is_some_and(|v| v.eq_ignore_ascii_case("true"))
            }
            _ => {}
        }
    }
    Ok(m)
}

/// A BVH file: joint hierarchy with channels, and frames of channel values.
#[derive(Debug, Clone)]
pub struct BvhData {
    /// (name, channel names) in file order.
    pub joints: Vec<(String, Vec<String>)>,
    pub frames: Vec<Vec<f32>>,
    pub frame_time: f32,
}

pub fn read_bvh(path: &Path) -> Result<BvhData, AssetError> {
    let text = read_text(path)?;
    let toks: Vec<&str> = text.split_whitespace().collect();
    let mut joints: Vec<(String, Vec<String>)> = Vec::new();
    let mut i = 0;
    let bad = |msg: &str| invalid(path, msg.to_string());
    while i < toks.len() && toks[i] != "MOTION" {
        match toks[i] {
            "ROOT" | "JOINT" => {
                joints.push((
                    toks.get(i + 1)
                        .ok_or_else(|| bad("ROOT/JOINT without a name"))?
                        .to_string(),
                    Vec::new(),
                ));
                i += 2;
            }
            "CHANNELS" => {
                let n: usize = toks
                    .get(i + 1)
                    .and_then(|t| t.parse().ok())
                    .ok_or_else(|| bad("bad CHANNELS count"))?;
                let ch: Vec<String> = toks
                    .get(i + 2..i + 2 + n)
                    .ok_or_else(|| bad("truncated CHANNELS"))?
                    .iter()
                    .map(|s| s.to_string())
                    .collect();
                joints
                    .last_mut()
                    .ok_or_else(|| bad("CHANNELS before any joint"))?
                    .1 = ch;
                i += 2 + n;
            }
            _ => i += 1,
        }
    }
    let nch: usize = joints.iter().map(|j| j.1.len()).sum();
    // MOTION Frames: N Frame Time: t
    let nframes: usize = toks
        .get(i + 2)
        .and_then(|t| t.parse().ok())
        .ok_or_else(|| bad("missing 'Frames: N'"))?;
    let frame_time: f32 = toks
        .get(i + 5)
        .and_then(|t| t.parse().ok())
        .ok_or_else(|| bad("missing 'Frame Time: t'"))?;
    let vals: Vec<f32> = toks[(i + 6).min(toks.len())..]
        .iter()
        .map(|t| {
            t.parse::<f32>()
                .map_err(|_| bad(&format!("bad motion value '{t}'")))
        })
        .collect::<Result<_, _>>()?;
    if vals.len() != nframes * nch {
        return Err(bad(&format!(
            "{} motion values for {nframes} frames x {nch} channels",
            vals.len()
        )));
    }
    let frames = vals.chunks(nch.max(1)).map(|c| c.to_vec()).collect();
    Ok(BvhData {
        joints,
        frames,
        frame_time,
    })
}

/// Per-joint local rotations of one frame, converted from the BVH's Z-up frame to the mesh
/// frame (`R' = C R C^T`, `C` maps (x, y, z) to (x, z, -y)), by joint name.
pub fn bvh_rotations(bvh: &BvhData, frame: usize) -> HashMap<String, Mat3> {
    let c = Mat3::from_cols(
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(0.0, 1.0, 0.0),
    );
    let mut out = HashMap::new();
    let vals = &bvh.frames[frame.min(bvh.frames.len().saturating_sub(1))];
    let mut k = 0;
    for (name, ch) in &bvh.joints {
        let mut r = Mat3::IDENTITY;
        for c_name in ch {
            let a = vals.get(k).copied().unwrap_or(0.0).to_radians();
            k += 1;
            r *= match c_name.as_str() {
                "Xrotation" => Mat3::from_rotation_x(a),
                "Yrotation" => Mat3::from_rotation_y(a),
                "Zrotation" => Mat3::from_rotation_z(a),
                _ => Mat3::IDENTITY,
            };
        }
        out.insert(name.clone(), c * r * c.transpose());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vertex influenced by many bones whose weights sum differently in f32 depending on
    /// the order: every read gives the same bits (the bones' hash-map order varies between
    /// maps, so twenty reads see several orders).
    #[test]
    fn weights_are_the_same_to_the_bit_whatever_the_file_order() {
        let bones: Vec<String> = (0..24).map(|i| format!("bone{i:02}")).collect();
        let weights: Vec<String> = bones
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let w = if i % 3 == 0 {
                    1e-4 * (i + 1) as f32
                } else {
                    0.3 / (i + 1) as f32
                };
                format!("\"{b}\": [[0, {w:?}]]")
            })
            .collect();
        let dir = std::env::temp_dir().join(format!("volcap-mhw-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("w.mhw");
        std::fs::write(
            &path,
            format!("{{\"weights\": {{{}}}}}", weights.join(", ")),
        )
        .unwrap();
        let first = read_mhw(&path, &bones, 1).unwrap();
        for _ in 0..20 {
            let again = read_mhw(&path, &bones, 1).unwrap();
            let bits = |v: &[Influences]| -> Vec<(u16, u32)> {
                v.iter().flatten().map(|(b, w)| (*b, w.to_bits())).collect()
            };
            assert_eq!(bits(&first), bits(&again));
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
