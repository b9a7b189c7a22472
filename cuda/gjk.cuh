// GJK intersection test between two convex vertex sets (seed paper Alg. I), in the distance form
// of Gilbert, Johnson & Keerthi as refined by van den Bergen 1999.
// Mirrors src/geometry/gjk.rs operation for operation.
#pragma once

#include "common.cuh"

namespace pd {

// Most iterations (Rust gjk::MAX_ITERATIONS).
#ifndef PD_GJK_MAX_ITERATIONS
#define PD_GJK_MAX_ITERATIONS 64
#endif

// gjk::support: the point of `points` farthest along `dir` (first one on ties).
template <class T> PD_HD V3<T> gjk_support(const V3<T>* points, int n, V3<T> dir) {
    V3<T> best = points[0];
    T best_dot = dot(best, dir);
    for (int i = 1; i < n; ++i) {
        T d = dot(points[i], dir);
        if (d > best_dot) {
            best_dot = d;
            best = points[i];
        }
    }
    return best;
}

// gjk::closest_on_triangle: closest point to the origin on triangle (a, b, c) by Voronoi regions
// (Ericson 2005 §5.1.5), and which vertices span its feature (keep[0..3]).
template <class T> PD_HD V3<T> gjk_closest_on_triangle(V3<T> a, V3<T> b, V3<T> c, bool keep[3]) {
    const T zero = T(0);
    V3<T> ab = b - a;
    V3<T> ac = c - a;
    V3<T> ap = -a;
    T d1 = dot(ab, ap);
    T d2 = dot(ac, ap);
    if (d1 <= zero && d2 <= zero) {
        keep[0] = true, keep[1] = false, keep[2] = false;
        return a;
    }
    V3<T> bp = -b;
    T d3 = dot(ab, bp);
    T d4 = dot(ac, bp);
    if (d3 >= zero && d4 <= d3) {
        keep[0] = false, keep[1] = true, keep[2] = false;
        return b;
    }
    T vc = d1 * d4 - d3 * d2;
    if (vc <= zero && d1 >= zero && d3 <= zero) {
        T v = d1 / (d1 - d3);
        keep[0] = true, keep[1] = true, keep[2] = false;
        return a + ab * v;
    }
    V3<T> cp = -c;
    T d5 = dot(ab, cp);
    T d6 = dot(ac, cp);
    if (d6 >= zero && d5 <= d6) {
        keep[0] = false, keep[1] = false, keep[2] = true;
        return c;
    }
    T vb = d5 * d2 - d1 * d6;
    if (vb <= zero && d2 >= zero && d6 <= zero) {
        T w = d2 / (d2 - d6);
        keep[0] = true, keep[1] = false, keep[2] = true;
        return a + ac * w;
    }
    T va = d3 * d6 - d5 * d4;
    if (va <= zero && (d4 - d3) >= zero && (d5 - d6) >= zero) {
        T w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        keep[0] = false, keep[1] = true, keep[2] = true;
        return b + (c - b) * w;
    }
    T denom = va + vb + vc;
    if (denom <= zero) {
        // Degenerate (collinear) triangle: fall back to the best of its edges.
        V3<T> best = a;
        keep[0] = true, keep[1] = false, keep[2] = false;
        V3<T> ps[3] = {a, a, b};
        V3<T> qs[3] = {b, c, c};
        for (int e = 0; e < 3; ++e) {
            V3<T> p = ps[e], q = qs[e];
            V3<T> pq = q - p;
            T l = norm2(pq);
            T t = zero;
            if (l > zero) {
                // Rust: (-p.dot(pq) / l).max(0).min(1)
                t = min_(max_(-dot(p, pq) / l, zero), T(1));
            }
            V3<T> x = p + pq * t;
            if (norm2(x) < norm2(best)) {
                best = x;
                keep[0] = e != 2;
                keep[1] = e != 1;
                keep[2] = e != 0;
            }
        }
        return best;
    }
    T v = vb / denom;
    T w = vc / denom;
    keep[0] = true, keep[1] = true, keep[2] = true;
    return a + ab * v + ac * w;
}

// gjk::Simplex: up to four points of A ⊖ B.
template <class T> struct GjkSimplex {
    V3<T> p[4];
    int n;

    PD_HD void push(V3<T> w) { p[n++] = w; }

    PD_HD bool contains(V3<T> w) const {
        for (int i = 0; i < n; ++i)
            if (p[i] == w) return true;
        return false;
    }

    // Simplex::reduce_segment.
    PD_HD V3<T> reduce_segment() {
        V3<T> a = p[0], b = p[1];
        V3<T> ab = b - a;
        T t = -dot(a, ab);
        if (t <= T(0)) {
            p[0] = a;
            n = 1;
            return a;
        }
        T denom = norm2(ab);
        if (t >= denom) {
            p[0] = b;
            n = 1;
            return b;
        }
        return a + ab * (t / denom);
    }

    // Simplex::reduce_triangle.
    PD_HD V3<T> reduce_triangle() {
        bool keep[3];
        V3<T> q = gjk_closest_on_triangle(p[0], p[1], p[2], keep);
        V3<T> old[3] = {p[0], p[1], p[2]};
        n = 0;
        for (int i = 0; i < 3; ++i)
            if (keep[i]) p[n++] = old[i];
        return q;
    }

    // Simplex::reduce_tetrahedron: false when the origin lies inside the tetrahedron.
    PD_HD bool reduce_tetrahedron(V3<T>& out) {
        V3<T> a = p[0], b = p[1], c = p[2], d = p[3];
        // Faces (p, q, r) with the opposite vertex and the face's vertex indices.
        V3<T> fp[4] = {a, a, a, b};
        V3<T> fq[4] = {b, c, d, d};
        V3<T> fr[4] = {c, d, b, c};
        V3<T> fo[4] = {d, b, c, a};
        const int fidx[4][3] = {{0, 1, 2}, {0, 2, 3}, {0, 3, 1}, {1, 3, 2}};
        bool have = false;
        T best_dist = T(0);
        V3<T> best_x = zero3<T>();
        int best_face = 0;
        bool best_keep[3] = {false, false, false};
        for (int f = 0; f < 4; ++f) {
            V3<T> pp = fp[f], qq = fq[f], rr = fr[f], opp = fo[f];
            V3<T> nrm = cross(qq - pp, rr - pp);
            T sign_origin = -dot(pp, nrm);
            T sign_opp = dot(opp - pp, nrm);
            // Outside when the signs differ; a flat tetrahedron (sign_opp ≈ 0) tests every face.
            bool outside = sign_origin * sign_opp <= T(0);
            if (!outside) continue;
            bool keep[3];
            V3<T> x = gjk_closest_on_triangle(pp, qq, rr, keep);
            T dist = norm2(x);
            if (!have || dist < best_dist) {
                have = true;
                best_dist = dist;
                best_x = x;
                best_face = f;
                best_keep[0] = keep[0], best_keep[1] = keep[1], best_keep[2] = keep[2];
            }
        }
        if (!have) return false;
        V3<T> old[4] = {p[0], p[1], p[2], p[3]};
        n = 0;
        for (int i = 0; i < 3; ++i)
            if (best_keep[i]) p[n++] = old[fidx[best_face][i]];
        out = best_x;
        return true;
    }

    // Simplex::reduce: replaces the simplex by the smallest sub-simplex containing its point
    // closest to the origin and returns that point; false when the origin is inside.
    PD_HD bool reduce(V3<T>& out) {
        if (n == 1) {
            out = p[0];
            return true;
        }
        if (n == 2) {
            out = reduce_segment();
            return true;
        }
        if (n == 3) {
            out = reduce_triangle();
            return true;
        }
        return reduce_tetrahedron(out);
    }
};

// gjk::gjk_separating_axis (seed Alg. I): returns true when the hulls of a and b are disjoint and
// then writes a separating axis v (a point of A ⊖ B, not normalised, with v·a > v·b for all
// a ∈ A, b ∈ B) to *axis; returns false (axis zeroed) when they intersect (touching counts as
// intersecting to within about 1e3 ε size). Empty inputs are disjoint with axis x. `dir` is the
// initial search direction, usually the centre-to-centre vector.
template <class T> PD_HD bool gjk_separating_axis(const V3<T>* a, int na, const V3<T>* b, int nb, V3<T> dir, V3<T>* axis) {
    *axis = zero3<T>();
    if (na == 0 || nb == 0) {
        *axis = v3<T>(T(1), T(0), T(0));
        return true;
    }
    // Length scale for the tolerances: the extent of A ⊖ B.
    T ext_a, ext_b;
    {
        V3<T> lo = a[0], hi = a[0];
        for (int i = 0; i < na; ++i) {
            lo = vmin(lo, a[i]);
            hi = vmax(hi, a[i]);
        }
        ext_a = norm(hi - lo);
    }
    {
        V3<T> lo = b[0], hi = b[0];
        for (int i = 0; i < nb; ++i) {
            lo = vmin(lo, b[i]);
            hi = vmax(hi, b[i]);
        }
        ext_b = norm(hi - lo);
    }
    T scale = ext_a + ext_b + norm(a[0] - b[0]);
    T tol = T(1e3) * Limits<T>::epsilon() * scale;
    T tol2 = tol * tol;

    V3<T> d = norm2(dir) > T(0) ? dir : v3<T>(T(1), T(0), T(0));
    // v: closest point of the simplex to the origin; start from one support point.
    V3<T> v = gjk_support(a, na, d) - gjk_support(b, nb, -d);
    GjkSimplex<T> simplex;
    simplex.n = 0;
    simplex.push(v);
    for (int it = 0; it < PD_GJK_MAX_ITERATIONS; ++it) {
        T vv = norm2(v);
        if (vv <= tol2) return false; // the origin is (within tolerance) on the simplex
        d = -v;
        V3<T> w = gjk_support(a, na, d) - gjk_support(b, nb, -d);
        // A support plane with normal v separates the origin by at least v·w/|v| (Eq. 3).
        T vw = dot(v, w);
        if (vw > tol * sqrt_(vv)) {
            *axis = v;
            return true;
        }
        // No progress: w is already (numerically) the closest extent in this direction.
        if (vv - vw <= T(64.0) * Limits<T>::epsilon() * vv || simplex.contains(w)) {
            if (sqrt_(vv) > tol) {
                *axis = v;
                return true;
            }
            return false;
        }
        simplex.push(w);
        V3<T> closest;
        if (!simplex.reduce(closest)) return false; // origin inside the tetrahedron
        v = closest;
    }
    if (norm2(v) > tol2) {
        *axis = v;
        return true;
    }
    return false;
}

// gjk::gjk_intersect: true when the convex hulls of a and b intersect.
template <class T> PD_HD bool gjk_intersect(const V3<T>* a, int na, const V3<T>* b, int nb, V3<T> dir) {
    V3<T> axis;
    return !gjk_separating_axis(a, na, b, nb, dir, &axis);
}

} // namespace pd
