//! The Fourier occupancy field (FOF, NeurIPS 2022), one definition shared with training
//! (`tools/train/volcap_train/fourier.py`).
//!
//! Every pixel of the crop stores the occupancy along its ray as a truncated Fourier series
//! in the depth coordinate `zeta = zeta_scale * u_z` (crop-NDC depth `u_z`, period 2):
//!
//! `occ(zeta) = c0 + sum_{k=1..K} a_k cos(k pi zeta) + b_k sin(k pi zeta)` for |zeta| <= 1,
//! and 0 outside (the series is periodic there, the body is not).
//!
//! Channel order `[c0, a_1, b_1, ..., a_K, b_K]` (2K + 1). Ground truth from the intervals
//! `[lo, hi]` where a ray is inside: `c0 = sum (hi - lo) / 2`,
//! `a_k = sum (sin(k pi hi) - sin(k pi lo)) / (k pi)`, `b_k = sum (cos(k pi lo) - cos(k pi hi)) / (k pi)`
//! ([`interval_coeffs`], f64).
//!
//! Decoding a point ([`FourierMaps::occupancy`]): the coefficient maps are sampled with the
//! engine's bilinear rule ([`super::sample::taps`], PyTorch's `grid_sample(align_corners=True,
//! border)`) and the basis is evaluated once per point by the angle-addition recurrence
//! ([`basis`]: one `sin_cos`, then two multiply-adds per term; exact at zeta = +-1). The maps are
//! stored pixel-interleaved so a tap reads 2K + 1 contiguous floats: about 4 (2K + 1) + 4K
//! multiply-adds per point (184 for K = 15) instead of an MLP's tens of thousands.
//!
//! [`Basis::Cosine`] (FOF-X): the same 2K + 1 channels hold a half-range cosine series on
//! `t = (zeta + 1) / 2` in [0, 1], `occ(t) = c0 + sum_{n=1..2K} a_n cos(n pi t)` (`c0 = a_0 / 2`);
//! its even extension has no jump between the ends of the depth range, so it rings less for
//! the same count. Ground truth: `c0 = sum (hi - lo)`, `a_n = 2 sum (sin(n pi hi) - sin(n pi lo)) /
//! (n pi)` with `lo, hi` in t. A head says which in its metadata `volcap.basis`.

use super::preprocess::INPUT_SIZE;
use super::sample::taps;
use super::{IMG, InputSpec, ModelError, Net, Precision, all_finite, meta_of, meta_usize};
use glam::Vec3;
use std::path::{Path, PathBuf};

mod basis;
mod seeds;
mod smooth;
pub use basis::{Basis, basis, cosine_basis, cosine_interval_coeffs, interval_coeffs};
use basis::{LANES, lane_basis};
pub use seeds::SEED_THIN;
pub use smooth::{DEFAULT_SMOOTH_PASSES, MAX_SMOOTH_PASSES, SMOOTH_INSIDE, SMOOTH_THIN};

/// A square dilation of radius `r` (Chebyshev) of an `n x n` row-major mask.
fn dilate(m: &[bool], n: usize, r: usize) -> Vec<bool> {
    if r == 0 {
        return m.to_vec();
    }
    // Rows, then columns (a square is separable).
    let mut rows = vec![false; m.len()];
    for y in 0..n {
        for x in 0..n {
            let (a, b) = (x.saturating_sub(r), (x + r).min(n - 1));
            rows[y * n + x] = m[y * n + a..=y * n + b].iter().any(|v| *v);
        }
    }
    let mut out = vec![false; m.len()];
    for y in 0..n {
        let (a, b) = (y.saturating_sub(r), (y + r).min(n - 1));
        for x in 0..n {
            out[y * n + x] = (a..=b).any(|yy| rows[yy * n + x]);
        }
    }
    out
}

/// A square erosion of radius `r` of an `n x n` row-major mask: what [`dilate`] of its
/// outside leaves (the map's own edge does not erode).
fn erode(m: &[bool], n: usize, r: usize) -> Vec<bool> {
    let outside: Vec<bool> = m.iter().map(|v| !v).collect();
    dilate(&outside, n, r).iter().map(|o| !o).collect()
}

/// Per-pixel Fourier coefficients over the crop: `size x size` pixels, `2K + 1` each,
/// pixel-interleaved.
#[derive(Debug, Clone)]
pub struct FourierMaps {
    k: usize,
    size: usize,
    zeta_scale: f32,
    data: Vec<f32>,
    /// Added to every decoded value before the clamp: `0.5 - iso level`, so that the model's
    /// calibrated level set becomes the 0.5 level every field is read at (0 by default).
    offset: f32,
    basis: Basis,
}

impl FourierMaps {
    /// From planar maps `[2K+1, size, size]` (the network's output layout). `None` if the
    /// length does not match or a value is not finite.
    pub fn from_planar(planar: &[f32], k: usize, size: usize, zeta_scale: f32) -> Option<Self> {
        if !Self::fits(planar, k, size, zeta_scale) {
            return None;
        }
        let c = 2 * k + 1;
        let plane = size * size;
        // The transpose in blocks of pixels whose interleaved values stay in the L1 cache
        // (64 pixels x 2K + 1 channels): channel by channel over the whole map, each write
        // touched another cache line of the 2 MB result.
        const BLOCK: usize = 64;
        let mut data = vec![0.0f32; c * plane];
        for (b, out) in data.chunks_mut(BLOCK * c).enumerate() {
            let p0 = b * BLOCK;
            let n = out.len() / c;
            for ch in 0..c {
                let src = &planar[ch * plane + p0..ch * plane + p0 + n];
                for (o, v) in out.iter_mut().skip(ch).step_by(c).zip(src) {
                    *o = *v;
                }
            }
        }
        Some(Self::checked(data, k, size, zeta_scale))
    }

    /// From pixel-interleaved maps `[size * size, 2K + 1]` (the layout the maps keep, as the
    /// GPU backend's frame maps come back). `None` as [`Self::from_planar`].
    pub fn from_interleaved(
        data: Vec<f32>,
        k: usize,
        size: usize,
        zeta_scale: f32,
    ) -> Option<Self> {
        Self::fits(&data, k, size, zeta_scale).then(|| Self::checked(data, k, size, zeta_scale))
    }

    /// Maps whose `data` passed [`Self::fits`].
    fn checked(data: Vec<f32>, k: usize, size: usize, zeta_scale: f32) -> Self {
        Self {
            k,
            size,
            zeta_scale,
            data,
            offset: 0.0,
            basis: Basis::Fourier,
        }
    }

    /// Whether `data` holds maps of order `k` and side `size`, every value finite, with a
    /// usable depth scale.
    fn fits(data: &[f32], k: usize, size: usize, zeta_scale: f32) -> bool {
        let len = (2 * k + 1) * size * size;
        size >= 2
            && data.len() == len
            && zeta_scale.is_finite()
            && zeta_scale > 0.0
            && all_finite(data)
    }

    /// The maps hold `basis`'s coefficients (the same 2K + 1 channels).
    pub fn with_basis(mut self, basis: Basis) -> Self {
        self.basis = basis;
        self
    }

    pub fn basis(&self) -> Basis {
        self.basis
    }

    /// The surface at `occ = iso` of the series instead of 0.5 (a model's calibrated level,
    /// `volcap.iso_level`): decoded values move by `0.5 - iso`, so the rest of the engine
    /// keeps reading "inside" as `> 0.5`. `iso` must lie in (0, 1) ([`FourierNet::load`]
    /// checks the file's).
    pub fn with_iso_level(mut self, iso: f32) -> Self {
        self.offset = 0.5 - iso;
        self
    }

    /// A peak-relative surface for thin parts: where a pixel's series peaks (over its ray)
    /// below `iso` (the ray would decode empty) but at `min_peak` or more, its surface is
    /// read at `frac` of its peak instead of at `iso` (a blurred thin part, a hand or a wrist, peaks under the
    /// global level and would vanish; half its peak is where its blurred edges are). The
    /// shift is folded into the pixel's constant term, so decoding is unchanged. Pixels
    /// peaking under `min_peak` (nothing there) keep `iso`.
    pub fn with_peak_relative_level(self, frac: f32, min_peak: f32) -> Self {
        self.with_peak_relative_level_in(frac, min_peak, None)
    }

    /// [`FourierMaps::with_peak_relative_level`] only on the pixels `gate` marks (`size x
    /// size`, row-major; e.g. those the person mask covers: the blurred halo just outside a
    /// silhouette, which a lower reading would turn into surface, lies outside it). A gate of
    /// another length leaves the maps unchanged.
    pub fn with_peak_relative_level_in(
        mut self,
        frac: f32,
        min_peak: f32,
        gate: Option<&[bool]>,
    ) -> Self {
        if !(frac > 0.0 && frac < 1.0 && min_peak.is_finite())
            || gate.is_some_and(|g| g.len() != self.size * self.size)
        {
            return self;
        }
        let c = 2 * self.k + 1;
        let iso = self.iso_level();
        let peaks = self.peaks();
        for (i, (px, &peak)) in self.data.chunks_exact_mut(c).zip(&peaks).enumerate() {
            // Only rays that would vanish (peak under the level) and hold something.
            if peak >= min_peak && peak < iso && gate.is_none_or(|g| g[i]) {
                // Read at frac * peak: raise the series by iso - frac * peak.
                px[0] += iso - frac * peak;
            }
        }
        self
    }

    /// The surface at `level` instead of the maps' own on the pixels `gate` marks (`size x
    /// size`, row-major; e.g. the person mask eroded by a few map pixels, where the blurred
    /// halo around a silhouette cannot be): folded into each such pixel's constant term, as
    /// [`Self::with_peak_relative_level_in`]. A gate of another length, or a level outside
    /// (0, 1), leaves the maps unchanged.
    pub fn with_level_in(mut self, level: f32, gate: &[bool]) -> Self {
        if !(level > 0.0 && level < 1.0) || gate.len() != self.size * self.size {
            return self;
        }
        let c = 2 * self.k + 1;
        let lift = self.iso_level() - level;
        for (px, _) in self.data.chunks_exact_mut(c).zip(gate).filter(|(_, g)| **g) {
            px[0] += lift;
        }
        self
    }

    /// The basis at the 129 depths the peak tests sample ([`sample_basis`]).
    fn sample_basis(&self) -> Vec<f32> {
        sample_basis(self.basis, self.k)
    }

    /// Each pixel's series at its highest over the ray (at [`Self::sample_basis`]'s depths).
    fn peaks(&self) -> Vec<f32> {
        let c = 2 * self.k + 1;
        let zs = self.sample_basis();
        self.data
            .chunks_exact(c)
            .map(|px| {
                zs.chunks_exact(c)
                    .map(|b| px.iter().zip(b).map(|(x, y)| x * y).sum::<f32>())
                    .fold(f32::MIN, f32::max)
            })
            .collect()
    }

    /// Thin parts from their moments (`volcap eval --moment-fill`, the daemon's `[model]
    /// thin_parts = "moment-fill"`; docs/eval/hands.md section 5): a pixel whose
    /// series peaks under the surface level (its ray would decode empty) yet holds at least
    /// `min_len` (zeta; the range is 2) of inside is a candidate; its series is replaced by
    /// the series of one interval of the ray's own inside length (`2 c0`, at most `max_len`)
    /// at its own depth centre (`int z f / int f`, from the sine terms). A blurred thin part (a hand whose
    /// depth the net is unsure of) keeps its mass and place instead of vanishing, and grows
    /// no wider than its predicted length. Only candidates at least `away` map pixels
    /// (Chebyshev) from any pixel that decodes, and those joined to them within `away - 1`
    /// steps through candidates, are filled: the blurred band just outside every silhouette
    /// (a few pixels wide, a candidate too) stays as it was, while a hand, which reaches
    /// beyond it, comes back. Fourier basis only (other bases are returned unchanged).
    pub fn with_moment_fill(mut self, min_len: f32, max_len: f32, away: usize) -> Self {
        if self.basis != Basis::Fourier
            || !(min_len.is_finite() && min_len > 0.0 && max_len >= min_len)
            || away == 0
        {
            return self;
        }
        let (k, c, n) = (self.k, 2 * self.k + 1, self.size);
        let solid = self.decodes();
        let cand: Vec<bool> = self
            .data
            .chunks_exact(c)
            .zip(&solid)
            .map(|(px, s)| !s && (min_len..=2.0).contains(&(2.0 * px[0])))
            .collect();
        // The seeds: candidates with no decoding pixel within away - 1; then grown back
        // through candidates, one ring a step.
        let near = dilate(&solid, n, away - 1);
        let mut keep: Vec<bool> = cand.iter().zip(&near).map(|(c, s)| *c && !s).collect();
        for _ in 1..away {
            keep = dilate(&keep, n, 1)
                .iter()
                .zip(&cand)
                .map(|(k, c)| *k && *c)
                .collect();
        }
        let w = centre_weights(k);
        for (px, _) in self
            .data
            .chunks_exact_mut(c)
            .zip(&keep)
            .filter(|(_, k)| **k)
        {
            let mass = 2.0 * px[0];
            let m1: f32 = (1..=k).map(|m| px[2 * m] * w[m - 1]).sum();
            let mid = (m1 / mass).clamp(-1.0, 1.0);
            // A ray this unsure of its depth spreads its mass too: at most max_len of it.
            let len = mass.min(max_len);
            let (lo, hi) = (mid - 0.5 * len, mid + 0.5 * len);
            // Kept inside [-1, 1] at its full length.
            let shift = (-1.0 - lo).max(0.0) - (hi - 1.0).max(0.0);
            let iv = [[(lo + shift) as f64, (hi + shift) as f64]];
            for (p, v) in px.iter_mut().zip(interval_coeffs(&iv, k)) {
                *p = v as f32;
            }
        }
        self
    }

    /// The level of the series that decodes as 0.5 (0.5 unless [`Self::with_iso_level`]).
    pub fn iso_level(&self) -> f32 {
        0.5 - self.offset
    }

    pub fn k(&self) -> usize {
        self.k
    }

    pub fn size(&self) -> usize {
        self.size
    }

    pub fn zeta_scale(&self) -> f32 {
        self.zeta_scale
    }

    /// Every pixel's coefficients, pixel-interleaved (`[pixel][2K + 1]`, pixel `j * size + i`).
    pub fn coefficients(&self) -> &[f32] {
        &self.data
    }

    /// Every pixel's coefficients, pixel-interleaved (`[pixel][2K + 1]`, pixel `j * size +
    /// i`), for filters that work on the maps ([`super::temporal`]).
    pub fn coefficients_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// The coefficients of pixel `(i, j)`.
    pub fn pixel(&self, i: usize, j: usize) -> &[f32] {
        let c = 2 * self.k + 1;
        let p = j * self.size + i;
        &self.data[p * c..(p + 1) * c]
    }

    /// Occupancy in [0, 1] at crop-NDC points; `scratch` holds the basis. Points outside
    /// the crop's depth range (|zeta| > 1) are 0; non-finite points are 0.
    ///
    /// In blocks of [`LANES`] points: the basis recurrences of a block's points side by side
    /// (independent lanes, not one dependent chain per point), then per point the four taps
    /// blended and dotted with its basis in [`LANES`] running sums (a single running sum per
    /// tap chained every add: 126 -> 91 ns a point on this CPU, `K = 15`).
    pub fn occupancy(&self, points: &[Vec3], out: &mut [f32], scratch: &mut Vec<f32>) {
        let c = 2 * self.k + 1;
        scratch.clear();
        scratch.resize(LANES * c, 0.0);
        let n = points.len().min(out.len());
        for (ob, pb) in out[..n].chunks_mut(LANES).zip(points[..n].chunks(LANES)) {
            let mut zeta = [0.0f32; LANES];
            let mut valid = [false; LANES];
            for (l, u) in pb.iter().enumerate() {
                let z = u.z * self.zeta_scale;
                valid[l] = z.is_finite() && z.abs() <= 1.0 && u.x.is_finite() && u.y.is_finite();
                zeta[l] = if valid[l] { z } else { 0.0 };
            }
            lane_basis(self.basis, &zeta, self.k, c, scratch);
            for (l, (o, u)) in ob.iter_mut().zip(pb).enumerate() {
                if !valid[l] {
                    *o = 0.0;
                    continue;
                }
                let b = &scratch[l * c..(l + 1) * c];
                let (idx, w) = taps(self.size, self.size, u.x, u.y);
                let row = |t: usize| &self.data[idx[t] * c..(idx[t] + 1) * c];
                let (m0, m1, m2, m3) = (row(0), row(1), row(2), row(3));
                let [w0, w1, w2, w3] = w;
                let mut acc = [0.0f32; LANES];
                let chunks = b
                    .chunks_exact(LANES)
                    .zip(m0.chunks_exact(LANES))
                    .zip(m1.chunks_exact(LANES))
                    .zip(m2.chunks_exact(LANES))
                    .zip(m3.chunks_exact(LANES));
                for ((((bb, a0), a1), a2), a3) in chunks {
                    for a in 0..LANES {
                        acc[a] += bb[a] * (w0 * a0[a] + w1 * a1[a] + w2 * a2[a] + w3 * a3[a]);
                    }
                }
                let whole = c / LANES * LANES;
                for j in whole..c {
                    let v = w0 * m0[j] + w1 * m1[j] + w2 * m2[j] + w3 * m3[j];
                    acc[j - whole] += b[j] * v;
                }
                // The truncated series rings past [0, 1] (Gibbs); occupancy is clamped,
                // which leaves the 0.5 level set unchanged.
                let s = acc.iter().sum::<f32>();
                *o = (s + self.offset).clamp(0.0, 1.0);
            }
        }
    }
}

/// Where a Fourier head puts the person along depth (ONNX metadata `volcap.depth_frame`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthFrame {
    /// Trained on depth as the training camera saw it (the crop's z = 0 is the middle of the
    /// camera's near/far range): files without the key.
    Camera,
    /// Trained with each image's mean occupied depth moved to z = 0 (what a single
    /// weak-perspective image can tell): the reconstruction is placed with the person's mean
    /// depth at the crop's z = 0.
    Body,
}

impl DepthFrame {
    pub fn name(self) -> &'static str {
        match self {
            Self::Camera => "camera",
            Self::Body => "body",
        }
    }
}

/// The Fourier occupancy head: one image-to-image network giving the 2K+1 coefficient maps
/// of the occupancy along every crop pixel's ray ([`fourier`]).
pub struct FourierNet {
    pub net: Net,
    /// Series order K.
    pub k: usize,
    /// Side of the coefficient maps.
    pub size: usize,
    /// `zeta = zeta_scale * crop-NDC z`.
    pub zeta_scale: f32,
    pub depth_frame: DepthFrame,
    /// The series level taken as the surface (metadata `volcap.iso_level`, written by the
    /// exporter: calibrated on the training split or chosen from a `volcap eval --iso-level`
    /// sweep on training subjects, see the model card; 0.5 when absent). A smooth fit of the
    /// series crosses 0.5 away from the true surface: below it thin parts shrink, above it
    /// the surface swells.
    pub iso_level: f32,
    /// The series the maps hold (metadata `volcap.basis`, absent: fourier).
    pub basis: Basis,
    /// The segmentation passes of the masks it was trained on (metadata
    /// `volcap.segment_passes`, written by the exporter for a `train --segment-passes 2` run;
    /// absent: 1): [`super::Models::segment_passes`] starts there.
    pub segment_passes: u8,
    /// [`FourierMaps::smoothed`] passes on every frame's maps, before any reading below
    /// ([`DEFAULT_SMOOTH_PASSES`] unless set: `Models::with_map_smooth`).
    pub smooth_passes: u8,
    /// Experimental: [`FourierMaps::with_peak_relative_level`] `(frac, min_peak)` on every
    /// frame's maps (`volcap eval --peak-level`); off by default.
    pub peak_level: Option<(f32, f32)>,
    /// With `peak_level`: only on the map pixels whose person mask (the encoder input's
    /// fourth channel, averaged over the pixel's footprint) reaches this value.
    pub peak_gate: Option<f32>,
    /// [`FourierMaps::with_moment_fill`] `(min_len, max_len, away)` on every frame's maps
    /// (`volcap eval --moment-fill`, `Models::with_moment_fill`); off by default.
    pub moment_fill: Option<(f32, f32, usize)>,
    /// Experimental: [`FourierMaps::with_level_in`] `(level, erode)` on every frame's maps,
    /// gated by the person mask (the encoder input's fourth channel, half its pixel's
    /// footprint or more) eroded by `erode` map pixels (`volcap eval --interior-level`);
    /// off by default.
    pub interior_level: Option<(f32, usize)>,
    /// Experimental: [`FourierMaps::with_level_in`] `(level, radius)` on the thin parts only:
    /// the person mask's map pixels (half their footprint or more) that an opening by
    /// `radius` map pixels removes ([`thin_gate`]: hands, wrists, arms seen edge-on), so the
    /// blurred edges of thick parts keep the model's level (`volcap eval --thin-level`).
    pub thin_level: Option<(f32, usize)>,
}

/// A Fourier file's `volcap.segment_passes` (absent: 1), checked against
/// [`super::SEGMENT_PASSES`].
pub(crate) fn trained_segment_passes(
    path: &Path,
    meta: &std::collections::HashMap<String, String>,
) -> Result<u8, ModelError> {
    match meta.get("volcap.segment_passes") {
        None => Ok(1),
        Some(v) => v
            .parse::<u8>()
            .ok()
            .filter(|n| super::SEGMENT_PASSES.contains(n))
            .ok_or_else(|| ModelError::Mismatch {
                path: path.display().to_string(),
                what: "metadata volcap.segment_passes".into(),
                expected: format!(
                    "{}..={}",
                    super::SEGMENT_PASSES.start(),
                    super::SEGMENT_PASSES.end()
                ),
                found: format!("{v:?}"),
            }),
    }
}

impl FourierNet {
    pub fn path(dir: &Path, name: &str, precision: Precision) -> PathBuf {
        dir.join(format!("shape-{name}.fourier{}.onnx", precision.suffix()))
    }

    pub fn load(dir: &Path, name: &str, precision: Precision) -> Result<Self, ModelError> {
        Self::load_on(dir, name, precision, &super::Runtime::Tract)
    }

    /// [`FourierNet::load`] on `rt`.
    pub fn load_on(
        dir: &Path,
        name: &str,
        precision: Precision,
        rt: &super::Runtime,
    ) -> Result<Self, ModelError> {
        let path = Self::path(dir, name, precision);
        let meta = meta_of(&path);
        let k = meta_usize(&path, &meta, "fourier_k")?;
        let size = meta_usize(&path, &meta, "coeff_size")?;
        let zeta_scale = meta
            .get("volcap.zeta_scale")
            .and_then(|v| v.parse::<f32>().ok())
            .filter(|v| v.is_finite() && *v > 0.0)
            .ok_or_else(|| ModelError::Mismatch {
                path: path.display().to_string(),
                what: "metadata volcap.zeta_scale".into(),
                expected: "a positive number".into(),
                found: format!("{:?}", meta.get("volcap.zeta_scale")),
            })?;
        let depth_frame = match meta.get("volcap.depth_frame").map(String::as_str) {
            None | Some("camera") => DepthFrame::Camera,
            Some("body") => DepthFrame::Body,
            Some(other) => {
                return Err(ModelError::Mismatch {
                    path: path.display().to_string(),
                    what: "metadata volcap.depth_frame".into(),
                    expected: "\"body\" or \"camera\"".into(),
                    found: format!("{other:?}"),
                });
            }
        };
        let iso_level = match meta.get("volcap.iso_level") {
            None => 0.5,
            Some(v) => v
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite() && *x > 0.0 && *x < 1.0)
                .ok_or_else(|| ModelError::Mismatch {
                    path: path.display().to_string(),
                    what: "metadata volcap.iso_level".into(),
                    expected: "a number in (0, 1)".into(),
                    found: format!("{v:?}"),
                })?,
        };
        let basis = match meta.get("volcap.basis") {
            None => Basis::Fourier,
            Some(v) => Basis::parse(v).ok_or_else(|| ModelError::Mismatch {
                path: path.display().to_string(),
                what: "metadata volcap.basis".into(),
                expected: "\"fourier\" or \"cosine\"".into(),
                found: format!("{v:?}"),
            })?,
        };
        let segment_passes = trained_segment_passes(&path, &meta)?;
        let net = Net::load_on(
            &path,
            "shape-fourier",
            &[InputSpec {
                name: "image",
                shape: &IMG,
            }],
            &[Some(1), Some(2 * k + 1), Some(size), Some(size)],
            rt,
        )?;
        Ok(Self {
            net,
            k,
            size,
            zeta_scale,
            depth_frame,
            iso_level,
            basis,
            segment_passes,
            smooth_passes: DEFAULT_SMOOTH_PASSES,
            peak_level: None,
            peak_gate: None,
            moment_fill: None,
            interior_level: None,
            thin_level: None,
        })
    }

    /// The coefficient maps of an encoder input `[4, S, S]`; non-finite output is refused.
    pub fn maps(&self, x: &[f32]) -> Result<FourierMaps, ModelError> {
        let s = INPUT_SIZE;
        let planar = self.net.run(&[(&[1, 4, s, s], x)])?;
        FourierMaps::from_planar(&planar, self.k, self.size, self.zeta_scale)
            .map(|m| {
                let m = m
                    .with_iso_level(self.iso_level)
                    .with_basis(self.basis)
                    .smoothed(self.smooth_passes);
                let m = match self.interior_level {
                    Some((level, r)) => {
                        let mask = mask_gate(&x[3 * s * s..], s, self.size, 0.5);
                        m.with_level_in(level, &erode(&mask, self.size, r))
                    }
                    None => m,
                };
                let m = match self.thin_level {
                    Some((level, r)) => {
                        let mask = mask_gate(&x[3 * s * s..], s, self.size, 0.5);
                        m.with_level_in(level, &thin_gate(&mask, self.size, r))
                    }
                    None => m,
                };
                let m = match self.peak_level {
                    Some((frac, min_peak)) => {
                        let gate = self
                            .peak_gate
                            .map(|t| mask_gate(&x[3 * s * s..], s, self.size, t));
                        m.with_peak_relative_level_in(frac, min_peak, gate.as_deref())
                    }
                    None => m,
                };
                match self.moment_fill {
                    Some((min_len, max_len, away)) => m.with_moment_fill(min_len, max_len, away),
                    None => m,
                }
            })
            .ok_or_else(|| ModelError::Run {
                path: self.net.path().display().to_string(),
                msg: "non-finite Fourier coefficients".into(),
            })
    }
}

/// `basis` of order `k` at the 129 depths the peak tests and the smoothing's kept runs
/// sample (`zeta = -1 + 2 i / 128`: the series is band-limited to K cycles), flat: depth
/// `i`'s is the `i`-th chunk of `2K + 1` (the GPU backend's `gpu/maps/smooth_keep.wgsl`
/// reads this table).
pub fn sample_basis(basis: Basis, k: usize) -> Vec<f32> {
    let c = 2 * k + 1;
    let mut zs = vec![0.0f32; 129 * c];
    for (i, v) in zs.chunks_exact_mut(c).enumerate() {
        basis.values(-1.0 + 2.0 * i as f32 / 128.0, k, v);
    }
    zs
}

/// `int_{-1}^{1} z sin(m pi z) dz = 2 (-1)^(m+1) / (m pi)` for m = 1..=K: a Fourier ray's
/// first moment is the sum of its sine terms times these (the cosine terms give 0).
fn centre_weights(k: usize) -> Vec<f32> {
    (1..=k)
        .map(|m| {
            let sign = if m % 2 == 1 { 1.0 } else { -1.0 };
            2.0 * sign / (m as f32 * std::f32::consts::PI)
        })
        .collect()
}

/// The pixels of an `n x n` mask that its opening (erosion, then dilation, by a square of
/// radius `r`) removes: the parts narrower than `2 r + 1` pixels.
pub fn thin_gate(mask: &[bool], n: usize, r: usize) -> Vec<bool> {
    let opened = dilate(&erode(mask, n, r), n, r);
    mask.iter().zip(opened).map(|(m, o)| *m && !o).collect()
}

/// The `n x n` map pixels whose `s x s` mask, averaged over each pixel's footprint (`s / n`
/// input pixels a side), reaches `t`; all false when `s` is not a multiple of `n` or the mask
/// is short.
pub fn mask_gate(mask: &[f32], s: usize, n: usize, t: f32) -> Vec<bool> {
    let mut out = vec![false; n * n];
    if n == 0 || !s.is_multiple_of(n) || mask.len() < s * s {
        return out;
    }
    let f = s / n;
    for (i, o) in out.iter_mut().enumerate() {
        let (y, x) = (i / n, i % n);
        let sum: f32 = (0..f)
            .flat_map(|dy| (0..f).map(move |dx| (y * f + dy) * s + x * f + dx))
            .map(|j| mask[j])
            .sum();
        *o = sum / (f * f) as f32 >= t;
    }
    out
}

#[cfg(test)]
mod level_tests;
#[cfg(test)]
mod tests;
