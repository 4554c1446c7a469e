//! The maps smoothed across pixels ([`FourierMaps::smoothed`]): the shape network predicts
//! every pixel's ray on its own, so neighbouring rows' depth profiles differ by noise that a
//! turned view shows as a serrated outline and streaked sides (the rows' surfaces stepping
//! back and forth). A pass replaces the coefficients of each pixel of the person's thick
//! parts by the 3x3 binomial average (weights 1 2 1 / 2 4 2 / 1 2 1) of the thick parts'
//! pixels around it; the series is linear in its coefficients, so this averages the
//! neighbouring rays' occupancy profiles.
//!
//! A person pixel is one whose ray is more than [`SMOOTH_INSIDE`] inside on average (its
//! `c0`, the series' mean over the depth range in both bases). Only the person's thick parts
//! are smoothed: the person pixels an opening of radius [`SMOOTH_THIN`] keeps
//! ([`smooth_region`]); pixels outside that region are left as they are and never enter a
//! mean, so the outline does not erode into the background and the thin parts (hands,
//! fingers) keep their own profiles. After the passes, a pixel whose smoothed ray would lose
//! one of its own inside runs takes its own coefficients back ([`keep_runs`]: a part in front
//! of the body, an arm pointing at the camera). The GPU backend's
//! `gpu/maps/smooth_region.wgsl`, `smooth.wgsl` and `smooth_keep.wgsl` are the same rule.

use super::FourierMaps;

/// A pixel whose series' mean (`c0`) is above this is a person pixel for [`smooth_pass`].
pub const SMOOTH_INSIDE: f32 = 0.02;

/// Most passes a model may be read with (`[model] map_smooth`, `--map-smooth`).
pub const MAX_SMOOTH_PASSES: u8 = 4;

/// The passes every Fourier model is read with unless told otherwise: measured on the
/// simulated scenes (`volcap bench temporal --setting default+map_smooth=N`, docs/bench/map-smooth).
pub const DEFAULT_SMOOTH_PASSES: u8 = 2;

/// Parts narrower than `2 * SMOOTH_THIN + 1` map pixels are not smoothed: a square opening
/// of this radius of the person pixels leaves them out. Hands' rays lie barely over the
/// surface level, and averaged with their neighbours they fell under it (held-out images,
/// fourier-medium: hands shown 53.8 % unsmoothed, 46.1 % smoothed everywhere, 52.6 % with
/// this; docs/bench/map-smooth). The seeds' thin parts' radius (`seeds::SEED_THIN`).
pub const SMOOTH_THIN: usize = super::seeds::SEED_THIN;

/// The pixels a pass smooths and averages over (`n x n` pixel-interleaved maps of `c`
/// channels, `c0` first): person pixels (`c0` above [`SMOOTH_INSIDE`]) that a square opening
/// of radius [`SMOOTH_THIN`] of the person pixels keeps (the map's own edge does not erode).
/// Passes do not change it: a mean of person pixels' `c0` is above the threshold, and other
/// pixels are copied.
pub fn smooth_region(data: &[f32], c: usize, n: usize) -> Vec<bool> {
    let inside: Vec<bool> = (0..n * n).map(|p| data[p * c] > SMOOTH_INSIDE).collect();
    let thin = super::thin_gate(&inside, n, SMOOTH_THIN);
    inside.iter().zip(thin).map(|(i, t)| *i && !t).collect()
}

/// One pass over pixel-interleaved maps `src` (`n x n` pixels, `c` channels each) into `dst`
/// of the same length: each pixel of `region` ([`smooth_region`]) becomes the 3x3 binomial
/// mean (1 2 1 / 2 4 2 / 1 2 1) of the pixels of `region` around it; the others are copied.
pub fn smooth_pass(src: &[f32], dst: &mut [f32], c: usize, n: usize, region: &[bool]) {
    debug_assert_eq!(src.len(), n * n * c);
    debug_assert_eq!(dst.len(), src.len());
    debug_assert_eq!(region.len(), n * n);
    for y in 0..n {
        for x in 0..n {
            let p = y * n + x;
            let out = &mut dst[p * c..(p + 1) * c];
            if !region[p] {
                out.copy_from_slice(&src[p * c..(p + 1) * c]);
                continue;
            }
            // The weights first, then the mean as a sum of fractions: no partial sum is
            // larger than the largest coefficient, whatever the values.
            let joined = (y.saturating_sub(1)..=(y + 1).min(n - 1))
                .flat_map(|yy| (x.saturating_sub(1)..=(x + 1).min(n - 1)).map(move |xx| (xx, yy)))
                .filter(|(xx, yy)| region[yy * n + xx])
                .map(|(xx, yy)| {
                    let w = if xx == x { 2.0f32 } else { 1.0 } * if yy == y { 2.0 } else { 1.0 };
                    (yy * n + xx, w)
                });
            let w: f32 = joined.clone().map(|(_, w)| w).sum();
            // `w` >= 4: the pixel itself is in the region.
            let inv = 1.0 / w;
            out.fill(0.0);
            for (q, wq) in joined {
                let f = wq * inv;
                for (o, v) in out.iter_mut().zip(&src[q * c..(q + 1) * c]) {
                    *o += f * v;
                }
            }
        }
    }
}

impl FourierMaps {
    /// The maps after `passes` passes of [`smooth_pass`] (0: as they are) over the region
    /// worked out once from the maps as they come ([`smooth_region`]), the pixels that lost
    /// one of their own inside runs given their own back ([`keep_runs`]).
    pub fn smoothed(mut self, passes: u8) -> Self {
        if passes == 0 || self.size == 0 {
            return self;
        }
        let c = 2 * self.k + 1;
        let region = smooth_region(&self.data, c, self.size);
        let own = self.data.clone();
        let mut other = vec![0.0f32; self.data.len()];
        for _ in 0..passes {
            smooth_pass(&self.data, &mut other, c, self.size, &region);
            std::mem::swap(&mut self.data, &mut other);
        }
        let (table, iso) = (self.sample_basis(), self.iso_level());
        keep_runs(&own, &mut self.data, c, &region, &table, iso);
        self
    }
}

/// After the passes: each pixel of `region` whose smoothed ray (`smoothed`) no longer
/// reaches `iso` at any depth of one of its own inside runs (`own`, the maps before the
/// passes, at the 129 depths of `table`, [`FourierMaps::sample_basis`]) takes its own
/// coefficients back. Averaging shortens a ray towards its neighbours'; where a part lies
/// in front of another (a hand or a forearm before the body) or ends along the ray (an arm
/// pointing at the camera), the part's rays lie barely over the level and averaged with
/// the body's around them the part is gone, not smoothed (the 126 held-out images,
/// fourier-medium at 2 passes: hands shown 50.7 % unsmoothed, 46.6 % smoothed without this,
/// 48.5 % with it; docs/bench/map-smooth/keep-runs). The GPU backend's
/// `gpu/maps/smooth_keep.wgsl` is the same rule.
pub(super) fn keep_runs(
    own: &[f32],
    smoothed: &mut [f32],
    c: usize,
    region: &[bool],
    table: &[f32],
    iso: f32,
) {
    // The table channel by channel, its depths padded to whole blocks, so that a ray's values
    // at a block of depths are `c` multiply-adds into accumulators that stay in registers
    // (each depth's sum in the channels' order, as a dot product of its basis would add).
    const BLOCK: usize = 16;
    let depths = table.len() / c.max(1);
    let stride = depths.div_ceil(BLOCK) * BLOCK;
    let mut by_channel = vec![0.0f32; c * stride];
    for (j, b) in table.chunks_exact(c).enumerate() {
        for (ch, v) in b.iter().enumerate() {
            by_channel[ch * stride + j] = *v;
        }
    }
    let mut values = vec![0.0f32; stride];
    for (p, _) in region.iter().enumerate().filter(|(_, r)| **r) {
        let own = &own[p * c..(p + 1) * c];
        for (j0, out) in values.chunks_exact_mut(BLOCK).enumerate() {
            let mut acc = [0.0f32; BLOCK];
            for (o, t) in own.iter().zip(by_channel.chunks_exact(stride)) {
                let t = &t[j0 * BLOCK..(j0 + 1) * BLOCK];
                for (a, t) in acc.iter_mut().zip(t) {
                    *a += o * t;
                }
            }
            out.copy_from_slice(&acc);
        }
        let values = &values[..depths];
        if loses_a_run(values, &smoothed[p * c..(p + 1) * c], table, iso) {
            smoothed[p * c..(p + 1) * c].copy_from_slice(own);
        }
    }
}

/// Whether ray `smoothed` stays under `iso` at every depth of one of the inside runs of a
/// ray whose values at the depths of `table` (`smoothed.len()` basis values each) are
/// `own`: the depths where `own` reaches `iso`.
fn loses_a_run(own: &[f32], smoothed: &[f32], table: &[f32], iso: f32) -> bool {
    let at = |b: &[f32]| smoothed.iter().zip(b).map(|(x, y)| x * y).sum::<f32>();
    // `Some(kept)` inside one of `own`'s runs: whether `smoothed` reached the level in it.
    let mut run: Option<bool> = None;
    for (v, b) in own.iter().zip(table.chunks_exact(smoothed.len())) {
        if *v >= iso {
            run = Some(run == Some(true) || at(b) >= iso);
        } else if run.take() == Some(false) {
            return true;
        }
    }
    run == Some(false)
}

#[cfg(test)]
mod tests {
    use super::super::{Basis, interval_coeffs, sample_basis};
    use super::*;

    /// Maps of `n x n` pixels with K = 1 whose pixel `(x, y)` has the coefficients `f(x, y)`.
    fn maps(n: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> FourierMaps {
        let mut d = Vec::new();
        for y in 0..n {
            for x in 0..n {
                d.extend(f(x, y));
            }
        }
        FourierMaps::from_interleaved(d, 1, n, 1.0).unwrap()
    }

    /// The region written from its definition: a person pixel that lies in some window of
    /// radius [`SMOOTH_THIN`] (clipped to the map) whose pixels are all a person's.
    fn reference_region(m: &FourierMaps) -> Vec<bool> {
        let n = m.size() as i64;
        let r = SMOOTH_THIN as i64;
        let inside = |x: i64, y: i64| m.pixel(x as usize, y as usize)[0] > SMOOTH_INSIDE;
        let window_full = |cx: i64, cy: i64| {
            (cy - r..=cy + r)
                .flat_map(|y| (cx - r..=cx + r).map(move |x| (x, y)))
                .filter(|&(x, y)| x >= 0 && y >= 0 && x < n && y < n)
                .all(|(x, y)| inside(x, y))
        };
        let mut out = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let in_full = (y - r..=y + r)
                    .flat_map(|cy| (x - r..=x + r).map(move |cx| (cx, cy)))
                    .filter(|&(cx, cy)| cx >= 0 && cy >= 0 && cx < n && cy < n)
                    .any(|(cx, cy)| window_full(cx, cy));
                out.push(inside(x, y) && in_full);
            }
        }
        out
    }

    /// The pass in f64, written from the definition (a weighted mean over the 3x3
    /// neighbours in the region).
    fn reference(m: &FourierMaps, region: &[bool]) -> Vec<f64> {
        let (n, c) = (m.size(), 2 * m.k() + 1);
        let mut out = Vec::new();
        for y in 0..n as i64 {
            for x in 0..n as i64 {
                let me = m.pixel(x as usize, y as usize);
                if !region[y as usize * n + x as usize] {
                    out.extend(me.iter().map(|v| *v as f64));
                    continue;
                }
                let (mut acc, mut w) = (vec![0.0f64; c], 0.0f64);
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (xx, yy) = (x + dx, y + dy);
                        if xx < 0 || yy < 0 || xx >= n as i64 || yy >= n as i64 {
                            continue;
                        }
                        if !region[yy as usize * n + xx as usize] {
                            continue;
                        }
                        let q = m.pixel(xx as usize, yy as usize);
                        let wq = ((2 - dx.abs()) * (2 - dy.abs())) as f64;
                        w += wq;
                        for (a, v) in acc.iter_mut().zip(q) {
                            *a += wq * *v as f64;
                        }
                    }
                }
                out.extend(acc.iter().map(|a| a / w));
            }
        }
        out
    }

    /// A 28 x 28 map: a 16 x 16 block of person pixels with varied coefficients (the torso)
    /// with a hole at the threshold itself and one of a negative mean, a bar two pixels wide
    /// off its side (an arm), a 5 x 5 square apart (a hand), the rest empty.
    fn body() -> FourierMaps {
        maps(28, |x, y| {
            let v = (x * 7 + y * 3) as f32;
            let varied = [0.2 + 0.01 * v, (v * 0.37).sin(), (v * 0.11).cos()];
            if (x, y) == (15, 15) {
                [SMOOTH_INSIDE, 9.0, 9.0]
            } else if (x, y) == (14, 3) {
                [-0.3, 1.0, 1.0]
            } else if (2..18).contains(&x) && (2..18).contains(&y)
                || (18..25).contains(&x) && (6..8).contains(&y)
                || (21..26).contains(&x) && (20..25).contains(&y)
            {
                varied
            } else {
                [0.0, 0.5, -0.5]
            }
        })
    }

    #[test]
    fn the_region_is_the_opened_person_and_a_pass_its_weighted_mean() {
        let m = body();
        let n = m.size();
        let c = 2 * m.k() + 1;
        let region = smooth_region(m.coefficients(), c, n);
        assert_eq!(region, reference_region(&m));
        // The block's pixels away from its holes are in it; the bar, the small square, the
        // holes and the background are not.
        assert!(region[4 * n + 4] && region[12 * n + 12]);
        for (x, y) in [
            (20, 6),
            (20, 7),
            (23, 22),
            (15, 15),
            (14, 3),
            (0, 0),
            (26, 1),
        ] {
            assert!(!region[y * n + x], "({x}, {y})");
        }
        let want = reference(&m, &region);
        let got = m.clone().smoothed(1);
        for (i, (g, w)) in got.coefficients().iter().zip(&want).enumerate() {
            assert!((*g as f64 - w).abs() < 1e-5, "value {i}: {g} vs {w}");
        }
        // Pixels outside the region kept to the bit; one inside changed.
        for p in (0..n * n).filter(|p| !region[*p]) {
            assert_eq!(got.pixel(p % n, p / n), m.pixel(p % n, p / n), "pixel {p}");
        }
        assert_ne!(got.pixel(5, 5), m.pixel(5, 5));
        // Passes keep the region; two passes are the pass twice, then each pixel whose
        // smoothed ray lost one of its own runs given its own back (K = 1 rays at the
        // default level 0.5: some are); none leaves the maps alone.
        assert_eq!(smooth_region(got.coefficients(), c, n), region);
        let (mut a, mut b) = (m.coefficients().to_vec(), vec![0.0; n * n * c]);
        for _ in 0..2 {
            smooth_pass(&a, &mut b, c, n, &region);
            std::mem::swap(&mut a, &mut b);
        }
        let two = m.clone().smoothed(2);
        let table = sample_basis(Basis::Fourier, 1);
        let mut given_back = 0;
        for p in 0..n * n {
            let (own, passes) = (m.pixel(p % n, p / n), &a[p * c..(p + 1) * c]);
            let lost =
                region[p] && loses_a_run(&values(own, &table), passes, &table, m.iso_level());
            given_back += usize::from(lost);
            let want = if lost { own } else { passes };
            assert_eq!(two.pixel(p % n, p / n), want, "pixel {p}");
        }
        assert!(
            given_back > 0 && given_back < 100,
            "{given_back} given back"
        );
        assert_eq!(m.clone().smoothed(0).coefficients(), m.coefficients());
    }

    #[test]
    fn thin_parts_keep_their_profiles_while_the_thick_one_is_smoothed() {
        // The arm (2 px) and the hand (5 px) of `body` are narrower than an opening of
        // radius SMOOTH_THIN keeps: their rays decode as the network gave them, after any
        // number of passes, while the torso's noise is averaged.
        let m = body();
        let s = m.clone().smoothed(MAX_SMOOTH_PASSES);
        for (x, y) in (18..25)
            .flat_map(|x| (6..8).map(move |y| (x, y)))
            .chain((21..26).flat_map(|x| (20..25).map(move |y| (x, y))))
        {
            assert_eq!(s.pixel(x, y), m.pixel(x, y), "({x}, {y})");
        }
        let changed = (4..14)
            .flat_map(|x| (4..12).map(move |y| (x, y)))
            .filter(|&(x, y)| s.pixel(x, y) != m.pixel(x, y))
            .count();
        assert!(changed > 60, "{changed} of 80 torso pixels changed");
    }

    #[test]
    fn a_part_one_pixel_wide_keeps_its_profile_and_the_outline_stays() {
        // A vertical strip one pixel wide (a finger) and a 3-wide bar, on empty maps: both
        // narrower than the region's opening, so passes leave their coefficients and the
        // rays they decode as they are, and the empty pixels stay empty.
        let n = 9;
        let m = maps(n, |x, _| match x {
            2 => [0.3, 0.4, -0.2],
            5..=7 => [0.5, 0.1, 0.3],
            _ => [0.0, 0.0, 0.0],
        });
        let s = m.clone().smoothed(3);
        for (a, b) in s.coefficients().iter().zip(m.coefficients()) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        let mut scratch = Vec::new();
        let pts: Vec<glam::Vec3> = (0..n)
            .flat_map(|x| (0..9).map(move |z| (x, z)))
            .map(|(x, z)| {
                let u = -1.0 + 2.0 * x as f32 / (n - 1) as f32;
                glam::Vec3::new(u, 0.1, -0.8 + 0.2 * z as f32)
            })
            .collect();
        let (mut a, mut b) = (vec![0.0; pts.len()], vec![0.0; pts.len()]);
        m.occupancy(&pts, &mut a, &mut scratch);
        s.occupancy(&pts, &mut b, &mut scratch);
        assert!(a.iter().any(|v| *v > 0.5));
        for (a, b) in a.iter().zip(&b) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn row_to_row_noise_shrinks_and_a_constant_field_stays() {
        // Rows alternating between two profiles (the serration a turned view shows): a pass
        // takes the difference between neighbouring rows down by half or more; a uniform
        // inside region is a fixed point.
        let n = 12;
        let m = maps(n, |_, y| {
            if y % 2 == 0 {
                [0.4, 0.2, 0.1]
            } else {
                [0.4, 0.0, 0.3]
            }
        });
        let s = m.clone().smoothed(1);
        let diff = |m: &FourierMaps, y: usize| {
            let (a, b) = (m.pixel(5, y), m.pixel(5, y + 1));
            a.iter()
                .zip(b)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max)
        };
        for y in 1..n - 2 {
            assert!(diff(&s, y) <= 0.5 * diff(&m, y) + 1e-6, "row {y}");
        }
        let flat = maps(n, |_, _| [0.35, -0.1, 0.25]);
        let f = flat.clone().smoothed(2);
        for (a, b) in f.coefficients().iter().zip(flat.coefficients()) {
            assert!((a - b).abs() < 1e-6);
        }
    }

    /// A ray's values at the depths of `table`, each a dot product in the channels' order.
    fn values(coeffs: &[f32], table: &[f32]) -> Vec<f32> {
        table
            .chunks_exact(coeffs.len())
            .map(|b| coeffs.iter().zip(b).map(|(x, y)| x * y).sum())
            .collect()
    }

    /// The inside runs of `coeffs` (K = `k`, the Fourier basis) at the 129 sampled depths,
    /// decoded in f64: `(first, last)` sample of each run where the series reaches `iso`.
    fn runs_f64(coeffs: &[f32], k: usize, iso: f64) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let mut start = None;
        for i in 0..=129 {
            let inside = i < 129 && {
                let z = -1.0 + 2.0 * i as f64 / 128.0;
                let mut v = coeffs[0] as f64;
                for m in 1..=k {
                    let a = m as f64 * std::f64::consts::PI * z;
                    v += coeffs[2 * m - 1] as f64 * a.cos() + coeffs[2 * m] as f64 * a.sin();
                }
                v >= iso
            };
            match (inside, start) {
                (true, None) => start = Some(i),
                (false, Some(s0)) => {
                    out.push((s0, i - 1));
                    start = None;
                }
                _ => {}
            }
        }
        out
    }

    #[test]
    fn a_part_in_front_of_the_body_keeps_its_rays() {
        // A 16 x 16 body at depths [-0.3, 0.1] (K = 15, level 0.5) with a 2 x 2 patch of rays
        // that also pass a part in front of it, 0.1 thick at [-0.8, -0.7] (a hand before the
        // torso): averaged with the body's rays around it, the part falls under the level; the
        // patch keeps its own coefficients, and the part its runs. Every other pixel is the
        // plain passes' result, and the body's rays keep their single run.
        let (k, n, c) = (15usize, 16usize, 31usize);
        let body = interval_coeffs(&[[-0.3, 0.1]], k);
        let both = interval_coeffs(&[[-0.8, -0.7], [-0.3, 0.1]], k);
        let patch = |x: usize, y: usize| (7..9).contains(&x) && (7..9).contains(&y);
        let mut d = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let src = if patch(x, y) { &both } else { &body };
                d.extend(src.iter().map(|v| *v as f32));
            }
        }
        let m = FourierMaps::from_interleaved(d, k, n, 1.0)
            .unwrap()
            .with_iso_level(0.5);
        let p = 7 * n + 7;
        let own = m.pixel(7, 7).to_vec();
        assert_eq!(
            runs_f64(&own, k, 0.5).len(),
            2,
            "the patch's own rays pass the part"
        );
        // The passes alone (the region is every pixel: the body fills the map).
        let region = smooth_region(m.coefficients(), c, n);
        assert!(region.iter().all(|r| *r));
        let (mut a, mut b) = (m.coefficients().to_vec(), vec![0.0; n * n * c]);
        for _ in 0..2 {
            smooth_pass(&a, &mut b, c, n, &region);
            std::mem::swap(&mut a, &mut b);
        }
        assert_eq!(
            runs_f64(&a[p * c..(p + 1) * c], k, 0.5).len(),
            1,
            "the passes alone take the part away"
        );
        let s = m.clone().smoothed(2);
        for y in 0..n {
            for x in 0..n {
                let q = y * n + x;
                let got = s.pixel(x, y);
                if patch(x, y) {
                    assert_eq!(got, m.pixel(x, y), "({x}, {y}) keeps its own");
                    assert_eq!(runs_f64(got, k, 0.5).len(), 2);
                } else {
                    assert_eq!(got, &a[q * c..(q + 1) * c], "({x}, {y}) smoothed");
                }
            }
        }
        // Without the part, nothing is given back: the passes' result everywhere.
        let plain = FourierMaps::from_interleaved(
            (0..n * n)
                .flat_map(|_| body.iter().map(|v| *v as f32))
                .collect(),
            k,
            n,
            1.0,
        )
        .unwrap()
        .with_iso_level(0.5);
        let flat = plain.clone().smoothed(2);
        for (g, w) in flat.coefficients().iter().zip(plain.coefficients()) {
            assert!((g - w).abs() < 1e-5);
        }
    }

    #[test]
    fn a_run_is_lost_only_where_the_smoothed_ray_misses_every_depth_of_it() {
        // `loses_a_run` against its definition, on K = 1 rays at level 0.5: own = 0.5 +
        // 0.6 cos(pi z) is inside on |z| <= 1/2 (one run of the sampled depths); a smoothed
        // ray that reaches the level at one depth of it keeps it, one inside only beyond it
        // (|z| >= 1/2) loses it.
        let table = sample_basis(Basis::Fourier, 1);
        let own = [0.5f32, 0.6, 0.0];
        let lost = |own: &[f32], smoothed: &[f32]| {
            loses_a_run(&values(own, &table), smoothed, &table, 0.5)
        };
        assert!(!lost(&own, &own));
        // 0.5 - 0.6 cos: inside where own is not.
        assert!(lost(&own, &[0.5, -0.6, 0.0]));
        // Lower and narrower around z = 0 (still reaching 0.5 there): kept.
        assert!(!lost(&own, &[0.2, 0.35, 0.0]));
        // A ray with no runs loses none, whatever the smoothed one.
        assert!(!lost(&[0.1, 0.1, 0.0], &[0.0; 3]));
        assert!(!lost(&[f32::NAN; 3], &[0.0; 3]));
    }

    #[test]
    fn extreme_coefficients_stay_finite() {
        let m = maps(6, |x, y| {
            let big = if (x + y) % 2 == 0 { 1e38 } else { -1e38 };
            [1e38, big, -big]
        });
        let s = m.smoothed(MAX_SMOOTH_PASSES);
        assert!(s.coefficients().iter().all(|v| v.is_finite()));
    }
}
