//! The CUDA backend: host side (cudarc). Kernels live in `cuda/` and are compiled at run time by
//! NVRTC ([`kernels`]); the structs they share with Rust are in [`layout`].
//!
//! [`CudaSimulation`] is composed of one part per expensive stage, each owning its device
//! buffers (as HOOMD-blue pairs a GPU class with each expensive CPU class): the particle arrays
//! (`particles`, declared by one field table), the pair list (`pairs`, evaluated in
//! `pair_contacts`), the walls (`walls`), a decomposed run's halo (`halo`) and the time
//! integration (`integrator`), over what they all share (`gpu`: context, streams, the kernels
//! of `launch`, the scene's constants). `forces` runs stages 2–8 in order, `upload` and `sync`
//! move the state between host and device, and `history` converts the contact history between
//! the device's slots and the host's keys.

mod backend;
mod error;
mod exchange;
mod forces;
mod gpu;
mod halo;
mod history;
mod integrator;
pub mod kernels;
mod launch;
pub mod layout;
mod list_builder;
mod pair_contacts;
mod pair_list;
mod pairs;
mod particles;
pub mod probe;
mod rebuild_records;
pub mod simulation;
mod sync;
mod upload;
mod walls;

pub use error::{CudaError, HaloError};
pub use kernels::{CompileError, KernelConfig, Precision};
pub use simulation::CudaSimulation;
