//! The temporal filter's maps between frames: the last frame's maps resampled into this
//! frame's crop (bilinear taps, computed once per crop change and map size, into buffers
//! kept from frame to frame) and the blend.

use super::{Crop, MapLayout};

/// Whether a `size x size` map made through `from` moves by a hundredth of a map pixel or
/// more somewhere when taken into `to`'s pixels (else it is used as it is).
pub(super) fn moved(size: usize, from: Crop, to: Crop) -> bool {
    let px = 0.5 * (size - 1) as f32;
    let moved = ((to.tx - from.tx).abs() + (to.ty - from.ty).abs()) / from.s
        + 2.0 * (to.s / from.s - 1.0).abs();
    let m = moved * px;
    m >= 0.01 || m.is_nan()
}

/// A resampling of a `size x size` map from one crop's pixels into another's: bilinear
/// taps per pixel, and whether the pixel fell inside the old map.
#[derive(Default)]
pub(super) struct Taps {
    taps: Vec<([usize; 4], [f32; 4])>,
    pub(super) valid: Vec<bool>,
}

impl Taps {
    /// Set to the taps that bring a map made through `from` into the pixels of `to`; false
    /// (nothing set) when the crop moved less than a hundredth of a map pixel anywhere (a
    /// still person's filtered box): the map as it is.
    pub(super) fn set(&mut self, size: usize, from: Crop, to: Crop) -> bool {
        if !moved(size, from, to) {
            return false;
        }
        let n = size * size;
        self.taps.clear();
        self.taps.resize(n, ([0usize; 4], [0.0f32; 4]));
        self.valid.clear();
        self.valid.resize(n, false);
        let m = (size - 1) as f32;
        let ndc = |i: usize| -1.0 + 2.0 * i as f32 / m;
        for (p, (ok, tap)) in self.valid.iter_mut().zip(&mut self.taps).enumerate() {
            let (ux, uy) = (ndc(p % size), ndc(p / size));
            // This crop's NDC -> input NDC -> the last crop's NDC -> its pixels.
            let (x, y) = (to.s * ux + to.tx, to.s * uy + to.ty);
            let (px, py) = (
                ((x - from.tx) / from.s + 1.0) * 0.5 * m,
                ((y - from.ty) / from.s + 1.0) * 0.5 * m,
            );
            if !(px >= 0.0 && py >= 0.0 && px <= m && py <= m) {
                continue;
            }
            *ok = true;
            // Integer taps; the weights are the fractional parts.
            let (x0, y0) = ((px as usize).min(size - 2), (py as usize).min(size - 2));
            let (fx, fy) = (px - x0 as f32, py - y0 as f32);
            let i = y0 * size + x0;
            *tap = (
                [i, i + 1, i + size, i + size + 1],
                [
                    (1.0 - fx) * (1.0 - fy),
                    fx * (1.0 - fy),
                    (1.0 - fx) * fy,
                    fx * fy,
                ],
            );
        }
        true
    }

    /// `data` (layout `l`, made through the old crop) in the new crop's pixels, into `out`;
    /// 0 where the pixel fell outside the old map.
    pub(super) fn apply(&self, l: MapLayout, data: &[f32], out: &mut Vec<f32>) {
        let n = l.size * l.size;
        let c = l.channels;
        if l.interleaved {
            // Every value written once (no clearing pass, no read-back of a running sum):
            // the four taps' pixels blended channel by channel (vectorizes).
            out.resize(data.len(), 0.0);
            let px = |t: usize| &data[t * c..(t + 1) * c];
            for ((o, (idx, w)), ok) in out.chunks_exact_mut(c).zip(&self.taps).zip(&self.valid) {
                if !ok {
                    o.fill(0.0);
                    continue;
                }
                let [w0, w1, w2, w3] = *w;
                let (d0, d1, d2, d3) = (px(idx[0]), px(idx[1]), px(idx[2]), px(idx[3]));
                for ((((v, a), b), e), f) in o.iter_mut().zip(d0).zip(d1).zip(d2).zip(d3) {
                    *v = w0 * a + w1 * b + w2 * e + w3 * f;
                }
            }
        } else {
            out.clear();
            out.resize(data.len(), 0.0);
            for (o, d) in out.chunks_exact_mut(n).zip(data.chunks_exact(n)) {
                for (p, (idx, w)) in self.taps.iter().enumerate() {
                    if self.valid[p] {
                        o[p] = d[idx[0]] * w[0]
                            + d[idx[1]] * w[1]
                            + d[idx[2]] * w[2]
                            + d[idx[3]] * w[3];
                    }
                }
            }
        }
    }
}

/// The last map in this frame's pixels, and which pixels have a value (`None`: all): the
/// map itself when the crop did not move (`moved` false), else resampled into `spare`.
pub(super) fn resampled<'a>(
    taps: &'a Taps,
    moved: bool,
    l: MapLayout,
    last: &'a [f32],
    spare: &'a mut Vec<f32>,
) -> (&'a [f32], Option<&'a [bool]>) {
    if moved {
        taps.apply(l, last, spare);
        (spare, Some(&taps.valid))
    } else {
        (last, None)
    }
}

/// `new = old + w (new - old)` per pixel where the last map had a value.
pub(super) fn blend(
    old: &[f32],
    valid: Option<&[bool]>,
    l: MapLayout,
    new: &mut [f32],
    weights: &[f32],
) {
    let n = l.size * l.size;
    let ok = |p: usize| valid.is_none_or(|v| v[p]);
    let mix = |v: &mut f32, o: f32, w: f32| *v = o + w * (*v - o);
    if l.interleaved {
        for (p, ((np, op), &w)) in new
            .chunks_exact_mut(l.channels)
            .zip(old.chunks_exact(l.channels))
            .zip(weights)
            .enumerate()
        {
            if w < 1.0 && ok(p) {
                for (v, o) in np.iter_mut().zip(op) {
                    mix(v, *o, w);
                }
            }
        }
    } else {
        for (np, op) in new.chunks_exact_mut(n).zip(old.chunks_exact(n)) {
            for (p, ((v, o), &w)) in np.iter_mut().zip(op).zip(weights).enumerate() {
                if w < 1.0 && ok(p) {
                    mix(v, *o, w);
                }
            }
        }
    }
}
