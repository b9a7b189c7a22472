//! [`CudaSimulation`] as a [`Backend`].

use super::{CudaError, CudaSimulation};
use crate::backend::Backend;
use crate::neighbor::NeighborReport;
use crate::run_state::RunState;
use anyhow::Result;

/// A simulation error keeps its own type (not wrapped in [`CudaError`]), so that the run can
/// tell a stability stop from a failure of the device.
fn unwrapped(e: CudaError) -> anyhow::Error {
    match e {
        CudaError::Simulation(s) => anyhow::Error::new(s),
        other => anyhow::Error::new(other),
    }
}

impl Backend for CudaSimulation {
    fn step(&mut self) -> Result<()> {
        CudaSimulation::step(self).map_err(unwrapped)
    }

    fn state(&self) -> &RunState {
        &self.state
    }

    fn particle_count(&self) -> usize {
        CudaSimulation::particle_count(self)
    }

    fn state_mut(&mut self) -> &mut RunState {
        &mut self.state
    }

    fn sync(&mut self) -> Result<&RunState> {
        self.sync_host().map_err(unwrapped)
    }

    fn edit(&mut self, f: &mut dyn FnMut(&mut RunState)) -> Result<()> {
        self.edit_host(f).map_err(unwrapped)
    }

    fn refresh(&mut self) -> Result<()> {
        CudaSimulation::refresh(self).map_err(unwrapped)
    }

    fn contact_counts(&mut self) -> Result<(u64, u64)> {
        CudaSimulation::contact_counts(self).map_err(unwrapped)
    }

    fn device_bytes(&self) -> Option<usize> {
        Some(CudaSimulation::device_bytes(self))
    }

    fn candidate_pairs(&self) -> Option<usize> {
        Some(CudaSimulation::candidate_pairs(self))
    }

    fn wall_candidates(&mut self) -> Result<(u64, u64)> {
        CudaSimulation::wall_candidates(self).map_err(unwrapped)
    }

    fn neighbor_report(&self) -> NeighborReport {
        CudaSimulation::neighbor_report(self)
    }

    fn describe(&self) -> String {
        self.device.clone()
    }

    fn name(&self) -> &'static str {
        "cuda"
    }

    fn cuda_mut(&mut self) -> Option<&mut CudaSimulation> {
        Some(self)
    }
}
