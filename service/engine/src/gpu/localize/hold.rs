//! The surface's dead band on the adapter ([`crate::sides`] on the CPU, the same rule bit for
//! bit): every grid value the evaluation kernels write (`localize_eval.wgsl` `held`) is given
//! out as last frame's while within the band of it, or on last frame's side while over the
//! level by less than the band.
//!
//! The memory is one word a grid point after the "already handled" bits in their buffer
//! (binding 2, so the evaluation kernels keep the default eight storage buffers): the frame's
//! stamp (16 bits), the quantized value given out the frame before (8) and the one given out
//! this frame (8). A word stamped with the last frame's stamp holds last frame's value, one
//! stamped with this frame's (a point evaluated again, or in an attempt run again) holds it
//! one field down; any other is not known. So nothing is cleared per frame: a frame that
//! forgets (another alignment, grid or band, a frame without the band) skips a stamp, and the
//! words are cleared only when the 16 bits run out (every 65,534 frames: that frame is held
//! against nothing). The quantized values a byte stands for come from [`dequantize`] as bits
//! in the field's parameters (the adapter's division is not exact).
//!
//! Four bytes a point (68 MB at 257^3) while on, where the bits and the memory fit one
//! storage binding (on a GPU the 513^3 grid's 540 MB of values are one binding; where the
//! values are tiled, lavapipe's 513^3, the frame is not held and
//! [`GpuLocalizer::hold_refused`] says why).

use super::GpuLocalizer;
use crate::grid::GridSpec;
use crate::sides::{dequantize, usable_band};

/// The last stamp before the memory is cleared (16 bits).
const LAST_STAMP: u32 = 0xffff;

/// Where the field's parameters (`localize_eval.wgsl` `f`) hold the band, the frame's stamp,
/// the memory's first word and the table of quantized values.
pub(super) const BAND_AT: usize = 6;
pub(super) const STAMP_AT: usize = 7;
pub(super) const MEMORY_AT: usize = 17;
pub(super) const TABLE_AT: usize = 20;
/// The field's parameters in words: the field's 20, then the table's 256.
pub(super) const PARAM_WORDS: usize = TABLE_AT + 256;

/// The dead band's state on the host: the next frame's band and alignment, and what the
/// frames before were held with.
#[derive(Default)]
pub(super) struct Hold {
    pending: (f32, Option<u64>),
    /// The band, alignment and grid size of the last frame held (`None`: the next forgets).
    last: Option<(f32, u64, usize)>,
    stamp: u32,
    /// The memory to be cleared ahead of the frame's first submission.
    pub(super) clear: bool,
    /// This frame's band and stamp (a stamp of 0: not held).
    pub(super) band: f32,
    pub(super) frame_stamp: u32,
    /// Why the last frame asked to be held was not.
    pub(super) refused: Option<String>,
    /// Points the last completed frame gave out as last frame's.
    pub(super) held: u64,
}

impl Hold {
    /// The frame's stamp from what [`GpuLocalizer::hold_sides`] gave for it, on a grid of
    /// `len` points whose memory fits (`fits`) or not.
    fn begin(&mut self, len: usize, fits: impl FnOnce() -> Result<(), String>) {
        let (band, key) = std::mem::take(&mut self.pending);
        let band = usable_band(band);
        self.refused = None;
        self.held = 0;
        let key = key.filter(|_| band > 0.0);
        if key.is_some()
            && let Err(e) = fits()
        {
            self.refused = Some(e);
        }
        let Some(key) = key.filter(|_| self.refused.is_none()) else {
            self.last = None;
            self.band = 0.0;
            self.frame_stamp = 0;
            return;
        };
        let same = self.last == Some((band, key, len));
        // The last frame's stamp follows; a skipped one forgets.
        self.stamp += if same { 1 } else { 2 };
        if self.stamp > LAST_STAMP {
            self.clear = true;
            self.stamp = 2;
        }
        self.last = Some((band, key, len));
        self.band = band;
        self.frame_stamp = self.stamp;
    }
}

/// The table of quantized values as bits ([`dequantize`], 0 standing for none).
pub(super) fn table() -> [u32; 256] {
    std::array::from_fn(|q| dequantize(q as u8).to_bits())
}

impl GpuLocalizer {
    /// Hold grid values within `band` of those given out last frame, and sides within `band`
    /// of the level, in the next run or rendered frame ([`crate::sides`], the CPU's rule bit
    /// for bit) when its alignment `key` is the last frame's; given for one frame (a frame
    /// without it forgets them).
    pub fn hold_sides(&mut self, band: f32, key: Option<u64>) {
        self.hold.pending = (band, key);
    }

    /// Forget the values held: the next frame starts from none.
    pub fn forget_sides(&mut self) {
        self.hold.last = None;
        self.hold.pending = Default::default();
    }

    /// Grid points the last completed frame gave out as last frame's.
    pub fn held_sides(&self) -> u64 {
        self.hold.held
    }

    /// Stamps used so far set to `stamp` (at most the last, 65,535): the tests reach the
    /// memory's clearing when the stamps run out without 65,534 frames.
    #[doc(hidden)]
    pub fn set_hold_stamp(&mut self, stamp: u32) {
        self.hold.stamp = stamp.min(LAST_STAMP);
    }

    /// Why the last frame was not held though a band and key were given (its grid's memory
    /// does not fit one storage binding here).
    pub fn hold_refused(&self) -> Option<&str> {
        self.hold.refused.as_deref()
    }

    /// Words of the "already handled" bits for `spec` (the memory follows them).
    pub(super) fn bit_words(spec: GridSpec) -> usize {
        spec.len().div_ceil(32)
    }

    /// The frame's stamp (in `prepare`, before the buffers are made for it).
    pub(super) fn begin_hold(&mut self, spec: GridSpec) {
        let bytes = (Self::bit_words(spec) + spec.len()) as u64 * 4;
        let limit = self.binding_bytes();
        let tiled = self.tiling(spec).tiles > 1;
        self.hold.begin(spec.len(), || {
            if tiled || bytes > limit {
                Err(format!(
                    "the surface's dead band on a {}^3 grid needs {:.1} MiB in one storage \
                     binding, more than the adapter's {:.1} MiB: not held",
                    spec.n(),
                    bytes as f64 / (1u64 << 20) as f64,
                    limit as f64 / (1u64 << 20) as f64
                ))
            } else {
                Ok(())
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_follow_for_the_same_alignment_and_skip_to_forget() {
        let ok = || Ok(());
        let mut h = Hold::default();
        let mut stamps = Vec::new();
        for (band, key, len) in [
            (0.06, Some(1), 10),
            (0.06, Some(1), 10),
            (0.06, Some(2), 10),
            (0.06, Some(2), 11),
            (0.05, Some(2), 11),
            (0.0, Some(2), 11),
            (0.05, None, 11),
            (0.05, Some(2), 11),
            (0.05, Some(2), 11),
        ] {
            h.pending = (band, key);
            h.begin(len, ok);
            stamps.push(h.frame_stamp);
        }
        assert_eq!(stamps, [2, 3, 5, 7, 9, 0, 0, 11, 12]);
        // Nothing given: off, and the next frame forgets.
        h.begin(11, ok);
        assert_eq!(h.frame_stamp, 0);
        h.pending = (0.05, Some(2));
        h.begin(11, ok);
        assert_eq!(h.frame_stamp, 14);
        // A memory that does not fit: off, with the reason.
        h.pending = (0.05, Some(2));
        h.begin(11, || Err("too large".into()));
        assert_eq!(
            (h.frame_stamp, h.refused.as_deref()),
            (0, Some("too large"))
        );
        // Past 16 bits: cleared, and the frame forgets (stamp 2 follows nothing).
        h.stamp = LAST_STAMP;
        h.last = Some((0.05, 2, 11));
        h.pending = (0.05, Some(2));
        h.begin(11, ok);
        assert!(h.clear && h.frame_stamp == 2);
        assert!(h.band == 0.05);
    }
}
