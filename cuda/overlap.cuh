// Overlap of two convex polyhedra by dual-space Quickhull (seed paper Alg. II–VI, Eq. 4–9).
// Mirrors src/geometry/overlap.rs operation for operation; the pair evaluation that places the
// planes is pair.cuh.
//
// With an interior point x0 each plane n·x <= h has a distance δ = h − n·x0 > 0 and a dual point
// n/δ (Eq. 4–5); the hull of the dual points gives the combinatorics of A ∩ B, each intersection
// vertex is recomputed from its three planes (Cramer), each face is fanned from the foot of x0:
// V = Σ δ_u A_u / 3 (Eq. 9), the centroid, S = dV/dx_B = Σ_{u∈B} A_u n_u (Feng, Han & Owen 2012)
// and the moment M_B of B's part of the overlap surface about the centroid.
#pragma once

#include "common.cuh"
#include "gjk.cuh"
#include "interior.cuh"
#include "polytope.cuh"
#include "quickhull.cuh"
#include "vertex_enumeration.cuh"

// Profiling build (PD_PHASE_CLOCKS, from POLYDEM_PHASE_CLOCKS): thread-cycles of each phase of a
// pair evaluation summed into pd_clk (slot meanings in src/backend/cuda/contacts.rs); the host
// harness and ordinary builds compile the markers away.
#if defined(PD_PHASE_CLOCKS) && defined(__CUDACC__)
__device__ unsigned long long pd_clk[16];
#define PD_CLK(i)                                                                                                     \
    {                                                                                                                  \
        long long n_ = clock64();                                                                                      \
        atomicAdd(&pd_clk[i], (unsigned long long)(n_ - pd_t));                                                        \
        pd_t = n_;                                                                                                     \
    }
#define PD_CLK_START long long pd_t = clock64();
#define PD_CLK_COUNT(i) atomicAdd(&pd_clk[i], 1ull);
#else
#define PD_CLK(i)
#define PD_CLK_START
#define PD_CLK_COUNT(i)
#endif

namespace pd {

// Geometric result of an overlap evaluation (Rust `Overlap<T>`).
template <class T> struct Overlap {
    // Overlap volume V.
    T volume;
    // Centroid of the overlap region.
    V3<T> centroid;
    // S = dV/dx_B: vector area of the overlap surface lying on B.
    V3<T> dv_dxb;
    // M_B: moment of B's part of the overlap surface about the centroid.
    V3<T> moment_b;
    // Radius of the largest ball inside the overlap; negative when the bodies are apart.
    T depth;
    // Extent of the overlap region along the normal −S/|S|.
    T thickness;
};

// Overlap::default.
template <class T> PD_HD Overlap<T> overlap_zero() {
    Overlap<T> o;
    o.volume = T(0);
    o.centroid = zero3<T>();
    o.dv_dxb = zero3<T>();
    o.moment_b = zero3<T>();
    o.depth = T(0);
    o.thickness = T(0);
    return o;
}

// Overlap::to_world: the same overlap in double, shifted by `origin` (back to world coordinates).
template <class T> PD_HD Overlap<double> to_world(const Overlap<T>& o, V3<double> origin) {
    Overlap<double> w;
    w.volume = double(o.volume);
    w.centroid = widen(o.centroid) + origin;
    w.dv_dxb = widen(o.dv_dxb);
    w.moment_b = widen(o.moment_b);
    w.depth = double(o.depth);
    w.thickness = double(o.thickness);
    return w;
}

// Buffers of one overlap evaluation (Rust `OverlapWorkspace<T>`), one per thread, reused.
template <class T> struct OverlapWorkspace {
    DualHull<T> hull;
    FaceEnumeration<T> faces;
    V3<T> dual[PD_MAX_HULL_POINTS];
    V3<T> normal[PD_MAX_HULL_POINTS];
    T delta[PD_MAX_HULL_POINTS];
    T area[PD_MAX_HULL_POINTS];
    V3<T> first_moment[PD_MAX_HULL_POINTS];
    V3<T> vertex[PD_MAX_HULL_FACES];
    T share_b[PD_MAX_HULL_POINTS];
    V3<T> x0;
    // Planes of the last evaluation, and whether its faces came from the dual hull.
    int m;
    bool by_hull;

    // OverlapWorkspace::face_area: area of the intersection face on plane i of the last
    // evaluation (planes of A first, then of B).
    PD_HD T face_area(int i) const { return area[i]; }

    // OverlapWorkspace::extent_along: the spread of the last evaluation's vertices along the unit
    // vector n (a facet overlap's penetration behind its facet).
    PD_HD T extent_along(V3<T> n) const {
        T lo = Limits<T>::max(), hi = -Limits<T>::max();
        if (by_hull) {
            for (int s = 0; s < hull.n_tri; ++s) {
                if (!hull.tri[s].alive) continue;
                T h = dot(n, vertex[s]);
                lo = min_(lo, h);
                hi = max_(hi, h);
            }
        } else {
            for (int v = 0; v < faces.n_vertices; ++v) {
                T h = dot(n, faces.vertex[v]);
                lo = min_(lo, h);
                hi = max_(hi, h);
            }
        }
        return max_(hi - lo, T(0));
    }

    // OverlapWorkspace::hull_vertex_excess: the farthest that a vertex of the last evaluation's
    // dual hull lies outside one of its planes (zero for the enumeration's faces); a hull that
    // round-off bent has vertices outside by as much as the particle size.
    PD_HD T hull_vertex_excess() const {
        T worst = T(0);
        if (!by_hull) return worst;
        for (int s = 0; s < hull.n_tri; ++s) {
            if (!hull.tri[s].alive) continue;
            for (int u = 0; u < m; ++u) worst = max_(worst, dot(normal[u], vertex[s]) - delta[u]);
        }
        return worst;
    }
};

// overlap::set_shares: share of each plane's face in S, 1 for B's planes, 0 for A's, half to
// each of a plane of A and a plane of B that coincide (dual points within tol).
template <class T> PD_HD void set_shares(OverlapWorkspace<T>& ws, int m, int na, T tol) {
    for (int i = 0; i < m; ++i) ws.share_b[i] = i < na ? T(0) : T(1);
    for (int i = 0; i < na; ++i) {
        for (int j = na; j < m; ++j) {
            if (norm2(ws.dual[i] - ws.dual[j]) <= tol * tol) {
                ws.share_b[i] = T(0.5);
                ws.share_b[j] = T(0.5);
            }
        }
    }
}

// overlap::enumerate_faces: face areas and first moments by vertex enumeration for
// m <= PD_ENUM_MAX_PLANES, coincident planes keeping the first copy; returns whether the faces
// close (|Σ A_u n_u| <= 256 ε Σ |A_u|) and the enumeration held its vertices, else the caller
// uses the hull.
template <class T> PD_HD bool enumerate_faces(OverlapWorkspace<T>& ws, int m, int na, T scale) {
    T max_coord = T(0);
    for (int i = 0; i < m; ++i) {
        max_coord = max_(max_(max_(max_coord, abs_(ws.dual[i].x)), abs_(ws.dual[i].y)), abs_(ws.dual[i].z));
    }
    const T tol = T(32.0) * Limits<T>::epsilon() * max_coord;
    set_shares(ws, m, na, tol);
    unsigned int active = 0u;
    for (int j = 0; j < m; ++j) {
        bool copy = false;
        for (int i = 0; i < j && !copy; ++i) copy = norm2(ws.dual[i] - ws.dual[j]) <= tol * tol;
        if (!copy) active |= 1u << j;
    }
    const T vertex_tol = T(64.0) * Limits<T>::epsilon() * scale;
    if (!ws.faces.enumerate(ws.normal, ws.delta, m, active, vertex_tol)) return false;
    V3<T> closure = zero3<T>();
    T total = T(0);
    for (int u = 0; u < m; ++u) {
        ws.first_moment[u] = zero3<T>();
        if (active & (1u << u)) {
            if (!ws.faces.face(u, ws.normal[u], ws.delta[u], &ws.area[u], &ws.first_moment[u])) return false;
            closure += ws.normal[u] * ws.area[u];
            total += abs_(ws.area[u]);
        }
    }
    const T closure_tol = T(256.0) * Limits<T>::epsilon() * total;
    return norm2(closure) <= closure_tol * closure_tol;
}

// overlap::hull_faces: face areas and first moments from the dual hull (seed Alg. III–VI).
template <class T> PD_HD int hull_faces(OverlapWorkspace<T>& ws, int m, int na) {
    // Outside tolerance of the dual hull (Rust HULL_EPS): retry coarser when round-off breaks
    // the first attempt.
    const double hull_eps[2] = {32.0, 4096.0};
    int result = STATUS_HULL_DEGENERATE;
    for (int e = 0; e < 2; ++e) {
        result = ws.hull.build(ws.dual, m, T(hull_eps[e]));
        if (result == STATUS_OK) break;
    }
    if (result != STATUS_OK) return result;
    set_shares(ws, m, na, ws.hull.tolerance());

    const int n_slots = ws.hull.n_tri;
    // Intersection vertices, one per dual triangle (seed Alg. VI, by Cramer's rule).
    for (int s = 0; s < n_slots; ++s) {
        const HullTriangle<T>& t = ws.hull.tri[s];
        if (!t.alive) continue;
        int i = t.v[0], j = t.v[1], k = t.v[2];
        V3<T> ni = ws.normal[i], nj = ws.normal[j], nk = ws.normal[k];
        V3<T> cjk = cross(nj, nk), cki = cross(nk, ni), cij = cross(ni, nj);
        T det = dot(ni, cjk);
        if (abs_(det) > T(64.0) * Limits<T>::epsilon()) {
            ws.vertex[s] = (cjk * ws.delta[i] + cki * ws.delta[j] + cij * ws.delta[k]) / det;
        } else if (t.offset > T(0)) {
            // Nearly dependent normals: unpolarise the dual plane instead (seed Eq. 6–8).
            ws.vertex[s] = t.normal / t.offset;
        } else {
            ws.vertex[s] = zero3<T>();
        }
    }

    // Faces of the intersection: fan every face from the foot of x0 on its plane.
    for (int i = 0; i < m; ++i) ws.first_moment[i] = zero3<T>();
    const T third = T(1.0 / 3.0);
    for (int s = 0; s < n_slots; ++s) {
        const HullTriangle<T>& t = ws.hull.tri[s];
        if (!t.alive) continue;
        for (int k = 0; k < 3; ++k) {
            int u = t.v[k];
            V3<T> p = ws.vertex[s];
            V3<T> q = ws.vertex[t.adj[k]];
            V3<T> foot = ws.normal[u] * ws.delta[u];
            T twice = dot(ws.normal[u], cross(p - foot, q - foot));
            T tri_area = twice * T(0.5);
            ws.area[u] += tri_area;
            ws.first_moment[u] += (foot + p + q) * (tri_area * third);
        }
    }
    return STATUS_OK;
}

// overlap::overlap_about: the overlap of {n·x <= h for the na planes of a} and likewise b, about
// the interior point x0 (normally the Chebyshev centre); seed Alg. II–VI, the faces by vertex
// enumeration for at most PD_ENUM_MAX_PLANES planes (when `enumerate`), else by the dual hull.
// Returns a status code (STATUS_TOO_MANY_PLANES or a hull error) with *out zeroed, or
// STATUS_OK; a zero overlap (with depth = the inscribed radius) when the interiors are disjoint
// or only touch. With kHull false the hull is not compiled in: where it would be needed the
// result is STATUS_DEFERRED (the pair kernel's lean pass).
template <class T, bool kHull>
PD_HD int overlap_about_t(OverlapWorkspace<T>& ws, const Plane<T>* a, int na, const Plane<T>* b, int nb, V3<T> x0,
                          bool enumerate, Overlap<T>* out) {
    *out = overlap_zero<T>();
    const int m = na + nb;
    if (m > PD_MAX_HULL_POINTS) return STATUS_TOO_MANY_PLANES;
    PD_CLK_START
    ws.x0 = x0;
    ws.m = m;
    ws.by_hull = false;
    T scale = T(0);
    T radius = Limits<T>::max();
    for (int i = 0; i < m; ++i) {
        const Plane<T>& p = i < na ? a[i] : b[i - na];
        ws.normal[i] = p.normal;
        ws.delta[i] = p.offset - dot(p.normal, x0);
        scale = max_(scale, ws.delta[i]);
        radius = min_(radius, ws.delta[i]);
    }
    Overlap<T> none = overlap_zero<T>();
    none.depth = radius;
    for (int i = 0; i < m; ++i) ws.area[i] = T(0);
    if (radius <= T(16.0) * Limits<T>::epsilon() * scale) {
        *out = none;
        return STATUS_OK;
    }
    // Polar transform (seed Alg. II): every δ is at least the inscribed radius.
    for (int i = 0; i < m; ++i) {
        ws.delta[i] = max_(ws.delta[i], radius);
        ws.dual[i] = ws.normal[i] / ws.delta[i];
    }
    const bool enumerated = enumerate && m <= PD_ENUM_MAX_PLANES && enumerate_faces(ws, m, na, scale);
    if (!enumerated) {
        if constexpr (!kHull) {
            return STATUS_DEFERRED;
        } else {
            for (int i = 0; i < m; ++i) ws.area[i] = T(0);
            int st = hull_faces(ws, m, na);
            if (st != STATUS_OK) return st;
            ws.by_hull = true;
        }
    }
    PD_CLK(13)
    // The hull's traversal orientation is a global convention; make the areas positive (the
    // enumeration's are by construction).
    const T third = T(1.0 / 3.0);
    T volume = T(0);
    for (int i = 0; i < m; ++i) volume += ws.delta[i] * ws.area[i];
    if (volume < T(0)) {
        for (int i = 0; i < m; ++i) {
            ws.area[i] = -ws.area[i];
            ws.first_moment[i] = -ws.first_moment[i];
        }
        volume = -volume;
    }
    volume *= third;
    if (volume <= T(0)) {
        *out = none;
        return STATUS_OK;
    }
    V3<T> centroid = zero3<T>();
    V3<T> dv_dxb = zero3<T>();
    V3<T> moment_b = zero3<T>();
    for (int i = 0; i < m; ++i) {
        centroid += ws.first_moment[i] * (ws.delta[i] * T(0.25));
        T share = ws.share_b[i];
        if (share > T(0)) {
            dv_dxb += ws.normal[i] * (ws.area[i] * share);
            moment_b += cross(ws.first_moment[i], ws.normal[i]) * share;
        }
    }
    centroid = centroid / volume;
    // Moment about the overlap centroid rather than x0.
    moment_b -= cross(centroid, dv_dxb);
    T thickness = T(0);
    T area = norm(dv_dxb);
    if (area > T(0)) {
        V3<T> n = dv_dxb / area;
        T lo = Limits<T>::max(), hi = -Limits<T>::max();
        if (enumerated) {
            for (int v = 0; v < ws.faces.n_vertices; ++v) {
                T h = dot(n, ws.faces.vertex[v]);
                lo = min_(lo, h);
                hi = max_(hi, h);
            }
        } else if constexpr (kHull) {
            for (int s = 0; s < ws.hull.n_tri; ++s) {
                if (!ws.hull.tri[s].alive) continue;
                T h = dot(n, ws.vertex[s]);
                lo = min_(lo, h);
                hi = max_(hi, h);
            }
        }
        T extent = max_(hi - lo, T(0));
        // The distance to separation along -n the vertices give (OverlapWorkspace::separation_along):
        // over the vertices, the largest of the least (delta_i - n_i.v)/(n_i.toward) over A's planes
        // that bound the overlap and face along it; kept where at least half of V/|S|.
        V3<T> toward = -n;
        bool carried = false;
        for (int i = 0; i < na; ++i) {
            if (ws.area[i] > T(0) && ws.area[i] * dot(ws.normal[i], toward) >= T(0.9) * area) carried = true;
        }
        T deepest = T(0);
        auto visit = [&](V3<T> v) {
            T depth = Limits<T>::max();
            for (int i = 0; i < na; ++i) {
                if (ws.area[i] > T(0)) {
                    T w = dot(ws.normal[i], toward);
                    if (w > T(0)) depth = min_(depth, (ws.delta[i] - dot(ws.normal[i], v)) / w);
                }
            }
            deepest = max_(deepest, depth);
        };
        // Only where one face of A carries the overlap's side towards A (geometry::overlap FACE_SHARE).
        if (carried && enumerated) {
            for (int v = 0; v < ws.faces.n_vertices; ++v) visit(ws.faces.vertex[v]);
        } else if (carried) {
            if constexpr (kHull) {
                for (int s = 0; s < ws.hull.n_tri; ++s) {
                    if (ws.hull.tri[s].alive) visit(ws.vertex[s]);
                }
            }
        }
        thickness = deepest * area >= T(0.5) * volume ? min_(deepest, extent) : extent;
    }
    PD_CLK(14)
    out->volume = volume;
    out->centroid = centroid + x0;
    out->dv_dxb = dv_dxb;
    out->moment_b = moment_b;
    out->depth = radius;
    out->thickness = thickness;
    return STATUS_OK;
}

template <class T>
PD_HD int overlap_about(OverlapWorkspace<T>& ws, const Plane<T>* a, int na, const Plane<T>* b, int nb, V3<T> x0,
                        Overlap<T>* out) {
    return overlap_about_t<T, true>(ws, a, na, b, nb, x0, true, out);
}

// overlap::overlap_volume_by_hull's evaluation: overlap_about with the faces from the hull only.
template <class T>
PD_HD int overlap_about_by_hull(OverlapWorkspace<T>& ws, const Plane<T>* a, int na, const Plane<T>* b, int nb,
                                V3<T> x0, Overlap<T>* out) {
    return overlap_about_t<T, true>(ws, a, na, b, nb, x0, false, out);
}

// overlap::overlap_volume: overlap_about about the Chebyshev centre of the two plane sets, the
// LP started at `start`.
template <class T>
PD_HD int overlap_volume(OverlapWorkspace<T>& ws, const Plane<T>* a, int na, const Plane<T>* b, int nb, V3<T> start,
                         Overlap<T>* out) {
    if (na + nb > PD_MAX_HULL_POINTS) {
        *out = overlap_zero<T>();
        return STATUS_TOO_MANY_PLANES;
    }
    ChebyshevCentre<T> centre = chebyshev_centre<T, T>(a, na, b, nb, start);
    return overlap_about(ws, a, na, b, nb, centre.point, out);
}
