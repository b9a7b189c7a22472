//! The CPU backend: the [`Simulation`] of [`crate::pipeline`] steps its [`RunState`] on
//! rayon's threads, so the host state is always current.

use super::Backend;
use crate::neighbor::{Builder, NeighborReport};
use crate::pipeline::Simulation;
use crate::run_state::RunState;
use anyhow::Result;

impl Backend for Simulation {
    fn step(&mut self) -> Result<()> {
        // A simulation error keeps its type, so that the run can tell a stability stop.
        Simulation::step(self).map_err(anyhow::Error::new)
    }

    fn state(&self) -> &RunState {
        &self.state
    }

    fn state_mut(&mut self) -> &mut RunState {
        &mut self.state
    }

    fn sync(&mut self) -> Result<&RunState> {
        Ok(&self.state)
    }

    fn edit(&mut self, f: &mut dyn FnMut(&mut RunState)) -> Result<()> {
        f(&mut self.state);
        Ok(())
    }

    fn refresh(&mut self) -> Result<()> {
        Simulation::refresh(self).map_err(anyhow::Error::new)
    }

    fn contact_counts(&mut self) -> Result<(u64, u64)> {
        Ok((self.state.stats.contacts, self.state.stats.wall_contacts))
    }

    fn device_bytes(&self) -> Option<usize> {
        None
    }

    fn candidate_pairs(&self) -> Option<usize> {
        None
    }

    fn wall_candidates(&mut self) -> Result<(u64, u64)> {
        Ok(Simulation::wall_candidates(self))
    }

    fn neighbor_report(&self) -> NeighborReport {
        // The CPU backend builds every list itself, whatever the mode asks of a GPU run.
        NeighborReport {
            mode: self.state.scene.simulation.neighbor.mode.name().into(),
            builder: Builder::Cpu.name().into(),
            host_builds: self.pair_list_builds(),
            ..NeighborReport::default()
        }
    }

    fn describe(&self) -> String {
        format!("CPU, {} threads", rayon::current_num_threads())
    }

    fn name(&self) -> &'static str {
        "cpu"
    }
}
