//! A frame's person: the letterboxed input segmented (once or twice), the most prominent
//! person kept and cropped, with what was found and where the time went ([`FrameInfo`],
//! [`SegmentTimings`]); between frames, the second pass's crop tracked so that the first
//! pass runs only every few frames ([`SegmentTrack`]).

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
    /// How the frame was segmented ([`SegmentTrack`]).
    pub tracked: Tracked,
}

/// How a frame was segmented with a [`SegmentTrack`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Tracked {
    /// Without a track, or with one segmenting every frame whole: as many passes as
    /// [`Models::segment_passes`].
    #[default]
    Off,
    /// The whole frame segmented: the track's first frame (or the first after a frame
    /// without a person: both passes, as untracked), or every `full_every`-th, which
    /// segments the tracked crop too and keeps its mask alone when the whole frame's
    /// person lies inside it (two runs, one where the crop is the whole frame); the people
    /// are counted again.
    Full,
    /// Only the last frame's crop was segmented (one network run instead of two).
    Crop,
    /// The last frame's crop was segmented but the person reached an edge of it with more
    /// frame beyond (or was not in it): the whole frame was segmented too and the crop's
    /// mask taken into it as its second pass (two runs); the track restarts from the two.
    Lost,
}

/// The segmentation's track between frames (the daemon's `[model] segment_full_every`).
///
/// With two passes ([`Models::segment_passes`] 2) a frame's person is segmented in the
/// whole frame, then again in the crop around what that found. A person moves little
/// between frames, and the crop keeps a margin around them ([`preprocess::FILL`]), so the
/// last frame's crop holds this frame's person too: a tracked frame segments that crop
/// alone, pastes it into an empty frame ([`Crop::paste_max`]) and keeps the most prominent
/// person, one network run where two were. The whole frame is segmented again every
/// `full_every` frames (a new person walking in is counted then; while the whole frame's
/// person lies inside the tracked crop the frame keeps the crop's mask, so that the masks
/// do not change kind from frame to frame), and at once when the crop's mask reaches an
/// edge of the crop with more frame beyond (the person may extend past it) or holds no
/// person: the whole frame's mask and the crop's together then give the frame's person
/// ([`Tracked::Lost`]). The crop changes only on whole frames, to the crop of the whole
/// frame's and the crop's masks together (so a limb the first pass missed, which the crop
/// cut, is taken in; the crop's mask alone could lose a hand and the crop follow it away);
/// on a scheduled whole frame only once that crop differs from it by [`TRACK_HOLD`] (a
/// still person's crop stays put). A crop that magnifies nothing (`s` >= 1: the person fills
/// the frame) is not segmented: the tracked frames segment the whole frame instead, one run
/// either way. Measured side by side with the untracked path by
/// `volcap bench temporal --setting default,default+segment_full_every=8` (accuracy,
/// flicker and the segment stage's ms; docs/bench/segment-track/).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SegmentTrack {
    /// The whole frame is segmented every this many frames; 0 or 1: every frame (no
    /// tracking).
    pub full_every: u32,
    /// The crop to segment next (the last frame's person's), if any.
    crop: Option<Crop>,
    /// Frames segmented since the last whole one.
    since_full: u32,
    /// The people counted by the last whole frame.
    people: usize,
    /// Where the frames' pixels lie in the input square ([`preprocess::letterbox_extent`]):
    /// a frame of another size (another camera) is segmented whole.
    extent: [f32; 4],
}

/// The longest `full_every` a caller should take: once a second at 30 fps (a person walking
/// in is counted within a second).
pub const SEGMENT_FULL_EVERY_MAX: u32 = 30;

/// The crop that is the whole input square (a copy).
const WHOLE_FRAME: Crop = Crop {
    s: 1.0,
    tx: 0.0,
    ty: 0.0,
    cut_by_frame: false,
};

/// A tracked crop's mask touching its edge within this many pixels (of the `S x S` crop
/// input) means the person may extend past it.
const TRACK_EDGE_PX: usize = 2;

/// A tracked crop moves once the person's crop differs from it by this fraction of its
/// half-size (in centre or size): 5 pixels of a crop that fills the 256-pixel input.
const TRACK_HOLD: f32 = 0.04;

impl SegmentTrack {
    /// A track segmenting the whole frame every `full_every` frames.
    pub fn new(full_every: u32) -> Self {
        SegmentTrack {
            full_every,
            ..Default::default()
        }
    }

    /// The crop the next frame segments alone, if it will (a frame of another size than the
    /// last is segmented whole all the same).
    pub fn next_crop(&self) -> Option<Crop> {
        self.crop.filter(|_| self.since_full + 1 < self.full_every)
    }
}

/// The crop a scheduled whole frame hands the next: the last one while the person's new
/// crop differs from it by less than [`TRACK_HOLD`] of its size (a still person's crop stays
/// put, so the mask it gives does not move the crop it is made in), else the new one.
fn held(last: Crop, new: Crop) -> Crop {
    let d = TRACK_HOLD * last.s;
    if (new.tx - last.tx).abs() < d && (new.ty - last.ty).abs() < d && (new.s - last.s).abs() < d {
        last
    } else {
        new
    }
}

/// A crop's mask taken into an empty input square, its most prominent person kept; `None`
/// when it holds no person.
fn crop_alone(crop: &Crop, crop_mask: &[f32], size: usize) -> Option<Vec<f32>> {
    let mut mask = if *crop == WHOLE_FRAME {
        crop_mask.to_vec()
    } else {
        let mut mask = vec![0.0f32; size * size];
        crop.paste_max(crop_mask, size, &mut mask);
        mask
    };
    (preprocess::keep_most_prominent(&mut mask, size) > 0).then_some(mask)
}

/// Whether every person pixel (> 0.5) of a `[S, S]` input mask lies inside `crop`'s square.
fn inside(crop: &Crop, mask: &[f32], size: usize) -> bool {
    let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (size - 1) as f32;
    let within = |v: f32, c: f32| (v - c).abs() <= crop.s;
    mask.iter().enumerate().all(|(i, &m)| {
        m <= 0.5 || (within(ndc(i % size), crop.tx) && within(ndc(i / size), crop.ty))
    })
}

/// Whether a mask made on `crop` (`[S, S]` in crop NDC) has a person pixel (> 0.5) within
/// [`TRACK_EDGE_PX`] of one of the crop's edges that has more of the frame beyond it
/// (`extent`: the frame's pixels in input NDC, [`preprocess::letterbox_extent`]; beyond an
/// edge in the letterbox's bars or outside the square there is no more person to find,
/// though the segmenter may mark a person cut by the frame up to the crop's edge).
fn reaches_inner_edge(crop: &Crop, mask: &[f32], size: usize, extent: [f32; 4]) -> bool {
    let b = TRACK_EDGE_PX.min(size);
    let [x0, x1, y0, y1] = extent;
    let row = |y: usize| mask[y * size..(y + 1) * size].iter().any(|&m| m > 0.5);
    let col = |x: usize| (0..size).any(|y| mask[y * size + x] > 0.5);
    (crop.ty - crop.s > y0 && (0..b).any(row))
        || (crop.ty + crop.s < y1 && (size - b..size).any(row))
        || (crop.tx - crop.s > x0 && (0..b).any(col))
        || (crop.tx + crop.s < x1 && (size - b..size).any(col))
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
        self.person_mask_timed(img, &mut 0.0, None)
            .map(|(m, p, _)| (m, p))
    }

    /// [`Models::person_mask`], adding the networks' wall ms to `nets_ms`; with a
    /// [`SegmentTrack`] that tracks (and two passes) the last frame's crop alone when it
    /// still holds the person, the track updated with this frame's person. `track` holds
    /// the frame's extent in the input square ([`preprocess::letterbox_extent`]).
    fn person_mask_timed(
        &self,
        img: &[f32],
        nets_ms: &mut f64,
        track: Option<(&mut SegmentTrack, [f32; 4])>,
    ) -> Result<(Vec<f32>, usize, Tracked), ModelError> {
        let (track, extent) = match track {
            Some((t, e)) => (Some(t), e),
            None => (None, [-1.0, 1.0, -1.0, 1.0]),
        };
        let s = INPUT_SIZE;
        let mut timed = |rgb: &[f32]| {
            let t = std::time::Instant::now();
            let m = self.segment(rgb);
            *nets_ms += t.elapsed().as_secs_f64() * 1e3;
            m
        };
        let tracking = self.segment_passes >= 2 && track.as_ref().is_some_and(|t| t.full_every > 1);
        // The tracked crop, its mask and whether the person reached an edge of it with more
        // frame beyond.
        let mut tracked = None;
        if let Some(tr) = track.as_deref().filter(|_| tracking)
            && let Some(held_crop) = tr.crop.filter(|_| tr.extent == extent)
        {
            // A crop that magnifies nothing (the person fills the frame) shows the person
            // no larger than the whole frame, and thin parts smaller: the whole frame is
            // segmented in its place (the crop's mask alone lost a still T-pose's hands,
            // mask IoU 0.78 where the whole frame's is 0.91).
            let whole = held_crop.s >= 1.0;
            let crop = if whole { WHOLE_FRAME } else { held_crop };
            let m2 = if whole {
                timed(img)?
            } else {
                timed(&crop.apply(img, 3, s))?
            };
            let edge = reaches_inner_edge(&crop, &m2, s, extent);
            if !edge
                && tr.since_full + 1 < tr.full_every
                && let Some(mask) = crop_alone(&crop, &m2, s)
            {
                let people = tr.people;
                if let Some(tr) = track {
                    tr.since_full += 1;
                }
                return Ok((mask, people, Tracked::Crop));
            }
            tracked = Some((crop, held_crop, m2, edge));
        }
        // The whole frame (already segmented when the track's crop was the whole frame).
        let mut mask = match &tracked {
            Some((crop, _, m2, _)) if *crop == WHOLE_FRAME => m2.clone(),
            _ => timed(img)?,
        };
        let people = preprocess::keep_most_prominent(&mut mask, s);
        let mut how = if tracking {
            Tracked::Full
        } else {
            Tracked::Off
        };
        let mut next = None;
        match tracked {
            Some((crop, held_crop, m2, edge)) => {
                // The whole frame's person inside the tracked crop, which holds all of them:
                // the frame keeps the crop's mask alone, as the tracked frames do (a whole
                // frame in the track counts the people and checks the crop).
                let alone = (!edge && inside(&crop, &mask, s))
                    .then(|| crop_alone(&crop, &m2, s))
                    .flatten();
                // The whole frame with the crop's mask taken into it as a second pass: the
                // next crop (which grows past an edge the person reached).
                crop.paste_max(&m2, s, &mut mask);
                preprocess::keep_most_prominent(&mut mask, s);
                next = Crop::from_mask(&mask, s);
                match alone {
                    Some(alone) => {
                        next = next.map(|c| held(held_crop, c));
                        mask = alone;
                    }
                    None => how = Tracked::Lost,
                }
            }
            None => {
                if self.segment_passes >= 2
                    && let Some(crop) = Crop::from_mask(&mask, s)
                {
                    let m2 = timed(&crop.apply(img, 3, s))?;
                    crop.paste_max(&m2, s, &mut mask);
                    preprocess::keep_most_prominent(&mut mask, s);
                }
            }
        }
        if let Some(tr) = track.filter(|_| tracking) {
            tr.crop = next.or_else(|| Crop::from_mask(&mask, s));
            tr.since_full = 0;
            tr.people = people;
            tr.extent = extent;
        }
        Ok((mask, people, how))
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
        self.prepare_tracked(rgb, width, height, info, None)
    }

    /// [`Models::prepare`] of a frame in a sequence: with a [`SegmentTrack`], the second
    /// pass's crop tracked from frame to frame (`info`'s `tracked` says how the frame went).
    pub fn prepare_tracked(
        &self,
        rgb: &[u8],
        width: usize,
        height: usize,
        info: &mut FrameInfo,
        track: Option<&mut SegmentTrack>,
    ) -> Result<(Vec<f32>, Vec<f32>, Crop), FrameError> {
        let ms = |t: std::time::Instant| t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        let img = preprocess::letterbox(rgb, width, height);
        let letterbox_ms = ms(t);
        let mut nets_ms = 0.0;
        let extent = preprocess::letterbox_extent(width, height);
        let (mask, people, tracked) =
            self.person_mask_timed(&img, &mut nets_ms, track.map(|t| (t, extent)))?;
        info.people = people;
        info.tracked = tracked;
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
