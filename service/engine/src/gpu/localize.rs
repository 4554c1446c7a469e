//! The paper's hierarchical localization on the adapter (and its no-conflict and tight
//! variants): the grid's values, the "already handled" bits and the index lists live in
//! the adapter's buffers; the field is evaluated there too (the Fourier head with the person
//! mask, or a table of values the host computed, which the parity tests use for the analytic
//! scenes). The steps are those of `localize/hierarchical.rs` (`localize.wgsl`): per level,
//! upsample the binarized coarse field and list the fractional points, dilate them by the
//! 1-ring (or not: tight), evaluate, then the conflict loop: its first round goes with the
//! level's passes, the next ones one per submission with the lists' lengths read back after
//! each (36 bytes); [`GpuLocalizer::with_rounds_per_wait`] records them in growing batches
//! instead (a round over an empty list does nothing). Lists are appended with atomics: their order
//! differs from the CPU's, their sets do not (a point is listed by whichever invocation claims
//! its bit first, and what decides whether it is listed does not change during a round).
//!
//! The values stay on the adapter for the stages that read them there;
//! [`GpuLocalizer::read_grid`] brings them (and the evaluated set) back into a CPU [`Grid`].
//! The lists start at [`START_CAP`] entries and grow (the frame run again) when a level
//! needs more. The grid's values are one storage buffer where one binding holds them (a
//! GPU's: [`super::buffer_limits`]), else tiles of a power of two floats each, in bindings
//! of their own ([`Tiling`]: 513^3, 540 MB, is five tiles where a binding holds 128 MiB, as
//! on lavapipe); the kernels read and write them through `vget` / `vset`. A grid whose tiles
//! need more storage bindings than the adapter has is refused with the sizes named.

use super::Gpu;
use super::kit::entry;
use crate::grid::{Grid, GridSpec};
use crate::localize::{HierarchicalMode, LocalizeStats, RoundWaits, check_coarse};
use std::sync::Arc;
use std::sync::atomic::Ordering;

mod field;
mod hold;
mod plan;
mod record;
mod tiling;
use field::FieldBufs;
pub use field::{GpuField, MapsRef};
use plan::LEVEL_KEYS;
use plan::Predictor;
pub(super) use record::{Dispatch, Rec, Retry};
pub use tiling::Tiling;

const BOOK: &str = include_str!("localize.wgsl");
const EVAL: &str = concat!(
    include_str!("series.wgsl"),
    include_str!("localize_eval.wgsl")
);

/// Entries each index list holds at first.
pub const START_CAP: usize = 1 << 18;

/// Counter slots (`localize.wgsl`; slot 0 counts the candidates).
pub(super) const LIST: [usize; 2] = [1, 2];
pub(super) const OVERFLOW: usize = 3;
pub(super) const EVALS: usize = 4;
/// The renderer's log of a round's evaluated points, and its two lists of culled points.
pub(super) const LOG: usize = 5;
pub(super) const CULLED: [usize; 2] = [6, 7];
/// Conflict rounds that evaluated something (`prep_round`).
pub(super) const ROUNDS: usize = 8;
/// Raised when a level's predicted rounds fell short (`plan.rs`).
pub(super) const MISS: usize = 9;
/// The evaluations before the render's final level.
pub(super) const MARK: usize = 10;
/// Conflict rounds per level ([`LEVEL_KEYS`] slots, `plan::level_key`).
pub(super) const LEVEL_ROUNDS: usize = 11;
/// Grid points given out as last frame's (the surface's dead band: `hold.rs`).
pub(super) const HELD: usize = LEVEL_ROUNDS + LEVEL_KEYS;
pub(super) const COUNTS: usize = HELD + 1;
/// Parameter blocks per level: lists 0 and 1 read (the other written), the renderer's log
/// read, its culled list 0 or 1 counted.
const ORIENTATIONS: usize = 5;

pub(super) struct Pipes {
    /// The values' tiling the kernels and `layout0` are made for.
    pub(super) tiling: Tiling,
    pub(super) layout0: wgpu::BindGroupLayout,
    pub(super) layout_args: wgpu::BindGroupLayout,
    pub(super) layout_field: wgpu::BindGroupLayout,
    pub(super) zero: wgpu::ComputePipeline,
    pub(super) prep_cand: wgpu::ComputePipeline,
    pub(super) prep_src: wgpu::ComputePipeline,
    pub(super) prep_eval: wgpu::ComputePipeline,
    pub(super) prep_round: wgpu::ComputePipeline,
    /// The miss flag after a level's predicted rounds, and the evaluations kept before the
    /// render's final level.
    pub(super) check_round: wgpu::ComputePipeline,
    pub(super) mark_evals: wgpu::ComputePipeline,
    pub(super) seed: wgpu::ComputePipeline,
    /// The field's seeds at a level (`localize.wgsl` `seeds`).
    pub(super) seeds: wgpu::ComputePipeline,
    pub(super) layout_seeds: wgpu::BindGroupLayout,
    pub(super) upsample: wgpu::ComputePipeline,
    pub(super) dilate: wgpu::ComputePipeline,
    pub(super) conflict: wgpu::ComputePipeline,
    pub(super) eval_table: wgpu::ComputePipeline,
    pub(super) eval_fourier: wgpu::ComputePipeline,
}

/// The grid's buffers for one size and list capacity.
pub(super) struct Bufs {
    spec: GridSpec,
    pub(super) cap: usize,
    /// Whether `queued` holds the dead band's memory after the bits (`hold.rs`).
    held: bool,
    /// The values, one buffer per tile (`Pipes::tiling`).
    pub(super) values: Vec<wgpu::Buffer>,
    queued: wgpu::Buffer,
    pub(super) counts: wgpu::Buffer,
    /// The renderer's lists ([`LOG`], [`CULLED`]): three regions of `cap` pairs, made only
    /// for rendering.
    pub(super) extra: wgpu::Buffer,
    render: bool,
    /// The counters' read-back, then the submission's two timestamps (where the adapter has
    /// them: `timer`).
    counts_staging: wgpu::Buffer,
    timer: Option<super::Timer>,
    args: wgpu::Buffer,
    args_bind: wgpu::BindGroup,
    /// Per level and list orientation: parameters and bind group.
    params: Vec<[wgpu::Buffer; ORIENTATIONS]>,
    binds: Vec<[wgpu::BindGroup; ORIENTATIONS]>,
    /// The values' and bits' read-back, made on first use.
    staging: Option<wgpu::Buffer>,
}

/// Reusable state of the hierarchical localizer on the adapter.
pub struct GpuLocalizer {
    gpu: Arc<Gpu>,
    pipes: Pipes,
    bufs: Option<Bufs>,
    field: Option<FieldBufs>,
    cap: usize,
    /// Whether the last run completed (its values are in the buffers).
    pub(super) done: bool,
    /// Whether the frame renders (the renderer's lists are needed).
    render: bool,
    /// Whether the field uploaded is the Fourier head (else a table).
    eval_fourier: bool,
    /// Incremented whenever the grid's buffers are remade (bind groups holding them are
    /// stale then).
    generation: u64,
    /// The buffers' generation and mode (tight or not) the parameter blocks hold.
    params_for: Option<(u64, bool)>,
    /// Conflict rounds per read-back at most ([`Self::with_rounds_per_wait`]).
    rounds_per_wait: usize,
    /// The last frame's rounds per level, when they are predicted ([`Self::with_round_waits`]).
    pub(super) predictor: Predictor,
    /// The surface's dead band (`hold.rs`).
    hold: hold::Hold,
    /// Maps on the adapter to copy into the field's buffer, recorded ahead of the next
    /// localization's work ([`Self::recorder`]).
    pending_copy: Option<(wgpu::Buffer, u64)>,
    /// Floats per tile of the values at most, below the adapter's binding limit
    /// ([`Self::with_tile_floats`]).
    tile_floats: Option<u64>,
    /// Entries per index list at most, below what one binding holds
    /// ([`Self::with_max_list_entries`]).
    max_list: Option<usize>,
}

/// Conflict rounds recorded per read-back at most, unless set: one. Batches (1, 2, 4, up to
/// the limit) save read-backs but dispatch the empty rounds after the last one that listed
/// something, and on an H200 those cost more than the waits they save: at 257^3 the
/// paper's method took 3.4 ms with one round per read-back (13 waits) and 5.4 ms with up to
/// eight (11 waits); at 513^3 20.1 and 18.8 ms (docs/bench/pipeline-gpu.md).
pub const DEFAULT_ROUNDS_PER_WAIT: usize = 1;

impl Pipes {
    /// The kernels for `tiling`; `field` keeps the field group's layout of the pipes they
    /// replace (the field's bind group, made with it, outlives a change of tiling).
    fn new(
        gpu: &Gpu,
        tiling: Tiling,
        field: Option<&wgpu::BindGroupLayout>,
    ) -> Result<Self, String> {
        use super::kit::{bind_layout, module, pipeline_layout, storage, uniform};
        let d = &gpu.device;
        // Six storage buffers here (one more per further tile of the values) and two in the
        // field's group: the default limit of eight per stage, untiled.
        let mut e0 = vec![uniform(0)];
        e0.extend(tiling.layout_entries(false));
        e0.extend((2..7).map(|b| storage(b, false)));
        let layout0 = bind_layout(d, "localize", &e0);
        let layout_args = bind_layout(d, "localize args", &[storage(0, false)]);
        let layout_seeds = bind_layout(d, "localize seeds", &[storage(1, true)]);
        let layout_field = field.cloned().unwrap_or_else(|| {
            bind_layout(
                d,
                "localize field",
                &[uniform(0), storage(1, true), storage(2, true)],
            )
        });
        let scope = d.push_error_scope(wgpu::ErrorFilter::Validation);
        let values = tiling.wgsl(true);
        let book = module(d, "localize", &format!("{values}{BOOK}"));
        let eval = module(
            d,
            "localize eval",
            &format!("const HELD: u32 = {HELD}u;\n{values}{EVAL}"),
        );
        let plain = pipeline_layout(d, &[&layout0]);
        let with_args = pipeline_layout(d, &[&layout0, &layout_args]);
        let with_field = pipeline_layout(d, &[&layout0, &layout_field]);
        let with_seeds = pipeline_layout(d, &[&layout0, &layout_seeds]);
        let pipe = |m, layout, entry| super::kit::pipeline(d, m, layout, entry);
        let p = Pipes {
            zero: pipe(&book, &plain, "zero"),
            prep_cand: pipe(&book, &with_args, "prep_cand"),
            prep_src: pipe(&book, &with_args, "prep_src"),
            prep_eval: pipe(&book, &with_args, "prep_eval"),
            prep_round: pipe(&book, &with_args, "prep_round"),
            check_round: pipe(&book, &plain, "check_round"),
            mark_evals: pipe(&book, &plain, "mark_evals"),
            seed: pipe(&book, &plain, "seed"),
            seeds: pipe(&book, &with_seeds, "seeds"),
            upsample: pipe(&book, &plain, "upsample"),
            dilate: pipe(&book, &plain, "dilate"),
            conflict: pipe(&book, &plain, "conflict"),
            eval_table: pipe(&eval, &with_field, "table"),
            eval_fourier: pipe(&eval, &with_field, "fourier"),
            tiling,
            layout0,
            layout_args,
            layout_field,
            layout_seeds,
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!("the localization kernels: {e}"));
        }
        Ok(p)
    }
}

/// The buffer limit a grid of `spec` needs for its values.
fn grid_bytes(spec: GridSpec) -> u64 {
    spec.len() as u64 * 4
}

impl GpuLocalizer {
    pub fn new(gpu: Arc<Gpu>) -> Result<Self, String> {
        let pipes = Pipes::new(&gpu, Tiling::ONE, None)?;
        Ok(GpuLocalizer {
            gpu,
            pipes,
            bufs: None,
            field: None,
            cap: START_CAP,
            done: false,
            render: false,
            eval_fourier: false,
            generation: 0,
            params_for: None,
            rounds_per_wait: DEFAULT_ROUNDS_PER_WAIT,
            predictor: Predictor::default(),
            hold: Default::default(),
            pending_copy: None,
            tile_floats: None,
            max_list: None,
        })
    }

    /// Conflict rounds recorded per read-back at most (default
    /// [`DEFAULT_ROUNDS_PER_WAIT`], clamped to 1..=64): batches of 1, 2, 4, ... up to it.
    /// The values, evaluations and rounds do not depend on it; the read-backs waited for
    /// and the empty rounds dispatched do (`volcap bench localize --rounds-per-wait`).
    pub fn with_rounds_per_wait(mut self, n: usize) -> Self {
        self.rounds_per_wait = n.clamp(1, 64);
        self
    }

    /// When the host reads the conflict loop's progress: after each round (batches of
    /// [`Self::with_rounds_per_wait`]), or once a frame with each level's rounds predicted
    /// from the last frame (a frame it falls short of is run again per round: `plan.rs`).
    /// The values, evaluations and rounds do not depend on it.
    pub fn with_round_waits(mut self, waits: RoundWaits) -> Self {
        self.predictor = Predictor::new(waits);
        self
    }

    /// Lists of `cap` entries at first (the tests make them small to exercise their growth).
    pub fn with_list_capacity(mut self, cap: usize) -> Self {
        self.cap = cap.max(1);
        self.bufs = None;
        self
    }

    /// Entries each index list holds now (grown by runs that needed more).
    pub fn list_capacity(&self) -> usize {
        self.cap
    }

    fn buffers(&mut self, spec: GridSpec) -> Result<&Bufs, String> {
        let cap = self.cap.min(spec.len()).min(self.list_bound());
        let render = self.render;
        let held = self.hold.frame_stamp != 0;
        let tiling = self.tiling(spec);
        let fits = self.bufs.as_ref().is_some_and(|b| {
            b.spec == spec && b.cap == cap && (b.render || !render) && (b.held || !held)
        }) && self.pipes.tiling == tiling;
        if !fits {
            let old = self.bufs.take();
            if self.pipes.tiling != tiling {
                // Kernels for this tiling (a grid size of another tiling than the last).
                self.pipes = Pipes::new(&self.gpu, tiling, Some(&self.pipes.layout_field))?;
            }
            let b = self.make_bufs(spec, cap, render, held);
            // The dead band's memory carried over (lists grown, the renderer's made).
            if let Some(o) = old.filter(|o| o.held && b.held && o.spec == spec) {
                let at = Self::bit_words(spec) as u64 * 4;
                let mut enc = self.gpu.device.create_command_encoder(&Default::default());
                enc.copy_buffer_to_buffer(&o.queued, at, &b.queued, at, spec.len() as u64 * 4);
                self.gpu.queue.submit([enc.finish()]);
            }
            self.generation += 1;
            self.bufs = Some(b);
        }
        Ok(self.bufs.as_ref().expect("made above"))
    }

    fn make_bufs(&self, spec: GridSpec, cap: usize, render: bool, held: bool) -> Bufs {
        use wgpu::BufferUsages as U;
        let d = &self.gpu.device;
        let buf = |label, bytes: u64, usage| {
            d.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(4),
                usage,
                mapped_at_creation: false,
            })
        };
        let rw = U::STORAGE | U::COPY_DST | U::COPY_SRC;
        let tiling = self.pipes.tiling;
        let values: Vec<wgpu::Buffer> = (0..tiling.tiles)
            .map(|t| buf("grid values", tiling.tile_len(t, spec.len()) as u64 * 4, rw))
            .collect();
        // The bits, then the dead band's memory (a word a point) where it is held.
        let words = (Self::bit_words(spec) + if held { spec.len() } else { 0 }) as u64;
        let queued = buf("grid handled bits", words * 4, rw);
        let cand = buf("candidates", cap as u64 * 4, U::STORAGE);
        // (point, value before evaluation) pairs.
        let lists = [0, 1].map(|_| buf("index list", cap as u64 * 8, U::STORAGE));
        let counts = buf("counts", COUNTS as u64 * 4, rw);
        let extra_bytes = if render { cap as u64 * 24 } else { 8 };
        let extra = buf("render lists", extra_bytes, U::STORAGE);
        let counts_staging = buf(
            "counts read-back",
            COUNTS as u64 * 4 + 16,
            U::MAP_READ | U::COPY_DST,
        );
        let timer = self.gpu.timer();
        let args = buf("dispatch args", 12, U::STORAGE | U::INDIRECT);
        let args_bind = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.pipes.layout_args,
            entries: &[entry(0, &args)],
        });
        let mut params = Vec::new();
        let mut binds = Vec::new();
        for _ in 0..=spec.level() {
            let ps =
                [0; ORIENTATIONS].map(|_| buf("localize params", 32, U::UNIFORM | U::COPY_DST));
            let bs: [wgpu::BindGroup; ORIENTATIONS] = std::array::from_fn(|o| {
                let (src, dst) = match o {
                    1 => (&lists[1], &lists[0]),
                    2 => (&extra, &lists[0]),
                    _ => (&lists[0], &lists[1]),
                };
                let mut entries = tiling.entries(&values);
                entries.extend([
                    entry(0, &ps[o]),
                    entry(2, &queued),
                    entry(3, &cand),
                    entry(4, src),
                    entry(5, dst),
                    entry(6, &counts),
                ]);
                d.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: None,
                    layout: &self.pipes.layout0,
                    entries: &entries,
                })
            });
            params.push(ps);
            binds.push(bs);
        }
        Bufs {
            spec,
            cap,
            held,
            values,
            queued,
            counts,
            extra,
            render,
            counts_staging,
            timer,
            args,
            args_bind,
            params,
            binds,
            staging: None,
        }
    }

    /// Localize `field`'s 0.5 level set on `spec` from level `coarse` with `mode`, the values
    /// left on the adapter (read them with [`Self::read_grid`]). The stats count the field
    /// evaluations exactly.
    pub fn run(
        &mut self,
        field: &GpuField<'_>,
        spec: GridSpec,
        coarse: u32,
        mode: HierarchicalMode,
    ) -> Result<LocalizeStats, String> {
        self.prepare(field, spec, coarse, false)?;
        loop {
            let mut rec = self.recorder(spec, coarse, mode)?;
            let retry = rec.levels(coarse, spec.level(), mode)?;
            let counts = rec.counts()?;
            drop(rec);
            match retry.or(Retry::of(&counts)) {
                None => {
                    self.done = true;
                    self.finish_hold(&counts);
                    self.predictor.learn(spec, coarse, mode, &counts);
                    return Ok(LocalizeStats {
                        evaluations: counts[EVALS] as u64,
                        conflict_rounds: counts[ROUNDS],
                        empty: false,
                    });
                }
                Some(r) => self.retry(r, spec)?,
            }
        }
    }

    /// What a completed frame's counters say of the dead band.
    pub(super) fn finish_hold(&mut self, counts: &[u32; COUNTS]) {
        self.hold.held = counts[HELD] as u64;
    }

    /// Before a frame is run again: lists four times larger after an overflow, a plan with
    /// more rounds after a predicted round count fell short (then waits per round:
    /// `plan.rs`).
    pub(super) fn retry(&mut self, r: Retry, spec: GridSpec) -> Result<(), String> {
        match r {
            Retry::Overflow => self.grow(spec),
            Retry::Missed(seen) => {
                self.predictor.missed(&seen);
                self.gpu.count().reruns.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
        }
    }

    pub(super) fn pipes(&self) -> &Pipes {
        &self.pipes
    }

    /// The buffers for `spec` made (for the renderer's bind groups).
    pub(super) fn ensure_buffers(&mut self, spec: GridSpec) -> Result<(), String> {
        self.buffers(spec).map(|_| ())
    }

    /// The buffers' generation, the renderer's lists and the grid's values (a buffer per
    /// tile), once made.
    pub(super) fn render_buffers(&self) -> Option<(u64, &wgpu::Buffer, &[wgpu::Buffer])> {
        self.bufs
            .as_ref()
            .map(|b| (self.generation, &b.extra, &b.values[..]))
    }

    /// Checks and the field's upload before a frame.
    pub(super) fn prepare(
        &mut self,
        field: &GpuField<'_>,
        spec: GridSpec,
        coarse: u32,
        render: bool,
    ) -> Result<(), String> {
        check_coarse(spec, coarse).map_err(|e| e.to_string())?;
        self.check_size(spec)?;
        self.done = false;
        self.render = render;
        self.eval_fourier = matches!(field, GpuField::Fourier { .. });
        self.begin_hold(spec);
        self.upload_field(field, spec)
    }

    /// A recorder of the frame's work on buffers sized for `spec` (its parameters written).
    pub(super) fn recorder(
        &mut self,
        spec: GridSpec,
        coarse: u32,
        mode: HierarchicalMode,
    ) -> Result<Rec<'_>, String> {
        let plan = self.predictor.plan(spec, coarse, mode);
        if plan.is_some() {
            self.gpu.count().predicted.fetch_add(1, Ordering::Relaxed);
        }
        self.buffers(spec)?;
        let b = self.bufs.as_ref().expect("made by buffers");
        let f = self.field.as_ref().ok_or("no field uploaded")?;
        let p = &self.pipes;
        let n = spec.n() as u32;
        let tight = mode == HierarchicalMode::Tight;
        // The blocks depend on the buffers (size, capacity) and the mode only.
        let fresh = self.params_for == Some((self.generation, tight));
        for l in (0..=spec.level()).filter(|_| !fresh) {
            let s = spec.stride(l) as u32;
            for o in 0..ORIENTATIONS {
                // Orientation o < 2 reads list o and writes list 1 - o; 2 reads the renderer's
                // log (its first region) and writes list 0; 3 and 4 count its culled lists
                // (for the indirect arguments over them).
                let (src, dst) = match o {
                    0 | 1 => (LIST[o], LIST[1 - o]),
                    2 => (LOG, LIST[0]),
                    _ => (CULLED[o - 3], LIST[1]),
                };
                let block = [
                    n,
                    s,
                    (n - 1) / s + 1,
                    b.cap as u32,
                    src as u32,
                    dst as u32,
                    tight as u32,
                    tight as u32,
                ];
                self.gpu.queue.write_buffer(
                    &b.params[l as usize][o],
                    0,
                    bytemuck::cast_slice(&block),
                );
            }
        }
        self.params_for = Some((self.generation, tight));
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        if let Some((src, bytes)) = self.pending_copy.take() {
            enc.copy_buffer_to_buffer(&src, 0, &f.maps, 0, bytes);
        }
        for v in &b.values {
            enc.clear_buffer(v, 0, None);
        }
        // The bits (the dead band's memory after them is cleared only when its stamps run
        // out: `hold.rs`).
        let bits = Self::bit_words(spec) as u64 * 4;
        enc.clear_buffer(&b.queued, 0, Some(bits));
        if std::mem::take(&mut self.hold.clear) && b.held {
            enc.clear_buffer(&b.queued, bits, None);
        }
        enc.clear_buffer(&b.counts, 0, None);
        Ok(Rec {
            gpu: &self.gpu,
            b,
            f,
            p,
            eval: if self.eval_fourier {
                &p.eval_fourier
            } else {
                &p.eval_table
            },
            spec,
            enc: Some(enc),
            timed: false,
            dispatches: 0,
            rounds_per_wait: self.rounds_per_wait,
            plan,
            last: None,
        })
    }

    /// The last run's values and evaluated set into `grid` (re-targeted to the run's grid).
    pub fn read_grid(&mut self, grid: &mut Grid) -> Result<(), String> {
        if !self.done {
            return Err("no completed localization to read".into());
        }
        let gpu = self.gpu.clone();
        let b = self.bufs.as_mut().ok_or("no buffers")?;
        let spec = b.spec;
        let words = spec.len().div_ceil(32);
        // One tile at a time through a read-back of the largest tile's size (or the bits').
        let tile_bytes = b.values.iter().map(|v| v.size()).max().unwrap_or(4);
        let staging = b.staging.get_or_insert_with(|| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("grid read-back"),
                size: tile_bytes.max(words as u64 * 4),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        grid.reset(spec);
        let mut at = 0;
        for v in &b.values {
            let floats = (v.size() / 4) as usize;
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(v, 0, staging, 0, v.size());
            let dst = grid
                .values
                .get_mut(at..at + floats)
                .ok_or("the grid's tiles exceed its size")?;
            gpu.submit_and_read_bytes(enc, staging, bytemuck::cast_slice_mut(dst))?;
            at += floats;
        }
        let mut bits = vec![0u32; words];
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&b.queued, 0, staging, 0, (words * 4) as u64);
        gpu.submit_and_read_bytes(enc, staging, bytemuck::cast_slice_mut(&mut bits))?;
        for (w, &word) in bits.iter().enumerate() {
            let mut m = word;
            while m != 0 {
                let i = w * 32 + m.trailing_zeros() as usize;
                if i < spec.len() {
                    grid.evaluated.set(i);
                }
                m &= m - 1;
            }
        }
        Ok(())
    }
}
