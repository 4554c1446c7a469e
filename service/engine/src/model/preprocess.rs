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

/// Largest input frame side accepted anywhere (the daemon's cameras and `volcap
/// reconstruct`), pixels.
pub const MAX_FRAME_SIDE: u32 = 8192;
/// Largest input frame accepted anywhere, pixels in all (a 40 MP camera frame): one limit
/// for the daemon and `volcap reconstruct`, checked before anything is decoded.
pub const MAX_FRAME_PIXELS: u64 = 40_000_000;

/// Whether a `w` x `h` frame is within [`MAX_FRAME_SIDE`] and [`MAX_FRAME_PIXELS`]; the
/// error says which limit and what to do.
pub fn check_frame_size(w: u64, h: u64) -> Result<(), String> {
    if w == 0 || h == 0 {
        return Err(format!("empty image ({w}x{h})"));
    }
    if w > MAX_FRAME_SIDE as u64 || h > MAX_FRAME_SIDE as u64 || w * h > MAX_FRAME_PIXELS {
        return Err(format!(
            "{w}x{h} is too large (at most {MAX_FRAME_SIDE} pixels a side and {} MP); downscale it first",
            MAX_FRAME_PIXELS / 1_000_000
        ));
    }
    Ok(())
}
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
    let (scale, fw, fh, ox, oy) = letterbox_geometry(w, h);
    // A source position's two taps and weight along one axis of `len` pixels; the columns'
    // are computed once, not per row.
    let tap = |i: usize, len: usize| {
        let sv = ((i as f32 + 0.5) / scale - 0.5).clamp(0.0, (len - 1) as f32);
        let i0 = sv.floor() as usize;
        ((i0, (i0 + 1).min(len - 1)), sv - i0 as f32)
    };
    let cols: Vec<((usize, usize), f32)> = (0..fw).map(|x| tap(x, w)).collect();
    for y in 0..fh {
        let ((y0, y1), fy) = tap(y, h);
        for (x, &((x0, x1), fx)) in cols.iter().enumerate() {
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

/// Where a `w x h` frame's pixels lie in the input square, in input NDC: `[x0, x1, y0, y1]`
/// of its first and last columns' and rows' centres (the letterbox's bars beyond).
pub fn letterbox_extent(w: usize, h: usize) -> [f32; 4] {
    if w == 0 || h == 0 {
        return [-1.0, 1.0, -1.0, 1.0];
    }
    let (_, fw, fh, ox, oy) = letterbox_geometry(w, h);
    let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (INPUT_SIZE - 1) as f32;
    [ndc(ox), ndc(ox + fw - 1), ndc(oy), ndc(oy + fh - 1)]
}

/// Where a `w x h` frame lands in the input square: scale, fitted size, offset (pixels).
fn letterbox_geometry(w: usize, h: usize) -> (f32, usize, usize, usize, usize) {
    let s = INPUT_SIZE;
    let scale = (s as f32 / w as f32).min(s as f32 / h as f32);
    let (fw, fh) = (
        ((w as f32 * scale).round() as usize).clamp(1, s),
        ((h as f32 * scale).round() as usize).clamp(1, s),
    );
    (scale, fw, fh, (s - fw) / 2, (s - fh) / 2)
}

/// Whether the person of a `[S, S]` mask (> 0.5) reaches the lower edge of a letterboxed
/// `w x h` frame, i.e. a row of person pixels lies in the frame's last row of the input
/// square (padding rows below a landscape frame do not count). The frame then cuts the
/// person (an upper body at a desk, someone close to the camera); a whole body standing in
/// view ends above it. An empty mask or frame is not cut.
pub fn cut_by_frame(mask: &[f32], w: usize, h: usize) -> bool {
    let s = INPUT_SIZE;
    if w == 0 || h == 0 || mask.len() < s * s {
        return false;
    }
    let (_, _, fh, _, oy) = letterbox_geometry(w, h);
    let last = (oy + fh).saturating_sub(1).min(s - 1);
    mask[last * s..(last + 1) * s].iter().any(|&m| m > 0.5)
}

/// The close-range choice held steady over frames: a person at the frame's lower edge (feet
/// in and out of view as they walk, a hand dipping below a desk's edge) would otherwise
/// switch shape models on every other frame, a visible jump in the render. The choice
/// changes only after `frames` consecutive frames disagree with it ([`cut_by_frame`]'s
/// answer on each); a frame without a person leaves it as it is. Starts on the main model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CloseRangeSwitch {
    frames: u32,
    on: bool,
    against: u32,
}

impl CloseRangeSwitch {
    /// `frames` consecutive disagreeing frames change the choice (0 is taken as 1: follow
    /// every frame).
    pub fn new(frames: u32) -> Self {
        Self {
            frames: frames.max(1),
            on: false,
            against: 0,
        }
    }

    /// Whether the close-range model is chosen, after a frame whose person the frame
    /// `cut` (or not).
    pub fn update(&mut self, cut: bool) -> bool {
        if cut == self.on {
            self.against = 0;
        } else {
            self.against += 1;
            if self.against >= self.frames {
                self.on = cut;
                self.against = 0;
            }
        }
        self.on
    }

    /// The current choice.
    pub fn is_on(&self) -> bool {
        self.on
    }
}

/// A `[S, S]` mask of the input square back at the frame's own `w x h` (the inverse of
/// [`letterbox`], bilinear), as 0/255 (person where the mask is > 0.5).
pub fn unletterbox_mask(mask: &[f32], w: usize, h: usize) -> Vec<u8> {
    let s = INPUT_SIZE;
    let mut out = vec![0u8; w * h];
    if w == 0 || h == 0 || mask.len() < s * s {
        return out;
    }
    let (scale, fw, fh, ox, oy) = if w == s && h == s {
        (1.0, s, s, 0, 0)
    } else {
        letterbox_geometry(w, h)
    };
    let at = |x: usize, y: usize| mask[(oy + y.min(fh - 1)) * s + ox + x.min(fw - 1)];
    for y in 0..h {
        let ly = ((y as f32 + 0.5) * scale - 0.5).clamp(0.0, (fh - 1) as f32);
        let (y0, fy) = (ly.floor() as usize, ly - ly.floor());
        for x in 0..w {
            let lx = ((x as f32 + 0.5) * scale - 0.5).clamp(0.0, (fw - 1) as f32);
            let (x0, fx) = (lx.floor() as usize, lx - lx.floor());
            let v = (at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx) * (1.0 - fy)
                + (at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx) * fy;
            out[y * w + x] = if v > 0.5 { 255 } else { 0 };
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
    /// The person reaches the frame's lower edge (the frame cuts them: close-range framing,
    /// [`cut_by_frame`]). Set by `Models::prepare`, which knows the frame; `from_mask` alone
    /// cannot tell and leaves it false. `Models::encode` reads it to choose the close-range
    /// model; a caller that holds the choice over frames ([`CloseRangeSwitch`]) sets it to
    /// the switch's answer before encoding.
    pub cut_by_frame: bool,
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
            cut_by_frame: false,
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
    ///
    /// The crop is a scale and a shift, so an output pixel's source column depends on its
    /// x alone and its source row on its y alone: the taps are computed once per column and
    /// per row, then each channel's rows are blended (the same arithmetic, value for value,
    /// as taking the taps per pixel: tested against it).
    pub fn apply(&self, img: &[f32], channels: usize, size: usize) -> Vec<f32> {
        let plane = size * size;
        let mut out = vec![0.0f32; channels * plane];
        if size < 2 {
            return out;
        }
        let to_px = |n: f32| (n + 1.0) * 0.5 * (size - 1) as f32;
        let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (size - 1) as f32;
        // Integer tap and weight per column (x) and per row (y).
        let taps = |input_ndc: f32| {
            let px = to_px(input_ndc);
            let f = px.floor();
            (f as i64, px - f)
        };
        let n = size as i64;
        // Per column (and per row) its two taps' indices, clamped into the image, and
        // weights, 0 for a tap outside it (which reads as 0: the image's values are finite,
        // so the clamped pixel times 0 adds nothing, and no bounds test is left per pixel).
        let pair = |(i, w): (i64, f32)| {
            let inside = |k: i64| (0..n).contains(&k);
            let clamp = |k: i64| k.clamp(0, n - 1) as usize;
            (
                [clamp(i), clamp(i + 1)],
                [
                    if inside(i) { 1.0 - w } else { 0.0 },
                    if inside(i + 1) { w } else { 0.0 },
                ],
            )
        };
        let xs: Vec<([usize; 2], [f32; 2])> = (0..size)
            .map(|x| pair(taps(self.s * ndc(x) + self.tx)))
            .collect();
        let ys: Vec<([usize; 2], [f32; 2])> = (0..size)
            .map(|y| pair(taps(self.s * ndc(y) + self.ty)))
            .collect();
        for c in 0..channels {
            let src = &img[c * plane..(c + 1) * plane];
            let dst = &mut out[c * plane..(c + 1) * plane];
            for (drow, &([y0, y1], [wy0, wy1])) in dst.chunks_exact_mut(size).zip(&ys) {
                let (r0, r1) = (&src[y0 * size..][..size], &src[y1 * size..][..size]);
                for (o, &([x0, x1], [wx0, wx1])) in drow.iter_mut().zip(&xs) {
                    *o = (r0[x0] * wx0 + r0[x1] * wx1) * wy0 + (r1[x0] * wx0 + r1[x1] * wx1) * wy1;
                }
            }
        }
        out
    }

    /// Take a mask made on this crop (`[S, S]` in crop NDC, e.g. the segmentation of
    /// `self.apply(img)`) back into the input square: every input pixel inside the crop's
    /// square gets the larger of its value in `into` and the crop mask's bilinear value there
    /// (`sample::bilinear1`, PyTorch's `grid_sample(align_corners=True)`); pixels outside
    /// the square keep theirs. The rule `seg_masks.paste_max` repeats for training.
    ///
    /// As in [`Crop::apply`], a pixel's crop column depends on its x alone and its crop row
    /// on its y alone: the taps (`sample::taps`' rule) are computed once per column and per
    /// row and combined per pixel with the same products, value for value (tested against
    /// `bilinear1` per pixel).
    pub fn paste_max(&self, crop_mask: &[f32], size: usize, into: &mut [f32]) {
        if size < 2 || crop_mask.len() < size * size || into.len() < size * size {
            return;
        }
        let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (size - 1) as f32;
        // Per input column (row) inside the crop's square: its two crop taps and their
        // weights (1 - f, f), as `sample::taps` computes them for that coordinate.
        let axis = |shift: f32| -> Vec<Option<([usize; 2], [f32; 2])>> {
            (0..size)
                .map(|i| {
                    let u = (ndc(i) - shift) / self.s;
                    (u.abs() <= 1.0).then(|| {
                        let p = (u + 1.0) * 0.5 * (size - 1) as f32;
                        let a = (p as usize).min(size - 1);
                        let f = p - a as f32;
                        ([a, (a + 1).min(size - 1)], [1.0 - f, f])
                    })
                })
                .collect()
        };
        let (xs, ys) = (axis(self.tx), axis(self.ty));
        for (row, y) in into.chunks_exact_mut(size).zip(&ys) {
            let Some(([y0, y1], [gy, fy])) = *y else {
                continue;
            };
            let (r0, r1) = (
                &crop_mask[y0 * size..][..size],
                &crop_mask[y1 * size..][..size],
            );
            for (v, x) in row.iter_mut().zip(&xs) {
                if let Some(([x0, x1], [gx, fx])) = *x {
                    let m = r0[x0] * (gx * gy)
                        + r0[x1] * (fx * gy)
                        + r1[x0] * (gx * fy)
                        + r1[x1] * (fx * fy);
                    *v = v.max(m);
                }
            }
        }
    }
}

/// A mask region counts as a person when it covers at least this fraction of the frame
/// (0.2 %: 131 pixels at 256x256, a person about a tenth of the frame high)...
pub const MIN_PERSON_FRACTION: f32 = 0.002;
/// ...and at least this fraction of the largest region (smaller ones are fragments).
pub const MIN_PERSON_RELATIVE: f32 = 0.1;

/// The people in a `[S, S]` soft mask and the most prominent one: people are the
/// 8-connected regions of `mask > 0.5` that pass [`MIN_PERSON_FRACTION`] and
/// [`MIN_PERSON_RELATIVE`]; the most prominent is the largest region (ties: the first in
/// row-major order). Everything outside it is set to 0 in `mask`, so the crop and the
/// encoders see one person. Returns the number of people (0: nothing is kept).
pub fn keep_most_prominent(mask: &mut [f32], size: usize) -> usize {
    let n = size * size;
    let mask = &mut mask[..n];
    let mut label = vec![0u32; n];
    let mut areas: Vec<usize> = vec![0];
    let mut stack = Vec::new();
    for start in 0..n {
        if mask[start] <= 0.5 || label[start] != 0 {
            continue;
        }
        let id = areas.len() as u32;
        let mut area = 0usize;
        label[start] = id;
        stack.push(start);
        while let Some(i) = stack.pop() {
            area += 1;
            let (x, y) = ((i % size) as i64, (i / size) as i64);
            for dy in -1..=1i64 {
                for dx in -1..=1i64 {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= size as i64 || yy >= size as i64 {
                        continue;
                    }
                    let j = yy as usize * size + xx as usize;
                    if mask[j] > 0.5 && label[j] == 0 {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
        }
        areas.push(area);
    }
    let (best, &largest) =
        areas.iter().enumerate().skip(1).fold(
            (0, &0),
            |acc, (i, a)| if *a > *acc.1 { (i, a) } else { acc },
        );
    let floor = (MIN_PERSON_FRACTION * n as f32).max(MIN_PERSON_RELATIVE * largest as f32);
    let people = areas.iter().skip(1).filter(|&&a| a as f32 >= floor).count();
    for (m, &l) in mask.iter_mut().zip(&label) {
        if people == 0 || l as usize != best {
            *m = 0.0;
        }
    }
    people
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
mod tests;
