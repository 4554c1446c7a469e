//! Grid values held across frames (the surface's dead band).
//!
//! A still person's field is not still: sensor noise through the networks moves the
//! occupancy of the grid points near the surface by a little each frame. Where a surface lies
//! along a grid plane (the crown, a leg's far side, the soles) a whole row of points sits near
//! the level at once, and each crossing adds or removes a one-cell line of the render; and
//! every point's small change slides the outline the display draws between the grid's
//! columns (the surface's depth and the antialiased edge are interpolated from the values).
//! [`HeldSides`] remembers the value each evaluated grid point was given last frame
//! (quantized to 1/254, on its side of the level: [`quantize`]). A point evaluated again:
//!
//! - within `band` of last frame's value is given that value again;
//! - otherwise, over the level from last frame's side but within `band` of the level
//!   ([`crate::ISO`]), is given the nearest value on last frame's side (`ISO` itself, or the
//!   next `f32` above it: [`JUST_INSIDE`]);
//! - otherwise keeps its own value (a real change goes through at once).
//!
//! So a value creeping through the level is late by at most the band (a fraction of a
//! cell: the networks' occupancy crosses from 0 to 1 within a cell or two).
//!
//! The memory is only good while grid point `q` is the same place in the field from frame
//! to frame: the caller names each frame's alignment with a key (the daemon and `bench
//! temporal`: the model field's render-to-crop transform and crop,
//! [`crate::model::ModelField::alignment_key`], which the temporal filter's crop hold keeps
//! bit for bit while the person is still and the view is not turned). A frame with another
//! key, another grid or no key forgets everything, so a moving crop (a person walking) is
//! never held back; a person moving inside a held crop is, by at most the band.
//!
//! Every evaluation path writes grid values through [`crate::field::Evaluator::eval_grid`],
//! which applies the memory when one is attached ([`crate::field::Evaluator::with_sides`]):
//! every localization level, the render's final level and its conflict loop alike. Two bytes a
//! grid point while the band is on (last frame's and this one's: 34 MB at 257^3), cleared
//! point by point from the lists of those written. The GPU backend applies the same rule bit
//! for bit where its kernels write grid values (`gpu/localize/hold.rs`).

use crate::grid::{ISO, is_inside};

/// The surface's dead band: each grid point's value given out last frame, given out again
/// while the point's occupancy stays within the band of it ([module docs](self)).
#[derive(Default)]
pub struct HeldSides {
    band: f32,
    key: Option<u64>,
    len: usize,
    /// Last frame's values given out, quantized ([`quantize`]; 0: not evaluated), and this
    /// frame's as it is evaluated, with the points written in each (to clear them).
    last: Vec<u8>,
    next: Vec<u8>,
    last_written: Vec<u32>,
    next_written: Vec<u32>,
    held: u64,
    /// The next frame's band and alignment ([`HeldSides::hold`]).
    pending: (f32, Option<u64>),
}

/// The smallest occupancy that is inside.
pub const JUST_INSIDE: f32 = f32::from_bits(ISO.to_bits() + 1);

/// The largest band accepted (beyond it a point could be held inside at a quarter
/// occupancy: no longer noise).
pub const MAX_BAND: f32 = 0.25;

/// A band as the memory uses it: within [0, [`MAX_BAND`]], 0 (off) when not finite.
pub fn usable_band(band: f32) -> f32 {
    if band.is_finite() {
        band.clamp(0.0, MAX_BAND)
    } else {
        0.0
    }
}

/// An occupancy in [0, 1] as 1..=255 on its side of the level: `1 + round(254 v)`, 129 at
/// least inside and 128 at most outside (128 is the level itself).
#[inline]
pub fn quantize(v: f32) -> u8 {
    let q = 1.0 + (v.clamp(0.0, 1.0) * 254.0).round();
    let q = q as u8;
    if is_inside(v) { q.max(129) } else { q.min(128) }
}

/// The occupancy a quantized value stands for (on the same side as the value quantized).
#[inline]
pub fn dequantize(q: u8) -> f32 {
    (q.saturating_sub(1)) as f32 / 254.0
}

impl HeldSides {
    pub fn new() -> Self {
        Self::default()
    }

    /// Start a frame on a grid of `len` points whose alignment is `key` with a dead band of
    /// `band` (0: off). The last frame's values are kept only when the band, key and grid are
    /// the same as then; otherwise (or with no key) the memory starts empty.
    pub fn begin(&mut self, band: f32, key: Option<u64>, len: usize) {
        let band = usable_band(band);
        let same = key.is_some() && key == self.key && len == self.len && band == self.band;
        clear_written(&mut self.last, &mut self.last_written);
        if same {
            std::mem::swap(&mut self.last, &mut self.next);
            std::mem::swap(&mut self.last_written, &mut self.next_written);
        } else {
            clear_written(&mut self.next, &mut self.next_written);
            let want = if band > 0.0 { len } else { 0 };
            for b in [&mut self.last, &mut self.next] {
                if b.len() != want {
                    b.clear();
                    b.resize(want, 0);
                }
            }
        }
        self.band = band;
        self.key = key.filter(|_| band > 0.0);
        self.len = len;
        self.held = 0;
    }

    /// The band and alignment of the next frame [`HeldSides::begin_pending`] starts (given
    /// for one frame: a frame begun without it forgets).
    pub fn hold(&mut self, band: f32, key: Option<u64>) {
        self.pending = (band, key);
    }

    /// [`HeldSides::begin`] with what [`HeldSides::hold`] gave for this frame (nothing: off).
    pub fn begin_pending(&mut self, len: usize) {
        let (band, key) = std::mem::take(&mut self.pending);
        self.begin(band, key, len);
    }

    /// What [`HeldSides::hold`] gave for the next frame, taken (the GPU backend's renderer
    /// holds that frame on the adapter: `gpu/localize/hold.rs`).
    pub fn take_pending(&mut self) -> (f32, Option<u64>) {
        std::mem::take(&mut self.pending)
    }

    /// Whether frames are held at all (a band above 0 and a key).
    pub fn active(&self) -> bool {
        self.band > 0.0 && self.key.is_some() && self.last.len() == self.len
    }

    /// The value given out for grid point `q` evaluated as `v` (a checked occupancy in
    /// [0, 1]), remembered for the next frame.
    #[inline]
    pub fn apply(&mut self, q: usize, v: f32) -> f32 {
        if !self.active() {
            return v;
        }
        let mut out = v;
        let was = self.last[q];
        if was != 0 {
            let w = dequantize(was);
            if (v - w).abs() < self.band {
                // Within the band of what was given out: that again.
                out = w;
            } else if is_inside(w) != is_inside(v) && (v - ISO).abs() < self.band {
                // Over the level, but not by the band: on last frame's side, nearest.
                out = if is_inside(w) { JUST_INSIDE } else { ISO };
            }
            if out != v {
                self.held += 1;
            }
        }
        let mine = quantize(out);
        if self.next[q] == 0 {
            self.next_written.push(q as u32);
        }
        self.next[q] = mine;
        out
    }

    /// Points given out as last frame's this frame.
    pub fn held(&self) -> u64 {
        self.held
    }

    /// Forget every frame and what [`HeldSides::hold`] gave (the next one starts empty).
    pub fn forget(&mut self) {
        self.key = None;
        self.pending = Default::default();
    }
}

/// Zero the entries `written` names and empty it.
fn clear_written(values: &mut [u8], written: &mut Vec<u32>) {
    for &q in written.iter() {
        if let Some(x) = values.get_mut(q as usize) {
            *x = 0;
        }
    }
    written.clear();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quantized values keep their side and are within a step of the value.
    #[test]
    fn quantized_values_keep_their_side() {
        for i in 0..=10_000 {
            let v = i as f32 / 10_000.0;
            for v in [
                v,
                f32::from_bits(v.to_bits().saturating_sub(1)),
                JUST_INSIDE,
            ] {
                let d = dequantize(quantize(v));
                assert_eq!(is_inside(d), is_inside(v), "{v}");
                // Half a step, a whole one where the side moves the rounding.
                assert!((d - v).abs() <= 1.0 / 254.0 + 1e-6, "{v} -> {d}");
                assert!((0.0..=1.0).contains(&d));
            }
        }
        assert_eq!(dequantize(quantize(ISO)), ISO);
    }

    /// A point within the band of last frame's value gets it again; one over the level by
    /// less than the band stays on its side, as the nearest value there; beyond both it
    /// goes through with its own value. Nothing is held for a point not evaluated last
    /// frame, after a new key, grid or band, with band 0 or without a key.
    #[test]
    fn a_point_keeps_its_value_and_side_within_the_band_and_only_there() {
        let mut h = HeldSides::new();
        h.begin(0.05, Some(7), 100);
        assert!(h.active());
        // First frame: nothing known, values pass.
        for (q, v) in [(1, 0.52), (2, 0.48), (3, 0.9), (5, 0.2)] {
            assert_eq!(h.apply(q, v), v);
        }
        assert_eq!(h.held(), 0);
        h.begin(0.05, Some(7), 100);
        // Within the band of the last value: the last value (quantized).
        let w = h.apply(1, 0.50001);
        assert!((w - 0.52).abs() < 0.5 / 254.0 + 1e-6 && is_inside(w), "{w}");
        // Far from the last value but over the level by less than the band: last side.
        assert_eq!(h.apply(3, 0.47), JUST_INSIDE);
        assert!(is_inside(JUST_INSIDE) && JUST_INSIDE - ISO < 1e-6);
        // Beyond both: its own value.
        assert_eq!(h.apply(5, 0.7), 0.7);
        // Not evaluated last frame.
        assert_eq!(h.apply(4, 0.51), 0.51);
        assert_eq!(h.held(), 2);
        // The next frame remembers what was given out: 3 just inside.
        h.begin(0.05, Some(7), 100);
        assert!(is_inside(h.apply(3, 0.46)));
        assert!(!is_inside(ISO));
        for (band, key, len) in [
            (0.05, Some(8), 100),
            (0.05, Some(7), 99),
            (0.1, Some(7), 100),
        ] {
            let mut h = HeldSides::new();
            h.begin(0.05, Some(7), 100);
            h.apply(1, 0.6);
            h.begin(band, key, len);
            assert_eq!(h.apply(1, 0.58), 0.58, "{band} {key:?} {len}");
        }
        for (band, key) in [(0.0, Some(7)), (0.05, None), (f32::NAN, Some(7))] {
            let mut h = HeldSides::new();
            for _ in 0..2 {
                h.begin(band, key, 100);
                assert!(!h.active());
                assert_eq!(h.apply(1, 0.49), 0.49);
                assert_eq!(h.apply(1, 0.51), 0.51);
            }
        }
        let mut h = HeldSides::new();
        h.begin(0.05, Some(7), 100);
        h.apply(1, 0.6);
        h.forget();
        h.begin(0.05, Some(7), 100);
        assert_eq!(h.apply(1, 0.58), 0.58);
        // Points written two frames back are cleared, not remembered.
        let mut h = HeldSides::new();
        h.begin(0.05, Some(7), 10);
        h.apply(1, 0.6);
        h.begin(0.05, Some(7), 10);
        h.begin(0.05, Some(7), 10);
        assert_eq!(h.apply(1, 0.58), 0.58);
    }

    /// A noisy still point keeps one value; a point that moves steadily through the level
    /// crosses late by at most the band's share of its motion; every output is in [0, 1].
    #[test]
    fn noise_is_held_and_motion_goes_through_late_by_at_most_the_band() {
        let mut state = 12345u32;
        let mut noise = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
        };
        let mut h = HeldSides::new();
        let mut given = Vec::new();
        for _ in 0..500 {
            h.begin(0.05, Some(1), 4);
            let v = 0.5 + 0.02 * noise();
            given.push(h.apply(0, v));
        }
        // The first frame gives its own value, the rest its quantized one, on its side.
        assert!(
            given[1..].windows(2).all(|w| w[0] == w[1]),
            "a noisy point moved"
        );
        assert_eq!(is_inside(given[0]), is_inside(given[1]));
        assert!((given[0] - given[1]).abs() <= 1.0 / 254.0);
        // A ramp through the level, 0.02 a frame: the raw crossing at frame 26 (0.52), the
        // held one when the value leaves the band of the last given out (0.06 late at most).
        let mut h = HeldSides::new();
        let mut first = None;
        for f in 0..=50 {
            h.begin(0.05, Some(1), 4);
            let v = f as f32 * 0.02;
            let out = h.apply(0, v);
            assert!((0.0..=1.0).contains(&out) && (out - v).abs() < 0.05 + 1e-6);
            if is_inside(out) && first.is_none() {
                first = Some(f);
            }
        }
        let f = first.expect("never crossed");
        assert!((26..=28).contains(&f), "crossed at frame {f}");
    }
}
