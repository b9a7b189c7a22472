// The Chebyshev centre of the intersection of two polytopes: the robust interior point of the
// dual-space overlap computation. Mirrors src/geometry/interior.rs.
//
// maximise t subject to n_i · x + t <= h_i for every face plane i of A and B, a linear
// programme in (x, t) solved by a primal active-set method (simplex method in projected-gradient
// form, Bland's rule against cycling). t* > 0 exactly when the interiors intersect.
#pragma once

#include "common.cuh"
#include "polytope.cuh"

namespace pd {

// Most active-set steps (Rust interior::MAX_STEPS).
#ifndef PD_CHEBYSHEV_MAX_STEPS
#define PD_CHEBYSHEV_MAX_STEPS 100
#endif

// A 4-vector (x, y, z, t) for the LP, with nalgebra's Vector4 operations.
template <class T> struct V4 {
    T x, y, z, w;
};
template <class T> PD_HD V4<T> v4(T x, T y, T z, T w) {
    V4<T> r;
    r.x = x;
    r.y = y;
    r.z = z;
    r.w = w;
    return r;
}
// nalgebra's dot for 4-vectors pairs the terms: (x x' + z z') + (y y' + w w').
template <class T> PD_HD T dot4(V4<T> a, V4<T> b) {
    T p = a.x * b.x;
    T q = a.y * b.y;
    T r = a.z * b.z;
    T s = a.w * b.w;
    p += r;
    q += s;
    return p + q;
}
template <class T> PD_HD T norm4(V4<T> a) { return sqrt_(dot4(a, a)); }
template <class T> PD_HD V4<T> add4(V4<T> a, V4<T> b) { return v4(a.x + b.x, a.y + b.y, a.z + b.z, a.w + b.w); }
template <class T> PD_HD V4<T> sub4(V4<T> a, V4<T> b) { return v4(a.x - b.x, a.y - b.y, a.z - b.z, a.w - b.w); }
template <class T> PD_HD V4<T> scale4(V4<T> a, T s) { return v4(a.x * s, a.y * s, a.z * s, a.w * s); }
template <class T> PD_HD V4<T> div4(V4<T> a, T s) { return v4(a.x / s, a.y / s, a.z / s, a.w / s); }

// Result of chebyshev_centre (Rust `ChebyshevCentre<T>`).
template <class T> struct ChebyshevCentre {
    // The centre of the largest ball inside both polytopes.
    V3<T> point;
    // Its radius; negative when the polytopes are disjoint.
    T radius;
    // Active-set steps taken.
    int steps;
};

// A plane of type P in the arithmetic of T (exact; the identity when P is T).
template <class T, class P> PD_HD Plane<T> plane_as(const Plane<P>& p) {
    Plane<T> q;
    q.normal = v3(T(p.normal.x), T(p.normal.y), T(p.normal.z));
    q.offset = T(p.offset);
    return q;
}

// The radius of the point x: its smallest slack over the planes of a and b.
template <class T, class P>
PD_HD T smallest_slack(const Plane<P>* a, int na, const Plane<P>* b, int nb, V3<T> x) {
    T radius = Limits<T>::max();
    for (int i = 0; i < na + nb; ++i) {
        const Plane<T> p = plane_as<T>(i < na ? a[i] : b[i - na]);
        radius = min_(radius, p.offset - dot(p.normal, x));
    }
    return radius;
}

// interior::chebyshev_centre (interior::solve): solves the inscribed-ball LP over the planes of
// a (na planes) and b (nb planes), of type P, in the arithmetic of T, starting from `start`.
template <class T, class P>
PD_HD ChebyshevCentre<T> chebyshev_centre(const Plane<P>* a, int na, const Plane<P>* b, int nb, V3<T> start) {
#define PD_CC_PLANE(i) plane_as<T>((i) < na ? a[(i)] : b[(i) - na])
    const int m = na + nb;
    const T tmax = Limits<T>::max();

    // Start: t = smallest slack at `start`, which makes that plane active.
    V4<T> z = v4(start.x, start.y, start.z, T(0));
    int first = 0;
    T t_min = tmax;
    for (int i = 0; i < m; ++i) {
        const Plane<T>& p = PD_CC_PLANE(i);
        T s = p.offset - dot(p.normal, start);
        if (s < t_min) {
            t_min = s;
            first = i;
        }
    }
    ChebyshevCentre<T> out;
    if (m == 0) {
        out.point = start;
        out.radius = T(0);
        out.steps = 0;
        return out;
    }
    z.w = t_min;
    const V4<T> objective = v4(T(0), T(0), T(0), T(1));
    const T tiny = T(64.0) * Limits<T>::epsilon();
    int active[4] = {first, 0, 0, 0};
    int n_active = 1;

    // The best point met (interior.rs): its radius is its smallest slack over every plane.
    V3<T> best_point = start;
    T best_radius = smallest_slack<T, P>(a, na, b, nb, start);

    int steps = 0;
    while (steps < PD_CHEBYSHEV_MAX_STEPS) {
        steps += 1;
        // Orthonormal basis q of the active rows (Gram–Schmidt), R with
        // row(active[j]) = Σ_k R[k][j] q_k; dependent rows are dropped.
        V4<T> q[4];
        T r[4][4];
        for (int k = 0; k < 4; ++k) {
            q[k] = v4(T(0), T(0), T(0), T(0));
            for (int j = 0; j < 4; ++j) r[k][j] = T(0);
        }
        int kept = 0;
        for (int j = 0; j < n_active; ++j) {
            const Plane<T>& pj = PD_CC_PLANE(active[j]);
            V4<T> v = v4(pj.normal.x, pj.normal.y, pj.normal.z, T(1));
            T norm0 = norm4(v);
            for (int k = 0; k < kept; ++k) {
                T c = dot4(q[k], v);
                r[k][kept] = c;
                v = sub4(v, scale4(q[k], c));
            }
            T nv = norm4(v);
            if (nv <= tiny * norm0) continue; // linearly dependent on the others
            r[kept][kept] = nv;
            q[kept] = div4(v, nv);
            active[kept] = active[j];
            kept += 1;
        }
        n_active = kept;

        // Projected objective: the part of c orthogonal to every active row.
        V4<T> d = objective;
        for (int k = 0; k < n_active; ++k) d = sub4(d, scale4(q[k], dot4(q[k], objective)));
        if (n_active == 4 || norm4(d) <= T(1024.0) * Limits<T>::epsilon()) {
            // c = Σ λ_j row_j: solve R λ = Qᵀ c.
            T rhs[4] = {T(0), T(0), T(0), T(0)};
            for (int k = 0; k < n_active; ++k) rhs[k] = dot4(q[k], objective);
            T lambda[4] = {T(0), T(0), T(0), T(0)};
            for (int k = n_active - 1; k >= 0; --k) {
                T s = rhs[k];
                for (int j = k + 1; j < n_active; ++j) s -= r[k][j] * lambda[j];
                lambda[k] = s / r[k][k];
            }
            // Bland's rule (lowest plane index among negative multipliers) prevents cycling.
            int drop = -1;
            for (int k = 0; k < n_active; ++k) {
                if (lambda[k] < -tiny && (drop < 0 || active[k] < active[drop])) drop = k;
            }
            if (drop < 0) break; // KKT conditions hold: optimal
            active[drop] = active[n_active - 1];
            n_active -= 1;
            continue;
        }

        // Ratio test: the first inactive plane met when moving along d.
        T step = tmax;
        int enter = -1;
        for (int i = 0; i < m; ++i) {
            bool is_active = false;
            for (int k = 0; k < n_active; ++k)
                if (active[k] == i) is_active = true;
            if (is_active) continue;
            const Plane<T>& pi = PD_CC_PLANE(i);
            V4<T> row = v4(pi.normal.x, pi.normal.y, pi.normal.z, T(1));
            T rate = dot4(row, d);
            if (rate <= tiny) continue;
            T slack = pi.offset - dot4(row, z);
            T s = max_(slack, T(0)) / rate;
            if (s < step) {
                step = s;
                enter = i;
            }
        }
        if (enter < 0) break; // unbounded cannot happen for bounded polytopes; stop defensively
        // A step along a direction made of round-off that breaks the active constraints it is
        // meant to keep is not taken (interior.rs gives the case).
        V4<T> shift = scale4(d, step);
        V4<T> moved = add4(z, shift);
        // A step that breaks the active constraints by more than rounding is put back on them
        // (interior.rs gives the case): z += Σ y_k q_k with Rᵀ y equal to their slacks.
        bool broken = false;
        for (int k = 0; k < n_active; ++k) {
            const Plane<T>& pk = PD_CC_PLANE(active[k]);
            V4<T> row = v4(pk.normal.x, pk.normal.y, pk.normal.z, T(1));
            V4<T> row_abs = v4(abs_(row.x), abs_(row.y), abs_(row.z), abs_(row.w));
            V4<T> moved_abs = v4(abs_(moved.x), abs_(moved.y), abs_(moved.z), abs_(moved.w));
            V4<T> shift_abs = v4(abs_(shift.x), abs_(shift.y), abs_(shift.z), abs_(shift.w));
            // The rounding bound of the slack: the magnitudes of its terms and of the step.
            T scale = abs_(pk.offset) + dot4(row_abs, moved_abs) + dot4(row_abs, shift_abs);
            if (pk.offset - dot4(row, moved) < -T(1024.0) * Limits<T>::epsilon() * scale) broken = true;
        }
        if (broken) {
            T y[4] = {T(0), T(0), T(0), T(0)};
            for (int k = 0; k < n_active; ++k) {
                const Plane<T>& pk = PD_CC_PLANE(active[k]);
                V4<T> row = v4(pk.normal.x, pk.normal.y, pk.normal.z, T(1));
                T s = pk.offset - dot4(row, moved);
                for (int j = 0; j < k; ++j) s -= r[j][k] * y[j];
                y[k] = s / r[k][k];
            }
            for (int k = 0; k < n_active; ++k) moved = add4(moved, scale4(q[k], y[k]));
        }
        z = moved;
        {
            V3<T> point = v3(z.x, z.y, z.z);
            T radius = smallest_slack<T, P>(a, na, b, nb, point);
            if (radius > best_radius) {
                best_point = point;
                best_radius = radius;
            }
        }
        if (n_active < 4) {
            active[n_active] = enter;
            n_active += 1;
        }
    }

    // The radius is recomputed from the final point so that it is exact for the point returned;
    // the best point met is returned if it is better.
    V3<T> point = v3(z.x, z.y, z.z);
    T radius = smallest_slack<T, P>(a, na, b, nb, point);
    if (best_radius > radius) {
        point = best_point;
        radius = best_radius;
    }
    out.point = point;
    out.radius = radius;
    out.steps = steps;
    return out;
#undef PD_CC_PLANE
}

// interior::chebyshev_centre_wide: the LP solved in double whatever the planes' type, from the
// frame origin; the point returned in T with its radius recomputed in T. In double it is
// chebyshev_centre itself. Mixed precision needs it for a face resting on a face: the LP's
// radius grows along the thin wedge of their overlap at the rate of the faces' tilt, which f32
// arithmetic cannot tell from zero (interior.rs gives the case).
template <class T>
PD_HD ChebyshevCentre<T> chebyshev_centre_wide(const Plane<T>* a, int na, const Plane<T>* b, int nb) {
    ChebyshevCentre<double> c = chebyshev_centre<double, T>(a, na, b, nb, zero3<double>());
    ChebyshevCentre<T> out;
    out.point = v3(T(c.point.x), T(c.point.y), T(c.point.z));
    out.radius = smallest_slack<T, T>(a, na, b, nb, out.point);
    out.steps = c.steps;
    return out;
}
template <>
PD_HD ChebyshevCentre<double> chebyshev_centre_wide<double>(const Plane<double>* a, int na, const Plane<double>* b,
                                                                 int nb) {
    return chebyshev_centre<double, double>(a, na, b, nb, zero3<double>());
}

} // namespace pd
