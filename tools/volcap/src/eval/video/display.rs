//! `bench temporal`'s silhouettes as the display draws them: the grid's views at display
//! resolution by the renderer's rule (`volcap_engine::render`'s `display.rs`), not one
//! pixel per grid column.
//!
//! The hit maps of the flicker figures count a column as shown or not: where a long
//! straight edge (a shin seen from the side) lies along a grid plane, a change of the field
//! too small to move the displayed edge by a fraction of a cell can turn a whole line of
//! columns at once. The display draws `size` x `size` pixels from the same grid: each pixel
//! blends its four nearest columns' values bilinearly at each point along its ray and is
//! the person where a blended value is inside, so its edge moves with the values, by
//! fractions of a cell. Consecutive frames compared this way give the flicker a viewer sees.

use volcap_engine::grid::{Grid, is_inside};
use volcap_engine::render::outline_coverage;

/// The direction a view looks along.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Along {
    /// Front: along depth k; image x = grid i, image y = grid j.
    Depth,
    /// Side: along x (i); image x = grid k, image y = grid j.
    X,
}

/// The display's axis mapping (`display.rs`): display pixel `u` of `size` between grid
/// columns `i0` and `i1` at fraction `f`.
fn axis(u: usize, n: usize, size: usize) -> (usize, usize, f32) {
    let den = size - 1;
    let num = u * (n - 1);
    let i0 = num / den;
    (i0, (i0 + 1).min(n - 1), (num % den) as f32 / den as f32)
}

/// The `size` x `size` silhouette (row-major) of `grid` looking `along`, with `hits` the
/// view's first-hit map (per column `j n + c`, `c` the image x's grid index; -1: none),
/// which bounds the search: a blended value is inside only at a ray index where one of its
/// four columns is, so never before their first hit, and never in a pixel none of them
/// hits. `size` < 2 gives an empty map.
#[cfg(test)]
pub(super) fn silhouette(grid: &Grid, hits: &[i32], along: Along, size: usize) -> Vec<bool> {
    shown(&coverage(grid, hits, along, size))
}

/// Shown by the binary rule: covered more than half.
pub(super) fn shown(cover: &[f32]) -> Vec<bool> {
    cover.iter().map(|&c| c > 0.5).collect()
}

/// [`silhouette`] with the outline antialiased as the renderer draws it
/// (`Renderer::set_antialias`, the main job's `render.antialias`): where one of a pixel's
/// four columns has no hit, its coverage is `volcap_engine::render::outline_coverage` of the
/// largest blended value along its ray and that value's gradient across the image at its
/// ray index; elsewhere 0 or 1. More than half exactly where [`silhouette`] shows the
/// person.
pub(super) fn coverage(grid: &Grid, hits: &[i32], along: Along, size: usize) -> Vec<f32> {
    let n = grid.spec().n();
    let plane = n * n;
    if size < 2 || hits.len() != plane || grid.values.len() != plane * n {
        return Vec::new();
    }
    // Grid index of (image x c, image y j, ray index r).
    let at = |c: usize, j: usize, r: usize| match along {
        Along::Depth => c + n * j + plane * r,
        Along::X => r + n * j + plane * c,
    };
    let per_px = (n - 1) as f32 / (size - 1) as f32;
    let mut out = vec![0.0; size * size];
    for v in 0..size {
        let (j0, j1, fy) = axis(v, n, size);
        for u in 0..size {
            let (c0, c1, fx) = axis(u, n, size);
            let cols = [(c0, j0), (c1, j0), (c0, j1), (c1, j1)];
            let w = [
                (1.0 - fx) * (1.0 - fy),
                fx * (1.0 - fy),
                (1.0 - fx) * fy,
                fx * fy,
            ];
            let Some(first) = cols
                .iter()
                .zip(&w)
                .filter(|(_, wi)| **wi > 0.0)
                .filter_map(|(&(c, j), _)| usize::try_from(hits[j * n + c]).ok())
                .min()
            else {
                continue;
            };
            let blend = |r: usize| -> f32 {
                cols.iter()
                    .zip(&w)
                    .map(|(&(c, j), &wi)| wi * grid.values[at(c, j, r)])
                    .sum()
            };
            let edge = cols.iter().any(|&(c, j)| hits[j * n + c] < 0);
            let (mut v_max, mut r_max) = (f32::NEG_INFINITY, first);
            for r in first..n {
                let b = blend(r);
                if b > v_max {
                    (v_max, r_max) = (b, r);
                }
                if !edge && is_inside(b) {
                    break;
                }
            }
            out[v * size + u] = if edge {
                let corners = cols.map(|(c, j)| grid.values[at(c, j, r_max)]);
                outline_coverage(v_max, corners, fx, fy, per_px)
            } else if is_inside(v_max) {
                1.0
            } else {
                0.0
            };
        }
    }
    out
}

/// The overlap of two coverage maps, the sum of the smaller over the sum of the larger (the
/// IoU of binary maps; 1 for two empty ones).
pub(super) fn soft_iou(a: &[f32], b: &[f32]) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    for (&x, &y) in a.iter().zip(b) {
        lo += x.min(y) as f64;
        hi += x.max(y) as f64;
    }
    if hi > 0.0 { lo / hi } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volcap_engine::grid::GridSpec;

    fn iou(a: &[bool], b: &[bool]) -> f64 {
        volcap_engine::metrics::mask_iou(a.iter().copied().zip(b.iter().copied()))
    }

    /// The silhouette follows the values by fractions of a cell where the hit map moves by
    /// whole columns: a slab whose edge value crosses 0.5 (0.49 -> 0.51) turns a whole column
    /// of the hit map (IoU 0.8) and one display pixel of 4 a cell (IoU 16/17). At the grid's size the
    /// silhouette is the hit map; along either axis the same rule holds (f64 reference for
    /// the edge).
    #[test]
    fn the_displayed_edge_moves_with_the_values() {
        let spec = GridSpec::from_resolution(9).unwrap();
        let n = spec.n();
        // A slab filling c <= 3 (inside 1.0), the column c = 4 at `edge`, outside beyond;
        // every ray index the same. Written for both view axes.
        let slab = |edge: f32, along: Along| {
            let mut g = Grid::new(spec);
            g.values.fill(0.0);
            for r in 0..n {
                for j in 0..n {
                    for c in 0..n {
                        let v = if c <= 3 {
                            1.0
                        } else if c == 4 {
                            edge
                        } else {
                            0.0
                        };
                        let at = match along {
                            Along::Depth => c + n * j + n * n * r,
                            Along::X => r + n * j + n * n * c,
                        };
                        g.values[at] = v;
                    }
                }
            }
            let hits: Vec<i32> = (0..n * n)
                .map(|col| {
                    if col % n <= 3 || (col % n == 4 && is_inside(edge)) {
                        0
                    } else {
                        -1
                    }
                })
                .collect();
            (g, hits)
        };
        for along in [Along::Depth, Along::X] {
            let size = 4 * (n - 1) + 1;
            let (ga, ha) = slab(0.49, along);
            let (gb, hb) = slab(0.51, along);
            // The hit maps: column 4 turns, a ninth of the shown columns.
            let hit_iou = {
                let a: Vec<bool> = ha.iter().map(|&h| h >= 0).collect();
                let b: Vec<bool> = hb.iter().map(|&h| h >= 0).collect();
                iou(&a, &b)
            };
            assert!((hit_iou - 4.0 / 5.0).abs() < 1e-12, "{hit_iou}");
            let (sa, sb) = (
                silhouette(&ga, &ha, along, size),
                silhouette(&gb, &hb, along, size),
            );
            // Along a display row the edge lies where the blend of 1 and `edge` (between
            // columns 3 and 4) or of `edge` and 0 (between 4 and 5) is 0.5.
            let edge_x = |e: f64| {
                if e > 0.5 {
                    4.0 + (e - 0.5) / e
                } else {
                    3.0 + 0.5 / (1.0 - e)
                }
            };
            for (s, e) in [(&sa, 0.49f64), (&sb, 0.51)] {
                let shown = s[..size].iter().filter(|&&x| x).count();
                // Display pixel u sits at grid x u / 4: shown while u / 4 < edge_x.
                let want = (0..size)
                    .filter(|&u| (u as f64) / 4.0 < edge_x(e) - 1e-9)
                    .count();
                assert_eq!(shown, want, "{along:?} edge {e}");
                assert!(s.chunks(size).all(|row| row == &s[..size]));
            }
            let d = iou(&sa, &sb);
            assert!(d > 0.94, "{along:?}: displayed IoU {d}, hit maps {hit_iou}");
            // Antialiased, the edge pixels fade: partial coverage, in [0, 1], and the two
            // frames overlap more than their whole pixels do.
            let (ca, cb) = (
                coverage(&ga, &ha, along, size),
                coverage(&gb, &hb, along, size),
            );
            assert!(ca.iter().chain(&cb).all(|c| (0.0..=1.0).contains(c)));
            assert!(cb.iter().any(|&c| c > 0.0 && c < 1.0), "{along:?}");
            let soft = soft_iou(&ca, &cb);
            assert!(
                soft > d && soft < 1.0,
                "{along:?}: antialiased {soft}, whole {d}"
            );
            // At the grid's size the display is the hit map.
            let hb_bits: Vec<bool> = hb.iter().map(|&h| h >= 0).collect();
            assert_eq!(silhouette(&gb, &hb, along, n), hb_bits, "{along:?}");
        }
        // Nothing hit, or a size below 2: nothing shown.
        let (g, _) = slab(0.49, Along::Depth);
        assert!(
            silhouette(&g, &vec![-1; n * n], Along::Depth, 17)
                .iter()
                .all(|x| !x)
        );
        assert!(silhouette(&g, &vec![0; n * n], Along::Depth, 1).is_empty());
        assert_eq!(iou(&[false, false], &[false, false]), 1.0);
    }
}
