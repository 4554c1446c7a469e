//! Pieces apart from the body: a post-pass over a localized grid that drops the inside
//! components lying farther than a gap from the largest one (the network's floaters: a rear
//! lower leg seen end-on, placed at a depth no limb reaches; docs/eval/hands.md section 21).
//!
//! Components are 26-connected sets of inside points ([`crate::grid::is_inside`]). The largest
//! is the body. Another component is kept when any of its points lies within `gap[a]` grid
//! points of a body point along every axis `a` (a box, integer), or when it holds at least
//! [`KEEP_FRACTION`] of the body's points (a second person-sized piece is not a floater). A
//! dropped component's values are set to 0 (outside); `evaluated` is left as it was.
//!
//! The mesh outputs (`volcapd`'s `/mesh.glb`, `volcap reconstruct`) run it at [`DEFAULT_GAP`],
//! and the mesh-free render on its level `L - 1` ([`crate::render::RenderOptions::drop_apart`],
//! [`Pieces::drop_apart`] at stride 2); `volcapd`'s `render.drop_apart` sets the gap for both.
//! `volcap eval --drop-apart XY,Z` measures it as a knob (the product's by default; `off`
//! keeps every piece).

use crate::grid::{Grid, GridSpec, IndexBox, is_inside};

/// A component at least this fraction of the body's points is always kept.
pub const KEEP_FRACTION: f32 = 0.25;

/// The product's gap on every axis (meshes and render), a fraction of the grid's side (about
/// 20 cm for an adult filling the frame): the 42 and 21 held-out images lose their floaters
/// and keep their hands there (docs/eval/hands.md section 21).
pub const DEFAULT_GAP: f32 = 0.1;

/// A gap as the product's settings give it (`volcapd`'s `render.drop_apart`, the tools'
/// `--drop-apart`): a fraction of the grid's side in [0, 1], where 0 turns the pass off
/// (`Ok(None)`). The error says what was given and what is accepted.
pub fn gap_setting(frac: f32) -> Result<Option<f32>, String> {
    if !(0.0..=1.0).contains(&frac) {
        return Err(format!(
            "{frac}: a fraction of the grid's side in [0, 1] (0 keeps every piece)"
        ));
    }
    Ok((frac > 0.0).then_some(frac))
}

/// `frac` of the grid's side in whole grid points.
pub fn gap_points(spec: GridSpec, frac: f32) -> usize {
    (frac.clamp(0.0, 1.0) * (spec.n() - 1) as f32).round() as usize
}

/// Words of [`Pieces::drop_apart_bits`]'s inside bits for the lattice of stride `s` of
/// `spec`'s grid: each row of `nl` points in whole 32-bit words.
pub fn lattice_words(spec: GridSpec, s: usize) -> usize {
    let nl = (spec.n() - 1) / s.max(1) + 1;
    nl.div_ceil(32) * nl * nl
}

/// What [`drop_apart`] found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PiecesStats {
    /// Inside components of the grid (26-connected).
    pub components: usize,
    /// Components dropped (set outside).
    pub dropped: usize,
    /// Inside points dropped.
    pub dropped_points: usize,
}

/// Drops the inside components of `grid` farther than `gap` grid points (per axis: a box)
/// from the largest (see the module's text). A gap of 0 keeps only the body and the large
/// components.
pub fn drop_apart(grid: &mut Grid, gap: [usize; 3]) -> PiecesStats {
    let mut b = IndexBox::EMPTY;
    let spec = grid.spec();
    for (q, &v) in grid.values.iter().enumerate() {
        if is_inside(v) {
            b.add(spec.unlinear(q));
        }
    }
    Pieces::default().drop_apart(grid, 1, b, gap)
}

/// [`drop_apart`] on a lattice of the grid, with buffers kept from call to call (the
/// renderer runs it every frame on its level `L - 1`: [`crate::render::RenderOptions`]).
///
/// It works on runs: the maximal x intervals of inside lattice points of each row (a person
/// at 129 lattice points a side is some ten thousand runs, not half a million points).
/// Runs of neighbouring rows that overlap or touch diagonally are joined (union-find), which
/// is 26-connectivity; a piece is near the body when one of its runs has a body run within
/// the gap's box (rows within `gap[1]`, `gap[2]`, x intervals within `gap[0]`).
#[derive(Default)]
pub struct Pieces {
    /// Runs in scan order (planes `k`, rows `j`, then `x`), lattice units relative to the
    /// box: `[x0, x1]` inclusive.
    runs: Vec<[u32; 2]>,
    /// Per row of the box (`j + dj * k`), its first run; one more entry at the end.
    row_start: Vec<u32>,
    parent: Vec<u32>,
    /// Per run, its component (0..components, in order of first run).
    comp: Vec<u32>,
    sizes: Vec<u64>,
    keep: Vec<bool>,
    dropped: Vec<u32>,
}

fn find(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        let up = parent[parent[a as usize] as usize];
        parent[a as usize] = up;
        a = up;
    }
    a
}

impl Pieces {
    /// Drops the pieces among the points of `grid` on the lattice of stride `s` (indices
    /// that are multiples of `s`) inside box `b`, which must hold every inside point of the
    /// lattice; `gap` counts lattice points. Components, the body and the rule are
    /// [`drop_apart`]'s, on the lattice (26-connected at stride `s`). The dropped points'
    /// values are set to 0 and their grid indices kept ([`Self::dropped`]).
    pub fn drop_apart(
        &mut self,
        grid: &mut Grid,
        s: usize,
        b: IndexBox,
        gap: [usize; 3],
    ) -> PiecesStats {
        self.dropped.clear();
        let spec = grid.spec();
        let s = s.max(1);
        if b.is_empty() {
            return PiecesStats::default();
        }
        // The lattice's points in the box, in lattice units.
        let lo: [usize; 3] = std::array::from_fn(|a| b.lo[a].div_ceil(s));
        let hi: [usize; 3] = std::array::from_fn(|a| b.hi[a].min(spec.n() - 1) / s);
        if (0..3).any(|a| lo[a] > hi[a]) {
            return PiecesStats::default();
        }
        let d: [usize; 3] = std::array::from_fn(|a| hi[a] - lo[a] + 1);
        let grid_of = |x: usize, row: usize| {
            let (j, k) = (row % d[1], row / d[1]);
            spec.linear([(lo[0] + x) * s, (lo[1] + j) * s, (lo[2] + k) * s])
        };
        let values = &grid.values;
        let stats = self.find(d, gap, |x, row| is_inside(values[grid_of(x, row)]), grid_of);
        for &g in &self.dropped {
            grid.values[g as usize] = 0.0;
        }
        stats
    }

    /// [`Self::drop_apart`] on the lattice of stride `s` of `spec`'s grid given as bits (the
    /// GPU renderer reads its level `L - 1` back so: [`lattice_words`]): lattice point
    /// `(x, j, k)` is bit `x % 32` of word `x / 32 + w (j + nl k)`, `nl` points a side, `w`
    /// words a row. Nothing is written: the dropped points' grid indices are
    /// [`Self::dropped`]. An error when the bits are not the lattice's size.
    pub fn drop_apart_bits(
        &mut self,
        spec: GridSpec,
        s: usize,
        bits: &[u32],
        gap: [usize; 3],
    ) -> Result<PiecesStats, String> {
        self.dropped.clear();
        let s = s.max(1);
        let nl = (spec.n() - 1) / s + 1;
        let w = nl.div_ceil(32);
        if bits.len() != lattice_words(spec, s) {
            return Err(format!(
                "{} words of inside bits for a lattice of {nl}^3 points ({} expected)",
                bits.len(),
                lattice_words(spec, s)
            ));
        }
        // The box of the inside points, in lattice units, from the rows that have any.
        let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
        for (row, words) in bits.chunks_exact(w).enumerate() {
            let Some(first) = words.iter().position(|&b| b != 0) else {
                continue;
            };
            let last = words.iter().rposition(|&b| b != 0).unwrap_or(first);
            let x0 = 32 * first + words[first].trailing_zeros() as usize;
            // (Bits past the row's last point, which the GPU's `pack` leaves 0, are not read.)
            let x1 = (32 * last + 31 - words[last].leading_zeros() as usize).min(nl - 1);
            if x0 >= nl {
                continue;
            }
            for (a, v) in [(0, x0), (0, x1), (1, row % nl), (2, row / nl)] {
                lo[a] = lo[a].min(v);
                hi[a] = hi[a].max(v);
            }
        }
        if lo[0] > hi[0] {
            return Ok(PiecesStats::default());
        }
        let d: [usize; 3] = std::array::from_fn(|a| hi[a] - lo[a] + 1);
        let at = |x: usize, row: usize| {
            let (j, k) = (lo[1] + row % d[1], lo[2] + row / d[1]);
            [lo[0] + x, j, k]
        };
        let inside = |x: usize, row: usize| {
            let [i, j, k] = at(x, row);
            bits[i / 32 + w * (j + nl * k)] >> (i % 32) & 1 != 0
        };
        let grid_of = |x: usize, row: usize| spec.linear(at(x, row).map(|v| v * s));
        Ok(self.find(d, gap, inside, grid_of))
    }

    /// The pass over a box of `d` lattice points whose inside points `inside(x, row)` tells
    /// (row `j + d[1] k`); the dropped points' grid indices (`grid_of`) into `self.dropped`.
    fn find(
        &mut self,
        d: [usize; 3],
        gap: [usize; 3],
        inside: impl Fn(usize, usize) -> bool,
        grid_of: impl Fn(usize, usize) -> usize,
    ) -> PiecesStats {
        self.dropped.clear();
        // The runs, row by row; each joined to the runs it touches in the rows before it
        // that neighbour it: (j - 1, k), (j - 1, k - 1), (j, k - 1), (j + 1, k - 1).
        self.runs.clear();
        self.row_start.clear();
        self.parent.clear();
        for row in 0..d[1] * d[2] {
            self.row_start.push(self.runs.len() as u32);
            let mut x = 0;
            while x < d[0] {
                if !inside(x, row) {
                    x += 1;
                    continue;
                }
                let x0 = x;
                while x + 1 < d[0] && inside(x + 1, row) {
                    x += 1;
                }
                let r = self.runs.len() as u32;
                self.runs.push([x0 as u32, x as u32]);
                self.parent.push(r);
                x += 1;
            }
        }
        self.row_start.push(self.runs.len() as u32);
        let rows_of = |row: usize| -> std::ops::Range<usize> {
            (self.row_start[row] as usize)..(self.row_start[row + 1] as usize)
        };
        let touch = |a: [u32; 2], b: [u32; 2]| a[0] <= b[1] + 1 && b[0] <= a[1] + 1;
        for row in 0..d[1] * d[2] {
            let (j, k) = (row % d[1], row / d[1]);
            let mut before = [None; 4];
            if j > 0 {
                before[0] = Some(row - 1);
            }
            if k > 0 {
                let up = row - d[1];
                before[1] = (j > 0).then(|| up - 1);
                before[2] = Some(up);
                before[3] = (j + 1 < d[1]).then_some(up + 1);
            }
            for r in rows_of(row) {
                for q_row in before.into_iter().flatten() {
                    for q in rows_of(q_row) {
                        if touch(self.runs[r], self.runs[q]) {
                            let (a, b) = (
                                find(&mut self.parent, r as u32),
                                find(&mut self.parent, q as u32),
                            );
                            // The earlier run's root stays the root (order of first run).
                            let (lo, hi) = (a.min(b), a.max(b));
                            self.parent[hi as usize] = lo;
                        }
                    }
                }
            }
        }
        // Components numbered in order of their first run, with their sizes.
        self.comp.clear();
        self.sizes.clear();
        for r in 0..self.runs.len() {
            let root = find(&mut self.parent, r as u32) as usize;
            let c = if root == r {
                self.sizes.push(0);
                self.sizes.len() as u32 - 1
            } else {
                self.comp[root]
            };
            self.comp.push(c);
            let [x0, x1] = self.runs[r];
            self.sizes[c as usize] += (x1 - x0 + 1) as u64;
        }
        let mut stats = PiecesStats {
            components: self.sizes.len(),
            ..Default::default()
        };
        // The body: the largest (the first found among equals).
        let Some(body) = (0..self.sizes.len()).rev().max_by_key(|&c| self.sizes[c]) else {
            return stats;
        };
        if self.sizes.len() < 2 {
            return stats;
        }
        let big = (self.sizes[body] as f32 * KEEP_FRACTION).ceil() as u64;
        self.keep.clear();
        self.keep.extend(
            self.sizes
                .iter()
                .enumerate()
                .map(|(c, &n)| c == body || n >= big),
        );
        // A piece is near when one of its runs has a body run in the gap's box.
        let gx = gap[0] as u32;
        for row in 0..d[1] * d[2] {
            let (j, k) = (row % d[1], row / d[1]);
            for r in rows_of(row) {
                let c = self.comp[r] as usize;
                if self.keep[c] {
                    continue;
                }
                let [x0, x1] = self.runs[r];
                let wide = [x0.saturating_sub(gx), x1 + gx];
                let near = (k.saturating_sub(gap[2])..=(k + gap[2]).min(d[2] - 1)).any(|kk| {
                    (j.saturating_sub(gap[1])..=(j + gap[1]).min(d[1] - 1)).any(|jj| {
                        rows_of(jj + d[1] * kk).any(|q| {
                            self.comp[q] as usize == body && {
                                let [q0, q1] = self.runs[q];
                                q0 <= wide[1] && wide[0] <= q1
                            }
                        })
                    })
                });
                if near {
                    self.keep[c] = true;
                }
            }
        }
        for row in 0..d[1] * d[2] {
            for r in rows_of(row) {
                if self.keep[self.comp[r] as usize] {
                    continue;
                }
                let [x0, x1] = self.runs[r];
                for x in x0..=x1 {
                    self.dropped.push(grid_of(x as usize, row) as u32);
                }
            }
        }
        stats.dropped = self.keep.iter().filter(|k| !**k).count();
        stats.dropped_points = self.dropped.len();
        stats
    }

    /// Grid indices of the points the last pass dropped ([`Self::drop_apart`] set them
    /// outside; [`Self::drop_apart_bits`] only lists them).
    pub fn dropped(&self) -> &[u32] {
        &self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{GridSpec, is_inside};

    fn cube(g: &mut Grid, lo: [usize; 3], hi: [usize; 3]) {
        let spec = g.spec();
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    g.values[spec.linear([i, j, k])] = 1.0;
                }
            }
        }
    }

    /// The body, a piece 3 points from it and a piece 10 points from it: gap 3 keeps the
    /// first and drops the second (its points set outside, the rest unchanged); gap 10 keeps
    /// both; a piece a third of the body's size is kept at any gap.
    #[test]
    fn drops_only_pieces_beyond_the_gap() {
        let spec = GridSpec::from_resolution(33).unwrap();
        let mut g = Grid::new(spec);
        cube(&mut g, [4, 4, 4], [13, 13, 13]); // body: 1000 points
        cube(&mut g, [16, 4, 4], [17, 5, 5]); // 3 points from the body along x (13 -> 16)
        cube(&mut g, [4, 23, 4], [5, 24, 5]); // 10 points from it along y (13 -> 23)
        let before = g.values.clone();
        let mut g3 = g.clone();
        let s = drop_apart(&mut g3, [3; 3]);
        assert_eq!(
            s,
            PiecesStats {
                components: 3,
                dropped: 1,
                dropped_points: 8
            }
        );
        for (i, (a, b)) in before.iter().zip(&g3.values).enumerate() {
            let idx = spec.unlinear(i);
            let far = (4..=5).contains(&idx[0])
                && (23..=24).contains(&idx[1])
                && (4..=5).contains(&idx[2]);
            assert_eq!(*b, if far { 0.0 } else { *a }, "{idx:?}");
        }
        // Gap 2: the near piece is 3 away, dropped too.
        let mut g2 = g.clone();
        assert_eq!(drop_apart(&mut g2, [2; 3]).dropped, 2);
        let mut g10 = g.clone();
        assert_eq!(drop_apart(&mut g10, [10; 3]).dropped, 0);
        assert_eq!(g10.values, before);
        // Per axis: 10 along y reaches the far piece, 2 along x drops the near one.
        let mut gxy = g.clone();
        let s = drop_apart(&mut gxy, [2, 10, 2]);
        assert_eq!((s.dropped, s.dropped_points), (1, 8));
        assert!(is_inside(gxy.values[spec.linear([4, 23, 4])]));
        assert!(!is_inside(gxy.values[spec.linear([16, 4, 4])]));
        // A large piece far away stays.
        let mut g = Grid::new(spec);
        cube(&mut g, [0, 0, 0], [9, 9, 9]);
        cube(&mut g, [20, 20, 20], [26, 26, 26]); // 343 points >= 250
        assert_eq!(drop_apart(&mut g, [1; 3]).dropped, 0);
    }

    /// Settings: 0 is off, a fraction in (0, 1] is the gap, anything else (NaN too) refused
    /// with the value.
    #[test]
    fn gap_settings() {
        assert_eq!(gap_setting(0.0), Ok(None));
        assert_eq!(gap_setting(0.1), Ok(Some(0.1)));
        assert_eq!(gap_setting(1.0), Ok(Some(1.0)));
        for bad in [-0.1, 1.5, f32::NAN] {
            assert!(
                gap_setting(bad)
                    .unwrap_err()
                    .starts_with(&format!("{bad}:"))
            );
        }
    }

    /// Diagonal neighbours are one component (26-connectivity); an empty grid and a single
    /// body are left alone; pieces at the grid's faces and corners do not index out of it.
    #[test]
    fn connectivity_and_edges() {
        assert_eq!(
            gap_points(GridSpec::from_resolution(257).unwrap(), DEFAULT_GAP),
            26
        );
        let spec = GridSpec::from_resolution(17).unwrap();
        let mut g = Grid::new(spec);
        assert_eq!(drop_apart(&mut g, [2; 3]), PiecesStats::default());
        cube(&mut g, [0, 0, 0], [5, 5, 5]);
        cube(&mut g, [6, 6, 6], [6, 6, 6]); // touches the body's corner diagonally
        assert_eq!(drop_apart(&mut g, [0; 3]).components, 1);
        cube(&mut g, [16, 16, 16], [16, 16, 16]); // the far corner
        cube(&mut g, [16, 0, 8], [16, 0, 8]);
        let s = drop_apart(&mut g, [4; 3]);
        assert_eq!((s.components, s.dropped, s.dropped_points), (3, 2, 2));
        assert!(!is_inside(g.values[spec.linear([16, 16, 16])]));
        assert!(is_inside(g.values[spec.linear([6, 6, 6])]));
    }

    /// On a lattice of stride 2 the pass equals the whole-grid pass on the grid of that
    /// lattice's points (a 33^3 grid's even points against a 17^3 grid), and leaves every
    /// point off the lattice as it was; the dropped points are reported by grid index.
    #[test]
    fn a_lattice_pass_is_the_pass_on_the_coarser_grid() {
        let (fine, coarse) = (
            GridSpec::from_resolution(33).unwrap(),
            GridSpec::from_resolution(17).unwrap(),
        );
        let mut c = Grid::new(coarse);
        cube(&mut c, [2, 2, 2], [8, 8, 8]); // body
        cube(&mut c, [10, 2, 2], [10, 3, 3]); // 2 coarse points apart
        cube(&mut c, [2, 14, 2], [3, 15, 3]); // 6 apart
        let mut f = Grid::new(fine);
        for (q, &v) in c.values.iter().enumerate() {
            let [i, j, k] = coarse.unlinear(q);
            f.values[fine.linear([2 * i, 2 * j, 2 * k])] = v;
        }
        // Off the lattice: inside points the pass must neither read nor change.
        for q in (0..fine.len()).filter(|q| fine.unlinear(*q).iter().any(|x| x % 2 == 1)) {
            f.values[q] = 0.75;
        }
        let before = f.clone();
        let want = drop_apart(&mut c, [3; 3]);
        assert_eq!(want.dropped, 1);
        let mut p = Pieces::default();
        // The box in fine indices (odd bounds: the lattice points inside it).
        let b = IndexBox {
            lo: [3, 3, 3],
            hi: [31, 31, 31],
        };
        assert_eq!(p.drop_apart(&mut f, 2, b, [3; 3]), want);
        assert_eq!(p.dropped().len(), want.dropped_points);
        for (q, (a, v)) in before.values.iter().zip(&f.values).enumerate() {
            let [i, j, k] = fine.unlinear(q);
            if [i, j, k].iter().all(|x| x % 2 == 0) {
                assert_eq!(
                    *v,
                    c.values[coarse.linear([i / 2, j / 2, k / 2])],
                    "{i} {j} {k}"
                );
                let dropped = p.dropped().contains(&(q as u32));
                assert_eq!(dropped, is_inside(*a) && !is_inside(*v), "{i} {j} {k}");
            } else {
                assert_eq!(a, v, "{i} {j} {k}");
            }
        }
        // Reused, on an empty box: nothing found, nothing reported.
        assert_eq!(
            p.drop_apart(&mut f, 2, IndexBox::EMPTY, [3; 3]),
            PiecesStats::default()
        );
        assert!(p.dropped().is_empty());
    }

    /// The grid's lattice of stride `s` as `drop_apart_bits` reads it.
    fn bits_of(g: &Grid, s: usize) -> Vec<u32> {
        let spec = g.spec();
        let nl = (spec.n() - 1) / s + 1;
        let w = nl.div_ceil(32);
        let mut bits = vec![0u32; lattice_words(spec, s)];
        for k in 0..nl {
            for j in 0..nl {
                for i in 0..nl {
                    if is_inside(g.values[spec.linear([i * s, j * s, k * s])]) {
                        bits[i / 32 + w * (j + nl * k)] |= 1 << (i % 32);
                    }
                }
            }
        }
        bits
    }

    /// The bits' pass on a lattice whose rows span several words (65 points: three words),
    /// pieces across the words' edges: what the pass on the grid drops, at its grid indices;
    /// bits of the wrong length are refused.
    #[test]
    fn the_pass_from_bits_is_the_pass_on_the_grid() {
        let spec = GridSpec::from_resolution(129).unwrap();
        let mut g = Grid::new(spec);
        cube(&mut g, [40, 40, 40], [90, 100, 70]); // body, x across words 0-2 at stride 2
        cube(&mut g, [100, 40, 40], [104, 42, 42]); // 5 lattice points apart along x
        cube(&mut g, [0, 0, 0], [66, 2, 2]); // far, x from 0 to 33 at stride 2
        cube(&mut g, [126, 126, 126], [128, 128, 128]); // the far corner
        let bits = bits_of(&g, 2);
        let b = IndexBox {
            lo: [0; 3],
            hi: [128; 3],
        };
        let mut want_p = Pieces::default();
        let want = want_p.drop_apart(&mut g, 2, b, [6; 3]);
        assert_eq!(want.dropped, 2, "{want:?}");
        let mut p = Pieces::default();
        assert_eq!(p.drop_apart_bits(spec, 2, &bits, [6; 3]), Ok(want));
        let (mut a, mut b) = (p.dropped().to_vec(), want_p.dropped().to_vec());
        a.sort_unstable();
        b.sort_unstable();
        assert!(a == b, "dropped points differ");
        // Bits past a row's last point are not read.
        let mut padded = bits.clone();
        padded[2] |= 1 << 31;
        padded[3 * 100 + 2] |= 1 << 5;
        assert_eq!(p.drop_apart_bits(spec, 2, &padded, [6; 3]), Ok(want));
        let mut c = p.dropped().to_vec();
        c.sort_unstable();
        assert!(c == b, "padding read");
        let e = p.drop_apart_bits(spec, 2, &bits[1..], [6; 3]).unwrap_err();
        assert!(
            e.contains("65^3") && e.contains(&bits.len().to_string()),
            "{e}"
        );
        // No inside point: nothing.
        let none = vec![0u32; bits.len()];
        assert_eq!(
            p.drop_apart_bits(spec, 2, &none, [6; 3]),
            Ok(PiecesStats::default())
        );
        assert!(p.dropped().is_empty());
    }

    /// On random speckled grids the run-based pass drops exactly what the definition does,
    /// computed the plain way: 26-connected components point by point
    /// (`metrics::components`), the body the largest first found, and a piece near when any
    /// of its points has a body point within the gap on every axis.
    #[test]
    fn runs_equal_the_definition_on_random_grids() {
        use rand::{Rng, SeedableRng};
        let spec = GridSpec::from_resolution(17).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut dropped_some = 0;
        for case in 0..60 {
            let mut g = Grid::new(spec);
            let density = [0.02, 0.05, 0.1][case % 3];
            for v in g.values.iter_mut() {
                *v = if rng.random::<f64>() < density {
                    1.0
                } else {
                    0.0
                };
            }
            let a = rng.random_range(2..12);
            cube(&mut g, [a, 3, 4], [a + 3, 12, 8]); // a body
            let gap = [0, 1, 2].map(|_| rng.random_range(0..5usize));
            // The definition.
            let comps = crate::metrics::components(spec, &g.binarized());
            let body = (0..comps.len())
                .rev()
                .max_by_key(|&c| comps[c].len())
                .unwrap();
            let big = (comps[body].len() as f32 * KEEP_FRACTION).ceil() as usize;
            let near = |p: u32| {
                let p = spec.unlinear(p as usize);
                comps[body].iter().any(|&q| {
                    let q = spec.unlinear(q as usize);
                    (0..3).all(|x| p[x].abs_diff(q[x]) <= gap[x])
                })
            };
            let mut want: Vec<u32> = comps
                .iter()
                .enumerate()
                .filter(|(c, comp)| {
                    *c != body && comp.len() < big && !comp.iter().any(|&p| near(p))
                })
                .flat_map(|(_, comp)| comp.iter().copied())
                .collect();
            want.sort_unstable();
            let mut p = Pieces::default();
            let all = IndexBox {
                lo: [0; 3],
                hi: [16; 3],
            };
            let bits = bits_of(&g, 1);
            let st = p.drop_apart(&mut g, 1, all, gap);
            let mut got = p.dropped().to_vec();
            got.sort_unstable();
            // The same from the grid's bits, nothing written.
            let mut pb = Pieces::default();
            assert_eq!(
                pb.drop_apart_bits(spec, 1, &bits, gap),
                Ok(st),
                "case {case}"
            );
            let mut from_bits = pb.dropped().to_vec();
            from_bits.sort_unstable();
            assert!(from_bits == got, "case {case}: the bits' pass differs");
            assert_eq!(st.components, comps.len(), "case {case}");
            assert_eq!(got, want, "case {case}, gap {gap:?}");
            assert!(got.iter().all(|&q| g.values[q as usize] == 0.0));
            dropped_some += (!got.is_empty()) as usize;
        }
        assert!(dropped_some > 10, "{dropped_some} cases dropped something");
    }
}
