//! Per-pixel occupancy along camera rays: the dense supervision of the Fourier occupancy head.
//!
//! Every pixel of a camera's image is a ray; in render-view NDC it is the line
//! `(x_i, y_j, z)` for `z` in [-1, 1] (larger z nearer), and in the world the straight line
//! `ndc_to_world(x_i, y_j, z)` (linear in z for both camera models). [`ray_intervals`] finds,
//! for each pixel, the z intervals where the clothed oracle is inside (`occupancy > 0.5`, the
//! same rule as the dense oracle grid): it marches the part of the ray inside the oracle's
//! voxel box at a fixed metric step and refines every transition by bisection. Open garment
//! shells are already closed by the oracle's flood fill, so intervals never end inside cloth.
//!
//! The intervals are stored compactly (CSR: `offsets[p]..offsets[p + 1]` index into `z`);
//! training turns them into Fourier coefficients in closed form after its crop
//! (`tools/train/volcap_train/fourier.py`), and [`volcap_engine::model::fourier`] holds the
//! same formula for the engine's tests.

use crate::camera::Camera;
use crate::oracle::{BrickState, Oracle};
use glam::Vec3;
use volcap_engine::model::fourier::{Basis, FourierMaps};
use volcap_engine::model::preprocess::Crop;

/// Ray intervals of one image, row-major pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct RayIntervals {
    pub width: usize,
    pub height: usize,
    /// `width * height + 1` offsets into `z`.
    pub offsets: Vec<u32>,
    /// `[z_lo, z_hi]` in render-view NDC, `z_lo < z_hi`, sorted far to near, disjoint.
    pub z: Vec<[f32; 2]>,
}

impl RayIntervals {
    /// The intervals of pixel `(i, j)`.
    pub fn pixel(&self, i: usize, j: usize) -> &[[f32; 2]] {
        let p = j * self.width + i;
        &self.z[self.offsets[p] as usize..self.offsets[p + 1] as usize]
    }

    /// The mean depth (render-view NDC z) of everything the rays hold: the sum over pixels of
    /// `int z dz` over the sum of `int dz`; `None` when no ray holds anything. The training
    /// side's `fourier.body_depth_centre` is the same mean over the crop's maps (the frame of
    /// `volcap.depth_frame = body` models).
    pub fn mean_depth(&self) -> Option<f32> {
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for [lo, hi] in &self.z {
            let (lo, hi) = (*lo as f64, *hi as f64);
            num += 0.5 * (hi * hi - lo * lo);
            den += hi - lo;
        }
        (den > 0.0).then(|| (num / den) as f32)
    }

    /// The most intervals on one ray.
    pub fn max_per_ray(&self) -> usize {
        self.offsets
            .windows(2)
            .map(|w| (w[1] - w[0]) as usize)
            .max()
            .unwrap_or(0)
    }

    /// Whether NDC depth `z` on pixel `(i, j)` is inside.
    pub fn inside(&self, i: usize, j: usize, z: f32) -> bool {
        self.pixel(i, j).iter().any(|[lo, hi]| *lo <= z && z <= *hi)
    }
}

/// The march step along rays in metres (the oracle's voxel is 5 mm by default; a structure
/// thinner than the step can be missed).
pub const DEFAULT_STEP_M: f32 = 0.002;

/// Entry/exit of a parametric line `a + t b` through an axis-aligned box, `t` clipped to
/// `[t0, t1]`; `None` if it misses.
fn clip_line(a: Vec3, b: Vec3, lo: Vec3, hi: Vec3, t0: f32, t1: f32) -> Option<(f32, f32)> {
    let (mut t0, mut t1) = (t0, t1);
    for ax in 0..3 {
        let (o, d, l, h) = (a[ax], b[ax], lo[ax], hi[ax]);
        if d.abs() < 1e-12 {
            if o < l || o > h {
                return None;
            }
            continue;
        }
        let (mut u, mut v) = ((l - o) / d, (h - o) / d);
        if u > v {
            std::mem::swap(&mut u, &mut v);
        }
        t0 = t0.max(u);
        t1 = t1.min(v);
        if t0 > t1 {
            return None;
        }
    }
    Some((t0, t1))
}

/// The inside intervals along every pixel ray of `camera`, marching `step_m` metres. A run of
/// steps through a brick of the oracle whose voxels all read as the ray's current state
/// ([`crate::oracle::Bricks`]: empty while outside, full while inside) is passed without
/// reading it: the same samples, states and bisections as [`ray_intervals_marched`], so the
/// same intervals, bit for bit (the sim's tests compare both).
pub fn ray_intervals(oracle: &Oracle, camera: &Camera, step_m: f32) -> RayIntervals {
    march(oracle, camera, step_m, true)
}

/// [`ray_intervals`] reading the oracle at every step (the reference of its tests).
pub fn ray_intervals_marched(oracle: &Oracle, camera: &Camera, step_m: f32) -> RayIntervals {
    march(oracle, camera, step_m, false)
}

fn march(oracle: &Oracle, camera: &Camera, step_m: f32, skip: bool) -> RayIntervals {
    let (w, h) = (camera.width, camera.height);
    let view = camera.projector();
    let (lo, hi) = oracle.bounds();
    let bricks = skip.then(|| oracle.bricks());
    let mut offsets = Vec::with_capacity(w * h + 1);
    let mut z = Vec::new();
    offsets.push(0u32);
    let inside = |p: Vec3| oracle.occupancy(p) > 0.5;
    let step_m = step_m.max(1e-4);
    for j in 0..h {
        let y = -1.0 + 2.0 * j as f32 / (h.max(2) - 1) as f32;
        for i in 0..w {
            let x = -1.0 + 2.0 * i as f32 / (w.max(2) - 1) as f32;
            let a = view.ndc_to_world(Vec3::new(x, y, 0.0));
            let b = view.ndc_to_world(Vec3::new(x, y, 1.0)) - a;
            if let Some((t0, t1)) = clip_line(a, b, lo, hi, -1.0, 1.0) {
                let dt = step_m / b.length().max(1e-9);
                let n = (((t1 - t0) / dt).ceil() as usize).max(1);
                let at = |t: f32| a + b * t;
                let sample = |k: usize| {
                    if k == n {
                        t1
                    } else {
                        t0 + (t1 - t0) * k as f32 / n as f32
                    }
                };
                // The line in voxel coordinates, for the bricks' exits.
                let u0 = oracle.voxel_coords(a);
                let du = oracle.voxel_coords(a + b) - u0;
                // March from far (t0) to near (t1); bisect each change of state.
                let mut prev_t = t0;
                let mut prev_in = inside(at(t0));
                let mut open = if prev_in { Some(t0) } else { None };
                let mut k = 1;
                // The line is in a mixed brick until here: no brick to pass before.
                let mut mixed_until = f32::NEG_INFINITY;
                while k <= n {
                    let t = sample(k);
                    let brick = match bricks {
                        Some(br) if t >= mixed_until => {
                            br.visit(oracle.voxel_coords(at(t)), u0, du)
                        }
                        _ => None,
                    };
                    if let Some((BrickState::Mixed, exit)) = brick {
                        mixed_until = exit;
                    }
                    let reads = if prev_in {
                        BrickState::Full
                    } else {
                        BrickState::Empty
                    };
                    if let Some((_, exit)) = brick.filter(|(s, _)| *s == reads) {
                        // Samples k..=last lie in a brick that reads `prev_in` everywhere:
                        // no change of state among them. (t grows with k.)
                        let est = (exit - t0) / (t1 - t0) * n as f32;
                        let mut last = if est.is_finite() && est > 0.0 {
                            (est as usize).clamp(k, n)
                        } else {
                            k
                        };
                        while last > k && sample(last) >= exit {
                            last -= 1;
                        }
                        while last < n && sample(last + 1) < exit {
                            last += 1;
                        }
                        if sample(last) < exit {
                            prev_t = sample(last);
                            k = last + 1;
                            continue;
                        }
                    }
                    let now_in = inside(at(t));
                    if now_in != prev_in {
                        let (mut l, mut r) = (prev_t, t);
                        for _ in 0..14 {
                            let m = 0.5 * (l + r);
                            if inside(at(m)) == prev_in {
                                l = m;
                            } else {
                                r = m;
                            }
                        }
                        let edge = 0.5 * (l + r);
                        match open.take() {
                            Some(s) => z.push([s, edge]),
                            None => open = Some(edge),
                        }
                        prev_in = now_in;
                    }
                    prev_t = t;
                    k += 1;
                }
                if let Some(s) = open {
                    z.push([s, t1]);
                }
            }
            offsets.push(z.len() as u32);
        }
    }
    RayIntervals {
        width: w,
        height: h,
        offsets,
        z,
    }
}

/// Ground-truth Fourier coefficient maps of a crop, the rule of training
/// (`volcap_train.train.fourier_items`): per input pixel, the coefficients of its intervals
/// with depth in crop units (`zeta = zeta_scale * z / s`, clipped to [-1, 1]); then resampled
/// through the crop onto a `size x size` map grid (bilinear, align_corners, zeros outside).
pub fn fourier_maps(
    rays: &RayIntervals,
    crop: &Crop,
    k: usize,
    size: usize,
    zeta_scale: f32,
) -> Option<FourierMaps> {
    basis_maps(rays, crop, Basis::Fourier, k, size, zeta_scale)
}

/// [`fourier_maps`] in `basis` (the same 2K + 1 channels).
pub fn basis_maps(
    rays: &RayIntervals,
    crop: &Crop,
    basis: Basis,
    k: usize,
    size: usize,
    zeta_scale: f32,
) -> Option<FourierMaps> {
    let (w, h) = (rays.width, rays.height);
    let c = 2 * k + 1;
    // Coefficients per input pixel (only pixels with intervals are non-zero).
    let mut per_px: Vec<Option<Vec<f64>>> = vec![None; w * h];
    for (p, slot) in per_px.iter_mut().enumerate() {
        let iv = &rays.z[rays.offsets[p] as usize..rays.offsets[p + 1] as usize];
        if iv.is_empty() {
            continue;
        }
        let zs: Vec<[f64; 2]> = iv
            .iter()
            .map(|[lo, hi]| {
                let f = |z: f32| (zeta_scale as f64 * z as f64 / crop.s as f64).clamp(-1.0, 1.0);
                [f(*lo), f(*hi)]
            })
            .collect();
        *slot = Some(basis.interval_coeffs(&zs, k));
    }
    let mut planar = vec![0.0f32; c * size * size];
    let plane = size * size;
    let to_px = |n: f32, n_px: usize| (n + 1.0) * 0.5 * (n_px - 1) as f32;
    for j in 0..size {
        let uy = -1.0 + 2.0 * j as f32 / (size - 1) as f32;
        for i in 0..size {
            let ux = -1.0 + 2.0 * i as f32 / (size - 1) as f32;
            let p = crop.to_input(Vec3::new(ux, uy, 0.0));
            let (px, py) = (to_px(p.x, w), to_px(p.y, h));
            let (x0, y0) = (px.floor(), py.floor());
            let (fx, fy) = (px - x0, py - y0);
            for (dx, dy, wt) in [
                (0, 0, (1.0 - fx) * (1.0 - fy)),
                (1, 0, fx * (1.0 - fy)),
                (0, 1, (1.0 - fx) * fy),
                (1, 1, fx * fy),
            ] {
                let (xi, yi) = (x0 as i64 + dx, y0 as i64 + dy);
                if wt == 0.0 || xi < 0 || yi < 0 || xi >= w as i64 || yi >= h as i64 {
                    continue;
                }
                if let Some(cf) = &per_px[yi as usize * w + xi as usize] {
                    for (ch, v) in cf.iter().enumerate() {
                        planar[ch * plane + j * size + i] += wt * *v as f32;
                    }
                }
            }
        }
    }
    FourierMaps::from_planar(&planar, k, size, zeta_scale).map(|m| m.with_basis(basis))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_depth_weights_each_interval_by_its_length() {
        // 2x1 pixels: [-0.5, -0.1] and [0.2, 0.4] on the first ray, nothing on the second.
        let r = RayIntervals {
            width: 2,
            height: 1,
            offsets: vec![0, 2, 2],
            z: vec![[-0.5, -0.1], [0.2, 0.4]],
        };
        let want = (0.5 * (0.01 - 0.25) + 0.5 * (0.16 - 0.04)) / (0.4 + 0.2);
        let got = r.mean_depth().unwrap() as f64;
        assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        let empty = RayIntervals {
            width: 1,
            height: 1,
            offsets: vec![0, 0],
            z: vec![],
        };
        assert_eq!(empty.mean_depth(), None);
    }

    #[test]
    fn clip_line_hits_and_misses() {
        let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
        let r = clip_line(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, lo, hi, -10.0, 10.0).unwrap();
        assert!((r.0 - 4.0).abs() < 1e-6 && (r.1 - 6.0).abs() < 1e-6);
        assert!(clip_line(Vec3::new(2.0, 0.0, 0.0), Vec3::Z, lo, hi, -10.0, 10.0).is_none());
        // Clipped by the parameter range.
        let r = clip_line(Vec3::ZERO, Vec3::Z, lo, hi, -0.5, 0.25).unwrap();
        assert_eq!(r, (-0.5, 0.25));
    }
}
