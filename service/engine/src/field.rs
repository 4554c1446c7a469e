//! Occupancy and colour fields, and the single counted, checked path through which every
//! localization method and the renderer evaluate them.

use crate::grid::{Grid, GridSpec};
use glam::Vec3;

/// Why a field evaluation failed.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum FieldError {
    /// The field returned NaN or an infinity. Never silently replaced.
    #[error("field returned non-finite value {value} at grid index {index:?} (NDC {point:?})")]
    NonFinite {
        index: Option<[usize; 3]>,
        point: [f32; 3],
        value: f32,
    },
    /// The field returned a value outside [0, 1].
    #[error(
        "field returned occupancy {value} outside [0, 1] at grid index {index:?} (NDC {point:?})"
    )]
    OutOfRange {
        index: Option<[usize; 3]>,
        point: [f32; 3],
        value: f32,
    },
    /// The field's backend failed (e.g. a network runtime error).
    #[error("field backend failed: {0}")]
    Backend(String),
}

/// A batch-evaluated occupancy field over NDC space: `out[i]` is the occupancy in [0, 1]
/// of `points[i]`. Implementations may be expensive (a network); callers batch.
pub trait OccupancyField: Sync {
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError>;

    /// Points (in the field's own coordinates) that the field already knows to be inside,
    /// where a part may be thinner than a coarse-to-fine localizer's strides (a hand, an arm
    /// seen edge-on): the hierarchical localizer evaluates each at every level, so the
    /// conflict loop traces a part that fell between its coarse samples instead of losing
    /// it (docs/eval/hands.md section 19). None by default.
    fn seeds(&self) -> Vec<Vec3> {
        Vec::new()
    }
}

/// A batch-evaluated colour field: linear RGB in [0, 1] at surface points.
pub trait ColorField: Sync {
    fn color(&self, points: &[Vec3], out: &mut [[f32; 3]]) -> Result<(), FieldError>;
}

impl<F: OccupancyField + ?Sized> OccupancyField for &F {
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        (**self).occupancy(points, out)
    }

    fn seeds(&self) -> Vec<Vec3> {
        (**self).seeds()
    }
}

/// Points per field call.
pub const BATCH: usize = 4096;

/// The counted, checked evaluation path: every evaluation of every method goes through
/// here, so the counts in benchmarks are exact and a NaN/Inf is always reported with the
/// point that produced it.
pub struct Evaluator<'f> {
    field: &'f dyn OccupancyField,
    count: u64,
    pts: Vec<Vec3>,
    out: Vec<f32>,
    threads: usize,
    /// Wall time spent inside the field (what is left of a method's time is bookkeeping).
    field_time: std::time::Duration,
    /// `spec.coord(i)` for every `i` of the last grid evaluated (the same values, without a
    /// division per point).
    coords: Vec<f32>,
    /// The surface's dead band ([`crate::sides`]), applied to every grid value written.
    sides: Option<&'f mut crate::sides::HeldSides>,
}

/// Smallest batch part worth a thread of its own (below it, one thread evaluates).
pub const PAR_MIN_POINTS: usize = 512;

/// `field` on `pts` into `out`, split into up to `threads` contiguous parts evaluated at
/// once (scoped threads). Every point is evaluated exactly as alone: the values do not
/// depend on the split.
pub fn occupancy_split(
    field: &dyn OccupancyField,
    pts: &[Vec3],
    out: &mut [f32],
    threads: usize,
) -> Result<(), FieldError> {
    let parts = threads.min(pts.len() / PAR_MIN_POINTS).max(1);
    if parts == 1 {
        return field.occupancy(pts, out);
    }
    let size = pts.len().div_ceil(parts);
    std::thread::scope(|s| {
        let mut handles = Vec::with_capacity(parts - 1);
        let mut chunks = pts.chunks(size).zip(out.chunks_mut(size));
        let first = chunks.next();
        for (p, o) in chunks {
            handles.push(s.spawn(move || field.occupancy(p, o)));
        }
        let mut result = match first {
            Some((p, o)) => field.occupancy(p, o),
            None => Ok(()),
        };
        for h in handles {
            let r = h
                .join()
                .unwrap_or_else(|_| Err(FieldError::Backend("evaluation thread panicked".into())));
            if result.is_ok() {
                result = r;
            }
        }
        result
    })
}

impl<'f> Evaluator<'f> {
    pub fn new(field: &'f dyn OccupancyField) -> Self {
        Self {
            field,
            count: 0,
            pts: Vec::with_capacity(BATCH),
            out: vec![0.0; BATCH],
            threads: 1,
            field_time: std::time::Duration::ZERO,
            coords: Vec::new(),
            sides: None,
        }
    }

    /// Give the grid points out through `sides` ([`crate::sides::HeldSides`], begun for this
    /// frame; nothing changes where it holds nothing): a value within the band of last
    /// frame's is given out as that, a side crossed by less than the band is kept.
    pub fn with_sides(mut self, sides: &'f mut crate::sides::HeldSides) -> Self {
        self.sides = sides.active().then_some(sides);
        self
    }

    /// Evaluate each batch on up to `threads` threads (1: the calling thread only).
    pub fn with_threads(mut self, threads: usize) -> Self {
        self.threads = threads.max(1);
        self
    }

    /// Evaluations so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The field's inside seeds ([`OccupancyField::seeds`]); not evaluated or counted here.
    pub fn seeds(&self) -> Vec<Vec3> {
        self.field.seeds()
    }

    /// Wall time spent in the field's evaluations so far.
    pub fn field_time(&self) -> std::time::Duration {
        self.field_time
    }

    fn check(
        &self,
        values: &[f32],
        spec: Option<GridSpec>,
        idxs: &[u32],
    ) -> Result<(), FieldError> {
        for (i, &v) in values.iter().enumerate() {
            if !(0.0..=1.0).contains(&v) {
                let index = spec.map(|s| s.unlinear(idxs[i] as usize));
                let point = self.pts[i].to_array();
                return Err(if v.is_finite() {
                    FieldError::OutOfRange {
                        index,
                        point,
                        value: v,
                    }
                } else {
                    FieldError::NonFinite {
                        index,
                        point,
                        value: v,
                    }
                });
            }
        }
        Ok(())
    }

    /// Evaluate the grid points `idxs` (linear indices of `grid`'s spec), writing their
    /// values and marking them evaluated.
    pub fn eval_grid(&mut self, grid: &mut Grid, idxs: &[u32]) -> Result<(), FieldError> {
        let spec = grid.spec();
        if self.coords.len() != spec.n() {
            self.coords = (0..spec.n()).map(|i| spec.coord(i)).collect();
        }
        let c = &self.coords;
        for chunk in idxs.chunks(BATCH) {
            self.pts.clear();
            self.pts.extend(chunk.iter().map(|&l| {
                let [i, j, k] = spec.unlinear(l as usize);
                Vec3::new(c[i], c[j], c[k])
            }));
            let out = &mut self.out[..chunk.len()];
            let t = std::time::Instant::now();
            let r = occupancy_split(self.field, &self.pts, out, self.threads);
            self.field_time += t.elapsed();
            r?;
            self.count += chunk.len() as u64;
            let out = &self.out[..chunk.len()];
            self.check(out, Some(spec), chunk)?;
            for (&l, &v) in chunk.iter().zip(out) {
                grid.values[l as usize] = match self.sides.as_deref_mut() {
                    Some(sides) => sides.apply(l as usize, v),
                    None => v,
                };
                grid.evaluated.set(l as usize);
            }
        }
        Ok(())
    }

    /// Evaluate arbitrary points (counted and checked the same way).
    pub fn eval_points(&mut self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        assert_eq!(
            points.len(),
            out.len(),
            "eval_points: points and out differ in length"
        );
        for (pc, oc) in points.chunks(BATCH).zip(out.chunks_mut(BATCH)) {
            self.pts.clear();
            self.pts.extend_from_slice(pc);
            let t = std::time::Instant::now();
            let r = occupancy_split(self.field, pc, oc, self.threads);
            self.field_time += t.elapsed();
            r?;
            self.count += pc.len() as u64;
            self.check(oc, None, &[])?;
        }
        Ok(())
    }
}

/// A field defined by a closure of one point (tests, small tools).
pub struct FnField<F>(pub F);

impl<F: Fn(Vec3) -> f32 + Sync> OccupancyField for FnField<F> {
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        for (o, p) in out.iter_mut().zip(points) {
            *o = (self.0)(*p);
        }
        Ok(())
    }
}

/// A field with the seeds given ([`OccupancyField::seeds`]) in place of its own (tests and
/// benches of the localizers; a caller that knows where a thin part is).
pub struct Seeded<F> {
    pub field: F,
    pub seeds: Vec<Vec3>,
}

impl<F: OccupancyField> OccupancyField for Seeded<F> {
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        self.field.occupancy(points, out)
    }

    fn seeds(&self) -> Vec<Vec3> {
        self.seeds.clone()
    }
}

/// A colour field defined by a closure of one point.
pub struct FnColor<F>(pub F);

impl<F: Fn(Vec3) -> [f32; 3] + Sync> ColorField for FnColor<F> {
    fn color(&self, points: &[Vec3], out: &mut [[f32; 3]]) -> Result<(), FieldError> {
        for (o, p) in out.iter_mut().zip(points) {
            *o = (self.0)(*p);
        }
        Ok(())
    }
}
