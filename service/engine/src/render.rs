//! Mesh-free rendering with view-based culling (MonoPort Sec. 3.3).
//!
//! The grid is the render view's NDC cube (see [`crate::grid`]): pixel `(i, j)` is the
//! column of grid points `[i, j, 0..n]`, and larger `k` (larger z) is nearer the camera. The
//! image is `n x n` pixels for a grid of `n` points per axis.
//!
//! 1. Localize to level `L - 1` with the paper's hierarchical method.
//!    Optionally ([`RenderOptions::drop_apart`], [`crate::pieces`]) the level `L - 1`
//!    pieces apart from the body are set outside here, and the level-`L` nodes beside them
//!    are never evaluated (not by the dilation, the field's seeds or the conflict loop):
//!    they cast no hit and cull nothing, so what they hid is rendered. `render_gpu` does
//!    the same on the adapter (`gpu/render/pieces.rs`: the level's inside bits read back,
//!    the pieces found here, the dropped points sent up).
//! 2. Upsample and binarize to level `L`; per pixel, the first inside node from the front
//!    (largest `k`) is the *coarse hit*. Nodes behind it (`k < hit`) are **shadow nodes**
//!    and are never evaluated.
//! 3. Evaluate the remaining boundary candidates (1-ring dilated; with the field's seeds,
//!    as at every level of step 1: [`crate::localize::Hierarchical`]), run the conflict loop
//!    under the same culling, and take the first hit again. Our additions: the conflict loop
//!    at this level, and a hit is only trusted once confirmed: where the predicted hit
//!    evaluates as outside (a grazing ray), the culled candidates in front of the new first
//!    hit are released and evaluated, until every column's hit stands.
//! 4. The surface lies between the hit node and the node in front of it, placed by linear
//!    interpolation of their occupancies (equal values guarded: the midpoint is used).
//! 5. Colour comes from the colour field at that point; pixels without a hit get the
//!    background (alpha 0 for a transparent background). Optional Lambert shading uses
//!    normals from central differences of the occupancy.

use crate::field::{ColorField, Evaluator, FieldError, OccupancyField};
use crate::grid::{BitSet, Grid, GridSpec};
use crate::localize::{Hierarchical, HierarchicalMode, LocalizeError, check_coarse};
pub use bytes::{rgb8, to_u8};
use columns::{col_k, crossing_depth, first_hits, update_hits};
pub use display::{edge_coverage, outline_coverage};
use glam::Vec3;

mod bytes;
mod columns;
mod display;

/// How to render.
#[derive(Debug, Clone, Copy)]
pub struct RenderOptions {
    /// Coarsest level of the localization (at most `L - 1`).
    pub coarse_level: u32,
    /// Background RGBA in [0, 1]; alpha 0 gives a transparent background for compositing.
    pub background: [f32; 4],
    /// Shade with normals from central differences (6 extra evaluations per pixel).
    pub shade: bool,
    /// Leave out inside pieces apart from the body ([`crate::pieces`]): after step 1, the
    /// level `L - 1` pieces farther than this fraction of the grid's side from the largest
    /// are set outside, and no level-`L` node beside them is evaluated (not the field's seeds
    /// there, nor the conflict loop), so what they hid is rendered. `None`: off.
    pub drop_apart: Option<f32>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            coarse_level: crate::localize::DEFAULT_COARSE_LEVEL,
            background: [0.0; 4],
            shade: false,
            drop_apart: None,
        }
    }
}

/// What a frame cost.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// Evaluations of the level `L - 1` localization.
    pub coarse_evaluations: u64,
    /// Evaluations of the final level (culled candidates).
    pub final_evaluations: u64,
    /// Candidates never evaluated because they lie behind a confirmed hit (shadow nodes).
    pub culled: u64,
    /// Occupancy evaluations for shading normals.
    pub normal_evaluations: u64,
    /// Colour field evaluations.
    pub color_evaluations: u64,
    /// Pixels with a surface.
    pub hits: u64,
    /// Level `L - 1` points of pieces apart from the body, set outside
    /// ([`RenderOptions::drop_apart`]).
    pub dropped_apart: u64,
    /// Grid points given out as last frame ([`Renderer::hold_sides`]).
    pub held_sides: u64,
}

/// Where the last frame's time went (wall ms on the calling thread): the parts the pipeline
/// bench splits the render stage into.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RenderTimes {
    /// Steps 1-4: localization, the final level and each column's surface depth (on the GPU
    /// backend the adapter's frame, its read-back included).
    pub localize_ms: f64,
    /// Step 5: the surface points, their colour and optional shading, the grid-size image.
    pub surface_ms: f64,
}

/// A mesh-free renderer; owns its buffers and reuses them frame to frame.
#[derive(Default)]
pub struct Renderer {
    threads: usize,
    times: RenderTimes,
    hier: Hierarchical,
    grid: Option<Grid>,
    coarse_hit: Vec<i32>,
    hit: Vec<i32>,
    depth: Vec<f32>,
    rgba: Vec<u8>,
    final_nodes: Vec<u32>,
    culled: Vec<u32>,
    hit_pixels: Vec<usize>,
    pts: Vec<Vec3>,
    cols: Vec<[f32; 3]>,
    occ: Vec<f32>,
    /// Pieces apart from the body ([`RenderOptions::drop_apart`]) and the level-`L` nodes
    /// beside the points they dropped (never evaluated); `apart_set`: some bit is set.
    pieces: crate::pieces::Pieces,
    apart: BitSet,
    apart_set: bool,
    size: usize,
    /// Per column of the last frame: its surface colour (columns with a hit).
    col_of: Vec<[f32; 3]>,
    display_rgba: Vec<u8>,
    display_depth: Vec<f32>,
    display_size: usize,
    /// The last frame was rendered on the adapter (no grid here: its display image is drawn
    /// there too).
    on_gpu: bool,
    /// Partial pixels along the outline in the display image ([`Self::set_antialias`]).
    antialias: bool,
    /// The surface's dead band ([`crate::sides`]) with the next frame's band and alignment.
    sides: crate::sides::HeldSides,
}

impl Renderer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Threads for field evaluation and for the display image's bands of rows
    /// ([`Self::render_display`]; 1, the default: the calling thread only). The images do
    /// not depend on it.
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads.max(1);
    }

    /// Draw the display image's outline with partial pixels ([`edge_coverage`], the rule in
    /// `render/display.rs`; off by default: the binary rule, whose image at the grid's size
    /// is the grid image). The same on the adapter ([`Self::render_display_gpu`]).
    pub fn set_antialias(&mut self, on: bool) {
        self.antialias = on;
    }

    /// Hold grid values within `band` of those given out last frame, and sides within `band`
    /// of the level, in the next frame ([`crate::sides`]) when its alignment `key` (what puts
    /// a grid point at the same place in the field: the view and the crop) is the last
    /// frame's; given for one frame (a frame without it forgets them).
    pub fn hold_sides(&mut self, band: f32, key: Option<u64>) {
        self.sides.hold(band, key);
    }

    /// Render `field` coloured by `colors` on a grid of level `spec.level()`.
    pub fn render(
        &mut self,
        field: &dyn OccupancyField,
        colors: &dyn ColorField,
        spec: GridSpec,
        opts: &RenderOptions,
    ) -> Result<RenderStats, LocalizeError> {
        let t = std::time::Instant::now();
        let big_l = spec.level();
        let fine = spec
            .coarser()
            .ok_or(crate::grid::GridError::BadResolution(spec.n()))?;
        let coarse = check_coarse(fine, opts.coarse_level)?;
        let grid = self.grid.get_or_insert_with(|| Grid::new(spec));
        grid.reset_sparse(spec);
        let n = spec.n();
        let plane = n * n;
        let mut stats = RenderStats::default();

        // 1. Localize to L - 1 inside the level-L grid.
        self.sides.begin_pending(spec.len());
        let mut ev = Evaluator::new(field)
            .with_threads(self.threads)
            .with_sides(&mut self.sides);
        self.hier
            .run(&mut ev, grid, coarse, big_l - 1, HierarchicalMode::Paper)?;
        stats.coarse_evaluations = ev.count();

        // 1b. Pieces apart from the body left out (before the upsampling: they then have
        // no candidates, and nothing behind them is culled).
        if self.apart_set {
            self.apart.drain_ones(|_| ());
            self.apart_set = false;
        }
        if let Some(f) = opts.drop_apart {
            if self.apart.len() != spec.len() {
                self.apart.reset(spec.len());
            }
            let gap = crate::pieces::gap_points(fine, f);
            let st = self
                .pieces
                .drop_apart(grid, 2, self.hier.inside_box(), [gap; 3]);
            stats.dropped_apart = st.dropped_points as u64;
            for &q in self.pieces.dropped() {
                let c = spec.unlinear(q as usize);
                for off in crate::grid::RING26
                    .iter()
                    .chain(std::iter::once(&[0, 0, 0]))
                {
                    if let Some(p) = crate::grid::offset(c, *off, 1, n) {
                        self.apart.set(spec.linear(p));
                    }
                }
                self.apart_set = true;
            }
        }
        let (apart, any) = (&self.apart, self.apart_set);
        let away = |q: usize| !any || !apart.get(q);

        // 2. Upsample to L, coarse hits per pixel.
        self.hier.upsample(grid, big_l);
        first_hits(
            grid,
            self.hier.inside_box(),
            self.hier.row_extents(),
            &mut self.coarse_hit,
        );

        // 3. Evaluate the candidates (and the field's seeds) in front of (or at) the coarse
        // hit.
        self.hier.dilate(grid, big_l, away);
        self.hier.queue_seeds(grid, big_l, away);
        self.final_nodes.clear();
        self.culled.clear();
        for &q in &self.hier.batch {
            let (c, k) = col_k(q, plane);
            let h = self.coarse_hit[c];
            if h < 0 || k >= h {
                self.final_nodes.push(q);
            } else {
                self.culled.push(q);
            }
        }
        let before = ev.count();
        let mut start = 0;
        self.hit.clone_from(&self.coarse_hit);
        loop {
            ev.eval_grid(grid, &self.final_nodes[start..])?;
            // The conflict loop under the same culling repairs interpolated nodes that hide a
            // surface in front of the hit.
            let hits = &self.hit;
            let keep = |q: usize| {
                let (c, k) = col_k(q as u32, plane);
                let h = hits[c];
                (h < 0 || k >= h) && away(q)
            };
            self.hier.conflict_loop(
                &mut ev,
                grid,
                big_l,
                false,
                keep,
                Some(&mut self.final_nodes),
            )?;
            // A predicted hit that evaluated as outside is refuted: release the culled
            // candidates in front of the new first hit of that column and go again. Only the
            // nodes evaluated in this round changed: update their columns.
            update_hits(grid, &mut self.hit, &self.final_nodes[start..]);
            start = self.final_nodes.len();
            let hits = &self.hit;
            let final_nodes = &mut self.final_nodes;
            self.culled.retain(|&q| {
                let (c, k) = col_k(q, plane);
                let h = hits[c];
                let release = h < 0 || k >= h;
                if release {
                    final_nodes.push(q);
                }
                !release
            });
            if self.final_nodes.len() == start {
                break;
            }
        }
        stats.culled = self.culled.len() as u64;
        stats.final_evaluations = ev.count() - before;
        drop(ev);
        stats.held_sides = self.sides.held();

        // 4. Surface by interpolation at the first hit (computed above).
        self.depth.clear();
        self.depth.resize(plane, -1.0);
        for c in 0..plane {
            let k = self.hit[c];
            if k < 0 {
                continue;
            }
            let k = k as usize;
            self.depth[c] = if k + 1 < n {
                crossing_depth(
                    spec,
                    k,
                    grid.values[c + k * plane],
                    grid.values[c + (k + 1) * plane],
                )
            } else {
                1.0
            };
        }
        self.on_gpu = false;
        self.timed_finish(t, field, colors, spec, opts, stats)
    }

    /// The frame on the GPU backend's adapter (`gpu::render::GpuRenderer`): localization and
    /// the final level with culling there, from `gpu_field` (the same field as `field`, which
    /// serves the shading normals' evaluations), then the surface placed, coloured and shaded
    /// here by the same code as [`Self::render`]. Follow with [`Self::render_display_gpu`].
    #[cfg(feature = "wgpu")]
    pub fn render_gpu(
        &mut self,
        gpu: &mut crate::gpu::render::GpuRenderer,
        gpu_field: &crate::gpu::localize::GpuField<'_>,
        field: &dyn OccupancyField,
        colors: &dyn ColorField,
        spec: GridSpec,
        opts: &RenderOptions,
    ) -> Result<RenderStats, LocalizeError> {
        let t = std::time::Instant::now();
        // The dead band's memory on the adapter (the same rule: `gpu/localize/hold.rs`),
        // continued only from a frame drawn there; a CPU frame after this one starts afresh.
        let (band, key) = self.sides.take_pending();
        self.sides.forget();
        if !self.on_gpu {
            gpu.forget_sides();
        }
        gpu.hold_sides(band, key);
        let fine = spec
            .coarser()
            .ok_or(crate::grid::GridError::BadResolution(spec.n()))?;
        let coarse = check_coarse(fine, opts.coarse_level)?;
        let cols = gpu
            .frame(gpu_field, spec, coarse, opts.drop_apart)
            .map_err(FieldError::Backend)?;
        let n = spec.n();
        let stats = RenderStats {
            coarse_evaluations: cols.coarse_evaluations,
            final_evaluations: cols.final_evaluations,
            culled: cols.culled,
            dropped_apart: cols.dropped_apart,
            held_sides: cols.held_sides,
            ..Default::default()
        };
        self.depth.clear();
        self.depth
            .extend(cols.hit.iter().enumerate().map(|(c, &k)| {
                if k < 0 {
                    -1.0
                } else if (k as usize) + 1 < n {
                    crossing_depth(spec, k as usize, cols.v_in[c], cols.v_out[c])
                } else {
                    1.0
                }
            }));
        self.hit.clone_from(&cols.hit);
        self.coarse_hit.clone_from(&cols.coarse_hit);
        self.final_nodes.clear();
        self.culled.clear();
        self.on_gpu = true;
        self.timed_finish(t, field, colors, spec, opts, stats)
    }

    /// The last frame rendered by [`Self::render_gpu`] at display size, drawn on the adapter
    /// from its values (the rule of [`Self::render_display`]).
    #[cfg(feature = "wgpu")]
    pub fn render_display_gpu(
        &mut self,
        gpu: &mut crate::gpu::render::GpuRenderer,
        size: usize,
        background: [f32; 4],
    ) -> Result<&[u8], String> {
        if !self.on_gpu {
            return Err("the last frame was not rendered on the adapter".into());
        }
        gpu.display(
            size,
            crate::gpu::render::DisplayLook {
                background: background.map(to_u8),
                antialias: self.antialias,
            },
            &self.depth,
            &self.col_of,
            &mut self.display_rgba,
            &mut self.display_depth,
        )?;
        self.display_size = size.max(2);
        Ok(&self.display_rgba)
    }

    /// Where the last frame's time went ([`Self::render`] or `render_gpu`; zero before the
    /// first).
    pub fn last_times(&self) -> RenderTimes {
        self.times
    }

    /// [`Self::finish`], the frame's times kept: localization from `t` until now, the rest
    /// from now.
    fn timed_finish(
        &mut self,
        t: std::time::Instant,
        field: &dyn OccupancyField,
        colors: &dyn ColorField,
        spec: GridSpec,
        opts: &RenderOptions,
        stats: RenderStats,
    ) -> Result<RenderStats, LocalizeError> {
        let localize_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        let r = self.finish(field, colors, spec, opts, stats);
        self.times = RenderTimes {
            localize_ms,
            surface_ms: t.elapsed().as_secs_f64() * 1e3,
        };
        r
    }

    /// Steps 4 and 5 from the hits and depths per column: the surface points, their colour,
    /// the optional shading (normals from `field`) and the grid-size image.
    fn finish(
        &mut self,
        field: &dyn OccupancyField,
        colors: &dyn ColorField,
        spec: GridSpec,
        opts: &RenderOptions,
        mut stats: RenderStats,
    ) -> Result<RenderStats, LocalizeError> {
        let n = spec.n();
        let plane = n * n;
        self.pts.clear();
        self.hit_pixels.clear();
        for c in 0..plane {
            if self.hit[c] < 0 {
                continue;
            }
            let (i, j) = (c % n, c / n);
            self.pts
                .push(Vec3::new(spec.coord(i), spec.coord(j), self.depth[c]));
            self.hit_pixels.push(c);
        }
        stats.hits = self.hit_pixels.len() as u64;

        // 5. Colour (and optional shading).
        self.cols.clear();
        self.cols.resize(self.pts.len(), [0.0; 3]);
        colors.color(&self.pts, &mut self.cols)?;
        stats.color_evaluations = self.pts.len() as u64;
        for (p, c) in self.pts.iter().zip(&self.cols) {
            if c.iter().any(|x| !x.is_finite()) {
                return Err(FieldError::NonFinite {
                    index: None,
                    point: p.to_array(),
                    value: f32::NAN,
                }
                .into());
            }
        }
        if opts.shade && !self.pts.is_empty() {
            let h = 0.5 * spec.spacing();
            let mut probe = Vec::with_capacity(self.pts.len() * 6);
            for p in &self.pts {
                for a in 0..3 {
                    let mut d = Vec3::ZERO;
                    d[a] = h;
                    probe.push(*p + d);
                    probe.push(*p - d);
                }
            }
            self.occ.clear();
            self.occ.resize(probe.len(), 0.0);
            let mut ev = Evaluator::new(field).with_threads(self.threads);
            ev.eval_points(&probe, &mut self.occ)?;
            stats.normal_evaluations = ev.count();
            // Light from the upper left front (y is down, z toward the camera).
            let light = Vec3::new(-0.4, -0.6, 0.7).normalize();
            for (i, c) in self.cols.iter_mut().enumerate() {
                let o = &self.occ[i * 6..i * 6 + 6];
                let grad = Vec3::new(o[0] - o[1], o[2] - o[3], o[4] - o[5]);
                // Occupancy grows inward: the outward normal is -grad.
                let nrm = (-grad).normalize_or_zero();
                let lambert = if nrm == Vec3::ZERO {
                    1.0
                } else {
                    nrm.dot(light).max(0.0)
                };
                let s = 0.35 + 0.65 * lambert;
                for x in c.iter_mut() {
                    *x *= s;
                }
            }
        }
        self.size = n;
        self.rgba.clear();
        let bg = opts.background.map(to_u8);
        self.rgba.resize(plane * 4, 0);
        for px in self.rgba.chunks_exact_mut(4) {
            px.copy_from_slice(&bg);
        }
        self.col_of.clear();
        self.col_of.resize(plane, [0.0; 3]);
        for (&c, col) in self.hit_pixels.iter().zip(&self.cols) {
            self.col_of[c] = *col;
            let px = &mut self.rgba[c * 4..c * 4 + 4];
            px[0] = to_u8(col[0]);
            px[1] = to_u8(col[1]);
            px[2] = to_u8(col[2]);
            px[3] = 255;
        }
        Ok(stats)
    }

    /// The last frame at display resolution: `size x size` pixels (any `size >= 2`), more
    /// rays than grid columns. Pixel `(u, v)` is the ray at grid position
    /// `(u (n - 1) / (size - 1), v (n - 1) / (size - 1))` (integer part and fraction from
    /// integer arithmetic); along it the occupancy is the bilinear blend of the four columns
    /// around it, scanned front to back between the nearest of their hits (one node in
    /// front) and the farthest (one behind), and the surface is placed where the blend
    /// crosses 0.5, by the same linear rule as the grid image. The colour is the blend of the
    /// neighbouring columns' surface colours whose depth is within two grid spacings of the
    /// pixel's (all of them where none is). No field is evaluated: the cost is a few taps per
    /// pixel. At `size == n` it is the grid image exactly (tested) unless the outline is
    /// antialiased ([`Self::set_antialias`]). Returns the RGBA8 image;
    /// [`Self::display_depth`] has its depth.
    pub fn render_display(&mut self, size: usize, background: [f32; 4]) -> &[u8] {
        let size = size.max(2);
        let bg = background.map(to_u8);
        self.display_size = size;
        self.display_rgba.clear();
        self.display_rgba.resize(size * size * 4, 0);
        for px in self.display_rgba.chunks_exact_mut(4) {
            px.copy_from_slice(&bg);
        }
        self.display_depth.clear();
        self.display_depth.resize(size * size, -1.0);
        let (Some(grid), n) = (self.grid.as_ref().filter(|_| !self.on_gpu), self.size) else {
            return &self.display_rgba;
        };
        let plane = n * n;
        let whole = [self.hit.len(), self.depth.len(), self.col_of.len()] == [plane; 3];
        if n < 2 || grid.spec().n() != n || !whole {
            return &self.display_rgba;
        }
        let columns = display::Columns {
            grid,
            hit: &self.hit,
            depth: &self.depth,
            color: &self.col_of,
            antialias: self.antialias,
        };
        display::draw(
            &columns,
            size,
            self.threads,
            &mut self.display_rgba,
            &mut self.display_depth,
        );
        &self.display_rgba
    }

    /// Side of the last [`Self::render_display`] image.
    pub fn display_size(&self) -> usize {
        self.display_size
    }

    /// NDC z per pixel of the last [`Self::render_display`] image, -1 where there is none.
    pub fn display_depth(&self) -> &[f32] {
        &self.display_depth
    }

    /// Image side in pixels (`n`).
    pub fn size(&self) -> usize {
        self.size
    }

    /// RGBA8, row-major, rows top to bottom (`j`), `size x size`.
    pub fn rgba(&self) -> &[u8] {
        &self.rgba
    }

    /// NDC z of the surface per pixel, or -1 where there is none (see [`Self::hits`]).
    pub fn depth(&self) -> &[f32] {
        &self.depth
    }

    /// Final first-hit node per pixel (-1 for none).
    pub fn hits(&self) -> &[i32] {
        &self.hit
    }

    /// Coarse (upsampled level `L - 1`) first-hit node per pixel (-1 for none).
    pub fn coarse_hits(&self) -> &[i32] {
        &self.coarse_hit
    }

    /// Linear indices of the level-`L` nodes evaluated in the last frame's final pass.
    pub fn final_nodes(&self) -> &[u32] {
        &self.final_nodes
    }

    /// The last frame's grid (levels up to `L - 1` localized, level `L` partially).
    pub fn grid(&self) -> Option<&Grid> {
        self.grid.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::AnalyticScene;
    use crate::grid::IndexBox;

    /// The incremental hit update equals a full scan of the final grid, on scenes with thin
    /// parts, several bodies and refuted hits.
    #[test]
    fn incremental_hits_equal_a_full_scan() {
        for name in ["capsule-human", "two-bodies", "thin-plate", "torus"] {
            let scene = AnalyticScene::by_name(name).unwrap();
            for level in [6, 7] {
                let spec = GridSpec::new(level).unwrap();
                let mut r = Renderer::new();
                r.render(&scene, &scene, spec, &RenderOptions::default())
                    .unwrap();
                let mut full = Vec::new();
                let n = spec.n();
                let all = IndexBox {
                    lo: [0; 3],
                    hi: [n - 1; 3],
                };
                let rows = vec![[0, n as u32 - 1]; n * n];
                first_hits(r.grid.as_ref().unwrap(), all, &rows, &mut full);
                assert_eq!(r.hit, full, "{name} at level {level}");
            }
        }
    }

    /// A renderer that drew another scene, at another resolution or after a dense fill of its
    /// grid draws exactly what a fresh one draws: nothing of an earlier frame survives the
    /// sparse reset.
    #[test]
    fn reused_renderer_equals_a_fresh_one() {
        let opts = RenderOptions::default();
        let a = AnalyticScene::by_name("two-bodies").unwrap();
        let b = AnalyticScene::by_name("capsule-human").unwrap();
        let (s6, s7) = (GridSpec::new(6).unwrap(), GridSpec::new(7).unwrap());
        let mut fresh = Renderer::new();
        fresh.render(&b, &b, s7, &opts).unwrap();
        let mut reused = Renderer::new();
        reused.render(&a, &a, s7, &opts).unwrap();
        reused.render(&a, &a, s6, &opts).unwrap();
        reused.render(&b, &b, s7, &opts).unwrap();
        assert_eq!(reused.rgba(), fresh.rgba());
        assert_eq!(reused.hits(), fresh.hits());
        assert_eq!(reused.coarse_hits(), fresh.coarse_hits());
        // A grid left full of ones by a dense method, then rendered into.
        if let Some(g) = reused.grid.as_mut() {
            g.reset(s7);
            g.values.fill(1.0);
        }
        reused.render(&b, &b, s7, &opts).unwrap();
        assert_eq!(reused.rgba(), fresh.rgba());
    }
}
