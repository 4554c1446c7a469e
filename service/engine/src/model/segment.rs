//! A frame's person: the letterboxed input segmented (once or twice), the most prominent
//! person kept and cropped, with what was found and where the time went ([`FrameInfo`],
//! [`SegmentTimings`]).

use super::preprocess::{self, Crop, INPUT_SIZE};
use super::{ModelError, Models};

/// Why a frame gives no field.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("no person in view (segmentation found no person pixel)")]
    NoPerson,
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// What [`Models::frame`] found and how long its stages took (milliseconds).
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameInfo {
    pub segment_ms: f64,
    /// Where [`FrameInfo::segment_ms`] went.
    pub segment_parts: SegmentTimings,
    pub encode_ms: f64,
    /// People in view ([`preprocess::keep_most_prominent`]); the field is the largest one.
    pub people: usize,
    /// Fraction of the 256x256 input that is the chosen person's mask (> 0.5).
    pub mask_fraction: f32,
    /// The frame cuts the person at its lower edge and the close-range shape model
    /// ([`Models::with_close_range`]) encodes it.
    pub close_range: bool,
}

/// Where one frame's segmentation spent its time (wall ms on the segmenting thread): the
/// parts the pipeline bench splits the segment stage into.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SegmentTimings {
    /// The frame letterboxed into the networks' square input.
    pub letterbox_ms: f64,
    /// The segmentation network's runs (one per pass; on the GPU backend each with its
    /// upload and read-back).
    pub nets_ms: f64,
    /// The rest on the host: the most prominent person kept, the second pass's crop of the
    /// image and its mask pasted back, the mask's fraction and the person's crop.
    pub person_ms: f64,
}

impl Models {
    /// The soft person mask `[S, S]` of a letterboxed frame `[3, S, S]`.
    pub fn segment(&self, rgb: &[f32]) -> Result<Vec<f32>, ModelError> {
        let s = INPUT_SIZE;
        let mut m = self.seg.run(&[(&[1, 3, s, s], rgb)])?;
        for v in &mut m {
            // A non-finite mask value is no evidence of a person.
            if !v.is_finite() {
                *v = 0.0;
            }
        }
        Ok(m)
    }

    /// The most prominent person's soft mask `[S, S]` in a letterboxed image `[3, S, S]`
    /// ([`preprocess::keep_most_prominent`]: 0 outside that person) and the people counted.
    /// With [`Models::segment_passes`] 2 the person's crop is segmented too and that mask
    /// taken back into the frame by its larger value ([`Crop::paste_max`]; measured on
    /// held-out renders: thin rays kept 0.61 -> 0.74, mask IoU 0.885 -> 0.898 in the frame;
    /// docs/eval/hands.md section 8), then the most prominent person kept again, so the
    /// crop made from the result holds what the second pass found. The people are those of
    /// the first pass (the second sees only the crop).
    pub fn person_mask(&self, img: &[f32]) -> Result<(Vec<f32>, usize), ModelError> {
        self.person_mask_timed(img, &mut 0.0)
    }

    /// [`Models::person_mask`], adding the networks' wall ms to `nets_ms`.
    fn person_mask_timed(
        &self,
        img: &[f32],
        nets_ms: &mut f64,
    ) -> Result<(Vec<f32>, usize), ModelError> {
        let mut timed = |rgb: &[f32]| {
            let t = std::time::Instant::now();
            let m = self.segment(rgb);
            *nets_ms += t.elapsed().as_secs_f64() * 1e3;
            m
        };
        let mut mask = timed(img)?;
        let people = preprocess::keep_most_prominent(&mut mask, INPUT_SIZE);
        if self.segment_passes >= 2
            && let Some(crop) = Crop::from_mask(&mask, INPUT_SIZE)
        {
            let m2 = timed(&crop.apply(img, 3, INPUT_SIZE))?;
            crop.paste_max(&m2, INPUT_SIZE, &mut mask);
            preprocess::keep_most_prominent(&mut mask, INPUT_SIZE);
        }
        Ok((mask, people))
    }

    /// Letterbox and segment one RGB8 frame and keep its most prominent person
    /// ([`preprocess::keep_most_prominent`]): the input square `[3, S, S]`, the person's soft
    /// mask `[S, S]` (0 outside the chosen person) and its crop; `info` gets the people
    /// count, the mask fraction and the segmentation time.
    pub fn prepare(
        &self,
        rgb: &[u8],
        width: usize,
        height: usize,
        info: &mut FrameInfo,
    ) -> Result<(Vec<f32>, Vec<f32>, Crop), FrameError> {
        let ms = |t: std::time::Instant| t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        let img = preprocess::letterbox(rgb, width, height);
        let letterbox_ms = ms(t);
        let mut nets_ms = 0.0;
        let (mask, people) = self.person_mask_timed(&img, &mut nets_ms)?;
        info.people = people;
        info.mask_fraction =
            mask.iter().filter(|&&m| m > 0.5).count() as f32 / (INPUT_SIZE * INPUT_SIZE) as f32;
        let crop = Crop::from_mask(&mask, INPUT_SIZE);
        info.segment_ms = ms(t);
        info.segment_parts = SegmentTimings {
            letterbox_ms,
            nets_ms,
            person_ms: (info.segment_ms - letterbox_ms - nets_ms).max(0.0),
        };
        let mut crop = crop.ok_or(FrameError::NoPerson)?;
        crop.cut_by_frame = preprocess::cut_by_frame(&mask, width, height);
        info.close_range = crop.cut_by_frame && self.close_range.is_some();
        Ok((img, mask, crop))
    }
}
