// Incremental Quickhull in fixed-capacity buffers (seed paper Alg. III–V): the convex hull of the
// dual points of a pair, as a triangle mesh with adjacency (adj[k] is the triangle across edge
// v[k] → v[k+1]). Mirrors src/geometry/quickhull.rs (DualHull) operation for operation.
#pragma once

#include "common.cuh"
#include "polytope.cuh"

// Largest number of points: the face planes of two templates plus a few wall planes
// (Rust MAX_HULL_POINTS = 2 MAX_TEMPLATE_FACES + 8).
#ifndef PD_MAX_HULL_POINTS
#define PD_MAX_HULL_POINTS (2 * PD_MAX_TEMPLATE_FACES + 8)
#endif
// Largest number of triangle slots (Rust MAX_HULL_FACES = 2 MAX_HULL_POINTS).
#ifndef PD_MAX_HULL_FACES
#define PD_MAX_HULL_FACES (2 * PD_MAX_HULL_POINTS)
#endif

namespace pd {

// Point and triangle indices: a byte when the capacities allow (a smaller per-thread
// workspace), else 16 bits as in Rust.
#if PD_MAX_HULL_FACES < 255 && PD_MAX_HULL_POINTS < 255
typedef unsigned char HullIndex;
#else
typedef unsigned short HullIndex;
#endif
// Rust quickhull::NONE (u16::MAX): no triangle.
#define PD_HULL_NONE ((HullIndex)~(HullIndex)0)

// One hull triangle (Rust `HullTriangle<T>`).
template <class T> struct HullTriangle {
    // Outward unit normal.
    V3<T> normal;
    // Plane offset: normal · y = offset on the triangle.
    T offset;
    T far_dist;
    // Vertex (point) indices, counter-clockwise seen from outside.
    HullIndex v[3];
    // Neighbouring triangle across edge v[k] → v[(k+1) % 3].
    HullIndex adj[3];
    // The vertex of smallest magnitude, from which distances are measured.
    HullIndex anchor;
    short far;
    bool alive;
    // Visited by the current expansion's search. Rust keeps an epoch number instead; both are
    // equivalent because every visited triangle is deleted (and unmarked) by the same expansion.
    bool mark;
};

// Workspace and result of the incremental Quickhull (Rust `DualHull<T>`). build() initialises
// everything it reads (live triangles are unmarked between expansions); zero-initialising the
// workspace once, as Rust's `Default` does, keeps memory checkers quiet.
template <class T> struct DualHull {
    // The input points, not copied (Rust copies them; they are not modified during a build).
    const V3<T>* pts;
    int n_pts;
    HullTriangle<T> tri[PD_MAX_HULL_FACES];
    int n_tri;
    HullIndex free_[PD_MAX_HULL_FACES];
    int n_free;
    // Per point: the triangle it is outside of (>= 0), -1 inside, -2 a hull vertex.
    int conflict[PD_MAX_HULL_POINTS];
    HullIndex stack[PD_MAX_HULL_FACES];
    HullIndex horizon[PD_MAX_HULL_FACES][3];
    HullIndex created[PD_MAX_HULL_FACES];
    HullIndex orphans[PD_MAX_HULL_POINTS];
    T eps;

    // DualHull::is_vertex: whether point i is a vertex of the hull.
    PD_HD bool is_vertex(int i) const { return conflict[i] == -2; }
    // DualHull::tolerance: the outside tolerance used by the last build.
    PD_HD T tolerance() const { return eps; }

    // DualHull::distance: signed distance of point p from triangle s's plane, measured from the
    // triangle's smallest vertex.
    PD_HD T distance(int s, int p) const {
        const HullTriangle<T>& t = tri[s];
        return dot(t.normal, pts[p] - pts[t.anchor]);
    }

    // DualHull::alloc.
    PD_HD int alloc(int* slot) {
        if (n_free > 0) {
            n_free -= 1;
            *slot = free_[n_free];
            return STATUS_OK;
        }
        if (n_tri >= PD_MAX_HULL_FACES) return STATUS_HULL_CAPACITY;
        n_tri += 1;
        *slot = n_tri - 1;
        return STATUS_OK;
    }

    // DualHull::make: creates triangle (a, b, c) with its plane; adjacency is set by the caller.
    PD_HD int make(HullIndex a, HullIndex b, HullIndex c, int* slot) {
        int s;
        int st = alloc(&s);
        if (st != STATUS_OK) return st;
        // Cross the two edges leaving the smallest vertex.
        HullIndex ids[3] = {a, b, c};
        T mags[3] = {norm2(pts[a]), norm2(pts[b]), norm2(pts[c])};
        int k = (mags[0] <= mags[1] && mags[0] <= mags[2]) ? 0 : (mags[1] <= mags[2] ? 1 : 2);
        HullIndex anchor = ids[k];
        V3<T> p0 = pts[anchor];
        V3<T> p1 = pts[ids[(k + 1) % 3]];
        V3<T> p2 = pts[ids[(k + 2) % 3]];
        V3<T> n = cross(p1 - p0, p2 - p0);
        T len = norm(n);
        // A zero-area triangle gets a zero normal: no point is ever outside it.
        V3<T> normal = len > T(0) ? n / len : zero3<T>();
        T offset = dot(normal, p0);
        HullTriangle<T>& t = tri[s];
        t.v[0] = a;
        t.v[1] = b;
        t.v[2] = c;
        t.adj[0] = t.adj[1] = t.adj[2] = PD_HULL_NONE;
        t.normal = normal;
        t.offset = offset;
        t.anchor = anchor;
        t.far = -1;
        t.far_dist = T(0);
        t.alive = true;
        t.mark = false;
        *slot = s;
        return STATUS_OK;
    }

    // DualHull::farthest_outside over the candidate slots cand[0..n_cand] (or, with cand null,
    // every slot 0..n_cand): the triangle p is farthest outside of beyond the tolerance (seed
    // Alg. IV). Returns the slot or -1, with the distance in *dist.
    PD_HD int farthest_outside(int p, const HullIndex* cand, int n_cand, T* dist) const {
        int best = -1;
        T bd = T(0);
        for (int c = 0; c < n_cand; ++c) {
            int s = cand ? int(cand[c]) : c;
            if (!tri[s].alive) continue;
            T d = distance(s, p);
            if (d > eps && (best < 0 || d > bd)) {
                best = s;
                bd = d;
            }
        }
        *dist = bd;
        return best;
    }

    // DualHull::set_conflict: records that p is outside triangle `s` (or inside the hull when
    // s < 0), keeping each triangle's farthest outside point.
    PD_HD void set_conflict(int p, int s, T d) {
        if (s >= 0) {
            conflict[p] = s;
            HullTriangle<T>& t = tri[s];
            if (t.far < 0 || d > t.far_dist) {
                t.far = (short)p;
                t.far_dist = d;
            }
        } else {
            conflict[p] = -1;
        }
    }

    // DualHull::init_simplex.
    PD_HD int init_simplex() {
        const int n = n_pts;
        // Two points far apart: the widest pair among the axis extremes.
        int ext[6] = {0, 0, 0, 0, 0, 0};
        for (int i = 0; i < n; ++i) {
            V3<T> p = pts[i];
            for (int k = 0; k < 3; ++k) {
                if (p[k] < pts[ext[2 * k]][k]) ext[2 * k] = i;
                if (p[k] > pts[ext[2 * k + 1]][k]) ext[2 * k + 1] = i;
            }
        }
        int i0 = 0, i1 = 0;
        T best = T(0);
        for (int a = 0; a < 6; ++a) {
            for (int b = a + 1; b < 6; ++b) {
                T d = norm2(pts[ext[a]] - pts[ext[b]]);
                if (d > best) {
                    i0 = ext[a];
                    i1 = ext[b];
                    best = d;
                }
            }
        }
        if (sqrt_(best) <= eps) return STATUS_HULL_DEGENERATE;
        V3<T> p0 = pts[i0], p1 = pts[i1];
        V3<T> dir = (p1 - p0) / norm(p1 - p0);
        int i2 = 0;
        best = T(0);
        for (int i = 0; i < n; ++i) {
            V3<T> v = pts[i] - p0;
            T d = norm2(v - dir * dot(v, dir));
            if (d > best) {
                i2 = i;
                best = d;
            }
        }
        if (sqrt_(best) <= eps) return STATUS_HULL_DEGENERATE;
        V3<T> cn = cross(p1 - p0, pts[i2] - p0);
        V3<T> normal = cn / norm(cn);
        int i3 = 0;
        best = T(0);
        for (int i = 0; i < n; ++i) {
            T d = dot(normal, pts[i] - p0);
            if (abs_(d) > abs_(best)) {
                i3 = i;
                best = d;
            }
        }
        if (abs_(best) <= eps) return STATUS_HULL_DEGENERATE;
        // Orient base (0,1,2) so that point 3 lies behind it.
        if (best > T(0)) {
            int tmp = i1;
            i1 = i2;
            i2 = tmp;
        }
        HullIndex ids[4] = {(HullIndex)i0, (HullIndex)i1, (HullIndex)i2, (HullIndex)i3};
        const int layout[4][3] = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {2, 3, 0}};
        HullIndex slots[4];
        for (int f = 0; f < 4; ++f) {
            int s;
            int st = make(ids[layout[f][0]], ids[layout[f][1]], ids[layout[f][2]], &s);
            if (st != STATUS_OK) return st;
            slots[f] = (HullIndex)s;
        }
        // Adjacency: the twin of edge a→b is the edge b→a of another triangle; for the four
        // distinct points of this layout that is always the same triangle.
        const int twin[4][3] = {{1, 2, 3}, {3, 2, 0}, {1, 3, 0}, {2, 1, 0}};
        for (int f = 0; f < 4; ++f) {
            for (int k = 0; k < 3; ++k) tri[slots[f]].adj[k] = slots[twin[f][k]];
        }
        for (int q = 0; q < 4; ++q) conflict[ids[q]] = -2;
        for (int p = 0; p < n; ++p) {
            if (conflict[p] == -1) {
                T d;
                int s = farthest_outside(p, slots, 4, &d);
                set_conflict(p, s, d);
            }
        }
        return STATUS_OK;
    }

    // DualHull::expand: adds the farthest outside point of triangle `base` (seed Alg. V).
    PD_HD int expand(int base) {
        const int apex = tri[base].far;
        conflict[apex] = -2;

        // Visible triangles by depth-first search from `base`; horizon edges lie between a
        // visible and a non-visible triangle.
        int n_stack = 1;
        stack[0] = (HullIndex)base;
        tri[base].mark = true;
        int n_horizon = 0;
        while (n_stack > 0) {
            n_stack -= 1;
            int s = stack[n_stack];
            for (int k = 0; k < 3; ++k) {
                int g = tri[s].adj[k];
                if (tri[g].mark) continue;
                if (distance(g, apex) > eps) {
                    tri[g].mark = true;
                    stack[n_stack] = (HullIndex)g;
                    n_stack += 1;
                } else {
                    horizon[n_horizon][0] = tri[s].v[k];
                    horizon[n_horizon][1] = tri[s].v[(k + 1) % 3];
                    horizon[n_horizon][2] = (HullIndex)g;
                    n_horizon += 1;
                }
            }
        }
        if (n_horizon < 3) return STATUS_HULL_TOPOLOGY;

        // Points that were outside a visible triangle must be re-assigned.
        int n_orphans = 0;
        for (int p = 0; p < n_pts; ++p) {
            int c = conflict[p];
            if (c >= 0 && tri[c].mark) orphans[n_orphans++] = (HullIndex)p;
        }
        // Delete the visible triangles.
        for (int s = 0; s < n_tri; ++s) {
            if (tri[s].alive && tri[s].mark) {
                tri[s].alive = false;
                tri[s].mark = false;
                free_[n_free++] = (HullIndex)s;
            }
        }
        // New triangles (a, b, apex) on each horizon edge a→b, keeping the orientation.
        for (int h = 0; h < n_horizon; ++h) {
            HullIndex ha = horizon[h][0], hb = horizon[h][1], g = horizon[h][2];
            int s;
            int st = make(ha, hb, (HullIndex)apex, &s);
            if (st != STATUS_OK) return st;
            created[h] = (HullIndex)s;
            tri[s].adj[0] = g;
            HullTriangle<T>& gt = tri[g];
            for (int j = 0; j < 3; ++j) {
                if (gt.v[j] == hb && gt.v[(j + 1) % 3] == ha) gt.adj[j] = (HullIndex)s;
            }
        }
        // Link the new triangles around the apex; a horizon that is not a simple cycle is a
        // round-off failure.
        for (int h = 0; h < n_horizon; ++h) {
            HullIndex ha = horizon[h][0], hb = horizon[h][1];
            HullIndex next = PD_HULL_NONE, prev = PD_HULL_NONE;
            for (int j = 0; j < n_horizon; ++j) {
                if (horizon[j][0] == hb) {
                    if (next != PD_HULL_NONE) return STATUS_HULL_TOPOLOGY;
                    next = created[j];
                }
                if (horizon[j][1] == ha) {
                    if (prev != PD_HULL_NONE) return STATUS_HULL_TOPOLOGY;
                    prev = created[j];
                }
            }
            if (next == PD_HULL_NONE || prev == PD_HULL_NONE) return STATUS_HULL_TOPOLOGY;
            int s = created[h];
            tri[s].adj[1] = next;
            tri[s].adj[2] = prev;
        }
        // Re-assign orphans to the new triangles; a point outside none of them may still be
        // outside an older triangle, so those fall back to a scan of every live triangle.
        for (int o = 0; o < n_orphans; ++o) {
            int p = orphans[o];
            T d;
            int s = farthest_outside(p, created, n_horizon, &d);
            if (s < 0) s = farthest_outside(p, (const HullIndex*)0, n_tri, &d);
            set_conflict(p, s, d);
        }
        return STATUS_OK;
    }

    // DualHull::build: the hull of points[0..n] (seed Alg. III: initial simplex, then repeated
    // expansion from the globally farthest outside point).
    PD_HD int build(const V3<T>* points, int n, T eps_factor) {
        if (n > PD_MAX_HULL_POINTS) return STATUS_HULL_TOO_MANY_POINTS;
        if (n < 4) return STATUS_HULL_DEGENERATE;
        n_pts = n;
        pts = points;
        n_tri = 0;
        n_free = 0;
        T max_coord = T(0);
        for (int i = 0; i < n; ++i) {
            max_coord = max_(max_(max_(max_coord, abs_(points[i].x)), abs_(points[i].y)), abs_(points[i].z));
        }
        eps = eps_factor * Limits<T>::epsilon() * max_coord;
        for (int i = 0; i < n_pts; ++i) conflict[i] = -1;
        int st = init_simplex();
        if (st != STATUS_OK) return st;
        // Each iteration turns one outside point into a hull vertex: at most n iterations.
        for (int it = 0; it < n_pts; ++it) {
            int best = -1;
            for (int s = 0; s < n_tri; ++s) {
                const HullTriangle<T>& t = tri[s];
                if (t.alive && t.far >= 0 && (best < 0 || t.far_dist > tri[best].far_dist)) best = s;
            }
            if (best < 0) return STATUS_OK;
            st = expand(best);
            if (st != STATUS_OK) return st;
        }
        return STATUS_OK;
    }
};

} // namespace pd
