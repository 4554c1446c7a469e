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
mod tests {
    use super::*;

    fn disc(mask: &mut [f32], size: usize, cx: f32, cy: f32, r: f32) {
        for y in 0..size {
            for x in 0..size {
                if (x as f32 - cx).hypot(y as f32 - cy) <= r {
                    mask[y * size + x] = 0.9;
                }
            }
        }
    }

    #[test]
    fn a_mask_goes_back_to_the_frame_it_came_from() {
        // A 400x200 frame: the letterbox is 256x128 at rows 64..192. A block of the frame
        // marked in the square must come back at its place in the frame.
        let s = INPUT_SIZE;
        let (w, h) = (400usize, 200usize);
        let mut sq = vec![0.0f32; s * s];
        // Frame pixels x 100..200, y 50..150 -> square x 64..128, y 64+32..64+96.
        for y in 96..160 {
            for x in 64..128 {
                sq[y * s + x] = 1.0;
            }
        }
        let m = unletterbox_mask(&sq, w, h);
        assert_eq!(m.len(), w * h);
        let on = |x: usize, y: usize| m[y * w + x] == 255;
        assert!(on(150, 100) && on(102, 52) && on(197, 147));
        assert!(!on(95, 100) && !on(205, 100) && !on(150, 45) && !on(150, 155));
        let count = m.iter().filter(|&&v| v == 255).count() as f64;
        assert!((count / 10_000.0 - 1.0).abs() < 0.05, "{count}");
    }

    #[test]
    fn the_largest_person_is_kept_and_people_are_counted() {
        let s = 64;
        let mut m = vec![0.0f32; s * s];
        disc(&mut m, s, 16.0, 32.0, 6.0); // 113 px: a person (>= 0.2 % of 4096 and >= 10 % of the largest)
        disc(&mut m, s, 44.0, 32.0, 12.0); // the most prominent
        m[2] = 0.9; // one stray pixel: a fragment, not a person
        let before = m.clone();
        assert_eq!(keep_most_prominent(&mut m, s), 2);
        for (i, (&a, &b)) in m.iter().zip(&before).enumerate() {
            let (x, y) = ((i % s) as f32, (i / s) as f32);
            let in_big = (x - 44.0).hypot(y - 32.0) <= 12.0;
            assert_eq!(a, if in_big { b } else { 0.0 }, "pixel {x},{y}");
        }
        let mut empty = vec![0.2f32; s * s];
        assert_eq!(keep_most_prominent(&mut empty, s), 0);
        assert!(empty.iter().all(|&v| v == 0.0));
        // A lone speck below the frame fraction is no person.
        let mut speck = vec![0.0f32; s * s];
        speck[100] = 1.0;
        assert_eq!(keep_most_prominent(&mut speck, s), 0);
    }

    #[test]
    fn cut_by_frame_is_a_person_on_the_frames_last_row() {
        let s = INPUT_SIZE;
        // A 4:3 landscape frame: letterboxed with padding rows above and below.
        let (_, _, fh, _, oy) = letterbox_geometry(640, 480);
        assert!(oy > 0 && oy + fh < s);
        let last = oy + fh - 1;
        let column = |rows: std::ops::Range<usize>| {
            let mut m = vec![0.0f32; s * s];
            for y in rows {
                for x in 100..140 {
                    m[y * s + x] = 1.0;
                }
            }
            m
        };
        // Reaching the frame's last row: cut. Ending a row above it: a whole body.
        assert!(cut_by_frame(&column(oy + 10..last + 1), 640, 480));
        assert!(!cut_by_frame(&column(oy + 10..last), 640, 480));
        // Mask values in the padding below the frame are not the frame's edge.
        let mut pad = column(oy + 10..last);
        pad[(s - 1) * s + 120] = 1.0;
        assert!(!cut_by_frame(&pad, 640, 480));
        // A portrait frame fills the square's height: its last row is the square's.
        assert!(cut_by_frame(&column(50..s), 480, 640));
        assert!(!cut_by_frame(&column(50..s - 3), 480, 640));
        // Soft values at or below 0.5 are not person; empty inputs are not cut.
        let mut soft = column(oy + 10..last);
        soft[last * s + 120] = 0.5;
        assert!(!cut_by_frame(&soft, 640, 480));
        assert!(!cut_by_frame(&vec![0.0; s * s], 640, 480));
        assert!(!cut_by_frame(&[], 640, 480));
        assert!(!cut_by_frame(&column(0..s), 0, 480));
    }

    #[test]
    fn the_close_range_choice_changes_only_after_frames_in_a_row_disagree() {
        let mut sw = CloseRangeSwitch::new(3);
        assert!(!sw.is_on());
        // Feet flickering at the frame's edge: never three cut frames in a row.
        for cut in [true, true, false, true, false, true, true, false] {
            assert!(!sw.update(cut));
        }
        // Three in a row switch on, at the third.
        assert!(!sw.update(true));
        assert!(!sw.update(true));
        assert!(sw.update(true));
        // And back only after three whole-body frames in a row.
        for cut in [false, false, true, false, false] {
            assert!(sw.update(cut));
        }
        assert!(!sw.update(false));
        // 0 and 1 follow every frame.
        for n in [0, 1] {
            let mut sw = CloseRangeSwitch::new(n);
            for cut in [true, false, false, true, true, false] {
                assert_eq!(sw.update(cut), cut);
            }
        }
    }

    #[test]
    fn crop_round_trips_points() {
        let c = Crop {
            s: 0.6,
            tx: 0.1,
            ty: -0.2,
            cut_by_frame: false,
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

    /// Crops inside, across and outside the square, and a degenerate one (scale 0).
    fn test_crops() -> Vec<Crop> {
        [
            (1.0, 0.0, 0.0),
            (0.31, 0.12, -0.27),
            (0.5, 0.9, 0.9),
            (1.7, -0.4, 0.2),
            (0.05, -1.3, 1.1),
            (2.5, 3.0, -3.0),
            (0.0, 0.0, 0.0),
        ]
        .into_iter()
        .map(|(s, tx, ty)| Crop {
            s,
            tx,
            ty,
            cut_by_frame: false,
        })
        .collect()
    }

    /// The separable resampling gives, value for value, what taking the taps per pixel
    /// gives (the rule as it was first written), for crops inside, across and outside the
    /// frame, and for a degenerate one.
    #[test]
    fn crop_resampling_equals_the_per_pixel_rule() {
        fn per_pixel(c: &Crop, img: &[f32], channels: usize, size: usize) -> Vec<f32> {
            let plane = size * size;
            let mut out = vec![0.0f32; channels * plane];
            let to_px = |n: f32| (n + 1.0) * 0.5 * (size - 1) as f32;
            for y in 0..size {
                let uy = -1.0 + 2.0 * y as f32 / (size - 1) as f32;
                let py = to_px(c.s * uy + c.ty);
                for x in 0..size {
                    let ux = -1.0 + 2.0 * x as f32 / (size - 1) as f32;
                    let px = to_px(c.s * ux + c.tx);
                    let (fx0, fy0) = (px.floor(), py.floor());
                    let (wx, wy) = (px - fx0, py - fy0);
                    let (ix, iy) = (fx0 as i64, fy0 as i64);
                    for ch in 0..channels {
                        let src = &img[ch * plane..(ch + 1) * plane];
                        let at = |xx: i64, yy: i64| -> f32 {
                            if xx < 0 || yy < 0 || xx >= size as i64 || yy >= size as i64 {
                                0.0
                            } else {
                                src[yy as usize * size + xx as usize]
                            }
                        };
                        out[ch * plane + y * size + x] =
                            (at(ix, iy) * (1.0 - wx) + at(ix + 1, iy) * wx) * (1.0 - wy)
                                + (at(ix, iy + 1) * (1.0 - wx) + at(ix + 1, iy + 1) * wx) * wy;
                    }
                }
            }
            out
        }
        let size = 37;
        let img: Vec<f32> = (0..3 * size * size)
            .map(|i| ((i * 7919) % 1000) as f32 / 999.0)
            .collect();
        for c in test_crops() {
            let (s, tx, ty) = (c.s, c.tx, c.ty);
            let got = c.apply(&img, 3, size);
            let want = per_pixel(&c, &img, 3, size);
            assert!(
                got.iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "crop {s} {tx} {ty}"
            );
        }
    }

    /// The separable paste equals, value for value, sampling the crop's mask per pixel with
    /// `bilinear1` (the rule as first written), for crops inside, across and outside the
    /// square and for a degenerate one.
    #[test]
    fn paste_max_equals_the_per_pixel_rule() {
        fn per_pixel(c: &Crop, m: &[f32], size: usize, into: &mut [f32]) {
            let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (size - 1) as f32;
            for j in 0..size {
                let uy = (ndc(j) - c.ty) / c.s;
                for i in 0..size {
                    let ux = (ndc(i) - c.tx) / c.s;
                    if uy.abs() <= 1.0 && ux.abs() <= 1.0 {
                        let v = &mut into[j * size + i];
                        *v = v.max(crate::model::sample::bilinear1(m, size, size, ux, uy));
                    }
                }
            }
        }
        let mut changed = 0;
        for size in [2, 37, 64] {
            let m: Vec<f32> = (0..size * size)
                .map(|i| ((i * 7919) % 1000) as f32 / 999.0)
                .collect();
            let base: Vec<f32> = (0..size * size)
                .map(|i| ((i * 104729) % 997) as f32 / 996.0 * 0.6)
                .collect();
            for c in test_crops() {
                let (s, tx, ty) = (c.s, c.tx, c.ty);
                let (mut got, mut want) = (base.clone(), base.clone());
                c.paste_max(&m, size, &mut got);
                per_pixel(&c, &m, size, &mut want);
                assert!(
                    got.iter()
                        .zip(&want)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "size {size} crop {s} {tx} {ty}"
                );
                changed += usize::from(got != base);
            }
        }
        // Not vacuous: most of the crops paste something.
        assert!(changed >= 10, "{changed} pastes changed the mask");
    }

    /// The letterbox with its column taps computed once equals, value for value, taking
    /// them per pixel (the rule as first written), for wide, tall and larger frames.
    #[test]
    fn letterbox_equals_the_per_pixel_rule() {
        for (w, h) in [(40usize, 23usize), (23, 40), (300, 200), (257, 256), (1, 5)] {
            let rgb: Vec<u8> = (0..w * h * 3).map(|i| ((i * 31) % 256) as u8).collect();
            let got = letterbox(&rgb, w, h);
            let s = INPUT_SIZE;
            let mut want = vec![0.0f32; 3 * s * s];
            let (scale, fw, fh, ox, oy) = letterbox_geometry(w, h);
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
                        want[c * s * s + (oy + y) * s + ox + x] = v / 255.0;
                    }
                }
            }
            assert!(
                got.iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{w}x{h}"
            );
        }
    }

    #[test]
    fn identity_crop_reproduces_the_image() {
        let s = 8;
        let img: Vec<f32> = (0..s * s).map(|i| i as f32).collect();
        let c = Crop {
            s: 1.0,
            tx: 0.0,
            ty: 0.0,
            cut_by_frame: false,
        };
        let out = c.apply(&img, 1, s);
        for (a, b) in img.iter().zip(&out) {
            assert!((a - b).abs() < 1e-3, "{a} vs {b}");
        }
    }
}
