//! `bench temporal`'s worst side pair, looked at closely: where on the side silhouette the
//! pixels that changed lie, and how deep the changes are.
//!
//! The side view looks along x at the crop's cube: its rows are the grid's y, its columns
//! the grid's depth k (larger k nearer the camera, the engine's convention). Along each row
//! the pixels shown in one frame of the pair only form *runs* (maximal spans of changed
//! pixels); the pixels just beyond a run are shown in both frames or in neither, so a run
//! is one of:
//! - **near edge**: shown-in-both on its far side, empty on its near side (the
//!   silhouette's edge toward the camera moved);
//! - **far edge**: empty on its far side, shown-in-both on its near side (the edge away
//!   from the camera, the one a single view sees least);
//! - **inside**: shown-in-both on both sides (a hole opened or closed);
//! - **apart**: empty on both sides (a whole span of the row came or went: a thin part's
//!   end, a piece).
//!
//! Pixels count for the part that shows them (as [`super::parts::compare_parts`]); a run's
//! depth (cells along k) counts for the part of its nearest pixel. The pair's two side
//! views are also drawn ([`draw`]).

use super::parts::{PARTS, ViewPair};
use anyhow::Context;
use std::path::Path;

/// Near edge, far edge, inside, apart.
pub(super) const CLASSES: usize = 4;
pub(super) const CLASS_NAMES: [&str; CLASSES] = ["near edge", "far edge", "inside", "apart"];

/// One part's changed pixels by class, and the runs that the part's nearest pixels start.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub(super) struct EdgeCounts {
    pub pixels: [usize; CLASSES],
    pub runs: usize,
    /// Cells of those runs, summed.
    pub run_cells: usize,
    /// The part's pixels of the first frame's outline (shown, with a 4-neighbour not shown
    /// or off the grid): how much of the outline the part has, the change's yardstick.
    pub outline: usize,
}

/// Per part, the changed side pixels of one pair by class ([`CLASSES`]). `a` and `b` are
/// side hit maps of `n` x `n` (row `j`, column `k`: index `j n + k`; hit: >= 0) with their
/// part labels (an index past [`PARTS`], or a missing label, counts nowhere).
pub(super) fn edge_split(
    a: &[i32],
    a_part: &[u8],
    b: &[i32],
    b_part: &[u8],
    n: usize,
) -> [EdgeCounts; PARTS] {
    let mut out = [EdgeCounts::default(); PARTS];
    if n == 0 || a.len() != n * n || b.len() != n * n {
        return out;
    }
    let part = |at: usize| -> Option<usize> {
        let p = if a[at] >= 0 {
            a_part.get(at)
        } else {
            b_part.get(at)
        };
        p.map(|&p| p as usize).filter(|&p| p < PARTS)
    };
    // Beyond the grid counts as empty.
    let shown_both = |at: Option<usize>| at.is_some_and(|at| a[at] >= 0 && b[at] >= 0);
    for j in 0..n {
        let row = j * n;
        let changed = |k: usize| (a[row + k] >= 0) != (b[row + k] >= 0);
        let mut k = 0;
        while k < n {
            if !changed(k) {
                k += 1;
                continue;
            }
            let start = k;
            while k < n && changed(k) {
                k += 1;
            }
            // The run is [start, k); its far side is start - 1, its near side k.
            let far = shown_both(start.checked_sub(1).map(|s| row + s));
            let near = shown_both((k < n).then_some(row + k));
            let class = match (far, near) {
                (true, false) => 0,
                (false, true) => 1,
                (true, true) => 2,
                (false, false) => 3,
            };
            for at in row + start..row + k {
                if let Some(p) = part(at) {
                    out[p].pixels[class] += 1;
                }
            }
            if let Some(p) = part(row + k - 1) {
                out[p].runs += 1;
                out[p].run_cells += k - start;
            }
        }
    }
    let shown = |j: usize, k: usize| a[j * n + k] >= 0;
    for j in 0..n {
        for k in 0..n {
            let edge = j == 0 || k == 0 || j + 1 == n || k + 1 == n || {
                !(shown(j - 1, k) && shown(j + 1, k) && shown(j, k - 1) && shown(j, k + 1))
            };
            if shown(j, k) && edge {
                let p = a_part.get(j * n + k).map(|&p| p as usize);
                if let Some(slot) = p.and_then(|p| out.get_mut(p)) {
                    slot.outline += 1;
                }
            }
        }
    }
    out
}

/// A pair's figures per part: the shares of its changed pixels by class (`None` where it
/// changed none), its runs' mean depth in cells, and its share of the first frame's outline.
pub(super) type EdgeFigures = (
    [Option<[f64; CLASSES]>; PARTS],
    [Option<f64>; PARTS],
    [Option<f64>; PARTS],
);

pub(super) fn edge_figures(counts: &[EdgeCounts; PARTS]) -> EdgeFigures {
    let shares = counts.map(|c| {
        let total: usize = c.pixels.iter().sum();
        (total > 0).then(|| c.pixels.map(|x| x as f64 / total as f64))
    });
    let depth = counts.map(|c| (c.runs > 0).then(|| c.run_cells as f64 / c.runs as f64));
    let outline: usize = counts.iter().map(|c| c.outline).sum();
    let outline = counts.map(|c| (outline > 0).then(|| c.outline as f64 / outline as f64));
    (shares, depth, outline)
}

/// [`edge_figures`] of the worst side pair (`None`: no pair, nothing), its runs' depth in
/// cm (`cm(frame)`: cm a cell along depth in the pair's first frame).
pub(super) fn pair_figures(
    pair: Option<&ViewPair>,
    n: usize,
    cm: impl Fn(usize) -> f64,
) -> EdgeFigures {
    let Some(w) = pair else {
        return ([None; PARTS], [None; PARTS], [None; PARTS]);
    };
    let (shares, cells, outline) = edge_figures(&edge_split(&w.a, &w.a_part, &w.b, &w.b_part, n));
    let per_cell = cm(w.frame);
    (shares, cells.map(|c| c.map(|c| c * per_cell)), outline)
}

/// [`draw`] of a pair to `dir/file` (the folder made first).
pub(super) fn draw_pair(dir: &Path, file: &str, pair: &ViewPair, n: usize) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
    draw(&pair.a, &pair.b, n, &dir.join(file))
}

/// A setting's label as a file name: anything but letters, digits, `.`, `-` and `_` as `_`.
pub(super) fn file_safe(label: &str) -> String {
    label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Draws a pair's hit maps (side or front views, row `j`), twice the grid's size: shown in
/// both frames grey, in the first only red, in the second only blue (a side view has the
/// camera to the right, larger k; a front view is as the camera sees it).
pub(super) fn draw(a: &[i32], b: &[i32], n: usize, path: &Path) -> anyhow::Result<()> {
    anyhow::ensure!(
        n > 0 && a.len() == n * n && b.len() == n * n,
        "side views of {} and {} pixels are not {n} x {n}",
        a.len(),
        b.len()
    );
    let side = u32::try_from(2 * n)?;
    let img = image::RgbImage::from_fn(side, side, |x, y| {
        let at = (y as usize / 2) * n + x as usize / 2;
        image::Rgb(match (a[at] >= 0, b[at] >= 0) {
            (true, true) => [150, 150, 150],
            (true, false) => [220, 30, 30],
            (false, true) => [30, 60, 230],
            (false, false) => [255, 255, 255],
        })
    });
    img.save(path)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each run's class follows from the pixels beyond it, its pixels count for the part
    /// that shows them, its depth for the part of its nearest pixel; the shares and depths
    /// follow from the counts.
    #[test]
    fn runs_are_classed_by_what_lies_beyond_them() {
        let n = 8;
        use volcap_sim::parts::Part;
        let (legs, feet) = (
            super::super::parts::index(Part::Legs),
            super::super::parts::index(Part::Feet),
        );
        let mut a = vec![-1i32; n * n];
        let mut b = vec![-1i32; n * n];
        let mut ap = vec![u8::MAX; n * n];
        let mut bp = vec![u8::MAX; n * n];
        let set = |m: &mut [i32], p: &mut [u8], j: usize, ks: std::ops::Range<usize>, part: u8| {
            for k in ks {
                m[j * n + k] = 1;
                p[j * n + k] = part;
            }
        };
        // Row 0: both show 2..6, a also 6..8 (up to the grid's end: near edge, 2 cells).
        set(&mut a, &mut ap, 0, 2..8, legs);
        set(&mut b, &mut bp, 0, 2..6, legs);
        // Row 1: both 3..7, b also 1..3 (far edge, 2 cells, b's labels).
        set(&mut a, &mut ap, 1, 3..7, legs);
        set(&mut b, &mut bp, 1, 1..7, legs);
        // Row 2: a shows 1..7, b the same but 4 (inside, 1 cell).
        set(&mut a, &mut ap, 2, 1..7, legs);
        set(&mut b, &mut bp, 2, 1..4, legs);
        set(&mut b, &mut bp, 2, 5..7, legs);
        // Row 3: only a, at 3..5, feet at 3 and legs at 4 (apart; the run's depth counts
        // for the legs, its nearest pixel's part).
        set(&mut a, &mut ap, 3, 3..4, feet);
        set(&mut a, &mut ap, 3, 4..5, legs);
        // Row 4: a 0..3 and b 3..6, both never together: one apart run of 6.
        set(&mut a, &mut ap, 4, 0..3, legs);
        set(&mut b, &mut bp, 4, 3..6, legs);
        let c = edge_split(&a, &ap, &b, &bp, n);
        let l = c[legs as usize];
        assert_eq!(l.pixels, [2, 2, 1, 1 + 6], "{l:?}");
        // a's outline: row 0 on the grid's edge (6), row 1's ends (2), row 2 but 3 and 4
        // (shown all round: 4), row 3's two (one of them feet), row 4's three (the first
        // on the grid's edge, the others with nothing above).
        assert_eq!(
            (l.outline, c[feet as usize].outline),
            (6 + 2 + 4 + 1 + 3, 1)
        );
        assert_eq!((l.runs, l.run_cells), (5, 2 + 2 + 1 + 2 + 6));
        let f = c[feet as usize];
        assert_eq!((f.pixels, f.runs, f.run_cells), ([0, 0, 0, 1], 0, 0));
        // Identical maps change nothing (the outline is a's still); maps of the wrong size
        // count nothing.
        let same = edge_split(&a, &ap, &a, &ap, n);
        for (x, y) in same.iter().zip(&c) {
            assert_eq!(
                (x.pixels, x.runs, x.run_cells, x.outline),
                ([0; CLASSES], 0, 0, y.outline)
            );
        }
        let wrong = edge_split(&a, &ap, &b[1..], &bp, n);
        assert!(wrong.iter().all(|c| *c == EdgeCounts::default()));
        let (shares, depth, outline) = edge_figures(&c);
        assert!((outline[legs as usize].unwrap() - 16.0 / 17.0).abs() < 1e-12);
        assert!((outline[feet as usize].unwrap() - 1.0 / 17.0).abs() < 1e-12);
        assert_eq!(
            edge_figures(&[EdgeCounts::default(); PARTS]).2,
            [None; PARTS]
        );
        let s = shares[legs as usize].unwrap();
        let want = [2.0 / 12.0, 2.0 / 12.0, 1.0 / 12.0, 7.0 / 12.0];
        for (x, w) in s.iter().zip(want) {
            assert!((x - w).abs() < 1e-12, "{s:?}");
        }
        assert!((depth[legs as usize].unwrap() - 13.0 / 5.0).abs() < 1e-12);
        let head = super::super::parts::index(Part::Head) as usize;
        assert_eq!((shares[head], depth[head]), (None, None));
        assert_eq!(depth[feet as usize], None);
        assert_eq!(shares[feet as usize], Some([0.0, 0.0, 0.0, 1.0]));
    }
}
