//! GJK intersection test between two convex vertex sets (seed paper Alg. I).
//!
//! The test runs GJK on the Minkowski difference `A ⊖ B` (Eq. 1–3) and keeps, at every
//! iteration, the point `v` of the current simplex closest to the origin (the distance form of
//! Gilbert, Johnson & Keerthi as refined by van den Bergen 1999). Using the closest point rather
//! than only a "which side" test makes the loop converge from deep overlap down to barely touching
//! bodies: it ends when the origin is enclosed (intersecting), when a support plane separates the
//! origin (disjoint), or when `v` stops improving (then `|v|` is the distance, compared with a
//! tolerance relative to the bodies' size).

use super::Real;
use nalgebra::Vector3;

/// Most iterations; GJK on polytopes terminates in far fewer (each iteration adds a new vertex of
/// `A ⊖ B`), the cap only guards against round-off ping-pong.
const MAX_ITERATIONS: usize = 64;

#[inline]
fn support<T: Real>(points: &[Vector3<T>], dir: &Vector3<T>) -> Vector3<T> {
    let mut best = points[0];
    let mut best_dot = best.dot(dir);
    for p in &points[1..] {
        let d = p.dot(dir);
        if d > best_dot {
            best_dot = d;
            best = *p;
        }
    }
    best
}

/// True when the convex hulls of `a` and `b` intersect (touching counts as intersecting, to
/// within a distance of about `1e3 · ε · size`). `dir` is the initial search direction, usually
/// the centre-to-centre vector (seed Alg. I line 1). Empty inputs never intersect.
pub fn gjk_intersect<T: Real>(a: &[Vector3<T>], b: &[Vector3<T>], dir: Vector3<T>) -> bool {
    gjk_separating_axis(a, b, dir).is_none()
}

/// GJK as [`gjk_intersect`], returning for disjoint hulls a separating axis `v` (a point of
/// `A ⊖ B`, not normalised) with `v·a > v·b` for every `a ∈ A`, `b ∈ B`, and `None` when they
/// intersect. Empty inputs are disjoint, with axis `x`.
///
/// The axis is what a caller keeps from one step to the next: bodies move little per step, so
/// the last axis usually still separates and two support evaluations replace the whole GJK
/// (frame coherence, van den Bergen 1999 §4).
pub fn gjk_separating_axis<T: Real>(
    a: &[Vector3<T>],
    b: &[Vector3<T>],
    dir: Vector3<T>,
) -> Option<Vector3<T>> {
    if a.is_empty() || b.is_empty() {
        return Some(Vector3::x());
    }
    // Length scale for the tolerances: the extent of A ⊖ B.
    let extent = |pts: &[Vector3<T>]| {
        let mut lo = pts[0];
        let mut hi = pts[0];
        for p in pts {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        (hi - lo).norm()
    };
    let scale = extent(a) + extent(b) + (a[0] - b[0]).norm();
    let tol = T::of(1e3) * T::EPSILON * scale;
    let tol2 = tol * tol;

    let mut d = if dir.norm_squared() > T::zero() {
        dir
    } else {
        Vector3::x()
    };
    // v: closest point of the simplex to the origin; start from one support point.
    let mut v = support(a, &d) - support(b, &(-d));
    let mut simplex = Simplex::<T>::default();
    simplex.push(v);
    for _ in 0..MAX_ITERATIONS {
        let vv = v.norm_squared();
        if vv <= tol2 {
            return None; // the origin is (within tolerance) on the simplex
        }
        d = -v;
        let w = support(a, &d) - support(b, &(-d));
        // A support plane with normal v separates the origin by at least v·w/|v| (Eq. 3 and
        // Alg. I line 7). A gap below the tolerance is treated as touching and refined further.
        let vw = v.dot(&w);
        if vw > tol * vv.sqrt() {
            return Some(v);
        }
        // No progress: w is already (numerically) the closest extent in this direction.
        if vv - vw <= T::of(64.0) * T::EPSILON * vv || simplex.contains(&w) {
            return (vv.sqrt() > tol).then_some(v);
        }
        simplex.push(w);
        match simplex.reduce() {
            Some(closest) => v = closest,
            None => return None, // origin inside the tetrahedron
        }
    }
    (v.norm_squared() > tol2).then_some(v)
}

/// A tetrahedron face whose closest point may be the simplex's: squared distance, the point,
/// the face's vertex indices, and which of them span the closest feature.
type FaceCandidate<T> = (T, Vector3<T>, [usize; 3], [bool; 3]);

/// Up to four points of `A ⊖ B`.
#[derive(Clone, Copy, Debug, Default)]
struct Simplex<T: Real> {
    p: [Vector3<T>; 4],
    n: usize,
}

impl<T: Real> Simplex<T> {
    fn push(&mut self, w: Vector3<T>) {
        self.p[self.n] = w;
        self.n += 1;
    }

    fn contains(&self, w: &Vector3<T>) -> bool {
        self.p[..self.n].iter().any(|p| p == w)
    }

    /// Replaces the simplex by the smallest sub-simplex containing its point closest to the
    /// origin and returns that point; `None` when the origin lies inside a tetrahedron.
    fn reduce(&mut self) -> Option<Vector3<T>> {
        match self.n {
            1 => Some(self.p[0]),
            2 => Some(self.reduce_segment()),
            3 => Some(self.reduce_triangle()),
            _ => self.reduce_tetrahedron(),
        }
    }

    fn reduce_segment(&mut self) -> Vector3<T> {
        let (a, b) = (self.p[0], self.p[1]);
        let ab = b - a;
        let t = -a.dot(&ab);
        if t <= T::zero() {
            self.p[0] = a;
            self.n = 1;
            return a;
        }
        let denom = ab.norm_squared();
        if t >= denom {
            self.p[0] = b;
            self.n = 1;
            return b;
        }
        a + ab * (t / denom)
    }

    /// Closest point of triangle (a, b, c) to the origin by Voronoi regions (Ericson 2005,
    /// "Real-Time Collision Detection" §5.1.5), shrinking the simplex to the feature used.
    fn reduce_triangle(&mut self) -> Vector3<T> {
        let (a, b, c) = (self.p[0], self.p[1], self.p[2]);
        let (q, keep) = closest_on_triangle(a, b, c);
        let old = self.p;
        self.n = 0;
        for (i, k) in keep.iter().enumerate() {
            if *k {
                self.p[self.n] = old[i];
                self.n += 1;
            }
        }
        q
    }

    fn reduce_tetrahedron(&mut self) -> Option<Vector3<T>> {
        let [a, b, c, d] = self.p;
        // Faces with the opposite vertex; the origin is outside a face when it lies on the
        // other side of the face plane from the opposite vertex.
        let faces = [
            (a, b, c, d, [0, 1, 2]),
            (a, c, d, b, [0, 2, 3]),
            (a, d, b, c, [0, 3, 1]),
            (b, d, c, a, [1, 3, 2]),
        ];
        let mut best: Option<FaceCandidate<T>> = None;
        for (p, q, r, opp, idx) in faces {
            let n = (q - p).cross(&(r - p));
            let sign_origin = -p.dot(&n);
            let sign_opp = (opp - p).dot(&n);
            // Outside when the signs differ; a flat tetrahedron (sign_opp ≈ 0) tests every face.
            let outside = sign_origin * sign_opp <= T::zero();
            if !outside {
                continue;
            }
            let (x, keep) = closest_on_triangle(p, q, r);
            let dist = x.norm_squared();
            if best.as_ref().is_none_or(|b| dist < b.0) {
                best = Some((dist, x, idx, keep));
            }
        }
        let (_, x, idx, keep) = best?;
        let old = self.p;
        self.n = 0;
        for (i, k) in keep.iter().enumerate() {
            if *k {
                self.p[self.n] = old[idx[i]];
                self.n += 1;
            }
        }
        Some(x)
    }
}

/// Closest point to the origin on triangle (a, b, c) and which vertices span its feature.
fn closest_on_triangle<T: Real>(
    a: Vector3<T>,
    b: Vector3<T>,
    c: Vector3<T>,
) -> (Vector3<T>, [bool; 3]) {
    let zero = T::zero();
    let ab = b - a;
    let ac = c - a;
    let ap = -a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= zero && d2 <= zero {
        return (a, [true, false, false]);
    }
    let bp = -b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= zero && d4 <= d3 {
        return (b, [false, true, false]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= zero && d1 >= zero && d3 <= zero {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [true, true, false]);
    }
    let cp = -c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= zero && d5 <= d6 {
        return (c, [false, false, true]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= zero && d2 >= zero && d6 <= zero {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [true, false, true]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= zero && (d4 - d3) >= zero && (d5 - d6) >= zero {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [false, true, true]);
    }
    let denom = va + vb + vc;
    if denom <= zero {
        // Degenerate (collinear) triangle: fall back to the best of its edges.
        let mut best = (a, [true, false, false]);
        for (p, q, keep) in [
            (a, b, [true, true, false]),
            (a, c, [true, false, true]),
            (b, c, [false, true, true]),
        ] {
            let pq = q - p;
            let l = pq.norm_squared();
            let t = if l > zero {
                (-p.dot(&pq) / l).max(zero).min(T::one())
            } else {
                zero
            };
            let x = p + pq * t;
            if x.norm_squared() < best.0.norm_squared() {
                best = (x, keep);
            }
        }
        return best;
    }
    let v = vb / denom;
    let w = vc / denom;
    (a + ab * v + ac * w, [true, true, true])
}
