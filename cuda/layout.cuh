// Every struct the kernels share with Rust, in one place: the mirror of
// src/backend/cuda/layout.rs, field for field. The host passes the Rust side's sizes and field
// offsets in as PD_SIZEOF_<STRUCT> and PD_OFFSETOF_<STRUCT>_<FIELD> defines (layout.rs
// `layout_defines`), and each struct is checked against them below, so a layout drift fails the
// kernel compile (tests/cuda_compile.rs) instead of reading garbage on the device (docs/design.md §3).
//
// The structs of the pair geometry and the contact law (GridParams, PairMaterial) compile on the
// host as well (tests/cuda_geometry_host.rs); the kernels' argument structs only with NVRTC or
// nvcc. Structs passed by value to a kernel (the *Params) live in the kernel parameter space
// (4 KB); explicit `pad` fields keep every member where Rust's `#[repr(C)]` puts it.
#pragma once
#include "common.cuh"

// offsetof in a constant expression: NVRTC has no <cstddef> and no __builtin_offsetof, but its
// front end folds __INTADDR__.
#if defined(__CUDACC_RTC__)
#define PD_OFFSETOF(T, f) ((unsigned long long)__INTADDR__(&(((T*)0)->f)))
#else
#include <cstddef>
#define PD_OFFSETOF(T, f) ((unsigned long long)offsetof(T, f))
#endif
#define PD_CHECK_SIZE(T, NAME) static_assert(sizeof(T) == PD_SIZEOF_##NAME, #T " differs in size from Rust's layout.rs")
#define PD_CHECK_OFFSET(T, f, NAME) \
    static_assert(PD_OFFSETOF(T, f) == PD_OFFSETOF_##NAME##_##f, #T "." #f " is not where Rust's layout.rs puts it")

namespace pd {

// The domain box and the neighbour grid (layout.rs `GridParams`). Mirrors src/neighbor/mod.rs
// `Bounds` and `Grid`.
struct GridParams {
    double min[3];     // domain box
    double max[3];
    double size[3];    // cell widths
    int dims[3];       // cells per axis
    int periodic[3];   // 1 on periodic axes
};
#ifdef PD_SIZEOF_GRID_PARAMS
PD_CHECK_SIZE(GridParams, GRID_PARAMS);
PD_CHECK_OFFSET(GridParams, min, GRID_PARAMS);
PD_CHECK_OFFSET(GridParams, max, GRID_PARAMS);
PD_CHECK_OFFSET(GridParams, size, GRID_PARAMS);
PD_CHECK_OFFSET(GridParams, dims, GRID_PARAMS);
PD_CHECK_OFFSET(GridParams, periodic, GRID_PARAMS);
#endif

// Contact parameters of one pair of materials (layout.rs `PairMaterial`).
struct PairMaterial {
    double restitution;
    double friction;
    double damping;         // Hunt–Crossley ᾱ(e), computed on the host
    double log_restitution; // ln e, computed on the host
    double log_norm;        // sqrt((ln e)² + π²), computed on the host
    double rolling_friction; // μ_r (0: no rolling couple)
};
#ifdef PD_SIZEOF_PAIR_MATERIAL
PD_CHECK_SIZE(PairMaterial, PAIR_MATERIAL);
PD_CHECK_OFFSET(PairMaterial, restitution, PAIR_MATERIAL);
PD_CHECK_OFFSET(PairMaterial, friction, PAIR_MATERIAL);
PD_CHECK_OFFSET(PairMaterial, damping, PAIR_MATERIAL);
PD_CHECK_OFFSET(PairMaterial, log_restitution, PAIR_MATERIAL);
PD_CHECK_OFFSET(PairMaterial, log_norm, PAIR_MATERIAL);
PD_CHECK_OFFSET(PairMaterial, rolling_friction, PAIR_MATERIAL);
#endif

#if defined(__CUDACC_RTC__) || defined(__CUDACC__)

// The per-step status flags of `kick_drift` (layout.rs `StepFlags`), zeroed by the host and read
// back after the drift.
struct StepFlags {
    unsigned int rebuild;        // some particle moved more than half the skin since the list build
    unsigned int outside;        // particles outside a closed domain box
    unsigned int unstable;       // a position or velocity is not finite, or the guard's speed bound
    unsigned int first_unstable; // ~(the smallest local index of such a particle); 0: none
    unsigned int wall_rebuild;   // some particle left the wall list's reach
    unsigned int snapshot;       // some particle moved more than the snapshot distance (a host build is due)
};
#ifdef PD_SIZEOF_STEP_FLAGS
PD_CHECK_SIZE(StepFlags, STEP_FLAGS);
PD_CHECK_OFFSET(StepFlags, rebuild, STEP_FLAGS);
PD_CHECK_OFFSET(StepFlags, outside, STEP_FLAGS);
PD_CHECK_OFFSET(StepFlags, unstable, STEP_FLAGS);
PD_CHECK_OFFSET(StepFlags, first_unstable, STEP_FLAGS);
PD_CHECK_OFFSET(StepFlags, wall_rebuild, STEP_FLAGS);
PD_CHECK_OFFSET(StepFlags, snapshot, STEP_FLAGS);
#endif

// The particle state the contact stages read (layout.rs `ParticleView`; device pointers,
// xyz-interleaved).
struct ParticleView {
    const double* position;
    const double* velocity;
    const double* angular_velocity;
    const double* orientation; // x, y, z, w
    const double* mass;
    const double* inertia;
    const double* scale;
    const double* radius;      // bounding (circumscribed) radius
    const double* cn;          // E / R (volume-equivalent radius): normal stiffness term
    const double* ct;          // E / (2 (1 + ν) R): tangential stiffness term
    const unsigned int* tmpl;  // template index
    const unsigned int* material;
    const unsigned int* contacts; // contacts at the last evaluation (the dashpot caps' mass splitting)
};
#ifdef PD_SIZEOF_PARTICLE_VIEW
PD_CHECK_SIZE(ParticleView, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, position, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, velocity, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, angular_velocity, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, orientation, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, mass, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, inertia, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, scale, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, radius, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, cn, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, ct, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, tmpl, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, material, PARTICLE_VIEW);
PD_CHECK_OFFSET(ParticleView, contacts, PARTICLE_VIEW);
#endif

// Per-pair outputs (layout.rs `PairOutputs`): force on B, torque on A, torque on B (nine
// doubles), elastic energy.
struct PairOutputs {
    double* forces;
    double* energy;
    // 1 when the pair is in contact (its spring is live history); PD_CONTACT_FAILED | status
    // when its geometry failed this step (contact.cu); else 0.
    unsigned int* contact;
};
#ifdef PD_SIZEOF_PAIR_OUTPUTS
PD_CHECK_SIZE(PairOutputs, PAIR_OUTPUTS);
PD_CHECK_OFFSET(PairOutputs, forces, PAIR_OUTPUTS);
PD_CHECK_OFFSET(PairOutputs, energy, PAIR_OUTPUTS);
PD_CHECK_OFFSET(PairOutputs, contact, PAIR_OUTPUTS);
#endif

// The arguments every pair evaluation reads and writes (layout.rs `PairArgs`).
struct PairArgs {
    const int2* pairs;
    GridParams grid;
    // Each pair's cached separating axis, in float (store_axis, load_axis of contact.cu).
    float* axes;
    ParticleView p;
    const PairMaterial* materials;
    int n_materials;
    const double* spring_in;
    double* spring_out;
    PairOutputs out;
    double dt;
    double max_overlap; // the stability guard's overlap-volume bound (src/stability.rs); inf: off
    unsigned int* error;
};
#ifdef PD_SIZEOF_PAIR_ARGS
PD_CHECK_SIZE(PairArgs, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, pairs, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, grid, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, axes, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, p, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, materials, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, n_materials, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, spring_in, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, spring_out, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, out, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, dt, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, max_overlap, PAIR_ARGS);
PD_CHECK_OFFSET(PairArgs, error, PAIR_ARGS);
#endif

// One wall mesh in its own frame (layout.rs `WallInfo`, src/contact/wall.rs `WallMesh`): facets
// [facet_offset, facet_offset + n_facets) of the concatenated arrays, its facet grid, material.
struct WallInfo {
    int facet_offset;
    int n_facets;
    int cell_offset; // into the concatenated cell starts (each grid has cells + 1 entries)
    int material;
    double grid_min[3];
    double grid_size;
    int dims[3];
    int pad;
};
#ifdef PD_SIZEOF_WALL_INFO
PD_CHECK_SIZE(WallInfo, WALL_INFO);
PD_CHECK_OFFSET(WallInfo, facet_offset, WALL_INFO);
PD_CHECK_OFFSET(WallInfo, n_facets, WALL_INFO);
PD_CHECK_OFFSET(WallInfo, cell_offset, WALL_INFO);
PD_CHECK_OFFSET(WallInfo, material, WALL_INFO);
PD_CHECK_OFFSET(WallInfo, grid_min, WALL_INFO);
PD_CHECK_OFFSET(WallInfo, grid_size, WALL_INFO);
PD_CHECK_OFFSET(WallInfo, dims, WALL_INFO);
PD_CHECK_OFFSET(WallInfo, pad, WALL_INFO);
#endif

// A wall's pose and velocity field at the current time (layout.rs `WallState`;
// WallMotion::transform, velocity_at, angular_velocity): a point c of the wall moves with
// v0 + omega × (c − origin).
struct WallState {
    double rotation[4]; // x, y, z, w
    double translation[3];
    double v0[3];
    double omega[3];
    double origin[3];
};
#ifdef PD_SIZEOF_WALL_STATE
PD_CHECK_SIZE(WallState, WALL_STATE);
PD_CHECK_OFFSET(WallState, rotation, WALL_STATE);
PD_CHECK_OFFSET(WallState, translation, WALL_STATE);
PD_CHECK_OFFSET(WallState, v0, WALL_STATE);
PD_CHECK_OFFSET(WallState, omega, WALL_STATE);
PD_CHECK_OFFSET(WallState, origin, WALL_STATE);
#endif

// The arguments of `kick_drift` (integrate.cu; layout.rs `KickDriftParams`).
struct KickDriftParams {
    int n;
    int wrap;   // nonzero: the periodic wrap
    int checks; // nonzero: the per-step checks against `reference`
    int pad;
    const unsigned int* ghost;
    double* position;
    double* velocity;
    double* orientation;
    double* angular_velocity;
    const double* force;
    const double* torque;
    const double* mass;
    const double* inertia;
    const double* radius;
    double gravity[3];
    double dt;
    GridParams grid;
    const double* reference;
    double half_skin;
    double snapshot_distance; // the hybrid list's trigger (docs/design.md §7); infinite: none
    const double* wall_reference; // null: no wall list to check
    double wall_half_reach;
    double max_speed;
    StepFlags* flags;
};
#ifdef PD_SIZEOF_KICK_DRIFT_PARAMS
PD_CHECK_SIZE(KickDriftParams, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, n, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, wrap, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, checks, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, pad, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, ghost, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, position, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, velocity, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, orientation, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, angular_velocity, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, force, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, torque, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, mass, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, inertia, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, radius, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, gravity, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, dt, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, grid, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, reference, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, half_skin, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, snapshot_distance, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, wall_reference, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, wall_half_reach, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, max_speed, KICK_DRIFT_PARAMS);
PD_CHECK_OFFSET(KickDriftParams, flags, KICK_DRIFT_PARAMS);
#endif

// The arguments of `reduce_and_kick` (integrate.cu; layout.rs `ReduceKickParams`).
struct ReduceKickParams {
    int n;
    int kick; // nonzero: the second half kick after the reduction
    const unsigned int* ref_offset;
    const unsigned int* refs;
    const double* pair_forces;
    const double* wall_force; // null without walls
    const double* wall_torque;
    double* force;
    double* torque;
    const unsigned int* ghost;
    double* velocity;
    double* angular_velocity;
    const double* mass;
    const double* inertia;
    const double* orientation;
    const unsigned int* pair_contact; // the pair slots' contact flags
    const unsigned int* wall_contact; // the wall slots' contact flags (particle-major), null without walls
    unsigned int* contacts;           // out: each particle's contacts, pairs and walls
    int n_walls;
    int pad;
    double gravity[3];
    double dt;
};
#ifdef PD_SIZEOF_REDUCE_KICK_PARAMS
PD_CHECK_SIZE(ReduceKickParams, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, n, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, kick, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, ref_offset, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, refs, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, pair_forces, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, wall_force, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, wall_torque, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, force, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, torque, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, ghost, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, velocity, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, angular_velocity, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, mass, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, inertia, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, orientation, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, pair_contact, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, wall_contact, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, contacts, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, n_walls, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, gravity, REDUCE_KICK_PARAMS);
PD_CHECK_OFFSET(ReduceKickParams, dt, REDUCE_KICK_PARAMS);
#endif

// The particles and the grid of `count_pairs` and `fill_pairs` (neighbor.cu; layout.rs
// `PairSearchParams`).
struct PairSearchParams {
    int n;
    int part; // 0 all pairs; in a decomposed run 1 those of two owned particles, 2 with a ghost
    const double* position;
    const double* radius;
    const pd_u64* id;
    const unsigned int* ghost;
    const unsigned int* cell_start;
    GridParams grid;
    double skin;
};
#ifdef PD_SIZEOF_PAIR_SEARCH_PARAMS
PD_CHECK_SIZE(PairSearchParams, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, n, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, part, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, position, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, radius, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, id, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, ghost, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, cell_start, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, grid, PAIR_SEARCH_PARAMS);
PD_CHECK_OFFSET(PairSearchParams, skin, PAIR_SEARCH_PARAMS);
#endif

// The arguments of `wall_candidates` (contact.cu; layout.rs `WallCandidatesParams`): null
// `offset` and `items` count, else list.
struct WallCandidatesParams {
    int n;
    int n_walls;
    ParticleView p;
    const WallInfo* walls;
    const WallState* states;
    const double* triangles;
    const unsigned int* cell_start;
    const unsigned int* cell_items;
    double skin;
    unsigned int* counts;
    const unsigned int* offset;
    uint2* items;
};
#ifdef PD_SIZEOF_WALL_CANDIDATES_PARAMS
PD_CHECK_SIZE(WallCandidatesParams, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, n, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, n_walls, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, p, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, walls, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, states, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, triangles, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, cell_start, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, cell_items, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, skin, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, counts, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, offset, WALL_CANDIDATES_PARAMS);
PD_CHECK_OFFSET(WallCandidatesParams, items, WALL_CANDIDATES_PARAMS);
#endif

// The arguments of `wall_facet_overlaps` (contact.cu; layout.rs `WallOverlapsParams`).
struct WallOverlapsParams {
    int n_items;
    int n_walls;
    const uint2* items;
    ParticleView p;
    const WallState* states;
    const double* triangles;
    const double* prisms;
    double* overlaps;
    unsigned int* error;
};
#ifdef PD_SIZEOF_WALL_OVERLAPS_PARAMS
PD_CHECK_SIZE(WallOverlapsParams, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, n_items, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, n_walls, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, items, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, p, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, states, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, triangles, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, prisms, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, overlaps, WALL_OVERLAPS_PARAMS);
PD_CHECK_OFFSET(WallOverlapsParams, error, WALL_OVERLAPS_PARAMS);
#endif

// The arguments of `wall_contacts` (contact.cu; layout.rs `WallContactsParams`).
struct WallContactsParams {
    int n;
    int n_walls;
    int n_materials;
    int pad;
    ParticleView p;
    const WallState* states;
    const WallInfo* walls;
    const unsigned int* item_offset;
    const uint2* items;
    const double* overlaps;
    const PairMaterial* materials;
    const double* spring_in;
    double* spring_out;
    double* wall_force;
    double* wall_torque;
    double* wall_energy;
    double* per_wall_force;
    unsigned int* wall_contact;
    double dt;
    double max_overlap;
    unsigned int* error;
};
#ifdef PD_SIZEOF_WALL_CONTACTS_PARAMS
PD_CHECK_SIZE(WallContactsParams, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, n, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, n_walls, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, n_materials, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, pad, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, p, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, states, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, walls, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, item_offset, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, items, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, overlaps, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, materials, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, spring_in, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, spring_out, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, wall_force, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, wall_torque, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, wall_energy, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, per_wall_force, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, wall_contact, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, dt, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, max_overlap, WALL_CONTACTS_PARAMS);
PD_CHECK_OFFSET(WallContactsParams, error, WALL_CONTACTS_PARAMS);
#endif

// The template table of the probe kernels (probe.cu; layout.rs `ProbeTemplates`).
struct ProbeTemplates {
    const double* vertices;
    const double* normals;
    const double* offsets;
    const int* counts;
    const double* radius;
    const unsigned short* face_start; // max_faces + 1 per template
    const double* face_points;        // 3 max_face_indices per template
    int max_vertices;
    int max_faces;
    int max_face_indices;
};
#ifdef PD_SIZEOF_PROBE_TEMPLATES
PD_CHECK_SIZE(ProbeTemplates, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, vertices, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, normals, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, offsets, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, counts, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, radius, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, face_start, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, face_points, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, max_vertices, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, max_faces, PROBE_TEMPLATES);
PD_CHECK_OFFSET(ProbeTemplates, max_face_indices, PROBE_TEMPLATES);
#endif

#endif // __CUDACC_RTC__ || __CUDACC__

} // namespace pd
