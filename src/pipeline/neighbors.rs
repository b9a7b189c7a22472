//! Stage 2: the neighbour list, rebuilt when some particle moved half the skin (in a decomposed
//! run, when any rank needs it, as decided in the exchange), with the ghosts binned after the
//! owned particles.

use super::Simulation;
use crate::neighbor::Reach;
use nalgebra::Vector3;
use std::time::Instant;

impl Simulation {
    /// Appends the ghosts (in a decomposed run) to the particle arrays and radii after the
    /// owned particles, for the pair stages; returns how many particles are owned. The pair
    /// stage drops them again ([`Simulation::pair_stage`]).
    pub(super) fn join_ghosts(&mut self) -> usize {
        let owned = self.state.particles.len();
        if let Some(par) = self.state.parallel.as_deref() {
            self.state.particles.extend_from(&par.ghosts.particles);
            let types = &self.state.scene.particle_types;
            let templates = &self.state.scene.templates;
            let g = &par.ghosts.particles;
            self.work.radius.extend((0..g.len()).map(|i| {
                templates[types[g.kind[i] as usize].template].circumscribed_radius * g.scale[i]
            }));
        }
        owned
    }

    /// Stage 2: rebuilds the candidate pair list if needed (clearing the separating axes of
    /// the previous list), with the first `owned` particles owned and the rest ghosts.
    pub(super) fn neighbor_list(&mut self, owned: usize) {
        let t0 = Instant::now();
        let skin = self.state.scene.simulation.neighbor.skin;
        let reach = Reach {
            skin,
            cutoff: self.state.scene.cutoff(),
        };
        let rebuild = match self.state.parallel {
            // Decided by all ranks together in the exchange.
            Some(_) => self.work.dirty,
            None => {
                self.work.dirty
                    || self
                        .work
                        .pairs
                        .needs_rebuild(&self.state.particles.position, &self.state.bounds)
            }
        };
        if rebuild {
            match self.state.parallel.as_deref() {
                Some(par) => {
                    let mut bins = self.state.particles.position[..owned].to_vec();
                    bins.extend(par.ghost_bins());
                    self.work.pairs.build_in(
                        &self.state.particles.position,
                        &bins,
                        &self.work.radius,
                        &self.state.particles.id,
                        owned,
                        &self.state.bounds,
                        &par.search_region(),
                        reach,
                    );
                }
                None => self.work.pairs.build(
                    &self.state.particles.position,
                    &self.work.radius,
                    &self.state.particles.id,
                    &self.state.bounds,
                    reach,
                ),
            }
            self.work.separating_axes = vec![Vector3::zeros(); self.work.pairs.pairs.len()];
            self.work.dirty = false;
        }
        self.state.timers.neighbor += t0.elapsed().as_secs_f64();
    }
}
