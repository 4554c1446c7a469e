//! Coarse-to-fine surface localization: the paper's hierarchical method, its variants, and
//! the baselines it is measured against, all on the same field, grid and evaluation path.
//!
//! Every method fills a [`Grid`] of the finest level (a value for every point) and returns
//! [`LocalizeStats`] with the exact number of field evaluations (counted by
//! [`Evaluator`]). Buffers live in [`Localizer`] and are reused across frames.

mod demo;
mod dense;
mod hierarchical;
mod mise;
mod octree;
mod waits;

pub use hierarchical::{Hierarchical, HierarchicalMode};
pub use waits::RoundWaits;

use crate::field::{Evaluator, FieldError, OccupancyField};
use crate::grid::{BitSet, Grid, GridError, GridSpec, is_inside};
use glam::Vec3;

/// Coarsest level used unless told otherwise: 9^3 points. (The public demo, `RTL/main.py`,
/// starts at 17^3: resolutions 17, 33, 65, 129, 257; the 8 + 1 comes from a test of the
/// authors' library on a 129-wide grid. At 257^3 the demo's coarse stride is 16, ours 32;
/// [`DEMO_COARSE_LEVEL`] is the demo's setting and the benchmark reports both.) We start
/// coarser because the paper's method is lossless from any start on connected surfaces and
/// the coarse level is evaluated densely: 9^3 = 729 points against 17^3 = 4,913. An
/// isolated feature thinner than the coarsest spacing (0.25 NDC here) may be missed by every
/// coarse-to-fine method (see the `thin-plate` scene); surfaces connected to what the coarse
/// grid sees are followed down the levels. The coarsest level is itself an accuracy/time
/// knob (`--coarse-level`).
pub const DEFAULT_COARSE_LEVEL: u32 = 3;

/// The public demo's coarsest level (17^3).
pub const DEMO_COARSE_LEVEL: u32 = 4;

/// PIFu threshold-octree thresholds shown in the benchmark.
pub const OCTREE_THRESHOLDS: [f32; 7] = [0.01, 0.05, 0.08, 0.12, 0.2, 0.3, 0.4];

/// A localization method.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Evaluate every point.
    Dense,
    /// Occupancy Networks' binarized octree (MISE).
    Mise,
    /// PIFu's threshold octree with the given threshold on max - min of a cell's corners.
    OctreeThreshold(f32),
    /// The paper's algorithm: binarize, upsample, boundary, 1-ring dilation, conflict loop;
    /// plus the field's seeds ([`OccupancyField::seeds`]) at every level (the product's).
    Hierarchical,
    /// [`Method::Hierarchical`] with the field's seeds ignored: the paper's method exactly (what
    /// the seeds cost and buy, side by side in `volcap bench localize`).
    HierarchicalUnseeded,
    /// The paper's method without the conflict loop (dilation by the 1-ring at every level,
    /// every level evaluated). Not the public demo's mode: that is [`Method::DemoFaster`].
    HierarchicalNoConflict,
    /// The public demo's "faster" mode: continuous trilinear upsampling, 9^3 / 7^3 / 3^3
    /// dilation, no conflict loop, the finest level never evaluated.
    DemoFaster,
    /// Our variant: boundary points without dilation, then the conflict loop widened to
    /// also evaluate every unevaluated neighbour whose assumed side differs from an
    /// evaluated point's (sign-change closure). Same exactness tests, fewer evaluations.
    HierarchicalTight,
}

impl Method {
    /// Stable name used on the command line and in reports.
    pub fn name(&self) -> &'static str {
        match self {
            Method::Dense => "dense",
            Method::Mise => "mise",
            Method::OctreeThreshold(_) => "octree-threshold",
            Method::Hierarchical => "hierarchical",
            Method::HierarchicalUnseeded => "hierarchical-unseeded",
            Method::HierarchicalNoConflict => "hierarchical-no-conflict",
            Method::HierarchicalTight => "hierarchical-tight",
            Method::DemoFaster => "demo-faster",
        }
    }

    /// The method's parameter, if any (the octree threshold).
    pub fn param(&self) -> Option<f32> {
        match self {
            Method::OctreeThreshold(t) => Some(*t),
            _ => None,
        }
    }

    /// A label unique per (method, parameter).
    pub fn label(&self) -> String {
        match self.param() {
            Some(p) => format!("{}@{p}", self.name()),
            None => self.name().to_string(),
        }
    }

    /// Parse a method name; `octree-threshold` expands to every threshold in
    /// [`OCTREE_THRESHOLDS`], `octree-threshold@0.05` to one.
    pub fn parse(s: &str) -> Result<Vec<Method>, String> {
        let s = s.trim();
        if let Some(t) = s.strip_prefix("octree-threshold@") {
            let t: f32 = t
                .parse()
                .map_err(|_| format!("bad octree threshold '{t}' in '{s}'"))?;
            if !(t.is_finite() && t > 0.0 && t < 1.0) {
                return Err(format!("octree threshold {t} in '{s}' must be in (0, 1)"));
            }
            return Ok(vec![Method::OctreeThreshold(t)]);
        }
        Ok(match s {
            "dense" => vec![Method::Dense],
            "mise" => vec![Method::Mise],
            "octree-threshold" => OCTREE_THRESHOLDS
                .iter()
                .map(|&t| Method::OctreeThreshold(t))
                .collect(),
            "hierarchical" => vec![Method::Hierarchical],
            "hierarchical-unseeded" => vec![Method::HierarchicalUnseeded],
            "hierarchical-no-conflict" => vec![Method::HierarchicalNoConflict],
            "hierarchical-tight" => vec![Method::HierarchicalTight],
            "demo-faster" => vec![Method::DemoFaster],
            _ => {
                return Err(format!(
                    "unknown method '{s}' (known: dense, mise, octree-threshold[@T], hierarchical, \
                     hierarchical-unseeded, hierarchical-no-conflict, hierarchical-tight, demo-faster)"
                ));
            }
        })
    }

    /// Methods named in a list ([`Method::parse`] each, in order; the command lines'
    /// comma-separated `--methods` / `--method`).
    pub fn parse_list(names: &[String]) -> Result<Vec<Method>, String> {
        let mut out = Vec::new();
        for n in names {
            out.extend(Method::parse(n)?);
        }
        Ok(out)
    }

    /// Every method, with every octree threshold.
    pub fn all() -> Vec<Method> {
        let mut v = vec![Method::Dense, Method::Mise];
        v.extend(
            OCTREE_THRESHOLDS
                .iter()
                .map(|&t| Method::OctreeThreshold(t)),
        );
        v.extend([
            Method::Hierarchical,
            Method::HierarchicalUnseeded,
            Method::HierarchicalNoConflict,
            Method::HierarchicalTight,
            Method::DemoFaster,
        ]);
        v
    }
}

/// What a localization run cost.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LocalizeStats {
    /// Field evaluations (points).
    pub evaluations: u64,
    /// Rounds of the conflict loop summed over levels (hierarchical methods).
    pub conflict_rounds: u32,
    /// The method gave up and returned nothing (the demo's mode when the coarsest level has
    /// no inside point); the grid is then all outside.
    pub empty: bool,
}

/// Errors from localization.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum LocalizeError {
    #[error(transparent)]
    Field(#[from] FieldError),
    #[error(transparent)]
    Grid(#[from] GridError),
}

/// Runs any [`Method`], owning the buffers that methods reuse from frame to frame.
#[derive(Default)]
pub struct Localizer {
    hier: Hierarchical,
    scratch: Scratch,
    threads: usize,
    field_time: std::time::Duration,
    /// The surface's dead band ([`crate::sides`]) with the next run's band and alignment.
    sides: crate::sides::HeldSides,
}

/// Reusable scratch shared by the baseline methods.
#[derive(Default)]
pub(crate) struct Scratch {
    pub list: Vec<u32>,
    pub queued: BitSet,
    pub filled: BitSet,
    pub cells: Vec<[u32; 3]>,
    pub next_cells: Vec<[u32; 3]>,
}

impl Localizer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Threads for field evaluation (1, the default: the calling thread only). The values
    /// and the evaluated set do not depend on it.
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads.max(1);
    }

    /// Hold grid values within `band` of those given out last run, and sides within `band` of
    /// the level, in the next [`Localizer::run`] ([`crate::sides`]) when that run's
    /// alignment `key` is the last run's; given for one run (a run without it forgets them).
    pub fn hold_sides(&mut self, band: f32, key: Option<u64>) {
        self.sides.hold(band, key);
    }

    /// Forget the values held ([`Localizer::hold_sides`]): the next run starts from none.
    pub fn forget_sides(&mut self) {
        self.sides.forget();
    }

    /// Grid points the last run gave out as the run before it ([`Localizer::hold_sides`]).
    pub fn held_sides(&self) -> u64 {
        self.sides.held()
    }

    /// Wall time the last [`Localizer::run`] spent inside the field (the rest of its time is
    /// the method's own bookkeeping).
    pub fn last_field_time(&self) -> std::time::Duration {
        self.field_time
    }

    /// Localize the surface of `field` on `spec` with `method`, starting (for coarse-to-fine
    /// methods) at `coarse_level`, writing into `grid` (re-targeted to `spec`).
    pub fn run(
        &mut self,
        method: Method,
        field: &dyn OccupancyField,
        spec: GridSpec,
        coarse_level: u32,
        grid: &mut Grid,
    ) -> Result<LocalizeStats, LocalizeError> {
        let coarse = check_coarse(spec, coarse_level)?;
        match method {
            // The hierarchical methods write only where values are non-zero.
            Method::Hierarchical
            | Method::HierarchicalUnseeded
            | Method::HierarchicalNoConflict
            | Method::HierarchicalTight => grid.reset_sparse(spec),
            _ => grid.reset(spec),
        }
        let unseeded = crate::field::Seeded {
            field,
            seeds: Vec::new(),
        };
        let field: &dyn OccupancyField = if method == Method::HierarchicalUnseeded {
            &unseeded
        } else {
            field
        };
        self.sides.begin_pending(spec.len());
        let mut ev = Evaluator::new(field)
            .with_threads(self.threads)
            .with_sides(&mut self.sides);
        let mut stats = LocalizeStats::default();
        match method {
            Method::Dense => dense::run(&mut ev, grid, &mut self.scratch)?,
            Method::Mise => mise::run(&mut ev, grid, coarse, &mut self.scratch)?,
            Method::OctreeThreshold(t) => octree::run(&mut ev, grid, coarse, t, &mut self.scratch)?,
            Method::DemoFaster => {
                stats.empty = !demo::run(&mut ev, grid, coarse, &mut self.scratch)?;
            }
            Method::Hierarchical
            | Method::HierarchicalUnseeded
            | Method::HierarchicalNoConflict
            | Method::HierarchicalTight => {
                let mode = match method {
                    Method::Hierarchical | Method::HierarchicalUnseeded => HierarchicalMode::Paper,
                    Method::HierarchicalNoConflict => HierarchicalMode::NoConflict,
                    _ => HierarchicalMode::Tight,
                };
                stats.conflict_rounds = self.hier.run(&mut ev, grid, coarse, spec.level(), mode)?;
            }
        }
        stats.evaluations = ev.count();
        self.field_time = ev.field_time();
        Ok(stats)
    }
}

/// The finest grid's points nearest to `seeds` (NDC; those outside the cube or not finite
/// dropped), as the hierarchical localizers take them ([`Hierarchical`], the GPU's).
pub fn seed_nodes(spec: GridSpec, seeds: &[Vec3]) -> Vec<[u32; 3]> {
    seeds
        .iter()
        .filter_map(|p| spec.index_of(*p))
        .map(|q| q.map(|v| v as u32))
        .collect()
}

/// Validate the coarse level against the grid: `1 <= coarse <= level`.
pub fn check_coarse(spec: GridSpec, coarse_level: u32) -> Result<u32, GridError> {
    if coarse_level == 0 || coarse_level > spec.level() {
        return Err(GridError::BadCoarseLevel {
            coarse: coarse_level,
            fine: spec.level(),
        });
    }
    Ok(coarse_level)
}

/// The coarse level to use on `spec` by default: [`DEFAULT_COARSE_LEVEL`], or the grid's
/// own level when it is coarser than that.
pub fn default_coarse(spec: GridSpec) -> u32 {
    DEFAULT_COARSE_LEVEL.min(spec.level())
}

/// Evaluate every point of level `l` (stride `2^(L-l)`) of `grid`.
pub(crate) fn eval_level(
    ev: &mut Evaluator,
    grid: &mut Grid,
    l: u32,
    list: &mut Vec<u32>,
) -> Result<(), FieldError> {
    let spec = grid.spec();
    let s = spec.stride(l);
    let n = spec.n();
    list.clear();
    for k in (0..n).step_by(s) {
        for j in (0..n).step_by(s) {
            for i in (0..n).step_by(s) {
                list.push(spec.linear([i, j, k]) as u32);
            }
        }
    }
    ev.eval_grid(grid, list)
}

/// Binary occupancy as 0.0 / 1.0.
#[inline]
pub(crate) fn bin(v: f32) -> f32 {
    if is_inside(v) { 1.0 } else { 0.0 }
}
