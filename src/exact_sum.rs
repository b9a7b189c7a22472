//! Sums of f64 values that do not depend on the order or grouping of the terms: the whole-run
//! diagnostics (energies, elastic energy, wall forces) are the same bits on 1, 2 or 3 ranks,
//! on either backend and after a restart (docs/parallel.md, "Output identical whatever the rank
//! count").
//!
//! Floating-point addition is not associative: a 2-rank run summed each rank's particles and
//! then the two partial sums, and its series differed from the 1-rank run's in the last bit
//! (potential 0.0025558616366241245 against 0.002555861636624125). [`ExactSum`] accumulates
//! every term exactly, as an integer multiple of 2⁻¹⁰⁸⁸ held in base-2³² digits (a long
//! accumulator in the manner of Kulisch's), so that any order, any grouping and any merge of
//! partial accumulators (from other ranks) gives the same exact value; [`ExactSum::value`]
//! rounds that one value the same way every time.

/// Bits per digit.
const DIGIT_BITS: u32 = 32;
/// The weight of digit 0 is `2^LOW`: below the least subnormal, 2⁻¹⁰⁷⁴, on a digit boundary.
const LOW: i32 = -1088;
/// Digits: up to `2^(LOW + 32 · DIGITS)` = 2¹⁰⁸⁸, past the largest f64 with room for carries.
const DIGITS: usize = 68;
/// Terms added between two carry propagations: each adds less than 2³² to a digit, so 2³⁰ of
/// them keep every digit far inside an i64.
const NORMALIZE_EVERY: u32 = 1 << 30;

/// An exact sum of finite f64 values (module docs); infinities and NaN are carried apart and
/// dominate the value as IEEE addition would make them. Two sums are equal when their exact
/// values are (and their non-finite parts' bits).
#[derive(Clone, Debug)]
pub struct ExactSum {
    digits: [i64; DIGITS],
    /// Terms since the last carry propagation.
    pending: u32,
    /// The sum of the non-finite terms (0 when there were none).
    special: f64,
}

impl PartialEq for ExactSum {
    fn eq(&self, other: &Self) -> bool {
        self.words() == other.words() && self.special.to_bits() == other.special.to_bits()
    }
}

impl Default for ExactSum {
    fn default() -> Self {
        ExactSum {
            digits: [0; DIGITS],
            pending: 0,
            special: 0.0,
        }
    }
}

/// `2^e` as an f64 (0 below the least subnormal), built from its bits.
fn power_of_two(e: i32) -> f64 {
    if e >= -1022 {
        f64::from_bits(((e + 1023) as u64) << 52)
    } else if e >= -1074 {
        f64::from_bits(1u64 << (e + 1074))
    } else {
        0.0
    }
}

impl ExactSum {
    /// An empty sum.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `x` exactly.
    pub fn add(&mut self, x: f64) {
        if x == 0.0 {
            return;
        }
        if !x.is_finite() {
            self.special += x;
            return;
        }
        let bits = x.to_bits();
        let exponent = ((bits >> 52) & 0x7ff) as i32;
        let fraction = bits & ((1u64 << 52) - 1);
        let (mantissa, e) = if exponent == 0 {
            (fraction, -1074)
        } else {
            (fraction | (1u64 << 52), exponent - 1075)
        };
        let shift = (e - LOW) as u32; // ≥ 14
        let (k, r) = ((shift / DIGIT_BITS) as usize, shift % DIGIT_BITS);
        let wide = u128::from(mantissa) << r; // at most 84 bits: three digits
        let sign: i64 = if x < 0.0 { -1 } else { 1 };
        for j in 0..3 {
            let digit = ((wide >> (DIGIT_BITS * j as u32)) & 0xffff_ffff) as i64;
            if digit != 0 {
                self.digits[k + j] += sign * digit;
            }
        }
        self.pending += 1;
        if self.pending >= NORMALIZE_EVERY {
            self.normalize();
        }
    }

    /// Adds every term of `other`.
    pub fn merge(&mut self, other: &ExactSum) {
        let mut other = other.clone();
        other.normalize();
        self.normalize();
        for (d, o) in self.digits.iter_mut().zip(other.digits) {
            *d += o;
        }
        self.special += other.special;
        self.normalize();
    }

    /// Propagates the carries: every digit but the last in `[0, 2³²)`, the last signed. The
    /// exact value has exactly one such form, from which [`ExactSum::value`] reads.
    fn normalize(&mut self) {
        let mut carry: i64 = 0;
        for d in self.digits.iter_mut().take(DIGITS - 1) {
            let v = *d + carry;
            *d = v.rem_euclid(1 << DIGIT_BITS);
            carry = v.div_euclid(1 << DIGIT_BITS);
        }
        self.digits[DIGITS - 1] += carry;
        self.pending = 0;
    }

    /// The sum, rounded from its exact value the same way whatever order and grouping the terms
    /// came in: the magnitude's canonical digits, largest first, each scaled exactly (a digit
    /// below the normal range in two steps), then the sign.
    pub fn value(&self) -> f64 {
        let mut s = self.clone();
        s.normalize();
        let negative = s.digits[DIGITS - 1] < 0;
        if negative {
            for d in s.digits.iter_mut() {
                *d = -*d;
            }
            s.normalize();
        }
        let mut total = 0.0;
        for (i, &d) in s.digits.iter().enumerate().rev() {
            if d == 0 {
                continue;
            }
            let e = LOW + DIGIT_BITS as i32 * i as i32;
            total += if e > 1023 {
                f64::INFINITY
            } else if e < -1022 {
                d as f64 * power_of_two(e + 128) * power_of_two(-128)
            } else {
                d as f64 * power_of_two(e)
            };
        }
        let total = if negative { -total } else { total };
        if s.special != 0.0 || s.special.is_nan() {
            total + s.special
        } else {
            total
        }
    }

    /// The canonical digits (two's complement) followed by the non-finite part's bits: what a
    /// rank sends for [`ExactSum::from_sums`].
    pub fn words(&self) -> Vec<u64> {
        let mut s = self.clone();
        s.normalize();
        s.digits.iter().map(|&d| d as u64).collect()
    }

    /// The sum of several ranks' [`ExactSum::words`] added element-wise with wrap-around (an
    /// MPI sum of unsigned 64-bit integers), and of their non-finite parts.
    pub fn from_sums(words: &[u64], special: f64) -> Self {
        let mut s = ExactSum::new();
        for (d, &w) in s.digits.iter_mut().zip(words) {
            *d = w as i64;
        }
        s.special = special;
        s.normalize();
        s
    }

    /// The non-finite part (0 when every term was finite).
    pub fn special(&self) -> f64 {
        self.special
    }

    /// The number of words of [`ExactSum::words`].
    pub const WORDS: usize = DIGITS;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Terms over 40 decades, positive and negative, with cancellation: every order and every
    /// split into partial sums merged gives the same bits, and the value is the exact sum to
    /// within an ulp (checked against a sum in which the cancelling pairs are exact).
    #[test]
    fn order_and_grouping_do_not_change_the_bits() {
        let mut rng = Rng::new(5);
        let terms: Vec<f64> = (0..20_000)
            .map(|_| rng.range(-1.0, 1.0) * 10f64.powf(rng.range(-20.0, 20.0)))
            .collect();
        let whole = {
            let mut s = ExactSum::new();
            terms.iter().for_each(|&x| s.add(x));
            s
        };
        for seed in 0..5 {
            let mut shuffled = terms.clone();
            let mut r = Rng::new(seed);
            for i in (1..shuffled.len()).rev() {
                shuffled.swap(i, (r.next_u64() % (i as u64 + 1)) as usize);
            }
            let parts = 1 + seed as usize;
            let mut acc = ExactSum::new();
            for chunk in shuffled.chunks(shuffled.len() / parts + 1) {
                let mut p = ExactSum::new();
                chunk.iter().for_each(|&x| p.add(x));
                acc.merge(&p);
            }
            assert_eq!(acc.value().to_bits(), whole.value().to_bits());
            // Through the words, as ranks exchange them.
            let mut words = vec![0u64; ExactSum::WORDS];
            for chunk in shuffled.chunks(shuffled.len() / parts + 1) {
                let mut p = ExactSum::new();
                chunk.iter().for_each(|&x| p.add(x));
                for (w, x) in words.iter_mut().zip(p.words()) {
                    *w = w.wrapping_add(x);
                }
            }
            let via = ExactSum::from_sums(&words, 0.0);
            assert_eq!(via.value().to_bits(), whole.value().to_bits());
        }
        // x + (−x) + y is y exactly, for tiny and huge x.
        let mut s = ExactSum::new();
        for x in [1e300, -1e-300, 5e-324, 0.1] {
            s.add(x);
        }
        for x in [-1e300, 1e-300, -5e-324] {
            s.add(x);
        }
        assert_eq!(s.value(), 0.1);
        // Negative sums, subnormal and huge terms: the value is the f64 sum where that is
        // exact.
        for (terms, want) in [
            (vec![-0.1], -0.1),
            (vec![-3.0, 1.0, -0.5], -2.5),
            (vec![5e-324, 5e-324, 5e-324], 1.5e-323),
            (vec![-5e-324, 1e-320], 1e-320 - 5e-324),
            (vec![1e308, 1e308, -1e308], 1e308),
            (vec![-1e308, -1e308], f64::NEG_INFINITY),
            (vec![1.0, -1.0], 0.0),
        ] {
            let mut s = ExactSum::new();
            terms.iter().for_each(|&x| s.add(x));
            assert_eq!(s.value(), want, "{terms:?}");
        }
        // The whole random sum against an f64 sum of the same terms (within its error).
        let naive: f64 = terms.iter().sum();
        let scale: f64 = terms.iter().map(|x| x.abs()).sum();
        assert!((whole.value() - naive).abs() <= 1e-12 * scale);
        let mut t = ExactSum::new();
        t.add(f64::INFINITY);
        t.add(1.0);
        assert_eq!(t.value(), f64::INFINITY);
        t.add(f64::NEG_INFINITY);
        assert!(t.value().is_nan());
    }
}

/// A rank's contact diagnostics as exact sums: the elastic energy of the contacts it counts and
/// each wall's force from its particles. The reduction (CPU) and the host's gathering of the
/// device's outcomes (GPU) fill it; the whole run's values come from merging every rank's.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DiagnosticSums {
    pub elastic: ExactSum,
    /// Per wall, its force's x, y and z.
    pub wall_forces: Vec<[ExactSum; 3]>,
}

impl DiagnosticSums {
    /// Empty sums for `walls` walls.
    pub fn new(walls: usize) -> Self {
        DiagnosticSums {
            elastic: ExactSum::new(),
            wall_forces: vec![Default::default(); walls],
        }
    }

    /// Adds one particle's force on wall `k`.
    pub fn add_wall_force(&mut self, k: usize, f: &nalgebra::Vector3<f64>) {
        for (s, x) in self.wall_forces[k].iter_mut().zip(f.iter()) {
            s.add(*x);
        }
    }

    /// The walls' forces, rounded.
    pub fn wall_force_values(&self) -> Vec<nalgebra::Vector3<f64>> {
        self.wall_forces
            .iter()
            .map(|w| nalgebra::Vector3::new(w[0].value(), w[1].value(), w[2].value()))
            .collect()
    }
}
