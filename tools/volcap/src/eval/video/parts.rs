//! `bench temporal`'s flicker by body part: where on the body the displayed silhouettes
//! change between consecutive frames.
//!
//! Every hit of a frame's crop-cube views (front and side, [`super::Views`]) is labelled
//! with the body part of the true body vertex nearest its point (the simulator's
//! [`volcap_sim::parts::PartLabeler`], the labels `volcap eval` splits its distances by).
//! Between consecutive frames a pixel shown in both counts for the earlier frame's part, one
//! shown in only one frame for that frame's part; per part the IoU is then (pixels shown in
//! both) / (pixels shown in either), front and side counted together, and the *share of the
//! change* is the part's share of the pixels shown in one frame only. A part's IoU reads
//! against its size (a hand is a few hundred pixels, the torso thousands); the share says
//! where the changing pixels are. The pair with the worst side-view IoU (the row's "side
//! IoU worst", the headline of a still scene) gets its own split: the parts' shares of the
//! side pixels that pair changed.

use super::{VFrame, Views};
use glam::Vec3;
use volcap_engine::grid::GridSpec;
use volcap_engine::model::preprocess::Crop;
use volcap_sim::parts::Part;

/// No hit in that column.
const NONE: u8 = u8::MAX;

/// Parts in report order ([`Part::ALL`]).
pub(super) const PARTS: usize = Part::ALL.len();

/// Index of a part in [`Part::ALL`].
pub(super) fn index(p: Part) -> u8 {
    Part::ALL.iter().position(|x| *x == p).unwrap_or(1) as u8
}

/// Fills `v.front_part` / `v.side_part`: per column the part of its hit ([`NONE`] where
/// nothing is hit), the hit's grid point taken to the world as `volcap eval` takes a mesh.
pub(super) fn label(v: &mut Views, spec: GridSpec, crop: Crop, fr: &VFrame) {
    let n = spec.n();
    let cam = fr.oracle.camera.projector();
    let world = |i: usize, j: usize, k: usize| {
        let u = Vec3::new(spec.coord(i), spec.coord(j), spec.coord(k));
        cam.ndc_to_world(fr.to_cam.apply(crop.to_input(u)))
            .as_dvec3()
    };
    v.front_part = vec![NONE; v.front.len()];
    v.side_part = vec![NONE; v.side.len()];
    for j in 0..n {
        for i in 0..n {
            if let Ok(k) = usize::try_from(v.front[j * n + i]) {
                v.front_part[j * n + i] = index(fr.parts.label(world(i, j, k)));
            }
        }
        for k in 0..n {
            if let Ok(i) = usize::try_from(v.side[j * n + k]) {
                v.side_part[j * n + k] = index(fr.parts.label(world(i, j, k)));
            }
        }
    }
}

/// Per part: (pixels shown in both frames, pixels shown in either) of two labelled hit
/// maps (hit: index >= 0). A pixel shown in both counts for `a`'s part, one shown in one
/// frame for that frame's part; a hit without a label (an empty label map) counts nowhere.
pub(super) fn compare_parts(
    a: &[i32],
    a_part: &[u8],
    b: &[i32],
    b_part: &[u8],
) -> [(usize, usize); PARTS] {
    let mut out = [(0usize, 0usize); PARTS];
    let part = |labels: &[u8], at: usize| labels.get(at).map(|&p| p as usize);
    for (at, (&x, &y)) in a.iter().zip(b).enumerate() {
        let p = match (x >= 0, y >= 0) {
            (true, _) => part(a_part, at),
            (false, true) => part(b_part, at),
            (false, false) => None,
        };
        if let Some(slot) = p.and_then(|p| out.get_mut(p)) {
            slot.0 += usize::from(x >= 0 && y >= 0);
            slot.1 += 1;
        }
    }
    out
}

/// A run's per-part flicker over its consecutive pairs.
#[derive(Debug, Default)]
pub(super) struct PartFlicker {
    /// Per part, each pair's IoU (pairs where the part is shown).
    iou: [Vec<f64>; PARTS],
    /// Per part, the pixels shown in one frame of a pair only, summed over the pairs.
    changed: [usize; PARTS],
    /// The pair with the worst side-view IoU: that IoU and its side pixels changed per part.
    worst_side: Option<(f64, [usize; PARTS])>,
    /// That pair's side views ([`super::edges`]).
    worst_pair: Option<ViewPair>,
    /// The same for the front view: the pair of its worst IoU, its front pixels changed per
    /// part, and its front views.
    worst_front: Option<(f64, [usize; PARTS])>,
    worst_front_pair: Option<ViewPair>,
}

/// A pair's views of one direction (side or front) with their part labels, and the index
/// of its first frame.
#[derive(Debug, Clone)]
pub(super) struct ViewPair {
    pub frame: usize,
    pub a: Vec<i32>,
    pub a_part: Vec<u8>,
    pub b: Vec<i32>,
    pub b_part: Vec<u8>,
}

/// Per part: IoU mean, IoU worst, share of the changed pixels, and share of the changed side
/// pixels in the pair of the worst side IoU (`None`: the part never shown; the shares `None`
/// when no pixel changed).
pub(super) type PartFigures = (
    [Option<f64>; PARTS],
    [Option<f64>; PARTS],
    [Option<f64>; PARTS],
    [Option<f64>; PARTS],
);

/// Each count's share of their sum (`None` for every part when the sum is 0).
fn shares(counts: &[usize; PARTS]) -> [Option<f64>; PARTS] {
    let total: usize = counts.iter().sum();
    counts.map(|c| (total > 0).then(|| c as f64 / total as f64))
}

/// A view's pair (per part: shown in both, shown in either) as (its IoU over the parts, its
/// pixels changed per part) where its IoU is below `worst`'s (or there is none yet).
fn worse(
    worst: Option<(f64, [usize; PARTS])>,
    c: &[(usize, usize); PARTS],
) -> Option<(f64, [usize; PARTS])> {
    let (inter, union) = c.iter().fold((0, 0), |acc, x| (acc.0 + x.0, acc.1 + x.1));
    let iou = if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    };
    worst
        .is_none_or(|(w, _)| iou < w)
        .then(|| (iou, c.map(|(i, u)| u - i)))
}

impl PartFlicker {
    /// One consecutive pair of labelled views (`frame`: the index of `v0`'s frame), front
    /// and side counted together.
    pub(super) fn add(&mut self, v0: &Views, v1: &Views, frame: usize) {
        let f = compare_parts(&v0.front, &v0.front_part, &v1.front, &v1.front_part);
        let s = compare_parts(&v0.side, &v0.side_part, &v1.side, &v1.side_part);
        for p in 0..PARTS {
            let (inter, union) = (f[p].0 + s[p].0, f[p].1 + s[p].1);
            if union > 0 {
                self.iou[p].push(inter as f64 / union as f64);
            }
            self.changed[p] += union - inter;
        }
        let pair = |a: &[i32], a_part: &[u8], b: &[i32], b_part: &[u8]| ViewPair {
            frame,
            a: a.to_vec(),
            a_part: a_part.to_vec(),
            b: b.to_vec(),
            b_part: b_part.to_vec(),
        };
        if let Some(w) = worse(self.worst_side, &s) {
            self.worst_side = Some(w);
            self.worst_pair = Some(pair(&v0.side, &v0.side_part, &v1.side, &v1.side_part));
        }
        if let Some(w) = worse(self.worst_front, &f) {
            self.worst_front = Some(w);
            self.worst_front_pair =
                Some(pair(&v0.front, &v0.front_part, &v1.front, &v1.front_part));
        }
    }

    /// The pair of the worst side IoU (the first of equals), if any pair was added.
    pub(super) fn worst_pair(&self) -> Option<&ViewPair> {
        self.worst_pair.as_ref()
    }

    /// The pair of the worst front IoU, and each part's share of the front pixels it
    /// changed (`None` for every part when it changed none).
    pub(super) fn worst_front(&self) -> Option<(&ViewPair, [Option<f64>; PARTS])> {
        let (_, changed) = self.worst_front?;
        Some((self.worst_front_pair.as_ref()?, shares(&changed)))
    }

    pub(super) fn figures(&self) -> PartFigures {
        let mut out: PartFigures = (
            [None; PARTS],
            [None; PARTS],
            shares(&self.changed),
            self.worst_side
                .map_or([None; PARTS], |(_, changed)| shares(&changed)),
        );
        for p in 0..PARTS {
            let v = &self.iou[p];
            if !v.is_empty() {
                out.0[p] = Some(v.iter().sum::<f64>() / v.len() as f64);
                out.1[p] = v.iter().copied().reduce(f64::min);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pixel shown in both frames counts for the first frame's part, one shown in one
    /// frame for that frame's part, an unlabelled run counts nowhere; the figures per part
    /// follow from the counts (f64 reference).
    #[test]
    fn pixels_count_for_the_part_that_shows_them() {
        let (h, t) = (index(Part::Hands), index(Part::Torso));
        // Four columns: both hit (torso in a, hands in b), only a (hands), only b (torso),
        // neither.
        let a = [3, 5, -1, -1];
        let b = [4, -1, 7, -1];
        let c = compare_parts(&a, &[t, h, NONE, NONE], &b, &[h, NONE, t, NONE]);
        assert_eq!(c[t as usize], (1, 2));
        assert_eq!(c[h as usize], (0, 1));
        let sum: usize = c.iter().map(|x| x.1).sum();
        assert_eq!(sum, 3);
        // Without labels nothing is counted.
        assert!(compare_parts(&a, &[], &b, &[]).iter().all(|x| *x == (0, 0)));

        // Two pairs: the hands change in both, the torso in neither.
        let view = |front: Vec<i32>, part: Vec<u8>| Views {
            side: vec![-1; front.len()],
            side_part: vec![NONE; front.len()],
            front_display: vec![],
            side_display: vec![],
            cam_front: vec![],
            cam_side: vec![],
            front,
            front_part: part,
        };
        let v0 = view(vec![1, 1, 1, -1], vec![t, t, h, NONE]);
        let v1 = view(vec![1, 1, 1, 1], vec![t, t, h, h]);
        let v2 = view(vec![1, 1, -1, -1], vec![t, t, NONE, NONE]);
        let mut f = PartFlicker::default();
        f.add(&v0, &v1, 0);
        f.add(&v1, &v2, 1);
        let (mean, worst, share, worst_side) = f.figures();
        let (hi, ti) = (h as usize, t as usize);
        // Hands: 1 of 2 shown in both, then 0 of 2.
        assert!((mean[hi].unwrap() - 0.25f64).abs() < 1e-12, "{mean:?}");
        assert_eq!(worst[hi], Some(0.0));
        assert_eq!((mean[ti], worst[ti]), (Some(1.0), Some(1.0)));
        assert_eq!(share[hi], Some(1.0));
        assert_eq!(share[ti], Some(0.0));
        assert_eq!(mean[index(Part::Feet) as usize], None);
        // The front's worst pair is the second (IoU 2/4 against 3/4), all of it hands.
        let (w, front_share) = f.worst_front().unwrap();
        assert_eq!((w.frame, &w.a, &w.b), (1, &v1.front, &v2.front));
        assert_eq!(front_share[hi], Some(1.0));
        assert_eq!(front_share[ti], Some(0.0));
        // The side views never changed: the worst side pair changed nothing.
        assert_eq!(worst_side, [None; PARTS]);
        // No change at all: no shares.
        let mut g = PartFlicker::default();
        g.add(&v0, &v0, 0);
        assert_eq!(g.figures().2, [None; PARTS]);

        // Side views: the first pair loses a torso pixel of four (IoU 0.75), the second a
        // hand pixel and a foot pixel of three shown (IoU 1/3, the worst): the worst pair's
        // split is the second's, half hands and half feet.
        let fe = index(Part::Feet);
        let side = |hits: Vec<i32>, part: Vec<u8>| Views {
            front: vec![-1; hits.len()],
            front_part: vec![NONE; hits.len()],
            front_display: vec![],
            side_display: vec![],
            cam_front: vec![],
            cam_side: vec![],
            side: hits,
            side_part: part,
        };
        let s0 = side(vec![1, 1, 1, 1, -1], vec![t, t, t, t, NONE]);
        let s1 = side(vec![1, 1, 1, -1, -1], vec![h, fe, t, NONE, NONE]);
        let s2 = side(vec![-1, -1, 1, -1, -1], vec![NONE, NONE, t, NONE, NONE]);
        let mut k = PartFlicker::default();
        k.add(&s0, &s1, 7);
        k.add(&s1, &s2, 8);
        let (_, _, share, worst_side) = k.figures();
        let w = k.worst_pair().unwrap();
        assert_eq!((w.frame, &w.a, &w.b), (8, &s1.side, &s2.side));
        assert_eq!(worst_side[hi], Some(0.5), "{worst_side:?}");
        assert_eq!(worst_side[fe as usize], Some(0.5));
        assert_eq!(worst_side[ti], Some(0.0));
        // Over both pairs: one torso, one hand and one foot pixel changed.
        assert!((share[ti].unwrap() - 1.0 / 3.0).abs() < 1e-12, "{share:?}");
    }
}
