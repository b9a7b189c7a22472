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

/// The planes of both bodies as rows of the LP over `(x, t)`, of type `P` read in the
/// arithmetic of `T` (each plane converted as it is read; exact, and the identity when `P` is
/// `T`).
struct Rows<'a, P: Real> {
    a: &'a [Plane<P>],
    b: &'a [Plane<P>],
}

impl<P: Real> Rows<'_, P> {
    fn len(&self) -> usize {
        self.a.len() + self.b.len()
    }

    fn plane<T: Real>(&self, i: usize) -> Plane<T> {
        let p = if i < self.a.len() {
            &self.a[i]
        } else {
            &self.b[i - self.a.len()]
        };
        Plane {
            normal: Vector3::new(
                T::of(p.normal.x.f64()),
                T::of(p.normal.y.f64()),
                T::of(p.normal.z.f64()),
            ),
            offset: T::of(p.offset.f64()),
        }
    }

    /// Row `i` of the constraint `n_i · x + t <= h_i`.
    fn row<T: Real>(&self, i: usize) -> Vector4<T> {
        let p = self.plane::<T>(i);
        Vector4::new(p.normal.x, p.normal.y, p.normal.z, T::one())
    }

    fn slack<T: Real>(&self, i: usize, z: &Vector4<T>) -> T {
        self.plane::<T>(i).offset - self.row(i).dot(z)
    }

    /// The radius of a point: its smallest slack over every plane.
    fn radius_at<T: Real>(&self, x: &Vector3<T>) -> T {
        let mut radius = T::max_value().unwrap_or(T::one());
        for i in 0..self.len() {
            let p = self.plane::<T>(i);
            radius = radius.min(p.offset - p.normal.dot(x));
        }
        radius
    }
}

/// The working set of the active-set method: at most four active rows, their orthonormal basis
/// `q` and the triangular `r` with `row(active[j]) = Σ_k r[k][j] q_k`.
struct WorkingSet<T: Real> {
    active: [usize; 4],
    n_active: usize,
    q: [Vector4<T>; 4],
    r: [[T; 4]; 4],
}

impl<T: Real> WorkingSet<T> {
    /// Gram–Schmidt over the active rows; rows dependent on the earlier ones (within `tiny`)
    /// are dropped from the working set.
    fn orthonormalise<P: Real>(&mut self, rows: &Rows<P>, tiny: T) {
        self.q = [Vector4::zeros(); 4];
        self.r = [[T::zero(); 4]; 4];
        let mut kept = 0;
        for j in 0..self.n_active {
            let mut v = rows.row::<T>(self.active[j]);
            let norm0 = v.norm();
            for k in 0..kept {
                let c = self.q[k].dot(&v);
                self.r[k][kept] = c;
                v -= self.q[k] * c;
            }
            let norm = v.norm();
            if norm <= tiny * norm0 {
                continue; // linearly dependent on the others: not needed in the working set
            }
            self.r[kept][kept] = norm;
            self.q[kept] = v / norm;
            self.active[kept] = self.active[j];
            kept += 1;
        }
        self.n_active = kept;
    }

    /// The part of `c` orthogonal to every active row.
    fn project(&self, c: Vector4<T>) -> Vector4<T> {
        let mut d = c;
        for qk in self.q.iter().take(self.n_active) {
            d -= qk * qk.dot(&c);
        }
        d
    }

    /// With `c = Σ λ_j row_j` in the span of the active rows (`R λ = Qᵀ c`), the working-set
    /// slot of the row to drop: the lowest plane index among multipliers below `-tiny` (Bland's
    /// rule, which prevents cycling); `None` when the KKT conditions hold.
    fn row_to_drop(&self, c: &Vector4<T>, tiny: T) -> Option<usize> {
        let n = self.n_active;
        let mut rhs = [T::zero(); 4];
        for (k, rk) in rhs.iter_mut().enumerate().take(n) {
            *rk = self.q[k].dot(c);
        }
        let mut lambda = [T::zero(); 4];
        for k in (0..n).rev() {
            let mut s = rhs[k];
            for (rkj, lj) in self.r[k].iter().zip(&lambda).take(n).skip(k + 1) {
                s -= *rkj * *lj;
            }
            lambda[k] = s / self.r[k][k];
        }
        let mut drop: Option<usize> = None;
        for (k, lk) in lambda.iter().enumerate().take(n) {
            if *lk < -tiny && drop.is_none_or(|j| self.active[k] < self.active[j]) {
                drop = Some(k);
            }
        }
        drop
    }

    /// Ratio test: the first inactive plane met when moving from `z` along `d`, and the step.
    fn entering<P: Real>(
        &self,
        rows: &Rows<P>,
        z: &Vector4<T>,
        d: &Vector4<T>,
        tiny: T,
    ) -> Option<(usize, T)> {
        let mut step = T::max_value().unwrap_or(T::one());
        let mut enter: Option<usize> = None;
        for i in 0..rows.len() {
            if self.active[..self.n_active].contains(&i) {
                continue;
            }
            let rate = rows.row::<T>(i).dot(d);
            if rate <= tiny {
                continue;
            }
            let s = rows.slack(i, z).max(T::zero()) / rate;
            if s < step {
                step = s;
                enter = Some(i);
            }
        }
        enter.map(|i| (i, step))
    }

    /// `z + shift`, put back on the active constraints where it breaks them by more than
    /// rounding.
    ///
    /// Two nearly opposite planes (a face lying on a face: a slab a few nanometres thick,
    /// tilted by 1e-12) leave a projected objective of 1e-13 that points along the slab, and
    /// a step of 1e10 along it: the rounding of d's other components, multiplied by that
    /// step, carried the point micrometres out of the slab, the radius came out negative
    /// and an overlap was reported as none. When a step breaks the active constraints by
    /// more than rounding, the point is put back on them: the least change z += Σ y_k q_k
    /// with Rᵀ y equal to their slacks.
    fn step_to<P: Real>(&self, rows: &Rows<P>, z: Vector4<T>, shift: Vector4<T>) -> Vector4<T> {
        let n = self.n_active;
        let mut moved = z + shift;
        let broken = self.active[..n].iter().any(|&j| {
            // The rounding bound of the slack: the magnitudes of its terms and of the step.
            let r = rows.row::<T>(j).abs();
            let scale = rows.plane::<T>(j).offset.abs() + r.dot(&moved.abs()) + r.dot(&shift.abs());
            rows.slack(j, &moved) < -T::of(1024.0) * T::EPSILON * scale
        });
        if broken {
            let mut y = [T::zero(); 4];
            for k in 0..n {
                let mut s = rows.slack(self.active[k], &moved);
                for (j, yj) in y.iter().enumerate().take(k) {
                    s -= self.r[j][k] * *yj;
                }
                y[k] = s / self.r[k][k];
            }
            for (qk, yk) in self.q.iter().zip(y.iter()).take(n) {
                moved += qk * *yk;
            }
        }
        moved
    }
}

/// The LP over planes of type `P`, in the arithmetic of `T`: the active-set iteration of the
/// module docs. Each step orthonormalises the working set, then either moves along the
/// projected objective to the first blocking plane (which joins the set) or, where the
/// objective lies in the span of the active rows, drops a row of negative multiplier or stops.
fn solve<P: Real, T: Real>(
    a: &[Plane<P>],
    b: &[Plane<P>],
    start: Vector3<T>,
) -> ChebyshevCentre<T> {
    let rows = Rows { a, b };
    let m = rows.len();

    // Start: t = smallest slack at `start`, which makes that plane active.
    let mut z = Vector4::new(start.x, start.y, start.z, T::zero());
    let mut first = 0;
    let mut t_min = T::max_value().unwrap_or(T::one());
    for i in 0..m {
        let p = rows.plane::<T>(i);
        let s = p.offset - p.normal.dot(&start);
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
    let mut set = WorkingSet {
        active: [first, 0, 0, 0],
        n_active: 1,
        q: [Vector4::zeros(); 4],
        r: [[T::zero(); 4]; 4],
    };

    // The best point met: a step that rounding has spoilt cannot lose a better one.
    let mut best_point = start;
    let mut best_radius = rows.radius_at(&start);

    let mut steps = 0;
    while steps < MAX_STEPS {
        steps += 1;
        set.orthonormalise(&rows, tiny);
        // Four independent active rows leave no null space: d is zero by definition, not by
        // round-off.
        let d = set.project(objective);
        if set.n_active == 4 || d.norm() <= T::of(1024.0) * T::EPSILON {
            match set.row_to_drop(&objective, tiny) {
                None => break, // KKT conditions hold: optimal
                Some(k) => {
                    set.active[k] = set.active[set.n_active - 1];
                    set.n_active -= 1;
                    continue;
                }
            }
        }
        let Some((i, step)) = set.entering(&rows, &z, &d, tiny) else {
            break; // unbounded cannot happen for bounded polytopes; stop defensively
        };
        z = set.step_to(&rows, z, d * step);
        let point = Vector3::new(z.x, z.y, z.z);
        let radius = rows.radius_at(&point);
        if radius > best_radius {
            best_point = point;
            best_radius = radius;
        }
        if set.n_active < 4 {
            set.active[set.n_active] = i;
            set.n_active += 1;
        }
    }

    // The radius is recomputed from the final point so that it is exact for the point returned;
    // the best point met is returned if it is better.
    let mut point = Vector3::new(z.x, z.y, z.z);
    let mut radius = rows.radius_at(&point);
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
