//! The series' bases (the full Fourier series and FOF-X's half-range cosine series): their
//! values by the angle-addition recurrence, for one point or a block of points side by side,
//! and the ground-truth coefficients of a ray's inside intervals.

/// `(sin, cos)` of the first harmonic at a finite `zeta`, the recurrences' step: `pi zeta`
/// for the full series, `pi t` (`t = (zeta + 1) / 2`) for the cosine one; set, not computed,
/// at the ends of the depth range, where f32's pi would miss `cos(k pi) = (-1)^k`.
#[inline]
fn first_harmonic(kind: Basis, zeta: f32) -> (f32, f32) {
    match kind {
        Basis::Fourier if zeta.abs() == 1.0 => (0.0, -1.0),
        Basis::Fourier => (zeta * std::f32::consts::PI).sin_cos(),
        Basis::Cosine => {
            let t = (zeta + 1.0) * 0.5;
            if t == 0.0 {
                (0.0, 1.0)
            } else if t == 1.0 {
                (0.0, -1.0)
            } else {
                (t * std::f32::consts::PI).sin_cos()
            }
        }
    }
}

/// `[1, cos(pi z), sin(pi z), ..., cos(K pi z), sin(K pi z)]` into `out[..2K+1]`.
///
/// One `sin_cos`, then `(c, s)_{k+1} = (c c1 - s s1, s c1 + c s1)`. At `zeta = +-1` the basis is
/// exact: `cos(k pi) = (-1)^k`, `sin(k pi) = 0` (f32's pi is not exactly pi, so these two points
/// are set, not computed). Non-finite `zeta` gives the basis of 0.
#[inline]
pub fn basis(zeta: f32, k: usize, out: &mut [f32]) {
    let zeta = if zeta.is_finite() { zeta } else { 0.0 };
    out[0] = 1.0;
    let (s1, c1) = first_harmonic(Basis::Fourier, zeta);
    let (mut c, mut s) = (c1, s1);
    for i in 0..k {
        out[1 + 2 * i] = c;
        out[2 + 2 * i] = s;
        let (cn, sn) = (c * c1 - s * s1, s * c1 + c * s1);
        c = cn;
        s = sn;
    }
}

/// Points evaluated side by side by [`super::FourierMaps::occupancy`].
pub(super) const LANES: usize = 8;

/// The basis ([`basis`] or [`cosine_basis`], the same values) of up to [`LANES`] finite
/// `zeta`s into `out[l * c..(l + 1) * c]` (`c = 2K + 1`), their recurrences side by side.
pub(super) fn lane_basis(kind: Basis, zeta: &[f32; LANES], k: usize, c: usize, out: &mut [f32]) {
    let mut c1 = [0.0f32; LANES];
    let mut s1 = [0.0f32; LANES];
    for l in 0..LANES {
        (s1[l], c1[l]) = first_harmonic(kind, zeta[l]);
        out[l * c] = 1.0;
    }
    let (mut cc, mut ss) = (c1, s1);
    let (steps, per) = match kind {
        Basis::Fourier => (k, 2),
        Basis::Cosine => (2 * k, 1),
    };
    for i in 0..steps {
        for l in 0..LANES {
            let o = &mut out[l * c + 1 + per * i..];
            o[0] = cc[l];
            if per == 2 {
                o[1] = ss[l];
            }
        }
        for l in 0..LANES {
            let (cn, sn) = (cc[l] * c1[l] - ss[l] * s1[l], ss[l] * c1[l] + cc[l] * s1[l]);
            cc[l] = cn;
            ss[l] = sn;
        }
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
    out[0] = 1.0;
    let (s1, c1) = first_harmonic(Basis::Cosine, zeta);
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
