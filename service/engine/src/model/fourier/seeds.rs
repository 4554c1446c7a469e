//! Which rays decode ([`FourierMaps::decodes`]), and the maps' inside seeds
//! ([`FourierMaps::seeds`]): where a coarse-to-fine localizer must look even when none of its
//! coarse samples falls inside.

use super::{FourierMaps, centre_weights, thin_gate};
use glam::Vec3;

/// The decoded parts narrower than `2 * SEED_THIN + 1` map pixels give seeds: those an
/// opening of this radius removes from the decoding pixels ([`super::thin_gate`]): arms,
/// hands, legs seen end-on, a person seen sideways. Wider parts hold samples of the coarse
/// levels or border them (the paper's boundary and conflict loop trace them from there).
pub const SEED_THIN: usize = 3;

impl FourierMaps {
    /// Whether each pixel's series reaches the surface level at one of the 129 depths
    /// [`Self::peaks`] samples: the same answer as `peak >= iso`, without scanning every ray.
    /// A ray whose coefficients' absolute sum is under the level cannot reach it (every basis
    /// value lies in [-1, 1]; the background); a Fourier ray that reaches it at the sample
    /// nearest its depth centre (`int z f / int f`) does (most of the body); only the others
    /// are scanned, stopping at the first sample that reaches it.
    pub(super) fn decodes(&self) -> Vec<bool> {
        self.decodes_in(None)
    }

    /// [`Self::decodes`] on the pixels `gate` marks (`size x size`; others false, unread);
    /// `None`: every pixel.
    pub(super) fn decodes_in(&self, gate: Option<&[bool]>) -> Vec<bool> {
        let (k, c) = (self.k, 2 * self.k + 1);
        let iso = self.iso_level();
        let zs = self.sample_basis();
        let at = |px: &[f32], b: &[f32]| px.iter().zip(b).map(|(x, y)| x * y).sum::<f32>();
        let w = centre_weights(k);
        self.data
            .chunks_exact(c)
            .enumerate()
            .map(|(p, px)| {
                if gate.is_some_and(|g| !g.get(p).copied().unwrap_or(false)) {
                    return false;
                }
                // (The margin covers the sum's rounding: a ray at the level is scanned.)
                if px.iter().map(|v| v.abs()).sum::<f32>() + 1e-4 < iso {
                    return false;
                }
                let mass = 2.0 * px[0];
                if self.basis == super::Basis::Fourier && mass > 0.0 {
                    let m1: f32 = (1..=k).map(|m| px[2 * m] * w[m - 1]).sum();
                    let mid = (m1 / mass).clamp(-1.0, 1.0);
                    let i = ((mid + 1.0) * 64.0).round().clamp(0.0, 128.0) as usize;
                    if at(px, &zs[i * c..(i + 1) * c]) >= iso {
                        return true;
                    }
                }
                zs.chunks_exact(c).any(|b| at(px, b) >= iso)
            })
            .collect()
    }

    /// One crop-NDC point per decoding map pixel of a thin part ([`SEED_THIN`]): the pixel's
    /// centre at a depth where its series reaches the surface level, the depth centre of its
    /// inside (`int z f / int f`) where the series reaches it there (most rays), else its
    /// highest of the 129 sampled depths. Every seed is inside at its pixel's centre; pixels
    /// that do not decode give none. Row-major order.
    pub fn seeds(&self) -> Vec<Vec3> {
        self.seeds_in(None)
    }

    /// [`Self::seeds`] from the pixels `gate` marks (`size x size`, e.g. the person's mask:
    /// the field is 0 elsewhere), the others taken as not decoding: most of the cost is the
    /// blurred rays around the silhouette, which a mask leaves out.
    pub fn seeds_in(&self, gate: Option<&[bool]>) -> Vec<Vec3> {
        let (k, c, n) = (self.k, 2 * self.k + 1, self.size);
        if n < 2 || !(self.zeta_scale.is_finite() && self.zeta_scale > 0.0) {
            return Vec::new();
        }
        let solid = self.decodes_in(gate);
        let thin = thin_gate(&solid, n, SEED_THIN);
        let iso = self.iso_level();
        let zs = self.sample_basis();
        let w = centre_weights(k);
        let mut basis = vec![0.0f32; c];
        let at = |px: &[f32], b: &[f32]| px.iter().zip(b).map(|(x, y)| x * y).sum::<f32>();
        let to_ndc = |i: usize| 2.0 * i as f32 / (n - 1) as f32 - 1.0;
        let mut out = Vec::new();
        for (p, px) in self.data.chunks_exact(c).enumerate() {
            if !thin[p] {
                continue;
            }
            let mass = 2.0 * px[0];
            let mut zeta = None;
            if self.basis == super::Basis::Fourier && mass > 0.0 {
                let m1: f32 = (1..=k).map(|m| px[2 * m] * w[m - 1]).sum();
                let mid = (m1 / mass).clamp(-1.0, 1.0);
                self.basis.values(mid, k, &mut basis);
                if at(px, &basis) >= iso {
                    zeta = Some(mid);
                }
            }
            let zeta = zeta.or_else(|| {
                let (i, v) = zs
                    .chunks_exact(c)
                    .map(|b| at(px, b))
                    .enumerate()
                    .fold((0, f32::MIN), |a, (i, v)| if v > a.1 { (i, v) } else { a });
                (v >= iso).then_some(-1.0 + 2.0 * i as f32 / 128.0)
            });
            if let Some(z) = zeta {
                out.push(Vec3::new(to_ndc(p % n), to_ndc(p / n), z / self.zeta_scale));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Basis, FourierMaps};
    use glam::Vec3;

    /// 32 x 32 maps: a 12 x 12 block at depths [-0.3, 0.1], a strip `h` pixels high leaving
    /// it at [0.4, 0.44] (thinner in depth than the series resolves well), the rest empty.
    fn maps_with(h: usize) -> (FourierMaps, usize, usize) {
        let (k, n) = (15, 32);
        let c = 2 * k + 1;
        let mut data = vec![0.0f32; n * n * c];
        for (p, px) in data.chunks_exact_mut(c).enumerate() {
            let (i, j) = (p % n, p / n);
            let iv = if (8..20).contains(&i) && (8..20).contains(&j) {
                [-0.3, 0.1]
            } else if (20..30).contains(&i) && (14..14 + h).contains(&j) {
                [0.4, 0.44]
            } else {
                continue;
            };
            for (v, x) in px.iter_mut().zip(Basis::Fourier.interval_coeffs(&[iv], k)) {
                *v = x as f32;
            }
        }
        (
            FourierMaps::from_interleaved(data, k, n, 2.0).unwrap(),
            n,
            c,
        )
    }

    #[test]
    fn seeds_lie_inside_on_thin_parts_only() {
        let (m, n, _) = maps_with(1);
        let seeds = m.seeds();
        let solid = m.decodes();
        let px = |u: Vec3| {
            let f = |v: f32| ((v + 1.0) * 0.5 * (n - 1) as f32).round() as usize;
            (f(u.x), f(u.y))
        };
        // Every seed is inside, at its pixel's centre, on a decoding pixel.
        let mut occ = vec![0.0; seeds.len()];
        m.occupancy(&seeds, &mut occ, &mut Vec::new());
        for (u, o) in seeds.iter().zip(&occ) {
            let (i, j) = px(*u);
            assert!(*o >= 0.5, "seed {u} reads {o}");
            assert!(solid[j * n + i], "seed {u} on a pixel that does not decode");
        }
        let at: Vec<(usize, usize)> = seeds.iter().map(|u| px(*u)).collect();
        // The strip's pixels that decode all give one (it is thin everywhere), at its depth.
        let strip: Vec<usize> = (20..30).filter(|i| solid[14 * n + i]).collect();
        assert!(strip.len() >= 8, "the strip decodes at {strip:?}");
        for i in &strip {
            let s = seeds[at.iter().position(|p| *p == (*i, 14)).expect("a seed")];
            assert!(
                (s.z * 2.0 - 0.42).abs() < 0.03,
                "strip seed depth {}",
                s.z * 2.0
            );
        }
        // The block (12 pixels a side) gives none: one seed per decoding pixel of the strip.
        assert!(
            !at.iter()
                .any(|(i, j)| (8..20).contains(i) && (8..20).contains(j))
        );
        assert_eq!(seeds.len(), strip.len());
        // Widened to 2 SEED_THIN + 1 pixels the strip is no longer thin: no seeds at all.
        let (wide, _, _) = maps_with(2 * super::SEED_THIN + 1);
        assert!(wide.decodes().iter().filter(|s| **s).count() > 144 + 60);
        assert!(wide.seeds().is_empty());
    }

    #[test]
    fn maps_with_nothing_inside_give_no_seeds() {
        let (k, n) = (7, 8);
        let m = FourierMaps::from_interleaved(vec![0.0; n * n * (2 * k + 1)], k, n, 1.0).unwrap();
        assert!(m.seeds().is_empty());
    }
}
