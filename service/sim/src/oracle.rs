//! Ground-truth occupancy and colour for arbitrary points.
//!
//! **Clothed occupancy** is defined on a voxel grid (default 5 mm) in world space:
//! 1. closed solids (the `body` group and the eye spheres) are voxelized exactly by ray
//!    winding numbers along +z columns through voxel centres (front/back crossings counted
//!    with orientation, so self-intersections in extreme poses give the union, not parity
//!    errors);
//! 2. open shells (garments, hair cards, shoes) are voxelized by dense sampling and dilated
//!    by one voxel, so a shell is watertight to a 6-connected flood fill;
//! 3. a flood fill from the grid boundary through free voxels marks the outside; everything
//!    else (body, cloth, and air enclosed between cloth and body) is inside.
//!
//! `occupancy(p)` is the trilinear interpolation of the inside indicator at voxel centres, a
//! value in [0, 1] whose 0.5 level lies on the voxel boundary of the solid; `contains(p)` is
//! the indicator of the voxel holding `p`. Tested against the watertight body alone
//! (volume, signs from generalized winding numbers).

use crate::camera::Camera;
use crate::raster::Texture;
use glam::{DVec3, Vec2, Vec3};
use std::sync::{Arc, OnceLock};
use volcap_engine::field::{ColorField, FieldError, OccupancyField};
use volcap_engine::grid::BitSet;
use volcap_engine::metrics::TriangleIndex;

/// A triangle mesh in world space (metres).
pub struct WorldMesh<'a> {
    pub verts: &'a [Vec3],
    pub tris: &'a [[u32; 3]],
    /// Closed (watertight, outward) solids are filled; open shells are thickened.
    pub closed: bool,
}

/// Default voxel size: 5 mm.
pub const DEFAULT_VOXEL_M: f32 = 0.005;

pub struct Oracle {
    origin: Vec3,
    voxel: f32,
    dims: [usize; 3],
    inside: BitSet,
    /// The voxels in bricks, made on first use ([`Oracle::bricks`]).
    bricks: OnceLock<Bricks>,
}

impl Oracle {
    /// Voxelize `meshes` with voxels of `voxel` metres (at least 1 mm).
    pub fn build(meshes: &[WorldMesh], voxel: f32) -> Self {
        let voxel = voxel.max(0.001);
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for m in meshes {
            for t in m.tris {
                for &i in t {
                    lo = lo.min(m.verts[i as usize]);
                    hi = hi.max(m.verts[i as usize]);
                }
            }
        }
        if !lo.is_finite() {
            return Self {
                origin: Vec3::ZERO,
                voxel,
                dims: [1, 1, 1],
                inside: BitSet::new(1),
                bricks: OnceLock::new(),
            };
        }
        let margin = 3.0 * voxel;
        let origin = lo - Vec3::splat(margin);
        let ext = hi - lo + Vec3::splat(2.0 * margin);
        let dims = [
            (ext.x / voxel).ceil() as usize + 1,
            (ext.y / voxel).ceil() as usize + 1,
            (ext.z / voxel).ceil() as usize + 1,
        ];
        let mut o = Self {
            origin,
            voxel,
            dims,
            inside: BitSet::new(dims[0] * dims[1] * dims[2]),
            bricks: OnceLock::new(),
        };
        let mut solid = BitSet::new(o.inside.len());
        for m in meshes.iter().filter(|m| m.closed) {
            o.fill_closed(m, &mut solid);
        }
        let mut shell = BitSet::new(o.inside.len());
        for m in meshes.iter().filter(|m| !m.closed) {
            o.mark_shell(m, &mut shell);
        }
        // Dilate the shell by one voxel (6-neighbourhood) and add it to the solid.
        for idx in shell.iter_ones().collect::<Vec<_>>() {
            solid.set(idx);
            let [i, j, k] = o.unlin(idx);
            for (a, d) in [(0, -1i64), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)] {
                let mut c = [i as i64, j as i64, k as i64];
                c[a] += d;
                if (0..3).all(|x| c[x] >= 0 && (c[x] as usize) < dims[x]) {
                    solid.set(o.lin([c[0] as usize, c[1] as usize, c[2] as usize]));
                }
            }
        }
        o.flood(&solid);
        o
    }

    fn lin(&self, [i, j, k]: [usize; 3]) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    fn unlin(&self, l: usize) -> [usize; 3] {
        let (nx, ny) = (self.dims[0], self.dims[1]);
        [l % nx, (l / nx) % ny, l / (nx * ny)]
    }

    fn centre(&self, [i, j, k]: [usize; 3]) -> Vec3 {
        self.origin + (Vec3::new(i as f32, j as f32, k as f32) + 0.5) * self.voxel
    }

    fn fill_closed(&self, m: &WorldMesh, solid: &mut BitSet) {
        let [nx, ny, nz] = self.dims;
        // Column centres get a tiny irrational offset so rays never pass exactly through a
        // shared edge or vertex.
        let jitter = Vec2::new(1.234_567e-5, 2.345_678e-5) * self.voxel;
        let mut crossings: Vec<(u32, f32, i8)> = Vec::new();
        for t in m.tris {
            let [a, b, c] = t.map(|i| m.verts[i as usize]);
            let nz_ = (b - a).cross(c - a).z;
            if nz_ == 0.0 {
                continue;
            }
            let delta: i8 = if nz_ < 0.0 { 1 } else { -1 };
            let x0 = (((a.x.min(b.x).min(c.x) - self.origin.x) / self.voxel - 0.5)
                .floor()
                .max(0.0)) as usize;
            let x1 = ((((a.x.max(b.x).max(c.x) - self.origin.x) / self.voxel - 0.5).ceil())
                as usize)
                .min(nx - 1);
            let y0 = (((a.y.min(b.y).min(c.y) - self.origin.y) / self.voxel - 0.5)
                .floor()
                .max(0.0)) as usize;
            let y1 = ((((a.y.max(b.y).max(c.y) - self.origin.y) / self.voxel - 0.5).ceil())
                as usize)
                .min(ny - 1);
            let (a2, b2, c2) = (a.truncate(), b.truncate(), c.truncate());
            let area = (b2 - a2).perp_dot(c2 - a2);
            for j in y0..=y1 {
                for i in x0..=x1 {
                    let p = self.centre([i, j, 0]).truncate() + jitter;
                    let wa = (c2 - b2).perp_dot(p - b2) / area;
                    let wb = (a2 - c2).perp_dot(p - c2) / area;
                    let wc = 1.0 - wa - wb;
                    if wa > 0.0 && wb > 0.0 && wc > 0.0 {
                        let z = wa * a.z + wb * b.z + wc * c.z;
                        crossings.push(((i + nx * j) as u32, z, delta));
                    }
                }
            }
        }
        crossings.sort_unstable_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)));
        let mut s = 0;
        while s < crossings.len() {
            let col = crossings[s].0;
            let mut e = s;
            while e < crossings.len() && crossings[e].0 == col {
                e += 1;
            }
            let (i, j) = (col as usize % nx, col as usize / nx);
            let mut wind = 0i32;
            let mut c = s;
            for k in 0..nz {
                let zc = self.origin.z + (k as f32 + 0.5) * self.voxel;
                while c < e && crossings[c].1 < zc {
                    wind += crossings[c].2 as i32;
                    c += 1;
                }
                if wind > 0 {
                    solid.set(self.lin([i, j, k]));
                }
            }
            s = e;
        }
    }

    fn mark_shell(&self, m: &WorldMesh, shell: &mut BitSet) {
        let step = 0.5 * self.voxel;
        for t in m.tris {
            let [a, b, c] = t.map(|i| m.verts[i as usize]);
            let longest = (b - a).length().max((c - a).length()).max((c - b).length());
            let n = ((longest / step).ceil() as usize).clamp(1, 4096);
            for u in 0..=n {
                for v in 0..=(n - u) {
                    let p = a + (b - a) * (u as f32 / n as f32) + (c - a) * (v as f32 / n as f32);
                    if let Some(idx) = self.voxel_of(p) {
                        shell.set(idx);
                    }
                }
            }
        }
    }

    fn flood(&mut self, solid: &BitSet) {
        let [nx, ny, nz] = self.dims;
        let mut outside = BitSet::new(solid.len());
        let mut stack: Vec<u32> = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    if i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1 {
                        let l = self.lin([i, j, k]);
                        if !solid.get(l) && outside.insert(l) {
                            stack.push(l as u32);
                        }
                    }
                }
            }
        }
        while let Some(l) = stack.pop() {
            let [i, j, k] = self.unlin(l as usize);
            let mut push = |c: [usize; 3]| {
                let q = self.lin(c);
                if !solid.get(q) && outside.insert(q) {
                    stack.push(q as u32);
                }
            };
            if i > 0 {
                push([i - 1, j, k]);
            }
            if i + 1 < nx {
                push([i + 1, j, k]);
            }
            if j > 0 {
                push([i, j - 1, k]);
            }
            if j + 1 < ny {
                push([i, j + 1, k]);
            }
            if k > 0 {
                push([i, j, k - 1]);
            }
            if k + 1 < nz {
                push([i, j, k + 1]);
            }
        }
        for l in 0..self.inside.len() {
            if !outside.get(l) {
                self.inside.set(l);
            }
        }
    }

    fn voxel_of(&self, p: Vec3) -> Option<usize> {
        let q = (p - self.origin) / self.voxel;
        if !q.is_finite() || q.min_element() < 0.0 {
            return None;
        }
        let c = [q.x as usize, q.y as usize, q.z as usize];
        if (0..3).any(|a| c[a] >= self.dims[a]) {
            return None;
        }
        Some(self.lin(c))
    }

    /// Whether the voxel holding `p` is inside.
    pub fn contains(&self, p: Vec3) -> bool {
        self.voxel_of(p).is_some_and(|l| self.inside.get(l))
    }

    /// Smooth occupancy in [0, 1]: trilinear interpolation of the inside indicator.
    pub fn occupancy(&self, p: Vec3) -> f32 {
        let q = (p - self.origin) / self.voxel - Vec3::splat(0.5);
        if !q.is_finite() {
            return 0.0;
        }
        let f = q.floor();
        let t = q - f;
        let mut acc = 0.0;
        for c in 0..8 {
            let d = [c & 1, (c >> 1) & 1, c >> 2];
            let idx = [
                f.x as i64 + d[0] as i64,
                f.y as i64 + d[1] as i64,
                f.z as i64 + d[2] as i64,
            ];
            if (0..3).any(|a| idx[a] < 0 || idx[a] as usize >= self.dims[a]) {
                continue;
            }
            if self
                .inside
                .get(self.lin([idx[0] as usize, idx[1] as usize, idx[2] as usize]))
            {
                let w = (if d[0] == 1 { t.x } else { 1.0 - t.x })
                    * (if d[1] == 1 { t.y } else { 1.0 - t.y })
                    * (if d[2] == 1 { t.z } else { 1.0 - t.z });
                acc += w;
            }
        }
        acc.clamp(0.0, 1.0)
    }

    /// Voxel coordinates of `p`: voxel `i` spans `[i, i + 1)` on each axis (its centre at
    /// `i + 0.5`, where [`Self::occupancy`] reads the indicator).
    pub fn voxel_coords(&self, p: Vec3) -> Vec3 {
        (p - self.origin) / self.voxel
    }

    /// The voxels in bricks of [`BRICK`]^3, each known to read 0 or 1 everywhere (made once
    /// per oracle, on first use).
    pub fn bricks(&self) -> &Bricks {
        self.bricks.get_or_init(|| Bricks::of(self))
    }

    /// Inside volume in cubic metres.
    pub fn volume_m3(&self) -> f64 {
        self.inside.count_ones() as f64 * (self.voxel as f64).powi(3)
    }

    pub fn voxel_m(&self) -> f32 {
        self.voxel
    }

    /// The world box of the voxel grid (outside it occupancy is 0).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let d = Vec3::new(
            self.dims[0] as f32,
            self.dims[1] as f32,
            self.dims[2] as f32,
        );
        (self.origin, self.origin + d * self.voxel)
    }
}

/// Voxels per side of a brick of [`Bricks`] (2 cm at the default 5 mm voxel: ten 2 mm march
/// steps).
pub const BRICK: usize = 4;

/// Voxels around a brick that decide its state: [`Oracle::occupancy`] at a point of the
/// brick's closed box reads the voxels one beyond it; one more absorbs rounding.
const BRICK_APRON: usize = 2;

/// What [`Oracle::occupancy`] reads everywhere in a brick's closed box.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrickState {
    /// 0: no voxel within the brick and its apron is inside.
    Empty,
    /// 1: every voxel within the brick and its apron is inside (none past the grid).
    Full,
    Mixed,
}

/// The oracle's voxels in bricks of [`BRICK`]^3 voxels (brick `b` spans voxel coordinates
/// `[b B, (b + 1) B]` per axis), each empty, full or mixed as [`Oracle::occupancy`] reads
/// it: a march along a ray ([`crate::rays::ray_intervals`]) passes a brick whose reading
/// is its own state without reading the voxels. Counted with a summed-volume table.
pub struct Bricks {
    dims: [usize; 3],
    state: Vec<BrickState>,
}

impl Bricks {
    fn of(o: &Oracle) -> Self {
        let [nx, ny, nz] = o.dims;
        // Inclusive prefix counts, zero-padded: s[(i, j, k)] counts the inside voxels of
        // [0, i) x [0, j) x [0, k).
        let (sx, sy) = (nx + 1, ny + 1);
        let at = |i: usize, j: usize, k: usize| i + sx * (j + sy * k);
        let mut s = vec![0u32; sx * sy * (nz + 1)];
        for k in 0..nz {
            for j in 0..ny {
                let mut row = 0u32;
                for i in 0..nx {
                    row += u32::from(o.inside.get(o.lin([i, j, k])));
                    s[at(i + 1, j + 1, k + 1)] = row;
                }
            }
        }
        for k in 1..=nz {
            for j in 1..=ny {
                for i in 1..=nx {
                    s[at(i, j, k)] += s[at(i, j - 1, k)];
                }
            }
        }
        for k in 1..=nz {
            for j in 1..=ny {
                for i in 1..=nx {
                    s[at(i, j, k)] += s[at(i, j, k - 1)];
                }
            }
        }
        // Inside voxels of [lo, hi) (clamped to the grid).
        let count = |lo: [usize; 3], hi: [usize; 3]| -> i64 {
            let c = |i, j, k| i64::from(s[at(i, j, k)]);
            let ([x0, y0, z0], [x1, y1, z1]) = (lo, hi);
            c(x1, y1, z1) - c(x0, y1, z1) - c(x1, y0, z1) - c(x1, y1, z0)
                + c(x0, y0, z1)
                + c(x0, y1, z0)
                + c(x1, y0, z0)
                - c(x0, y0, z0)
        };
        let dims = o.dims.map(|n| n.div_ceil(BRICK));
        let side = (BRICK + 2 * BRICK_APRON) as i64;
        let mut state = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for bz in 0..dims[2] {
            for by in 0..dims[1] {
                for bx in 0..dims[0] {
                    let mut lo = [0; 3];
                    let mut hi = [0; 3];
                    let mut clipped = false;
                    for (a, b) in [bx, by, bz].into_iter().enumerate() {
                        let l = (b * BRICK) as i64 - BRICK_APRON as i64;
                        let h = ((b + 1) * BRICK + BRICK_APRON) as i64;
                        clipped |= l < 0 || h > o.dims[a] as i64;
                        lo[a] = l.max(0) as usize;
                        hi[a] = (h as usize).min(o.dims[a]);
                    }
                    let n = count(lo, hi);
                    state.push(if n == 0 {
                        BrickState::Empty
                    } else if !clipped && n == side * side * side {
                        BrickState::Full
                    } else {
                        BrickState::Mixed
                    });
                }
            }
        }
        Bricks { dims, state }
    }

    /// The state of the brick holding voxel coordinates `u` (None past the grid).
    pub fn state_at(&self, u: Vec3) -> Option<BrickState> {
        self.index(u).map(|(i, _)| self.state[i])
    }

    fn index(&self, u: Vec3) -> Option<(usize, [usize; 3])> {
        if !(u.x >= 0.0 && u.y >= 0.0 && u.z >= 0.0) {
            return None;
        }
        // Non-negative: truncation is the floor (and the cast saturates).
        let b = [u.x, u.y, u.z].map(|c| (c / BRICK as f32) as usize);
        if (0..3).any(|a| b[a] >= self.dims[a]) {
            return None;
        }
        Some((b[0] + self.dims[0] * (b[1] + self.dims[1] * b[2]), b))
    }

    /// The state of the brick that holds `u` (a point of the line `u0 + du t`, voxel
    /// coordinates) and where the line leaves it; None past the grid or where the line does
    /// not move.
    pub fn visit(&self, u: Vec3, u0: Vec3, du: Vec3) -> Option<(BrickState, f32)> {
        let (i, b) = self.index(u)?;
        let mut exit = f32::INFINITY;
        for a in 0..3 {
            let edge = if du[a] > 0.0 {
                (b[a] + 1) * BRICK
            } else if du[a] < 0.0 {
                b[a] * BRICK
            } else {
                continue;
            };
            exit = exit.min((edge as f32 - u0[a]) / du[a]);
        }
        exit.is_finite().then_some((self.state[i], exit))
    }
}

/// Generalized winding number of a triangle soup at `p` (f64; Van Oosterom & Strackee).
/// 1 inside a closed outward mesh, 0 outside.
pub fn winding_number(p: DVec3, verts: &[Vec3], tris: &[[u32; 3]]) -> f64 {
    let mut sum = 0.0;
    for t in tris {
        let [a, b, c] = t.map(|i| verts[i as usize].as_dvec3() - p);
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let num = a.dot(b.cross(c));
        let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
        sum += 2.0 * num.atan2(den);
    }
    sum / (4.0 * std::f64::consts::PI)
}

/// A surface to colour from: mesh, uv triangles, material.
pub struct ColorMesh {
    pub verts: Vec<Vec3>,
    pub tris: Vec<[u32; 3]>,
    pub uv_tris: Vec<[u32; 3]>,
    pub uvs: Vec<[f32; 2]>,
    pub texture: Option<Arc<Texture>>,
    pub color: [f32; 3],
}

/// Surface colour of the nearest surface point.
pub struct ColorOracle {
    index: TriangleIndex,
    owner: Vec<(u32, u32)>,
    meshes: Vec<ColorMesh>,
}

impl ColorOracle {
    pub fn new(meshes: Vec<ColorMesh>) -> Self {
        let mut tris = Vec::new();
        let mut owner = Vec::new();
        for (mi, m) in meshes.iter().enumerate() {
            for (ti, t) in m.tris.iter().enumerate() {
                tris.push(t.map(|i| m.verts[i as usize].as_dvec3()));
                owner.push((mi as u32, ti as u32));
            }
        }
        Self {
            index: TriangleIndex::new(tris),
            owner,
            meshes,
        }
    }

    pub fn color(&self, p: Vec3) -> [f32; 3] {
        let Some((ti, _, bary, _)) = self.index.nearest(p.as_dvec3()) else {
            return [0.0; 3];
        };
        let (mi, t) = self.owner[ti];
        let m = &self.meshes[mi as usize];
        let Some(tex) = &m.texture else {
            return m.color;
        };
        let uvt = m.uv_tris.get(t as usize).copied().unwrap_or([0; 3]);
        let uv =
            |k: usize| Vec2::from_array(m.uvs.get(uvt[k] as usize).copied().unwrap_or([0.0; 2]));
        let uv = uv(0) * bary[0] as f32 + uv(1) * bary[1] as f32 + uv(2) * bary[2] as f32;
        let s = tex.sample(uv);
        [s[0] * m.color[0], s[1] * m.color[1], s[2] * m.color[2]]
    }
}

/// The oracle as an engine field over a camera's render-view NDC cube.
pub struct SceneField {
    pub oracle: Oracle,
    pub colors: ColorOracle,
    pub camera: Camera,
}

impl OccupancyField for SceneField {
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        let view = self.camera.projector();
        for (o, p) in out.iter_mut().zip(points) {
            *o = self.oracle.occupancy(view.ndc_to_world(*p));
        }
        Ok(())
    }
}

impl ColorField for SceneField {
    fn color(&self, points: &[Vec3], out: &mut [[f32; 3]]) -> Result<(), FieldError> {
        let view = self.camera.projector();
        for (o, p) in out.iter_mut().zip(points) {
            *o = self.colors.color(view.ndc_to_world(*p));
        }
        Ok(())
    }
}
