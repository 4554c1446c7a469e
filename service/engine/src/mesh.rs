//! Meshes on request: marching cubes over a localized grid, and export as binary PLY and
//! glTF binary (.glb).
//!
//! Vertices are welded (one per crossed grid edge), so a closed surface gives a closed,
//! manifold mesh: every edge is shared by exactly two triangles (tested). Triangles wind
//! counter-clockwise seen from outside (outward normals) in the NDC frame.
//!
//! Exports convert NDC (y down, z toward the camera) to the y-up, right-handed frame that
//! glTF and most PLY viewers expect: `(x, y, z) -> (x, -y, z)`, with winding flipped to match.

use crate::field::{ColorField, FieldError};
use crate::grid::{Grid, ISO, is_inside};
use crate::mc_tables::{CORNERS, EDGE_CORNERS, TRI_TABLE};
use glam::Vec3;
use std::collections::HashMap;
use std::io::{self, Write};

/// A triangle mesh in NDC, with optional per-vertex colours (linear RGB in [0, 1]).
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub vertices: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub colors: Option<Vec<[f32; 3]>>,
}

impl Mesh {
    /// Signed volume (positive for outward-facing triangles), f64.
    pub fn volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Total surface area, f64.
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize].as_dvec3());
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// Edges used by other than exactly two triangles (0 for a closed manifold surface).
    pub fn boundary_edges(&self) -> usize {
        let mut count: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &self.triangles {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        count.values().filter(|&&c| c != 2).count()
    }

    /// Colour every vertex from a colour field.
    pub fn paint(&mut self, colors: &dyn ColorField) -> Result<(), FieldError> {
        let mut out = vec![[0.0f32; 3]; self.vertices.len()];
        colors.color(&self.vertices, &mut out)?;
        self.colors = Some(out);
        Ok(())
    }

    fn export_vertex(v: Vec3) -> [f32; 3] {
        [v.x, -v.y, v.z]
    }

    fn export_triangle(t: [u32; 3]) -> [u32; 3] {
        [t[0], t[2], t[1]]
    }

    fn color_u8(c: [f32; 3]) -> [u8; 3] {
        c.map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8)
    }

    /// Write binary little-endian PLY (positions, optional RGB, triangles), converting NDC
    /// to y up.
    pub fn write_ply(&self, w: &mut impl Write) -> io::Result<()> {
        self.write_ply_impl(w, true)
    }

    /// Write PLY with positions as they are (for meshes already in a y-up world frame).
    pub fn write_ply_as_is(&self, w: &mut impl Write) -> io::Result<()> {
        self.write_ply_impl(w, false)
    }

    fn write_ply_impl(&self, w: &mut impl Write, from_ndc: bool) -> io::Result<()> {
        let mut head = format!(
            "ply\nformat binary_little_endian 1.0\ncomment volcap mesh, y up\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\n",
            self.vertices.len()
        );
        if self.colors.is_some() {
            head.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
        }
        head.push_str(&format!(
            "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
            self.triangles.len()
        ));
        let mut buf =
            Vec::with_capacity(head.len() + self.vertices.len() * 15 + self.triangles.len() * 13);
        buf.extend_from_slice(head.as_bytes());
        for (i, v) in self.vertices.iter().enumerate() {
            let p = if from_ndc {
                Self::export_vertex(*v)
            } else {
                v.to_array()
            };
            for c in p {
                buf.extend_from_slice(&c.to_le_bytes());
            }
            if let Some(cols) = &self.colors {
                buf.extend_from_slice(&Self::color_u8(cols[i]));
            }
        }
        for t in &self.triangles {
            buf.push(3);
            for i in if from_ndc {
                Self::export_triangle(*t)
            } else {
                *t
            } {
                buf.extend_from_slice(&i.to_le_bytes());
            }
        }
        w.write_all(&buf)
    }

    /// The mesh as a glTF 2.0 binary (.glb): one mesh, positions, optional COLOR_0, indices.
    pub fn to_glb(&self) -> Vec<u8> {
        let nv = self.vertices.len();
        let mut bin = Vec::with_capacity(nv * 16 + self.triangles.len() * 12);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for v in &self.vertices {
            let e = Self::export_vertex(*v);
            for a in 0..3 {
                lo[a] = lo[a].min(e[a]);
                hi[a] = hi[a].max(e[a]);
                bin.extend_from_slice(&e[a].to_le_bytes());
            }
        }
        if nv == 0 {
            (lo, hi) = ([0.0; 3], [0.0; 3]);
        }
        let pos_len = bin.len();
        for t in &self.triangles {
            for i in Self::export_triangle(*t) {
                bin.extend_from_slice(&i.to_le_bytes());
            }
        }
        let idx_len = bin.len() - pos_len;
        let mut views = vec![
            serde_json::json!({"buffer": 0, "byteOffset": 0, "byteLength": pos_len, "target": 34962}),
            serde_json::json!({"buffer": 0, "byteOffset": pos_len, "byteLength": idx_len, "target": 34963}),
        ];
        let mut accessors = vec![
            serde_json::json!({"bufferView": 0, "componentType": 5126, "count": nv, "type": "VEC3",
                               "min": lo, "max": hi}),
            serde_json::json!({"bufferView": 1, "componentType": 5125, "count": self.triangles.len() * 3,
                               "type": "SCALAR"}),
        ];
        let mut attributes = serde_json::json!({"POSITION": 0});
        if let Some(cols) = &self.colors {
            let off = bin.len();
            for c in cols {
                let [r, g, b] = Self::color_u8(*c);
                bin.extend_from_slice(&[r, g, b, 255]);
            }
            views.push(
                serde_json::json!({"buffer": 0, "byteOffset": off, "byteLength": bin.len() - off,
                                          "target": 34962}),
            );
            accessors.push(
                serde_json::json!({"bufferView": 2, "componentType": 5121, "normalized": true,
                                              "count": nv, "type": "VEC4"}),
            );
            attributes["COLOR_0"] = serde_json::json!(2);
        }
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let doc = serde_json::json!({
            "asset": {"version": "2.0", "generator": "volcap"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": attributes, "indices": 1, "mode": 4}]}],
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": views,
            "accessors": accessors,
        });
        let mut json = doc.to_string().into_bytes();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }
}

/// Marching cubes over `grid` at the iso level [`ISO`], using the same inside rule as
/// everything else ([`is_inside`]).
pub fn marching_cubes(grid: &Grid) -> Mesh {
    let spec = grid.spec();
    let n = spec.n();
    let v = &grid.values;
    let mut mesh = Mesh::default();
    // Welded vertices: one per (grid point, axis) edge.
    let mut edge_vertex: HashMap<(u32, u8), u32> = HashMap::new();
    let mut case_vals = [0f32; 8];
    let mut case_idx = [0usize; 8];
    for k in 0..n - 1 {
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let mut case = 0usize;
                for (c, off) in CORNERS.iter().enumerate() {
                    let l = spec.linear([i + off[0], j + off[1], k + off[2]]);
                    case_idx[c] = l;
                    case_vals[c] = v[l];
                    if !is_inside(v[l]) {
                        case |= 1 << c;
                    }
                }
                if case == 0 || case == 255 {
                    continue;
                }
                let row = &TRI_TABLE[case];
                let mut t = 0;
                while t + 2 < 16 && row[t] >= 0 {
                    let mut tri = [0u32; 3];
                    for (slot, &e) in tri.iter_mut().zip(&row[t..t + 3]) {
                        let (a, b) = EDGE_CORNERS[e as usize];
                        let (la, lb) = (case_idx[a], case_idx[b]);
                        let (lo, hi) = if la < lb { (la, lb) } else { (lb, la) };
                        let axis = (0..3)
                            .find(|&ax| CORNERS[a][ax] != CORNERS[b][ax])
                            .unwrap_or(0) as u8;
                        *slot = *edge_vertex.entry((lo as u32, axis)).or_insert_with(|| {
                            let (va, vb) = (v[lo], v[hi]);
                            let d = vb - va;
                            // va and vb straddle ISO so d != 0; guarded anyway.
                            let t = if d.abs() > f32::MIN_POSITIVE {
                                ((ISO - va) / d).clamp(0.0, 1.0)
                            } else {
                                0.5
                            };
                            let (pa, pb) =
                                (spec.world(spec.unlinear(lo)), spec.world(spec.unlinear(hi)));
                            mesh.vertices.push(pa + (pb - pa) * t);
                            (mesh.vertices.len() - 1) as u32
                        });
                    }
                    // With the case bit set for outside corners the table's winding gives
                    // outward normals (positive signed volume; tested).
                    mesh.triangles.push(tri);
                    t += 3;
                }
            }
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::AnalyticScene;
    use crate::grid::GridSpec;
    use crate::localize::{Localizer, Method};

    fn sphere_mesh(level: u32) -> Mesh {
        let s = AnalyticScene::by_name("sphere").unwrap();
        let spec = GridSpec::new(level).unwrap();
        let mut g = Grid::new(spec);
        Localizer::new()
            .run(Method::Dense, &s, spec, level, &mut g)
            .unwrap();
        marching_cubes(&g)
    }

    #[test]
    fn sphere_mesh_is_closed_outward_and_accurate() {
        let m = sphere_mesh(6);
        assert_eq!(m.boundary_edges(), 0);
        let r = 0.6f64;
        let vol = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        assert!(
            (m.volume() - vol).abs() / vol < 0.01,
            "volume {} vs {}",
            m.volume(),
            vol
        );
        let area = 4.0 * std::f64::consts::PI * r * r;
        assert!(
            (m.area() - area).abs() / area < 0.02,
            "area {} vs {}",
            m.area(),
            area
        );
        let c = glam::Vec3::new(0.05, -0.03, 0.02);
        for v in &m.vertices {
            assert!(((*v - c).length() - 0.6).abs() < 0.01);
        }
    }

    #[test]
    fn empty_grid_gives_empty_mesh() {
        let spec = GridSpec::new(3).unwrap();
        let g = Grid::new(spec);
        let m = marching_cubes(&g);
        assert!(m.triangles.is_empty());
        assert!(m.to_glb().starts_with(b"glTF"));
    }
}
