// The contact geometry on its own, on the GPU: GJK + overlap for given pairs of posed templates
// and the facet-prism overlap for given body–triangle cases, each in double and in float. The
// device twin of cuda/host/geometry_harness.cpp (same cases, same results, same order), used by
// the parity tests to hold the kernels to the Rust reference on the device itself, and by
// `GeometryProbe` (src/backend/cuda/probe.rs).
//
// Templates are read from global memory (not the step's constant tables), so one build serves
// any set of templates up to PD_MAX_TEMPLATE_VERTICES/FACES. Every value crosses as a double:
// indices and status codes are small integers, exact in a double.
#include "common.cuh"
#include "pair.cuh"
#include "prism.cuh"
#include "layout.cuh"

using namespace pd;

// Template table: template t's vertices at vertices[3 (t mv + i)], its face normals at
// normals[3 (t mf + i)] with offsets[t mf + i]; counts[2t], counts[2t + 1] the vertex and face
// counts; radius[t] the circumscribed radius; face polygons as in TemplateView (the struct
// `ProbeTemplates` is in layout.cuh).

PD_DEVICE TemplateView probe_template(const ProbeTemplates& t, int i) {
    TemplateView v;
    v.vertices = t.vertices + (size_t)i * t.max_vertices * 3;
    v.n_vertices = t.counts[2 * i];
    v.normals = t.normals + (size_t)i * t.max_faces * 3;
    v.offsets = t.offsets + (size_t)i * t.max_faces;
    v.n_faces = t.counts[2 * i + 1];
    v.face_start = t.face_start + (size_t)i * (t.max_faces + 1);
    v.face_points = t.face_points + (size_t)i * t.max_face_indices * 3;
    v.face_mask = nullptr; // the face test reads the corners (the same decisions)
    v.circumscribed_radius = t.radius[i];
    return v;
}

// A body from 9 doubles: template, scale, position (3), orientation (x, y, z, w).
PD_DEVICE BodyRef probe_body(const ProbeTemplates& t, const double* in) {
    BodyRef b;
    b.tpl = probe_template(t, (int)in[0]);
    b.scale = in[1];
    b.pos = v3(in[2], in[3], in[4]);
    b.rot.x = in[5];
    b.rot.y = in[6];
    b.rot.z = in[7];
    b.rot.w = in[8];
    return b;
}

// volume, centroid (3), S (3), M (3), depth, thickness: 12 doubles.
PD_DEVICE double* put_overlap(double* out, const Overlap<double>& o) {
    *out++ = o.volume;
    *out++ = o.centroid.x;
    *out++ = o.centroid.y;
    *out++ = o.centroid.z;
    *out++ = o.dv_dxb.x;
    *out++ = o.dv_dxb.y;
    *out++ = o.dv_dxb.z;
    *out++ = o.moment_b.x;
    *out++ = o.moment_b.y;
    *out++ = o.moment_b.z;
    *out++ = o.depth;
    *out++ = o.thickness;
    return out;
}

// status, intersects, separating axis (3), overlap (12): 17 doubles.
template <class T> PD_DEVICE double* put_pair(double* out, const BodyRef& a, const BodyRef& b) {
    PairWorkspace<T> ws;
    PairGeometry g;
    int st = overlap_pair(ws, a, b, &g);
    *out++ = (double)st;
    *out++ = (double)g.intersects;
    *out++ = g.separating_axis.x;
    *out++ = g.separating_axis.y;
    *out++ = g.separating_axis.z;
    return put_overlap(out, g.overlap);
}

// Pair case k: in[22 k ...] = body A (9), body B (9), axis (3), margin; out[35 k ...] = the
// double result (17), the float result (17), axis_separates (0/1).
extern "C" __global__ void probe_pairs(int n, ProbeTemplates t, const double* in, double* out) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= n) {
        return;
    }
    const double* c = in + (size_t)k * 22;
    BodyRef a = probe_body(t, c), b = probe_body(t, c + 9);
    double* o = out + (size_t)k * 35;
    o = put_pair<double>(o, a, b);
    o = put_pair<float>(o, a, b);
    *o = axis_separates(a, b, v3(c[18], c[19], c[20]), c[21]) ? 1.0 : 0.0;
}

// prism status, overlap status, overlap (12): 14 doubles.
template <class T>
PD_DEVICE double* put_facet(double* out, const BodyRef& r, V3<double> origin, const V3<double> tri[3]) {
    OverlapWorkspace<T> ws;
    PosedPolytope<T> body;
    place(body, r.tpl, r.scale, r.pos, r.rot, origin);
    V3<T> tt[3];
    for (int j = 0; j < 3; ++j) tt[j] = cast3<T>(tri[j]);
    Plane<T> prism[4];
    int pst = facet_prism(tt, prism);
    Overlap<T> o = overlap_zero<T>();
    int st = 0;
    // The wall stage's evaluation (WallMesh::contact, clip::prism_overlap_culled).
    if (pst == STATUS_OK) {
        st = prism_overlap_culled(ws, body, r.tpl, placement(r.scale, r.pos, r.rot, origin),
                                  T(r.tpl.circumscribed_radius * r.scale), prism, &o);
    }
    *out++ = (double)pst;
    *out++ = (double)st;
    return put_overlap(out, to_world(o, zero3<double>()));
}

// Facet case k: in[21 k ...] = body (9), pair-frame origin (3), triangle (9, relative to the
// origin); out[28 k ...] = the double result (14), the float result (14).
extern "C" __global__ void probe_facets(int n, ProbeTemplates t, const double* in, double* out) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= n) {
        return;
    }
    const double* c = in + (size_t)k * 21;
    BodyRef r = probe_body(t, c);
    V3<double> origin = v3(c[9], c[10], c[11]);
    V3<double> tri[3];
    for (int j = 0; j < 3; ++j) tri[j] = v3(c[12 + 3 * j], c[13 + 3 * j], c[14 + 3 * j]);
    double* o = out + (size_t)k * 28;
    o = put_facet<double>(o, r, origin, tri);
    put_facet<float>(o, r, origin, tri);
}
