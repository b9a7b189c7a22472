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

/// π/2 to 33 significant bits (its low 20 bits zero, so `n · PIO2_HI` is exact for
/// `|n| < 2^20`) and the rest of π/2: the two-part constant of a Cody–Waite reduction.
const PIO2_HI: f64 = 1.570_796_326_734_125_6; // 0x1.921fb544p+0
const PIO2_LO: f64 = 6.077_100_506_506_192e-11; // π/2 − PIO2_HI, rounded

/// Taylor coefficients of sin (r³ … r¹⁷) and cos (r⁴ … r¹⁸): on `|r| ≤ π/4` the first term
/// left out is below 2e-19 of the result, so only the evaluation's rounding remains.
const SIN_COEFFS: [f64; 8] = [
    -1.0 / 6.0,
    1.0 / 120.0,
    -1.0 / 5040.0,
    1.0 / 362_880.0,
    -1.0 / 39_916_800.0,
    1.0 / 6_227_020_800.0,
    -1.0 / 1_307_674_368_000.0,
    1.0 / 355_687_428_096_000.0,
];
const COS_COEFFS: [f64; 8] = [
    1.0 / 24.0,
    -1.0 / 720.0,
    1.0 / 40_320.0,
    -1.0 / 3_628_800.0,
    1.0 / 479_001_600.0,
    -1.0 / 87_178_291_200.0,
    1.0 / 20_922_789_888_000.0,
    -1.0 / 6_402_373_705_728_000.0,
];

/// `(sin x, cos x)` from `+ − × ÷` and `floor` only, so that the CPU and the CUDA twin
/// (`cuda/common.cuh: portable_sin_cos`) give the same bits: libm's sin/cos and CUDA's are
/// each within an ulp or two of the exact values but differ from each other in the last bit
/// for some arguments, which made the GPU's double trajectories leave the CPU's after a few
/// thousand steps (the free rotation takes five of them per particle and step).
///
/// `x = n π/2 + r` with `n = ⌊2x/π + 1/2⌋` and `r = (x − n P₁) − n P₂` (Cody–Waite, `P₁ + P₂ =
/// π/2`, `n P₁` exact for `|n| < 2^20`), skipped for `|x| ≤ π/4`; then the Taylor polynomials
/// of degree 17 (sin) and 18 (cos) in Horner form on `r² `, and the quadrant `n mod 4`.
/// Within 1 ulp of libm for `|x| < 10⁵` (tested); past `|x| ≈ 10⁶` the reduction loses
/// accuracy but stays the same on both backends. A rotation step of that many radians is a
/// blow-up, which the stability guard stops first.
pub fn portable_sin_cos(x: f64) -> (f64, f64) {
    if !x.is_finite() {
        return (f64::NAN, f64::NAN);
    }
    let (n, r) = if x.abs() <= std::f64::consts::FRAC_PI_4 {
        (0.0, x)
    } else {
        let n = (x * std::f64::consts::FRAC_2_PI + 0.5).floor();
        (n, (x - n * PIO2_HI) - n * PIO2_LO)
    };
    let z = r * r;
    let mut ps = SIN_COEFFS[7];
    let mut pc = COS_COEFFS[7];
    for k in (0..7).rev() {
        ps = SIN_COEFFS[k] + z * ps;
        pc = COS_COEFFS[k] + z * pc;
    }
    let s = r + r * z * ps;
    let c = 1.0 - (0.5 * z - z * z * pc);
    // n mod 4 in exact floating point (n is an integer-valued double of any size).
    let quadrant = n - 4.0 * (n * 0.25).floor();
    if quadrant == 0.0 {
        (s, c)
    } else if quadrant == 1.0 {
        (c, -s)
    } else if quadrant == 2.0 {
        (-s, -c)
    } else {
        (-c, s)
    }
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

    /// Within 1 ulp of libm's sin and cos (each within an ulp of the exact values) over
    /// `|x| < 10⁵`, densely near 0 where the free rotation's angles lie, odd/even in x, exact
    /// at 0, NaN for non-finite x.
    #[test]
    fn portable_sin_cos_is_within_an_ulp_of_libm() {
        let mut rng = crate::rng::Rng::new(5);
        // In ulps of the value, or of 1e-3 where the value is smaller: near a zero of sin or
        // cos far from the origin the reduction's absolute error (≈ 1e-21 n) is what counts.
        let ulps = |a: f64, b: f64| (a - b).abs() / (f64::EPSILON * b.abs().max(1e-3));
        let (mut worst_s, mut worst_c) = (0.0f64, 0.0f64);
        for k in 0..400_000 {
            let x = if k % 2 == 0 {
                (rng.uniform() - 0.5) * 2e5
            } else {
                (rng.uniform() - 0.5) * 10f64.powf(rng.uniform() * 20.0 - 18.0)
            };
            let (s, c) = portable_sin_cos(x);
            let (ls, lc) = x.sin_cos();
            worst_s = worst_s.max(ulps(s, ls));
            worst_c = worst_c.max(ulps(c, lc));
            assert_eq!(portable_sin_cos(-x), (-s, c));
        }
        println!("portable_sin_cos vs libm: sin {worst_s:.3} cos {worst_c:.3} ulp");
        assert!(
            worst_s <= 1.0 && worst_c <= 1.0,
            "sin {worst_s} cos {worst_c} ulp"
        );
        assert_eq!(portable_sin_cos(0.0), (0.0, 1.0));
        assert!(portable_sin_cos(f64::INFINITY).0.is_nan());
        assert!(portable_sin_cos(f64::NAN).1.is_nan());
    }
}
