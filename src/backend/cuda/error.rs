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
    /// A buffer of the step did not fit in the GPU's memory: the driver's out-of-memory,
    /// named by what was being allocated (`CudaError::out_of_memory`).
    #[error(
        "{what} need {}, and the GPU has {} free of {}; run fewer particles per GPU \
         (more ranks), a smaller skin, or the CPU backend",
        needed(need),
        gib(*free),
        gib(*total)
    )]
    DeviceMemory {
        what: String,
        need: Option<usize>,
        free: usize,
        total: usize,
    },
    #[error(transparent)]
    Simulation(#[from] SimulationError),
    #[error(transparent)]
    Halo(#[from] HaloError),
    /// The thread of a host build of the pair list could not be started.
    #[error("the host's pair-list build could not start its thread")]
    PrebuildThread(#[source] std::io::Error),
    /// The thread of a host build of the pair list panicked.
    #[error("the host's pair-list build panicked")]
    PrebuildPanicked,
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

/// Bytes as GiB with two decimals, for the memory errors.
fn gib(bytes: usize) -> String {
    format!("{:.2} GiB", bytes as f64 / (1u64 << 30) as f64)
}

/// What a [`CudaError::DeviceMemory`] says was needed: the bytes when they are known before
/// the allocation (a list whose pairs are counted), else nothing.
fn needed(need: &Option<usize>) -> String {
    need.map_or_else(
        || "more GPU memory than is free".to_string(),
        |b| format!("{} of GPU memory", gib(b)),
    )
}

impl CudaError {
    /// This error, or, when it is the driver's out-of-memory, a [`CudaError::DeviceMemory`]
    /// naming `what` failed to fit, the bytes it needed (`need`, when known) and the device's
    /// free and total memory now. Other errors pass through unchanged.
    pub(super) fn out_of_memory(self, what: impl FnOnce() -> String, need: Option<usize>) -> Self {
        match self {
            CudaError::Driver(e)
                if e.0 == cudarc::driver::sys::cudaError_enum::CUDA_ERROR_OUT_OF_MEMORY =>
            {
                let (free, total) = cudarc::driver::result::mem_get_info().unwrap_or((0, 0));
                CudaError::DeviceMemory {
                    what: what(),
                    need,
                    free,
                    total,
                }
            }
            other => other,
        }
    }
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
