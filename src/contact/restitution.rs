//! Damping that gives the prescribed restitution for every contact type, and the impact
//! durations the time step is chosen from.
//!
//! The volume-based normal force is a power of the approach δ whose exponent depends on what
//! touches (validation.md §1): `F ∝ δ³` vertex–face, `δ^{5/3}` edge–face, `δ^{1/3}` face–face.
//! The contact law damps with Hunt and Crossley's form `F = F_e (1 + ᾱ δ̇ / v_ref)`
//! ([`hunt_crossley_alpha`], docs/contact.md §2), whose restitution is the same for every
//! exponent and which is bounded wherever the elastic force is, first touch of a face included.
//!
//! The viscous alternative `F_d = −γ(e, p) √(m k_loc) δ̇`, `k_loc = dF/dδ = p F/δ`, which the law
//! used before, also gives one restitution for every mass, stiffness and speed, but `γ` depends
//! on `p`, and for a face (`p = 1/3`) its coefficient is unbounded at first touch, so an explicit
//! step's phase decided the restitution.

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

/// The dimensionless Hunt–Crossley coefficient `ᾱ(e)` of the contact law's damping
/// `F = F_e (1 + ᾱ δ̇ / v_ref)` (docs/contact.md §2): the root of
///
/// ```text
///   ᾱ (1 + e) = ln((1 + ᾱ) / (1 − ᾱ e)),   0 ≤ ᾱ < 1/e.
/// ```
///
/// For any elastic force `F_e(δ)` (any exponent, any shape), `v dv / (1 + ᾱ v/v₀) = −F_e dδ / m`
/// separates in the potential `∫F_e dδ`, so an impact at `v₀` returns when
/// `∫_{−e v₀}^{v₀} v dv / (1 + ᾱ v / v₀) = 0`, which is the equation above. The restitution
/// therefore depends on `ᾱ` alone: vertex, edge and face contacts get the same `e` from one
/// coefficient. Solved by bisection to 1 ulp of the bracket (the left side minus the right is
/// negative below the root and positive above it).
pub fn hunt_crossley_alpha(e: f64) -> f64 {
    if e >= 1.0 {
        return 0.0;
    }
    let e = e.max(1e-6);
    let f = |a: f64| a * (1.0 + e) - ((1.0 + a) / (1.0 - a * e)).ln();
    // f ≈ (1 − e²) a² / 2 > 0 near 0 and f → −∞ as a → 1/e, with one root between.
    let (mut lo, mut hi) = (1e-12, (1.0 / e) * (1.0 - 1e-15));
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= f64::EPSILON * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Restitution of the Hunt–Crossley impact `X'' = −X^p (1 + ᾱ X')`, `X(0) = 0`, `X'(0) = 1`,
/// with the net force clamped at zero (the contact never pulls), by RK4: the independent check
/// of [`hunt_crossley_alpha`] for several exponents.
pub fn hunt_crossley_restitution(alpha: f64, p: f64) -> f64 {
    let accel = |x: f64, v: f64| {
        if x <= 0.0 {
            0.0
        } else {
            -(x.powf(p) * (1.0 + alpha * v)).max(0.0)
        }
    };
    let (mut x, mut v) = (1e-14f64, 1.0f64);
    for _ in 0..50_000_000 {
        let h = (0.05 * x).clamp(1e-12, 1e-3);
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
            return -(v + (vn - v) * (x / (x - xn)));
        }
        if vn < 0.0 && 1.0 + alpha * vn <= 0.0 {
            return -vn;
        }
        x = xn;
        v = vn;
    }
    0.0
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

    /// ᾱ(e) solves its closed form, and the RK4 impact with that ᾱ returns at e for the
    /// exponents of vertex (3), edge (5/3), sphere (5/3), linear (1) and face (1/3) contacts.
    #[test]
    fn hunt_crossley_restitution_is_independent_of_the_exponent() {
        for e in [0.1, 0.3, 0.5, 0.7, 0.9, 0.95] {
            let a = hunt_crossley_alpha(e);
            let residual = a * (1.0 + e) - ((1.0 + a) / (1.0 - a * e)).ln();
            assert!(residual.abs() < 1e-12, "e {e}: residual {residual}");
            for p in [1.0 / 3.0, 1.0, 5.0 / 3.0, 3.0] {
                let out = hunt_crossley_restitution(a, p);
                assert!((out - e).abs() < 2e-6, "e {e}, p {p}: {out}");
            }
        }
        assert_eq!(hunt_crossley_alpha(1.0), 0.0);
        // Lankarani–Nikravesh's ᾱ = 3(1 − e²)/4 is its first-order expansion near e = 1.
        let a = hunt_crossley_alpha(0.99);
        assert!((a - 0.75 * (1.0 - 0.99f64.powi(2))).abs() < 0.02 * a, "{a}");
    }
}
