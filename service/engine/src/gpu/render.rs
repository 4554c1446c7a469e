//! The mesh-free renderer on the adapter: the grid localized there ([`GpuLocalizer`], levels
//! up to `L - 1`), then the final level with the renderer's culling (`render.wgsl`: the
//! coarse hit per column, the dilated candidates split into those in front of it and the
//! shadow nodes, the conflict loop that evaluates nothing behind a column's current hit, the
//! hits raised and refuted after each round, the culled nodes released in front of a new
//! hit, until none is), and the frame at display size (`display.wgsl`). What comes back is
//! per column: the hit, the coarse hit and the two values around the surface (four numbers
//! a pixel); the host places the surface, queries the colour field there and shades, as
//! `render.rs` does (the same code), and the display image comes back whole. The grid's
//! values stay on the adapter.
//!
//! The evaluated set is the CPU renderer's (tests/gpu.rs: equal hits, depths and images on
//! the analytic scenes from a host-evaluated table; the real photos' fields through the
//! Fourier kernel in tools/volcap/tests/gpu_frames.rs).

use super::kit::entry;
use super::localize::{
    CULLED, Dispatch, EVALS, GpuField, GpuLocalizer, LIST, LOG, MARK, Retry, Tiling,
};
use super::{Gpu, groups};
use crate::grid::GridSpec;
use crate::localize::{HierarchicalMode, RoundWaits};
use std::sync::Arc;
use std::sync::atomic::Ordering;

mod pieces;

const RENDER: &str = concat!(include_str!("localize.wgsl"), include_str!("render.wgsl"));
const DISPLAY: &str = include_str!("display.wgsl");

/// What the final level left per column (indices `i + n j`).
#[derive(Debug, Default, Clone)]
pub struct Columns {
    /// The first inside node from the front, or -1.
    pub hit: Vec<i32>,
    /// The first hit after upsampling level `L - 1` (before the final level), or -1.
    pub coarse_hit: Vec<i32>,
    /// The values at the hit node and at the node in front of it (0 past the grid).
    pub v_in: Vec<f32>,
    pub v_out: Vec<f32>,
    /// Evaluations of the levels up to `L - 1`, and of the final level.
    pub coarse_evaluations: u64,
    pub final_evaluations: u64,
    /// Candidates never evaluated: behind a confirmed hit.
    pub culled: u64,
    /// Level `L - 1` points of pieces apart from the body, set outside (`render.rs`'s
    /// `RenderStats::dropped_apart`).
    pub dropped_apart: u64,
    /// Grid points given out as last frame's (the surface's dead band:
    /// [`GpuRenderer::hold_sides`]).
    pub held_sides: u64,
}

struct RenderPipes {
    /// The values' tiling the kernels are made for (the localizer's).
    tiling: Tiling,
    layout: wgpu::BindGroupLayout,
    first_hits: wgpu::ComputePipeline,
    split: wgpu::ComputePipeline,
    log_append: wgpu::ComputePipeline,
    conflict_keep: wgpu::ComputePipeline,
    raise: wgpu::ComputePipeline,
    refute: wgpu::ComputePipeline,
    reset_release: wgpu::ComputePipeline,
    release: wgpu::ComputePipeline,
    surface: wgpu::ComputePipeline,
    /// Pieces apart from the body (`render/pieces.rs`).
    apart: pieces::ApartPipes,
    display_layout: wgpu::BindGroupLayout,
    display: wgpu::ComputePipeline,
}

/// Buffers per grid size: the columns, their read-back, the two parameter blocks (culled
/// list 0 or 1 read) and their bind groups. Rebuilt when the localizer's buffers are.
struct ColumnBufs {
    spec: GridSpec,
    /// The localizer's buffer generation the bind groups hold.
    generation: u64,
    cols: wgpu::Buffer,
    staging: wgpu::Buffer,
    binds: [wgpu::BindGroup; 2],
}

struct DisplayBufs {
    size: usize,
    n: usize,
    params: wgpu::Buffer,
    cols: wgpu::Buffer,
    out: wgpu::Buffer,
    /// The image, then the pass's two timestamps (where the adapter has them).
    staging: wgpu::Buffer,
    timer: Option<super::Timer>,
}

/// How [`GpuRenderer::display`] draws: the background (RGBA8) and whether the outline is
/// antialiased (`Renderer::set_antialias`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DisplayLook {
    pub background: [u8; 4],
    pub antialias: bool,
}

/// The renderer's state on the adapter, reused frame to frame.
pub struct GpuRenderer {
    gpu: Arc<Gpu>,
    loc: GpuLocalizer,
    pipes: RenderPipes,
    columns: Option<ColumnBufs>,
    display: Option<DisplayBufs>,
    /// The last frame's columns, and the host-side scratch of the read-backs and uploads,
    /// kept from frame to frame.
    out: Columns,
    raw: Vec<u32>,
    upload: Vec<f32>,
    apart: pieces::Apart,
}

impl RenderPipes {
    fn new(gpu: &Gpu, layout0: &wgpu::BindGroupLayout, tiling: Tiling) -> Result<Self, String> {
        use super::kit::{bind_layout, module, pipeline_layout, storage, uniform};
        let d = &gpu.device;
        let layout = bind_layout(
            d,
            "render",
            &[uniform(1), storage(2, false), storage(3, false)],
        );
        let mut display_entries = tiling.layout_entries(true);
        display_entries.extend([
            uniform(0),
            storage(2, true),
            storage(3, true),
            storage(4, false),
        ]);
        let display_layout = bind_layout(d, "display", &display_entries);
        let scope = d.push_error_scope(wgpu::ErrorFilter::Validation);
        let render = module(d, "render", &format!("{}{RENDER}", tiling.wgsl(true)));
        let display = module(d, "display", &format!("{}{DISPLAY}", tiling.wgsl(false)));
        let with_render = pipeline_layout(d, &[layout0, &layout]);
        let display_pl = pipeline_layout(d, &[&display_layout]);
        let pipe = |m, layout, entry| super::kit::pipeline(d, m, layout, entry);
        let p = RenderPipes {
            first_hits: pipe(&render, &with_render, "first_hits"),
            split: pipe(&render, &with_render, "split"),
            log_append: pipe(&render, &with_render, "log_append"),
            conflict_keep: pipe(&render, &with_render, "conflict_keep"),
            raise: pipe(&render, &with_render, "raise"),
            refute: pipe(&render, &with_render, "refute"),
            reset_release: pipe(&render, &with_render, "reset_release"),
            release: pipe(&render, &with_render, "release"),
            surface: pipe(&render, &with_render, "surface"),
            display: pipe(&display, &display_pl, "main"),
            apart: pieces::ApartPipes::new(d, layout0, tiling),
            tiling,
            layout,
            display_layout,
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!("the render kernels: {e}"));
        }
        Ok(p)
    }
}

impl GpuRenderer {
    pub fn new(gpu: Arc<Gpu>) -> Result<Self, String> {
        let loc = GpuLocalizer::new(gpu.clone())?;
        let pipes = RenderPipes::new(&gpu, &loc.pipes().layout0, loc.pipes().tiling)?;
        Ok(GpuRenderer {
            gpu,
            loc,
            pipes,
            columns: None,
            display: None,
            out: Columns::default(),
            raw: Vec::new(),
            upload: Vec::new(),
            apart: pieces::Apart::default(),
        })
    }

    /// Conflict rounds per read-back at most in the levels up to `L - 1`
    /// ([`GpuLocalizer::with_rounds_per_wait`]; 1 by default); the final level's loop reads
    /// its counts after each round.
    pub fn with_rounds_per_wait(mut self, n: usize) -> Self {
        self.loc = self.loc.with_rounds_per_wait(n);
        self
    }

    /// When the levels' conflict rounds are read ([`GpuLocalizer::with_round_waits`]; the
    /// final level's loop reads after each round either way).
    pub fn with_round_waits(mut self, waits: RoundWaits) -> Self {
        self.loc = self.loc.with_round_waits(waits);
        self
    }

    /// Lists of `cap` entries at first (tests make them small to exercise their growth).
    pub fn with_list_capacity(mut self, cap: usize) -> Self {
        self.loc = self.loc.with_list_capacity(cap);
        self
    }

    /// Index lists of at most `n` entries ([`GpuLocalizer::with_max_list_entries`]).
    pub fn with_max_list_entries(mut self, n: usize) -> Self {
        self.loc = self.loc.with_max_list_entries(n);
        self
    }

    /// Tiles of the grid's values of at most `n` floats
    /// ([`GpuLocalizer::with_tile_floats`]).
    pub fn with_tile_floats(mut self, n: usize) -> Self {
        self.loc = self.loc.with_tile_floats(n);
        self
    }

    /// The surface's dead band in the next frame ([`GpuLocalizer::hold_sides`]).
    pub fn hold_sides(&mut self, band: f32, key: Option<u64>) {
        self.loc.hold_sides(band, key);
    }

    /// Forget the values held ([`GpuLocalizer::forget_sides`]).
    pub fn forget_sides(&mut self) {
        self.loc.forget_sides();
    }

    /// Why the last frame was not held though asked to ([`GpuLocalizer::hold_refused`]).
    pub fn hold_refused(&self) -> Option<&str> {
        self.loc.hold_refused()
    }

    /// Whether a grid of `spec` fits the adapter (see [`GpuLocalizer::check_size`]).
    pub fn check_size(&self, spec: GridSpec) -> Result<(), String> {
        self.loc.check_size(spec)
    }

    fn column_bufs(&mut self, spec: GridSpec) -> Result<(), String> {
        self.loc.ensure_buffers(spec)?;
        let tiling = self.loc.pipes().tiling;
        if self.pipes.tiling != tiling {
            // The localizer's kernels were made for another tiling of the values: so are ours.
            self.pipes = RenderPipes::new(&self.gpu, &self.loc.pipes().layout0, tiling)?;
            self.columns = None;
        }
        let (generation, extra, _) = self.loc.render_buffers().ok_or("no grid buffers")?;
        let fits = self
            .columns
            .as_ref()
            .is_some_and(|c| c.spec == spec && c.generation == generation);
        if fits {
            return Ok(());
        }
        use wgpu::BufferUsages as U;
        let d = &self.gpu.device;
        let plane = (spec.n() * spec.n()) as u64;
        let cols = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("columns"),
            size: plane * 16,
            usage: U::STORAGE | U::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("columns read-back"),
            size: plane * 16,
            usage: U::MAP_READ | U::COPY_DST,
            mapped_at_creation: false,
        });
        let binds = [0u32, 1].map(|x| {
            let params = d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("render params"),
                size: 16,
                usage: U::UNIFORM | U::COPY_DST,
                mapped_at_creation: false,
            });
            self.gpu
                .queue
                .write_buffer(&params, 0, bytemuck::cast_slice(&[plane as u32, x, 0, 0]));
            d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &self.pipes.layout,
                entries: &[entry(1, &params), entry(2, &cols), entry(3, extra)],
            })
        });
        self.columns = Some(ColumnBufs {
            spec,
            generation,
            cols,
            staging,
            binds,
        });
        Ok(())
    }

    /// Localize `field` up to level `L - 1` from `coarse` (the paper's method), then the final
    /// level with culling; the columns come back. With `drop_apart` (a gap, a fraction of
    /// the grid's side: `RenderOptions::drop_apart`), the level `L - 1` pieces apart from the
    /// body are left out in between (`render/pieces.rs`).
    pub fn frame(
        &mut self,
        field: &GpuField<'_>,
        spec: GridSpec,
        coarse: u32,
        drop_apart: Option<f32>,
    ) -> Result<&Columns, String> {
        let fine = spec
            .level()
            .checked_sub(1)
            .filter(|l| *l >= 1)
            .ok_or_else(|| format!("a {}^3 grid is too small to render", spec.n()))?;
        if coarse == 0 || coarse > fine {
            return Err(format!(
                "coarse level {coarse} must lie in 1..={fine} to render a {}^3 grid",
                spec.n()
            ));
        }
        self.loc.prepare(field, spec, coarse, true)?;
        loop {
            match self.attempt(spec, coarse, fine, drop_apart)? {
                None => {
                    self.loc.done = true;
                    return Ok(&self.out);
                }
                Some(r) => self.loc.retry(r, spec)?,
            }
        }
    }

    /// One attempt into `self.out`; `Some` when it must run again (a list overflowed, or the
    /// levels' predicted rounds fell short).
    fn attempt(
        &mut self,
        spec: GridSpec,
        coarse: u32,
        fine: u32,
        drop_apart: Option<f32>,
    ) -> Result<Option<Retry>, String> {
        // The localizer's buffers first (the column bind groups hold its lists).
        self.column_bufs(spec)?;
        let cb = self.columns.as_ref().expect("made above");
        let rp = &self.pipes;
        let mode = HierarchicalMode::Paper;
        let mut rec = self.loc.recorder(spec, coarse, mode)?;
        if let Some(r) = rec.levels(coarse, fine, mode)? {
            return Ok(Some(r));
        }
        let p = rec.p;
        rec.pass(&[(&p.mark_evals, fine, 0, Dispatch::One)]);
        // Pieces apart from the body left out (render.rs step 1b); its read-back the first
        // of a predicted frame's, which may say to run it again.
        let dropped_apart = match drop_apart {
            Some(frac) => match self.apart.run(&mut rec, &rp.apart, spec, fine, frac)? {
                Ok(n) => n,
                Err(r) => return Ok(Some(r)),
            },
            None => 0,
        };
        let big_l = spec.level();
        let plane = (spec.n() * spec.n()) as u32;
        let ev = rec.eval_pipe();
        let r0 = &cb.binds[0];
        let pts = rec.level_points(big_l);
        // Upsample to L, coarse hits, dilate (and the seeds), split into the front (list 1) and
        // culled 0.
        rec.pass(&[
            (&p.zero, big_l, 1, Dispatch::One),
            (&p.upsample, big_l, 1, Dispatch::Points(pts)),
            (&rp.first_hits, big_l, 0, Dispatch::With(r0, Some(plane))),
            (&p.prep_cand, big_l, 1, Dispatch::Prep),
            (&p.dilate, big_l, 1, Dispatch::Indirect),
        ]);
        // The field's seeds join the dilated list (as render.rs), then the split.
        rec.seeds(big_l, 1);
        rec.pass(&[
            (&p.zero, big_l, 0, Dispatch::One),
            (&p.prep_src, big_l, 0, Dispatch::Prep),
            (&rp.split, big_l, 0, Dispatch::With(r0, None)),
        ]);
        // The front (list 1) evaluated and logged first; orientation 2 reads the log (the
        // released points) in later rounds. The batch the conflict loop scans first is the
        // whole dilated list (list 0, as render.rs: its culled points, unevaluated, show no
        // conflict until they are released and evaluated).
        let mut batch = 0usize;
        let mut x = 0usize;
        let mut first = true;
        loop {
            if first {
                rec.pass(&[
                    (&p.prep_eval, big_l, 1, Dispatch::Prep),
                    (ev, big_l, 1, Dispatch::Eval),
                    (&p.prep_src, big_l, 1, Dispatch::Prep),
                    (&rp.log_append, big_l, 1, Dispatch::With(r0, None)),
                ]);
            } else {
                // The released points are the log's first entries: evaluated from there.
                rec.pass(&[
                    (&p.prep_eval, big_l, 2, Dispatch::Prep),
                    (ev, big_l, 2, Dispatch::Eval),
                ]);
            }
            // The conflict loop under the culling of the hits as they stand: the last batch
            // scanned (render.rs: the hierarchical localizer's batch), each round evaluated
            // and logged.
            loop {
                let o = batch;
                rec.pass(&[
                    (&p.zero, big_l, o, Dispatch::One),
                    (&p.prep_src, big_l, o, Dispatch::Prep),
                    (&rp.conflict_keep, big_l, o, Dispatch::With(r0, None)),
                ]);
                let counts = rec.counts()?;
                if let Some(r) = Retry::of(&counts) {
                    return Ok(Some(r));
                }
                if counts[LIST[1 - o]] == 0 {
                    break;
                }
                batch = 1 - o;
                rec.pass(&[
                    (&p.prep_eval, big_l, batch, Dispatch::Prep),
                    (ev, big_l, batch, Dispatch::Eval),
                    (&p.prep_src, big_l, batch, Dispatch::Prep),
                    (&rp.log_append, big_l, batch, Dispatch::With(r0, None)),
                ]);
            }
            // Hits from the round's log, then the release of culled points in front of them.
            let rx = &cb.binds[x];
            rec.pass(&[
                (&p.prep_src, big_l, 2, Dispatch::Prep),
                (&rp.raise, big_l, 2, Dispatch::With(rx, None)),
                (&rp.refute, big_l, 2, Dispatch::With(rx, None)),
                (&rp.reset_release, big_l, 0, Dispatch::With(rx, Some(1))),
                (&p.prep_src, big_l, 3 + x, Dispatch::Prep),
                (&rp.release, big_l, 0, Dispatch::With(rx, None)),
            ]);
            x = 1 - x;
            let counts = rec.counts()?;
            if let Some(r) = Retry::of(&counts) {
                return Ok(Some(r));
            }
            first = false;
            if counts[LOG] == 0 {
                break;
            }
        }
        rec.pass(&[(&rp.surface, big_l, 0, Dispatch::With(r0, Some(plane)))]);
        // The columns come back with the counters, after one wait.
        let n2 = plane as usize;
        let raw = &mut self.raw;
        raw.resize(4 * n2, 0);
        let counts = rec.counts_and_read(&cb.cols, &cb.staging, bytemuck::cast_slice_mut(raw))?;
        let dispatches = std::mem::take(&mut rec.dispatches);
        drop(rec);
        if let Some(r) = Retry::of(&counts) {
            return Ok(Some(r));
        }
        self.loc.predictor.learn(spec, coarse, mode, &counts);
        self.loc.finish_hold(&counts);
        let c = self.gpu.count();
        c.dispatches.fetch_add(dispatches, Ordering::Relaxed);
        c.render_runs.fetch_add(1, Ordering::Relaxed);
        let hit = |h: &u32| *h as i32 - 1;
        let o = &mut self.out;
        let fill_i = |v: &mut Vec<i32>, r: &[u32]| {
            v.clear();
            v.extend(r.iter().map(hit));
        };
        let fill_f = |v: &mut Vec<f32>, r: &[u32]| {
            v.clear();
            v.extend(r.iter().map(|&b| f32::from_bits(b)));
        };
        fill_i(&mut o.hit, &raw[..n2]);
        fill_i(&mut o.coarse_hit, &raw[n2..2 * n2]);
        fill_f(&mut o.v_in, &raw[2 * n2..3 * n2]);
        fill_f(&mut o.v_out, &raw[3 * n2..]);
        o.coarse_evaluations = counts[MARK] as u64;
        o.final_evaluations = (counts[EVALS] as u64).saturating_sub(counts[MARK] as u64);
        o.culled = counts[CULLED[x]] as u64;
        o.dropped_apart = dropped_apart;
        o.held_sides = self.loc.held_sides();
        Ok(None)
    }

    /// The last frame at `size x size` pixels (`render.rs` `render_display`'s rule, from the
    /// values on the adapter) over `look`'s background: RGBA8 into `rgba` and depth into `z`. `depth` and `color` are
    /// the frame's per column (as the host placed and coloured them).
    pub fn display(
        &mut self,
        size: usize,
        look: DisplayLook,
        depth: &[f32],
        color: &[[f32; 3]],
        rgba: &mut Vec<u8>,
        z: &mut Vec<f32>,
    ) -> Result<(), String> {
        if !self.loc.done {
            return Err("no frame rendered on the adapter".into());
        }
        let size = size.max(2);
        let cb = self
            .columns
            .as_ref()
            .ok_or("no frame rendered on the adapter")?;
        let spec = cb.spec;
        let (n, plane) = (spec.n(), spec.n() * spec.n());
        if depth.len() != plane || color.len() != plane {
            return Err(format!(
                "{} depths and {} colours for {plane} columns",
                depth.len(),
                color.len()
            ));
        }
        let fits = self
            .display
            .as_ref()
            .is_some_and(|d| d.size == size && d.n == n);
        if !fits {
            use wgpu::BufferUsages as U;
            let d = &self.gpu.device;
            let buf = |label, bytes: usize, usage| {
                d.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes as u64,
                    usage,
                    mapped_at_creation: false,
                })
            };
            let params = buf("display params", 32, U::UNIFORM | U::COPY_DST);
            let cols = buf(
                "column colours",
                (4 * plane + n) * 4,
                U::STORAGE | U::COPY_DST,
            );
            let out = buf(
                "display image",
                2 * size * size * 4,
                U::STORAGE | U::COPY_SRC,
            );
            let staging = buf(
                "display read-back",
                2 * size * size * 4 + 16,
                U::MAP_READ | U::COPY_DST,
            );
            self.display = Some(DisplayBufs {
                size,
                n,
                params,
                cols,
                out,
                staging,
                timer: self.gpu.timer(),
            });
        }
        let db = self.display.as_ref().expect("made above");
        // Bound each frame: the grid's buffers are remade when its lists grow.
        let (_, _, values) = self.loc.render_buffers().ok_or("no grid buffers")?;
        let mut entries = self.pipes.tiling.entries(values);
        entries.extend([
            entry(0, &db.params),
            entry(2, &cb.cols),
            entry(3, &db.cols),
            entry(4, &db.out),
        ]);
        let bind = self
            .gpu
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &self.pipes.display_layout,
                entries: &entries,
            });
        let bg = u32::from_le_bytes(look.background);
        let params = [
            n as u32,
            size as u32,
            plane as u32,
            bg,
            spec.spacing().to_bits(),
            u32::from(look.antialias),
            0,
            0,
        ];
        let cols = &mut self.upload;
        cols.clear();
        for (d, c) in depth.iter().zip(color) {
            cols.extend_from_slice(&[*d, c[0], c[1], c[2]]);
        }
        cols.extend((0..n).map(|k| spec.coord(k)));
        let q = &self.gpu.queue;
        q.write_buffer(&db.params, 0, bytemuck::cast_slice(&params));
        q.write_buffer(&db.cols, 0, bytemuck::cast_slice(cols));
        let c = self.gpu.count();
        c.bytes_up
            .fetch_add((cols.len() * 4 + 32) as u64, Ordering::Relaxed);
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes: db.timer.as_ref().map(|t| t.begin()),
            });
            pass.set_pipeline(&self.pipes.display);
            pass.set_bind_group(0, &bind, &[]);
            let (x, y) = groups((size * size) as u32);
            pass.dispatch_workgroups(x, y, 1);
        }
        c.dispatches.fetch_add(1, Ordering::Relaxed);
        let image = (2 * size * size * 4) as u64;
        enc.copy_buffer_to_buffer(&db.out, 0, &db.staging, 0, image);
        if let Some(t) = &db.timer {
            t.end_into(&mut enc, &db.staging, image);
        }
        let raw = &mut self.raw;
        // The image's words, then the timestamps' four.
        let stamps = if db.timer.is_some() { 4 } else { 0 };
        raw.resize(2 * size * size + stamps, 0);
        self.gpu
            .submit_and_read_bytes(enc, &db.staging, bytemuck::cast_slice_mut(raw))?;
        if stamps > 0 {
            let ticks: &[u8] = bytemuck::cast_slice(&raw[2 * size * size..]);
            self.gpu.add_span(&c.display_gpu_ns, ticks);
        }
        rgba.clear();
        rgba.extend(raw[..size * size].iter().flat_map(|p| p.to_le_bytes()));
        z.clear();
        z.extend(
            raw[size * size..2 * size * size]
                .iter()
                .map(|&b| f32::from_bits(b)),
        );
        Ok(())
    }
}
