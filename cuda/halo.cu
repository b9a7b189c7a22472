// Stage 1 of a decomposed run on the GPU. Between rebuilds: the halo's motion records packed
// and unpacked on the device (the GPU twin of src/domain/halo.rs's write_motion/refresh), so
// that only the outer region's particles cross the PCIe bus, through pinned host buffers, each
// step. At rebuilds: the migrating particles' history packed, and the walls' springs carried
// over (src/backend/cuda/exchange.rs).
//
// A motion record is 14 doubles: centroid (3), velocity (3), orientation (x, y, z, w as stored
// here; nalgebra's storage order, which the host packing uses too), angular velocity (3) and the
// contact count of the last evaluation (exact in a double; the dashpot caps' mass splitting
// needs a ghost's whole count, its contacts on other ranks included).
#include "common.cuh"

#define PD_MOTION_DOUBLES 14

// out[14 k ..] = motion of particle slots[k], for k < count.
extern "C" __global__ void pack_motion(int count, const unsigned int* slots, const double* position,
                                       const double* velocity, const double* orientation,
                                       const double* angular_velocity, const unsigned int* contacts,
                                       double* out) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= count) {
        return;
    }
    size_t i = slots[k];
    double* o = out + (size_t)k * PD_MOTION_DOUBLES;
    for (int c = 0; c < 3; ++c) {
        o[c] = position[3 * i + c];
        o[3 + c] = velocity[3 * i + c];
        o[10 + c] = angular_velocity[3 * i + c];
    }
    for (int c = 0; c < 4; ++c) {
        o[6 + c] = orientation[4 * i + c];
    }
    o[13] = (double)contacts[i];
}

// The motion of particle slots[k] = in[14 k ..], for k < count (the ghosts, refreshed).
extern "C" __global__ void unpack_motion(int count, const unsigned int* slots, const double* in, double* position,
                                         double* velocity, double* orientation, double* angular_velocity,
                                         unsigned int* contacts) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= count) {
        return;
    }
    size_t i = slots[k];
    const double* r = in + (size_t)k * PD_MOTION_DOUBLES;
    for (int c = 0; c < 3; ++c) {
        position[3 * i + c] = r[c];
        velocity[3 * i + c] = r[3 + c];
        angular_velocity[3 * i + c] = r[10 + c];
    }
    for (int c = 0; c < 4; ++c) {
        orientation[4 * i + c] = r[6 + c];
    }
    contacts[i] = (unsigned int)r[13];
}

// A rebuild on the device (src/backend/cuda/exchange.rs): the contact history of the particles
// that migrate, packed for the host to send with them, and the walls' springs carried over.

// out[k] = the pairs in contact (either member) of particle slots[k], for k < count.
extern "C" __global__ void count_live_refs(int count, const unsigned int* slots, const unsigned int* ref_offset,
                                           const unsigned int* refs, const unsigned int* contact,
                                           unsigned int* out) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= count) {
        return;
    }
    unsigned int i = slots[k], c = 0;
    for (unsigned int m = ref_offset[i]; m < ref_offset[i + 1]; ++m) {
        c += contact[refs[m] >> 1] == PD_CONTACT_LIVE ? 1u : 0u;
    }
    out[k] = c;
}

// The pairs in contact of particle slots[k], from row row_offset[k] on (count_live_refs's counts
// scanned): the members' global ids (the lower first, as the list names them) and the spring.
extern "C" __global__ void pack_live_refs(int count, const unsigned int* slots, const unsigned int* ref_offset,
                                          const unsigned int* refs, const int2* pairs, const pd_u64* id,
                                          const unsigned int* contact, const double* spring,
                                          const unsigned int* row_offset, pd_u64* out_a, pd_u64* out_b,
                                          double* out_spring) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= count) {
        return;
    }
    unsigned int i = slots[k], row = row_offset[k];
    for (unsigned int m = ref_offset[i]; m < ref_offset[i + 1]; ++m) {
        unsigned int q = refs[m] >> 1;
        if (contact[q] != PD_CONTACT_LIVE) {
            continue;
        }
        int2 p = pairs[q];
        out_a[row] = id[p.x];
        out_b[row] = id[p.y];
        for (int c = 0; c < PD_HISTORY_WIDTH; ++c) {
            out_spring[PD_HISTORY_WIDTH * (size_t)row + c] = spring[PD_HISTORY_WIDTH * (size_t)q + c];
        }
        ++row;
    }
}

// The wall springs of n particles after a rebuild, `walls` per particle: particle k's spring
// with wall w is that of old slot source[k] when that particle's contact with w was live, zero
// otherwise (PD_NO_SLOT: no old slot), as the host's history keeps live contacts alone.
extern "C" __global__ void gather_live_wall_springs(int n, int walls, const unsigned int* source,
                                                    const unsigned int* contact, const double* src, double* dst) {
    int t = blockIdx.x * blockDim.x + threadIdx.x;
    if (t >= n * walls) {
        return;
    }
    int k = t / walls, w = t - k * walls;
    unsigned int o = source[k];
    bool live = o != PD_NO_SLOT && contact[(size_t)o * walls + w] == PD_CONTACT_LIVE;
    for (int c = 0; c < PD_HISTORY_WIDTH; ++c) {
        dst[PD_HISTORY_WIDTH * (size_t)t + c] = live ? src[PD_HISTORY_WIDTH * ((size_t)o * walls + w) + c] : 0.0;
    }
}
