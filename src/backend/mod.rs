//! Compute backends: one [`Backend`] trait, its CPU ([`cpu`]) and CUDA ([`cuda`])
//! implementations side by side, and the [`Engine`] that is the only way to make one.
//!
//! A backend steps a run's [`RunState`]: the CPU backend is the [`Simulation`](crate::pipeline::Simulation) of
//! [`crate::pipeline`] (rayon), the CUDA backend keeps the particle state on the GPU and a host
//! copy that it syncs on demand (docs/design.md §5). The choice is made once, from the command line's [`BackendChoice`]
//! to the [`Device`] it resolves to ([`select_device`]); nothing downstream compares names.

pub mod cpu;
pub mod cuda;
mod detect;
mod engine;

pub use detect::{CudaInfo, GpuInfo, cuda_info};
pub use engine::{Engine, Start};

use crate::domain::Comm;
use crate::neighbor::NeighborReport;
use crate::run_state::RunState;
use anyhow::{Result, bail};
use cuda::Precision;

/// What steps a simulation: the operations the driver, the benchmark and the tests need of
/// either backend. Every method leaves the simulation steppable; errors of the step that
/// the run reports as a stability stop keep their type ([`crate::pipeline::SimulationError`]).
pub trait Backend {
    /// Advances one time step (the stages of docs/design.md §1).
    fn step(&mut self) -> Result<()>;

    /// The host state: time, step, dt and scene are always current; the particles, contact
    /// history and statistics only after [`Backend::sync`] (the count:
    /// [`Backend::particle_count`]).
    fn state(&self) -> &RunState;

    /// Particles this rank owns now, without a sync (a GPU rank's rebuilds on the device move
    /// particles between ranks without updating the host's copy).
    fn particle_count(&self) -> usize {
        self.state().particles.len()
    }

    /// The host state for its bookkeeping (timers, counters), which the backend does not hold
    /// elsewhere; its particle state may be stale (see [`Backend::state`]).
    fn state_mut(&mut self) -> &mut RunState;

    /// The host state with the backend's state copied in.
    fn sync(&mut self) -> Result<&RunState>;

    /// Changes the state between steps (a prescribed motion, say): the state is made current
    /// on the host, changed there by `f` and taken back with its contact history; the next
    /// step rebuilds the pair list. The forces stay those of the last evaluation (see
    /// [`Backend::refresh`]).
    fn edit(&mut self, f: &mut dyn FnMut(&mut RunState)) -> Result<()>;

    /// Evaluates the forces again at the current state without advancing the contact
    /// history (as [`Simulation::refresh`](crate::pipeline::Simulation::refresh) does), after an [`Backend::edit`] that moved the
    /// particles or the domain so far that the stored forces no longer fit them (a rescaled
    /// periodic box).
    fn refresh(&mut self) -> Result<()>;

    /// Particle–particle and particle–wall contacts of the last force evaluation.
    fn contact_counts(&mut self) -> Result<(u64, u64)>;

    /// Bytes of device memory held for the simulation's buffers (`None` on the CPU, whose
    /// memory is the host's).
    fn device_bytes(&self) -> Option<usize>;

    /// Candidate pairs of the current neighbour list, where the backend counts them apart
    /// from the host (`None`: see the host's list).
    fn candidate_pairs(&self) -> Option<usize>;

    /// Wall facets the wall stage evaluates: (particle–facet items, particles with at least
    /// one). The CPU counts the facets within each particle's bounding radius, which it clips
    /// every step; the GPU its wall list, built with the skin added to the reach.
    fn wall_candidates(&mut self) -> Result<(u64, u64)>;

    /// Who built the pair lists so far (`[simulation.neighbor] mode`, docs/design.md §7).
    fn neighbor_report(&self) -> NeighborReport;

    /// What it runs on, for logs and reports ("CPU, 16 threads", the GPU's name).
    fn describe(&self) -> String;

    /// The backend's name in summaries: "cpu" or "cuda".
    fn name(&self) -> &'static str;

    /// The CUDA simulation behind this backend, for what only the GPU has (its list and build
    /// counters, the hybrid builder's test switches); `None` on the CPU.
    fn cuda_mut(&mut self) -> Option<&mut cuda::CudaSimulation> {
        None
    }
}

/// Which backend a run asks for (`--backend`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    /// CUDA when a usable GPU is present, else the CPU.
    Auto,
    /// The CPU (rayon).
    Cpu,
    /// CUDA.
    Cuda,
}

/// Where an [`Engine`] steps: a [`BackendChoice`] resolved on this machine and rank.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Device {
    /// The CPU backend (rayon).
    Cpu,
    /// The CPU backend with the polyhedral pair geometry in the GPU's mixed precision
    /// ([`crate::geometry::pair::overlap_pair_mixed`], the same decisions pair by pair):
    /// `--backend cpu --gpu-precision mixed`, to reproduce or check a mixed-precision GPU run
    /// without a GPU.
    CpuMixed,
    /// GPU `ordinal`, with the pair geometry in `precision`.
    Cuda {
        ordinal: usize,
        precision: Precision,
    },
}

impl Device {
    /// The arithmetic of the polyhedral pair geometry on this device.
    pub fn pair_precision(&self) -> Precision {
        match self {
            Device::Cpu => Precision::Double,
            Device::CpuMixed => Precision::Mixed,
            Device::Cuda { precision, .. } => *precision,
        }
    }

    /// The arithmetic of the pair geometry as summaries name it: "double" on the CPU.
    pub fn precision_name(&self) -> String {
        format!("{:?}", self.pair_precision()).to_lowercase()
    }
}

/// Resolves `choice` for this rank of `comm` (docs/design.md §5): `cuda` needs a usable GPU and
/// NVRTC, `auto` takes the GPU when there is one and says in the log why it does not. `cpu`
/// with `precision` mixed is [`Device::CpuMixed`]; `auto` without a GPU is the CPU in f64
/// whatever `precision` says, the fastest there. Every
/// rank of a decomposed run steps on the same backend (their collectives differ): with `auto`,
/// one rank without a usable GPU puts all on the CPU (an explicit `cuda` has already failed on
/// that rank, which ends the run on all). A GPU rank drives its node-local rank modulo the
/// GPUs it sees (docs/design.md §6).
pub fn select_device(
    choice: BackendChoice,
    precision: Precision,
    comm: &dyn Comm,
) -> Result<Device> {
    let info = cuda_info();
    let gpu = match (choice, &info.unavailable, info.gpus.first()) {
        (BackendChoice::Cpu, _, _) => false,
        (_, None, Some(g)) => {
            tracing::info!("running on GPU 0: {}", g.name);
            true
        }
        (BackendChoice::Cuda, Some(why), _) => bail!("--backend cuda: {why}; use --backend cpu"),
        (BackendChoice::Cuda, None, None) => {
            bail!("--backend cuda: no GPU found; use --backend cpu")
        }
        (BackendChoice::Auto, Some(why), _) => {
            tracing::info!("running on the CPU: {why}");
            false
        }
        (BackendChoice::Auto, None, None) => {
            tracing::info!("running on the CPU");
            false
        }
    };
    let cpu = if choice == BackendChoice::Cpu && precision == Precision::Mixed {
        tracing::info!(
            "the polyhedral pair geometry in the GPU's mixed precision (--gpu-precision mixed)"
        );
        Device::CpuMixed
    } else {
        Device::Cpu
    };
    if comm.size() == 1 {
        return Ok(if gpu {
            Device::Cuda {
                ordinal: 0,
                precision,
            }
        } else {
            cpu
        });
    }
    let cpu_somewhere = comm.any(!gpu);
    if cpu_somewhere && gpu {
        tracing::warn!("another rank has no usable GPU: all ranks run on the CPU");
    }
    if cpu_somewhere {
        return Ok(cpu);
    }
    let gpus = info.gpus.len().max(1);
    let local = crate::domain::comm::node_local_rank().unwrap_or(comm.rank());
    let ordinal = local % gpus;
    tracing::info!(
        "{} ranks on the GPU: rank {} on GPU {ordinal} of {gpus}",
        comm.size(),
        comm.rank()
    );
    Ok(Device::Cuda { ordinal, precision })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::SerialComm;

    /// `--backend cpu` runs the GPU's mixed precision only when asked; `auto` on a machine
    /// without a GPU is the CPU in f64 whatever the precision (the fastest there).
    #[test]
    fn the_cpu_runs_mixed_precision_only_when_asked() {
        let cpu = |p| select_device(BackendChoice::Cpu, p, &SerialComm).unwrap();
        assert_eq!(cpu(Precision::Double), Device::Cpu);
        assert_eq!(cpu(Precision::Mixed), Device::CpuMixed);
        assert_eq!(Device::CpuMixed.pair_precision(), Precision::Mixed);
        assert_eq!(Device::CpuMixed.precision_name(), "mixed");
        if cuda_info().unavailable.is_some() {
            let auto = select_device(BackendChoice::Auto, Precision::Mixed, &SerialComm).unwrap();
            assert_eq!(auto, Device::Cpu);
        }
    }
}
