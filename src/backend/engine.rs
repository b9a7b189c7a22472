//! One handle on a simulation stepped by either backend, for the driver, the benchmark and the
//! tests that hold the backends to the same results: the CPU [`Simulation`] or the GPU
//! [`CudaSimulation`] with its host copy synced on demand.

use super::cuda::{CudaSimulation, Precision};
use crate::pipeline::Simulation;
use anyhow::{Result, anyhow};

/// Where an [`Engine`] steps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Device {
    /// The CPU backend (rayon).
    Cpu,
    /// GPU `ordinal`, with the pair geometry in `precision`.
    Cuda {
        ordinal: usize,
        precision: Precision,
    },
}

/// A simulation on the CPU, or on the GPU with a host copy synced for output.
pub enum Engine {
    Cpu(Box<Simulation>),
    Cuda(Box<CudaSimulation>),
}

impl Engine {
    /// Moves `sim` (created with [`Simulation::new`], or refreshed or restored: its forces are
    /// evaluated) onto `device`.
    pub fn new(sim: Simulation, device: Device) -> Result<Self> {
        Ok(match device {
            Device::Cpu => Engine::Cpu(Box::new(sim)),
            Device::Cuda { ordinal, precision } => Engine::Cuda(Box::new(
                CudaSimulation::new(sim, ordinal, precision).map_err(|e| anyhow!("{e}"))?,
            )),
        })
    }

    /// Advances one time step.
    pub fn step(&mut self) -> Result<()> {
        match self {
            // A simulation error keeps its type, so that the run can tell a stability stop.
            Engine::Cpu(s) => s.step().map_err(anyhow::Error::new),
            Engine::Cuda(c) => c.step().map_err(|e| match e {
                super::cuda::CudaError::Simulation(s) => anyhow::Error::new(s),
                other => anyhow!("{other}"),
            }),
        }
    }

    /// The host simulation: time, step, dt, scene and particle count are always current; the
    /// particle state and statistics only after [`Engine::synced`].
    pub fn host(&self) -> &Simulation {
        match self {
            Engine::Cpu(s) => s,
            Engine::Cuda(c) => &c.host,
        }
    }

    /// The host simulation with the device state copied in.
    pub fn synced(&mut self) -> Result<&Simulation> {
        match self {
            Engine::Cpu(s) => Ok(s),
            Engine::Cuda(c) => c.sync_host().map_err(|e| anyhow!("{e}")),
        }
    }

    /// Changes the state between steps (a prescribed motion, say): on the GPU the state is
    /// copied to the host, changed there and uploaded with its contact history, and the next
    /// step rebuilds the pair list.
    pub fn edit(&mut self, f: impl FnOnce(&mut Simulation)) -> Result<()> {
        match self {
            Engine::Cpu(s) => {
                f(s);
                Ok(())
            }
            Engine::Cuda(c) => c.edit_host(f).map_err(|e| anyhow!("{e}")),
        }
    }

    /// Particle–particle and particle–wall contacts of the last force evaluation; on the GPU
    /// this copies only the contact flags.
    pub fn contact_counts(&mut self) -> Result<(u64, u64)> {
        match self {
            Engine::Cpu(s) => Ok((s.stats.contacts, s.stats.wall_contacts)),
            Engine::Cuda(c) => c.contact_counts().map_err(|e| anyhow!("{e}")),
        }
    }

    /// "cpu" or "cuda".
    pub fn backend_name(&self) -> &'static str {
        match self {
            Engine::Cpu(_) => "cpu",
            Engine::Cuda(_) => "cuda",
        }
    }
}
