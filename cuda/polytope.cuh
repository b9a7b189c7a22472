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
};

// A convex template in its body frame, as plain arrays: kernels point it at constant or global
// memory, the host harness at ordinary arrays. Mirrors the parts of `shape::ConvexTemplate` the
// contact geometry reads.
struct TemplateView {
    const double* vertices; // xyz interleaved, body frame
    int n_vertices;
    const double* normals; // xyz interleaved, outward unit face normals, body frame
    const double* offsets; // face plane offsets: normal · x <= offset inside
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
    // Template face of each plane slot (planes can be culled, see retain_planes_cutting).
    unsigned short face[PD_MAX_TEMPLATE_FACES];
    int n_planes;
    // The body's centroid (reference point of its pose) in the pair frame.
    V3<T> centre;
};

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

// PosedPolytope::place: places template `t`, scaled by `scale`, at (pos, rot) (body frame →
// world), in a frame whose origin is the world point `origin`: x = R (s v) + (pos − origin),
// the subtraction done in double before rounding to T (DESIGN.md §3, relative coordinates).
// Input beyond the capacities is ignored, as in Rust.
template <class T>
PD_HD void place(PosedPolytope<T>& p, const TemplateView& t, double scale, V3<double> pos, Quat<double> rot_q,
                 V3<double> origin) {
    Mat3<double> rot = to_rotation_matrix(rot_q);
    V3<double> shift = pos - origin;
    p.n_vertices = min_(t.n_vertices, PD_MAX_TEMPLATE_VERTICES);
    for (int i = 0; i < p.n_vertices; ++i) {
        p.vertices[i] = cast3<T>(mul(rot, template_vertex(t, i) * scale) + shift);
    }
    p.n_planes = min_(t.n_faces, PD_MAX_TEMPLATE_FACES);
    for (int i = 0; i < p.n_planes; ++i) p.face[i] = (unsigned short)i;
    reposition_planes(p, t, scale, pos, rot_q, origin);
}

// PosedPolytope::radius: largest distance from the centre to a vertex.
template <class T> PD_HD T polytope_radius(const PosedPolytope<T>& p) {
    T r = T(0);
    for (int i = 0; i < p.n_vertices; ++i) r = max_(r, norm(p.vertices[i] - p.centre));
    return r;
}

// PosedPolytope::retain_planes_cutting: drops the planes that cannot bound the intersection with
// a body whose vertices are `other` (a half-space containing all of the other body contains the
// whole intersection); planes within round-off (64 ε radius) of touching it are kept.
template <class T> PD_HD void retain_planes_cutting(PosedPolytope<T>& p, const V3<T>* other, int n_other) {
    T tol = T(64.0) * Limits<T>::epsilon() * polytope_radius(p);
    int kept = 0;
    for (int i = 0; i < p.n_planes; ++i) {
        Plane<T> pl = p.planes[i];
        bool cuts = false;
        for (int j = 0; j < n_other; ++j) {
            if (plane_distance(pl, other[j]) > -tol) {
                cuts = true;
                break;
            }
        }
        if (cuts) {
            p.planes[kept] = pl;
            p.face[kept] = p.face[i];
            ++kept;
        }
    }
    p.n_planes = kept;
}

// PosedPolytope::set: a polytope given directly by its vertices and planes (already in the pair
// frame); input beyond the capacities is ignored.
template <class T>
PD_HD void set_polytope(PosedPolytope<T>& p, const V3<T>* vertices, int n_vertices, const Plane<T>* planes, int n_planes,
                        V3<T> centre) {
    p.n_vertices = min_(n_vertices, PD_MAX_TEMPLATE_VERTICES);
    for (int i = 0; i < p.n_vertices; ++i) p.vertices[i] = vertices[i];
    p.n_planes = min_(n_planes, PD_MAX_TEMPLATE_FACES);
    for (int i = 0; i < p.n_planes; ++i) {
        p.planes[i] = planes[i];
        p.face[i] = (unsigned short)i;
    }
    p.centre = centre;
}

} // namespace pd
