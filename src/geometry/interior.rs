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
    solve::<T, T>(a, b, start)
}

/// [`chebyshev_centre`] solved in f64 whatever the planes' type, from the frame origin; the
/// point is returned in `T` with its radius recomputed in `T`. In f64 it is
/// `chebyshev_centre` itself.
///
/// The pair geometry of mixed precision (f32 planes) needs it. A face resting on a face
/// overlaps in a thin wedge: the LP's radius grows along the wedge at a rate of its faces'
/// tilt, 1e-5 for a settled packing, which is below what the LP's f32 arithmetic can tell from
/// zero (1024 ε = 1.2e-4 for the projected objective, 64 ε for the ratio test), so in f32 it
/// stopped wherever it entered the wedge, often nanometres from a face. The proof of the
/// intersection then failed and the overlap evaluated about that point was wrong by orders of
/// magnitude (tests/mixed_flat_contacts.rs). The f32 planes carry the wedge's tilt to 1e-7,
/// and the f64 LP finds their centre; the rest of the geometry, about that centre, keeps f32.
pub fn chebyshev_centre_wide<T: Real>(a: &[Plane<T>], b: &[Plane<T>]) -> ChebyshevCentre<T> {
    if T::EPSILON.f64() == f64::EPSILON {
        return solve::<T, T>(a, b, Vector3::zeros());
    }
    let c = solve::<T, f64>(a, b, Vector3::zeros());
    let point = Vector3::new(T::of(c.point.x), T::of(c.point.y), T::of(c.point.z));
    let mut radius = T::max_value().unwrap_or(T::one());
    for p in a.iter().chain(b) {
        radius = radius.min(p.offset - p.normal.dot(&point));
    }
    ChebyshevCentre {
        point,
        radius,
        steps: c.steps,
    }
}

/// The LP over planes of type `P`, in the arithmetic of `T` (each plane converted as it is
/// read; exact, and the identity when `P` is `T`).
fn solve<P: Real, T: Real>(
    a: &[Plane<P>],
    b: &[Plane<P>],
    start: Vector3<T>,
) -> ChebyshevCentre<T> {
    let convert = |p: &Plane<P>| Plane {
        normal: Vector3::new(
            T::of(p.normal.x.f64()),
            T::of(p.normal.y.f64()),
            T::of(p.normal.z.f64()),
        ),
        offset: T::of(p.offset.f64()),
    };
    let plane = |i: usize| convert(if i < a.len() { &a[i] } else { &b[i - a.len()] });
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

    // The radius of a point: its smallest slack over every plane.
    let radius_at = |x: &Vector3<T>| {
        let mut radius = T::max_value().unwrap_or(T::one());
        for i in 0..m {
            radius = radius.min(plane(i).offset - plane(i).normal.dot(x));
        }
        radius
    };
    // The best point met: a step that rounding has spoilt cannot lose a better one.
    let mut best_point = start;
    let mut best_radius = radius_at(&start);

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
        // Two nearly opposite planes (a face lying on a face: a slab a few nanometres thick,
        // tilted by 1e-12) leave a projected objective of 1e-13 that points along the slab, and
        // a step of 1e10 along it: the rounding of d's other components, multiplied by that
        // step, carried the point micrometres out of the slab, the radius came out negative
        // and an overlap was reported as none. When a step breaks the active constraints by
        // more than rounding, the point is put back on them: the least change z += Σ y_k q_k
        // with Rᵀ y equal to their slacks.
        let shift = d * step;
        let mut moved = z + shift;
        let broken = active[..n_active].iter().any(|&j| {
            // The rounding bound of the slack: the magnitudes of its terms and of the step.
            let r = row(j).abs();
            let scale = plane(j).offset.abs() + r.dot(&moved.abs()) + r.dot(&shift.abs());
            slack(j, &moved) < -T::of(1024.0) * T::EPSILON * scale
        });
        if broken {
            let mut y = [T::zero(); 4];
            for k in 0..n_active {
                let mut s = slack(active[k], &moved);
                for (j, yj) in y.iter().enumerate().take(k) {
                    s -= r[j][k] * *yj;
                }
                y[k] = s / r[k][k];
            }
            for (qk, yk) in q.iter().zip(y.iter()).take(n_active) {
                moved += qk * *yk;
            }
        }
        z = moved;
        let point = Vector3::new(z.x, z.y, z.z);
        let radius = radius_at(&point);
        if radius > best_radius {
            best_point = point;
            best_radius = radius;
        }
        if n_active < 4 {
            active[n_active] = i;
            n_active += 1;
        }
    }

    // The radius is recomputed from the final point so that it is exact for the point returned;
    // the best point met is returned if it is better.
    let mut point = Vector3::new(z.x, z.y, z.z);
    let mut radius = radius_at(&point);
    if best_radius > radius {
        point = best_point;
        radius = best_radius;
    }
    ChebyshevCentre {
        point,
        radius,
        steps,
    }
}
