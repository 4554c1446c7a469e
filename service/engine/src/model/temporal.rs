//! A steady live render: the person's mask, crop and the networks' maps held still while the
//! person is still, and let go as soon as they move.
//!
//! Every frame of a live camera is reconstructed from scratch, so sensor noise in the mask's
//! edge, the crop box and the encoder's maps reaches the screen as flicker (hands and the
//! arm's outline appear and vanish). Three filters, in the order a frame meets them, all in
//! the camera's frame (nothing here depends on the render view, so turning the view needs no
//! reset):
//!
//! 1. **Mask hysteresis** ([`Temporal::steady_input`]): where the person does not move, a
//!    pixel of the letterboxed soft mask turns person only above `mask_high` and stops
//!    being one only below `mask_low`; while the new value is inside the band on the other
//!    side of 0.5, the pixel keeps the value it had. Where the person moves (a
//!    [`MOTION_BLOCK`]^2 block, or one beside it, with more than `mask_motion` of its pixels
//!    changed side since the last frame: sensor noise flips scattered pixels along the
//!    outline, a raised arm a band of them) the mask follows the segmenter at once. A
//!    pixel the segmenter keeps on the other side for `mask_hold_frames` frames in a row is
//!    followed too: tremor flips back and forth, a slow real change stays. While the crop
//!    given out stays put (the person still as a whole: the crop's play holds it), that is
//!    `mask_still_hold_frames` instead: a still person's tremor is held longer. Where the person
//!    does not move, a pixel that stays on its side within `mask_dead_band` of the value
//!    given out last is given that value again: the mask's 0.5 contour gates the field, so
//!    the outline does not slide with sensor noise.
//! 2. **Crop** (same call): the segmenter's crop box goes through a One Euro filter (Casiez
//!    et al., CHI 2012) on its centre and scale: a low cutoff while the box is still, opened
//!    by its speed, so a walking person is followed without lag. (A box from the held mask
//!    would trail a raised hand's tip and shrink the whole reconstruction with it.)
//! 3. **Maps** ([`Temporal::steady_maps`]): the shape maps (Fourier coefficients or MLP
//!    features) and the colour features are blended with the last frame's, per map pixel,
//!    after undoing the crop change (the last maps are resampled into this frame's crop).
//!    Each pixel's blend weight is a One Euro weight from its own rate of change, each
//!    value's rate low-passed (`map_change_cutoff_hz`) as in the One Euro filter's
//!    derivative: a pixel whose maps move (a raised arm) keeps the sign of its change and
//!    opens the filter within a frame or two; a pixel that only trembles changes sign from
//!    frame to frame, its rate averages out and it is averaged over frames.
//!
//! The state resets on a new person (the steady and the new mask overlap less than
//! `same_person_iou`), a change in the people count, a close-range model switch, a gap in
//! time (a camera reconnect, a pause) or a frame without a person. Every output is finite
//! whatever the input (non-finite inputs reset the state and pass through as they came).

use super::all_finite;
use super::preprocess::Crop;

/// Side of the mask's motion blocks, pixels ([`TemporalSettings::mask_motion`]).
pub const MOTION_BLOCK: usize = 16;

/// Per [`MOTION_BLOCK`]^2 block of a `size x size` mask (row-major, `ceil(size / B)` a
/// side): whether more than `fraction` of its pixels, or of a neighbouring block's, changed
/// side of 0.5 between `last` and `now`. A `last` of another length: everything moves.
fn moving_blocks(now: &[f32], last: &[f32], size: usize, fraction: f32) -> Vec<bool> {
    let nb = size.div_ceil(MOTION_BLOCK);
    if last.len() != now.len() || now.len() < size * size {
        return vec![true; nb * nb];
    }
    let mut flips = vec![0usize; nb * nb];
    for (p, (a, b)) in now.iter().zip(last).enumerate().take(size * size) {
        if (*a > 0.5) != (*b > 0.5) {
            flips[(p / size / MOTION_BLOCK) * nb + (p % size) / MOTION_BLOCK] += 1;
        }
    }
    let limit = fraction * (MOTION_BLOCK * MOTION_BLOCK) as f32;
    let mut out = vec![false; nb * nb];
    for by in 0..nb {
        for bx in 0..nb {
            let (y0, y1) = (by.saturating_sub(1), (by + 1).min(nb - 1));
            let (x0, x1) = (bx.saturating_sub(1), (bx + 1).min(nb - 1));
            out[by * nb + bx] =
                (y0..=y1).any(|y| (x0..=x1).any(|x| flips[y * nb + x] as f32 > limit));
        }
    }
    out
}

/// The One Euro weight of a first-order low-pass at `cutoff_hz` over a step of `dt` seconds.
fn one_euro_alpha(cutoff_hz: f32, dt: f32) -> f32 {
    let tau = 1.0 / (2.0 * std::f32::consts::PI * cutoff_hz);
    (1.0 / (1.0 + tau / dt)).clamp(0.0, 1.0)
}

/// The crop `held` moved only as far as `to` pulls it beyond `play` times `to`'s half-side
/// (`s`), each of `tx`, `ty` and `s` on its own: within the play nothing moves; beyond it
/// the crop trails `to` by the play. `to`'s `cut_by_frame` is kept.
pub fn backlash(held: Crop, to: Crop, play: f32) -> Crop {
    let band = (play * to.s.abs()).max(0.0);
    let follow = |h: f32, x: f32| {
        if h.is_finite() && band.is_finite() {
            h.clamp(x - band, x + band)
        } else {
            x
        }
    };
    Crop {
        tx: follow(held.tx, to.tx),
        ty: follow(held.ty, to.ty),
        s: follow(held.s, to.s),
        cut_by_frame: to.cut_by_frame,
    }
}

/// A scalar One Euro filter (derivative cutoff 1 Hz).
#[derive(Debug, Clone, Copy, Default)]
pub struct OneEuro {
    x: f32,
    dx: f32,
    primed: bool,
    /// The weight the last step gave the new value (1 on a restart).
    alpha: f32,
}

impl OneEuro {
    /// The filtered value of `x` a step of `dt` seconds after the last one.
    pub fn filter(&mut self, x: f32, dt: f32, min_cutoff_hz: f32, beta: f32) -> f32 {
        if !self.primed || !x.is_finite() || !dt.is_finite() || dt <= 0.0 {
            *self = Self {
                x,
                dx: 0.0,
                primed: x.is_finite(),
                alpha: 1.0,
            };
            return x;
        }
        let d = (x - self.x) / dt;
        self.dx += one_euro_alpha(1.0, dt) * (d - self.dx);
        let cutoff = min_cutoff_hz + beta * self.dx.abs();
        self.alpha = one_euro_alpha(cutoff, dt);
        self.x += self.alpha * (x - self.x);
        self.x
    }

    /// The weight the last step gave the new value: near 0 while still, 1 when moving fast.
    pub fn alpha(&self) -> f32 {
        self.alpha
    }
}

/// A map's layout: `channels` values per pixel of a `size x size` grid over crop NDC
/// (pixel `i` at `-1 + 2 i / (size - 1)`), interleaved (`[pixel][channel]`, the Fourier
/// maps) or planar (`[channel][pixel]`, the encoders' features).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MapLayout {
    pub channels: usize,
    pub size: usize,
    pub interleaved: bool,
}

impl MapLayout {
    fn len(&self) -> usize {
        self.channels * self.size * self.size
    }
}

struct LastMaps {
    crop: Crop,
    shape: (MapLayout, Vec<f32>),
    /// Per shape-map value: its filtered rate of change (per second).
    rate: Vec<f32>,
    color: Option<(MapLayout, Vec<f32>)>,
    /// Kept from frame to frame: the taps of a moved crop (shape and colour grids) and the
    /// buffers the last maps and rates are resampled into.
    shape_taps: Taps,
    color_taps: Taps,
    spare: Vec<f32>,
    spare_rate: Vec<f32>,
    spare_color: Vec<f32>,
}

/// What [`Temporal::steady_input`] did with a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// The frame continues the last one: filtered.
    Continued,
    /// The filter started again on this frame (why).
    Reset(ResetCause),
}

/// Why the filter started again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetCause {
    First,
    Gap,
    PeopleCount,
    CloseRange,
    NewPerson,
    NonFinite,
}

/// The temporal filter's state for one camera.
pub struct Temporal {
    settings: TemporalSettings,
    crop: [OneEuro; 3],
    /// The crop given out last (`crop_hold`'s backlash; `None` after a reset), and whether
    /// it was the one given out the frame before (`mask_still_hold_frames`).
    held: Option<Crop>,
    crop_still: bool,
    /// Per letterbox pixel: person by the hysteresis rule.
    on: Vec<bool>,
    /// Per letterbox pixel: frames in a row the segmenter put it on the other side of 0.5
    /// than `on` (saturating).
    against: Vec<u8>,
    /// The steady mask given out last.
    out: Vec<f32>,
    /// The segmenter's mask of the last frame, before steadying.
    raw: Vec<f32>,
    /// This frame's moving blocks (`moving_blocks`) and the mask's side, for the maps
    /// (`map_motion_weight`); empty after a reset (the maps start again there anyway).
    motion: (Vec<bool>, usize),
    last_t: Option<f64>,
    /// Seconds since the previous frame (0 on a reset).
    dt: f32,
    people: usize,
    close_range: bool,
    maps: Option<LastMaps>,
    /// The maps' filter on the GPU backend's adapter (`temporal/adapter.rs`).
    #[cfg(feature = "wgpu")]
    adapter: Option<adapter::AdapterMaps>,
    /// Frames since the last reset.
    pub continued: u64,
    pub resets: u64,
}

impl Temporal {
    pub fn new(settings: TemporalSettings) -> Self {
        Self {
            settings,
            crop: [OneEuro::default(); 3],
            held: None,
            crop_still: false,
            on: Vec::new(),
            against: Vec::new(),
            out: Vec::new(),
            raw: Vec::new(),
            motion: (Vec::new(), 0),
            last_t: None,
            dt: 0.0,
            people: 0,
            close_range: false,
            maps: None,
            #[cfg(feature = "wgpu")]
            adapter: None,
            continued: 0,
            resets: 0,
        }
    }

    pub fn settings(&self) -> TemporalSettings {
        self.settings
    }

    /// Forget every frame: the next one passes unfiltered.
    pub fn reset(&mut self) {
        self.crop = [OneEuro::default(); 3];
        self.held = None;
        self.crop_still = false;
        self.on.clear();
        self.against.clear();
        self.out.clear();
        self.raw.clear();
        self.motion.0.clear();
        self.last_t = None;
        self.maps = None;
        #[cfg(feature = "wgpu")]
        if let Some(a) = &mut self.adapter {
            a.forget();
        }
        self.continued = 0;
    }

    /// Steady the mask (letterboxed `[S, S]`, in place) and the crop of a frame taken at
    /// `t_s` seconds showing `people` people; `crop` is the segmenter's (its `cut_by_frame`
    /// is kept), filtered in time; `None` when no pixel of the steady mask is person (the
    /// caller reports no person; the state is reset).
    pub fn steady_input(
        &mut self,
        t_s: f64,
        people: usize,
        mask: &mut [f32],
        crop: Crop,
    ) -> (Option<Crop>, Step) {
        let size = (mask.len() as f64).sqrt() as usize;
        let step = self.continuation(t_s, people, mask, crop);
        // Where the segmenter's mask moved since the last frame (a reset starts again from
        // this one); then this mask, before steadying, is the next frame's last one.
        let moving = match step {
            Step::Continued => Some(moving_blocks(
                mask,
                &self.raw,
                size,
                self.settings.mask_motion,
            )),
            Step::Reset(_) => {
                self.reset();
                self.resets += 1;
                self.on = mask.iter().map(|&m| m > 0.5).collect();
                self.against = vec![0; mask.len()];
                None
            }
        };
        self.raw.clear();
        self.raw.extend_from_slice(mask);
        self.motion.0.clear();
        if let Some(moving) = moving {
            self.continued += 1;
            let (lo, hi) = (self.settings.mask_low, self.settings.mask_high);
            let nb = size.div_ceil(MOTION_BLOCK);
            // A person still as a whole (the crop held) keeps a trembling pixel longer.
            let hold = if self.crop_still {
                self.settings.mask_still_hold_frames
            } else {
                self.settings.mask_hold_frames
            };
            let hold = hold.min(255) as u8;
            let dead = self.settings.mask_dead_band;
            let pixels = mask.iter_mut().zip(&mut self.on).zip(&mut self.against);
            for (p, (((m, on), against), out)) in pixels.zip(&self.out).enumerate() {
                let v = *m;
                let raw_on = v > 0.5;
                let block = (p / size / MOTION_BLOCK) * nb + (p % size) / MOTION_BLOCK;
                if raw_on == *on {
                    *against = 0;
                    // The dead band: a value that stays on its side and near the one given
                    // out last is given out again (the mask's 0.5 contour, which gates the
                    // field, then does not slide with sensor noise).
                    if (v - *out).abs() < dead && (*out > 0.5) == raw_on && !moving[block] {
                        *m = *out;
                    }
                    continue;
                }
                *against = against.saturating_add(1);
                if moving[block] || v > hi || v < lo || *against >= hold {
                    *on = raw_on;
                    *against = 0;
                } else {
                    *m = *out;
                }
            }
            self.motion = (moving, size);
        }
        self.out.clear();
        self.out.extend_from_slice(mask);
        self.last_t = Some(t_s);
        self.people = people;
        self.close_range = crop.cut_by_frame;
        // The crop follows the segmenter's own box (its noise is the One Euro filter's to
        // take out): a box from the held mask would trail a raised hand's tip and shrink
        // the whole reconstruction with it.
        if !mask.iter().take(size * size).any(|&m| m > 0.5) {
            self.reset();
            return (None, step);
        }
        let raw = crop;
        let dt = self.dt;
        let s = &self.settings;
        let (c, b) = (s.crop_min_cutoff_hz, s.crop_beta);
        let filtered = Crop {
            tx: self.crop[0].filter(raw.tx, dt, c, b),
            ty: self.crop[1].filter(raw.ty, dt, c, b),
            s: self.crop[2].filter(raw.s, dt, c, b),
            cut_by_frame: crop.cut_by_frame,
        };
        let steady = match self.held {
            Some(held) => backlash(held, filtered, s.crop_hold),
            None => filtered,
        };
        self.crop_still = self.held == Some(steady);
        self.held = Some(steady);
        (Some(steady), step)
    }

    /// Whether this frame continues the last one, and the step since it (`self.dt`).
    fn continuation(&mut self, t_s: f64, people: usize, mask: &[f32], crop: Crop) -> Step {
        self.dt = 0.0;
        if mask.iter().any(|m| !m.is_finite()) || !t_s.is_finite() {
            return Step::Reset(ResetCause::NonFinite);
        }
        let Some(last) = self.last_t else {
            return Step::Reset(ResetCause::First);
        };
        if self.on.len() != mask.len() {
            return Step::Reset(ResetCause::First);
        }
        let dt = t_s - last;
        if !(dt > 0.0 && dt <= self.settings.max_gap_s as f64) {
            return Step::Reset(ResetCause::Gap);
        }
        if people != self.people {
            return Step::Reset(ResetCause::PeopleCount);
        }
        if crop.cut_by_frame != self.close_range {
            return Step::Reset(ResetCause::CloseRange);
        }
        let (mut both, mut either) = (0usize, 0usize);
        for (&m, &on) in mask.iter().zip(&self.on) {
            let new = m > 0.5;
            both += (new && on) as usize;
            either += (new || on) as usize;
        }
        if either == 0 || (both as f32) < self.settings.same_person_iou * either as f32 {
            return Step::Reset(ResetCause::NewPerson);
        }
        self.dt = dt as f32;
        Step::Continued
    }

    /// Blend this frame's maps (made through `crop`, the crop [`Self::steady_input`] gave)
    /// with the last frame's, in place: the shape maps and, when given, the colour features.
    /// Called once per frame after [`Self::steady_input`]; shape maps of another layout than
    /// the last ones (a model switch) start again; colour features that come back after
    /// frames without them (or in another layout) start again on their own.
    pub fn steady_maps(
        &mut self,
        crop: Crop,
        shape: (MapLayout, &mut [f32]),
        mut color: Option<(MapLayout, &mut [f32])>,
    ) {
        let fits = |l: MapLayout, d: &[f32]| l.size >= 2 && l.channels > 0 && d.len() == l.len();
        let shape_ok = fits(shape.0, shape.1) && all_finite(shape.1);
        let color_ok = color
            .as_ref()
            .is_none_or(|(l, d)| fits(*l, d) && all_finite(d));
        #[cfg(feature = "wgpu")]
        if let Some(a) = &mut self.adapter {
            a.forget();
        }
        if !(shape_ok && color_ok) {
            self.maps = None;
            return;
        }
        match self.maps.take() {
            Some(mut last) if self.dt > 0.0 && last.shape.0 == shape.0 => {
                // The last maps in this frame's crop (as they are when the crop did not
                // move), once per map: the weights and the blend read the same values.
                let l = shape.0;
                let moved = last.shape_taps.set(l.size, last.crop, crop);
                if moved {
                    last.shape_taps.apply(l, &last.rate, &mut last.spare_rate);
                    std::mem::swap(&mut last.rate, &mut last.spare_rate);
                }
                let (old, valid) =
                    resampled(&last.shape_taps, moved, l, &last.shape.1, &mut last.spare);
                let weights = self.blend_weights(old, valid, l, shape.1, &mut last.rate, crop);
                blend(old, valid, l, shape.1, &weights);
                match (&mut last.color, color.as_mut()) {
                    (Some((llast, lc)), Some((lcol, d))) if *llast == *lcol => {
                        let lcol = *lcol;
                        let (w, taps, moved) = if lcol.size == l.size {
                            (weights, &last.shape_taps, moved)
                        } else {
                            let w = weights_at(&weights, l.size, lcol.size);
                            let moved = last.color_taps.set(lcol.size, last.crop, crop);
                            (w, &last.color_taps, moved)
                        };
                        let (old, valid) = resampled(taps, moved, lcol, lc, &mut last.spare_color);
                        blend(old, valid, lcol, d, &w);
                        lc.copy_from_slice(d);
                    }
                    // Colour features again (the view turned away from the camera's: the
                    // encoder runs again) or of another layout: they start from this frame,
                    // the shape maps' filter goes on.
                    (_, Some((lcol, d))) => {
                        last.color = Some((*lcol, d.to_vec()));
                        last.color_taps = Taps::default();
                    }
                    // None this frame (the camera's own view takes the input's colours and
                    // the encoder does not run): forgotten.
                    (_, None) => last.color = None,
                }
                // This frame's maps are the next one's last (in the same buffers).
                last.shape.1.copy_from_slice(shape.1);
                last.crop = crop;
                self.maps = Some(last);
            }
            _ => {
                self.maps = Some(LastMaps {
                    crop,
                    shape: (shape.0, shape.1.to_vec()),
                    rate: vec![0.0; shape.1.len()],
                    color: color.map(|(l, d)| (l, d.to_vec())),
                    shape_taps: Taps::default(),
                    color_taps: Taps::default(),
                    spare: Vec::new(),
                    spare_rate: Vec::new(),
                    spare_color: Vec::new(),
                });
            }
        }
    }

    /// Per shape-map pixel, the weight of the new value: the crop filter's own weight (a
    /// person moving as a whole, whose box moves fast, is followed everywhere at once) or,
    /// where larger, the One Euro weight of the pixel's rate of change (the sum over its channels of each value's filtered rate, `rate`,
    /// updated here, over the maps' mean magnitude); 1 where the last map has no value.
    fn blend_weights(
        &self,
        old: &[f32],
        valid: Option<&[bool]>,
        l: MapLayout,
        new: &[f32],
        rate: &mut [f32],
        crop: Crop,
    ) -> Vec<f32> {
        let (dt, s) = (self.dt, &self.settings);
        let n = l.size * l.size;
        let a = one_euro_alpha(s.map_change_cutoff_hz, dt);
        let inv_dt = 1.0 / dt;
        // Per pixel the sum of |rate|, and the sum of |new|, in the layout's memory order
        // (sums kept in registers per pixel or per plane: a running sum in memory would
        // chain every value's add through a store).
        let mut speed = vec![0.0f32; n];
        let mut magnitude = 0.0f32;
        if l.interleaved {
            let c = l.channels;
            for (((sp, np), op), rp) in speed
                .iter_mut()
                .zip(new.chunks_exact(c))
                .zip(old.chunks_exact(c))
                .zip(rate.chunks_exact_mut(c))
            {
                let (mut acc, mut mag) = (0.0f32, 0.0f32);
                for ((v, o), r) in np.iter().zip(op).zip(rp) {
                    *r += a * ((v - o) * inv_dt - *r);
                    acc += r.abs();
                    mag += v.abs();
                }
                *sp = acc;
                magnitude += mag;
            }
        } else {
            for ((np, op), rp) in new
                .chunks_exact(n)
                .zip(old.chunks_exact(n))
                .zip(rate.chunks_exact_mut(n))
            {
                for (((sp, v), o), r) in speed.iter_mut().zip(np).zip(op).zip(rp) {
                    *r += a * ((v - o) * inv_dt - *r);
                    *sp += r.abs();
                }
                magnitude += np.iter().map(|v| v.abs()).sum::<f32>();
            }
        }
        let scale = magnitude / new.len() as f32 + 1e-6;
        let norm = 1.0 / (l.channels as f32 * scale);
        let floor = self.crop.iter().map(OneEuro::alpha).fold(0.0f32, f32::max);
        let mut w: Vec<f32> = speed
            .iter()
            .map(|sp| one_euro_alpha(s.map_min_cutoff_hz + s.map_beta * sp * norm, dt).max(floor))
            .collect();
        self.motion_floor(l.size, crop, &mut w);
        if let Some(valid) = valid {
            for (w, ok) in w.iter_mut().zip(valid) {
                if !*ok {
                    *w = 1.0;
                }
            }
        }
        w
    }
}

impl Temporal {
    /// Per pixel of a `size x size` map made through `crop`, whether it lies in or beside a
    /// block where this frame's mask moved (`None` when nothing moved, the crop given out
    /// stayed put, or the setting is off: a person still as a whole keeps the maps' filter
    /// whole, as the mask keeps its longer hold, so that noise that now and then flips a
    /// block's worth of outline pixels does not open it). The crop is a scale and a shift,
    /// so a map column's block depends on its x alone and a row's on its y alone.
    pub(super) fn motion_pixels(&self, size: usize, crop: Crop) -> Option<Vec<bool>> {
        let (moving, side) = (&self.motion.0, self.motion.1);
        if self.settings.map_motion_weight <= 0.0
            || self.crop_still
            || !moving.contains(&true)
            || size < 2
        {
            return None;
        }
        let nb = side.div_ceil(MOTION_BLOCK);
        let m = (size - 1) as f32;
        // Map pixel -> crop NDC -> the mask's NDC -> its pixel (nearest) -> its block.
        let block = |i: usize, t: f32| {
            let ndc = crop.s * (-1.0 + 2.0 * i as f32 / m) + t;
            let px = ((ndc + 1.0) * 0.5 * (side - 1) as f32).round();
            (px >= 0.0 && px <= (side - 1) as f32).then_some(px as usize / MOTION_BLOCK)
        };
        let cols: Vec<Option<usize>> = (0..size).map(|x| block(x, crop.tx)).collect();
        let rows: Vec<Option<usize>> = (0..size).map(|y| block(y, crop.ty)).collect();
        let mut out = vec![false; size * size];
        for (row, by) in out.chunks_exact_mut(size).zip(&rows) {
            let Some(by) = by else { continue };
            for (o, bx) in row.iter_mut().zip(&cols) {
                *o = bx.is_some_and(|bx| moving[by * nb + bx]);
            }
        }
        Some(out)
    }

    /// Raise the new maps' weight to `map_motion_weight` where the mask moved.
    fn motion_floor(&self, size: usize, crop: Crop, w: &mut [f32]) {
        if let Some(pixels) = self.motion_pixels(size, crop) {
            let least = self.settings.map_motion_weight;
            for (w, _) in w.iter_mut().zip(pixels).filter(|(_, m)| *m) {
                *w = w.max(least);
            }
        }
    }
}

/// The shape map's per-pixel weights (`shape` pixels a side) at the pixels of a map `size`
/// a side (nearest: both grids span the crop's NDC corner to corner).
fn weights_at(weights: &[f32], shape: usize, size: usize) -> Vec<f32> {
    let (a, b) = (shape - 1, size - 1);
    let near = |i: usize| (i * a + b / 2) / b;
    (0..size * size)
        .map(|p| weights[near(p / size) * shape + near(p % size)])
        .collect()
}

#[cfg(feature = "wgpu")]
mod adapter;
mod settings;
mod warp;
pub use settings::{CROP_HOLD_DEFAULT, TemporalSettings};
use warp::{Taps, blend, resampled};

#[cfg(test)]
mod tests;
