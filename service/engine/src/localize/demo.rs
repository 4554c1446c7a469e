//! The public MonoPort demo's "faster" mode (`Seg3dLossless._forward_faster` in the authors'
//! ImplicitSegCUDA), reproduced faithfully on our grid so it can be measured beside the
//! paper's method. What it does, per its own comment ("exchange accuracy for speed"):
//!
//! 1. Evaluate every point of the coarsest level. If no value is above 0.5 the demo returns
//!    nothing: here the grid is left all outside (every value 0) and [`run`] says so.
//! 2. For every level but the finest: the *continuous* values are trilinearly upsampled
//!    (not the binarized field); points whose upsampled *binarized* field is fractional are
//!    boundary candidates; they are dilated with a cube of 9^3 points at the first upsampled
//!    level, 7^3 at the second and 3^3 after that (at the level's stride); the dilated
//!    candidates not evaluated before are evaluated. There is no conflict loop.
//! 3. The finest level is never evaluated: its values are the previous level trilinearly
//!    upsampled.
//!
//! Differences that do not matter for what is measured: the demo samples cell centres
//! (`align_corners=False` in its `batch_eval`), we sample grid corners (the engine's one
//! convention); evaluation counts and the binarized result are defined on the same lattice.

use super::Scratch;
use super::bin;
use crate::field::{Evaluator, FieldError};
use crate::grid::{Grid, is_inside};

/// Dilation radius (in points of the level) of the demo at the `i`-th upsampled level.
pub(crate) fn dilation_radius(i: u32) -> i64 {
    match i {
        1 => 4, // 9^3
        2 => 3, // 7^3
        _ => 1, // 3^3
    }
}

/// Run the demo's faster mode from `coarse` to the grid's level. Returns `false` when the
/// coarsest level had no inside point (the demo's empty result).
pub(crate) fn run(
    ev: &mut Evaluator,
    grid: &mut Grid,
    coarse: u32,
    scratch: &mut Scratch,
) -> Result<bool, FieldError> {
    let spec = grid.spec();
    let last = spec.level();
    super::eval_level(ev, grid, coarse, &mut scratch.list)?;
    if !scratch
        .list
        .iter()
        .any(|&l| is_inside(grid.values[l as usize]))
    {
        grid.values.iter_mut().for_each(|v| *v = 0.0);
        return Ok(false);
    }
    scratch.queued.reset(spec.len());
    for &l in &scratch.list {
        scratch.queued.set(l as usize);
    }
    for l in coarse + 1..=last {
        upsample_continuous(grid, l, &mut scratch.cells);
        if l == last {
            break;
        }
        let n = spec.n() as i64;
        let s = spec.stride(l) as i64;
        let r = dilation_radius(l - coarse);
        scratch.list.clear();
        for c in &scratch.cells {
            let [ci, cj, ck] = c.map(|v| v as i64);
            for dk in -r..=r {
                let k = ck + dk * s;
                if k < 0 || k >= n {
                    continue;
                }
                for dj in -r..=r {
                    let j = cj + dj * s;
                    if j < 0 || j >= n {
                        continue;
                    }
                    for di in -r..=r {
                        let i = ci + di * s;
                        if i < 0 || i >= n {
                            continue;
                        }
                        let q = spec.linear([i as usize, j as usize, k as usize]);
                        if scratch.queued.insert(q) {
                            scratch.list.push(q as u32);
                        }
                    }
                }
            }
        }
        ev.eval_grid(grid, &scratch.list)?;
    }
    Ok(true)
}

/// Every point of level `l` that is not on level `l - 1` gets the mean of its 2, 4 or 8
/// coarse parents' values (trilinear at the midpoints, continuous values); `cells` receives
/// the points where the parents' binarized values differ (a fractional binarized upsample).
fn upsample_continuous(grid: &mut Grid, l: u32, cells: &mut Vec<[u32; 3]>) {
    let spec = grid.spec();
    let n = spec.n();
    let s = spec.stride(l);
    cells.clear();
    for k in (0..n).step_by(s) {
        let ok = (k / s) % 2 == 1;
        for j in (0..n).step_by(s) {
            let oj = (j / s) % 2 == 1;
            for i in (0..n).step_by(s) {
                let oi = (i / s) % 2 == 1;
                if !(oi || oj || ok) {
                    continue; // on the coarser lattice
                }
                let (mut sum, mut bins, mut cnt) = (0.0f32, 0.0f32, 0u32);
                for pk in if ok { [k - s, k + s] } else { [k, k] }
                    .into_iter()
                    .take(if ok { 2 } else { 1 })
                {
                    for pj in if oj { [j - s, j + s] } else { [j, j] }
                        .into_iter()
                        .take(if oj { 2 } else { 1 })
                    {
                        for pi in if oi { [i - s, i + s] } else { [i, i] }
                            .into_iter()
                            .take(if oi { 2 } else { 1 })
                        {
                            let v = grid.values[spec.linear([pi, pj, pk])];
                            sum += v;
                            bins += bin(v);
                            cnt += 1;
                        }
                    }
                }
                let c = cnt as f32;
                grid.values[spec.linear([i, j, k])] = sum / c;
                if bins > 0.0 && bins < c {
                    cells.push([i as u32, j as u32, k as u32]);
                }
            }
        }
    }
}
