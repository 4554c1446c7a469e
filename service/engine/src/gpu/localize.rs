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

const MIB: f64 = (1u64 << 20) as f64;

/// The binding of the values' second tile (the first is binding 1), then one each.
const TILE_BINDING: u32 = 16;

/// Storage bindings per stage that the localization's kernels take besides the values'
/// (the lists, bits and counts, and the field's maps and mask in the evaluation kernels).
const OTHER_STORAGE: u32 = 7;

/// How a grid's values are laid over storage bindings: `tiles` buffers of `1 << shift`
/// floats (the last one shorter), point `q` at `q & ((1 << shift) - 1)` of tile
/// `q >> shift`. One tile is the whole grid in one binding, as before tiling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tiling {
    pub shift: u32,
    pub tiles: u32,
}

impl Tiling {
    /// The whole grid in one binding.
    pub const ONE: Tiling = Tiling {
        shift: 31,
        tiles: 1,
    };

    /// Tiles for `len` floats where a binding holds `max_floats` at most: one tile if it
    /// fits, else tiles of the largest power of two floats within the limit.
    pub fn new(len: usize, max_floats: u64) -> Tiling {
        if len as u64 <= max_floats {
            return Tiling::ONE;
        }
        let shift = 63 - max_floats.max(1).leading_zeros();
        Tiling {
            shift,
            tiles: (len as u64).div_ceil(1 << shift) as u32,
        }
    }

    /// Floats in tile `t` of a grid of `len`.
    fn tile_len(&self, t: u32, len: usize) -> usize {
        if self.tiles == 1 {
            return len;
        }
        let per = 1usize << self.shift;
        len.saturating_sub(t as usize * per).min(per)
    }

    fn binding(t: u32) -> u32 {
        if t == 0 { 1 } else { TILE_BINDING + t - 1 }
    }

    /// The layout entries of the tiles (binding 1, then [`TILE_BINDING`] on).
    pub(super) fn layout_entries(&self, read_only: bool) -> Vec<wgpu::BindGroupLayoutEntry> {
        (0..self.tiles)
            .map(|t| super::kit::storage(Self::binding(t), read_only))
            .collect()
    }

    /// Bind group entries of `tiles` (one buffer per tile).
    pub(super) fn entries<'b>(&self, tiles: &'b [wgpu::Buffer]) -> Vec<wgpu::BindGroupEntry<'b>> {
        tiles
            .iter()
            .enumerate()
            .map(|(t, b)| entry(Self::binding(t as u32), b))
            .collect()
    }

    /// WGSL ahead of a kernel source: the tiles' bindings, `vget(q)` and (`writable`)
    /// `vset(q, v)`.
    pub(super) fn wgsl(&self, writable: bool) -> String {
        use std::fmt::Write;
        let access = if writable { "read_write" } else { "read" };
        let name = |t: u32| {
            if t == 0 {
                "values".to_string()
            } else {
                format!("values_{t}")
            }
        };
        let mut w = String::new();
        for t in 0..self.tiles {
            let _ = writeln!(
                w,
                "@group(0) @binding({}) var<storage, {access}> {}: array<f32>;",
                Self::binding(t),
                name(t)
            );
        }
        if self.tiles == 1 {
            w.push_str("fn vget(q: u32) -> f32 { return values[q]; }\n");
            if writable {
                w.push_str("fn vset(q: u32, v: f32) { values[q] = v; }\n");
            }
            return w;
        }
        let (shift, mask) = (self.shift, (1u64 << self.shift) - 1);
        let cases = |body: &dyn Fn(&str) -> String| {
            let mut c = String::new();
            for t in 1..self.tiles {
                let _ = writeln!(c, "        case {t}u: {{ {} }}", body(&name(t)));
            }
            let _ = writeln!(c, "        default: {{ {} }}", body("values"));
            c
        };
        let _ = write!(
            w,
            "fn vget(q: u32) -> f32 {{\n    let o = q & {mask}u;\n    switch q >> {shift}u {{\n{}    }}\n}}\n",
            cases(&|v| format!("return {v}[o];"))
        );
        if writable {
            let _ = write!(
                w,
                "fn vset(q: u32, x: f32) {{\n    let o = q & {mask}u;\n    switch q >> {shift}u {{\n{}    }}\n}}\n",
                cases(&|v| format!("{v}[o] = x;"))
            );
        }
        w
    }
}

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
        let eval = module(d, "localize eval", &format!("{values}{EVAL}"));
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
            tiling,
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
            pending_copy: None,
            tile_floats: None,
            max_list: None,
        })
    }

    /// Tiles of the values of at most `n` floats (a power of two at most; the adapter's
    /// binding limit bounds them anyway): the tests tile small grids with it, so that the
    /// tiled kernels run where a binding would hold the whole grid.
    pub fn with_tile_floats(mut self, n: usize) -> Self {
        self.tile_floats = Some(n.max(1) as u64);
        self.bufs = None;
        self
    }

    /// How a grid of `spec` lays its values over storage bindings here.
    pub fn tiling(&self, spec: GridSpec) -> Tiling {
        let limits = self.gpu.device.limits();
        let bytes = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let floats = (bytes / 4).min(self.tile_floats.unwrap_or(u64::MAX));
        Tiling::new(spec.len(), floats)
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

    /// Lists of at most `n` entries (one storage binding bounds them anyway; the tests make
    /// the bound small to reach it).
    pub fn with_max_list_entries(mut self, n: usize) -> Self {
        self.max_list = Some(n.max(1));
        self.bufs = None;
        self
    }

    /// Entries each index list holds now (grown by runs that needed more).
    pub fn list_capacity(&self) -> usize {
        self.cap
    }

    /// Whether a grid of `spec` fits the adapter's limits: its values in as many storage
    /// bindings as the adapter's binding size needs ([`Self::tiling`]), with the kernels'
    /// other storage buffers, within the adapter's storage buffers per stage. The error
    /// names the sizes.
    pub fn check_size(&self, spec: GridSpec) -> Result<(), String> {
        let t = self.tiling(spec);
        let limits = self.gpu.device.limits();
        let per_stage = limits.max_storage_buffers_per_shader_stage;
        // Bindings are numbered below the group's limit too (tile t > 0 at 15 + t).
        let max_tiles = per_stage.saturating_sub(OTHER_STORAGE).min(
            limits
                .max_bindings_per_bind_group
                .saturating_sub(TILE_BINDING - 1),
        );
        if t.tiles > max_tiles {
            let n = spec.n();
            return Err(format!(
                "a {n}^3 grid needs {:.1} MiB of values in {} storage bindings of at most \
                 {:.1} MiB, more than the {max_tiles} that the adapter's {per_stage} storage \
                 buffers per stage leave beside the localization's other {OTHER_STORAGE} \
                 (localize it on the CPU)",
                grid_bytes(spec) as f64 / MIB,
                t.tiles,
                (4u64 << t.shift).min(grid_bytes(spec)) as f64 / MIB,
            ));
        }
        Ok(())
    }

    fn buffers(&mut self, spec: GridSpec) -> Result<&Bufs, String> {
        let cap = self.cap.min(spec.len()).min(self.list_bound());
        let render = self.render;
        let tiling = self.tiling(spec);
        let fits = self
            .bufs
            .as_ref()
            .is_some_and(|b| b.spec == spec && b.cap == cap && (b.render || !render))
            && self.pipes.tiling == tiling;
        if !fits {
            self.bufs = None;
            if self.pipes.tiling != tiling {
                // Kernels for this tiling (a grid size of another tiling than the last).
                self.pipes = Pipes::new(&self.gpu, tiling, Some(&self.pipes.layout_field))?;
            }
            let b = self.make_bufs(spec, cap, render);
            self.generation += 1;
            self.bufs = Some(b);
        }
        Ok(self.bufs.as_ref().expect("made above"))
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
        let tiling = self.pipes.tiling;
        let values: Vec<wgpu::Buffer> = (0..tiling.tiles)
            .map(|t| buf("grid values", tiling.tile_len(t, spec.len()) as u64 * 4, rw))
            .collect();
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
        self.upload_field(field, spec)
    }

    /// After a list overflowed: lists four times larger (up to the grid's size).
    pub(super) fn grow(&mut self, spec: GridSpec) -> Result<(), String> {
        if self.cap >= spec.len() {
            return Err("the index lists overflowed at the grid's size".into());
        }
        let next = (self.cap * 4).min(spec.len()).min(self.list_bound());
        if next <= self.cap {
            // Not a wgpu validation error (a panic) on a buffer over the binding limit.
            return Err(format!(
                "this {}^3 frame needs index lists of more than {} entries, the most one \
                 storage binding holds here (localize it on the CPU)",
                spec.n(),
                self.cap
            ));
        }
        self.cap = next;
        Ok(())
    }

    /// Entries an index list may hold: the largest buffer per entry (the renderer's lists,
    /// three pairs of words an entry, else a list's pair) within one storage binding, or
    /// [`Self::with_max_list_entries`].
    fn list_bound(&self) -> usize {
        let limits = self.gpu.device.limits();
        let binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let per_entry = if self.render { 24 } else { 8 };
        usize::try_from(binding / per_entry)
            .unwrap_or(usize::MAX)
            .min(self.max_list.unwrap_or(usize::MAX))
            .max(1)
    }

    /// A recorder of the frame's work on buffers sized for `spec` (its parameters written).
    pub(super) fn recorder(
        &mut self,
        spec: GridSpec,
        mode: HierarchicalMode,
    ) -> Result<Rec<'_>, String> {
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

#[cfg(test)]
mod tests {
    use super::Tiling;

    #[test]
    fn tiles_are_the_largest_power_of_two_within_the_binding_and_cover_the_grid() {
        let len = 513usize * 513 * 513;
        // A 128 MiB binding (lavapipe's): five tiles of 2^25 floats, the last one short.
        let t = Tiling::new(len, (128 << 20) / 4);
        assert_eq!(
            t,
            Tiling {
                shift: 25,
                tiles: 5
            }
        );
        let lens: Vec<usize> = (0..t.tiles).map(|i| t.tile_len(i, len)).collect();
        assert_eq!(lens.iter().sum::<usize>(), len);
        assert!(lens[..4].iter().all(|&l| l == 1 << 25));
        assert_eq!(lens[4], len - 4 * (1 << 25));
        // A limit that is not a power of two: tiles of the power of two below it.
        assert_eq!(
            Tiling::new(1000, 100),
            Tiling {
                shift: 6,
                tiles: 16
            }
        );
        assert_eq!(Tiling::new(1000, 100).tile_len(15, 1000), 1000 - 15 * 64);
        // A grid that fits: one tile, the whole grid.
        assert_eq!(Tiling::new(len, len as u64), Tiling::ONE);
        assert_eq!(Tiling::ONE.tile_len(0, len), len);
    }

    #[test]
    fn the_tiles_wgsl_declares_each_binding_and_routes_by_the_high_bits() {
        let one = Tiling::ONE.wgsl(true);
        assert!(one.contains("@binding(1) var<storage, read_write> values: array<f32>;"));
        assert!(one.contains("fn vset"));
        assert!(!Tiling::ONE.wgsl(false).contains("fn vset"));
        let t = Tiling {
            shift: 16,
            tiles: 3,
        };
        let w = t.wgsl(false);
        assert!(
            w.contains("@binding(1) var<storage, read> values: array<f32>;"),
            "{w}"
        );
        assert!(
            w.contains("@binding(16) var<storage, read> values_1"),
            "{w}"
        );
        assert!(
            w.contains("@binding(17) var<storage, read> values_2"),
            "{w}"
        );
        assert!(w.contains("q & 65535u") && w.contains("q >> 16u"), "{w}");
        assert!(w.contains("case 2u: { return values_2[o]; }"), "{w}");
        assert!(!w.contains("fn vset"), "{w}");
        // (Compiled with the kernels by the adapter in tests/gpu.rs.)
    }
}
