//! The CUDA backend: host side (cudarc). Kernels live in `cuda/` and are compiled at run time by
//! NVRTC ([`kernels`]); the structs they share with Rust are in [`layout`].

mod backend;
mod contacts;
mod halo;
pub mod kernels;
pub mod layout;
mod pairs;
pub mod probe;
pub mod simulation;
mod sync;
mod upload;

pub use kernels::{KernelConfig, Precision};
pub use simulation::{CudaError, CudaSimulation};
