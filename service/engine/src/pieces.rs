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
//! The mesh outputs (`volcapd`'s `/mesh.glb`, `volcap reconstruct`) run it at [`MESH_GAP`];
//! the mesh-free render does not yet; `volcap eval --drop-apart XY,Z` measures it as a knob
//! (off by default there, so the figures stay the render's).

use crate::grid::{Grid, GridSpec};
use crate::metrics::components;

/// A component at least this fraction of the body's points is always kept.
pub const KEEP_FRACTION: f32 = 0.25;

/// The mesh outputs' gap on every axis, a fraction of the grid's side (about 20 cm for an
/// adult filling the frame): the 42 and 21 held-out images lose their floaters and keep their
/// hands there (docs/eval/hands.md section 21).
pub const MESH_GAP: f32 = 0.1;

/// `frac` of the grid's side in whole grid points.
pub fn gap_points(spec: GridSpec, frac: f32) -> usize {
    (frac.clamp(0.0, 1.0) * (spec.n() - 1) as f32).round() as usize
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
    let spec = grid.spec();
    let n = spec.n();
    let comps = components(spec, &grid.binarized());
    let mut stats = PiecesStats {
        components: comps.len(),
        ..Default::default()
    };
    // The body: the largest (the first found among equals).
    let Some(body) = (0..comps.len()).rev().max_by_key(|&c| comps[c].len()) else {
        return stats;
    };
    if comps.len() < 2 {
        return stats;
    }
    let big = (comps[body].len() as f32 * KEEP_FRACTION).ceil() as usize;
    // The box of every inside point, padded by the gap (nothing outside it is inside,
    // so nothing there needs the dilated body).
    let (mut lo, mut hi) = ([n; 3], [0usize; 3]);
    for &g in comps.iter().flatten() {
        let idx = spec.unlinear(g as usize);
        for a in 0..3 {
            lo[a] = lo[a].min(idx[a]);
            hi[a] = hi[a].max(idx[a]);
        }
    }
    let lo = [0, 1, 2].map(|a| lo[a].saturating_sub(gap[a]));
    let hi = [0, 1, 2].map(|a| (hi[a] + gap[a]).min(n - 1));
    let dims = [hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1];
    let at = |g: u32| {
        let [i, j, k] = spec.unlinear(g as usize);
        (i - lo[0]) + dims[0] * ((j - lo[1]) + dims[1] * (k - lo[2]))
    };
    // The body dilated by the gap, over the box (a `u8` per point).
    let mut near = vec![0u8; dims[0] * dims[1] * dims[2]];
    let mut tmp = Vec::with_capacity(near.len());
    for &g in &comps[body] {
        near[at(g)] = 1;
    }
    // The body dilated by the gap: a running-window maximum along each axis in turn.
    for axis in 0..3 {
        tmp.clear();
        tmp.extend_from_slice(&near);
        let step = [1, dims[0], dims[0] * dims[1]][axis];
        let m = dims[axis];
        let gap = gap[axis];
        for line in 0..near.len() / m {
            // The line's first point: its `axis` coordinate 0.
            let base = match axis {
                0 => line * dims[0],
                1 => (line % dims[0]) + (line / dims[0]) * dims[0] * dims[1],
                _ => line,
            };
            // Set points in the window [t - gap, t + gap].
            let mut count = 0usize;
            for t in 0..gap.min(m) {
                count += tmp[base + t * step] as usize;
            }
            for t in 0..m {
                if t + gap < m {
                    count += tmp[base + (t + gap) * step] as usize;
                }
                if t > gap {
                    count -= tmp[base + (t - gap - 1) * step] as usize;
                }
                near[base + t * step] = (count > 0) as u8;
            }
        }
    }
    for (c, comp) in comps.iter().enumerate() {
        let keep = c == body || comp.len() >= big || comp.iter().any(|&g| near[at(g)] != 0);
        if !keep {
            for &g in comp {
                grid.values[g as usize] = 0.0;
            }
            stats.dropped += 1;
            stats.dropped_points += comp.len();
        }
    }
    stats
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

    /// Diagonal neighbours are one component (26-connectivity); an empty grid and a single
    /// body are left alone; pieces at the grid's faces and corners do not index out of it.
    #[test]
    fn connectivity_and_edges() {
        assert_eq!(
            gap_points(GridSpec::from_resolution(257).unwrap(), MESH_GAP),
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
}
