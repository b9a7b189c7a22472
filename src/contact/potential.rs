//! The contact law's elastic potential (seed Eq. 12): `U(V) = (3/4) c V^{4/3}`, its mean slope
//! over a kick window, the local power law `V(δ)` a contact's exit is judged by, and the
//! regularized potential `W` below `V*` that a resting face needs (docs/contact.md §1).

use crate::geometry::{portable_cbrt, portable_pow};

/// The elastic force takes the mean slope of U over its kick window when the window's half
/// width is more than this fraction of the volume, and the slope at V otherwise.
pub const WINDOW_FRACTION: f64 = 0.5;

/// The kick window (its mean slope, the entry and the exit) is for contacts whose local
/// exponent `k = A_n h / V` (`h` the overlap's thickness) is below this: the force
/// `F ∝ δ^{4k/3 − 1}` then has the stiffness `δ^{4k/3 − 2}`, unbounded at first touch (a face
/// on a face, `k = 1`). From `k = 3/2` on (an edge, a sphere, a vertex) the force vanishes at
/// least linearly at touch, the slope at V is as accurate, and it keeps the step symplectic:
/// with the window open on every grazing sphere or vertex contact a packing's energy drifted,
/// and the aligned cubes' energy error stopped converging below `t_c/80` (docs/validation.md
/// §3).
pub const SINGULAR_EXPONENT: f64 = 1.5;

/// The overlap's local power law `V(δ) = V (δ/h)^k` about the current penetration `h` (the
/// overlap's `thickness` along the normal), with `k = A_n h / V`: 1 for a face on a face, 2 for
/// an edge or a sphere, 3 for a vertex (`V` convex in `δ` bounds `k` to `[1, 3]` for convex
/// bodies; round-off is clamped into it). It decides where the kick window is needed
/// ([`SINGULAR_EXPONENT`]) and, being apart exactly at `δ = 0`, predicts a contact's exit. An
/// overlap without a thickness (a degenerate geometry) is taken as a face, `h = V/A_n`.
#[derive(Clone, Copy, Debug)]
pub(super) struct LocalPowerLaw {
    pub(super) volume: f64,
    pub(super) depth: f64,
    pub(super) exponent: f64,
}

impl LocalPowerLaw {
    pub(super) fn new(volume: f64, area: f64, thickness: f64) -> Self {
        let thickness = if thickness > 0.0 && thickness.is_finite() {
            thickness
        } else {
            volume / area
        };
        let ratio = area * thickness / volume;
        // max then min, not clamp: a NaN ratio becomes 1 as in the CUDA twin's
        // `min_(max_(…))`, where clamp would keep the NaN.
        #[allow(clippy::manual_clamp)]
        let exponent = ratio.max(1.0).min(3.0);
        // A clamped exponent takes the depth that keeps the law's slope at V the contact's
        // area, `V'(h) = k V/h = A_n`: the vertices' exit depth is taken down to half of
        // `V/A_n` (geometry::overlap), and such a depth short of `V/A_n` with k held at 1 gave
        // the face's motion of `contact::trajectory` the area `V/h`, up to twice `A_n`, and an
        // elastic force as much too large. (Past `3 V/A_n`, k held at 3 gave too small a one.)
        let depth = if ratio.is_finite() && ratio != exponent {
            exponent * volume / area
        } else {
            thickness
        };
        Self {
            volume,
            depth,
            exponent,
        }
    }

    /// The volume after the bodies approach by `d` more (move apart for `d < 0`): 0 once they
    /// are apart.
    pub(super) fn volume_at(&self, d: f64) -> f64 {
        let ratio = 1.0 + d / self.depth;
        if ratio > 0.0 {
            self.volume * portable_pow(ratio, self.exponent)
        } else {
            0.0
        }
    }
}

/// `U(V) = (3/4) c V^{4/3}` for `V > 0`, else 0.
fn potential(c: f64, v: f64) -> f64 {
    if v > 0.0 {
        0.75 * c * v * portable_cbrt(v)
    } else {
        0.0
    }
}

/// The mean slope `(U(hi) − U(lo))/(hi − lo)` of `U = (3/4) c V^{4/3}` (zero below `V = 0`)
/// over the volume window `[lo, hi]`, `hi > 0`, `hi ≥ lo`; `c V^{1/3}` = U'(V) for an empty
/// window. With `x = lo^{1/3}`, `y = hi^{1/3}` the secant is `(3/4) c (x + y)(x² + y²) /
/// (x² + x y + y²)`, which has no cancellation as the window closes.
pub fn mean_pressure(c: f64, lo: f64, hi: f64) -> f64 {
    if hi <= lo {
        return c * portable_cbrt(hi.max(0.0));
    }
    if lo <= 0.0 {
        return potential(c, hi) / (hi - lo);
    }
    let (x, y) = (portable_cbrt(lo), portable_cbrt(hi));
    0.75 * c * (x + y) * (x * x + y * y) / (x * x + x * y + y * y)
}

/// `ω Δt` at the stiffest point of a face contact's law as regularized below
/// [`resolved_volume`]: a resting face then oscillates about its load with at most half a
/// radian per step, well inside the explicit step's limit of 2 even with several such
/// contacts on one particle.
pub const RESOLVED_STEP: f64 = 0.5;

/// The volume `V* = (A_n Δt √(c/m*) / σ)³`, `σ` = [`RESOLVED_STEP`], below which a face
/// contact's potential is regularized ([`resolved_potential`]). The seed's face law
/// `F = c A_n^{4/3} δ^{1/3}` has the stiffness `F/(3δ)`, unbounded as `δ → 0`: a face resting
/// under a load `m g` sits at `δ = (m g / (c A_n^{4/3}))³` (0.6 nm for a soft 2 cm cube, 1e-15 m
/// at E = 10 MPa), where its oscillation period is far below any practical step, so an explicit
/// step cannot hold it at rest: it is thrown off, falls back and chatters at the step's scale,
/// and every hop resets its friction spring. Below `V*` the force grows linearly with the
/// stiffness `A_n² c V*^{−2/3} = σ² m*/Δt²`, which the step resolves; above it the force is
/// the seed's. `V*` shrinks as `Δt³`, so the law converges to the seed's as the step does; an
/// impact at `Δt = t_c/40` reaches about 1e4 times `V*`.
pub fn resolved_volume(c: f64, area: f64, dt: f64, effective_mass: f64) -> f64 {
    let x = area * dt * (c / effective_mass).sqrt() / RESOLVED_STEP;
    x * x * x
}

/// The regularized face potential: `W(V) = (c/2) V*^{−2/3} V²` below `V*`, `U(V) − (1/4) c
/// V*^{4/3}` above it ([`resolved_volume`]); zero at touch, continuous with a continuous
/// slope `W'`, which is `c V*^{−2/3} V` below `V*` and the seed's `c V^{1/3}` above. `U` for
/// `V* = 0`.
pub fn resolved_potential(c: f64, v: f64, resolved: f64) -> f64 {
    if v <= 0.0 {
        0.0
    } else if v < resolved {
        let r = portable_cbrt(resolved);
        0.5 * c * v * v / (r * r)
    } else {
        potential(c, v) - 0.25 * c * resolved * portable_cbrt(resolved)
    }
}

/// `W'(V)` of [`resolved_potential`].
pub(super) fn resolved_pressure(c: f64, v: f64, resolved: f64) -> f64 {
    if v <= 0.0 {
        0.0
    } else if v < resolved {
        let r = portable_cbrt(resolved);
        c * v / (r * r)
    } else {
        c * portable_cbrt(v)
    }
}

/// The mean slope of [`resolved_potential`] over `[lo, hi]` (`hi > 0`): [`mean_pressure`]
/// where the window lies above `V*` (the offset cancels), the difference quotient of `W`
/// where it reaches below (the kick window is used only when it is wider than the volume, so
/// the quotient has no cancellation).
pub fn resolved_mean_pressure(c: f64, lo: f64, hi: f64, resolved: f64) -> f64 {
    if hi <= lo {
        resolved_pressure(c, hi, resolved)
    } else if lo >= resolved {
        mean_pressure(c, lo, hi)
    } else {
        (resolved_potential(c, hi, resolved) - resolved_potential(c, lo, resolved)) / (hi - lo)
    }
}
