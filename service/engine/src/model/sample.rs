//! Pixel-aligned feature sampling, the same rule as PyTorch's
//! `grid_sample(mode="bilinear", padding_mode="border", align_corners=True)`:
//! NDC -1 / +1 are the centres of the first / last feature pixels (the engine's grid
//! convention, no half-pixel offset) and points outside are clamped to the border.

/// The four taps of the bilinear rule at NDC `(x, y)` on an `h x w` grid: pixel indices
/// (row-major) and weights summing to 1. Non-finite coordinates sample the centre.
#[inline]
pub fn taps(h: usize, w: usize, x: f32, y: f32) -> ([usize; 4], [f32; 4]) {
    let to_px = |n: f32, size: usize| -> f32 {
        let n = if n.is_finite() {
            n.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        (n + 1.0) * 0.5 * (size - 1) as f32
    };
    let (px, py) = (to_px(x, w), to_px(y, h));
    // Integer indices; the fractional weights only. `px, py >= 0` (clamped above), so the
    // conversion's truncation is the floor (no libm call on baseline x86-64).
    let x0 = (px as usize).min(w - 1);
    let y0 = (py as usize).min(h - 1);
    let x1 = (x0 + 1).min(w - 1);
    let y1 = (y0 + 1).min(h - 1);
    let (fx, fy) = (px - x0 as f32, py - y0 as f32);
    (
        [y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1],
        [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ],
    )
}

/// [`bilinear`] of a one-channel `[H, W]` map (the same value), inlined where a caller
/// samples it once per point (the person mask of every field evaluation).
#[inline]
pub fn bilinear1(feat: &[f32], h: usize, w: usize, x: f32, y: f32) -> f32 {
    let ([i00, i10, i01, i11], [w00, w10, w01, w11]) = taps(h, w, x, y);
    feat[i00] * w00 + feat[i10] * w10 + feat[i01] * w01 + feat[i11] * w11
}

/// Sample planar features `[C, H, W]` at NDC `(x, y)` (x right, y down) into `out[..C]`.
/// Non-finite coordinates are treated as the border's centre-most clamp (never NaN out).
pub fn bilinear(feat: &[f32], c: usize, h: usize, w: usize, x: f32, y: f32, out: &mut [f32]) {
    let ([i00, i10, i01, i11], [w00, w10, w01, w11]) = taps(h, w, x, y);
    let plane = h * w;
    for (ch, o) in out.iter_mut().enumerate().take(c) {
        let f = &feat[ch * plane..(ch + 1) * plane];
        *o = f[i00] * w00 + f[i10] * w10 + f[i01] * w01 + f[i11] * w11;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f64 reference of the same rule.
    fn reference(feat: &[f32], h: usize, w: usize, x: f64, y: f64) -> f64 {
        let px = (x.clamp(-1.0, 1.0) + 1.0) * 0.5 * (w - 1) as f64;
        let py = (y.clamp(-1.0, 1.0) + 1.0) * 0.5 * (h - 1) as f64;
        let mut acc = 0.0;
        for yy in 0..h {
            for xx in 0..w {
                let wx = (1.0 - (px - xx as f64).abs()).max(0.0);
                let wy = (1.0 - (py - yy as f64).abs()).max(0.0);
                acc += wx * wy * feat[yy * w + xx] as f64;
            }
        }
        acc
    }

    #[test]
    fn corners_are_pixel_centres_and_interior_matches_reference() {
        let (h, w) = (5, 7);
        let feat: Vec<f32> = (0..h * w).map(|i| (i as f32 * 0.37).sin()).collect();
        let mut o = [0.0f32];
        bilinear(&feat, 1, h, w, -1.0, -1.0, &mut o);
        assert_eq!(o[0], feat[0]);
        bilinear(&feat, 1, h, w, 1.0, 1.0, &mut o);
        assert_eq!(o[0], feat[h * w - 1]);
        for k in 0..200 {
            let x = -1.3 + 2.6 * ((k * 37 % 200) as f64 / 199.0);
            let y = -1.3 + 2.6 * ((k * 91 % 200) as f64 / 199.0);
            bilinear(&feat, 1, h, w, x as f32, y as f32, &mut o);
            let r = reference(&feat, h, w, x, y);
            assert_eq!(bilinear1(&feat, h, w, x as f32, y as f32), o[0]);
            assert!(
                (o[0] as f64 - r).abs() < 1e-5,
                "({x}, {y}): {} vs {r}",
                o[0]
            );
        }
    }

    #[test]
    fn non_finite_coordinates_give_finite_values() {
        let feat = vec![1.0f32; 4 * 4];
        let mut o = [0.0f32];
        for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30] {
            bilinear(&feat, 1, 4, 4, v, v, &mut o);
            assert!(o[0].is_finite());
        }
    }
}
