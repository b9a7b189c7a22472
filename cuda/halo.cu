// Stage 1 of a decomposed run on the GPU: the halo's motion records packed and unpacked on the
// device (the GPU twin of src/domain/halo.rs's write_motion/refresh), so that only the outer
// region's particles cross the PCIe bus, through pinned host buffers, each step.
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
