// A convex template placed in a pair frame: its vertices (for support functions) and its face
// planes (for the half-space intersection), in fixed-capacity storage.
// Mirrors src/geometry/polytope.rs (Plane, PosedPolytope) and the template capacities of
// src/shape/mod.rs.
#pragma once

#include "common.cuh"

// Capacities. The defaults are the Rust constants (MAX_TEMPLATE_FACES, MAX_TEMPLATE_VERTICES);
// the GPU build lowers them to the scene's largest template (e.g. 20 vertices and 12 faces for
// dodecahedra) so that the per-thread workspace stays small. The derived hull capacities live
// in quickhull.cuh.
#ifndef PD_MAX_TEMPLATE_FACES
#define PD_MAX_TEMPLATE_FACES 128
#endif
#ifndef PD_MAX_TEMPLATE_VERTICES
#define PD_MAX_TEMPLATE_VERTICES 256
#endif
// Corners of all face polygons of one template: twice the edge count, at most 6V − 12 for a
// polyhedron of V vertices (Euler).
#define PD_MAX_TEMPLATE_FACE_INDICES (6 * PD_MAX_TEMPLATE_VERTICES - 12)

namespace pd {

// Status codes of the geometry functions (0 = success). Where Rust returns `Err`, the CUDA twin
// returns the code and leaves its outputs zeroed.
enum GeometryStatus {
    STATUS_OK = 0,
    // OverlapError::TooManyPlanes: more planes than PD_MAX_HULL_POINTS.
    STATUS_TOO_MANY_PLANES = 1,
    // HullError::TooManyPoints (cannot happen behind the plane-count check).
    STATUS_HULL_TOO_MANY_POINTS = 2,
    // HullError::Degenerate: the dual points span less than three dimensions.
    STATUS_HULL_DEGENERATE = 3,
    // HullError::CapacityExceeded: triangle slots exhausted.
    STATUS_HULL_CAPACITY = 4,
    // HullError::Topology: inconsistent horizon (round-off on near-coplanar points).
    STATUS_HULL_TOPOLOGY = 5,
    // facet_prism: degenerate triangle (Rust returns None).
    STATUS_DEGENERATE_FACET = 6,
    // The lean evaluation (overlap_pair_t<T, false>, no GJK and no hull compiled in): the centre
    // did not prove an intersection, or the faces need the dual hull; the pair needs the full
    // evaluation (never returned by overlap_pair).
    STATUS_DEFERRED = 7,
    // Mixed precision (pair_planes_t<float, ·, true>): the Chebyshev centre did not prove an
    // intersection, or proved one thinner than f32 resolves (PD_MIXED_WIDE_ULPS); the pair is
    // evaluated in f64 (Rust's overlap_pair_mixed; never returned by overlap_pair).
    STATUS_WIDE = 8,
};

// Mixed precision evaluates in f64 a pair whose Chebyshev radius (about half its overlap's
// thickness) is below this many f32 epsilons of ra + rb (geometry::pair::MIXED_WIDE_ULPS).
#define PD_MIXED_WIDE_ULPS 512.0

// Mixed precision evaluates in f64 a pair whose f32 dual hull has a vertex outside one of the
// planes by more than this fraction of the Chebyshev radius (geometry::overlap::
// MIXED_VERTEX_SLACK, OverlapWorkspace::hull_vertex_excess).
#define PD_MIXED_VERTEX_SLACK 1e-2

// A convex template in its body frame, as plain arrays: kernels point it at constant or global
// memory, the host harness at ordinary arrays. Mirrors the parts of `shape::ConvexTemplate` the
// contact geometry reads.
struct TemplateView {
    const double* vertices; // xyz interleaved, body frame
    int n_vertices;
    const double* normals; // xyz interleaved, outward unit face normals, body frame
    const double* offsets; // face plane offsets: normal · x <= offset inside
    // Face polygons: face i's vertices are points face_start[i] .. face_start[i + 1] − 1 of
    // face_points (xyz interleaved, body frame: copies of the template vertices, so that a
    // thread reads a face's corners without an index, in global memory for divergent reads).
    const unsigned short* face_start;
    const double* face_points;
    // Face i's corners as a bit set of vertex indices (bit v: vertex v), for templates of at
    // most 64 vertices; null where not provided (the face test then reads the corners).
    const unsigned long long* face_mask;
    int n_faces;
    double circumscribed_radius;
};

PD_HD V3<double> template_vertex(const TemplateView& t, int i) {
    return v3(t.vertices[3 * i], t.vertices[3 * i + 1], t.vertices[3 * i + 2]);
}
PD_HD V3<double> template_normal(const TemplateView& t, int i) {
    return v3(t.normals[3 * i], t.normals[3 * i + 1], t.normals[3 * i + 2]);
}

// A half-space `normal · x <= offset` with a unit outward normal (Rust `Plane<T>`).
template <class T> struct Plane {
    V3<T> normal;
    T offset;
};

// Plane::distance: signed distance of x from the plane, positive outside.
template <class T> PD_HD T plane_distance(const Plane<T>& p, V3<T> x) { return dot(p.normal, x) - p.offset; }

// Widens a T vector to double (Rust `polytope::widen`).
template <class T> PD_HD V3<double> widen(V3<T> v) { return v3<double>(double(v.x), double(v.y), double(v.z)); }

// Vertices and face planes of one convex body in a pair frame (Rust `PosedPolytope<T>`).
template <class T> struct PosedPolytope {
    V3<T> vertices[PD_MAX_TEMPLATE_VERTICES];
    int n_vertices;
    Plane<T> planes[PD_MAX_TEMPLATE_FACES];
    // Template face of each plane slot (planes can be culled, see retain_planes_reaching).
    unsigned short face[PD_MAX_TEMPLATE_FACES];
    int n_planes;
    // Planes set aside by set_aside_faces_apart, with their template faces.
    Plane<T> aside[PD_MAX_TEMPLATE_FACES];
    unsigned short aside_face[PD_MAX_TEMPLATE_FACES];
    int n_aside;
    // The body's centroid (reference point of its pose) in the pair frame.
    V3<T> centre;
};

// A body's placement in a pair frame: x = R (s v) + (pos − origin), in double.
struct Placement {
    Mat3<double> rot;
    V3<double> shift;
    double scale;
};

PD_HD Placement placement(double scale, V3<double> pos, Quat<double> rot_q, V3<double> origin) {
    Placement p;
    p.rot = to_rotation_matrix(rot_q);
    p.shift = pos - origin;
    p.scale = scale;
    return p;
}

// A template point placed and rounded to T, exactly as PosedPolytope::place places a vertex.
template <class T> PD_HD V3<T> placed_point(const Placement& pl, V3<double> v) {
    return cast3<T>(mul(pl.rot, v * pl.scale) + pl.shift);
}

// PosedPolytope::reposition_planes: recomputes the planes in use (after culling, only those
// kept) for the frame origin `origin`; the vertices are left as they were. The rotation and the
// shift are done in double, then rounded to T.
template <class T>
PD_HD void reposition_planes(PosedPolytope<T>& p, const TemplateView& t, double scale, V3<double> pos, Quat<double> rot_q,
                             V3<double> origin) {
    Mat3<double> rot = to_rotation_matrix(rot_q);
    V3<double> shift = pos - origin;
    p.centre = cast3<T>(shift);
    for (int s = 0; s < p.n_planes; ++s) {
        int k = p.face[s];
        V3<double> n = mul(rot, template_normal(t, k));
        p.planes[s].normal = cast3<T>(n);
        p.planes[s].offset = T(t.offsets[k] * scale + dot(n, shift));
    }
}

// The face planes half of PosedPolytope::place (every plane in use, none set aside); the
// vertices are placed separately (place_vertices) when a support function needs them.
template <class T>
PD_HD void place_planes(PosedPolytope<T>& p, const TemplateView& t, double scale, V3<double> pos, Quat<double> rot_q,
                        V3<double> origin) {
    p.n_planes = min_(t.n_faces, PD_MAX_TEMPLATE_FACES);
    p.n_aside = 0;
    for (int i = 0; i < p.n_planes; ++i) p.face[i] = (unsigned short)i;
    reposition_planes(p, t, scale, pos, rot_q, origin);
}

// The vertex half of PosedPolytope::place.
template <class T>
PD_HD void place_vertices(PosedPolytope<T>& p, const TemplateView& t, double scale, V3<double> pos, Quat<double> rot_q,
                          V3<double> origin) {
    Placement pl = placement(scale, pos, rot_q, origin);
    p.n_vertices = min_(t.n_vertices, PD_MAX_TEMPLATE_VERTICES);
    for (int i = 0; i < p.n_vertices; ++i) p.vertices[i] = placed_point<T>(pl, template_vertex(t, i));
}

// PosedPolytope::place: places template `t`, scaled by `scale`, at (pos, rot) (body frame →
// world), in a frame whose origin is the world point `origin`: x = R (s v) + (pos − origin),
// the subtraction done in double before rounding to T (docs/design.md §3, relative coordinates).
// Input beyond the capacities is ignored, as in Rust.
template <class T>
PD_HD void place(PosedPolytope<T>& p, const TemplateView& t, double scale, V3<double> pos, Quat<double> rot_q,
                 V3<double> origin) {
    place_vertices(p, t, scale, pos, rot_q, origin);
    place_planes(p, t, scale, pos, rot_q, origin);
}

// PosedPolytope::retain_planes_reaching: drops the planes whose half-space contains the whole ball
// (centre, radius) around the other body (it then contains the whole intersection); planes within
// `tol` of touching the ball are kept.
template <class T> PD_HD void retain_planes_reaching(PosedPolytope<T>& p, V3<T> centre, T radius, T tol) {
    int kept = 0;
    for (int i = 0; i < p.n_planes; ++i) {
        Plane<T> pl = p.planes[i];
        if (plane_distance(pl, centre) + radius > -tol) {
            p.planes[kept] = pl;
            p.face[kept] = p.face[i];
            ++kept;
        }
    }
    p.n_planes = kept;
    p.n_aside = 0;
}

// PosedPolytope::restore_aside: puts the planes set aside by set_aside_faces_apart back in use,
// after those kept.
template <class T> PD_HD void restore_aside(PosedPolytope<T>& p) {
    for (int j = 0; j < p.n_aside; ++j) {
        p.planes[p.n_planes] = p.aside[j];
        p.face[p.n_planes] = p.aside_face[j];
        p.n_planes += 1;
    }
    p.n_aside = 0;
}

// PosedPolytope::set_aside_beyond: moves the planes whose face polygon lies beyond one of
// q[0..nq] ∪ r[0..nr] by more than `tol` to the set-aside list, keeping both lists in order. The
// faces are tested in the body's frame from the template's corners, in double, against each
// plane carried into that frame once: for a corner v, s (Rᵀ n)·v − (o − n·(pos − origin)).
template <class T>
PD_HD void set_aside_beyond(PosedPolytope<T>& p, const TemplateView& t, const Placement& pl, const Plane<T>* q, int nq,
                            const Plane<T>* r, int nr, T tol) {
    const double tol_d = double(tol);
    const Mat3<double>& m = pl.rot;
    bool apart[PD_MAX_TEMPLATE_FACES];
    for (int i = 0; i < p.n_planes; ++i) apart[i] = false;
    for (int j = 0; j < nq + nr; ++j) {
        const Plane<T> h = j < nq ? q[j] : r[j - nq];
        const V3<double> n = widen(h.normal);
        const V3<double> body_normal = v3(m.m[0][0] * n.x + m.m[1][0] * n.y + m.m[2][0] * n.z,
                                          m.m[0][1] * n.x + m.m[1][1] * n.y + m.m[2][1] * n.z,
                                          m.m[0][2] * n.x + m.m[1][2] * n.y + m.m[2][2] * n.z) *
                                       pl.scale;
        const double body_offset = double(h.offset) - dot(n, pl.shift);
        if (t.face_mask && t.n_vertices <= 64) {
            // The same corner test once per template vertex, in a loop every thread of a warp
            // runs alike (broadcast reads of the template); a face is apart when all its
            // corners are beyond.
            unsigned long long beyond = 0ull;
            for (int v = 0; v < t.n_vertices; ++v) {
                if (dot(body_normal, template_vertex(t, v)) - body_offset > tol_d) beyond |= 1ull << v;
            }
            if (beyond == 0ull) continue;
            for (int i = 0; i < p.n_planes; ++i) {
                const unsigned long long corners = t.face_mask[p.face[i]];
                apart[i] = apart[i] || (beyond & corners) == corners;
            }
            continue;
        }
        for (int i = 0; i < p.n_planes; ++i) {
            if (apart[i]) continue;
            const int f = p.face[i];
            const int first = t.face_start[f], last = t.face_start[f + 1];
            const double* corner = t.face_points + 3 * first;
            bool beyond = true;
            for (int k = 0; k < last - first && beyond; ++k) {
                V3<double> v = v3(corner[3 * k], corner[3 * k + 1], corner[3 * k + 2]);
                beyond = dot(body_normal, v) - body_offset > tol_d;
            }
            apart[i] = beyond;
        }
    }
    int kept = 0;
    p.n_aside = 0;
    for (int i = 0; i < p.n_planes; ++i) {
        if (apart[i]) {
            p.aside[p.n_aside] = p.planes[i];
            p.aside_face[p.n_aside] = p.face[i];
            p.n_aside += 1;
        } else {
            p.planes[kept] = p.planes[i];
            p.face[kept] = p.face[i];
            kept += 1;
        }
    }
    p.n_planes = kept;
}

// polytope::set_aside_faces_apart: sets aside every plane of a whose face lies strictly beyond
// one plane of b, and likewise for b (tested against a's planes as they were on entry). Such a
// plane supports no facet of A ∩ B; the caller keeps the result only once an interior point
// proves that A ∩ B has an interior (see overlap_pair). Each body: template, scale, position,
// orientation; `origin`: the pair frame's origin.
template <class T>
PD_HD void set_aside_faces_apart(PosedPolytope<T>& a, const TemplateView& ta, double sa, V3<double> xa, Quat<double> qa,
                                 PosedPolytope<T>& b, const TemplateView& tb, double sb, V3<double> xb, Quat<double> qb,
                                 V3<double> origin, T tol) {
    // One placement at a time: each is 13 doubles of registers.
    set_aside_beyond(a, ta, placement(sa, xa, qa, origin), b.planes, b.n_planes, (const Plane<T>*)0, 0, tol);
    set_aside_beyond(b, tb, placement(sb, xb, qb, origin), a.planes, a.n_planes, a.aside, a.n_aside, tol);
}

// PosedPolytope::set: a polytope given directly by its vertices and planes (already in the pair
// frame); input beyond the capacities is ignored.
template <class T>
PD_HD void set_polytope(PosedPolytope<T>& p, const V3<T>* vertices, int n_vertices, const Plane<T>* planes, int n_planes,
                        V3<T> centre) {
    p.n_vertices = min_(n_vertices, PD_MAX_TEMPLATE_VERTICES);
    for (int i = 0; i < p.n_vertices; ++i) p.vertices[i] = vertices[i];
    p.n_planes = min_(n_planes, PD_MAX_TEMPLATE_FACES);
    p.n_aside = 0;
    for (int i = 0; i < p.n_planes; ++i) {
        p.planes[i] = planes[i];
        p.face[i] = (unsigned short)i;
    }
    p.centre = centre;
}

} // namespace pd
