//! polydem: the discrete element method for convex polyhedral particles (and spheres, as a
//! fast path), on the CPU, on a GPU and on many MPI ranks.
//!
//! The crate is laid out by concept, one top-level module each; `docs/design.md` is the map
//! (the step, the layout, the CPU/GPU twin rule, the contact history), drawn from the code.
//!
//! # The step
//!
//! [`pipeline::Simulation::step`] names every stage in order, and the GPU's
//! [`backend::cuda::CudaSimulation`] runs the same stages as kernels (`cuda/`):
//!
//! | # | stage | CPU | GPU |
//! |---|---|---|---|
//! | 9a | half kick, drift, rotation | `pipeline/integration.rs`, [`integrate`] | `integrate.cu` |
//! | 1 | exchange: insertion, removal, wrap; migration and halo | `run_state/exchange.rs`, [`domain`] | wrap in `integrate.cu`; ghost motion and migration by `halo.cu` on the device; insertion and removal through the host |
//! | 2 | neighbour list (bins, 1D pair list, Verlet skin) | `pipeline/neighbors.rs`, [`neighbor`] | `neighbor.cu`, `scan.cu` |
//! | 3–5 | broad phase, narrow phase, overlap volume | `pipeline/pairs.rs`, [`geometry`] | `contact.cu` |
//! | 6 | walls: facet clipping | `pipeline/walls.rs`, [`contact::WallMesh`] | `contact.cu` |
//! | 7 | contact law | [`contact`] | `contact_law.cuh` |
//! | 8 | deterministic reduction | `pipeline/reduction.rs` | `integrate.cu` |
//! | 9b | second half kick | `pipeline/integration.rs` | `integrate.cu` |
//! | 10 | output, checkpoints | [`run`], [`io`] | host copy synced on demand |
//!
//! # Modules
//!
//! - [`run_state`]: the [`run_state::RunState`] both backends step (scene, particles, contact
//!   history, walls, clock, inserter, statistics, a decomposed run's part), its stability
//!   guard and the host part of stage 1.
//! - [`pipeline`]: the [`pipeline::Simulation`] (a run state and the CPU's workspace), its
//!   builder and its step (the CPU backend's stages).
//! - [`backend`]: the [`backend::Backend`] trait, [`backend::Engine`] (the only way to make
//!   one) and device selection; the CPU ([`backend::cpu`]) and CUDA ([`backend::cuda`])
//!   implementations.
//! - [`domain`]: MPI domain decomposition: subdomains, exchange, halo, migration, load
//!   balance, and the [`domain::Comm`] trait.
//! - [`run`]: the driver of `polydem run`, `check`, `bench` and `pack`: start or restore,
//!   outputs, the step loop, the summary.
//! - [`scene`]: scene files: schema, validation, insertion, walls, the restart fingerprint.
//! - [`shape`]: particle templates: convex hulls, merged faces, mass properties, generators,
//!   STL/OBJ import.
//! - [`geometry`]: exact contact geometry: GJK, the interior point, the overlap volume by
//!   dual-space Quickhull or vertex enumeration, facet clipping, spheres, portable math.
//! - [`contact`]: the contact law, restitution, contact history, wall meshes.
//! - [`neighbor`]: bins and the 1D candidate pair list.
//! - [`integrate`]: velocity Verlet and the rotation splitting.
//! - [`state`]: the particles (structure of arrays) and per-step observables.
//! - [`stability`]: the stability guard's bounds.
//! - [`io`]: VTU/PVTU/PVD frames, CSV series, checkpoints, packings, atomic writes.
//! - [`probe`]: the contact-geometry probe (`polydem probe`).
//! - [`accuracy`]: `polydem bench accuracy`, restitution and energy against run time.
//! - [`analysis`]: observables of a saved state (`polydem analyze`): fill height, porosity.
//! - [`interrupt`]: SIGINT and SIGTERM stop a run after a step, with a checkpoint.
//! - [`tuning`]: the `POLYDEM_*` environment knobs, read once and logged.
//! - [`par`]: grain sizes of the CPU backend's rayon loops (small scenes stay on one thread).
//! - [`rng`]: the insertion's portable, checkpointed random numbers.

// The library never writes to stdout: the CLI's JSON output goes there (clippy.toml lets
// `#[cfg(test)]` code print what it measured).
#![warn(clippy::print_stdout)]

pub mod accuracy;
pub mod analysis;
pub mod backend;
pub mod contact;
pub mod domain;
pub mod exact_sum;
pub mod geometry;
pub mod input;
pub mod integrate;
pub mod interrupt;
pub mod io;
pub mod neighbor;
pub mod par;
pub mod pipeline;
pub mod probe;
pub mod rng;
pub mod run;
pub mod run_state;
pub mod scene;
pub mod shape;
pub mod stability;
pub mod state;
pub mod tuning;

/// The arithmetic of the pair geometry a run takes (`--gpu-precision`), one type for the crate.
pub use geometry::pair::Precision;
