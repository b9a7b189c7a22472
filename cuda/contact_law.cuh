// The volume-based contact law, in its energy-conserving form: the GPU twin of
// src/contact/law.rs `contact_forces` (seed paper Eq. 12–22, docs/contact.md) and of the
// pipeline's `normal_effective_mass`. Always double precision: it runs once per contact on world-frame
// quantities, after the pair geometry (which may be float) has been widened.
#pragma once
#include "common.cuh"
#include "overlap.cuh"
#include "layout.cuh"

// Rolling friction compiled in: the kernels of a scene with some [[material_pairs]]
// rolling_friction > 0 (KernelConfig), and the host parity harness.
#ifndef PD_ROLLING_FRICTION
#define PD_ROLLING_FRICTION 1
#endif

namespace pd {

// Parameters of one contact (law.rs `ContactParameters`).
struct ContactParameters {
    double normal_stiffness;     // c = E1/R1 + E2/R2 (Pa/m)
    double tangential_stiffness; // E1/(2(1+ν1)R1) + E2/(2(1+ν2)R2) (Pa/m)
    double restitution;
    double friction;
    double rolling_friction; // μ_r (0: no rolling couple)
    double damping; // ᾱ(e)
    bool rocking;   // the contact area resists rocking (polyhedra, not spheres)
    bool trajectory; // face_window = "trajectory" (law.rs `FaceWindow`; PD_FACE_TRAJECTORY)
};

// Kinematics of a contact (law.rs `ContactKinematics`).
struct ContactKinematics {
    V3<double> x_a, x_b, v_a, v_b, w_a, w_b;
    double effective_mass;
    double inverse_mass_a, inverse_mass_b; // 1/m; zero for a wall
    Quat<double> q_a, q_b;
    V3<double> inverse_inertia_a, inverse_inertia_b; // zero for a wall
    double sphere_radius_a, sphere_radius_b;          // zero for a polyhedron or a wall
    // The dashpot caps' mass splitting (law.rs ContactKinematics::split_a, dashpot_mass): each
    // body's share (its contacts at the last evaluation, at least 1; 1 for a wall) and the
    // effective mass with each body's term multiplied by it.
    double split_a, split_b;
    double dashpot_mass;
};

// A body's share of the dashpot caps' mass splitting (law.rs `mass_share`).
PD_HD double mass_share(unsigned int contacts) { return (double)(contacts > 1u ? contacts : 1u); }

// The history of one contact (history.rs `ContactState`), PD_HISTORY_WIDTH doubles in memory.
struct ContactHistoryRecord {
    V3<double> spring;
    double approach_speed; // this loading cycle's, + loading, - unloading; 0: not evaluated yet
    double twist;
};

PD_HD ContactHistoryRecord load_history(const double* h, size_t k) {
    const double* r = h + PD_HISTORY_WIDTH * k;
    ContactHistoryRecord out;
    out.spring = v3(r[0], r[1], r[2]);
    out.approach_speed = r[3];
    out.twist = r[4];
    return out;
}

PD_HD void store_history(double* h, size_t k, const ContactHistoryRecord& s) {
    double* r = h + PD_HISTORY_WIDTH * k;
    r[0] = s.spring.x;
    r[1] = s.spring.y;
    r[2] = s.spring.z;
    r[3] = s.approach_speed;
    r[4] = s.twist;
}

PD_HD ContactHistoryRecord no_history() {
    ContactHistoryRecord out;
    out.spring = zero3<double>();
    out.approach_speed = 0.0;
    out.twist = 0.0;
    return out;
}

// Forces of one contact (law.rs `ContactForces`).
struct ContactForces {
    V3<double> force_b;
    V3<double> torque_a;
    V3<double> torque_b;
    double elastic_energy;
};

// The mass a contact's normal impulse sees, 1/m* = Σ 1/m + (r × n)·I⁻¹(r × n), for one body
// (pipeline/pairs.rs `normal_effective_mass`): returns its term of the sum. `inertia` holds the
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

// ContactKinematics::inverse_inertia_about (k_a = k_b = 1) and split_inverse_inertia_about (k the
// bodies' shares of the caps' mass splitting): u·(k_A I_A⁻¹ + k_B I_B⁻¹)u for the unit axis u.
PD_HD double weighted_inverse_inertia(const ContactKinematics& kin, V3<double> u, double k_a, double k_b) {
    V3<double> ba = rotate_inverse(kin.q_a, u);
    V3<double> bb = rotate_inverse(kin.q_b, u);
    V3<double> sa = v3(ba.x * kin.inverse_inertia_a.x, ba.y * kin.inverse_inertia_a.y, ba.z * kin.inverse_inertia_a.z);
    V3<double> sb = v3(bb.x * kin.inverse_inertia_b.x, bb.y * kin.inverse_inertia_b.y, bb.z * kin.inverse_inertia_b.z);
    return k_a * dot(sa, ba) + k_b * dot(sb, bb);
}

// ContactKinematics::tangential_inverse_mass_trace: the trace of the tangential block of
// W = Σ k (1/m − [r − x]× I⁻¹ [r − x]×), as tr W − n·W n, each body's term times its share.
PD_HD double tangential_inverse_mass_term(Quat<double> q, V3<double> d, double m, V3<double> x, V3<double> r,
                                          V3<double> n) {
    V3<double> b = rotate_inverse(q, r - x);
    V3<double> nb = rotate_inverse(q, n);
    double x2 = b.x * b.x, y2 = b.y * b.y, z2 = b.z * b.z;
    double trace = d.x * (y2 + z2) + d.y * (x2 + z2) + d.z * (x2 + y2);
    V3<double> a = cross(b, nb);
    V3<double> da = v3(a.x * d.x, a.y * d.y, a.z * d.z);
    return 2.0 * m + (trace - dot(da, a));
}
PD_HD double tangential_inverse_mass_trace(const ContactKinematics& kin, V3<double> r, V3<double> n, double k_a,
                                           double k_b) {
    double sum = k_a * tangential_inverse_mass_term(kin.q_a, kin.inverse_inertia_a, kin.inverse_mass_a, kin.x_a, r, n) +
                 k_b * tangential_inverse_mass_term(kin.q_b, kin.inverse_inertia_b, kin.inverse_mass_b, kin.x_b, r, n);
    return max_(sum, 0.0);
}

// friction.rs `resolved_stiffness`: the stiffest spring the step resolves, (σ/Δt)²/w, σ = 0.5.
PD_HD double resolved_stiffness(double inverse, double dt) {
    if (dt > 0.0 && inverse > 0.0) {
        double x = 0.5 / dt;
        return x * x / inverse;
    }
    return 0.0;
}

// friction.rs `lock_coefficient`: the dashpot whose one-step impulse takes `share` of the motion.
PD_HD double lock_coefficient(double share, double inverse, double dt) {
    return dt > 0.0 && inverse > 0.0 ? share / (dt * inverse) : 0.0;
}

// friction.rs `stretch`: the stretch s/√k of a spring carried at constant energy.
PD_HD V3<double> stretch(V3<double> stored, double root_k) {
    return root_k > 0.0 ? stored * (1.0 / root_k) : zero3<double>();
}
PD_HD double stretch(double stored, double root_k) { return root_k > 0.0 ? stored * (1.0 / root_k) : 0.0; }

// friction.rs `slip_step`: one step of a Kelvin–Voigt element in series with a Coulomb slider;
// the force into *force, the stretch at the end of the step returned.
PD_HD V3<double> slip_step(V3<double> xi_old, V3<double> v, double k, double c, double cap, double dt,
                           V3<double>* force) {
    V3<double> xi = xi_old + v * dt;
    V3<double> trial = xi * (-k) + v * (-c);
    double magnitude = norm(trial);
    if (magnitude <= cap) {
        *force = trial;
        return xi;
    }
    V3<double> unit = trial * (1.0 / magnitude);
    double stiffness = k + (dt > 0.0 ? c / dt : 0.0);
    *force = unit * cap;
    return stiffness > 0.0 ? xi + unit * ((magnitude - cap) / stiffness) : zero3<double>();
}
PD_HD double slip_step(double xi_old, double v, double k, double c, double cap, double dt, double* force) {
    double xi = xi_old + v * dt;
    double trial = xi * (-k) + v * (-c);
    double magnitude = abs_(trial);
    if (magnitude <= cap) {
        *force = trial;
        return xi;
    }
    double unit = trial * (1.0 / magnitude);
    double stiffness = k + (dt > 0.0 ? c / dt : 0.0);
    *force = unit * cap;
    return stiffness > 0.0 ? xi + unit * ((magnitude - cap) / stiffness) : 0.0;
}

// U(V) = (3/4) c V^{4/3} for V > 0 (law.rs `potential`).
PD_HD double contact_potential(double c, double v) { return v > 0.0 ? 0.75 * c * v * portable_cbrt(v) : 0.0; }

// The mean slope of U over the volume window [lo, hi] (law.rs `mean_pressure`).
PD_HD double mean_pressure(double c, double lo, double hi) {
    if (hi <= lo) {
        return c * portable_cbrt(max_(hi, 0.0));
    }
    if (lo <= 0.0) {
        return contact_potential(c, hi) / (hi - lo);
    }
    double x = portable_cbrt(lo), y = portable_cbrt(hi);
    return 0.75 * c * (x + y) * (x * x + y * y) / (x * x + x * y + y * y);
}

// The Hunt–Crossley reference speed of the current loading cycle, signed by its phase
// (law.rs loading_cycle_speed): a new cycle at first touch and at each approach after an
// unloading; the largest approach speed of the cycle while loading.
PD_HD double loading_cycle_speed(double stored, double vn) {
    double speed = max_(abs_(vn), 2.2250738585072014e-308);
    if (vn < 0.0) {
        return stored > 0.0 ? max_(stored, speed) : speed;
    }
    return stored == 0.0 ? -speed : -abs_(stored);
}

// V* = (A_n Δt √(c/m*) / σ)³, σ = 0.5: the volume below which the potential is regularized
// (law.rs `resolved_volume`, RESOLVED_STEP).
PD_HD double resolved_volume(double c, double area, double dt, double effective_mass) {
    double x = area * dt * sqrt_(c / effective_mass) / 0.5;
    return x * x * x;
}

// W(V): (c/2) V*^{-2/3} V² below V*, U(V) − (1/4) c V*^{4/3} above (law.rs `resolved_potential`).
PD_HD double resolved_potential(double c, double v, double resolved) {
    if (v <= 0.0) {
        return 0.0;
    }
    if (v < resolved) {
        double r = portable_cbrt(resolved);
        return 0.5 * c * v * v / (r * r);
    }
    return contact_potential(c, v) - 0.25 * c * resolved * portable_cbrt(resolved);
}

// W'(V) (law.rs `resolved_pressure`).
PD_HD double resolved_pressure(double c, double v, double resolved) {
    if (v <= 0.0) {
        return 0.0;
    }
    if (v < resolved) {
        double r = portable_cbrt(resolved);
        return c * v / (r * r);
    }
    return c * portable_cbrt(v);
}

// The mean slope of W over [lo, hi] (law.rs `resolved_mean_pressure`).
PD_HD double resolved_mean_pressure(double c, double lo, double hi, double resolved) {
    if (hi <= lo) {
        return resolved_pressure(c, hi, resolved);
    }
    if (lo >= resolved) {
        return mean_pressure(c, lo, hi);
    }
    return (resolved_potential(c, hi, resolved) - resolved_potential(c, lo, resolved)) / (hi - lo);
}

// The overlap's local power law V(δ) = V (δ/h)^k about its depth h (law.rs `LocalPowerLaw`).
struct LocalPowerLaw {
    double volume, depth, exponent;
};

PD_HD LocalPowerLaw local_power_law(double volume, double area, double thickness) {
    LocalPowerLaw out;
    out.volume = volume;
    double h = thickness > 0.0 && thickness - thickness == 0.0 ? thickness : volume / area;
    double ratio = area * h / volume;
    out.exponent = min_(max_(ratio, 1.0), 3.0);
    // A clamped exponent takes the depth that keeps V'(h) = k V/h the contact's area.
    out.depth = ratio - ratio == 0.0 && ratio != out.exponent ? out.exponent * volume / area : h;
    return out;
}

// LocalPowerLaw::volume_at: the volume after the bodies approach by d more (0 once apart).
PD_HD double local_volume_at(const LocalPowerLaw& l, double d) {
    double ratio = 1.0 + d / l.depth;
    return ratio > 0.0 ? l.volume * portable_pow(ratio, l.exponent) : 0.0;
}

// The normal force of a contact for a pressure (law.rs `contact_forces`' `normal` closure):
// elastic, the Hunt–Crossley coefficient, and the capped total that never pulls.
struct NormalForce {
    double f_elastic, c_n, f_normal;
};

PD_HD NormalForce normal_force(const ContactParameters& params, double cap_mass, double pressure, double area,
                               double v_ref, double share, double vn, double dt) {
    NormalForce out;
    out.f_elastic = pressure * area;
    out.c_n = params.damping * out.f_elastic / v_ref;
    double f_damp = -out.c_n * vn;
    if (dt > 0.0) {
        double limit = share * cap_mass * abs_(vn) / dt;
        f_damp = min_(max_(f_damp, -limit), limit);
    }
    out.f_normal = max_(out.f_elastic + f_damp, 0.0);
    return out;
}

// The normal force a kick applies for an elastic force (law.rs: `normal(force / area)`), with
// which the window judges whether the coming drift ends apart (trajectory.rs `window_force`'s
// `kick`).
struct Kick {
    const ContactParameters* params;
    double cap_mass, area, v_ref, share, vn;
};

PD_HD double kick_force(const Kick& k, double force, double dt) {
    return normal_force(*k.params, k.cap_mass, force / k.area, k.area, k.v_ref, k.share, k.vn, dt).f_normal;
}

// A face contact's one-dimensional normal motion about its current state (trajectory.rs
// `NormalMotion`): the approach d beyond the depth h and its rate, under the regularized
// potential W of the local power law.
struct NormalMotion {
    LocalPowerLaw law;
    double stiffness, resolved, inverse_mass;
};

// NormalMotion::acceleration: -W'(V) V'(δ)/m*, V'(δ) = k V/δ; zero once apart.
PD_HD double motion_acceleration(const NormalMotion& m, double d) {
    double depth = m.law.depth + d;
    if (depth <= 0.0) {
        return 0.0;
    }
    double v = local_volume_at(m.law, d);
    double area = m.law.exponent * v / depth;
    return -resolved_pressure(m.stiffness, v, m.resolved) * area * m.inverse_mass;
}

// NormalMotion::flow: the state (d, rate) after `span` (backward when negative), RK4 in 4
// sub-steps (trajectory.rs WINDOW_SUBSTEPS), a sub-step that would cross touch at its starting
// speed cut there, free flight once apart.
PD_HD void motion_flow(const NormalMotion& m, double* d_io, double* rate_io, double span) {
    double d = *d_io, rate = *rate_io;
    double sign = span < 0.0 ? -1.0 : 1.0;
    double left = abs_(span);
    double full = left / 4.0;
    for (int i = 0; i < 16; ++i) {
        if (left <= 0.0) {
            break;
        }
        double depth = m.law.depth + d;
        if (depth <= 0.0) {
            d += sign * rate * left;
            break;
        }
        double h = min_(full, left);
        double out = -sign * rate;
        if (out > 0.0 && depth - out * h < 0.0) {
            double touch = depth / out;
            if (touch >= 1e-14 * full) {
                h = min_(h, touch);
            }
        }
        double s = sign * h;
        double k1d = rate, k1r = motion_acceleration(m, d);
        double k2d = rate + 0.5 * s * k1r, k2r = motion_acceleration(m, d + 0.5 * s * k1d);
        double k3d = rate + 0.5 * s * k2r, k3r = motion_acceleration(m, d + 0.5 * s * k2d);
        double k4d = rate + s * k3r, k4r = motion_acceleration(m, d + s * k3d);
        d += s / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d);
        rate += s / 6.0 * (k1r + 2.0 * k2r + 2.0 * k3r + k4r);
        left -= h;
    }
    *d_io = d;
    *rate_io = rate;
}

// NormalMotion::window_force: the mean elastic force over the kick window from the mid-point
// speed (3 fixed-point passes, trajectory.rs MIDPOINT_PASSES), the window before a new contact
// and the window after a leaving one included, judged with the force the kick applies.
PD_HD double motion_window_force(const NormalMotion& m, double vn, double dt, bool first, double guess,
                                 const Kick& kick) {
    double half = -vn;
    double force = guess;
    for (int pass = 0; pass < 3; ++pass) {
        double mid = half - 0.5 * force * m.inverse_mass * dt;
        double d_back = 0.0, r_back = mid;
        motion_flow(m, &d_back, &r_back, -0.5 * dt);
        double d_ahead = 0.0, r_ahead = mid;
        motion_flow(m, &d_ahead, &r_ahead, 0.5 * dt);
        double taken = r_back - r_ahead;
        if (first) {
            double d = d_back, r = r_back;
            motion_flow(m, &d, &r, -dt);
            taken += r - r_back;
        }
        double left = kick_force(kick, taken / (m.inverse_mass * dt), dt) * m.inverse_mass * dt;
        if (m.law.depth + (half - left) * dt <= 0.0) {
            double d = d_ahead, r = r_ahead;
            motion_flow(m, &d, &r, dt);
            taken += r_ahead - r;
        }
        force = taken / (m.inverse_mass * dt);
    }
    return force;
}

// V^{2/3}, the area scale of an overlap of volume V (law.rs `volume_area_scale`).
PD_HD double volume_area_scale(double volume) {
    double r = portable_cbrt(volume);
    return r * r;
}

// A body wholly inside the other (law.rs `wholly_inside`): S along the line of centres from A
// to B (+z for coincident centres) with |S| = V^{2/3}, no surface moment.
PD_HD Overlap<double> wholly_inside(const Overlap<double>& o, const ContactKinematics& kin) {
    V3<double> d = kin.x_b - kin.x_a;
    double len = norm(d);
    V3<double> u = len > 0.0 ? d / len : v3(0.0, 0.0, 1.0);
    Overlap<double> out = o;
    out.dv_dxb = (-u) * volume_area_scale(o.volume);
    out.moment_b = zero3<double>();
    return out;
}

// Where damping and friction act (law.rs `contact_point`): a sphere's surface point on a wall,
// the plane of the lens's rim for two spheres, the elastic line of action at the centroid's
// depth for polyhedra.
PD_HD V3<double> contact_point(const Overlap<double>& o, const ContactKinematics& kin, V3<double> n) {
    double ra = kin.sphere_radius_a, rb = kin.sphere_radius_b;
    if (ra > 0.0) {
        if (rb <= 0.0) {
            return kin.x_a + n * ra;
        }
        V3<double> d = kin.x_b - kin.x_a;
        double d2 = norm2(d);
        if (d2 > 0.0) {
            return kin.x_a + d * ((d2 + ra * ra - rb * rb) / (2.0 * d2));
        }
    }
    double area = norm(o.dv_dxb);
    V3<double> offset = cross(o.dv_dxb, o.moment_b) / (area * area);
    // x − x is 0 exactly for finite x (Rust's is_finite), NaN otherwise.
    bool finite = offset.x - offset.x == 0.0 && offset.y - offset.y == 0.0 && offset.z - offset.z == 0.0;
    return finite ? o.centroid + offset : o.centroid;
}

// Evaluates the contact law for an overlap, updating the contact's history over `dt`
// (law.rs `contact_forces`; the comments there and docs/contact.md give every term). ln e
// and its norm come from `pm`, computed once on the host with the CPU backend's expressions.
PD_HD ContactForces contact_forces(const ContactParameters& params, const PairMaterial& pm,
                                   const Overlap<double>& given, const ContactKinematics& kin,
                                   ContactHistoryRecord* state, double dt) {
    double volume = given.volume;
    if (volume <= 0.0) {
        return no_contact_forces();
    }
    Overlap<double> o = given;
    // law.rs: |S| > 1e-6 V^{2/3} (INSIDE_AREA_FRACTION) as |S|³ > 1e-18 V², without a cube root.
    double given_area = norm(given.dv_dxb);
    if (!(given_area * given_area * given_area > 1e-18 * volume * volume)) {
        o = wholly_inside(given, kin);
    }
    double area = norm(o.dv_dxb);
    V3<double> s_vec = o.dv_dxb;
    V3<double> n = (-s_vec) / area;
    V3<double> c = o.centroid;
    V3<double> r_e = contact_point(o, kin, n);
    V3<double> v_rel = (kin.v_b + cross(kin.w_b, r_e - kin.x_b)) - (kin.v_a + cross(kin.w_a, r_e - kin.x_a));
    double vn = dot(v_rel, n);
    bool first_touch = state->approach_speed == 0.0;

    double stiffness = params.normal_stiffness;
    double travel = 0.5 * abs_(vn) * dt;
    double sweep = travel * area;
    LocalPowerLaw local = local_power_law(volume, area, o.thickness);
    bool windowed = local.exponent < 1.5; // law.rs SINGULAR_EXPONENT
    // The regularized potential W of every contact (law.rs `resolved_volume`).
    double resolved = resolved_volume(stiffness, area, dt, kin.effective_mass);
    bool secant = windowed && !params.trajectory;
    double pressure = secant && sweep > 0.5 * volume
                          ? resolved_mean_pressure(stiffness, volume - sweep, volume + sweep, resolved)
                          : resolved_pressure(stiffness, volume, resolved); // law.rs WINDOW_FRACTION
    if (secant && first_touch && sweep > 0.0 && volume - 2.0 * sweep <= 0.0 && volume - sweep > 0.0) {
        pressure += resolved_potential(stiffness, volume - sweep, resolved) / (2.0 * sweep);
    }
    state->approach_speed = loading_cycle_speed(state->approach_speed, vn);
    double energy = resolved_potential(stiffness, volume, resolved);
    double cycle = abs_(state->approach_speed), floor_speed = sqrt_(2.0 * energy / kin.effective_mass);
    double v_ref = max_(cycle, floor_speed);
    // The caps' share of the relative speed: the whole of it for an impact, half where the floor
    // sets the damping, and there against the masses split among the bodies' contacts.
    bool at_floor = floor_speed > cycle;
    double share = at_floor ? 0.5 : 1.0;
    double cap_mass = at_floor ? kin.dashpot_mass : kin.effective_mass;
    double cap_a = at_floor ? kin.split_a : 1.0, cap_b = at_floor ? kin.split_b : 1.0;
    // Or the impulse of the contact's own normal motion over the kick window (trajectory.rs).
    // A contact deep against its step's travel keeps the slope at V (trajectory.rs
    // TRAJECTORY_FRACTION).
    if (windowed && !secant && dt > 0.0 && sweep > 0.1 * volume) {
        NormalMotion motion;
        motion.law = local;
        motion.stiffness = stiffness;
        motion.resolved = resolved;
        motion.inverse_mass = 1.0 / kin.effective_mass;
        Kick kick;
        kick.params = &params;
        kick.cap_mass = cap_mass;
        kick.area = area;
        kick.v_ref = v_ref;
        kick.share = share;
        kick.vn = vn;
        pressure = motion_window_force(motion, vn, dt, first_touch, pressure * area, kick) / area;
    }
    NormalForce nf = normal_force(params, cap_mass, pressure, area, v_ref, share, vn, dt);
    // The exit (law.rs): a separating contact that the coming drift carries apart.
    if (secant && vn > 0.0 && dt > 0.0) {
        double exit = 0.5 * (vn + nf.f_normal * dt / kin.effective_mass) * dt;
        if (local.depth - 2.0 * exit <= 0.0 && local.depth - exit > 0.0) {
            pressure += resolved_potential(stiffness, local_volume_at(local, -exit), resolved) / (2.0 * exit * area);
            nf = normal_force(params, cap_mass, pressure, area, v_ref, share, vn, dt);
        }
    }
    double f_elastic = nf.f_elastic;
    double c_n = nf.c_n;
    double f_normal = nf.f_normal;
    V3<double> torque_b_el = (-(o.moment_b + cross(c - kin.x_b, s_vec))) * pressure;
    V3<double> torque_a_el = (-((-o.moment_b) + cross(c - kin.x_a, -s_vec))) * pressure;

    // The relative rotation: about the normal (twist) and about tangent axes (rocking).
    const double pi = 3.141592653589793;
    V3<double> w_rel = kin.w_b - kin.w_a;
    double wn = dot(w_rel, n);
    V3<double> w_perp = w_rel - n * wn;

    // Friction at r_e (law.rs, friction.rs): Kelvin–Voigt elements in series with Coulomb
    // sliders, their dashpots the step's lock.
    V3<double> v_t = v_rel - n * vn;
    double disk = area / pi;
    V3<double> tangential = zero3<double>();
    double m_tw = 0.0;
    if (params.friction > 0.0) {
        double seed_t = params.tangential_stiffness * area;
        double w_t = tangential_inverse_mass_trace(kin, r_e, n, cap_a, cap_b);
        double k_t = max_(seed_t, resolved_stiffness(w_t, dt));
        double root_t = sqrt_(k_t);
        V3<double> old = state->spring;
        V3<double> in_plane = old - n * dot(old, n);
        double len = norm(in_plane);
        V3<double> carried = len > 0.0 ? in_plane * (norm(old) / len) : zero3<double>();
        double c_t = lock_coefficient(share, w_t, dt);
        double cap = params.friction * f_normal;
        V3<double> xi = slip_step(stretch(carried, root_t), v_t, k_t, c_t, cap, dt, &tangential);
        state->spring = xi * root_t;
        double w_n = weighted_inverse_inertia(kin, n, cap_a, cap_b);
        double k_tw = max_(0.5 * seed_t * disk, resolved_stiffness(w_n, dt));
        double root_tw = sqrt_(k_tw);
        double c_tw = lock_coefficient(share, w_n, dt);
        double cap_tw = cap * (2.0 / 3.0) * sqrt_(disk);
        double phi = slip_step(stretch(state->twist, root_tw), wn, k_tw, c_tw, cap_tw, dt, &m_tw);
        state->twist = phi * root_tw;
    } else {
        state->spring = zero3<double>();
        state->twist = 0.0;
    }

    // Rocking damping of the contact area: the normal dashpot spread over its disk.
    V3<double> couple_b = n * m_tw;
    double rocking = norm(w_perp);
    if (params.rocking && c_n > 0.0 && rocking > 0.0) {
        double c_roll = 0.25 * c_n * disk;
        double inverse = weighted_inverse_inertia(kin, w_perp / rocking, cap_a, cap_b);
        if (dt > 0.0 && inverse > 0.0) {
            c_roll = min_(c_roll, share / (dt * inverse));
        }
        couple_b -= w_perp * c_roll;
    }
#if PD_ROLLING_FRICTION
    // Rolling friction (law.rs `rolling_couple`): Coulomb's couple μ_r R_r F_n against the
    // relative rolling, R_r = r_A r_B/(r_A + r_B) from the centres to r_e (r_A on a wall),
    // capped at the step's lock so that it never reverses the rolling.
    if (params.rolling_friction > 0.0 && f_normal > 0.0 && rocking > 0.0) {
        double r_a = norm(r_e - kin.x_a);
        double radius = r_a;
        if (kin.inverse_mass_b > 0.0) {
            double r_b = norm(r_e - kin.x_b);
            radius = r_a * r_b / (r_a + r_b);
        }
        V3<double> axis = w_perp / rocking;
        double inverse = weighted_inverse_inertia(kin, axis, cap_a, cap_b);
        double lock = lock_coefficient(share, inverse, dt) * rocking;
        couple_b -= axis * min_(params.rolling_friction * radius * f_normal, lock);
    }
#endif

    V3<double> f_line = n * (f_normal - f_elastic) + tangential;
    ContactForces out;
    out.force_b = n * f_normal + tangential;
    out.torque_b = torque_b_el + cross(r_e - kin.x_b, f_line) + couple_b;
    out.torque_a = torque_a_el + cross(r_e - kin.x_a, -f_line) - couple_b;
    out.elastic_energy = energy + 0.5 * norm2(state->spring) + 0.5 * state->twist * state->twist;
    return out;
}

} // namespace pd
