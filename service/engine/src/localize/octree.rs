//! PIFu's threshold octree (`eval_grid_octree` in PIFu's `sdf.py`): evaluate the coarsest
//! level, then for each cell whose corners' `max - min` is below the threshold fill the
//! cell with `(max + min) / 2`; otherwise subdivide and evaluate the new points that were
//! neither evaluated nor filled. One difference, on purpose: PIFu's half-open slice also
//! overwrote the cell's own evaluated min corner with the fill value; we keep evaluated
//! values and fill only points that have no value yet.

use super::{Scratch, eval_level};
use crate::field::{Evaluator, FieldError};
use crate::grid::Grid;

pub(crate) fn run(
    ev: &mut Evaluator,
    grid: &mut Grid,
    coarse: u32,
    threshold: f32,
    sc: &mut Scratch,
) -> Result<(), FieldError> {
    let spec = grid.spec();
    let n = spec.n();
    let big_l = spec.level();
    sc.filled.reset(spec.len());
    sc.queued.reset(spec.len());
    eval_level(ev, grid, coarse, &mut sc.list)?;
    // All cells of the coarsest level, by min corner.
    let s0 = spec.stride(coarse);
    sc.cells.clear();
    for k in (0..n - 1).step_by(s0) {
        for j in (0..n - 1).step_by(s0) {
            for i in (0..n - 1).step_by(s0) {
                sc.cells.push([i as u32, j as u32, k as u32]);
            }
        }
    }
    for l in coarse..big_l {
        let s = spec.stride(l);
        let h = s / 2;
        sc.list.clear();
        sc.next_cells.clear();
        for &[ci, cj, ck] in &sc.cells {
            let (ci, cj, ck) = (ci as usize, cj as usize, ck as usize);
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for c in 0..8 {
                let v = grid.values
                    [spec.linear([ci + s * (c & 1), cj + s * ((c >> 1) & 1), ck + s * (c >> 2)])];
                lo = lo.min(v);
                hi = hi.max(v);
            }
            if hi - lo < threshold {
                let fill = 0.5 * (hi + lo);
                for k in ck..=ck + s {
                    for j in cj..=cj + s {
                        let row = spec.linear([0, j, k]);
                        for i in ci..=ci + s {
                            let idx = row + i;
                            if !grid.evaluated.get(idx) && sc.filled.insert(idx) {
                                grid.values[idx] = fill;
                            }
                        }
                    }
                }
            } else {
                for c in 0..8 {
                    sc.next_cells.push([
                        (ci + h * (c & 1)) as u32,
                        (cj + h * ((c >> 1) & 1)) as u32,
                        (ck + h * (c >> 2)) as u32,
                    ]);
                }
                for dk in 0..3 {
                    for dj in 0..3 {
                        for di in 0..3 {
                            let idx = spec.linear([ci + h * di, cj + h * dj, ck + h * dk]);
                            if !grid.evaluated.get(idx) && sc.queued.insert(idx) {
                                sc.list.push(idx as u32);
                            }
                        }
                    }
                }
            }
        }
        // As in PIFu, points filled by any cell of this pass are not evaluated.
        sc.list.retain(|&i| !sc.filled.get(i as usize));
        ev.eval_grid(grid, &sc.list)?;
        std::mem::swap(&mut sc.cells, &mut sc.next_cells);
    }
    Ok(())
}
