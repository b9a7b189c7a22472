// Stage 9, integration: the GPU twin of src/integrate/mod.rs (velocity Verlet for translation,
// the Dullweber–Leimkuhler–McLachlan splitting of the free rotation in the body frame with
// quaternions, seed paper Eq. 23–26 in energy-conserving form). One thread per particle. The
// operations follow nalgebra's order (quaternion product, rotation, normalisation) and the
// rotation steps' sin/cos are common.cuh's portable_sin_cos, so that double results match the
// CPU backend bit for bit.
//
// A step makes two passes over the particle state: `kick_drift` (half kick, drift, periodic wrap
// and the per-step checks) and `reduce_and_kick` (the force reduction of stage 8 and the second
// half kick). Separate kernels for each stage read and wrote the whole state once per stage;
// the fused ones give the same bits with half the memory traffic and a third of the launches,
// which matters for spheres, whose contacts cost little.
//
// Layout: positions, velocities, angular velocities, forces, torques and principal inertias are
// xyz-interleaved doubles; orientations are (x, y, z, w) like nalgebra's quaternion storage.
#include "common.cuh"
#include "state.cuh"

using namespace pd;

// Hamilton product a b, in nalgebra's order of operations.
PD_DEVICE Quat<double> quat_mul(Quat<double> a, Quat<double> b) {
    Quat<double> r;
    r.w = a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z;
    r.x = a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y;
    r.y = a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x;
    r.z = a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w;
    return r;
}

// Whether slot i holds a ghost of a decomposed run (PD_GHOSTS): ghosts are not integrated, their
// owners' motion arrives through the halo each step.
PD_DEVICE bool is_ghost(const unsigned int* ghost, int i) {
#if PD_GHOSTS
    return ghost[i] != 0u;
#else
    (void)ghost;
    (void)i;
    return false;
#endif
}

// Half kick of particle i: v += (F/m + g) dt/2; π += Rᵀτ dt/2 with ω recomputed
// (integrate::half_kick). Returns the new velocity and angular velocity; the caller stores them.
PD_DEVICE void half_kick_particle(int i, double* velocity, double* angular_velocity, V3<double> f, V3<double> torque,
                                  const double* mass, const double* inertia, const double* orientation, V3<double> g,
                                  double dt, V3<double>* v_out, V3<double>* w_out) {
    double h = 0.5 * dt;
    double m = mass[i];
    V3<double> v = load3(velocity, i);
    *v_out = v + (v3(f.x / m, f.y / m, f.z / m) + g) * h;
    Quat<double> q = load_quat(orientation, i);
    V3<double> I = load3(inertia, i);
    V3<double> wb = rotate_inverse(q, load3(angular_velocity, i));
    V3<double> tb = rotate_inverse(q, torque);
    V3<double> pi = v3(I.x * wb.x, I.y * wb.y, I.z * wb.z) + tb * h;
    *w_out = rotate(q, v3(pi.x / I.x, pi.y / I.y, pi.z / I.z));
}

// Periodic wrap of one coordinate into [lo, hi) (Bounds::wrap, the same arithmetic): outside,
// x = lo + (x − lo) mod L with the Euclidean remainder, and lo where that rounds to hi; inside,
// x unchanged, so that wrapping twice (the device, then the host at a round trip) is wrapping
// once.
PD_DEVICE double wrap_coordinate(double x, double lo, double hi) {
    if (x >= lo && x < hi) {
        return x;
    }
    double l = hi - lo;
    double r = fmod(x - lo, l);
    if (r < 0.0) {
        r += l; // rem_euclid
    }
    double y = lo + r;
    return y >= hi ? lo : y;
}

// The first half of a step for particle i, in one pass over its state (the stage order of
// Simulation::step): the half kick with last step's forces, the drift x += v dt with the free
// rotation by the symmetric splitting 1(dt/2) 2(dt/2) 3(dt) 2(dt/2) 1(dt/2) (integrate::drift,
// integrate::free_rotation), the periodic wrap (`wrap` nonzero) and the per-step checks
// (`checks` nonzero), reduced into `flags` (StepFlags of layout.cuh, zeroed by the host):
// `rebuild` = 1 when some particle moved more than half the skin since the last list build
// (PairList::needs_rebuild), `outside` = number of particles outside a closed domain box,
// `unstable` = 1 when a position or velocity is not finite, or an owned particle's angular
// velocity or orientation is not, or it moves faster than `max_speed` (|v| + |ω| radius; the
// stability guard, Simulation::check_motion), `first_unstable` = the bitwise complement of the
// smallest local index of such a particle, for the error message (a complement, so that zeroed
// flags are cleared), `snapshot` = 1 when some particle moved more than `snapshot_distance`
// since the last list build (the hybrid list's snapshot is due, docs/design.md §7; infinite
// when none is wanted), `wall_rebuild` = 1 when, with `wall_reference` not null, some particle is
// farther than `wall_half_reach` from where the wall list was built (the plain difference: a
// periodic wrap moves a particle against the walls; the host has already taken the walls' own
// motion off the half skin). Ghosts of a decomposed run are neither kicked nor drifted (their
// owners' motion arrives through the halo) but are wrapped and checked, as on the CPU. Each
// value takes the same operations as the separate stages of the CPU backend, in the same
// order, so that fusing them changes no bit.
extern "C" __global__ void kick_drift(KickDriftParams args) {
    const int n = args.n;
    const unsigned int* ghost = args.ghost;
    double* position = args.position;
    double* velocity = args.velocity;
    double* orientation = args.orientation;
    double* angular_velocity = args.angular_velocity;
    const double* force = args.force;
    const double* torque = args.torque;
    const double* mass = args.mass;
    const double* inertia = args.inertia;
    const double gx = args.gravity[0], gy = args.gravity[1], gz = args.gravity[2];
    const double dt = args.dt;
    const int wrap = args.wrap;
    const GridParams& grid = args.grid;
    const int checks = args.checks;
    const double* reference = args.reference;
    const double half_skin = args.half_skin;
    const double snapshot_distance = args.snapshot_distance;
    const double* wall_reference = args.wall_reference;
    const double wall_half_reach = args.wall_half_reach;
    const double* radius = args.radius;
    const double max_speed = args.max_speed;
    StepFlags* flags = args.flags;
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    V3<double> x = load3(position, i);
    V3<double> v;
    // The owned particle's new angular velocity and orientation, for the stability guard.
    V3<double> w_new = zero3<double>();
    Quat<double> q_new;
    q_new.w = 1.0;
    q_new.x = 0.0;
    q_new.y = 0.0;
    q_new.z = 0.0;
    bool owned = !is_ghost(ghost, i);
    if (owned) {
        V3<double> w;
        half_kick_particle(i, velocity, angular_velocity, load3(force, i), load3(torque, i), mass, inertia,
                           orientation, v3(gx, gy, gz), dt, &v, &w);
        x = x + v * dt;
        Quat<double> q = load_quat(orientation, i);
        V3<double> I = load3(inertia, i);
        V3<double> wb = rotate_inverse(q, w);
        double pi[3] = {I.x * wb.x, I.y * wb.y, I.z * wb.z};
        double inertia_k[3] = {I.x, I.y, I.z};
        const int axes[5] = {0, 1, 2, 1, 0};
        const double halves[5] = {0.5, 0.5, 1.0, 0.5, 0.5};
        for (int s = 0; s < 5; ++s) {
            int axis = axes[s];
            double theta = halves[s] * dt * pi[axis] / inertia_k[axis];
            double sang, cang;
            portable_sin_cos(theta / 2.0, &sang, &cang);
            Quat<double> step;
            step.w = cang;
            step.x = axis == 0 ? sang : 0.0;
            step.y = axis == 1 ? sang : 0.0;
            step.z = axis == 2 ? sang : 0.0;
            // nalgebra multiplies the unit axis by sin: 1·s = s and 0·s = ±0, as here up to
            // the sign of zero, which no later operation can observe.
            q = quat_mul(q, step);
            V3<double> p = rotate_inverse(step, v3(pi[0], pi[1], pi[2]));
            pi[0] = p.x;
            pi[1] = p.y;
            pi[2] = p.z;
        }
        // new_normalize: coords (x, y, z, w) divided by their norm, summed as (x²+z²) + (y²+w²).
        double a = q.x * q.x, b = q.y * q.y, c = q.z * q.z, d = q.w * q.w;
        double len = sqrt((a + c) + (b + d));
        q.x = q.x / len;
        q.y = q.y / len;
        q.z = q.z / len;
        q.w = q.w / len;
        store3(velocity, i, v);
        store_quat(orientation, i, q);
        w_new = rotate(q, v3(pi[0] / I.x, pi[1] / I.y, pi[2] / I.z));
        q_new = q;
        store3(angular_velocity, i, w_new);
    } else if (checks) {
        v = load3(velocity, i);
    }
    if (wrap) {
        if (grid.periodic[0]) x.x = wrap_coordinate(x.x, grid.min[0], grid.max[0]);
        if (grid.periodic[1]) x.y = wrap_coordinate(x.y, grid.min[1], grid.max[1]);
        if (grid.periodic[2]) x.z = wrap_coordinate(x.z, grid.min[2], grid.max[2]);
    }
    store3(position, i, x);
    if (!checks) {
        return;
    }
    V3<double> dx = displacement(grid, load3(reference, i), x);
    if (norm2(dx) > half_skin * half_skin) {
        flags->rebuild = 1u;
    }
    if (norm2(dx) > snapshot_distance * snapshot_distance) {
        flags->snapshot = 1u;
    }
    if (wall_reference != nullptr && norm2(x - load3(wall_reference, i)) > wall_half_reach * wall_half_reach) {
        flags->wall_rebuild = 1u;
    }
    double c[3] = {x.x, x.y, x.z};
    bool outside = false;
    for (int k = 0; k < 3; ++k) {
        if (!grid.periodic[k] && (c[k] < grid.min[k] || c[k] > grid.max[k])) {
            outside = true;
        }
    }
    if (outside) {
        atomicAdd(&flags->outside, 1u);
    }
    // Finiteness, and for owned particles the stability guard's speed bound (src/stability.rs
    // StabilityGuard::check_motion; the host names the cause from the synced state).
    double all = x.x + x.y + x.z + v.x + v.y + v.z;
    bool bad = all - all != 0.0;
    if (owned) {
        double more = w_new.x + w_new.y + w_new.z + q_new.x + q_new.y + q_new.z + q_new.w;
        bad = bad || more - more != 0.0 || norm(v) + norm(w_new) * radius[i] > max_speed;
    }
    if (bad) {
        flags->unstable = 1u;
        atomicMax(&flags->first_unstable, ~(unsigned int)i);
    }
}

// Stage 8, the deterministic reduction (src/pipeline/reduction.rs), fused with the second half kick when
// `kick` is nonzero: per particle, the pair forces and torques summed in the order of its
// references (sorted by partner id at the list build), then the wall sums (PD_WALLS), stored as
// the particle's force and torque, then the half kick with them (half_kick_particle). Reference
// r names pair r >> 1, whose slot holds the force on B and the torques on A and B; bit 0 says
// whether the particle is B. Ghosts are summed but not kicked.
extern "C" __global__ void reduce_and_kick(ReduceKickParams args) {
    const int n = args.n;
    const unsigned int* ref_offset = args.ref_offset;
    const unsigned int* refs = args.refs;
    const double* pair_forces = args.pair_forces;
    const double* wall_force = args.wall_force;
    const double* wall_torque = args.wall_torque;
    double* force = args.force;
    double* torque = args.torque;
    const int kick = args.kick;
    const unsigned int* ghost = args.ghost;
    double* velocity = args.velocity;
    double* angular_velocity = args.angular_velocity;
    const double* mass = args.mass;
    const double* inertia = args.inertia;
    const double* orientation = args.orientation;
    const unsigned int* pair_contact = args.pair_contact;
    const double gx = args.gravity[0], gy = args.gravity[1], gz = args.gravity[2];
    const double dt = args.dt;
    int ii = blockIdx.x * blockDim.x + threadIdx.x;
    if (ii >= n) {
        return;
    }
    size_t i = (size_t)ii;
    V3<double> f = zero3<double>(), t = zero3<double>();
    // The particle's contacts, which the next evaluation's dashpot caps split its mass among
    // (pipeline/reduction.rs reduce_forces); a ghost's partial count is replaced by its
    // owner's through the halo before it is read.
    unsigned int contacts = 0u;
    for (unsigned int m = ref_offset[i]; m < ref_offset[i + 1]; ++m) {
        unsigned int r = refs[m];
        size_t k = r >> 1;
        contacts += pair_contact[k] == 1u ? 1u : 0u;
        if (r & 1u) {
            f += load3(pair_forces, 3 * k);
            t += load3(pair_forces, 3 * k + 2);
        } else {
            f -= load3(pair_forces, 3 * k);
            t += load3(pair_forces, 3 * k + 1);
        }
    }
#if PD_WALLS
    f += load3(wall_force, i);
    t += load3(wall_torque, i);
    for (int w = 0; w < args.n_walls; ++w) {
        contacts += args.wall_contact[i * (size_t)args.n_walls + w] == 1u ? 1u : 0u;
    }
#else
    (void)wall_force;
    (void)wall_torque;
#endif
    store3(force, i, f);
    store3(torque, i, t);
    args.contacts[i] = contacts;
    if (kick && !is_ghost(ghost, ii)) {
        V3<double> v, w;
        half_kick_particle(ii, velocity, angular_velocity, f, t, mass, inertia, orientation, v3(gx, gy, gz), dt, &v,
                           &w);
        store3(velocity, i, v);
        store3(angular_velocity, i, w);
    }
}
