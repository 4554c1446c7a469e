//! The renderer's columns: each pixel's first inside node from the front (a full scan of a
//! box, and the update after some nodes were evaluated) and the surface's depth between the
//! hit node and the node in front of it.

use crate::grid::{Grid, GridSpec, IndexBox, is_inside};

/// Per-column first inside node from the front, or -1, given a box `b` that holds every
/// inside node and per row `j + n k` an x extent `rows` holding the row's inside nodes
/// ([`crate::localize::Hierarchical`]'s row extents). Scans the box's planes front to back,
/// each row over its extent only (most of the box's rows are empty or short), so memory is
/// read in order.
pub(super) fn first_hits(grid: &Grid, b: IndexBox, rows: &[[u32; 2]], out: &mut Vec<i32>) {
    let n = grid.spec().n();
    let plane = n * n;
    out.clear();
    out.resize(plane, -1);
    if b.is_empty() {
        return;
    }
    for k in (b.lo[2]..=b.hi[2]).rev() {
        let base = k * plane;
        let kk = k as i32;
        for j in b.lo[1]..=b.hi[1] {
            let [lo, hi] = rows[j + n * k];
            let (lo, hi) = ((lo as usize).max(b.lo[0]), (hi as usize).min(b.hi[0]));
            if lo > hi {
                continue;
            }
            let r = j * n;
            let (lo, hi) = (r + lo, r + hi);
            let values = &grid.values[base + lo..=base + hi];
            // Branch-free (vectorizes).
            for (h, &v) in out[lo..=hi].iter_mut().zip(values) {
                let hit = (*h < 0) & is_inside(v);
                *h = if hit { kk } else { *h };
            }
        }
    }
}

/// Update first hits after the nodes `evaluated` got their values (nothing else changed):
/// an inside node above a column's hit becomes its hit; a hit node that evaluated outside is
/// refuted and that column is scanned down from it. Equal to [`first_hits`] on the new grid,
/// at the cost of the evaluated nodes instead of the whole volume.
pub(super) fn update_hits(grid: &Grid, hits: &mut [i32], evaluated: &[u32]) {
    let n = grid.spec().n();
    let plane = n * n;
    let v = &grid.values;
    for &q in evaluated {
        let (c, k) = col_k(q, plane);
        if k > hits[c] && is_inside(v[q as usize]) {
            hits[c] = k;
        }
    }
    for &q in evaluated {
        let (c, k) = col_k(q, plane);
        if hits[c] == k && !is_inside(v[q as usize]) {
            let mut kk = k - 1;
            while kk >= 0 && !is_inside(v[c + kk as usize * plane]) {
                kk -= 1;
            }
            hits[c] = kk.max(-1);
        }
    }
}

/// Column (pixel, `i + n j`) and depth index `k` of the linear grid index `q` of a grid with
/// `plane = n * n` (one u32 division: every grid index fits in u32).
#[inline]
pub(super) fn col_k(q: u32, plane: usize) -> (usize, i32) {
    let p = plane as u32;
    let k = q / p;
    ((q - k * p) as usize, k as i32)
}

/// Depth of the 0.5 crossing between node `k` (inside, `v_in`) and node `k + 1` (outside,
/// `v_out`), linear in the field; the middle where the two are equal.
pub(super) fn crossing_depth(spec: GridSpec, k: usize, v_in: f32, v_out: f32) -> f32 {
    let d = v_in - v_out;
    let t = if d > 1e-12 {
        ((v_in - 0.5) / d).clamp(0.0, 1.0)
    } else {
        0.5
    };
    let (z0, z1) = (spec.coord(k), spec.coord(k + 1));
    z0 + (z1 - z0) * t
}
