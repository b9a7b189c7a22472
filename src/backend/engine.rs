//! One handle on a simulation stepped by either backend, for the driver, the benchmark and the
//! tests that hold the backends to the same results.

use super::cuda::CudaSimulation;
use super::{Backend, Device};
use crate::domain::Comm;
use crate::pipeline::Simulation;
use crate::run_state::RunState;
use crate::scene::Scene;
use anyhow::Result;
use std::sync::Arc;

/// What an [`Engine`] starts from.
pub enum Start {
    /// A simulation whose forces are evaluated (new or refreshed) or restored from a
    /// checkpoint: the backend continues from its stored forces.
    State(Box<Simulation>),
    /// A new run of `scene` on `comm`'s ranks: particles of count insertions placed, the first
    /// forces evaluated by the backend that steps it (on the GPU by the GPU, so that a GPU run
    /// is bitwise the same from its first step).
    Scene {
        scene: Box<Scene>,
        comm: Arc<dyn Comm>,
    },
}

impl From<Simulation> for Start {
    fn from(sim: Simulation) -> Self {
        Start::State(Box::new(sim))
    }
}

/// A simulation on the backend of its [`Device`]: the only way to make a backend.
pub struct Engine {
    backend: Box<dyn Backend>,
    device: Device,
}

impl Engine {
    /// Starts `start` on `device`.
    pub fn new(start: impl Into<Start>, device: Device) -> Result<Self> {
        let start = start.into();
        let backend: Box<dyn Backend> = match (start, device) {
            (Start::State(mut sim), Device::Cpu | Device::CpuMixed) => {
                sim.set_pair_precision(device.pair_precision());
                sim
            }
            (Start::Scene { scene, comm }, Device::Cpu | Device::CpuMixed) => Box::new(
                Simulation::builder(*scene)
                    .comm(comm)
                    .pair_precision(device.pair_precision())
                    .build()?,
            ),
            (Start::State(sim), Device::Cuda { ordinal, precision }) => {
                Box::new(CudaSimulation::new(sim.into_state(), ordinal, precision)?)
            }
            (Start::Scene { scene, comm }, Device::Cuda { ordinal, precision }) => Box::new(
                CudaSimulation::from_scene(*scene, comm, ordinal, precision)?,
            ),
        };
        if let Device::Cuda { precision, .. } = device {
            tracing::info!(
                "kernels compiled for {} ({precision:?} pair geometry)",
                backend.describe()
            );
        }
        Ok(Engine { backend, device })
    }

    /// Where it steps.
    pub fn device(&self) -> Device {
        self.device
    }

    /// Advances one time step.
    pub fn step(&mut self) -> Result<()> {
        self.backend.step()
    }

    /// See [`Backend::state`].
    pub fn state(&self) -> &RunState {
        self.backend.state()
    }

    /// See [`Backend::particle_count`].
    pub fn particle_count(&self) -> usize {
        self.backend.particle_count()
    }

    /// See [`Backend::state_mut`].
    pub fn state_mut(&mut self) -> &mut RunState {
        self.backend.state_mut()
    }

    /// The host state with the backend's state copied in.
    pub fn synced(&mut self) -> Result<&RunState> {
        self.backend.sync()
    }

    /// See [`Backend::refresh`].
    pub fn refresh(&mut self) -> Result<()> {
        self.backend.refresh()
    }

    /// See [`Backend::edit`].
    pub fn edit(&mut self, f: impl FnOnce(&mut RunState)) -> Result<()> {
        let mut f = Some(f);
        self.backend.edit(&mut |sim| {
            if let Some(f) = f.take() {
                f(sim)
            }
        })
    }

    /// Particle–particle and particle–wall contacts of the last force evaluation; on the GPU
    /// this copies only the contact flags.
    pub fn contact_counts(&mut self) -> Result<(u64, u64)> {
        self.backend.contact_counts()
    }

    /// See [`Backend::cuda_mut`].
    pub fn cuda_mut(&mut self) -> Option<&mut CudaSimulation> {
        self.backend.cuda_mut()
    }

    /// See [`Backend::device_bytes`].
    pub fn device_bytes(&self) -> Option<usize> {
        self.backend.device_bytes()
    }

    /// See [`Backend::wall_candidates`].
    pub fn wall_candidates(&mut self) -> Result<(u64, u64)> {
        self.backend.wall_candidates()
    }

    /// See [`Backend::candidate_pairs`].
    pub fn candidate_pairs(&self) -> Option<usize> {
        self.backend.candidate_pairs()
    }

    /// See [`Backend::describe`].
    pub fn describe(&self) -> String {
        self.backend.describe()
    }

    /// See [`Backend::neighbor_report`].
    pub fn neighbor_report(&self) -> crate::neighbor::NeighborReport {
        self.backend.neighbor_report()
    }

    /// "cpu" or "cuda".
    pub fn backend_name(&self) -> &'static str {
        self.backend.name()
    }
}
