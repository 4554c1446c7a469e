//! The paper's hierarchical surface localization (Sec. 3.2 of MonoPort), faithfully, plus
//! the variant without the conflict loop and our tighter variant.
//!
//! Per level `l` (fine stride `s`, coarse stride `2s`), working in integer indices of the
//! finest grid:
//! 1. **Upsample**: every new level-`l` point gets the mean of its 1, 2, 4 or 8 coarse
//!    parents' *binarized* values (a separable trilinear upsample of the binary field).
//!    Points whose mean is neither 0 nor 1 are the **boundary** candidates.
//! 2. **Dilate** the candidates by the 1-ring (3x3x3 at stride `s`) and evaluate those not
//!    yet evaluated.
//! 3. **Conflicts**: an evaluated point whose interpolated value and evaluated value lie on
//!    opposite sides of 0.5 (`(interp - 0.5) * (v - 0.5) < 0`) means a surface was missed;
//!    evaluate its unevaluated 26-neighbours, check them, and repeat until no conflict is
//!    left. It terminates: the evaluated set only grows and is bounded by the grid.
//! 4. Points never evaluated keep their interpolated value (0 or 1).
//!
//! Buffers (index lists, the queued bitset) are kept between frames.
//!
//! **Sparse upsampling.** A new point all of whose parents are outside gets 0, which is what
//! a grid cleared by [`Grid::reset_sparse`] already holds; so step 1 visits only the box of
//! the inside points grown by one fine stride (every new point with an inside parent lies in
//! it, and every inside point lies in the box of its inside parents), and the grid records the
//! box it wrote. The box of inside points is kept from level to level: the previous box plus
//! every evaluated point that came out inside. Values, candidates and evaluations are those of
//! a pass over the whole volume (the exactness tests compare against dense).

use super::{bin, eval_level};
use crate::field::{Evaluator, FieldError};
use crate::grid::{BitSet, Grid, IndexBox, RING26, offset};

/// Which variant of the hierarchical method to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HierarchicalMode {
    /// The paper: dilation and conflict loop.
    Paper,
    /// Dilation, no conflict loop (the public demo's "faster" mode).
    NoConflict,
    /// No dilation; conflict loop plus sign-change closure.
    Tight,
}

/// Reusable state of the hierarchical localizer.
#[derive(Default)]
pub struct Hierarchical {
    /// Boundary candidates of the current level (new points with fractional upsampled value).
    pub(crate) cand: Vec<u32>,
    /// Points to evaluate next, and their value before evaluation (their interpolation).
    pub(crate) batch: Vec<u32>,
    pub(crate) pre: Vec<f32>,
    next: Vec<u32>,
    next_pre: Vec<f32>,
    queued: BitSet,
    /// A box holding every inside point of the levels done so far.
    inside: IndexBox,
}

impl Hierarchical {
    /// Run levels `coarse..=last` on `grid` (whose own level may be finer than `last`; finer
    /// points are then left untouched). Returns the number of conflict-loop rounds.
    pub fn run(
        &mut self,
        ev: &mut Evaluator,
        grid: &mut Grid,
        coarse: u32,
        last: u32,
        mode: HierarchicalMode,
    ) -> Result<u32, FieldError> {
        self.start(ev, grid, coarse)?;
        let mut rounds = 0;
        for l in coarse + 1..=last {
            self.upsample(grid, l);
            match mode {
                HierarchicalMode::Paper | HierarchicalMode::NoConflict => {
                    self.dilate(grid, l, |_| true)
                }
                HierarchicalMode::Tight => self.candidates_only(grid),
            }
            ev.eval_grid(grid, &self.batch)?;
            grow_inside(&mut self.inside, grid, &self.batch);
            if mode != HierarchicalMode::NoConflict {
                rounds += self.conflict_loop(
                    ev,
                    grid,
                    l,
                    mode == HierarchicalMode::Tight,
                    |_| true,
                    None,
                )?;
            }
        }
        Ok(rounds)
    }

    /// Reset buffers for `grid` (which must come from [`Grid::reset_sparse`]) and evaluate
    /// every point of the coarsest level.
    pub(crate) fn start(
        &mut self,
        ev: &mut Evaluator,
        grid: &mut Grid,
        coarse: u32,
    ) -> Result<(), FieldError> {
        self.queued.reset(grid.spec().len());
        self.inside = IndexBox::EMPTY;
        eval_level(ev, grid, coarse, &mut self.batch)?;
        grow_inside(&mut self.inside, grid, &self.batch);
        Ok(())
    }

    /// The box holding every inside point of the levels localized so far (after
    /// [`Hierarchical::upsample`] to a level, of that level's too).
    pub(crate) fn inside_box(&self) -> IndexBox {
        self.inside
    }

    /// Step 1: write the upsampled binarized coarse field into every new level-`l` point and
    /// collect the boundary candidates (fractional values) in `self.cand`.
    pub(crate) fn upsample(&mut self, grid: &mut Grid, l: u32) {
        let spec = grid.spec();
        let n = spec.n();
        let s = spec.stride(l);
        let s2 = 2 * s;
        self.cand.clear();
        // Every new point with an inside parent, aligned to the coarse lattice so that the
        // separable passes read only values they wrote (or zeros) at the box's edges.
        let b = self.inside.padded(s, s2, n);
        if b.is_empty() {
            return;
        }
        grid.mark_written(b);
        let v = &mut grid.values;
        let cand = &mut self.cand;
        let mut put = |idx: usize, m: f32, v: &mut Vec<f32>| {
            v[idx] = m;
            if m > 0.0 && m < 1.0 {
                cand.push(idx as u32);
            }
        };
        let (x0, x1) = (b.lo[0], b.hi[0]);
        let (y0, y1) = (b.lo[1], b.hi[1]);
        let (z0, z1) = (b.lo[2], b.hi[2]);
        // Along x, in rows of coarse points.
        for k in (z0..=z1).step_by(s2) {
            for j in (y0..=y1).step_by(s2) {
                let row = n * (j + n * k);
                for i in (x0 + s..x1).step_by(s2) {
                    let m = 0.5 * (bin(v[row + i - s]) + bin(v[row + i + s]));
                    put(row + i, m, v);
                }
            }
        }
        // Along y, in coarse planes: old points are binarized, x-upsampled points taken as is.
        for k in (z0..=z1).step_by(s2) {
            for j in (y0 + s..y1).step_by(s2) {
                let r0 = n * (j - s + n * k);
                let r1 = n * (j + s + n * k);
                let r = n * (j + n * k);
                for i in (x0..=x1).step_by(s) {
                    let m = if (i / s).is_multiple_of(2) {
                        0.5 * (bin(v[r0 + i]) + bin(v[r1 + i]))
                    } else {
                        0.5 * (v[r0 + i] + v[r1 + i])
                    };
                    put(r + i, m, v);
                }
            }
        }
        // Along z, between coarse planes.
        let plane = n * n;
        for k in (z0 + s..z1).step_by(s2) {
            for j in (y0..=y1).step_by(s) {
                let even_j = (j / s).is_multiple_of(2);
                let r0 = n * j + plane * (k - s);
                let r1 = n * j + plane * (k + s);
                let r = n * j + plane * k;
                for i in (x0..=x1).step_by(s) {
                    let m = if even_j && (i / s).is_multiple_of(2) {
                        0.5 * (bin(v[r0 + i]) + bin(v[r1 + i]))
                    } else {
                        0.5 * (v[r0 + i] + v[r1 + i])
                    };
                    put(r + i, m, v);
                }
            }
        }
    }

    /// Step 2 (paper): the candidates and their 1-ring at stride `s`, not yet evaluated and
    /// accepted by `keep`, go to `self.batch`.
    pub(crate) fn dilate(&mut self, grid: &Grid, l: u32, keep: impl Fn(usize) -> bool) {
        let spec = grid.spec();
        let (n, s) = (spec.n(), spec.stride(l));
        self.batch.clear();
        self.pre.clear();
        for &c in &self.cand {
            let ci = spec.unlinear(c as usize);
            for off in RING26.iter().chain(std::iter::once(&[0, 0, 0])) {
                if let Some(q) = offset(ci, *off, s, n) {
                    let ql = spec.linear(q);
                    if !grid.evaluated.get(ql) && !self.queued.get(ql) && keep(ql) {
                        self.queued.set(ql);
                        self.batch.push(ql as u32);
                        self.pre.push(grid.values[ql]);
                    }
                }
            }
        }
    }

    /// Step 2 (tight): the candidates alone.
    fn candidates_only(&mut self, grid: &Grid) {
        self.batch.clear();
        self.pre.clear();
        for &c in &self.cand {
            if self.queued.insert(c as usize) {
                self.batch.push(c);
                self.pre.push(grid.values[c as usize]);
            }
        }
    }

    /// Step 3: the conflict loop over the points just evaluated (`self.batch`, with their
    /// interpolated values in `self.pre`). With `closure`, an evaluated point also pulls in
    /// every unevaluated 26-neighbour whose assumed (interpolated) side differs from its own.
    /// Only points accepted by `keep` are evaluated; evaluated points are appended to `log`.
    pub(crate) fn conflict_loop(
        &mut self,
        ev: &mut Evaluator,
        grid: &mut Grid,
        l: u32,
        closure: bool,
        keep: impl Fn(usize) -> bool,
        mut log: Option<&mut Vec<u32>>,
    ) -> Result<u32, FieldError> {
        let spec = grid.spec();
        let (n, s) = (spec.n(), spec.stride(l));
        let mut rounds = 0;
        loop {
            self.next.clear();
            self.next_pre.clear();
            for (&p, &interp) in self.batch.iter().zip(&self.pre) {
                let v = grid.values[p as usize];
                let conflict = (interp - 0.5) * (v - 0.5) < 0.0;
                if !conflict && !closure {
                    continue;
                }
                let pi = spec.unlinear(p as usize);
                for off in &RING26 {
                    let Some(q) = offset(pi, *off, s, n) else {
                        continue;
                    };
                    let ql = spec.linear(q);
                    if grid.evaluated.get(ql) || self.queued.get(ql) || !keep(ql) {
                        continue;
                    }
                    let assumed = grid.values[ql];
                    if conflict || bin(assumed) != bin(v) {
                        self.queued.set(ql);
                        self.next.push(ql as u32);
                        self.next_pre.push(assumed);
                    }
                }
            }
            if self.next.is_empty() {
                return Ok(rounds);
            }
            rounds += 1;
            ev.eval_grid(grid, &self.next)?;
            grow_inside(&mut self.inside, grid, &self.next);
            if let Some(log) = log.as_deref_mut() {
                log.extend_from_slice(&self.next);
            }
            std::mem::swap(&mut self.batch, &mut self.next);
            std::mem::swap(&mut self.pre, &mut self.next_pre);
        }
    }
}

/// Grow `b` by the points of `idxs` that are inside.
pub(crate) fn grow_inside(b: &mut IndexBox, grid: &Grid, idxs: &[u32]) {
    let spec = grid.spec();
    for &q in idxs {
        if crate::grid::is_inside(grid.values[q as usize]) {
            b.add(spec.unlinear(q as usize));
        }
    }
}
