//! Friction at a contact: the tangential force and the twisting couple, each a spring and a
//! dashpot side by side (a Kelvin–Voigt element) in series with a Coulomb slider
//! (docs/contact.md §4).
//!
//! The element's elastic stretch `ξ` changes by the relative motion less the slider's slip,
//! `ξ̇ = v_t − ṗ`; its force is `F = −k ξ − c ξ̇`; the slider slips only at `|F| = μ F_n`, in
//! the direction that `F` opposes. The power the contact puts into the bodies is then
//!
//! ```text
//! F·v_t = −d(k|ξ|²/2)/dt − c|ξ̇|² − μ F_n |ṗ|
//! ```
//!
//! so friction only ever gives back what its spring stored, and the spring's energy is lost
//! when the contact ends: over a contact's life friction does no positive work. A step keeps
//! that exactly (the backward-Euler return mapping of [`slip_step`]), and the stretch is
//! carried from step to step at constant energy ([`stretch`]), so that a change of the
//! contact's stiffness (its area) neither stores nor releases energy.
//!
//! The element is sized by the step, as the regularized normal potential is: its dashpot is
//! the step's lock ([`lock_coefficient`]), which takes the slip of one step (half of it where
//! the normal damping is at its floor, against the bodies' masses split among their
//! contacts), and its spring the stiffest the step resolves ([`resolved_stiffness`]) where
//! the seed's `k_t = k̂ A_n` is softer (nearly always). A contact below the Coulomb limit then
//! sticks within a step or two instead of ringing on a soft spring, a sticking impact ends
//! rolling, as rigid-body theory with Coulomb friction has it, and a contact loaded steadily
//! holds its load without creeping. As the step shrinks the element tends to Coulomb's rigid
//! stick.

use super::potential::RESOLVED_STEP;
use nalgebra::Vector3;

/// The stretch `ξ = s/√k` of a spring carried between steps as `s = √k ξ` (zero where `k` is).
///
/// The stored energy `|s|²/2` does not depend on the stiffness. A contact's tangential
/// stiffness follows its area (`k_t = k̂ A_n`): a stretch kept as a length would gain
/// `|ξ|² Δk/2` whenever the area grows, energy no motion put in, and give it back as the
/// contact unloads. Carried as `s`, the stretch at the new stiffness is `s/√k`: the energy is
/// unchanged, and only the work of the relative motion changes it.
pub fn stretch<T: SlipValue>(stored: T, root_k: f64) -> T {
    if root_k > 0.0 {
        stored.scale(1.0 / root_k)
    } else {
        T::zero()
    }
}

/// One step of a Kelvin–Voigt element (stiffness `k`, dashpot `c`) in series with a Coulomb
/// slider of strength `cap`, given the stretch `xi_old` at the start of the step and the
/// relative velocity `v` over it. Returns the force (on B, opposing B's motion relative to A)
/// and the stretch at the end of the step.
///
/// Without slip `ξ = ξ₀ + v Δt` and `F = −k ξ − c v`. Where that exceeds the cap, the slider
/// slips by `Δp` along `−F̂` and the element takes `ξ = ξ₀ + v Δt − Δp` with
/// `F = −k ξ − c (ξ − ξ₀)/Δt` of magnitude `cap`: with `K = k + c/Δt`, `F = cap F̂_trial` and
/// `ξ = ξ_trial + (|F_trial| − cap)/K · F̂_trial` (the radial return). The work the step puts
/// into the bodies, `F·v Δt`, is then `−Δ(k|ξ|²/2) − (k/2 + c/Δt)|ξ − ξ₀|² − cap |Δp|`:
/// never more than the spring gave up.
///
/// Generic over the tangential vector and the scalar twist through [`SlipValue`].
pub fn slip_step<T: SlipValue>(xi_old: T, v: T, k: f64, c: f64, cap: f64, dt: f64) -> (T, T) {
    let xi = xi_old.add(v.scale(dt));
    let trial = xi.scale(-k).add(v.scale(-c));
    let magnitude = trial.magnitude();
    if magnitude <= cap {
        return (trial, xi);
    }
    // The slip of the step, along the trial force: |F_trial| > cap ≥ 0, so the unit is defined.
    let unit = trial.scale(1.0 / magnitude);
    let stiffness = k + if dt > 0.0 { c / dt } else { 0.0 };
    let xi = if stiffness > 0.0 {
        xi.add(unit.scale((magnitude - cap) / stiffness))
    } else {
        T::zero()
    };
    (unit.scale(cap), xi)
}

/// What [`slip_step`] needs of the tangential vector and of the scalar twist.
pub trait SlipValue: Copy {
    fn zero() -> Self;
    fn add(self, other: Self) -> Self;
    fn scale(self, factor: f64) -> Self;
    fn magnitude(self) -> f64;
}

impl SlipValue for Vector3<f64> {
    fn zero() -> Self {
        Vector3::zeros()
    }
    fn add(self, other: Self) -> Self {
        self + other
    }
    fn scale(self, factor: f64) -> Self {
        self * factor
    }
    fn magnitude(self) -> f64 {
        self.norm()
    }
}

impl SlipValue for f64 {
    fn zero() -> Self {
        0.0
    }
    fn add(self, other: Self) -> Self {
        self + other
    }
    fn scale(self, factor: f64) -> Self {
        self * factor
    }
    fn magnitude(self) -> f64 {
        self.abs()
    }
}

/// The lock dashpot `c = share/(Δt · w)` of a contact whose relative motion sees the inverse
/// mass (or moment of inertia) `w` along it: its impulse over one step takes `share` of the
/// relative velocity it acts on, all of it for one contact at `share = 1`, and never reverses
/// it. Zero where the step or `w` is (no motion to lock).
pub fn lock_coefficient(share: f64, inverse: f64, dt: f64) -> f64 {
    if dt > 0.0 && inverse > 0.0 {
        share / (dt * inverse)
    } else {
        0.0
    }
}

/// The stiffest spring the step resolves against the inverse mass `w`: `k = (σ/Δt)²/w`, the
/// period `ω Δt = σ` with σ = [`RESOLVED_STEP`], as the regularized normal potential
/// (docs/contact.md §1). With the lock dashpot it settles within a few steps without
/// overshoot (for one contact, the step's error contracts by `1 − σ²` per step), so a
/// contact loaded steadily sticks where the seed's soft spring would let it creep for
/// `m/(k Δt)`. Zero where the step or `w` is.
pub fn resolved_stiffness(inverse: f64, dt: f64) -> f64 {
    if dt > 0.0 && inverse > 0.0 {
        let x = RESOLVED_STEP / dt;
        x * x / inverse
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sticking: below the cap the element is the spring and dashpot, and the stretch grows by
    /// the motion.
    #[test]
    fn below_the_cap_the_element_sticks() {
        let (f, xi) = slip_step(0.5f64, 2.0, 10.0, 3.0, 100.0, 0.25);
        assert_eq!(xi, 1.0);
        assert_eq!(f, -10.0 * 1.0 - 3.0 * 2.0);
    }

    /// Sliding: the force is the cap along the trial force, and the element's own force law
    /// holds with the returned stretch, `F = −k ξ − c (ξ − ξ₀)/Δt`.
    #[test]
    fn at_the_cap_the_force_is_the_cap_and_the_element_consistent() {
        let (k, c, dt) = (1e4, 40.0, 1e-3);
        let xi_old = Vector3::new(1e-4, -2e-4, 0.0);
        let v = Vector3::new(0.3, 0.1, 0.0);
        let cap = 2.0;
        let (f, xi) = slip_step(xi_old, v, k, c, cap, dt);
        assert!((f.norm() - cap).abs() <= 1e-12 * cap, "{}", f.norm());
        let law = -xi * k - (xi - xi_old) * (c / dt);
        assert!((law - f).norm() <= 1e-12 * cap, "{law:?} vs {f:?}");
    }

    /// The discrete work identity: over random steps (sticking and sliding, stretches and
    /// reversals), `F·v Δt ≤ −Δ(k ξ²/2)` at every step, so the sum over a contact's life never
    /// exceeds what the spring held at its start.
    #[test]
    fn no_step_gives_the_bodies_more_than_the_spring_gave_up() {
        let mut rng = crate::rng::Rng::new(7);
        let (k, c, dt) = (5e3, 3.0, 1e-5);
        let mut xi = 0.0f64;
        let mut work = 0.0;
        for _ in 0..100_000 {
            let v = rng.range(-1.0, 1.0) * 10f64.powf(rng.range(-4.0, 0.0));
            let cap = 10f64.powf(rng.range(-4.0, 0.0));
            let (f, next) = slip_step(xi, v, k, c, cap, dt);
            let step_work = f * v * dt;
            let released = 0.5 * k * (xi * xi - next * next);
            assert!(
                step_work <= released + 1e-15 * (released.abs() + step_work.abs()),
                "work {step_work:e} > released {released:e}"
            );
            work += step_work;
            xi = next;
        }
        assert!(work <= 0.0, "{work:e}");
    }
}
