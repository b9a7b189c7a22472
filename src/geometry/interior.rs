//! The Chebyshev centre of the intersection of two polytopes: the robust interior point of the
//! dual-space overlap computation.
//!
//! The polar transform of seed Eq. 4–5 maps each face plane to `n / δ`, where `δ` is the distance
//! from the reference point `x₀` to the plane. It is well conditioned only when every `δ` is
//! large compared with round-off: `x₀` must be deep inside the intersection. The midpoint of the
//! two centroids is not even inside it for a barely-touching pair, and points found by GJK lie on
//! its boundary. We therefore take the point that maximises the smallest distance to all planes,
//! the centre of the largest inscribed ball:
//!
//! ```text
//!   maximise t   subject to   n_i · x + t <= h_i   for every face plane i of A and B,
//! ```
//!
//! a linear programme in the four unknowns (x, t). It is solved by a primal active-set method
//! (the simplex method in its "projected gradient" form): starting from any x with t equal to its
//! smallest slack (always feasible, because t is free), move along the projection of the objective
//! onto the null space of the active constraints until another constraint blocks, and drop an
//! active constraint whose Lagrange multiplier is negative. With four unknowns a vertex has four
//! active constraints, every step costs one pass over the planes, and the optimum is reached in a
//! handful of steps. The optimum `t*` is positive exactly when the interiors intersect, so the same
//! solve is also an exact intersection test; `t*` is the half-thickness of the overlap lens.

use super::Real;
use super::polytope::Plane;
use nalgebra::{Vector3, Vector4};

/// Most active-set steps; the optimum is usually found in fewer than ten. Hitting the cap leaves a
/// feasible (if not optimal) point, which is still a valid reference point when `radius > 0`.
const MAX_STEPS: usize = 100;

/// Result of [`chebyshev_centre`].
#[derive(Clone, Copy, Debug)]
pub struct ChebyshevCentre<T: Real> {
    /// The centre of the largest ball inside both polytopes.
    pub point: Vector3<T>,
    /// Its radius: the smallest distance from `point` to any plane. Negative when the polytopes
    /// are disjoint (then `-radius` bounds how far apart they are, in the sense of this LP).
    pub radius: T,
    /// Active-set steps taken.
    pub steps: usize,
}

/// Solves the inscribed-ball LP over the planes of `a` and `b`, starting from `start`.
pub fn chebyshev_centre<T: Real>(
    a: &[Plane<T>],
    b: &[Plane<T>],
    start: Vector3<T>,
) -> ChebyshevCentre<T> {
    let plane = |i: usize| if i < a.len() { &a[i] } else { &b[i - a.len()] };
    let m = a.len() + b.len();
    let row = |i: usize| {
        let p = plane(i);
        Vector4::new(p.normal.x, p.normal.y, p.normal.z, T::one())
    };
    let slack = |i: usize, z: &Vector4<T>| plane(i).offset - row(i).dot(z);

    // Start: t = smallest slack at `start`, which makes that plane active.
    let mut z = Vector4::new(start.x, start.y, start.z, T::zero());
    let mut first = 0;
    let mut t_min = T::max_value().unwrap_or(T::one());
    for i in 0..m {
        let s = plane(i).offset - plane(i).normal.dot(&start);
        if s < t_min {
            t_min = s;
            first = i;
        }
    }
    if m == 0 {
        return ChebyshevCentre {
            point: start,
            radius: T::zero(),
            steps: 0,
        };
    }
    z.w = t_min;
    let objective = Vector4::new(T::zero(), T::zero(), T::zero(), T::one());
    let tiny = T::of(64.0) * T::EPSILON;
    let mut active = [0usize; 4];
    let mut n_active = 1;
    active[0] = first;

    let mut steps = 0;
    while steps < MAX_STEPS {
        steps += 1;
        // Orthonormal basis q of the active rows (Gram–Schmidt), with R such that
        // row(active[j]) = Σ_k R[k][j] q_k; dependent rows are dropped.
        let mut q = [Vector4::<T>::zeros(); 4];
        let mut r = [[T::zero(); 4]; 4];
        let mut kept = 0;
        for j in 0..n_active {
            let mut v = row(active[j]);
            let norm0 = v.norm();
            for k in 0..kept {
                let c = q[k].dot(&v);
                r[k][kept] = c;
                v -= q[k] * c;
            }
            let norm = v.norm();
            if norm <= tiny * norm0 {
                continue; // linearly dependent on the others: not needed in the working set
            }
            r[kept][kept] = norm;
            q[kept] = v / norm;
            active[kept] = active[j];
            kept += 1;
        }
        n_active = kept;

        // Projected objective: the part of c orthogonal to every active row. Four independent
        // active rows leave no null space: d is zero by definition, not by round-off.
        let mut d = objective;
        for qk in q.iter().take(n_active) {
            d -= qk * qk.dot(&objective);
        }
        if n_active == 4 || d.norm() <= T::of(1024.0) * T::EPSILON {
            // c lies in the span of the active rows: c = Σ λ_j row_j. Solve R λ = Qᵀ c.
            let mut rhs = [T::zero(); 4];
            for k in 0..n_active {
                rhs[k] = q[k].dot(&objective);
            }
            let mut lambda = [T::zero(); 4];
            for k in (0..n_active).rev() {
                let mut s = rhs[k];
                for j in k + 1..n_active {
                    s -= r[k][j] * lambda[j];
                }
                lambda[k] = s / r[k][k];
            }
            // Bland's rule (lowest plane index among negative multipliers) prevents cycling.
            let mut drop: Option<usize> = None;
            for k in 0..n_active {
                if lambda[k] < -tiny && drop.is_none_or(|j| active[k] < active[j]) {
                    drop = Some(k);
                }
            }
            match drop {
                None => break, // KKT conditions hold: optimal
                Some(k) => {
                    active[k] = active[n_active - 1];
                    n_active -= 1;
                    continue;
                }
            }
        }

        // Ratio test: the first inactive plane met when moving along d.
        let mut step = T::max_value().unwrap_or(T::one());
        let mut enter: Option<usize> = None;
        for i in 0..m {
            if active[..n_active].contains(&i) {
                continue;
            }
            let rate = row(i).dot(&d);
            if rate <= tiny {
                continue;
            }
            let s = slack(i, &z).max(T::zero()) / rate;
            if s < step {
                step = s;
                enter = Some(i);
            }
        }
        let Some(i) = enter else {
            break; // unbounded cannot happen for bounded polytopes; stop defensively
        };
        z += d * step;
        if n_active < 4 {
            active[n_active] = i;
            n_active += 1;
        }
    }

    // The radius is recomputed from the final point so that it is exact for the point returned.
    let point = Vector3::new(z.x, z.y, z.z);
    let mut radius = T::max_value().unwrap_or(T::one());
    for i in 0..m {
        radius = radius.min(plane(i).offset - plane(i).normal.dot(&point));
    }
    ChebyshevCentre {
        point,
        radius,
        steps,
    }
}
