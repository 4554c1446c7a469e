//! SoftZ: depth as a soft one-hot vector (MonoPort, METHOD.md).
//!
//! `P'z = 0.5 (Pz + 1)`, `k = floor((N - 1) P'z)`, `t = (N - 1) P'z - k`, `Z_k = 1 - t`,
//! `Z_{k+1} = t`, all others 0. Rules at the edges, stated once:
//! * non-finite `Pz` (NaN, +-inf) is **refused** with an error;
//! * finite `Pz` outside `[-1, 1]` is **clamped** to `[-1, 1]`;
//! * at `Pz = 1`, `k = N - 1` and `k + 1` would run past the end: `Z_{N-1} = 1`.
//!
//! The output always sums to 1, has at most two non-zero entries, and is never NaN.

/// Number of SoftZ bins used by the paper and our models.
pub const SOFTZ_BINS: usize = 64;

#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SoftZError {
    #[error("SoftZ depth {0} is not finite")]
    NonFinite(f32),
    #[error("SoftZ needs at least 2 bins, got {0}")]
    TooFewBins(usize),
}

/// Encode `pz` into `out` (its length is N, at least 2).
pub fn soft_z(pz: f32, out: &mut [f32]) -> Result<(), SoftZError> {
    let n = out.len();
    if n < 2 {
        return Err(SoftZError::TooFewBins(n));
    }
    if !pz.is_finite() {
        return Err(SoftZError::NonFinite(pz));
    }
    out.fill(0.0);
    let pz = pz.clamp(-1.0, 1.0);
    let x = 0.5 * (pz + 1.0) * (n - 1) as f32;
    // x in [0, N-1]; integer index, never a float index.
    let k = (x.floor() as usize).min(n - 1);
    if k == n - 1 {
        out[n - 1] = 1.0;
        return Ok(());
    }
    let t = (x - k as f32).clamp(0.0, 1.0);
    out[k] = 1.0 - t;
    out[k + 1] = t;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn enc(pz: f32) -> Vec<f32> {
        let mut v = vec![0.0; SOFTZ_BINS];
        soft_z(pz, &mut v).unwrap();
        v
    }

    #[test]
    fn ends() {
        let v = enc(-1.0);
        assert_eq!(v[0], 1.0);
        assert_eq!(v.iter().sum::<f32>(), 1.0);
        let v = enc(1.0);
        assert_eq!(v[SOFTZ_BINS - 1], 1.0);
        assert_eq!(v.iter().filter(|&&x| x != 0.0).count(), 1);
    }

    #[test]
    fn just_inside_the_ends() {
        let below_one = f32::from_bits(1.0f32.to_bits() - 1);
        let v = enc(below_one);
        let s: f64 = v.iter().map(|&x| x as f64).sum();
        assert!((s - 1.0).abs() < 1e-6);
        assert!(v[SOFTZ_BINS - 1] > 0.999 && v[SOFTZ_BINS - 2] < 1e-3);
        let above_minus_one = f32::from_bits((-1.0f32).to_bits() - 1);
        let v = enc(above_minus_one);
        assert!(v[0] > 0.999);
    }

    #[test]
    fn out_of_range_is_clamped_and_non_finite_refused() {
        assert_eq!(enc(7.0), enc(1.0));
        assert_eq!(enc(-1e30), enc(-1.0));
        let mut v = vec![0.0; 8];
        assert_eq!(
            soft_z(f32::NAN, &mut v).unwrap_err().to_string(),
            "SoftZ depth NaN is not finite"
        );
        assert!(soft_z(f32::INFINITY, &mut v).is_err());
        assert!(soft_z(0.0, &mut v[..1]).is_err());
    }

    #[test]
    fn decodes_back_to_depth() {
        // The expectation sum(k * Z_k) / (N - 1) recovers P'z (f64 reference).
        for i in 0..=1000 {
            let pz = -1.0 + 2.0 * i as f32 / 1000.0;
            let v = enc(pz);
            let e: f64 = v
                .iter()
                .enumerate()
                .map(|(k, &z)| k as f64 * z as f64)
                .sum::<f64>()
                / (SOFTZ_BINS - 1) as f64;
            assert!((e - 0.5 * (pz as f64 + 1.0)).abs() < 1e-5, "{pz}");
            assert!(v.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)));
        }
    }
}
