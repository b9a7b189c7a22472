// Overlap of two convex polyhedra by dual-space Quickhull (seed paper Alg. II–VI, Eq. 4–9), and
// the full pair evaluation (GJK, plane culling, Chebyshev centre, re-centred frame, overlap).
// Mirrors src/geometry/overlap.rs operation for operation.
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
// close (|Σ A_u n_u| <= 256 ε Σ |A_u|), else the caller uses the hull.
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
    ws.faces.enumerate(ws.normal, ws.delta, m, active, vertex_tol);
    V3<T> closure = zero3<T>();
    T total = T(0);
    for (int u = 0; u < m; ++u) {
        ws.first_moment[u] = zero3<T>();
        if (active & (1u << u)) {
            ws.faces.face(u, ws.normal[u], ws.delta[u], &ws.area[u], &ws.first_moment[u]);
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

// One body of a pair: its template, scale and pose (position and body → world rotation), all in
// double.
struct BodyRef {
    TemplateView tpl;
    double scale;
    V3<double> pos;
    Quat<double> rot;
};

// Rust geometry/contained.rs `inside`: whether the inner body lies wholly inside the outer one
// (every vertex within 64 ε (r_i + r_o) of its planes; tested only when the inner centre lies in
// the outer's circumscribed ball), and then its overlap: the inner body's volume from its faces,
// its centroid, S = 0, no surface moment. In f64 whatever the pair's precision, the same
// operations in the same order as the CPU's.
// Rust contained.rs `least_offset`: the radius of the ball about the centre the template holds.
PD_HD double least_offset(const TemplateView& t) {
    double least = bits_double(0x7ff0000000000000ULL); // +infinity
    for (int f = 0; f < t.n_faces; ++f) least = t.offsets[f] < least ? t.offsets[f] : least;
    return least;
}

PD_HD bool contained_inside(const BodyRef& in, const BodyRef& outer, Overlap<double>* out) {
    V3<double> d = in.pos - outer.pos;
    double ri = in.tpl.circumscribed_radius * in.scale, ro = outer.tpl.circumscribed_radius * outer.scale;
    double tol = 64.0 * 2.220446049250313e-16 * (ri + ro);
    // Rust `could_be_inside`: |d| + ρ_i ≤ R_o (1 + tol/ρ_o) + tol, a necessary condition.
    double rho_i = least_offset(in.tpl) * in.scale, rho_o = least_offset(outer.tpl) * outer.scale;
    double reach = ro + ro * (tol / rho_o) + tol - rho_i;
    if (!(reach >= 0.0) || dot(d, d) > reach * reach) return false;
    Quat<double> inv;
    inv.w = outer.rot.w;
    inv.x = -outer.rot.x;
    inv.y = -outer.rot.y;
    inv.z = -outer.rot.z;
    for (int v = 0; v < in.tpl.n_vertices; ++v) {
        V3<double> w = rotate(inv, rotate(in.rot, template_vertex(in.tpl, v) * in.scale) + d);
        for (int f = 0; f < outer.tpl.n_faces; ++f) {
            if (dot(template_normal(outer.tpl, f), w) - outer.tpl.offsets[f] * outer.scale > tol) return false;
        }
    }
    // The volume, Σ offset · area / 3, each face's area by a fan from its first corner.
    double volume = 0.0, least = bits_double(0x7ff0000000000000ULL); // +infinity
    for (int f = 0; f < in.tpl.n_faces; ++f) {
        const double* c = in.tpl.face_points + 3 * (int)in.tpl.face_start[f];
        int m = (int)in.tpl.face_start[f + 1] - (int)in.tpl.face_start[f];
        V3<double> p0 = v3(c[0], c[1], c[2]), nf = template_normal(in.tpl, f);
        double twice_area = 0.0;
        for (int k = 1; k + 1 < m; ++k) {
            V3<double> p1 = v3(c[3 * k], c[3 * k + 1], c[3 * k + 2]);
            V3<double> p2 = v3(c[3 * k + 3], c[3 * k + 4], c[3 * k + 5]);
            twice_area += dot(nf, cross(p1 - p0, p2 - p0));
        }
        volume += in.tpl.offsets[f] * (0.5 * twice_area);
        least = in.tpl.offsets[f] < least ? in.tpl.offsets[f] : least;
    }
    out->volume = volume / 3.0 * (in.scale * in.scale * in.scale);
    out->centroid = in.pos;
    out->dv_dxb = zero3<double>();
    out->moment_b = zero3<double>();
    out->depth = least * in.scale;
    out->thickness = 0.0;
    return true;
}

// Rust contained_overlap: B inside A, else A inside B.
PD_HD bool contained_overlap(const BodyRef& A, const BodyRef& B, Overlap<double>* out) {
    return contained_inside(B, A, out) || contained_inside(A, B, out);
}

// Contact geometry of one particle pair in world coordinates (Rust `PairGeometry`).
struct PairGeometry {
    // Narrow-phase (GJK) verdict.
    int intersects;
    // For disjoint bodies GJK's separating axis (v·a > v·b for a ∈ A, b ∈ B); zero otherwise.
    V3<double> separating_axis;
    // The overlap, evaluated only when GJK reports an intersection.
    Overlap<double> overlap;
};

// Buffers for a full pair evaluation (Rust `PairWorkspace<T>`).
template <class T> struct PairWorkspace {
    PosedPolytope<T> a;
    PosedPolytope<T> b;
    OverlapWorkspace<T> overlap;
    // pair_planes_t left planes of an intersection the Chebyshev centre did not prove (GJK's
    // verdict, no interior thicker than the LP's tolerance): see overlap_pair_t.
    bool unproven;
};

// pair::axis_separates: whether the plane with normal `axis` separates A from B by a gap of
// more than `margin`: min_A axis·a − max_B axis·b > margin |axis|. Two support evaluations over
// the template vertices in each body's frame: the frame-coherence test run before GJK.
PD_HD bool axis_separates(const BodyRef& A, const BodyRef& B, V3<double> axis, double margin) {
    double ext[2];
    for (int side = 0; side < 2; ++side) {
        const BodyRef& body = side == 0 ? A : B;
        double sign = side == 0 ? -1.0 : 1.0;
        V3<double> d = rotate_inverse(body.rot, axis) * sign;
        double best = -Limits<double>::max();
        for (int i = 0; i < body.tpl.n_vertices; ++i) best = max_(best, dot(template_vertex(body.tpl, i), d));
        ext[side] = best;
    }
    double min_a = dot(A.pos, axis) - A.scale * ext[0];
    double max_b = dot(B.pos, axis) + B.scale * ext[1];
    return min_a - max_b > margin * norm(axis);
}

// Mixed precision's Chebyshev LP in f32 instead of f64 (1), on trial (POLYDEM_MIXED_LP=f32).
#ifndef PD_MIXED_LP_F32
#define PD_MIXED_LP_F32 0
#endif

// pair::overlap_pair: narrow phase and overlap of A against B computed in arithmetic T in a
// frame centred near the contact (docs/design.md §3): frame origin on the centre line where the
// bounding spheres would touch, planes culled to those that reach the other's ball and the faces
// that miss it set aside, Chebyshev centre started at the origin (the verdict when it proves an
// interior; GJK, seed Alg. I, otherwise), frame moved onto it in double, overlap about it (seed
// Alg. II–VI), result back in world coordinates. Returns a status code; on error *out is
// zeroed. With kFull false (the lean evaluation), a pair whose intersection the centre does not
// prove, or whose faces need the dual hull, returns STATUS_DEFERRED instead of running GJK or
// the hull (the pair kernel defers those to a second pass, so that neither its registers nor its
// local memory are sized by them); with kFull true this is Rust's overlap_pair.
//
// The work splits in two at the frame move: pair_planes_t leaves the planes about the centre,
// overlap_pair_t then computes their overlap. The GPU's lean pass stages the planes between
// two kernels, so that the faces run in warps of pairs with equal plane counts.
//
// With kWide (mixed precision, T = float), a pair whose intersection the centre does not prove,
// or proves with a Chebyshev radius below PD_MIXED_WIDE_ULPS f32 epsilons of ra + rb, returns
// STATUS_WIDE: f32 cannot place the planes of a face resting on a face to the overlap's
// thickness, and the caller evaluates such a pair in f64 (Rust's overlap_pair_mixed).
template <class T, bool kFull, bool kWide = false>
PD_HD int pair_planes_t(PairWorkspace<T>& ws, const BodyRef& A, const BodyRef& B, PairGeometry* out,
                        V3<double>* frame, bool* ready) {
    *ready = false;
    ws.unproven = false;
    out->intersects = 0;
    out->separating_axis = zero3<double>();
    out->overlap = overlap_zero<double>();
    // A body wholly inside the other (geometry/contained.rs): answered before any plane is
    // placed, in f64; the lean pass leaves it to the full one.
    if (contained_overlap(A, B, &out->overlap)) {
        if (!kFull) {
            out->overlap = overlap_zero<double>();
            return STATUS_DEFERRED;
        }
        out->intersects = 1;
        return STATUS_OK;
    }
    V3<double> xa = A.pos, xb = B.pos;
    double ra = A.tpl.circumscribed_radius * A.scale, rb = B.tpl.circumscribed_radius * B.scale;
    V3<double> origin = xa + (xb - xa) * (ra / (ra + rb));
    PD_CLK_START
    place_planes(ws.a, A.tpl, A.scale, A.pos, A.rot, origin);
    place_planes(ws.b, B.tpl, B.scale, B.pos, B.rot, origin);
    PD_CLK(1)
    // Exact culling, then the faces that miss the other body set aside; the LP runs on the rest.
    const T tol = T(64.0) * Limits<T>::epsilon() * T(ra + rb);
    retain_planes_reaching(ws.a, ws.b.centre, T(rb), tol);
    retain_planes_reaching(ws.b, ws.a.centre, T(ra), tol);
    PD_CLK(2)
    set_aside_faces_apart(ws.a, A.tpl, A.scale, A.pos, A.rot, ws.b, B.tpl, B.scale, B.pos, B.rot, origin, tol);
    PD_CLK(3)
    // Mixed precision's LP in f32 with PD_MIXED_LP_F32 (POLYDEM_MIXED_LP=f32, on trial; pair.rs
    // overlap_pair_mixed_with): the thin pairs it cannot resolve leave by their radius below.
    // Both branches are compiled in every configuration; the constant removes one.
    ChebyshevCentre<T> centre =
        (kWide && PD_MIXED_LP_F32)
            ? chebyshev_centre<T, T>(ws.a.planes, ws.a.n_planes, ws.b.planes, ws.b.n_planes, zero3<T>())
            : chebyshev_centre_wide(ws.a.planes, ws.a.n_planes, ws.b.planes, ws.b.n_planes);
    PD_CLK(4)
    // A centre strictly inside every plane of both bodies proves an intersection with an
    // interior (the narrow-phase verdict without GJK): the planes in use hold it by the LP's
    // radius, the set-aside ones are checked, and those culled against a ball hold every point of
    // that ball. Otherwise GJK decides, and an intersection the check could not prove is
    // evaluated on every plane that reaches the other body's ball.
    bool proven = centre.radius > tol && norm2(centre.point - ws.a.centre) < T(ra) * T(ra) &&
                  norm2(centre.point - ws.b.centre) < T(rb) * T(rb);
    for (int i = 0; i < ws.a.n_aside && proven; ++i) proven = plane_distance(ws.a.aside[i], centre.point) < -tol;
    for (int i = 0; i < ws.b.n_aside && proven; ++i) proven = plane_distance(ws.b.aside[i], centre.point) < -tol;
    if (kWide && !(proven && (double)centre.radius >= PD_MIXED_WIDE_ULPS * (double)Limits<float>::epsilon() * (ra + rb))) {
        return STATUS_WIDE;
    }
    if (!proven) {
        if (!kFull) return STATUS_DEFERRED;
        PD_CLK_COUNT(12)
        place_vertices(ws.a, A.tpl, A.scale, A.pos, A.rot, origin);
        place_vertices(ws.b, B.tpl, B.scale, B.pos, B.rot, origin);
        V3<T> dir = ws.b.centre - ws.a.centre;
        V3<T> axis;
        if (gjk_separating_axis(ws.a.vertices, ws.a.n_vertices, ws.b.vertices, ws.b.n_vertices, dir, &axis)) {
            out->separating_axis = widen(axis);
            return STATUS_OK;
        }
        restore_aside(ws.a);
        restore_aside(ws.b);
        centre = chebyshev_centre_wide(ws.a.planes, ws.a.n_planes, ws.b.planes, ws.b.n_planes);
        ws.unproven = true;
    }
    PD_CLK(5)
    origin = origin + widen(centre.point);
    reposition_planes(ws.a, A.tpl, A.scale, A.pos, A.rot, origin);
    reposition_planes(ws.b, B.tpl, B.scale, B.pos, B.rot, origin);
    PD_CLK(6)
    *frame = origin;
    *ready = true;
    return STATUS_OK;
}

// The second half of overlap_pair: the overlap of the planes pair_planes_t left about the
// origin of `frame`, back in world coordinates.
template <class T, bool kFull>
PD_HD int overlap_of_planes(OverlapWorkspace<T>& ws, const Plane<T>* a, int na, const Plane<T>* b, int nb,
                            V3<double> frame, PairGeometry* out) {
    PD_CLK_START
    Overlap<T> o;
    int st = overlap_about_t<T, kFull>(ws, a, na, b, nb, zero3<T>(), true, &o);
    PD_CLK(7)
    if (st != STATUS_OK) return st;
    out->intersects = 1;
    out->overlap = to_world(o, frame);
    return STATUS_OK;
}

template <class T, bool kFull>
PD_HD int overlap_pair_t(PairWorkspace<T>& ws, const BodyRef& A, const BodyRef& B, PairGeometry* out) {
    V3<double> frame;
    bool ready;
    int st = pair_planes_t<T, kFull>(ws, A, B, out, &frame, &ready);
    if (st != STATUS_OK || !ready) return st;
    st = overlap_of_planes<T, kFull>(ws.overlap, ws.a.planes, ws.a.n_planes, ws.b.planes, ws.b.n_planes, frame, out);
    // Touching below what the dual resolves (pair.rs overlap_pair): no volume.
    if (st == STATUS_HULL_DEGENERATE && ws.unproven) {
        out->intersects = 1;
        out->overlap = overlap_zero<double>();
        return STATUS_OK;
    }
    return st;
}

template <class T> PD_HD int overlap_pair(PairWorkspace<T>& ws, const BodyRef& A, const BodyRef& B, PairGeometry* out) {
    return overlap_pair_t<T, true>(ws, A, B, out);
}

// pair::overlap_pair_mixed, the pair geometry of mixed precision in full (the GPU's deferred
// pass, and its CPU twin): f32 where the Chebyshev centre proves an overlap at least
// PD_MIXED_WIDE_ULPS f32 epsilons of ra + rb thick, f64 (`wide`) otherwise, and f64 again
// where the f32 dual hull fails or comes out bent (a vertex outside a plane by more than
// PD_MIXED_VERTEX_SLACK of the Chebyshev radius): a thin slab between two faces lying on each
// other puts its two large faces' dual points at 1/δ and the others at ~1/L.
PD_HD int overlap_pair_mixed(PairWorkspace<float>& ws, PairWorkspace<double>& wide, const BodyRef& A, const BodyRef& B,
                             PairGeometry* out) {
    V3<double> frame;
    bool ready;
    int status = pair_planes_t<float, true, true>(ws, A, B, out, &frame, &ready);
    if (status == STATUS_OK && ready) {
        status = overlap_of_planes<float, true>(ws.overlap, ws.a.planes, ws.a.n_planes, ws.b.planes, ws.b.n_planes,
                                                frame, out);
        if (status == STATUS_OK && (double)ws.overlap.hull_vertex_excess() > PD_MIXED_VERTEX_SLACK * out->overlap.depth) {
            status = STATUS_WIDE;
        }
    }
    if (status == STATUS_WIDE || status == STATUS_HULL_DEGENERATE || status == STATUS_HULL_TOPOLOGY ||
        status == STATUS_HULL_CAPACITY) {
        status = overlap_pair_t<double, true>(wide, A, B, out);
    }
    return status;
}

} // namespace pd
