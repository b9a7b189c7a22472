// The faces of a small intersection of half-spaces by vertex enumeration: the exact alternative
// to the dual hull for the few planes a culled pair keeps (vertices from every independent
// triple of planes, kept when inside the others; each face the polygon of its vertices ordered
// by pseudo-angle and fanned from the foot of the interior point). Its workspace is a few hundred
// bytes where the hull's triangle mesh is kilobytes, which is what the pair kernel's time goes to
// (local-memory latency). Mirrors src/geometry/vertex_enumeration.rs operation for operation.
#pragma once

#include "common.cuh"

// Rust vertex_enumeration::{enum_planes_for, ENUM_MAX_VERTICES, ENUM_MAX_FACE_VERTICES}: the
// planes up to which pairs take the enumeration (the scene's 8 or 16, or POLYDEM_ENUM_PLANES,
// from Rust), and the vertices it keeps. At 8 planes every triple fits (C(8, 3) = 56, C(7, 2) = 21 on
// a face) and the workspace keeps its size; past 8 it holds Rust's 96 and 32 and declines, as
// Rust does, when a pair finds more.
#ifndef PD_ENUM_MAX_PLANES
#define PD_ENUM_MAX_PLANES 8
#endif
#if PD_ENUM_MAX_PLANES <= 8
#define PD_ENUM_MAX_VERTICES 56
#define PD_ENUM_MAX_FACE_VERTICES 21
typedef unsigned char EnumPlaneBits;
#else
#define PD_ENUM_MAX_VERTICES 96
#define PD_ENUM_MAX_FACE_VERTICES 32
typedef unsigned short EnumPlaneBits;
#endif

namespace pd {

// vertex_enumeration::pseudo_angle: monotone stand-in for the angle of (s, t) in [0, 4).
template <class T> PD_HD T pseudo_angle(T s, T t) {
    T r = abs_(s) + abs_(t);
    if (r > T(0)) {
        T q = s / r;
        return t >= T(0) ? T(1) - q : T(3.0) + q;
    }
    return T(0);
}

// Rust `FaceEnumeration<T>`.
template <class T> struct FaceEnumeration {
    V3<T> vertex[PD_ENUM_MAX_VERTICES];
    // Bit u set: the vertex was computed from plane u.
    EnumPlaneBits on[PD_ENUM_MAX_VERTICES];
    int n_vertices;
    unsigned char order[PD_ENUM_MAX_FACE_VERTICES];
    T key[PD_ENUM_MAX_FACE_VERTICES];

    // FaceEnumeration::enumerate: the vertices of {x : normal[u]·x <= delta[u]} over the planes
    // u < m whose bit is set in `active`, within `tol` of every other plane; false (declined)
    // when there are more than PD_ENUM_MAX_VERTICES.
    PD_HD bool enumerate(const V3<T>* normal, const T* delta, int m, unsigned int active, T tol) {
        m = min_(m, PD_ENUM_MAX_PLANES);
        const T singular = T(64.0) * Limits<T>::epsilon();
        n_vertices = 0;
        for (int i = 0; i < m; ++i) {
            if (!(active & (1u << i))) continue;
            for (int j = i + 1; j < m; ++j) {
                if (!(active & (1u << j))) continue;
                V3<T> cij = cross(normal[i], normal[j]);
                for (int k = j + 1; k < m; ++k) {
                    if (!(active & (1u << k))) continue;
                    V3<T> ni = normal[i], nj = normal[j], nk = normal[k];
                    V3<T> cjk = cross(nj, nk);
                    T det = dot(ni, cjk);
                    if (abs_(det) <= singular) continue;
                    V3<T> cki = cross(nk, ni);
                    // det · x with det made positive: the tests are scaled by det, so only the
                    // vertices kept pay for the division.
                    V3<T> scaled = cjk * delta[i] + cki * delta[j] + cij * delta[k];
                    if (det < T(0)) {
                        scaled = -scaled;
                        det = -det;
                    }
                    const T margin = tol * det;
                    bool inside = true;
                    for (int l = 0; l < m && inside; ++l) {
                        if (l != i && l != j && l != k && (active & (1u << l))) {
                            inside = dot(normal[l], scaled) - delta[l] * det <= margin;
                        }
                    }
                    if (inside) {
                        if (n_vertices == PD_ENUM_MAX_VERTICES) return false;
                        vertex[n_vertices] = scaled / det;
                        on[n_vertices] = (EnumPlaneBits)((1u << i) | (1u << j) | (1u << k));
                        n_vertices += 1;
                    }
                }
            }
        }
        return true;
    }

    // FaceEnumeration::face: area and first moment of the face on plane u (unit normal n,
    // distance delta from the interior point); zero when fewer than three vertices lie on it;
    // false (declined) when more than PD_ENUM_MAX_FACE_VERTICES do.
    PD_HD bool face(int u, V3<T> n, T delta, T* area_out, V3<T>* first_moment_out) {
        const unsigned int bit = 1u << u;
        int count = 0;
        V3<T> mean = zero3<T>();
        for (int v = 0; v < n_vertices; ++v) {
            if (on[v] & bit) {
                if (count == PD_ENUM_MAX_FACE_VERTICES) return false;
                order[count] = (unsigned char)v;
                mean += vertex[v];
                count += 1;
            }
        }
        *area_out = T(0);
        *first_moment_out = zero3<T>();
        if (count < 3) return true;
        mean = mean / T(count);
        T ax = abs_(n.x), ay = abs_(n.y), az = abs_(n.z);
        V3<T> axis = (ax <= ay && ax <= az) ? v3<T>(T(1), T(0), T(0))
                                            : (ay <= az ? v3<T>(T(0), T(1), T(0)) : v3<T>(T(0), T(0), T(1)));
        V3<T> e1 = cross(axis, n);
        V3<T> e2 = cross(n, e1);
        for (int c = 0; c < count; ++c) {
            unsigned char v = order[c];
            V3<T> d = vertex[v] - mean;
            T k = pseudo_angle(dot(d, e1), dot(d, e2));
            int p = c;
            while (p > 0 && key[p - 1] > k) {
                key[p] = key[p - 1];
                order[p] = order[p - 1];
                p -= 1;
            }
            key[p] = k;
            order[p] = v;
        }
        V3<T> foot = n * delta;
        const T third = T(1.0 / 3.0);
        T area = T(0);
        V3<T> first_moment = zero3<T>();
        for (int c = 0; c < count; ++c) {
            V3<T> p = vertex[order[c]];
            V3<T> q = vertex[order[c + 1 < count ? c + 1 : 0]];
            T twice = dot(n, cross(p - foot, q - foot));
            T tri_area = twice * T(0.5);
            area += tri_area;
            first_moment += (foot + p + q) * (tri_area * third);
        }
        *area_out = area;
        *first_moment_out = first_moment;
        return true;
    }
};

} // namespace pd
