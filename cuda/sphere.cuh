// The sphere fast path (docs/design.md §1): the lens of two spheres and a sphere's cap behind a wall
// facet in closed form, as the same Overlap record the polyhedral stages produce. Twins of
// `sphere_lens`, `disk_polygon` and `sphere_facet` in src/geometry/sphere.rs, operation for
// operation (the module docs there derive the formulas); always in double, since the lens is a
// few dozen flops and needs no pair workspace.
#pragma once

#include "common.cuh"
#include "overlap.cuh"

namespace pd {

PD_HD double sphere_pi() { return 3.14159265358979323846; }

// sphere::cap_volume: πh²(3r − h)/3.
PD_HD double cap_volume(double r, double h) { return sphere_pi() * h * h * (3.0 * r - h) / 3.0; }

// sphere::cap_centroid_distance: 3(2r − h)²/(4(3r − h)).
PD_HD double cap_centroid_distance(double r, double h) {
    double t = 2.0 * r - h;
    return 3.0 * t * t / (4.0 * (3.0 * r - h));
}

// sphere::sphere_lens: sphere A (radius ra) at the origin, sphere B (radius rb) at d.
PD_HD Overlap<double> sphere_lens(double ra, double rb, V3<double> d) {
    Overlap<double> o = overlap_zero<double>();
    double dist = norm(d);
    double delta = ra + rb - dist;
    if (delta <= 0.0) {
        o.depth = 0.5 * delta;
        o.thickness = delta;
        return o;
    }
    if (dist <= abs_(ra - rb)) {
        double r = ra <= rb ? ra : rb;
        o.volume = 4.0 / 3.0 * sphere_pi() * r * r * r;
        o.centroid = ra <= rb ? zero3<double>() : d;
        o.depth = r;
        o.thickness = 2.0 * r;
        return o;
    }
    V3<double> u = d / dist;
    double da = (dist * dist + ra * ra - rb * rb) / (2.0 * dist);
    double ha = ra - da, hb = rb - (dist - da);
    double va = cap_volume(ra, ha), vb = cap_volume(rb, hb);
    double volume = va + vb;
    double za = cap_centroid_distance(ra, ha);
    double zb = dist - cap_centroid_distance(rb, hb);
    double z = (va * za + vb * zb) / volume;
    double a2 = max_(ra * ra - da * da, 0.0);
    o.volume = volume;
    o.centroid = u * z;
    o.dv_dxb = u * (-sphere_pi() * a2);
    o.depth = 0.5 * delta;
    o.thickness = delta;
    return o;
}

PD_HD double cross2(double ax, double ay, double bx, double by) { return ax * by - ay * bx; }

PD_HD double clamp01(double x) {
    if (x < 0.0) x = 0.0;
    if (x > 1.0) x = 1.0;
    return x;
}

// sphere::atan2: atan2 from + − × ÷ only, so that host, GPU and Rust round identically.
PD_HD double portable_atan2(double y, double x) {
    const double PI_2 = 1.57079632679489661923;
    const double PI_6 = 0.52359877559829887308;
    const double SQRT3 = 1.7320508075688772;
    const double TAN_PI_12 = 0.2679491924311227;
    if (y == 0.0 && x >= 0.0) return 0.0;
    if (x == 0.0 && y == 0.0) return 1.0 / x < 0.0 ? copysign(sphere_pi(), y) : 0.0;  // x = -0: ±π
    double ax = abs_(x), ay = abs_(y);
    bool swap = ay > ax;
    double t = swap ? ax / ay : ay / ax;
    double base = 0.0;
    if (t > TAN_PI_12) {
        t = (SQRT3 * t - 1.0) / (SQRT3 + t);
        base = PI_6;
    }
    double t2 = t * t;
    double series = 0.0;
    for (int k = 14; k >= 0; --k) {
        double term = 1.0 / (double)(2 * k + 1);
        series = (k % 2 == 0 ? term : -term) + t2 * series;
    }
    double angle = base + t * series;
    if (swap) angle = PI_2 - angle;
    if (x < 0.0) angle = sphere_pi() - angle;
    return y < 0.0 ? -angle : angle;
}

// sphere::sector: the signed sector of radius a from direction s to direction e; adds its area
// and first moment (half-angle sine and cosine without sin/cos, as in Rust).
PD_HD void disk_sector(double a, double sx, double sy, double ex, double ey, double* area, double* mx, double* my) {
    double sn_raw = cross2(sx, sy, ex, ey), cs_raw = sx * ex + sy * ey;
    double theta = portable_atan2(sn_raw, cs_raw);
    if (theta == 0.0) return;
    double ns = sqrt_(sx * sx + sy * sy);
    double ux = sx / ns, uy = sy / ns;
    double px = -uy, py = ux;
    double rho = sqrt_(sn_raw * sn_raw + cs_raw * cs_raw);
    double c = cs_raw / rho, sn = sn_raw / rho;
    double sh, ch;
    if (c > -0.5) {
        ch = sqrt_(0.5 * (1.0 + c));
        sh = sn / (2.0 * ch);
    } else {
        sh = copysign(sqrt_(0.5 * (1.0 - c)), sn);
        ch = sn / (2.0 * sh);
    }
    double bx = ux * ch + px * sh, by = uy * ch + py * sh;
    double k = 2.0 / 3.0 * a * a * a * sh;
    *area += 0.5 * a * a * theta;
    *mx += bx * k;
    *my += by * k;
}

// sphere::disk_polygon: area and first moment of the disk of radius a at the origin inside the
// counter-clockwise polygon (px, py)[0..n).
PD_HD void disk_polygon(double a, const double* px, const double* py, int n, double* area, double* mx, double* my) {
    *area = 0.0;
    *mx = 0.0;
    *my = 0.0;
    // A disk clear of every edge: the whole disk, exactly.
    bool inside = true;
    for (int k = 0; k < n && inside; ++k) {
        int j = (k + 1) % n;
        double e0 = px[j] - px[k], e1 = py[j] - py[k];
        inside = cross2(e0, e1, -px[k], -py[k]) >= a * sqrt_(e0 * e0 + e1 * e1);
    }
    if (inside) {
        *area = sphere_pi() * a * a;
        return;
    }
    for (int k = 0; k < n; ++k) {
        int j = (k + 1) % n;
        double p0 = px[k], p1 = py[k], q0 = px[j], q1 = py[j];
        double e0 = q0 - p0, e1 = q1 - p1;
        double ee = e0 * e0 + e1 * e1;
        double pe = p0 * e0 + p1 * e1;
        double disc = pe * pe - ee * ((p0 * p0 + p1 * p1) - a * a);
        double t1 = 1.0, t2 = 1.0;
        if (disc > 0.0 && ee > 0.0) {
            double root = sqrt_(disc);
            t1 = clamp01((-pe - root) / ee);
            t2 = clamp01((-pe + root) / ee);
        }
        double s1x = p0 + e0 * t1, s1y = p1 + e1 * t1;
        double s2x = p0 + e0 * t2, s2y = p1 + e1 * t2;
        disk_sector(a, p0, p1, s1x, s1y, area, mx, my);
        double tri = 0.5 * cross2(s1x, s1y, s2x, s2y);
        *area += tri;
        *mx += (s1x + s2x) * (tri / 3.0);
        *my += (s1y + s2y) * (tri / 3.0);
        disk_sector(a, s2x, s2y, q0, q1, area, mx, my);
    }
}

// sphere::sphere_facet: the share of the sphere (centre c, radius r) behind facet t[0..3]
// (normal n towards the front) that the facet owns.
PD_HD Overlap<double> sphere_facet(V3<double> c, double r, const V3<double> t[3], V3<double> n) {
    Overlap<double> o = overlap_zero<double>();
    double s = dot(n, c - t[0]);
    double h = r - s;
    if (h <= 0.0) return o;
    h = min_(h, 2.0 * r);
    double a = sqrt_(max_(r * r - s * s, 0.0));
    V3<double> e1 = t[1] - t[0];
    e1 = e1 / norm(e1);
    V3<double> e2 = cross(n, e1);
    V3<double> foot = c - n * s;
    double px[3], py[3];
    for (int k = 0; k < 3; ++k) {
        V3<double> w = t[k] - foot;
        px[k] = dot(w, e1);
        py[k] = dot(w, e2);
    }
    double area = 0.0, mx = 0.0, my = 0.0;
    if (a > 0.0) disk_polygon(a, px, py, 3, &area, &mx, &my);
    if (area <= 0.0) return o;
    double share = area / (sphere_pi() * a * a);
    V3<double> lateral = (e1 * mx + e2 * my) / area;
    o.volume = share * cap_volume(r, h);
    o.centroid = foot + lateral + n * (s - cap_centroid_distance(r, h));
    o.dv_dxb = n * area;
    o.depth = 0.5 * h;
    o.thickness = h;
    return o;
}

} // namespace pd
