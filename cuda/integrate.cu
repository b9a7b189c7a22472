// Stage 9, integration: the GPU twin of src/integrate/mod.rs (velocity Verlet for translation,
// the Dullweber–Leimkuhler–McLachlan splitting of the free rotation in the body frame with
// quaternions, seed paper Eq. 23–26 in energy-conserving form). One thread per particle. The
// operations follow nalgebra's order (quaternion product, rotation, normalisation) so that
// double results match the CPU backend up to the sin/cos of the rotation steps.
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

// Half kick: v += (F/m + g) dt/2; π += Rᵀτ dt/2 with ω recomputed (integrate::half_kick).
extern "C" __global__ void half_kick(int n, const unsigned int* ghost, double* velocity, double* angular_velocity,
                                     const double* force, const double* torque, const double* mass,
                                     const double* inertia, const double* orientation, double gx, double gy,
                                     double gz, double dt) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n || is_ghost(ghost, i)) {
        return;
    }
    double h = 0.5 * dt;
    V3<double> g = v3(gx, gy, gz);
    V3<double> f = load3(force, i);
    double m = mass[i];
    V3<double> v = load3(velocity, i);
    store3(velocity, i, v + (v3(f.x / m, f.y / m, f.z / m) + g) * h);
    Quat<double> q = load_quat(orientation, i);
    V3<double> I = load3(inertia, i);
    V3<double> wb = rotate_inverse(q, load3(angular_velocity, i));
    V3<double> tb = rotate_inverse(q, load3(torque, i));
    V3<double> pi = v3(I.x * wb.x, I.y * wb.y, I.z * wb.z) + tb * h;
    store3(angular_velocity, i, rotate(q, v3(pi.x / I.x, pi.y / I.y, pi.z / I.z)));
}

// Drift: x += v dt and the free rotation by the symmetric splitting 1(dt/2) 2(dt/2) 3(dt)
// 2(dt/2) 1(dt/2) (integrate::drift, integrate::free_rotation).
extern "C" __global__ void drift(int n, const unsigned int* ghost, double* position, const double* velocity,
                                 double* orientation, double* angular_velocity, const double* inertia, double dt) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n || is_ghost(ghost, i)) {
        return;
    }
    store3(position, i, load3(position, i) + load3(velocity, i) * dt);
    Quat<double> q = load_quat(orientation, i);
    V3<double> I = load3(inertia, i);
    V3<double> wb = rotate_inverse(q, load3(angular_velocity, i));
    double pi[3] = {I.x * wb.x, I.y * wb.y, I.z * wb.z};
    double inertia_k[3] = {I.x, I.y, I.z};
    const int axes[5] = {0, 1, 2, 1, 0};
    const double halves[5] = {0.5, 0.5, 1.0, 0.5, 0.5};
    for (int s = 0; s < 5; ++s) {
        int axis = axes[s];
        double theta = halves[s] * dt * pi[axis] / inertia_k[axis];
        double sang, cang;
        sincos(theta / 2.0, &sang, &cang);
        Quat<double> step;
        step.w = cang;
        step.x = axis == 0 ? sang : 0.0;
        step.y = axis == 1 ? sang : 0.0;
        step.z = axis == 2 ? sang : 0.0;
        // nalgebra multiplies the unit axis by sin: 1·s = s and 0·s = ±0, as here up to the
        // sign of zero, which no later operation can observe.
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
    store_quat(orientation, i, q);
    store3(angular_velocity, i, rotate(q, v3(pi[0] / I.x, pi[1] / I.y, pi[2] / I.z)));
}

// Per-step checks in one pass, reduced into `flags` (zeroed by the host):
// flags[0] = 1 when some particle moved more than half the skin since the last list build
// (PairList::needs_rebuild), flags[1] = number of particles outside a closed domain box,
// flags[2] = 1 when a position or velocity is not finite (Simulation::check_finite), flags[3] =
// smallest local index with a non-finite value (for the error message).
extern "C" __global__ void step_checks(int n, const double* position, const double* velocity,
                                       const double* reference, GridParams grid, double half_skin,
                                       unsigned int* flags) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    V3<double> x = load3(position, i);
    V3<double> d = displacement(grid, load3(reference, i), x);
    if (norm2(d) > half_skin * half_skin) {
        flags[0] = 1u;
    }
    double c[3] = {x.x, x.y, x.z};
    bool outside = false;
    for (int k = 0; k < 3; ++k) {
        if (!grid.periodic[k] && (c[k] < grid.min[k] || c[k] > grid.max[k])) {
            outside = true;
        }
    }
    if (outside) {
        atomicAdd(&flags[1], 1u);
    }
    V3<double> v = load3(velocity, i);
    double all = x.x + x.y + x.z + v.x + v.y + v.z;
    if (all - all != 0.0) {
        flags[2] = 1u;
        atomicMin(&flags[3], (unsigned int)i);
    }
}

// Periodic wrap of positions into the box (Bounds::wrap), x = min + (x − min) mod L with the
// Euclidean remainder.
extern "C" __global__ void wrap_periodic(int n, double* position, GridParams grid) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    for (int k = 0; k < 3; ++k) {
        if (grid.periodic[k]) {
            double l = grid.max[k] - grid.min[k];
            double r = fmod(position[3 * i + k] - grid.min[k], l);
            if (r < 0.0) {
                r += l; // rem_euclid
            }
            position[3 * i + k] = grid.min[k] + r;
        }
    }
}
