//! Damping that gives the prescribed restitution for every contact type.
//!
//! The volume-based normal force is a power of the approach δ whose exponent depends on what
//! touches (validation.md §1): `F ∝ δ³` vertex–face, `δ^{5/3}` edge–face, `δ^{1/3}` face–face.
//! A dashpot tuned from a linear spring (seed Eq. 15) gives a different restitution for each.
//! For a spring `F = K δ^p` with the damping
//!
//! ```text
//!   F_d = −γ √(m k_loc) δ̇,   k_loc = dF/dδ = p F/δ,
//! ```
//!
//! the substitution `δ = a X`, `t = b T` with `b² = m a^{1−p} / K` and `a` chosen so that
//! `X'(0) = 1` turns the impact into `X'' = −X^p − γ √p X^{(p−1)/2} X'` for every mass,
//! stiffness and impact speed: the restitution depends on `γ` and `p` only. This module solves
//! that dimensionless impact (RK4, the net force clamped at zero so the contact never pulls,
//! as in the simulation) and inverts it for `γ(e, p)` by bisection, on a table of `p` between
//! 1/3 and 3 that the contact law interpolates.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

/// Exponents of the table: 1/3 … 3.
const P_MIN: f64 = 1.0 / 3.0;
const P_MAX: f64 = 3.0;
/// Number of exponents tabulated in a [`DampingTable`] (`cuda/contact_law.cuh` has the same).
pub const TABLE_SIZE: usize = 25;

/// Restitution of the dimensionless impact `X'' = −X^p − γ √p X^{(p−1)/2} X'`, `X(0) = 0`,
/// `X'(0) = 1`: minus the velocity when X returns to zero (or when the net force would turn
/// attractive, after which the bodies separate freely).
pub fn restitution_of(gamma: f64, p: f64) -> f64 {
    let rate = |x: f64| gamma * p.sqrt() * x.max(0.0).powf((p - 1.0) / 2.0);
    let accel = |x: f64, v: f64| {
        if x <= 0.0 {
            return 0.0;
        }
        // No attraction: the net normal force is clamped at zero.
        -(x.powf(p) + rate(x) * v).max(0.0)
    };
    // For p < 1 the damping rate grows without bound as X → 0 (the face–face spring is
    // infinitely stiff at first touch), so the step follows it: rate·h ≤ 0.05 keeps RK4 stable
    // and accurate there, and h ≤ 2e-3 resolves the rest of the impact (which lasts a few units).
    // The impact starts at X = 1e-12 rather than 0, where the rate is infinite.
    let (mut x, mut v) = (1e-12, 1.0);
    for _ in 0..5_000_000 {
        let h = (0.05 / (rate(x) + 1e-30)).min(2e-3);
        let (k1x, k1v) = (v, accel(x, v));
        let (k2x, k2v) = (
            v + 0.5 * h * k1v,
            accel(x + 0.5 * h * k1x, v + 0.5 * h * k1v),
        );
        let (k3x, k3v) = (
            v + 0.5 * h * k2v,
            accel(x + 0.5 * h * k2x, v + 0.5 * h * k2v),
        );
        let (k4x, k4v) = (v + h * k3v, accel(x + h * k3x, v + h * k3v));
        let xn = x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
        let vn = v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        if xn <= 0.0 && vn < 0.0 {
            // Interpolate the crossing for the exit speed.
            return -(v + (vn - v) * (x / (x - xn)));
        }
        if vn < 0.0 && accel(xn, vn) >= 0.0 {
            return -vn; // force vanished while receding: the bodies part at this speed
        }
        x = xn;
        v = vn;
    }
    0.0
}

/// Duration of the undamped dimensionless impact `X'' = −X^p`, `X(0) = 0`, `X'(0) = 1`: the
/// contact lasts `T = τ(p) · (m v^{1−p} / K)^{1/(1+p)}` for a spring `F = K δ^p`, mass `m` and
/// impact speed `v` (the scaling of the module docs).
pub fn dimensionless_duration(p: f64) -> f64 {
    let (mut x, mut v, mut t) = (1e-12f64, 1.0f64, 0.0);
    let accel = |x: f64| -x.max(0.0).powf(p);
    let h = 1e-4;
    while t < 1e3 {
        let (k1x, k1v) = (v, accel(x));
        let (k2x, k2v) = (v + 0.5 * h * k1v, accel(x + 0.5 * h * k1x));
        let (k3x, k3v) = (v + 0.5 * h * k2v, accel(x + 0.5 * h * k2x));
        let (k4x, k4v) = (v + h * k3v, accel(x + h * k3x));
        let xn = x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
        let vn = v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        if xn <= 0.0 {
            return t + h * x / (x - xn);
        }
        (x, v, t) = (xn, vn, t + h);
    }
    t
}

/// Contact duration of a face-to-face impact at speed `v` between two bodies of mass `m` with a
/// common flat face of area `a`, elastic constant `c = E₁/R₁ + E₂/R₂`: with `V = A δ` the seed
/// law is `F = c A^{4/3} δ^{1/3}`, the stiffest contact of the volume law at first touch (its
/// stiffness `F/(3δ)` is unbounded as δ → 0), so it bounds the explicit time step.
pub fn face_contact_time(m_eff: f64, c: f64, a: f64, v: f64) -> f64 {
    let p = 1.0 / 3.0;
    let k = c * a.powf(4.0 / 3.0);
    dimensionless_duration(p) * (m_eff * v.powf(1.0 - p) / k).powf(1.0 / (1.0 + p))
}

/// Contact duration of a head-on impact at speed `v` of two spheres of effective radius
/// `r_eff = r₁r₂/(r₁ + r₂)` and effective mass `m_eff`, elastic constant `c`: for `δ ≪ r` the
/// lens has `V = π r_eff δ²` and `A_n = 2π r_eff δ`, so the volume law is the power law
/// `F = c V^{1/3} A_n = 2π^{4/3} c r_eff^{4/3} δ^{5/3}` (p = 5/3, against Hertz's 3/2).
pub fn sphere_contact_time(m_eff: f64, c: f64, r_eff: f64, v: f64) -> f64 {
    let p = 5.0 / 3.0;
    let k = 2.0 * std::f64::consts::PI.powf(4.0 / 3.0) * c * r_eff.powf(4.0 / 3.0);
    dimensionless_duration(p) * (m_eff * v.powf(1.0 - p) / k).powf(1.0 / (1.0 + p))
}

/// `γ` such that [`restitution_of`]`(γ, p) = e`, by bisection (restitution decreases with γ).
pub fn damping_for(e: f64, p: f64) -> f64 {
    if e >= 1.0 {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    while restitution_of(hi, p) > e && hi < 1e3 {
        hi *= 2.0;
    }
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if restitution_of(mid, p) > e {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-6 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// `γ(p)` for one restitution coefficient, tabulated for interpolation.
#[derive(Clone, Debug, PartialEq)]
pub struct DampingTable {
    gamma: [f64; TABLE_SIZE],
}

impl DampingTable {
    /// Tabulates `γ(e, p)` for `p` in [1/3, 3]. Tables are cached per restitution value for the
    /// life of the process (building one solves a few hundred impacts).
    pub fn new(restitution: f64) -> Self {
        static CACHE: OnceLock<Mutex<HashMap<u64, DampingTable>>> = OnceLock::new();
        let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
        let key = restitution.to_bits();
        if let Some(t) = cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
            return t;
        }
        let mut gamma = [0.0; TABLE_SIZE];
        for (k, g) in gamma.iter_mut().enumerate() {
            *g = damping_for(restitution, Self::exponent(k));
        }
        let table = DampingTable { gamma };
        if let Ok(mut c) = cache.lock() {
            c.insert(key, table.clone());
        }
        table
    }

    fn exponent(k: usize) -> f64 {
        P_MIN + (P_MAX - P_MIN) * k as f64 / (TABLE_SIZE - 1) as f64
    }

    /// The tabulated values, at exponents evenly spaced over [1/3, 3] (for the GPU tables).
    pub fn values(&self) -> &[f64; TABLE_SIZE] {
        &self.gamma
    }

    /// `γ` at exponent `p` (clamped to the table's range [1/3, 3], the range of convex contacts).
    pub fn gamma(&self, p: f64) -> f64 {
        let u = ((p.clamp(P_MIN, P_MAX) - P_MIN) / (P_MAX - P_MIN)) * (TABLE_SIZE - 1) as f64;
        let k = (u.floor() as usize).min(TABLE_SIZE - 2);
        let w = u - k as f64;
        self.gamma[k] * (1.0 - w) + self.gamma[k + 1] * w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The undamped impact `X'' = −X^p` lasts `τ = 2 X_max ∫₀¹ (1 − u^{p+1})^{−1/2} du` with
    /// `X_max = ((p+1)/2)^{1/(p+1)}`; the integral is `Γ(1/q + 1) Γ(1/2) / Γ(1/q + 1/2)`,
    /// `q = p + 1`. For p = 1/3: τ = 2.651 8…; for p = 1 (linear): τ = π.
    #[test]
    fn impact_duration_matches_the_closed_form() {
        let tau_third =
            2.0 * (2.0f64 / 3.0).powf(0.75) * 0.919_062_526_848_883_5 * std::f64::consts::PI.sqrt()
                / 0.906_402_477_055_477;
        assert!((dimensionless_duration(1.0 / 3.0) - tau_third).abs() < 1e-4 * tau_third);
        assert!((dimensionless_duration(1.0) - std::f64::consts::PI).abs() < 1e-4);
    }

    #[test]
    fn interpolated_table_reproduces_restitution() {
        let t0 = std::time::Instant::now();
        let table = DampingTable::new(0.37);
        println!("table built in {:?}", t0.elapsed());
        // Interpolated values reproduce e to within the 3 % the validation asks for.
        for p in [0.5, 1.2, 2.2] {
            let e = restitution_of(table.gamma(p), p);
            assert!((e - 0.37).abs() < 0.01 * 0.37, "p {p}: e {e}");
        }
    }

    #[test]
    fn undamped_impact_is_elastic_and_damping_inverts() {
        for p in [1.0 / 3.0, 1.0, 5.0 / 3.0, 3.0] {
            assert!((restitution_of(0.0, p) - 1.0).abs() < 1e-6, "p {p}");
            for e in [0.1, 0.5, 0.85] {
                let g = damping_for(e, p);
                assert!((restitution_of(g, p) - e).abs() < 1e-5, "p {p}, e {e}");
            }
        }
        // Linear spring, against the closed form of the damped oscillator: with ζ = γ/2,
        // X = e^{−ζt} sin(ωt)/ω, ω = √(1 − ζ²); the contact ends when the net force X + γX'
        // vanishes, and e = −X' there.
        for gamma in [0.2f64, 0.6, 1.2] {
            let zeta = gamma / 2.0;
            let w = (1.0 - zeta * zeta).sqrt();
            let x = |t: f64| (-zeta * t).exp() * (w * t).sin() / w;
            let v = |t: f64| (-zeta * t).exp() * ((w * t).cos() - zeta * (w * t).sin() / w);
            // x + γv > 0 at the start; its first zero by bisection on (0, π/ω].
            let (mut lo, mut hi) = (1e-9, std::f64::consts::PI / w);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if x(mid) + gamma * v(mid) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let exact = -v(0.5 * (lo + hi));
            let ours = restitution_of(gamma, 1.0);
            assert!((ours - exact).abs() < 1e-6, "γ {gamma}: {ours} vs {exact}");
        }
    }
}
