//! Frame preprocessing, one rule shared with training (`tools/train/volcap_train/crop.py`).
//!
//! All images here are planar f32 `[C, S, S]` with `S = INPUT_SIZE`, in the engine's NDC
//! convention: pixel `i` sits at `-1 + 2 i / (S - 1)` (align_corners = True).
//!
//! * [`letterbox`]: any RGB8 frame -> the `S x S` input square (aspect kept, bilinear, black
//!   bars), RGB in [0, 1].
//! * [`Crop::from_mask`]: bounding box of mask > 0.5 in NDC, centre `t`, scale
//!   `s = max(w, h) / 2 / FILL` (at least `MIN_SCALE`); a crop NDC point `u` is input NDC
//!   `(s u_x + t_x, s u_y + t_y, s u_z)`. No person pixel: `None`.
//! * [`Crop::apply`]: the crop resampled bilinearly (zeros outside), like PyTorch's
//!   `affine_grid` + `grid_sample(align_corners=True, padding_mode="zeros")`.

use glam::Vec3;

/// Network input side in pixels.
pub const INPUT_SIZE: usize = 256;
/// Fraction of the crop the person's larger bounding-box side fills.
pub const FILL: f32 = 0.8;
/// Smallest crop scale (a tiny subject is magnified at most 8x).
pub const MIN_SCALE: f32 = 0.125;

/// Letterbox an RGB8 frame of `w x h` into `[3, S, S]` RGB in [0, 1] (bilinear, centred).
pub fn letterbox(rgb: &[u8], w: usize, h: usize) -> Vec<f32> {
    let s = INPUT_SIZE;
    let mut out = vec![0.0f32; 3 * s * s];
    if w == 0 || h == 0 || rgb.len() < w * h * 3 {
        return out;
    }
    if w == s && h == s {
        for (i, px) in rgb.chunks_exact(3).take(s * s).enumerate() {
            for c in 0..3 {
                out[c * s * s + i] = px[c] as f32 / 255.0;
            }
        }
        return out;
    }
    let scale = (s as f32 / w as f32).min(s as f32 / h as f32);
    let (fw, fh) = (
        ((w as f32 * scale).round() as usize).clamp(1, s),
        ((h as f32 * scale).round() as usize).clamp(1, s),
    );
    let (ox, oy) = ((s - fw) / 2, (s - fh) / 2);
    for y in 0..fh {
        let sy = ((y as f32 + 0.5) / scale - 0.5).clamp(0.0, (h - 1) as f32);
        let y0 = sy.floor() as usize;
        let y1 = (y0 + 1).min(h - 1);
        let fy = sy - y0 as f32;
        for x in 0..fw {
            let sx = ((x as f32 + 0.5) / scale - 0.5).clamp(0.0, (w - 1) as f32);
            let x0 = sx.floor() as usize;
            let x1 = (x0 + 1).min(w - 1);
            let fx = sx - x0 as f32;
            for c in 0..3 {
                let p = |xx: usize, yy: usize| rgb[(yy * w + xx) * 3 + c] as f32;
                let v = (p(x0, y0) * (1.0 - fx) + p(x1, y0) * fx) * (1.0 - fy)
                    + (p(x0, y1) * (1.0 - fx) + p(x1, y1) * fx) * fy;
                out[c * s * s + (oy + y) * s + ox + x] = v / 255.0;
            }
        }
    }
    out
}

/// The person crop: crop NDC `u` -> input NDC `(s u_x + tx, s u_y + ty, s u_z)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crop {
    pub s: f32,
    pub tx: f32,
    pub ty: f32,
}

impl Crop {
    /// From a `[S, S]` mask (person where > 0.5); `None` when no pixel is person.
    pub fn from_mask(mask: &[f32], size: usize) -> Option<Crop> {
        let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0usize, usize::MAX, 0usize);
        for (i, &m) in mask.iter().enumerate().take(size * size) {
            if m > 0.5 {
                let (x, y) = (i % size, i / size);
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
        if x0 == usize::MAX {
            return None;
        }
        let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (size - 1) as f32;
        let (ax, bx, ay, by) = (ndc(x0), ndc(x1), ndc(y0), ndc(y1));
        let s = ((bx - ax).max(by - ay) / 2.0 / FILL).max(MIN_SCALE);
        Some(Crop {
            s,
            tx: 0.5 * (ax + bx),
            ty: 0.5 * (ay + by),
        })
    }

    /// Crop NDC -> input NDC.
    pub fn to_input(&self, u: Vec3) -> Vec3 {
        Vec3::new(self.s * u.x + self.tx, self.s * u.y + self.ty, self.s * u.z)
    }

    /// Input NDC -> crop NDC.
    pub fn to_crop(&self, p: Vec3) -> Vec3 {
        Vec3::new(
            (p.x - self.tx) / self.s,
            (p.y - self.ty) / self.s,
            p.z / self.s,
        )
    }

    /// Resample planar `[C, S, S]` through the crop (bilinear, zeros outside).
    pub fn apply(&self, img: &[f32], channels: usize, size: usize) -> Vec<f32> {
        let plane = size * size;
        let mut out = vec![0.0f32; channels * plane];
        let to_px = |n: f32| (n + 1.0) * 0.5 * (size - 1) as f32;
        for y in 0..size {
            let uy = -1.0 + 2.0 * y as f32 / (size - 1) as f32;
            let py = to_px(self.s * uy + self.ty);
            for x in 0..size {
                let ux = -1.0 + 2.0 * x as f32 / (size - 1) as f32;
                let px = to_px(self.s * ux + self.tx);
                let (fx0, fy0) = (px.floor(), py.floor());
                let (wx, wy) = (px - fx0, py - fy0);
                let (ix, iy) = (fx0 as i64, fy0 as i64);
                for c in 0..channels {
                    let src = &img[c * plane..(c + 1) * plane];
                    let at = |xx: i64, yy: i64| -> f32 {
                        if xx < 0 || yy < 0 || xx >= size as i64 || yy >= size as i64 {
                            0.0
                        } else {
                            src[yy as usize * size + xx as usize]
                        }
                    };
                    out[c * plane + y * size + x] = (at(ix, iy) * (1.0 - wx) + at(ix + 1, iy) * wx)
                        * (1.0 - wy)
                        + (at(ix, iy + 1) * (1.0 - wx) + at(ix + 1, iy + 1) * wx) * wy;
                }
            }
        }
        out
    }
}

/// The encoders' 4-channel input from RGB `[3, S, S]` in [0, 1] and mask `[S, S]`:
/// `((rgb * 2 - 1) * mask, mask)`.
pub fn encoder_input(rgb: &[f32], mask: &[f32], size: usize) -> Vec<f32> {
    let plane = size * size;
    let mut out = vec![0.0f32; 4 * plane];
    for c in 0..3 {
        for i in 0..plane {
            out[c * plane + i] = (rgb[c * plane + i] * 2.0 - 1.0) * mask[i];
        }
    }
    out[3 * plane..].copy_from_slice(&mask[..plane]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_round_trips_points() {
        let c = Crop {
            s: 0.6,
            tx: 0.1,
            ty: -0.2,
        };
        let p = Vec3::new(0.3, -0.4, 0.25);
        assert!((c.to_input(c.to_crop(p)) - p).length() < 1e-6);
    }

    #[test]
    fn empty_mask_has_no_crop_and_full_mask_is_identity_like() {
        let s = 16;
        assert_eq!(Crop::from_mask(&vec![0.0; s * s], s), None);
        let c = Crop::from_mask(&vec![1.0; s * s], s).unwrap();
        assert!((c.s - 1.0 / FILL).abs() < 1e-6 && c.tx.abs() < 1e-6 && c.ty.abs() < 1e-6);
        // One pixel: smallest scale, centred on it.
        let mut m = vec![0.0; s * s];
        m[5 * s + 3] = 1.0;
        let c = Crop::from_mask(&m, s).unwrap();
        assert_eq!(c.s, MIN_SCALE);
        assert!((c.tx - (-1.0 + 6.0 / 15.0)).abs() < 1e-6);
    }

    #[test]
    fn identity_crop_reproduces_the_image() {
        let s = 8;
        let img: Vec<f32> = (0..s * s).map(|i| i as f32).collect();
        let c = Crop {
            s: 1.0,
            tx: 0.0,
            ty: 0.0,
        };
        let out = c.apply(&img, 1, s);
        for (a, b) in img.iter().zip(&out) {
            assert!((a - b).abs() < 1e-3, "{a} vs {b}");
        }
    }
}
