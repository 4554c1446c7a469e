//! `bench temporal`'s comparisons of two frames' views, and the lag of a filtered run.

use super::{Views, mean};
use volcap_engine::model::preprocess::Crop;

/// How far the crop moved from `a` to `b`, in cells of an `n`-point grid over its cube (a
/// cell is `2 s / (n - 1)` of input NDC, `a`'s `s`): the largest of its shift across, its
/// shift down, and the move of the cube's edge by its change of scale (the edge is
/// `(n - 1) / 2` cells from the centre: `(n - 1) / 2 * |s_b / s_a - 1|`).
pub(super) fn crop_move_cells(a: &Crop, b: &Crop, n: usize) -> f64 {
    let half = (n.saturating_sub(1)) as f64 / 2.0;
    let s = f64::from(a.s);
    if s <= 0.0 {
        return f64::INFINITY;
    }
    let dx = (f64::from(b.tx) - f64::from(a.tx)).abs() / s * half;
    let dy = (f64::from(b.ty) - f64::from(a.ty)).abs() / s * half;
    let ds = (f64::from(b.s) / s - 1.0).abs() * half;
    dx.max(dy).max(ds)
}

/// IoU of two hit maps (hit: index >= 0), and the mean |change| of the hit index where both
/// hit.
pub(super) fn compare_hits(a: &[i32], b: &[i32]) -> (f64, f64) {
    let (mut inter, mut union, mut dsum) = (0usize, 0usize, 0i64);
    for (&x, &y) in a.iter().zip(b) {
        inter += (x >= 0 && y >= 0) as usize;
        union += (x >= 0 || y >= 0) as usize;
        if x >= 0 && y >= 0 {
            dsum += (x as i64 - y as i64).abs();
        }
    }
    let iou = if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    };
    let d = if inter == 0 {
        0.0
    } else {
        dsum as f64 / inter as f64
    };
    (iou, d)
}

/// The same for camera-frame rasters (depth in metres).
pub(super) fn compare_raster(a: &[Option<f32>], b: &[Option<f32>]) -> (f64, f64) {
    let (mut inter, mut union, mut dsum) = (0usize, 0usize, 0f64);
    for (x, y) in a.iter().zip(b) {
        union += (x.is_some() || y.is_some()) as usize;
        if let (Some(x), Some(y)) = (x, y) {
            inter += 1;
            dsum += (*x as f64 - *y as f64).abs();
        }
    }
    let iou = if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    };
    let d = if inter == 0 { 0.0 } else { dsum / inter as f64 };
    (iou, d)
}

/// The shift (0..=4 frames) that best lines a run's camera-frame silhouettes (front and
/// side) up with the reference's earlier ones.
pub(super) fn lag_of(per: &[Option<(Views, Views, Crop)>], reference: &[Option<&Views>]) -> usize {
    (0..=4usize)
        .map(|k| {
            let mut v = Vec::new();
            for t in 4..per.len().min(reference.len()) {
                if let (Some((m, _, _)), Some(o)) = (&per[t], reference[t - k]) {
                    let (a, _) = compare_raster(&m.cam_front, &o.cam_front);
                    let (b, _) = compare_raster(&m.cam_side, &o.cam_side);
                    v.push(0.5 * (a + b));
                }
            }
            (k, mean(&v))
        })
        .filter(|(_, v)| v.is_finite())
        .fold((0usize, f64::MIN), |best, (k, v)| {
            if v > best.1 + 1e-9 { (k, v) } else { best }
        })
        .0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shift of one cell across, down, or a scale that moves the cube's edge by a cell,
    /// reads one cell (f64 reference); no move reads 0.
    #[test]
    fn crop_moves_count_in_cells() {
        let n = 257;
        let a = Crop {
            s: 0.8,
            tx: 0.1,
            ty: -0.2,
            cut_by_frame: false,
        };
        let cell = 2.0 * 0.8 / 256.0;
        let near = |x: f64| (x - 1.0).abs() < 1e-4;
        assert!(near(crop_move_cells(
            &a,
            &Crop {
                tx: 0.1 + cell,
                ..a
            },
            n
        )));
        assert!(near(crop_move_cells(
            &a,
            &Crop {
                ty: -0.2 - cell,
                ..a
            },
            n
        )));
        assert!(near(crop_move_cells(
            &a,
            &Crop {
                s: 0.8 * (1.0 + 1.0 / 128.0),
                ..a
            },
            n
        )));
        assert_eq!(crop_move_cells(&a, &a, n), 0.0);
        let two = Crop {
            tx: 0.1 + 2.0 * cell,
            ty: -0.2 + cell,
            ..a
        };
        assert!((crop_move_cells(&a, &two, n) - 2.0).abs() < 1e-4);
    }
}
