// The volume-based contact law, in its energy-conserving form: the GPU twin of
// src/contact/law.rs `contact_forces` (seed paper Eq. 12–22), of the damping table lookup
// `DampingTable::gamma` (src/contact/restitution.rs) and of the pipeline's
// `normal_effective_mass`. Always double precision: it runs once per contact on world-frame
// quantities, after the pair geometry (which may be float) has been widened.
#pragma once
#include "common.cuh"
#include "overlap.cuh"

namespace pd {

// Exponent range and size of a damping table (restitution.rs: P_MIN, P_MAX, TABLE_SIZE).
#define PD_DAMPING_TABLE_SIZE 25
#define PD_DAMPING_P_MIN (1.0 / 3.0)
#define PD_DAMPING_P_MAX 3.0

// Contact parameters of one pair of materials (shared with Rust: layout.rs `PairMaterial`).
struct PairMaterial {
    double restitution;
    double friction;
    double damping[PD_DAMPING_TABLE_SIZE]; // γ(e, p) at p evenly spaced over [1/3, 3]
    double log_restitution;                // ln e, computed on the host
    double log_norm;                       // sqrt((ln e)² + π²), computed on the host
};
#ifdef PD_SIZEOF_PAIR_MATERIAL
static_assert(sizeof(PairMaterial) == PD_SIZEOF_PAIR_MATERIAL, "PairMaterial differs from Rust's layout::PairMaterial");
#endif

// Parameters of one contact (law.rs `ContactParameters`).
struct ContactParameters {
    double normal_stiffness;     // c = E1/R1 + E2/R2 (Pa/m)
    double tangential_stiffness; // E1/(2(1+ν1)R1) + E2/(2(1+ν2)R2) (Pa/m)
    double restitution;
    double friction;
};

// Kinematics of a contact (law.rs `ContactKinematics`).
struct ContactKinematics {
    V3<double> x_a, x_b, v_a, v_b, w_a, w_b;
    double effective_mass;
};

// Forces of one contact (law.rs `ContactForces`).
struct ContactForces {
    V3<double> force_b;
    V3<double> torque_a;
    V3<double> torque_b;
    double elastic_energy;
};

// γ(e, p) by linear interpolation in a table of PD_DAMPING_TABLE_SIZE values over
// p ∈ [1/3, 3] (DampingTable::gamma).
PD_HD double damping_gamma(const double* table, double p) {
    double clamped = min_(max_(p, PD_DAMPING_P_MIN), PD_DAMPING_P_MAX);
    double u = ((clamped - PD_DAMPING_P_MIN) / (PD_DAMPING_P_MAX - PD_DAMPING_P_MIN)) *
               (double)(PD_DAMPING_TABLE_SIZE - 1);
    int k = min_((int)floor(u), PD_DAMPING_TABLE_SIZE - 2);
    double w = u - (double)k;
    return table[k] * (1.0 - w) + table[k + 1] * w;
}

// The mass a contact's normal impulse sees, 1/m* = Σ 1/m + (r × n)·I⁻¹(r × n), for one body
// (pipeline.rs `normal_effective_mass`): returns its term of the sum. `inertia` holds the
// principal moments, `q` the orientation (body → world).
PD_HD double inverse_mass_term(double mass, V3<double> inertia, Quat<double> q, V3<double> x,
                               V3<double> centroid, V3<double> n) {
    V3<double> arm = cross(centroid - x, n);
    V3<double> body = rotate_inverse(q, arm);
    V3<double> scaled = v3(body.x / inertia.x, body.y / inertia.y, body.z / inertia.z);
    return 1.0 / mass + dot(scaled, body);
}

PD_HD ContactForces no_contact_forces() {
    ContactForces f;
    f.force_b = zero3<double>();
    f.torque_a = zero3<double>();
    f.torque_b = zero3<double>();
    f.elastic_energy = 0.0;
    return f;
}

// Evaluates the contact law for an overlap, updating the tangential spring `spring` over `dt`
// (law.rs `contact_forces`; the comments there give the derivation of every term). The pair's
// damping table and the logarithms of its restitution come from `pm`: ln e computed once on
// the host, with the same function as the CPU backend's, rather than per contact here.
PD_HD ContactForces contact_forces(const ContactParameters& params, const PairMaterial& pm,
                                   const Overlap<double>& o, const ContactKinematics& kin,
                                   V3<double>* spring, double dt) {
    const double* damping = pm.damping;
    double area = norm(o.dv_dxb);
    double volume = o.volume;
    if (volume <= 0.0 || area <= 0.0) {
        return no_contact_forces();
    }
    V3<double> n = (-o.dv_dxb) / area;
    V3<double> c = o.centroid;
    V3<double> v_rel = (kin.v_b + cross(kin.w_b, c - kin.x_b)) - (kin.v_a + cross(kin.w_a, c - kin.x_a));
    double vn = dot(v_rel, n);

    double u_prime = params.normal_stiffness * cbrt_(volume);
    double f_elastic = u_prime * area;
    V3<double> torque_b_el = (-(o.moment_b + cross(c - kin.x_b, o.dv_dxb))) * u_prime;
    V3<double> torque_a_el = (-((-o.moment_b) + cross(c - kin.x_a, -o.dv_dxb))) * u_prime;

    double delta = max_(o.thickness, volume / area);
    double q = max_(area * delta / volume - 1.0, 0.0);
    double p = (4.0 * q + 1.0) / 3.0;
    double k_loc = p * f_elastic / delta;
    double gamma = damping_gamma(damping, p);
    double f_damp = -gamma * sqrt_(kin.effective_mass * k_loc) * vn;
    if (dt > 0.0) {
        double limit = kin.effective_mass * abs_(vn) / dt;
        f_damp = min_(max_(f_damp, -limit), limit);
    }
    double f_normal = max_(f_elastic + f_damp, 0.0);
    V3<double> force_b = n * f_normal;

    V3<double> v_t = v_rel - n * vn;
    V3<double> tangential = zero3<double>();
    if (params.friction > 0.0) {
        V3<double> old = *spring;
        V3<double> in_plane = old - n * dot(old, n);
        double len = norm(in_plane);
        V3<double> rotated = len > 0.0 ? in_plane * (norm(old) / len) : zero3<double>();
        V3<double> xi = rotated + v_t * dt;
        double k_t = params.tangential_stiffness * area;
        double e = params.restitution;
        double c_t = 0.0;
        if (e < 1.0) {
            c_t = 2.0 * abs_(pm.log_restitution) * sqrt_(k_t * kin.effective_mass) / pm.log_norm;
        }
        V3<double> f_t = (-xi) * k_t - v_t * c_t;
        double cap = params.friction * f_normal;
        double magnitude = norm(f_t);
        if (magnitude > cap) {
            f_t = f_t * (magnitude > 0.0 ? cap / magnitude : 0.0);
            xi = k_t > 0.0 ? (-f_t) / k_t : zero3<double>();
        }
        *spring = xi;
        tangential = f_t;
    } else {
        *spring = zero3<double>();
    }
    force_b += tangential;

    V3<double> f_other = force_b - n * f_elastic;
    ContactForces out;
    out.force_b = force_b;
    out.torque_b = torque_b_el + cross(c - kin.x_b, f_other);
    out.torque_a = torque_a_el + cross(c - kin.x_a, -f_other);
    double k_t = params.tangential_stiffness * area;
    // U(V) = (3/4) c V^{4/3} = (3/4) U'(V) V: no second root.
    out.elastic_energy = 0.75 * u_prime * volume + 0.5 * k_t * norm2(*spring);
    return out;
}

} // namespace pd
