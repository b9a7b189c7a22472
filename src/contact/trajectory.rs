//! A face contact's normal motion over its kick window (docs/contact.md §1,
//! `simulation.face_window = "trajectory"`).
//!
//! The secant window of [`super::potential::resolved_mean_pressure`] averages the face's force
//! over the volume swept at the drift's constant speed, switches on where that sweep exceeds
//! half the volume, and adds the entry's and the exit's shares as separate terms. Entry and
//! exit then see different approximations, and an elastic face impact gains up to 2.9e-3 of
//! its energy at `dt_fraction` 0.05 (docs/validation.md §3). Here a step of a face contact
//! near its entry or exit ([`TRAJECTORY_FRACTION`]) takes, instead, the impulse of the
//! contact's own one-dimensional motion
//!
//! `m* δ̈ = −W'(V(δ)) V'(δ)`,  `V(δ) = V (δ/h)^k` (the local power law),
//!
//! over its kick window `[t − Δt/2, t + Δt/2]`, integrated backward and forward from the
//! current depth `h` at the window's mid-point speed `v̄ = v_{n+1/2} + F̄ Δt/(2 m*)` (the speed
//! at the force's sample time, found by a few fixed-point passes: `F̄` is the impulse over
//! `Δt`). The kick is time-symmetric about the sample, so a contact's entry and exit errors
//! mirror each other and cancel to a higher order. A contact's first step also carries the
//! impulse of the window before it (the last step saw the bodies apart), and a step whose
//! coming drift carries the bodies apart the impulse of the window after it: both from the same
//! motion, so nothing is counted twice.

use super::potential::{LocalPowerLaw, resolved_pressure};

/// How a face contact's elastic force is sampled over a step (`simulation.face_window`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FaceWindow {
    /// The secant of the potential over the volume swept at constant speed, with separate
    /// entry and exit terms (docs/contact.md §1); both backends. The default until the
    /// trajectory's gated kernels had run on a GPU: scenes whose results were made with it
    /// (the production cases) name it.
    Secant,
    /// The impulse of the contact's one-dimensional motion over the kick window (the module
    /// docs); both backends (`PD_FACE_TRAJECTORY` in the kernels). The default: an elastic
    /// face impact gains at most 3.1e-4 on a wall and 7.0e-4 on a cube at `dt_fraction` 0.05,
    /// against 2.7e-3 with the secant.
    #[default]
    Trajectory,
}

impl FaceWindow {
    /// The name in scene files.
    pub fn name(self) -> &'static str {
        match self {
            FaceWindow::Secant => "secant",
            FaceWindow::Trajectory => "trajectory",
        }
    }
}

/// A face contact follows its trajectory only while the window's half width sweeps more than
/// this fraction of its volume (`|v_n| Δt/2 · A > f V`: within a few steps of its entry or
/// exit); deeper, it takes the slope at V, as the secant does below its own fraction. There
/// the two differ by about `f²/27` of the force (the window's mean of `δ^{1/3}` about the
/// sample), the step is symplectic, and a settled packing, whose face contacts are all deep,
/// does not pay for the trajectory (ungated it cost 41 % of the settled dodecahedra's GPU
/// step, docs/contact.md §1). With 0.1 the face impacts of docs/validation.md §3 hold the
/// ungated trajectory's bounds (an elastic one gains at most 7.0e-4 at `dt_fraction` 0.05).
pub const TRAJECTORY_FRACTION: f64 = 0.1;

/// RK4 sub-steps over each half of the kick window (and over each neighbouring window). The
/// face's stiffness is bounded by the regularization below `V*` at `ω Δt` ≤
/// [`super::potential::RESOLVED_STEP`], so four sub-steps resolve it; with two the face impact
/// of docs/validation.md §3 did not reach 1e-3 at `dt_fraction` 0.05.
pub const WINDOW_SUBSTEPS: u32 = 4;

/// Fixed-point passes for the window's mid-point speed. Each pass contracts the error by about
/// `(ω Δt/2)²` ≤ 1/16; the impact's energy changed in the fourth digit from the second pass
/// to the third and not after it.
pub const MIDPOINT_PASSES: u32 = 3;

/// The one-dimensional normal motion of a contact about its current state: the approach `d`
/// beyond the current depth `h` and its rate (positive approaching).
#[derive(Clone, Copy, Debug)]
pub(super) struct NormalMotion {
    law: LocalPowerLaw,
    stiffness: f64,
    resolved: f64,
    inverse_mass: f64,
}

impl NormalMotion {
    /// The motion under the regularized potential `W` (stiffness `c`, `V*` = `resolved`) of the
    /// local power law `law`, for the effective mass `mass`.
    pub(super) fn new(law: LocalPowerLaw, stiffness: f64, resolved: f64, mass: f64) -> Self {
        Self {
            law,
            stiffness,
            resolved,
            inverse_mass: 1.0 / mass,
        }
    }

    /// `d̈` at the approach `d`: `−W'(V) V'(δ)/m*` with `V'(δ) = k V/δ` (the contact area of
    /// the power law), zero once apart.
    fn acceleration(&self, d: f64) -> f64 {
        let depth = self.law.depth + d;
        if depth <= 0.0 {
            return 0.0;
        }
        let v = self.law.volume_at(d);
        let area = self.law.exponent * v / depth;
        -resolved_pressure(self.stiffness, v, self.resolved) * area * self.inverse_mass
    }

    /// The state `(d, ḋ)` after the time `span` (backward when negative): RK4 in
    /// [`WINDOW_SUBSTEPS`] sub-steps, a sub-step that would carry the bodies apart at its
    /// starting speed shortened to that moment (the force has a kink at touch), free flight
    /// once apart.
    fn flow(&self, mut d: f64, mut rate: f64, span: f64) -> (f64, f64) {
        let sign = if span < 0.0 { -1.0 } else { 1.0 };
        let mut left = span.abs();
        let full = left / f64::from(WINDOW_SUBSTEPS);
        for _ in 0..4 * WINDOW_SUBSTEPS {
            if left <= 0.0 {
                break;
            }
            let depth = self.law.depth + d;
            if depth <= 0.0 {
                d += sign * rate * left;
                break;
            }
            let mut h = full.min(left);
            // The depth lost per unit time along the integration.
            let out = -sign * rate;
            if out > 0.0 && depth - out * h < 0.0 {
                let touch = depth / out;
                if touch >= 1e-14 * full {
                    h = h.min(touch);
                }
            }
            let s = sign * h;
            let (k1d, k1r) = (rate, self.acceleration(d));
            let (k2d, k2r) = (rate + 0.5 * s * k1r, self.acceleration(d + 0.5 * s * k1d));
            let (k3d, k3r) = (rate + 0.5 * s * k2r, self.acceleration(d + 0.5 * s * k2d));
            let (k4d, k4r) = (rate + s * k3r, self.acceleration(d + s * k3d));
            d += s / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d);
            rate += s / 6.0 * (k1r + 2.0 * k2r + 2.0 * k3r + k4r);
            left -= h;
        }
        (d, rate)
    }

    /// The mean elastic force (N, pushing apart) over the kick window of a step whose last
    /// drift had the normal speed `vn` (positive separating), from the first guess `guess`;
    /// `first` when the last step found the bodies apart (the window before this one is
    /// carried too). A step whose coming drift, at the speed this kick leaves, ends apart also
    /// carries the window after it. `kick` maps an elastic force to the normal force the step
    /// applies (the law's damping and caps): the speed the kick leaves is judged with it, so
    /// that the window after is carried exactly when the next step finds the bodies apart. With
    /// the elastic force alone a damped exit was judged apart too early, and the next step,
    /// still in contact, took the same window again (one phase of a cube's e = 0.5 impact
    /// rebounded 0.6 % too fast at `dt_fraction` 0.05).
    pub(super) fn window_force(
        &self,
        vn: f64,
        dt: f64,
        first: bool,
        guess: f64,
        kick: impl Fn(f64) -> f64,
    ) -> f64 {
        let half = -vn;
        let mut force = guess;
        for _ in 0..MIDPOINT_PASSES {
            let mid = half - 0.5 * force * self.inverse_mass * dt;
            let (d_back, r_back) = self.flow(0.0, mid, -0.5 * dt);
            let (d_ahead, r_ahead) = self.flow(0.0, mid, 0.5 * dt);
            // The approach rate the window's force takes away.
            let mut taken = r_back - r_ahead;
            if first {
                let (_, r) = self.flow(d_back, r_back, -dt);
                taken += r - r_back;
            }
            let left = kick(taken / (self.inverse_mass * dt)) * self.inverse_mass * dt;
            if self.law.depth + (half - left) * dt <= 0.0 {
                let (_, r) = self.flow(d_ahead, r_ahead, dt);
                taken += r_ahead - r;
            }
            force = taken / (self.inverse_mass * dt);
        }
        force
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A face (k = 1, unit area) of the seed's law, no regularization, unit mass and
    /// stiffness, at the depth `h`.
    fn face(h: f64) -> NormalMotion {
        NormalMotion::new(
            LocalPowerLaw {
                volume: h,
                depth: h,
                exponent: 1.0,
            },
            1.0,
            0.0,
            1.0,
        )
    }

    /// At rest at the depth h the window's force is the force at h to second order in Δt:
    /// `F(h) = h^{1/3}`, and the motion's own curvature changes it by O(Δt²).
    #[test]
    fn at_rest_the_window_force_is_the_force_at_the_sample() {
        let h = 1.0;
        let f = face(h);
        for dt in [0.1, 0.05, 0.025] {
            let w = f.window_force(0.0, dt, false, 1.0, |f| f.max(0.0));
            // δ(t) ≈ h − F t²/2 about the sample (v̄ = 0 after the kick's half): the mean of
            // F(δ) over ±Δt/2 is F(h) (1 − F Δt²/(72 h) + …) = 1 − Δt²/72 here.
            let expected = 1.0 - dt * dt / 72.0;
            assert!(
                (w - expected).abs() < 2e-2 * dt * dt,
                "dt {dt}: {w} against {expected}"
            );
        }
    }

    /// The motion conserves `ḋ²/2 + W(V(d))/m*` (for a face `V = δ`, `W = (3/4) δ^{4/3}`): a
    /// check of the RK4 and its touch-shortened sub-steps over one window of `dt_fraction`
    /// 0.05 (Δt = 0.085 for this law at unit speed) through the separation, where the face's
    /// stiffness is unbounded (no regularization here).
    #[test]
    fn the_motion_conserves_its_energy_through_separation() {
        let f = face(0.01);
        let energy = |d: f64, r: f64| {
            let x: f64 = (0.01 + d).max(0.0);
            0.5 * r * r + 0.75 * x * x.cbrt()
        };
        let (d, r) = f.flow(0.0, -0.9, 0.0425);
        assert!(0.01 + d < 0.0, "apart at the end: depth {}", 0.01 + d);
        let (e0, e1) = (energy(0.0, -0.9), energy(d, r));
        // 5.6e-5: four sub-steps against the unbounded stiffness at touch, which the scene's
        // regularization below V* bounds in a run.
        assert!((e1 - e0).abs() < 1e-4 * e0, "{e0} → {e1}");
        // Backward from the same state: the mirror motion.
        let (d2, r2) = f.flow(0.0, 0.9, -0.0425);
        assert!(
            (d2 - d).abs() < 1e-12 && (r2 + r).abs() < 1e-12,
            "{d2} {r2}"
        );
        // From deep inside, a whole window: the RK4's own error.
        let g = face(0.5);
        let energy = |d: f64, r: f64| {
            let x: f64 = 0.5 + d;
            0.5 * r * r + 0.75 * x * x.cbrt()
        };
        let (d, r) = g.flow(0.0, 0.3, 0.085);
        let (e0, e1) = (energy(0.0, 0.3), energy(d, r));
        assert!((e1 - e0).abs() < 1e-9 * e0, "{e0} → {e1}");
    }
}
