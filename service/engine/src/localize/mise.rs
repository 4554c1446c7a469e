//! Occupancy Networks' Multiresolution IsoSurface Extraction (MISE, `libmise`), faithfully:
//!
//! * a voxel octree whose roots are the cells of the coarsest level;
//! * every known grid point marks the leaf voxels whose closed region contains it as
//!   "next to positive" (`value >= 0.5`) and/or "next to negative" (`value <= 0.5`);
//! * each round, every leaf below the finest level marked both ways is subdivided, adding
//!   its 27-point lattice; the unknown points are evaluated; repeat until nothing is
//!   unknown. A coarse leaf can still be subdivided in a later round when a neighbour's
//!   finer points on their shared face disagree with it. No dilation, no recovery;
//! * unknown points are filled as `to_dense` does: forward fill along x, then y, then z.
//!
//! Voxels are addressed per level by their cell coordinates; flags are bitsets per level.

use super::{Scratch, eval_level};
use crate::field::{Evaluator, FieldError};
use crate::grid::{BitSet, Grid, ISO};

struct Levels {
    coarse: u32,
    fine: u32,
    /// Per level (index l - coarse), for levels coarse..fine-1: subdivided / pos / neg bits
    /// over that level's cells.
    subdiv: Vec<BitSet>,
    pos: Vec<BitSet>,
    neg: Vec<BitSet>,
}

impl Levels {
    fn cells_per_axis(l: u32) -> usize {
        1usize << l
    }

    fn cell_index(l: u32, c: [usize; 3]) -> usize {
        let m = Self::cells_per_axis(l);
        c[0] + m * (c[1] + m * c[2])
    }

    /// The leaf voxel containing the finest cell with min corner `c`: (level, cell coords).
    fn leaf_of(&self, c: [usize; 3]) -> (u32, [usize; 3]) {
        let mut l = self.coarse;
        loop {
            let sh = self.fine - l;
            let cc = [c[0] >> sh, c[1] >> sh, c[2] >> sh];
            if l == self.fine
                || !self.subdiv[(l - self.coarse) as usize].get(Self::cell_index(l, cc))
            {
                return (l, cc);
            }
            l += 1;
        }
    }

    fn mark(&mut self, l: u32, cc: [usize; 3], v: f32, touched: &mut Vec<(u32, [u32; 3])>) {
        if l == self.fine {
            return; // finest voxels are never subdivided
        }
        let li = (l - self.coarse) as usize;
        let ci = Self::cell_index(l, cc);
        let mut changed = false;
        if v >= ISO && self.pos[li].insert(ci) {
            changed = true;
        }
        if v <= ISO && self.neg[li].insert(ci) {
            changed = true;
        }
        if changed {
            touched.push((l, [cc[0] as u32, cc[1] as u32, cc[2] as u32]));
        }
    }
}

pub(crate) fn run(
    ev: &mut Evaluator,
    grid: &mut Grid,
    coarse: u32,
    sc: &mut Scratch,
) -> Result<(), FieldError> {
    let spec = grid.spec();
    let n = spec.n();
    let fine = spec.level();
    // Per-level flags: sum over levels of 8^l bits, small next to the grid.
    let fresh = || {
        (coarse..fine)
            .map(|l| BitSet::new(Levels::cells_per_axis(l).pow(3)))
            .collect::<Vec<_>>()
    };
    let mut lv = Levels {
        coarse,
        fine,
        subdiv: fresh(),
        pos: fresh(),
        neg: fresh(),
    };

    eval_level(ev, grid, coarse, &mut sc.list)?;
    let mut touched: Vec<(u32, [u32; 3])> = Vec::new();
    let mut new_known = std::mem::take(&mut sc.list);
    sc.queued.reset(spec.len());
    loop {
        // Mark leaves around every newly known point.
        touched.clear();
        for &p in &new_known {
            let pi = spec.unlinear(p as usize);
            let v = grid.values[p as usize];
            for c in 0..8usize {
                let d = [c & 1, (c >> 1) & 1, c >> 2];
                if (0..3).any(|a| pi[a] < d[a] || pi[a] - d[a] >= n - 1) {
                    continue;
                }
                let cell = [pi[0] - d[0], pi[1] - d[1], pi[2] - d[2]];
                let (l, cc) = lv.leaf_of(cell);
                lv.mark(l, cc, v, &mut touched);
            }
        }
        // Subdivide every touched leaf that is marked both ways (new children may be active
        // at once from points already on their boundary; they are checked in the same pass).
        new_known.clear();
        let mut qi = 0;
        while qi < touched.len() {
            let (l, c) = touched[qi];
            qi += 1;
            let li = (l - coarse) as usize;
            let cc = [c[0] as usize, c[1] as usize, c[2] as usize];
            let ci = Levels::cell_index(l, cc);
            if l == fine || lv.subdiv[li].get(ci) || !(lv.pos[li].get(ci) && lv.neg[li].get(ci)) {
                continue;
            }
            lv.subdiv[li].set(ci);
            let s = spec.stride(l);
            let h = s / 2;
            let base = [cc[0] * s, cc[1] * s, cc[2] * s];
            // New lattice points.
            for dk in 0..3 {
                for dj in 0..3 {
                    for di in 0..3 {
                        let idx =
                            spec.linear([base[0] + h * di, base[1] + h * dj, base[2] + h * dk]);
                        if !grid.evaluated.get(idx) && sc.queued.insert(idx) {
                            new_known.push(idx as u32);
                        }
                    }
                }
            }
            // Children: flags from the known points on their boundary (a leaf has none inside).
            if l + 1 < fine {
                for ch in 0..8usize {
                    let d = [ch & 1, (ch >> 1) & 1, ch >> 2];
                    let cb = [base[0] + h * d[0], base[1] + h * d[1], base[2] + h * d[2]];
                    let ccc = [cb[0] / h, cb[1] / h, cb[2] / h];
                    for k in cb[2]..=cb[2] + h {
                        for j in cb[1]..=cb[1] + h {
                            let on_kj =
                                k == cb[2] || k == cb[2] + h || j == cb[1] || j == cb[1] + h;
                            let step = if on_kj { 1 } else { h };
                            let mut i = cb[0];
                            while i <= cb[0] + h {
                                let idx = spec.linear([i, j, k]);
                                if grid.evaluated.get(idx) {
                                    lv.mark(l + 1, ccc, grid.values[idx], &mut touched);
                                }
                                i += step;
                            }
                        }
                    }
                }
            }
        }
        if new_known.is_empty() {
            break;
        }
        ev.eval_grid(grid, &new_known)?;
    }
    sc.list = new_known;

    // to_dense: unknown points forward-filled along x, then y, then z.
    sc.filled.clone_from(&grid.evaluated);
    let known = &mut sc.filled;
    let v = &mut grid.values;
    for k in 0..n {
        for j in 0..n {
            let row = n * (j + n * k);
            for i in 1..n {
                if !known.get(row + i) && known.get(row + i - 1) {
                    v[row + i] = v[row + i - 1];
                    known.set(row + i);
                }
            }
        }
    }
    for k in 0..n {
        for j in 1..n {
            for i in 0..n {
                let idx = i + n * (j + n * k);
                if !known.get(idx) && known.get(idx - n) {
                    v[idx] = v[idx - n];
                    known.set(idx);
                }
            }
        }
    }
    let plane = n * n;
    for k in 1..n {
        for idx in k * plane..(k + 1) * plane {
            if !known.get(idx) {
                // (0, 0, 0) is a coarse point, so the z pass always finds a known predecessor.
                debug_assert!(known.get(idx - plane));
                v[idx] = v[idx - plane];
                known.set(idx);
            }
        }
    }
    Ok(())
}
