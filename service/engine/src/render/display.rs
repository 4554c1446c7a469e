//! The frame at display resolution ([`super::Renderer::render_display`]'s rule), drawn in
//! bands of rows on up to `threads` threads: each display pixel reads only the grid and the
//! columns' hits, depths and colours, so the bands are independent and the image does not
//! depend on the thread count.
//!
//! **Antialiased edges** ([`super::Renderer::set_antialias`]): where one of a pixel's four
//! columns has no hit (the person's outline against the background), the pixel is covered
//! by the fraction [`edge_coverage`] gives: the largest blended value along its ray
//! (the one the binary rule tests against 0.5), its distance from 0.5 over the blend's
//! gradient across the image at that ray index (in display pixels), read as a signed
//! distance to the outline; the pixel's colour is composited over the background by it.
//! A pixel is covered more than half exactly where the binary rule draws it, so the outline
//! is where it was, drawn with partial pixels instead of a staircase, and a value crossing
//! 0.5 fades a pixel in or out by a fraction instead of switching it. Pixels whose four
//! columns all hit (an arm in front of the body) stay whole.

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
    /// Partial pixels along the outline (the module's doc).
    pub antialias: bool,
}

/// The fraction of a display pixel an outline covers, from the largest blended occupancy
/// `v` along its ray and the size of that value's gradient across the image, `grad`, in
/// occupancy per display pixel: `(v - 0.5) / grad` is the pixel centre's signed distance to
/// the outline (inside positive) in pixels, and a pixel-wide ramp around it gives
/// `clamp(0.5 + distance, 0, 1)`. Above one half exactly where `v` is inside
/// ([`is_inside`]), so the binary rule's outline stays where it was; a flat
/// value (`grad` ~ 0) or one that is not finite gives the binary rule's 0 or 1, and the
/// result is always finite.
pub fn edge_coverage(v: f32, grad: f32) -> f32 {
    let inside = if is_inside(v) { 1.0 } else { 0.0 };
    if !(grad > 1e-6 && grad.is_finite() && v.is_finite()) {
        return inside;
    }
    let c = (0.5 + (v - crate::grid::ISO) / grad).clamp(0.0, 1.0);
    // At exactly 0.5 the binary rule says outside: keep the halves on its side.
    if inside == 0.0 {
        c.min(0.5)
    } else {
        c.max(0.5 + f32::EPSILON)
    }
}

/// [`edge_coverage`] of a display pixel between four grid columns: `v` the largest blended
/// value along its ray, `corners` the four columns' values at that ray index (in the order
/// `(i0, j0), (i1, j0), (i0, j1), (i1, j1)`), `(fx, fy)` the pixel's fractions between them
/// and `per_px` grid columns a display pixel: the bilinear blend's gradient there, per pixel.
pub fn outline_coverage(v: f32, corners: [f32; 4], fx: f32, fy: f32, per_px: f32) -> f32 {
    let a = corners;
    let gx = (1.0 - fy) * (a[1] - a[0]) + fy * (a[3] - a[2]);
    let gy = (1.0 - fx) * (a[2] - a[0]) + fx * (a[3] - a[1]);
    edge_coverage(v, per_px * (gx * gx + gy * gy).sqrt())
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
    // Grid columns per display pixel.
    let per_px = (n - 1) as f32 / den as f32;
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
            let at = |col: usize, k: usize| grid.values[col + k * plane];
            let blend =
                |k: usize| -> f32 { cols.iter().zip(&w).map(|(&col, &wi)| wi * at(col, k)).sum() };
            // The outline: a column without a hit among the four (antialiased there).
            let edge = c.antialias && hits.iter().any(|&h| h < 0);
            let mut v_out = if top + 1 < n { blend(top + 1) } else { 0.0 };
            let mut found = None;
            let (mut v_max, mut k_max) = (f32::NEG_INFINITY, top);
            for k in (bottom..=top).rev() {
                let v_in = blend(k);
                if v_in > v_max {
                    (v_max, k_max) = (v_in, k);
                }
                if found.is_none() && is_inside(v_in) {
                    found = Some(if k + 1 < n {
                        crossing_depth(spec, k, v_in, v_out)
                    } else {
                        1.0
                    });
                    if !edge {
                        break;
                    }
                }
                v_out = v_in;
            }
            let cover = if edge {
                // The blend's gradient across the image at the largest value's ray index,
                // per display pixel (`per_px` grid columns a pixel).
                outline_coverage(v_max, cols.map(|col| at(col, k_max)), fx, fy, per_px)
            } else if found.is_some() {
                1.0
            } else {
                0.0
            };
            if cover <= 0.0 {
                continue;
            }
            // Where the binary rule draws nothing, a partial pixel sits at the depth of its
            // largest value.
            let z = found.unwrap_or_else(|| spec.coord(k_max));
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
            let rgb = acc.map(|a| a / wsum);
            if cover >= 1.0 {
                for (p, x) in px.iter_mut().zip(rgb) {
                    *p = to_u8(x);
                }
                px[3] = 255;
            } else {
                // Over the background (straight alpha): a = c + a_bg (1 - c).
                let bg = [px[0], px[1], px[2], px[3]].map(|b| b as f32 / 255.0);
                let rest = bg[3] * (1.0 - cover);
                let alpha = cover + rest;
                for (i, x) in rgb.into_iter().enumerate() {
                    px[i] = to_u8((cover * x + rest * bg[i]) / alpha);
                }
                px[3] = to_u8(alpha);
            }
            row_z[u] = z;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `edge_coverage` against its f64 reference on a lattice of values and gradients, and
    /// on what input can bring (NaN, infinities, a zero, negative or tiny gradient, values
    /// far outside [0, 1]): always finite and in [0, 1], above one half exactly where the
    /// value is inside, monotone in the value.
    #[test]
    fn edge_coverage_is_finite_and_keeps_the_binary_side() {
        let reference = |v: f64, g: f64| (0.5 + (v - 0.5) / g).clamp(0.0, 1.0);
        let specials = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -1.0,
            1e-30,
            1e-7,
            f32::MAX,
            -f32::MAX,
            0.5,
            0.5 + f32::EPSILON,
            1e30,
            -1e30,
        ];
        let grads = [0.0, 1e-3, 0.05, 0.25, 0.5, 1.0, 4.0];
        for &v in specials.iter().chain(
            (0..=200)
                .map(|i| i as f32 / 200.0)
                .collect::<Vec<_>>()
                .iter(),
        ) {
            for &g in specials.iter().chain(&grads) {
                let c = edge_coverage(v, g);
                assert!(c.is_finite() && (0.0..=1.0).contains(&c), "{v} {g}: {c}");
                assert_eq!(c > 0.5, is_inside(v), "{v} {g}: {c}");
                if v.is_finite() && g.is_finite() && g > 1e-3 {
                    let want = reference(v as f64, g as f64);
                    // The guard keeps an inside value's half above 0.5 by an ulp.
                    assert!((c as f64 - want).abs() < 1e-6, "{v} {g}: {c} vs {want}");
                }
            }
        }
        // Monotone in the value at a fixed gradient.
        for g in grads.into_iter().skip(1) {
            let cs: Vec<f32> = (0..=1000)
                .map(|i| edge_coverage(i as f32 / 1000.0, g))
                .collect();
            assert!(cs.windows(2).all(|w| w[0] <= w[1]), "{g}");
        }
    }
}
