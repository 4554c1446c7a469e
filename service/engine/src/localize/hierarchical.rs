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
//! Our addition, **seeds**: the field's [`crate::field::OccupancyField::seeds`] (points it knows to be
//! inside, e.g. along thin parts), each at its nearest point of every level, join step 2's
//! evaluations; one that comes out inside where the interpolation said outside is a
//! conflict, and step 3 traces the part from it. Without seeds (every analytic field) the
//! method is the paper's.
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
//!
//! **Row extents.** Inside the box a person fills a small part (about 8 % of the finest
//! box's rows' length at 257^3 on front-walk): most rows are empty and the rest are short.
//! So every row of the grid (fixed `j`, `k`) keeps an extent `[lo, hi]` of x indices that
//! holds all of its inside points ([`Hierarchical::row_extents`]): grown by every evaluated
//! point that comes out inside, and set by each pass of the upsampling to the span it wrote.
//! A pass writes only where a source row has an extent (the x pass: the coarse row's inside
//! points, found in its extent, one stride each side; the y and z passes: the union of their
//! two source rows' spans), since everything else it would write is 0, which the cleared
//! grid already holds. Candidates come out in the same order (rows in the same order, each
//! scanned where it can hold a fraction), so the values, candidates and evaluations are
//! those of the whole box.

use super::{bin, eval_level};
use crate::field::{Evaluator, FieldError};
use crate::grid::{BitSet, Grid, IndexBox, RING26, is_inside, offset};

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
    /// Every point evaluated or queued for evaluation this frame (a superset of the grid's
    /// `evaluated`: the coarsest level is marked in [`Hierarchical::start`]), so one bit
    /// answers "already handled".
    queued: BitSet,
    /// The box [`Hierarchical::upsample`] wrote (every candidate lies in it).
    cand_box: IndexBox,
    /// A box holding every inside point of the levels done so far.
    inside: IndexBox,
    /// Per row `j + n k` of the grid, x indices `[lo, hi]` holding every inside point of
    /// the row (`lo > hi`: none); see the module's doc.
    rows: Vec<[u32; 2]>,
    /// The field's seeds as indices of the finest grid (set by [`Hierarchical::start`]).
    seeds: Vec<[u32; 3]>,
}

/// A row with no inside point.
const NO_ROW: [u32; 2] = [u32::MAX, 0];

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
            self.queue_seeds(grid, l, |_| true);
            ev.eval_grid(grid, &self.batch)?;
            grow_inside(&mut self.inside, &mut self.rows, grid, &self.batch);
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
        let n = grid.spec().n();
        self.rows.clear();
        self.rows.resize(n * n, NO_ROW);
        self.seeds = super::seed_nodes(grid.spec(), &ev.seeds());
        eval_level(ev, grid, coarse, &mut self.batch)?;
        for &q in &self.batch {
            self.queued.set(q as usize);
        }
        grow_inside(&mut self.inside, &mut self.rows, grid, &self.batch);
        Ok(())
    }

    /// The box holding every inside point of the levels localized so far (after
    /// [`Hierarchical::upsample`] to a level, of that level's too).
    pub(crate) fn inside_box(&self) -> IndexBox {
        self.inside
    }

    /// Per row `j + n k`, x indices `[lo, hi]` holding every inside point of the row
    /// (`lo > hi`: none) as of the last step (the evaluations and upsamplings so far).
    pub(crate) fn row_extents(&self) -> &[[u32; 2]] {
        &self.rows
    }

    /// Step 1: write the upsampled binarized coarse field into every new level-`l` point and
    /// collect the boundary candidates (fractional values) in `self.cand`.
    pub(crate) fn upsample(&mut self, grid: &mut Grid, l: u32) {
        let spec = grid.spec();
        let n = spec.n();
        let s = spec.stride(l);
        // Strides are powers of two: an index `i` (a multiple of `s`) is on the coarse
        // lattice when `i / s` is even, i.e. when `i & s == 0` (no division per point).
        debug_assert!(s.is_power_of_two());
        let s2 = 2 * s;
        self.cand.clear();
        // Every new point with an inside parent, aligned to the coarse lattice so that the
        // separable passes read only values they wrote (or zeros) at the box's edges.
        let b = self.inside.padded(s, s2, n);
        self.cand_box = b;
        if b.is_empty() {
            return;
        }
        let (v, written) = grid.written_spans(b);
        let mut wrote = |id: usize, lo: usize, hi: usize| {
            let w = &mut written[id];
            w[0] = w[0].min(lo as u32);
            w[1] = w[1].max(hi as u32);
        };
        let cand = &mut self.cand;
        let rows = &mut self.rows;
        let (x0, x1) = (b.lo[0], b.hi[0]);
        let (y0, y1) = (b.lo[1], b.hi[1]);
        let (z0, z1) = (b.lo[2], b.hi[2]);
        // Rows run from x0 to x1, both multiples of 2s (the box is aligned); a row position
        // t = i - x0 has the parity of i. Each row is written over its span, then scanned
        // there for candidates (the same points in the same order as one point at a time
        // over the whole box: outside the span every value stays 0).
        let len = x1 - x0 + 1;
        // Along x, in rows of coarse points: the odd positions from their even neighbours,
        // one stride each side of the row's inside coarse points.
        for k in (z0..=z1).step_by(s2) {
            for j in (y0..=y1).step_by(s2) {
                let id = j + n * k;
                let base = n * id + x0;
                let r = &mut v[base..base + len];
                let [lo, hi] = rows[id];
                let (mut first_in, mut last_in) = (None, 0);
                if lo <= hi && (lo as usize) <= x1 && (hi as usize) >= x0 {
                    // The coarse positions of the row's extent inside the box.
                    let tlo = ((lo as usize).max(x0) - x0).next_multiple_of(s2);
                    let thi = (hi as usize).min(x1) - x0;
                    for t in (tlo..=thi).step_by(s2) {
                        if is_inside(r[t]) {
                            first_in.get_or_insert(t);
                            last_in = t;
                        }
                    }
                }
                let Some(ta) = first_in else {
                    rows[id] = NO_ROW;
                    continue;
                };
                let first = if ta >= s { ta - s } else { ta + s };
                let last = (last_in + s).min(len - 1 - s);
                for t in (first..=last).step_by(s2) {
                    r[t] = 0.5 * (bin(r[t - s]) + bin(r[t + s]));
                }
                scan(&r[..=last], first, s2, base, cand);
                wrote(id, x0 + first, x0 + last);
                rows[id] = [
                    (x0 + ta.saturating_sub(s)) as u32,
                    (x0 + last_in + s).min(x1) as u32,
                ];
            }
        }
        // The span of a row made from rows with extents `a` and `b`: their union inside the
        // box, widened to the coarse lattice (the blend's parity counts from its start).
        let span = |a: [u32; 2], b: [u32; 2]| -> Option<(usize, usize)> {
            let (lo, hi) = (a[0].min(b[0]) as usize, a[1].max(b[1]) as usize);
            if lo > hi || lo > x1 || hi < x0 {
                return None;
            }
            let tlo = (lo.max(x0) - x0) / s2 * s2;
            let thi = (hi.min(x1) - x0).next_multiple_of(s2).min(len - 1);
            Some((tlo, thi))
        };
        // Along y, in coarse planes: old points are binarized, x-upsampled points taken as is.
        for k in (z0..=z1).step_by(s2) {
            for j in (y0 + s..y1).step_by(s2) {
                let id = j + n * k;
                let Some((tlo, thi)) = span(rows[id - s], rows[id + s]) else {
                    rows[id] = NO_ROW;
                    continue;
                };
                let r = n * id + x0 + tlo;
                let (a, out, b) = rows3(v, r - s * n, r, r + s * n, thi - tlo + 1);
                blend(out, a, b, s, true);
                scan(out, 0, s, r, cand);
                wrote(id, x0 + tlo, x0 + thi);
                rows[id] = [(x0 + tlo) as u32, (x0 + thi) as u32];
            }
        }
        // Along z, between coarse planes (rows of odd y hold no old points).
        let plane = n * n;
        for k in (z0 + s..z1).step_by(s2) {
            for j in (y0..=y1).step_by(s) {
                let id = j + n * k;
                let Some((tlo, thi)) = span(rows[id - s * n], rows[id + s * n]) else {
                    rows[id] = NO_ROW;
                    continue;
                };
                let r = n * id + x0 + tlo;
                let (a, out, b) = rows3(v, r - s * plane, r, r + s * plane, thi - tlo + 1);
                blend(out, a, b, s, j & s == 0);
                scan(out, 0, s, r, cand);
                wrote(id, x0 + tlo, x0 + thi);
                rows[id] = [(x0 + tlo) as u32, (x0 + thi) as u32];
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
        // (The candidates are taken out for the loops, which queue through `self`.)
        let cand = std::mem::take(&mut self.cand);
        let b = self.cand_box;
        // Every candidate is at least a stride from the border.
        let interior = !b.is_empty() && (0..3).all(|a| b.lo[a] >= s && b.hi[a] + s < n);
        if interior && s == 1 {
            // Away from the border, and at the finest stride
            // a ring is 9 rows of 3 neighbouring points (the centre's row without the centre,
            // which comes last, as below): a row whose points are all queued already (most
            // of them: neighbouring candidates share their rings) is passed over with one
            // test of the bits.
            let rows: [isize; 9] = std::array::from_fn(|r| {
                let (n, dy, dz) = (n as isize, r as isize % 3 - 1, r as isize / 3 - 1);
                n * (dy + n * dz)
            });
            for &c in &cand {
                for (r, d) in rows.iter().enumerate() {
                    let first = (c as isize + d - 1) as usize;
                    let mask = if r == 4 { 0b101 } else { 0b111 };
                    if self.queued.all_set(first, mask) {
                        continue;
                    }
                    for x in 0..3 {
                        if mask >> x & 1 == 1 {
                            self.queue(grid, first + x, &keep);
                        }
                    }
                }
                self.queue(grid, c as usize, &keep);
            }
        } else if interior {
            // Away from the border a ring is the same linear offsets everywhere (same order
            // as below).
            let ring: [isize; 27] = std::array::from_fn(|r| {
                let o = RING26.get(r).copied().unwrap_or([0, 0, 0]);
                let (n, s) = (n as isize, s as isize);
                s * (o[0] as isize + n * (o[1] as isize + n * o[2] as isize))
            });
            for &c in &cand {
                for d in ring {
                    self.queue(grid, (c as isize + d) as usize, &keep);
                }
            }
        } else {
            for &c in &cand {
                let ci = spec.unlinear(c as usize);
                for off in RING26.iter().chain(std::iter::once(&[0, 0, 0])) {
                    if let Some(q) = offset(ci, *off, s, n) {
                        self.queue(grid, spec.linear(q), &keep);
                    }
                }
            }
        }
        self.cand = cand;
    }

    /// The seeds, each at its nearest level-`l` point, not yet queued and accepted by `keep`,
    /// to the batch (after step 2's points).
    pub(crate) fn queue_seeds(&mut self, grid: &Grid, l: u32, keep: impl Fn(usize) -> bool) {
        let spec = grid.spec();
        let (n, s) = (spec.n(), spec.stride(l));
        let seeds = std::mem::take(&mut self.seeds);
        for q in &seeds {
            // Nearest multiple of the stride (the last index, n - 1, is one).
            let q = q.map(|v| ((v as usize + s / 2) / s * s).min(n - 1));
            self.queue(grid, spec.linear(q), &keep);
        }
        self.seeds = seeds;
    }

    /// Point `q` to the batch with its value before evaluation, if not queued yet and kept.
    #[inline]
    fn queue(&mut self, grid: &Grid, q: usize, keep: &impl Fn(usize) -> bool) {
        if !self.queued.get(q) && keep(q) {
            self.queued.set(q);
            self.batch.push(q as u32);
            self.pre.push(grid.values[q]);
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
                    if self.queued.get(ql) || !keep(ql) {
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
            grow_inside(&mut self.inside, &mut self.rows, grid, &self.next);
            if let Some(log) = log.as_deref_mut() {
                log.extend_from_slice(&self.next);
            }
            std::mem::swap(&mut self.batch, &mut self.next);
            std::mem::swap(&mut self.pre, &mut self.next_pre);
        }
    }
}

/// Rows `a`, `o`, `b` of `len` values of `v` (`a + len <= o`, `o + len <= b`), `o` mutable.
fn rows3(v: &mut [f32], a: usize, o: usize, b: usize, len: usize) -> (&[f32], &mut [f32], &[f32]) {
    let (lo, hi) = v.split_at_mut(o);
    let (out, rest) = hi.split_at_mut(len);
    (&lo[a..a + len], out, &rest[b - o - len..b - o])
}

/// `out[t] = (a[t] + b[t]) / 2` at row positions `t = 0, s, 2s, ...`, with `a` and `b`
/// binarized at the positions on the coarse lattice (multiples of `2s`) when `bin_even`.
/// Rows of stride 1 run as contiguous slices (vectorized).
fn blend(out: &mut [f32], a: &[f32], b: &[f32], s: usize, bin_even: bool) {
    let len = out.len();
    if s > 1 {
        for t in (0..len).step_by(s) {
            out[t] = if bin_even && t & s == 0 {
                0.5 * (bin(a[t]) + bin(b[t]))
            } else {
                0.5 * (a[t] + b[t])
            };
        }
    } else if bin_even {
        let pairs = len / 2;
        for ((o, a), b) in out[..2 * pairs]
            .chunks_exact_mut(2)
            .zip(a.chunks_exact(2))
            .zip(b.chunks_exact(2))
        {
            o[0] = 0.5 * (bin(a[0]) + bin(b[0]));
            o[1] = 0.5 * (a[1] + b[1]);
        }
        if len % 2 == 1 {
            out[len - 1] = 0.5 * (bin(a[len - 1]) + bin(b[len - 1]));
        }
    } else {
        for ((o, a), b) in out.iter_mut().zip(a).zip(b) {
            *o = 0.5 * (a + b);
        }
    }
}

/// Push `base + t` for the row positions `t = first, first + step, ...` holding a fractional
/// value (a boundary candidate).
fn scan(row: &[f32], first: usize, step: usize, base: usize, cand: &mut Vec<u32>) {
    let frac = |m: f32| (m > 0.0) & (m < 1.0);
    if step == 1 && first == 0 {
        // Most of a row is 0 or 1: test 16 values at once (vectorized), then look closer.
        const W: usize = 16;
        for (c, chunk) in row.chunks(W).enumerate() {
            if chunk.iter().fold(false, |a, &m| a | frac(m)) {
                for (t, &m) in chunk.iter().enumerate() {
                    if frac(m) {
                        cand.push((base + c * W + t) as u32);
                    }
                }
            }
        }
        return;
    }
    for t in (first..row.len()).step_by(step) {
        if frac(row[t]) {
            cand.push((base + t) as u32);
        }
    }
}

/// Grow `b` and the row extents `rows` by the points of `idxs` that are inside.
pub(crate) fn grow_inside(b: &mut IndexBox, rows: &mut [[u32; 2]], grid: &Grid, idxs: &[u32]) {
    let spec = grid.spec();
    let n = spec.n();
    for &q in idxs {
        if is_inside(grid.values[q as usize]) {
            let p = spec.unlinear(q as usize);
            b.add(p);
            let r = &mut rows[p[1] + n * p[2]];
            r[0] = r[0].min(p[0] as u32);
            r[1] = r[1].max(p[0] as u32);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analytic::AnalyticScene;
    use crate::grid::GridSpec;

    /// `scene` localized by the paper's method from level 3 to `last` on a fresh grid.
    fn localized(scene: &AnalyticScene, spec: GridSpec, last: u32) -> (Grid, Hierarchical) {
        let mut grid = Grid::new(spec);
        grid.reset_sparse(spec);
        let mut h = Hierarchical::default();
        let mut ev = Evaluator::new(scene);
        h.run(&mut ev, &mut grid, 3, last, HierarchicalMode::Paper)
            .unwrap();
        (grid, h)
    }

    /// The dilation lists, in order, each candidate's 26 neighbours and then itself, those
    /// not yet queued and kept (the rule, point by point), at every stride, with and without
    /// a filter.
    #[test]
    fn dilation_lists_each_ring_in_order() {
        // (The thin plate has no candidates below the level that first sees it.)
        let mut listed = 0;
        for name in ["capsule-human", "two-bodies", "thin-plate", "noise"] {
            let scene = AnalyticScene::by_name(name).unwrap();
            let spec = GridSpec::new(7).unwrap();
            for l in 4..=7 {
                for filtered in [false, true] {
                    let keep = |q: usize| !filtered || !q.is_multiple_of(3);
                    let (mut grid, mut h) = localized(&scene, spec, l - 1);
                    h.upsample(&mut grid, l);
                    let (n, st) = (spec.n(), spec.stride(l));
                    let mut queued = h.queued.clone();
                    let mut want = Vec::new();
                    for &c in &h.cand {
                        let ci = spec.unlinear(c as usize);
                        for off in RING26.iter().chain(std::iter::once(&[0, 0, 0])) {
                            if let Some(q) = offset(ci, *off, st, n) {
                                let ql = spec.linear(q);
                                if !queued.get(ql) && keep(ql) {
                                    queued.set(ql);
                                    want.push(ql as u32);
                                }
                            }
                        }
                    }
                    h.dilate(&grid, l, keep);
                    listed += want.len();
                    assert_eq!(h.batch, want, "{name} level {l} filtered {filtered}");
                    let pre: Vec<f32> = want.iter().map(|&q| grid.values[q as usize]).collect();
                    assert_eq!(h.pre, pre);
                }
            }
        }
        assert!(listed > 10_000, "{listed} points listed");
    }

    /// After frames of different scenes and levels, [`Grid::reset_sparse`] leaves every
    /// value 0 and nothing evaluated, clearing only the rows' written spans; a grid a dense
    /// method left full of values ([`Grid::reset`]) is cleared whole.
    #[test]
    fn sparse_reset_after_row_spans_clears_every_value() {
        let spec = GridSpec::new(7).unwrap();
        let mut grid = Grid::new(spec);
        let mut h = Hierarchical::default();
        for (name, last) in [("capsule-human", 7), ("two-bodies", 6), ("torus", 7)] {
            let scene = AnalyticScene::by_name(name).unwrap();
            grid.reset_sparse(spec);
            assert!(grid.values.iter().all(|v| *v == 0.0), "{name}");
            assert_eq!(grid.evaluated_count(), 0);
            let mut ev = Evaluator::new(&scene);
            h.run(&mut ev, &mut grid, 3, last, HierarchicalMode::Paper)
                .unwrap();
            assert!(grid.values.iter().any(|v| *v > 0.0 && *v < 1.0), "{name}");
        }
        // Values a dense method wrote anywhere, spans unrecorded: the whole grid is cleared.
        let n = spec.n();
        grid.reset(spec);
        for k in 5..=62 {
            grid.values[spec.linear([3, 4, k])] = 1.0;
            grid.values[spec.linear([60, 61, k])] = 0.5;
        }
        grid.reset_sparse(spec);
        assert!(grid.values.iter().all(|v| *v == 0.0));
        assert_eq!(grid.values.len(), n * n * n);
    }

    /// The upsampling over the rows' extents writes what the method defines over the whole
    /// grid: every new level-`l` point the mean of its coarse parents' binarized values (old
    /// points kept), and the candidates are exactly the new points with a fractional mean,
    /// row by row in memory order within each pass. Scenes with thin parts, several bodies
    /// and holes; every level from the first upsampled one to the finest.
    #[test]
    fn upsampling_over_row_extents_equals_the_whole_grid_rule() {
        for name in [
            "capsule-human",
            "two-bodies",
            "thin-plate",
            "torus",
            "noise",
        ] {
            let scene = AnalyticScene::by_name(name).unwrap();
            let spec = GridSpec::new(7).unwrap();
            let n = spec.n();
            for l in 4..=7 {
                let (mut grid, mut h) = localized(&scene, spec, l - 1);
                let before = grid.values.clone();
                h.upsample(&mut grid, l);
                let s = spec.stride(l);
                let parents = |i: usize| -> Vec<usize> {
                    if i.is_multiple_of(2 * s) {
                        vec![i]
                    } else {
                        vec![i - s, i + s]
                    }
                };
                let mut want_cand = Vec::new();
                for k in (0..n).step_by(s) {
                    for j in (0..n).step_by(s) {
                        for i in (0..n).step_by(s) {
                            let q = spec.linear([i, j, k]);
                            let old = [i, j, k].iter().all(|v| v.is_multiple_of(2 * s));
                            let want = if old {
                                before[q]
                            } else {
                                let (px, py, pz) = (parents(i), parents(j), parents(k));
                                let mut sum = 0.0f32;
                                let mut cnt = 0.0f32;
                                for &c in &pz {
                                    for &b in &py {
                                        for &a in &px {
                                            sum += bin(before[spec.linear([a, b, c])]);
                                            cnt += 1.0;
                                        }
                                    }
                                }
                                let m = sum / cnt;
                                if m > 0.0 && m < 1.0 {
                                    want_cand.push(q as u32);
                                }
                                m
                            };
                            assert_eq!(grid.values[q], want, "{name} level {l} at {:?}", [i, j, k]);
                        }
                    }
                }
                let mut got = h.cand.clone();
                // Each pass lists its rows in memory order.
                assert!(
                    got.windows(2).filter(|w| w[0] > w[1]).count() <= 2,
                    "{name} level {l}: candidates out of order"
                );
                got.sort_unstable();
                assert_eq!(got, want_cand, "{name} level {l}: candidates");
                // Every inside point lies in its row's extent.
                for q in 0..spec.len() {
                    if is_inside(grid.values[q]) {
                        let [i, j, k] = spec.unlinear(q);
                        let [lo, hi] = h.row_extents()[j + n * k];
                        assert!(lo as usize <= i && i <= hi as usize, "{name} level {l}");
                    }
                }
            }
        }
    }
}
