// Device-side views of the particle state and of the per-step parameters, shared by every
// kernel file. The structs shared with Rust (GridParams among them) are in layout.cuh.
#pragma once
#include "common.cuh"
#include "layout.cuh"

namespace pd {

// Loads and stores of the particle arrays' layout: vectors as three consecutive doubles, unit
// quaternions as (x, y, z, w), nalgebra's storage order.
PD_HD V3<double> load3(const double* a, size_t i) { return v3(a[3 * i], a[3 * i + 1], a[3 * i + 2]); }
PD_HD void store3(double* a, size_t i, V3<double> v) {
    a[3 * i] = v.x;
    a[3 * i + 1] = v.y;
    a[3 * i + 2] = v.z;
}
PD_HD Quat<double> load_quat(const double* q, size_t i) {
    Quat<double> r;
    r.x = q[4 * i];
    r.y = q[4 * i + 1];
    r.z = q[4 * i + 2];
    r.w = q[4 * i + 3];
    return r;
}
PD_HD void store_quat(double* q, size_t i, Quat<double> r) {
    q[4 * i] = r.x;
    q[4 * i + 1] = r.y;
    q[4 * i + 2] = r.z;
    q[4 * i + 3] = r.w;
}


// Minimum-image displacement from a to b (Bounds::displacement); C's `round`, like Rust's,
// rounds half away from zero.
PD_HD V3<double> displacement(const GridParams& g, V3<double> a, V3<double> b) {
    V3<double> d = b - a;
    double c[3] = {d.x, d.y, d.z};
    for (int k = 0; k < 3; ++k) {
        if (g.periodic[k]) {
            double l = g.max[k] - g.min[k];
            c[k] -= l * round(c[k] / l);
        }
    }
    return v3(c[0], c[1], c[2]);
}

// Cell coordinate of x along axis k (Grid::coord): particles outside a closed box are binned
// in the edge cells.
PD_HD int cell_coord(const GridParams& g, double x, int k) {
    double c = floor((x - g.min[k]) / g.size[k]);
    if (c - c != 0.0) { // NaN or infinite
        return 0;
    }
    int v = c < 0.0 ? 0 : (int)min_(c, (double)(g.dims[k] - 1));
    return v;
}

PD_HD int cell_of(const GridParams& g, V3<double> x) {
    int a = cell_coord(g, x.x, 0), b = cell_coord(g, x.y, 1), c = cell_coord(g, x.z, 2);
    return (c * g.dims[1] + b) * g.dims[0] + a;
}

// The distinct cells of the 3×3×3 stencil along one axis (Grid::neighbours): writes up to three
// cell coordinates and returns how many.
PD_HD int stencil_axis(const GridParams& g, int k, int v, int out[3]) {
    int d = g.dims[k];
    if (d == 1) {
        out[0] = 0;
        return 1;
    }
    if (d == 2 && !g.periodic[k]) {
        out[0] = 0;
        out[1] = 1;
        return 2;
    }
    int n = 0;
    if (v > 0) {
        out[n++] = v - 1;
    } else if (g.periodic[k]) {
        out[n++] = d - 1;
    }
    out[n++] = v;
    if (v + 1 < d) {
        out[n++] = v + 1;
    } else if (g.periodic[k]) {
        out[n++] = 0;
    }
    return n;
}

} // namespace pd
