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
use super::{IMG, InputSpec, ModelError, Net, Precision, meta_of, meta_usize};
use glam::Vec3;
use std::path::{Path, PathBuf};

/// `[1, cos(pi z), sin(pi z), ..., cos(K pi z), sin(K pi z)]` into `out[..2K+1]`.
///
/// One `sin_cos`, then `(c, s)_{k+1} = (c c1 - s s1, s c1 + c s1)`. At `zeta = +-1` the basis is
/// exact: `cos(k pi) = (-1)^k`, `sin(k pi) = 0` (f32's pi is not exactly pi, so these two points
/// are set, not computed). Non-finite `zeta` gives the basis of 0.
#[inline]
pub fn basis(zeta: f32, k: usize, out: &mut [f32]) {
    let zeta = if zeta.is_finite() { zeta } else { 0.0 };
    out[0] = 1.0;
    let (s1, c1) = if zeta.abs() == 1.0 {
        (0.0, -1.0)
    } else {
        (zeta * std::f32::consts::PI).sin_cos()
    };
    let (mut c, mut s) = (c1, s1);
    for i in 0..k {
        out[1 + 2 * i] = c;
        out[2 + 2 * i] = s;
        let (cn, sn) = (c * c1 - s * s1, s * c1 + c * s1);
        c = cn;
        s = sn;
    }
}

/// Which series the maps hold (ONNX metadata `volcap.basis`; absent: `fourier`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Basis {
    /// Full range, period 2 in zeta: `[c0, a_1, b_1, ..., a_K, b_K]`.
    #[default]
    Fourier,
    /// Half-range cosine on `t = (zeta + 1) / 2`: `[c0, a_1, ..., a_2K]`.
    Cosine,
}

impl Basis {
    pub fn name(self) -> &'static str {
        match self {
            Basis::Fourier => "fourier",
            Basis::Cosine => "cosine",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "fourier" => Some(Basis::Fourier),
            "cosine" => Some(Basis::Cosine),
            _ => None,
        }
    }

    /// The 2K + 1 basis values at `zeta` into `out`.
    #[inline]
    pub fn values(self, zeta: f32, k: usize, out: &mut [f32]) {
        match self {
            Basis::Fourier => basis(zeta, k, out),
            Basis::Cosine => cosine_basis(zeta, k, out),
        }
    }

    /// Ground-truth coefficients `[2K+1]` (f64) of the indicator of `intervals` (zeta, each
    /// clipped to [-1, 1]).
    pub fn interval_coeffs(self, intervals: &[[f64; 2]], k: usize) -> Vec<f64> {
        match self {
            Basis::Fourier => interval_coeffs(intervals, k),
            Basis::Cosine => cosine_interval_coeffs(intervals, k),
        }
    }
}

/// `[1, cos(pi t), cos(2 pi t), ..., cos(2K pi t)]` at `t = (zeta + 1) / 2` into
/// `out[..2K+1]`, by the angle-addition recurrence; exact at `t = 0` (all 1) and `t = 1`
/// (`(-1)^n`). Non-finite `zeta` gives the basis of `t = 0.5`.
#[inline]
pub fn cosine_basis(zeta: f32, k: usize, out: &mut [f32]) {
    let zeta = if zeta.is_finite() { zeta } else { 0.0 };
    let t = (zeta + 1.0) * 0.5;
    out[0] = 1.0;
    let (s1, c1) = if t == 0.0 {
        (0.0, 1.0)
    } else if t == 1.0 {
        (0.0, -1.0)
    } else {
        (t * std::f32::consts::PI).sin_cos()
    };
    let (mut c, mut s) = (c1, s1);
    for v in out[1..=2 * k].iter_mut() {
        *v = c;
        let (cn, sn) = (c * c1 - s * s1, s * c1 + c * s1);
        c = cn;
        s = sn;
    }
}

/// Ground-truth half-range cosine coefficients `[2K+1]` (f64) of the indicator of
/// `intervals` (zeta, each clipped to [-1, 1]).
pub fn cosine_interval_coeffs(intervals: &[[f64; 2]], k: usize) -> Vec<f64> {
    let mut out = vec![0.0; 2 * k + 1];
    for iv in intervals {
        let (lo, hi) = (iv[0].clamp(-1.0, 1.0), iv[1].clamp(-1.0, 1.0));
        if hi <= lo {
            continue;
        }
        let (lo, hi) = ((lo + 1.0) * 0.5, (hi + 1.0) * 0.5);
        out[0] += hi - lo;
        for (n, o) in out.iter_mut().enumerate().skip(1) {
            let w = n as f64 * std::f64::consts::PI;
            *o += 2.0 * ((w * hi).sin() - (w * lo).sin()) / w;
        }
    }
    out
}

/// Ground-truth coefficients `[2K+1]` (f64) of the indicator of `intervals` (zeta, each
/// clipped to [-1, 1]).
pub fn interval_coeffs(intervals: &[[f64; 2]], k: usize) -> Vec<f64> {
    let mut out = vec![0.0; 2 * k + 1];
    for iv in intervals {
        let (lo, hi) = (iv[0].clamp(-1.0, 1.0), iv[1].clamp(-1.0, 1.0));
        if hi <= lo {
            continue;
        }
        out[0] += 0.5 * (hi - lo);
        for n in 1..=k {
            let w = n as f64 * std::f64::consts::PI;
            out[2 * n - 1] += ((w * hi).sin() - (w * lo).sin()) / w;
            out[2 * n] += ((w * lo).cos() - (w * hi).cos()) / w;
        }
    }
    out
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
        let c = 2 * k + 1;
        let plane = size * size;
        if size < 2 || planar.len() != c * plane || !zeta_scale.is_finite() || zeta_scale <= 0.0 {
            return None;
        }
        if planar.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut data = vec![0.0f32; c * plane];
        for ch in 0..c {
            for (p, v) in planar[ch * plane..(ch + 1) * plane].iter().enumerate() {
                data[p * c + ch] = *v;
            }
        }
        Some(Self {
            k,
            size,
            zeta_scale,
            data,
            offset: 0.0,
            basis: Basis::Fourier,
        })
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
    pub fn with_peak_relative_level(mut self, frac: f32, min_peak: f32) -> Self {
        if !(frac > 0.0 && frac < 1.0 && min_peak.is_finite()) {
            return self;
        }
        let c = 2 * self.k + 1;
        let iso = self.iso_level();
        let mut b = vec![0.0f32; c];
        // The peak sampled at 129 depths (the series is band-limited to K cycles).
        let zs: Vec<Vec<f32>> = (0..129)
            .map(|i| {
                let mut v = vec![0.0f32; c];
                self.basis
                    .values(-1.0 + 2.0 * i as f32 / 128.0, self.k, &mut v);
                v
            })
            .collect();
        for px in self.data.chunks_exact_mut(c) {
            let mut peak = f32::MIN;
            for v in &zs {
                b.copy_from_slice(v);
                let d: f32 = px.iter().zip(&b).map(|(x, y)| x * y).sum();
                peak = peak.max(d);
            }
            // Only rays that would vanish (peak under the level) and hold something.
            if peak >= min_peak && peak < iso {
                // Read at frac * peak: raise the series by iso - frac * peak.
                px[0] += iso - frac * peak;
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
    pub fn occupancy(&self, points: &[Vec3], out: &mut [f32], scratch: &mut Vec<f32>) {
        let c = 2 * self.k + 1;
        scratch.resize(c, 0.0);
        let b = &mut scratch[..c];
        for (o, u) in out.iter_mut().zip(points) {
            let zeta = u.z * self.zeta_scale;
            // NaN zeta fails `is_finite`; beyond the depth range is outside.
            if !zeta.is_finite() || zeta.abs() > 1.0 || !u.x.is_finite() || !u.y.is_finite() {
                *o = 0.0;
                continue;
            }
            self.basis.values(zeta, self.k, b);
            let (idx, w) = taps(self.size, self.size, u.x, u.y);
            let mut acc = 0.0f32;
            for t in 0..4 {
                if w[t] == 0.0 {
                    continue;
                }
                let m = &self.data[idx[t] * c..(idx[t] + 1) * c];
                let mut d = 0.0f32;
                for (x, y) in m.iter().zip(b.iter()) {
                    d += x * y;
                }
                acc += w[t] * d;
            }
            // The truncated series rings past [0, 1] (Gibbs); occupancy is clamped, which
            // leaves the 0.5 level set unchanged.
            *o = (acc + self.offset).clamp(0.0, 1.0);
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
    /// Experimental: [`FourierMaps::with_peak_relative_level`] `(frac, min_peak)` on every
    /// frame's maps (`volcap eval --peak-level`); off by default.
    pub peak_level: Option<(f32, f32)>,
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
            peak_level: None,
        })
    }

    /// The coefficient maps of an encoder input `[4, S, S]`; non-finite output is refused.
    pub fn maps(&self, x: &[f32]) -> Result<FourierMaps, ModelError> {
        let s = INPUT_SIZE;
        let planar = self.net.run(&[(&[1, 4, s, s], x)])?;
        FourierMaps::from_planar(&planar, self.k, self.size, self.zeta_scale)
            .map(|m| {
                let m = m.with_iso_level(self.iso_level).with_basis(self.basis);
                match self.peak_level {
                    Some((frac, min_peak)) => m.with_peak_relative_level(frac, min_peak),
                    None => m,
                }
            })
            .ok_or_else(|| ModelError::Run {
                path: self.net.path().display().to_string(),
                msg: "non-finite Fourier coefficients".into(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn basis64(z: f64, k: usize) -> Vec<f64> {
        let mut v = vec![1.0];
        for n in 1..=k {
            let a = n as f64 * std::f64::consts::PI * z;
            v.push(a.cos());
            v.push(a.sin());
        }
        v
    }

    #[test]
    fn recurrence_matches_f64_trig_and_is_exact_at_the_ends() {
        for k in [7usize, 15, 31] {
            let mut b = vec![0.0f32; 2 * k + 1];
            for i in 0..=400 {
                let z = -1.0 + 2.0 * i as f64 / 400.0;
                basis(z as f32, k, &mut b);
                let r = basis64(z as f32 as f64, k);
                for (x, y) in b.iter().zip(&r) {
                    assert!(
                        (*x as f64 - y).abs() < 2e-5 * k as f64,
                        "k {k} z {z}: {x} vs {y}"
                    );
                }
            }
            for z in [-1.0f32, 1.0] {
                basis(z, k, &mut b);
                assert_eq!(b[0], 1.0);
                for n in 1..=k {
                    let sign = if n % 2 == 0 { 1.0 } else { -1.0 };
                    assert_eq!(b[2 * n - 1], sign, "cos({n} pi) at {z}");
                    assert_eq!(b[2 * n], 0.0, "sin({n} pi) at {z}");
                }
            }
            for z in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
                basis(z, k, &mut b);
                assert!(b.iter().all(|v| v.is_finite()));
            }
        }
    }

    /// The coefficients are the L2 projection of the indicator: the series converges to it
    /// (away from the edges) and crosses 0.5 at the edges of a wide interval.
    #[test]
    fn series_of_interval_coefficients_reconstructs_the_indicator() {
        let iv = [[-0.6, -0.2], [0.1, 0.5]];
        for k in [15usize, 31, 63] {
            let c = interval_coeffs(&iv, k);
            let cf: Vec<f32> = c.iter().map(|v| *v as f32).collect();
            let maps = FourierMaps::from_planar(
                &cf.iter().flat_map(|v| [*v; 4]).collect::<Vec<_>>(),
                k,
                2,
                1.0,
            )
            .unwrap();
            let mut out = [0.0f32];
            let mut s = Vec::new();
            let mut worst: f32 = 0.0;
            for i in 0..=200 {
                let z = -1.0 + 2.0 * i as f32 / 200.0;
                let dist = iv
                    .iter()
                    .flat_map(|w| [(w[0] as f32 - z).abs(), (w[1] as f32 - z).abs()])
                    .fold(f32::MAX, f32::min);
                maps.occupancy(&[Vec3::new(0.3, -0.2, z)], &mut out, &mut s);
                let truth = iv.iter().any(|w| w[0] as f32 <= z && z <= w[1] as f32);
                // Away from an edge by a few wavelengths the partial sum is on the right side.
                if dist > 4.0 / k as f32 {
                    assert_eq!(out[0] > 0.5, truth, "k {k} z {z}: {}", out[0]);
                    worst = worst.max((out[0] - truth as u8 as f32).abs());
                }
            }
            assert!(worst < 0.2, "k {k}: worst error {worst}");
            // At an edge of a wide interval the series is 1/2 (Gibbs is symmetric there).
            maps.occupancy(&[Vec3::new(0.0, 0.0, 0.1)], &mut out, &mut s);
            assert!((out[0] - 0.5).abs() < 0.06, "k {k}: edge value {}", out[0]);
        }
        // Outside the depth range: 0; non-finite: 0.
        let maps = FourierMaps::from_planar(&[1.0; 4], 0, 2, 1.0).unwrap();
        let mut out = [9.0f32; 3];
        let pts = [
            Vec3::new(0.0, 0.0, 1.01),
            Vec3::new(0.0, 0.0, f32::NAN),
            Vec3::new(f32::INFINITY, 0.0, 0.0),
        ];
        maps.occupancy(&pts, &mut out, &mut Vec::new());
        assert_eq!(out, [0.0; 3]);
    }

    /// The cosine basis against f64 trig, exact at both ends of the depth range; its
    /// coefficients against a numerical integral of the indicator (f64 midpoint rule); its
    /// series reconstructs the indicator through `FourierMaps` like the full one, and an
    /// interval touching an end of the range is reproduced there without the full series'
    /// jump (the cosine's even extension is continuous at the ends).
    #[test]
    fn cosine_basis_coefficients_and_reconstruction() {
        for k in [7usize, 15, 31] {
            let mut b = vec![0.0f32; 2 * k + 1];
            for i in 0..=400 {
                let z = -1.0 + 2.0 * i as f64 / 400.0;
                cosine_basis(z as f32, k, &mut b);
                let t = (z as f32 as f64 + 1.0) * 0.5;
                for (n, x) in b.iter().enumerate() {
                    let y = (n as f64 * std::f64::consts::PI * t).cos();
                    assert!(
                        (*x as f64 - y).abs() < 3e-5 * k as f64,
                        "k {k} z {z} n {n}: {x} vs {y}"
                    );
                }
            }
            cosine_basis(-1.0, k, &mut b);
            assert!(b.iter().all(|v| *v == 1.0));
            cosine_basis(1.0, k, &mut b);
            for (n, v) in b.iter().enumerate() {
                assert_eq!(*v, if n % 2 == 0 { 1.0 } else { -1.0 });
            }
            cosine_basis(f32::NAN, k, &mut b);
            assert!(b.iter().all(|v| v.is_finite()));
        }
        let iv = [[-0.6, -0.2], [0.1, 0.5]];
        let k = 15;
        let c = cosine_interval_coeffs(&iv, k);
        let m = 200_000;
        for (n, cn) in c.iter().enumerate() {
            // a_n = 2 * int_0^1 f(t) cos(n pi t) dt, and c0 = a_0 / 2.
            let integral: f64 = (0..m)
                .map(|i| {
                    let t = (i as f64 + 0.5) / m as f64;
                    let z = 2.0 * t - 1.0;
                    let f = iv.iter().any(|w| w[0] <= z && z <= w[1]) as u8 as f64;
                    f * (n as f64 * std::f64::consts::PI * t).cos() / m as f64
                })
                .sum();
            let want = if n == 0 { integral } else { 2.0 * integral };
            assert!((cn - want).abs() < 1e-4, "n {n}: {cn} vs {want}");
        }
        assert_eq!(Basis::Cosine.interval_coeffs(&iv, k), c);
        assert_eq!(
            Basis::Fourier.interval_coeffs(&iv, k),
            interval_coeffs(&iv, k)
        );
        // Through the maps, with an interval touching the back end of the range.
        let iv = [[-1.0, -0.7], [0.1, 0.5]];
        for k in [15usize, 31] {
            let decode = |basis: Basis, z: f32| {
                let c = basis.interval_coeffs(&iv, k);
                let cf: Vec<f32> = c.iter().map(|v| *v as f32).collect();
                let maps = FourierMaps::from_planar(
                    &cf.iter().flat_map(|v| [*v; 4]).collect::<Vec<_>>(),
                    k,
                    2,
                    1.0,
                )
                .unwrap()
                .with_basis(basis);
                assert_eq!(maps.basis(), basis);
                let mut out = [0.0f32];
                maps.occupancy(&[Vec3::new(0.1, 0.2, z)], &mut out, &mut Vec::new());
                out[0]
            };
            for i in 0..=200 {
                let z = -1.0 + 2.0 * i as f32 / 200.0;
                let dist = iv
                    .iter()
                    .flat_map(|w| [(w[0] as f32 - z).abs(), (w[1] as f32 - z).abs()])
                    .filter(|d| *d > 0.0 || z > -1.0)
                    .fold(f32::MAX, f32::min);
                let truth = iv.iter().any(|w| w[0] as f32 <= z && z <= w[1] as f32);
                if dist > 4.0 / k as f32 {
                    let v = decode(Basis::Cosine, z);
                    assert_eq!(v > 0.5, truth, "cosine k {k} z {z}: {v}");
                }
            }
            // At the back end, inside: the cosine series is about 1, the full series about
            // 1/2 (its periodic extension jumps there).
            assert!(decode(Basis::Cosine, -0.999) > 0.9, "cosine at the end");
            assert!(
                (decode(Basis::Fourier, -1.0) - 0.5).abs() < 0.1,
                "fourier at the end"
            );
        }
        assert_eq!(Basis::parse("cosine"), Some(Basis::Cosine));
        assert_eq!(Basis::parse("fourier"), Some(Basis::Fourier));
        assert_eq!(Basis::parse("chebyshev"), None);
    }

    /// A level under 0.5 widens the decoded interval by where the series crosses that level
    /// (a blurred thin part comes back), a level above narrows it; occupancy stays in [0, 1]
    /// and the default is the series' own 0.5 crossing.
    #[test]
    fn iso_level_moves_the_surface_to_that_level_of_the_series() {
        let k = 15;
        // A thin interval, its series scaled as a blurring regression would leave it: peak
        // well under 1, so at 0.5 it decodes narrower than it is.
        let c: Vec<f32> = interval_coeffs(&[[-0.1, 0.1]], k)
            .iter()
            .map(|v| 0.6 * *v as f32)
            .collect();
        let planar: Vec<f32> = c.iter().flat_map(|v| [*v; 4]).collect();
        let raw = FourierMaps::from_planar(&planar, k, 2, 1.0).unwrap();
        assert_eq!(raw.iso_level(), 0.5);
        let width = |m: &FourierMaps| {
            let (mut out, mut s, mut n) = ([0.0f32], Vec::new(), 0);
            for i in 0..=2000 {
                let z = -1.0 + 2.0 * i as f32 / 2000.0;
                m.occupancy(&[Vec3::new(0.1, 0.1, z)], &mut out, &mut s);
                assert!((0.0..=1.0).contains(&out[0]), "{}", out[0]);
                n += (out[0] > 0.5) as usize;
            }
            n as f64 / 1000.0
        };
        let (w_raw, w_low, w_high) = (
            width(&raw),
            width(&raw.clone().with_iso_level(0.3)),
            width(&raw.clone().with_iso_level(0.58)),
        );
        assert!(w_low > w_raw && w_raw > w_high, "{w_low} {w_raw} {w_high}");
        // The level-0.3 surface is where the series equals 0.3: check one crossing in f64.
        let series = |z: f64| -> f64 {
            let mut b = vec![0.0f32; 2 * k + 1];
            basis(z as f32, k, &mut b);
            c.iter()
                .zip(&b)
                .map(|(x, y)| (*x as f64) * (*y as f64))
                .sum()
        };
        let edge = w_low / 2.0;
        assert!(
            (series(edge) - 0.3).abs() < 0.02,
            "series at the edge {}",
            series(edge)
        );
    }

    /// The peak-relative level brings back a thin part whose blurred series peaks under the
    /// surface level, at half its peak (about its true width), and leaves alone a thick part
    /// (peak over the level / frac) and an empty ray (peak under `min_peak`).
    #[test]
    fn peak_relative_level_keeps_thin_parts_and_nothing_else() {
        let k = 15;
        let scaled = |iv: [f64; 2], g: f32| -> FourierMaps {
            let c: Vec<f32> = interval_coeffs(&[iv], k)
                .iter()
                .map(|v| g * *v as f32)
                .collect();
            let planar: Vec<f32> = c.iter().flat_map(|v| [*v; 4]).collect();
            FourierMaps::from_planar(&planar, k, 2, 1.0)
                .unwrap()
                .with_iso_level(0.55)
        };
        let inside = |m: &FourierMaps| {
            let (mut out, mut s) = ([0.0f32], Vec::new());
            (0..=2000)
                .filter(|i| {
                    let z = -1.0 + 2.0 * *i as f32 / 2000.0;
                    m.occupancy(&[Vec3::new(0.1, 0.1, z)], &mut out, &mut s);
                    out[0] > 0.5
                })
                .count() as f64
                / 1000.0
        };
        // A thin part (true width 0.2) blurred to a peak of about 0.45: gone at 0.55.
        let thin = scaled([-0.1, 0.1], 0.45);
        assert_eq!(inside(&thin), 0.0);
        let back = inside(&thin.clone().with_peak_relative_level(0.5, 0.2));
        assert!(
            (back - 0.2).abs() < 0.06,
            "thin part decodes {back} wide (0.2 true)"
        );
        // A thick part at full height: unchanged.
        let thick = scaled([-0.5, 0.3], 1.0);
        assert_eq!(
            inside(&thick),
            inside(&thick.clone().with_peak_relative_level(0.5, 0.2))
        );
        // Nearly nothing on the ray: still nothing.
        let faint = scaled([-0.1, 0.1], 0.15);
        assert_eq!(inside(&faint.with_peak_relative_level(0.5, 0.2)), 0.0);
        // Out-of-range knobs leave the maps as they were.
        let same = thin.clone().with_peak_relative_level(1.5, 0.2);
        assert_eq!(same.pixel(0, 0), thin.pixel(0, 0));
    }

    #[test]
    fn maps_refuse_bad_shapes_and_non_finite_values() {
        assert!(FourierMaps::from_planar(&[0.0; 12], 1, 2, 1.0).is_some());
        assert!(FourierMaps::from_planar(&[0.0; 11], 1, 2, 1.0).is_none());
        let mut v = [0.0f32; 12];
        v[5] = f32::NAN;
        assert!(FourierMaps::from_planar(&v, 1, 2, 1.0).is_none());
        assert!(FourierMaps::from_planar(&[0.0; 12], 1, 2, 0.0).is_none());
    }
}
