//! The frame at display resolution ([`super::Renderer::render_display`]'s rule), drawn in
//! bands of rows on up to `threads` threads: each display pixel reads only the grid and the
//! columns' hits, depths and colours, so the bands are independent and the image does not
//! depend on the thread count.

use super::columns::crossing_depth;
use super::to_u8;
use crate::grid::{Grid, is_inside};

/// What the display image is drawn from: the localized grid and, per grid column, its hit
/// (depth index, -1 for none), surface depth and colour.
pub(super) struct Columns<'a> {
    pub grid: &'a Grid,
    pub hit: &'a [i32],
    pub depth: &'a [f32],
    pub color: &'a [[f32; 3]],
}

/// Display rows per band at least: a band's work should outweigh starting its thread.
const MIN_BAND_ROWS: usize = 32;

/// Draw the `size x size` image into `rgba` and `depth` (already filled with the background
/// and -1), split into bands of rows over `threads` threads (the calling thread takes one).
pub(super) fn draw(
    c: &Columns<'_>,
    size: usize,
    threads: usize,
    rgba: &mut [u8],
    depth: &mut [f32],
) {
    let bands = threads.clamp(1, size.div_ceil(MIN_BAND_ROWS).max(1));
    let rows = size.div_ceil(bands);
    if bands == 1 {
        rows_into(c, size, 0, rgba, depth);
        return;
    }
    std::thread::scope(|s| {
        let mut parts = rgba
            .chunks_mut(rows * size * 4)
            .zip(depth.chunks_mut(rows * size))
            .enumerate();
        let first = parts.next();
        for (b, (px, z)) in parts {
            s.spawn(move || rows_into(c, size, b * rows, px, z));
        }
        if let Some((_, (px, z))) = first {
            rows_into(c, size, 0, px, z);
        }
    });
}

/// Display rows from `v0` on, as many as `rgba` holds (`size` pixels each).
fn rows_into(c: &Columns<'_>, size: usize, v0: usize, rgba: &mut [u8], depth: &mut [f32]) {
    let grid = c.grid;
    let spec = grid.spec();
    let n = spec.n();
    let plane = n * n;
    let den = size - 1;
    let spacing = spec.spacing();
    let axis = |u: usize| {
        let num = u * (n - 1);
        let i0 = num / den;
        (i0, (i0 + 1).min(n - 1), (num % den) as f32 / den as f32)
    };
    for (dv, (row_px, row_z)) in rgba
        .chunks_exact_mut(size * 4)
        .zip(depth.chunks_exact_mut(size))
        .enumerate()
    {
        let (j0, j1, fy) = axis(v0 + dv);
        for u in 0..size {
            let (i0, i1, fx) = axis(u);
            let cols = [i0 + n * j0, i1 + n * j0, i0 + n * j1, i1 + n * j1];
            let w = [
                (1.0 - fx) * (1.0 - fy),
                fx * (1.0 - fy),
                (1.0 - fx) * fy,
                fx * fy,
            ];
            let hits = cols.map(|col| c.hit[col]);
            let Some(&hmax) = hits.iter().max().filter(|h| **h >= 0) else {
                continue;
            };
            let hmin = hits
                .iter()
                .copied()
                .filter(|&h| h >= 0)
                .min()
                .unwrap_or(hmax);
            let top = (hmax as usize + 1).min(n - 1);
            let bottom = (hmin as usize).saturating_sub(1);
            let blend = |k: usize| -> f32 {
                cols.iter()
                    .zip(&w)
                    .map(|(&col, &wi)| wi * grid.values[col + k * plane])
                    .sum()
            };
            let mut v_out = if top + 1 < n { blend(top + 1) } else { 0.0 };
            let mut found = None;
            for k in (bottom..=top).rev() {
                let v_in = blend(k);
                if is_inside(v_in) {
                    found = Some(if k + 1 < n {
                        crossing_depth(spec, k, v_in, v_out)
                    } else {
                        1.0
                    });
                    break;
                }
                v_out = v_in;
            }
            let Some(z) = found else { continue };
            let mut acc = [0.0f32; 3];
            let mut wsum = 0.0f32;
            for near_only in [true, false] {
                for ((&col, &wi), &h) in cols.iter().zip(&w).zip(&hits) {
                    if h < 0 || wi <= 0.0 || (near_only && (c.depth[col] - z).abs() > 2.0 * spacing)
                    {
                        continue;
                    }
                    for (a, x) in acc.iter_mut().zip(c.color[col]) {
                        *a += wi * x;
                    }
                    wsum += wi;
                }
                if wsum > 0.0 {
                    break;
                }
            }
            if wsum <= 0.0 {
                continue;
            }
            let px = &mut row_px[u * 4..u * 4 + 4];
            for (p, a) in px.iter_mut().zip(acc) {
                *p = to_u8(a / wsum);
            }
            px[3] = 255;
            row_z[u] = z;
        }
    }
}
