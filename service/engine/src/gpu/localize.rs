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
//! needs more. The whole grid is one storage buffer: grids over the adapter's binding limit
//! (513^3 where a binding holds 128 MiB, as on lavapipe; a GPU's holds it, see
//! [`super::buffer_limits`]) are refused with the sizes named.

use super::Gpu;
use super::kit::entry;
use crate::grid::{Grid, GridSpec};
use crate::localize::{HierarchicalMode, LocalizeStats, check_coarse};
use crate::model::fourier::FourierMaps;
use glam::Mat3;
use std::sync::Arc;
use std::sync::atomic::Ordering;

mod record;
pub(super) use record::{Dispatch, Rec};

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
pub(super) const COUNTS: usize = 9;
/// Parameter blocks per level: lists 0 and 1 read (the other written), the renderer's log
/// read, its culled list 0 or 1 counted.
const ORIENTATIONS: usize = 5;

/// A field the localizer evaluates on the adapter.
pub enum GpuField<'a> {
    /// One value per point of the run's grid (linear index order), evaluated by the host.
    Table(&'a [f32]),
    /// The Fourier head over the render view: `to_crop` maps render NDC to crop NDC, points
    /// outside the crop or where the `mask_size` x `mask_size` mask is below 0.5 are 0, the
    /// rest the series (`model/field.rs` `ModelField::occupancy`).
    Fourier {
        maps: MapsRef<'a>,
        mask: &'a [f32],
        mask_size: usize,
        to_crop: Mat3,
    },
}

/// Where a frame's Fourier maps are: on the host (written to the adapter with the field), or
/// already on the adapter (the GPU backend's frames: copied there, nothing goes up).
#[derive(Clone, Copy)]
pub enum MapsRef<'a> {
    Host(&'a FourierMaps),
    Adapter(&'a super::maps::GpuMaps),
}

impl MapsRef<'_> {
    fn series_head(&self) -> [u32; 5] {
        match self {
            MapsRef::Host(m) => super::fourier::series_head(m),
            MapsRef::Adapter(m) => m.head().series(),
        }
    }
}

/// The field's data as `upload_field` writes it.
enum FieldData<'a> {
    Host(&'a [f32]),
    /// A buffer on the adapter and the floats to copy from its start.
    Adapter(&'a wgpu::Buffer, usize),
}

impl FieldData<'_> {
    fn len(&self) -> usize {
        match self {
            FieldData::Host(d) => d.len(),
            FieldData::Adapter(_, n) => *n,
        }
    }
}

pub(super) struct Pipes {
    pub(super) layout0: wgpu::BindGroupLayout,
    pub(super) layout_args: wgpu::BindGroupLayout,
    pub(super) layout_field: wgpu::BindGroupLayout,
    pub(super) zero: wgpu::ComputePipeline,
    pub(super) prep_cand: wgpu::ComputePipeline,
    pub(super) prep_src: wgpu::ComputePipeline,
    pub(super) prep_eval: wgpu::ComputePipeline,
    pub(super) prep_round: wgpu::ComputePipeline,
    pub(super) seed: wgpu::ComputePipeline,
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
    pub(super) values: wgpu::Buffer,
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

/// The field's buffers (grown, never shrunk).
struct FieldBufs {
    params: wgpu::Buffer,
    maps: wgpu::Buffer,
    /// The grid's coordinates, then the mask.
    aux: wgpu::Buffer,
    maps_cap: usize,
    aux_cap: usize,
    /// Points per axis of the grid whose coordinates `aux` holds (0: none yet).
    coords_n: usize,
    bind: wgpu::BindGroup,
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
    /// Maps on the adapter to copy into the field's buffer, recorded ahead of the next
    /// localization's work ([`Self::recorder`]).
    pending_copy: Option<(wgpu::Buffer, u64)>,
}

/// Conflict rounds recorded per read-back at most, unless set: one. Batches (1, 2, 4, up to
/// the limit) save read-backs but dispatch the empty rounds after the last one that listed
/// something, and on an H200 those cost more than the waits they save: at 257^3 the
/// paper's method took 3.4 ms with one round per read-back (13 waits) and 5.4 ms with up to
/// eight (11 waits); at 513^3 20.1 and 18.8 ms (docs/bench/pipeline-gpu.md).
pub const DEFAULT_ROUNDS_PER_WAIT: usize = 1;

impl Pipes {
    fn new(gpu: &Gpu) -> Result<Self, String> {
        use super::kit::{bind_layout, module, pipeline_layout, storage, uniform};
        let d = &gpu.device;
        // Six storage buffers here and two in the field's group: the default limit of eight
        // per stage.
        let mut e0 = vec![uniform(0)];
        e0.extend((1..7).map(|b| storage(b, false)));
        let layout0 = bind_layout(d, "localize", &e0);
        let layout_args = bind_layout(d, "localize args", &[storage(0, false)]);
        let layout_field = bind_layout(
            d,
            "localize field",
            &[uniform(0), storage(1, true), storage(2, true)],
        );
        let scope = d.push_error_scope(wgpu::ErrorFilter::Validation);
        let book = module(d, "localize", BOOK);
        let eval = module(d, "localize eval", EVAL);
        let plain = pipeline_layout(d, &[&layout0]);
        let with_args = pipeline_layout(d, &[&layout0, &layout_args]);
        let with_field = pipeline_layout(d, &[&layout0, &layout_field]);
        let pipe = |m, layout, entry| super::kit::pipeline(d, m, layout, entry);
        let p = Pipes {
            zero: pipe(&book, &plain, "zero"),
            prep_cand: pipe(&book, &with_args, "prep_cand"),
            prep_src: pipe(&book, &with_args, "prep_src"),
            prep_eval: pipe(&book, &with_args, "prep_eval"),
            prep_round: pipe(&book, &with_args, "prep_round"),
            seed: pipe(&book, &plain, "seed"),
            upsample: pipe(&book, &plain, "upsample"),
            dilate: pipe(&book, &plain, "dilate"),
            conflict: pipe(&book, &plain, "conflict"),
            eval_table: pipe(&eval, &with_field, "table"),
            eval_fourier: pipe(&eval, &with_field, "fourier"),
            layout0,
            layout_args,
            layout_field,
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
        let pipes = Pipes::new(&gpu)?;
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
            pending_copy: None,
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

    /// Whether a grid of `spec` fits the adapter's limits (one storage binding for its
    /// values); the error names the sizes.
    pub fn check_size(&self, spec: GridSpec) -> Result<(), String> {
        let limits = self.gpu.device.limits();
        let need = grid_bytes(spec);
        let max = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if need > max {
            let n = spec.n();
            return Err(format!(
                "a {n}^3 grid needs {} MiB of values in one buffer, over the adapter's {} MiB \
                 per binding (localize it on the CPU: tiling the grid is not built yet)",
                need >> 20,
                max >> 20
            ));
        }
        Ok(())
    }

    fn buffers(&mut self, spec: GridSpec) -> &Bufs {
        let cap = self.cap.min(spec.len());
        let render = self.render;
        let fits = self
            .bufs
            .as_ref()
            .is_some_and(|b| b.spec == spec && b.cap == cap && (b.render || !render));
        if !fits {
            self.bufs = None;
            let b = self.make_bufs(spec, cap, render);
            self.generation += 1;
            self.bufs = Some(b);
        }
        self.bufs.as_ref().expect("made above")
    }

    fn make_bufs(&self, spec: GridSpec, cap: usize, render: bool) -> Bufs {
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
        let values = buf("grid values", grid_bytes(spec), rw);
        let words = spec.len().div_ceil(32) as u64;
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
                d.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: None,
                    layout: &self.pipes.layout0,
                    entries: &[
                        entry(0, &ps[o]),
                        entry(1, &values),
                        entry(2, &queued),
                        entry(3, &cand),
                        entry(4, src),
                        entry(5, dst),
                        entry(6, &counts),
                    ],
                })
            });
            params.push(ps);
            binds.push(bs);
        }
        Bufs {
            spec,
            cap,
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

    /// Write the field's data (grown buffers where needed) and its bind group.
    fn upload_field(&mut self, field: &GpuField<'_>, spec: GridSpec) -> Result<(), String> {
        self.pending_copy = None;
        let (data, mask, head, to_crop): (FieldData<'_>, &[f32], [u32; 6], Mat3) = match field {
            GpuField::Table(t) => {
                if t.len() != spec.len() {
                    return Err(format!(
                        "the table holds {} values for a grid of {}",
                        t.len(),
                        spec.len()
                    ));
                }
                (FieldData::Host(t), &[0.0][..], [0; 6], Mat3::IDENTITY)
            }
            GpuField::Fourier {
                maps,
                mask,
                mask_size,
                to_crop,
            } => {
                if mask.len() != mask_size * mask_size || *mask_size < 2 {
                    return Err(format!(
                        "the mask holds {} values, not {mask_size}^2",
                        mask.len()
                    ));
                }
                let s = maps.series_head();
                let head = [s[0], s[1], s[2], s[3], s[4], *mask_size as u32];
                let data = match maps {
                    MapsRef::Host(m) => FieldData::Host(m.coefficients()),
                    MapsRef::Adapter(m) => FieldData::Adapter(m.buffer(), m.head().len()),
                };
                (data, *mask, head, *to_crop)
            }
        };
        let limit = self.gpu.device.limits().max_storage_buffer_binding_size as usize;
        if data.len() * 4 > limit {
            return Err(format!(
                "the field's data of {} bytes exceed the adapter's {limit} per binding",
                data.len() * 4
            ));
        }
        let n = spec.n();
        let aux_len = n + mask.len();
        let fits = self
            .field
            .as_ref()
            .is_some_and(|f| f.maps_cap >= data.len() && f.aux_cap >= aux_len);
        if !fits {
            let old = self.field.take();
            let maps_cap = old.as_ref().map_or(0, |f| f.maps_cap).max(data.len());
            let aux_cap = old.as_ref().map_or(0, |f| f.aux_cap).max(aux_len);
            use wgpu::BufferUsages as U;
            let d = &self.gpu.device;
            let buf = |label, floats: usize, usage| {
                d.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: (floats.max(1) * 4) as u64,
                    usage: usage | U::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            let params = buf("field params", 20, U::UNIFORM);
            let maps_b = buf("field data", maps_cap, U::STORAGE);
            let aux_b = buf("grid coords and mask", aux_cap, U::STORAGE);
            let bind = d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &self.pipes.layout_field,
                entries: &[entry(0, &params), entry(1, &maps_b), entry(2, &aux_b)],
            });
            self.field = Some(FieldBufs {
                params,
                maps: maps_b,
                aux: aux_b,
                maps_cap,
                aux_cap,
                coords_n: 0,
                bind,
            });
        }
        let f = self.field.as_mut().expect("made above");
        let mut params = [0u32; 20];
        params[..6].copy_from_slice(&head);
        for (i, v) in to_crop.to_cols_array().iter().enumerate() {
            params[8 + i] = v.to_bits();
        }
        let q = &self.gpu.queue;
        q.write_buffer(&f.params, 0, bytemuck::cast_slice(&params));
        let mut up = std::mem::size_of_val(mask) + 80;
        match data {
            FieldData::Host(d) => {
                q.write_buffer(&f.maps, 0, bytemuck::cast_slice(d));
                up += std::mem::size_of_val(d);
            }
            // On the adapter already: copied there at the start of the localization's first
            // submission ([`Self::recorder`]).
            FieldData::Adapter(b, n) => self.pending_copy = Some((b.clone(), (n * 4) as u64)),
        }
        if f.coords_n != n {
            // The coordinates from the host (GridSpec::coord: the same floats as the CPU's
            // points, whatever the adapter's division), when the grid's size changes.
            let coords: Vec<f32> = (0..n).map(|i| spec.coord(i)).collect();
            q.write_buffer(&f.aux, 0, bytemuck::cast_slice(&coords));
            f.coords_n = n;
            up += n * 4;
        }
        // The mask after them.
        q.write_buffer(&f.aux, (n * 4) as u64, bytemuck::cast_slice(mask));
        self.gpu
            .count()
            .bytes_up
            .fetch_add(up as u64, Ordering::Relaxed);
        Ok(())
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
            let mut rec = self.recorder(spec, mode)?;
            let (stats, overflow) = rec.levels(coarse, spec.level(), mode)?;
            if !overflow {
                self.done = true;
                return Ok(stats);
            }
            self.grow(spec)?;
        }
    }

    pub(super) fn pipes(&self) -> &Pipes {
        &self.pipes
    }

    /// The buffers for `spec` made (for the renderer's bind groups).
    pub(super) fn ensure_buffers(&mut self, spec: GridSpec) {
        self.buffers(spec);
    }

    /// The buffers' generation, the renderer's lists and the grid's values, once made.
    pub(super) fn render_buffers(&self) -> Option<(u64, &wgpu::Buffer, &wgpu::Buffer)> {
        self.bufs
            .as_ref()
            .map(|b| (self.generation, &b.extra, &b.values))
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
        self.upload_field(field, spec)
    }

    /// After a list overflowed: lists four times larger (up to the grid's size).
    pub(super) fn grow(&mut self, spec: GridSpec) -> Result<(), String> {
        if self.cap >= spec.len() {
            return Err("the index lists overflowed at the grid's size".into());
        }
        self.cap = (self.cap * 4).min(spec.len());
        Ok(())
    }

    /// A recorder of the frame's work on buffers sized for `spec` (its parameters written).
    pub(super) fn recorder(
        &mut self,
        spec: GridSpec,
        mode: HierarchicalMode,
    ) -> Result<Rec<'_>, String> {
        self.buffers(spec);
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
        enc.clear_buffer(&b.values, 0, None);
        enc.clear_buffer(&b.queued, 0, None);
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
        let bytes = grid_bytes(spec);
        let words = spec.len().div_ceil(32);
        let staging = b.staging.get_or_insert_with(|| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("grid read-back"),
                size: bytes,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        grid.reset(spec);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&b.values, 0, staging, 0, bytes);
        gpu.submit_and_read_bytes(enc, staging, bytemuck::cast_slice_mut(&mut grid.values))?;
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
