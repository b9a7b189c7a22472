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

/// ln 2 in two parts (fdlibm's): `LN2_HI` has its low 32 bits zero, so `n · LN2_HI` is exact
/// for `|n| < 2^20`, and `LN2_LO = ln 2 − LN2_HI`.
const LN2_HI: f64 = 6.931_471_803_691_238e-1; // 0x1.62e42feep-1
const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;

/// The natural logarithm of a positive finite `x` from `+ − × ÷` and bit operations only, so
/// that the CPU and the CUDA twin (`cuda/common.cuh: portable_ln`) give the same bits.
/// `x = m 2^e` with `m ∈ [√½, √2)` (exact, from the exponent bits; subnormals scaled by 2^54
/// first), `ln m = 2 atanh f = 2 (f + f³/3 + … + f²¹/21)` with `f = (m − 1)/(m + 1)`, `|f| ≤
/// 0.172` (the first term left out is below 1e-18 of the result), then `e ln 2` in two parts.
/// NaN for `x ≤ 0` or non-finite `x`. Within 2 ulp of libm (tested).
pub fn portable_ln(x: f64) -> f64 {
    if !(x > 0.0 && x.is_finite()) {
        return f64::NAN;
    }
    let mut bits = x.to_bits();
    let mut e: i64 = 0;
    if bits >> 52 == 0 {
        bits = (x * 18_014_398_509_481_984.0).to_bits(); // 2^54
        e = -54;
    }
    e += ((bits >> 52) & 0x7ff) as i64 - 1023;
    let mut m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | (1023u64 << 52));
    if m > std::f64::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let f = (m - 1.0) / (m + 1.0);
    let z = f * f;
    let mut series = 1.0 / 21.0;
    for k in (0..10).rev() {
        series = 1.0 / (2 * k + 1) as f64 + z * series;
    }
    let e = e as f64;
    e * LN2_HI + (2.0 * f * series + e * LN2_LO)
}

/// `e^y` from `+ − × ÷`, `floor` and bit operations only (the CUDA twin is
/// `cuda/common.cuh: portable_exp`): `y = n ln 2 + r` with `n = ⌊y/ln 2 + 1/2⌋` and `r = (y −
/// n LN2_HI) − n LN2_LO`, `|r| ≤ 0.347`; the Taylor polynomial of degree 14 in Horner form (the
/// first term left out is below 1e-19 of the result), then `2^n` applied in two exact halves.
/// 0 below −746, ∞ above 710, NaN for NaN. Within 2 ulp of libm (tested).
pub fn portable_exp(y: f64) -> f64 {
    if y.is_nan() {
        return y;
    }
    if y > 710.0 {
        return f64::INFINITY;
    }
    if y < -746.0 {
        return 0.0;
    }
    let n = (y * std::f64::consts::LOG2_E + 0.5).floor();
    let r = (y - n * LN2_HI) - n * LN2_LO;
    let mut p = 1.0 / 87_178_291_200.0; // 1/14!
    let mut fact = 87_178_291_200.0;
    for k in (0..14).rev() {
        fact /= (k + 1) as f64;
        p = 1.0 / fact + r * p;
    }
    let n = n as i64;
    let half = n / 2;
    let pow2 = |k: i64| f64::from_bits(((1023 + k) as u64) << 52);
    p * pow2(half) * pow2(n - half)
}

/// `x^p` for `x ≥ 0` as `exp(p ln x)` through [`portable_ln`] and [`portable_exp`] (0 for
/// `x = 0`, `p > 0`): the same bits on the CPU and the GPU (`cuda/common.cuh: portable_pow`).
/// The contact law raises ratios in `[0, 2]` to exponents in `[1, 4]` with it. Within 32 ulp
/// of libm's `powf` there (the rounding of `p ln x` is what `exp` magnifies).
pub fn portable_pow(x: f64, p: f64) -> f64 {
    if x == 0.0 && p > 0.0 {
        return 0.0;
    }
    portable_exp(p * portable_ln(x))
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

    /// Within 2 ulp of libm's ln and exp over their ranges, exact where the result is (ln 1,
    /// exp 0), and `portable_pow` within 32 ulp of `powf` on the contact law's range (ratios
    /// in [1e-3, 2], exponents in [1, 4]): the rounding of `p ln x`, up to 28 in magnitude
    /// there, is what `exp` magnifies (ulps of 28 are 16 ulps of 1).
    #[test]
    fn portable_ln_exp_pow_are_within_ulps_of_libm() {
        let mut rng = crate::rng::Rng::new(7);
        let ulps = |a: f64, b: f64| (a - b).abs() / (f64::EPSILON * b.abs());
        let (mut worst_ln, mut worst_exp, mut worst_pow) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..200_000 {
            let x = 10f64.powf(rng.uniform() * 620.0 - 310.0);
            // ln near 1 is small: judge it in ulps of 1 there.
            let l = x.ln();
            worst_ln = worst_ln.max((portable_ln(x) - l).abs() / (f64::EPSILON * l.abs().max(1.0)));
            let y = (rng.uniform() - 0.5) * 1400.0;
            worst_exp = worst_exp.max(ulps(portable_exp(y), y.exp()));
            let (r, p) = (rng.uniform() * 2.0, 1.0 + 3.0 * rng.uniform());
            if r > 1e-3 {
                worst_pow = worst_pow.max(ulps(portable_pow(r, p), r.powf(p)));
            }
        }
        println!("portable ln {worst_ln:.2} exp {worst_exp:.2} pow {worst_pow:.2} ulp");
        assert!(worst_ln <= 2.0, "ln: {worst_ln} ulp");
        assert!(worst_exp <= 2.0, "exp: {worst_exp} ulp");
        assert!(worst_pow <= 32.0, "pow: {worst_pow} ulp");
        assert_eq!(portable_ln(1.0), 0.0);
        assert_eq!(portable_exp(0.0), 1.0);
        assert_eq!(portable_pow(0.0, 1.5), 0.0);
        assert_eq!(portable_exp(1e6), f64::INFINITY);
        assert_eq!(portable_exp(-1e6), 0.0);
        assert!(portable_ln(-1.0).is_nan() && portable_ln(0.0).is_nan());
    }
}
