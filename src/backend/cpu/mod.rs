//! The CPU backend: the [`Simulation`] of [`crate::pipeline`] steps itself on rayon's threads,
//! so its host copy is always current.

use super::Backend;
use crate::neighbor::{Builder, NeighborReport};
use crate::pipeline::Simulation;
use anyhow::Result;

impl Backend for Simulation {
    fn step(&mut self) -> Result<()> {
        // A simulation error keeps its type, so that the run can tell a stability stop.
        Simulation::step(self).map_err(anyhow::Error::new)
    }

    fn host(&self) -> &Simulation {
        self
    }

    fn host_mut(&mut self) -> &mut Simulation {
        self
    }

    fn sync(&mut self) -> Result<&Simulation> {
        Ok(self)
    }

    fn edit(&mut self, f: &mut dyn FnMut(&mut Simulation)) -> Result<()> {
        f(self);
        Ok(())
    }

    fn contact_counts(&mut self) -> Result<(u64, u64)> {
        Ok((self.stats.contacts, self.stats.wall_contacts))
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
            mode: self.scene.simulation.neighbor.mode.name().into(),
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
