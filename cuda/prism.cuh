// A convex polyhedron against one triangular wall facet: the penetrating volume, i.e. the
// intersection of the polyhedron with the half-infinite prism under the triangle (seed paper
// Sec. 2.4), evaluated exactly by the dual-space overlap. Mirrors `facet_prism` and
// `prism_overlap` of src/geometry/clip.rs (the Sutherland–Hodgman section clipping of Alg. VII
// is not needed on the GPU).
#pragma once

#include "common.cuh"
#include "overlap.cuh"
#include "interior.cuh"
#include "polytope.cuh"

namespace pd {

// clip::facet_prism (with FacetFrame::of_triangle): the half-infinite prism under triangle
// tri[0..3] (counter-clockwise seen from the side the particles are on): prism[0] is the facet
// plane (outward normal towards the particles), prism[1 + k] the side plane through edge
// k → k+1, perpendicular to the facet, facing out. Returns STATUS_DEGENERATE_FACET (prism
// zeroed) for a degenerate triangle, where Rust returns None.
template <class T> PD_HD int facet_prism(const V3<T> tri[3], Plane<T> prism[4]) {
    for (int k = 0; k < 4; ++k) {
        prism[k].normal = zero3<T>();
        prism[k].offset = T(0);
    }
    V3<T> n = cross(tri[1] - tri[0], tri[2] - tri[0]);
    V3<T> e = tri[1] - tri[0];
    if (norm(n) <= T(0) || norm(e) <= T(0)) return STATUS_DEGENERATE_FACET;
    V3<T> normal = n / norm(n);
    V3<T> origin = tri[0];
    prism[0].normal = normal;
    prism[0].offset = dot(normal, origin);
    for (int k = 0; k < 3; ++k) {
        V3<T> p = tri[k], q = tri[(k + 1) % 3];
        V3<T> c = cross(q - p, normal);
        V3<T> sn = c / norm(c);
        prism[k + 1].normal = sn;
        prism[k + 1].offset = dot(sn, p);
    }
    return STATUS_OK;
}

// clip::facet_thickness: a facet overlap's thickness is its penetration behind the facet, along
// the facet's normal, not along its own −S/|S| (which leans on the prism's side planes where a
// contact straddles facets).
template <class T>
PD_HD void facet_thickness(const OverlapWorkspace<T>& ws, const Plane<T>& facet, int status, Overlap<T>* out) {
    if (status == STATUS_OK && out->volume > T(0)) out->thickness = ws.extent_along(facet.normal);
}

// clip::prism_overlap: overlap of `body` with a facet's prism [facet plane, side planes…]
// (planes of B): the penetrating volume, its centroid, S (so dV/dx_body = −S) and the moment of
// the prism's part of the surface, in the frame of `body` and `prism`. A prism plane with every
// vertex of the body on its outer side separates the two (zero overlap); otherwise the
// interior-point search starts on the facet plane under the body's centre (overlap_volume).
// Returns a status code; on error *out is zeroed.
template <class T>
PD_HD int prism_overlap(OverlapWorkspace<T>& ws, const PosedPolytope<T>& body, const Plane<T> prism[4], Overlap<T>* out) {
    *out = overlap_zero<T>();
    const Plane<T>& facet = prism[0];
    for (int k = 0; k < 4; ++k) {
        bool all_outside = true;
        for (int i = 0; i < body.n_vertices; ++i) {
            if (!(plane_distance(prism[k], body.vertices[i]) >= T(0))) {
                all_outside = false;
                break;
            }
        }
        if (all_outside) return STATUS_OK;
    }
    V3<T> start = body.centre - facet.normal * plane_distance(facet, body.centre);
    int status = overlap_volume(ws, body.planes, body.n_planes, prism, 4, start, out);
    facet_thickness(ws, facet, status, out);
    return status;
}

// clip::prism_overlap_culled: prism_overlap on the planes that can bound it. `body` was placed
// from template `t` by `pl` in the prism's frame (its planes in template order; on return they
// may be reordered, which a body placed per item does not mind). A body plane whose face has no
// corner behind the facet plane is set aside; a side plane that holds the ball around the part
// of the body's bounding ball (radius `radius`) behind the facet plane is dropped (exact); the
// Chebyshev centre of the planes kept, strictly inside every plane set aside, proves the
// overlap has an interior and is then the point it is evaluated about. Otherwise every body
// plane is used, as in prism_overlap.
template <class T>
PD_HD int prism_overlap_culled(OverlapWorkspace<T>& ws, PosedPolytope<T>& body, const TemplateView& t,
                               const Placement& pl, T radius, const Plane<T> prism[4], Overlap<T>* out) {
    *out = overlap_zero<T>();
    const Plane<T>& facet = prism[0];
    for (int k = 0; k < 4; ++k) {
        bool all_outside = true;
        for (int i = 0; i < body.n_vertices; ++i) {
            if (!(plane_distance(prism[k], body.vertices[i]) >= T(0))) {
                all_outside = false;
                break;
            }
        }
        if (all_outside) return STATUS_OK;
    }
    const T r = radius;
    const T tol = T(64.0) * Limits<T>::epsilon() * r;
    set_aside_beyond(body, t, pl, prism, 1, (const Plane<T>*)0, 0, tol);
    const T d = plane_distance(facet, body.centre);
    V3<T> cap_centre = body.centre;
    T cap_radius = r;
    if (d >= T(0)) {
        cap_centre = body.centre - facet.normal * d;
        cap_radius = sqrt_(max_(r * r - d * d, T(0)));
    }
    Plane<T> kept[4];
    kept[0] = prism[0];
    int n_kept = 1;
    for (int k = 1; k < 4; ++k) {
        if (plane_distance(prism[k], cap_centre) + cap_radius > -tol) {
            kept[n_kept] = prism[k];
            n_kept += 1;
        }
    }
    const V3<T> start = body.centre - facet.normal * d;
    ChebyshevCentre<T> centre = chebyshev_centre<T, T>(body.planes, body.n_planes, kept, n_kept, start);
    bool proven = centre.radius > tol;
    for (int j = 0; j < body.n_aside && proven; ++j) {
        proven = plane_distance(body.aside[j], centre.point) < -tol;
    }
    int status;
    if (proven) {
        status = overlap_about(ws, body.planes, body.n_planes, kept, n_kept, centre.point, out);
    } else {
        restore_aside(body);
        status = overlap_volume(ws, body.planes, body.n_planes, kept, n_kept, start, out);
    }
    facet_thickness(ws, facet, status, out);
    return status;
}

} // namespace pd
