//! The errors of the CUDA backend, each saying what failed.

use super::kernels::CompileError;
use crate::pipeline::SimulationError;

/// Errors of the CUDA backend.
#[derive(Debug, thiserror::Error)]
pub enum CudaError {
    /// The driver reported an error. Its message is part of this one, so it is not also
    /// chained as a source (an error report would print it twice).
    #[error("CUDA driver: {0}")]
    Driver(cudarc::driver::DriverError),
    /// A kernel file did not compile (or its source could not be assembled).
    #[error(transparent)]
    Compile(#[from] CompileError),
    /// A constant or global table of a kernel module is missing or smaller than the host's data.
    #[error("the kernels' table {name} holds fewer than the {expected} values the host has")]
    Symbol { name: &'static str, expected: usize },
    /// A template exceeds the capacities the geometry probe was compiled for.
    #[error(
        "template {template} has {vertices} vertices and {faces} faces; the probe was built for \
         at most {max_vertices} and {max_faces}"
    )]
    ProbeCapacity {
        template: String,
        vertices: usize,
        faces: usize,
        max_vertices: usize,
        max_faces: usize,
    },
    #[error(transparent)]
    Simulation(#[from] SimulationError),
    #[error(transparent)]
    Halo(#[from] HaloError),
    /// The host build of a pair list could not run.
    #[error("the host's pair-list build: {0}")]
    Prebuild(String),
    /// A host-built pair list does not fit the device's particles (another count, or a
    /// decomposed run, whose lists the device builds).
    #[error(
        "a host-built pair list for {list} particles was offered to {device} (decomposed: {decomposed})"
    )]
    HostListMismatch {
        list: usize,
        device: usize,
        decomposed: bool,
    },
}

impl From<cudarc::driver::DriverError> for CudaError {
    fn from(e: cudarc::driver::DriverError) -> Self {
        CudaError::Driver(e)
    }
}

/// What went wrong in a decomposed run's device halo (`super::halo`).
#[derive(Debug, thiserror::Error)]
pub enum HaloError {
    /// A pair-list rebuild found no contact history from the host: a decomposed run's list is in
    /// two parts, no CSR by particle, so its history always comes up from the host.
    #[error("a decomposed run's pair list was rebuilt without the host's history")]
    MissingHistory,
    /// The neighbours sent motion for another number of ghosts than this rank expects.
    #[error(
        "halo refresh on rank {rank}: {values} motion values for {ghosts} ghosts (the \
         neighbours' plans changed between rebuilds)"
    )]
    MotionCount {
        rank: usize,
        values: usize,
        ghosts: usize,
    },
}
