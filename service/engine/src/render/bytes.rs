//! Linear values in [0, 1] to bytes: the render's pixels and the simulator's frames.

/// A unit value to a byte: `(x.clamp(0.0, 1.0) * 255.0).round() as u8` exactly (halves away
/// from zero, NaN to 0), in float arithmetic that vectorizes: `f32::round` is a call into libm
/// on x86-64's baseline and `as u8` a saturating conversion per value (per pixel, that was a
/// third of the simulated camera's frame).
#[inline]
pub fn to_u8(x: f32) -> u8 {
    const MAGIC: f32 = 8_388_608.0; // 2^23: v + 2^23 keeps v's integer part in the mantissa
    let v = x.clamp(0.0, 1.0) * 255.0;
    // Rounded to the nearest integer, halves to even (the FPU's rounding of the sum), exact
    // for v in [0, 255]; its mantissa's low byte is that integer.
    let m = v + MAGIC;
    let r = m - MAGIC;
    // Halves away from zero: an exact half rounded down (to even) goes up one. NaN compares
    // false and its mantissa's low byte is 0.
    let up = u32::from(v - r == 0.5);
    (m.to_bits().wrapping_add(up) & 0xff) as u8
}

/// Linear RGB in [0, 1] to RGB8 by [`to_u8`], row-major as given.
pub fn rgb8(src: &[[f32; 3]]) -> Vec<u8> {
    src.as_flattened().iter().map(|&x| to_u8(x)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `to_u8` is the rounding it replaced, `round(clamp(x) * 255)` in f64 on the same f32
    /// product, on every byte's halfway points and their neighbours, the ends, values
    /// outside [0, 1], infinities and NaN, and a million values drawn over [-0.1, 1.1].
    #[test]
    fn to_u8_rounds_as_f64_does() {
        let reference = |x: f32| {
            let v = x.clamp(0.0, 1.0) * 255.0;
            if v.is_nan() {
                0
            } else {
                (v as f64).round() as u8
            }
        };
        let mut xs = vec![
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            0.0,
            1.0,
            -5.0,
            7.5,
        ];
        for k in 0..=256u32 {
            // The product's halfway points, stepped by ulps either side.
            let half = (k as f32 - 0.5) / 255.0;
            let mut lo = half;
            let mut hi = half;
            for _ in 0..4 {
                xs.extend([lo, hi]);
                lo = f32::from_bits(lo.to_bits().wrapping_sub(1));
                hi = f32::from_bits(hi.to_bits() + 1);
            }
            xs.push(k as f32 / 255.0);
        }
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..1_000_000 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            xs.push(-0.1 + 1.2 * ((state >> 40) as f32 / (1u64 << 24) as f32));
        }
        for x in xs {
            assert_eq!(to_u8(x), reference(x), "x = {x:e} ({:#x})", x.to_bits());
        }
        let px = [[0.0, 0.5, 1.0], [f32::NAN, -1.0, 2.0 / 255.0]];
        assert_eq!(rgb8(&px), [0, 128, 255, 0, 0, 2]);
    }
}
