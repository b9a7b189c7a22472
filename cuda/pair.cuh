// The contact geometry of one particle pair (GJK, plane culling, Chebyshev centre, re-centred
// frame, overlap), and the defined answer for a body wholly inside the other. Mirrors
// src/geometry/pair.rs and src/geometry/contained.rs operation for operation.
#pragma once

#include "overlap.cuh"

// One body of a pair: its template, scale and pose (position and body → world rotation), all in
// double.
struct BodyRef {
    TemplateView tpl;
    double scale;
    V3<double> pos;
    Quat<double> rot;
};

// Rust contained.rs `least_offset`: the radius of the ball about the centre the template holds.
PD_HD double least_offset(const TemplateView& t) {
    double least = bits_double(0x7ff0000000000000ULL); // +infinity
    for (int f = 0; f < t.n_faces; ++f) least = t.offsets[f] < least ? t.offsets[f] : least;
    return least;
}

// Rust geometry/contained.rs `inside`: whether the inner body lies wholly inside the outer one
// (every vertex within 64 ε (r_i + r_o) of its planes; tested only when the inner centre lies in
// the outer's circumscribed ball and the inner body could fit), and then its overlap: the inner
// body's volume from its faces, its centroid, S = 0, no surface moment. In f64 whatever the
// pair's precision, the same operations in the same order as the CPU's. Out of line
// (PD_HD_COLD): almost every pair leaves at the first distance, and the vertex and face loops
// inlined into pair_planes cost the settled mineral grains 30 % of their speed.
PD_HD_COLD bool contained_inside(const BodyRef& in, const BodyRef& outer, Overlap<double>* out) {
    V3<double> d = in.pos - outer.pos;
    double ri = in.tpl.circumscribed_radius * in.scale, ro = outer.tpl.circumscribed_radius * outer.scale;
    double tol = 64.0 * 2.220446049250313e-16 * (ri + ro);
    // The ball first (one distance), then Rust `could_be_inside`: |d| + ρ_i ≤ R_o (1 + tol/ρ_o)
    // + tol, a necessary condition.
    if (dot(d, d) > ro * ro) return false;
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
    PD_CLK_START
    // A body wholly inside the other (geometry/contained.rs): answered before any plane is
    // placed, in f64; the lean pass leaves it to the full one.
    bool contained = contained_overlap(A, B, &out->overlap);
    PD_CLK(9)
    if (contained) {
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
