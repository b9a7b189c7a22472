//! Stage 2: the neighbour list, rebuilt when some particle moved half the skin (in a decomposed
//! run, when any rank needs it, as decided in the exchange), with the ghosts binned after the
//! owned particles.

use super::Simulation;
use nalgebra::Vector3;
use std::time::Instant;

impl Simulation {
    /// Appends the ghosts (in a decomposed run) to the particle arrays and radii after the
    /// owned particles, for the pair stages; returns how many particles are owned. The pair
    /// stage drops them again ([`Simulation::pair_stage`]).
    pub(super) fn join_ghosts(&mut self) -> usize {
        let owned = self.particles.len();
        if let Some(par) = self.parallel.as_deref() {
            self.particles.extend_from(&par.ghosts.particles);
            let types = &self.scene.particle_types;
            let templates = &self.scene.templates;
            let g = &par.ghosts.particles;
            self.radius.extend((0..g.len()).map(|i| {
                templates[types[g.kind[i] as usize].template].circumscribed_radius * g.scale[i]
            }));
        }
        owned
    }

    /// Stage 2: rebuilds the candidate pair list if needed (clearing the separating axes of
    /// the previous list), with the first `owned` particles owned and the rest ghosts.
    pub(super) fn neighbor_list(&mut self, owned: usize) {
        let t0 = Instant::now();
        let skin = self.scene.simulation.neighbor.skin;
        let rebuild = match self.parallel {
            // Decided by all ranks together in the exchange.
            Some(_) => self.dirty,
            None => {
                self.dirty
                    || self
                        .pairs
                        .needs_rebuild(&self.particles.position, &self.bounds)
            }
        };
        if rebuild {
            match self.parallel.as_deref() {
                Some(par) => {
                    let mut bins = self.particles.position[..owned].to_vec();
                    bins.extend(par.ghost_bins());
                    self.pairs.build_in(
                        &self.particles.position,
                        &bins,
                        &self.radius,
                        &self.particles.id,
                        owned,
                        &self.bounds,
                        &par.search_region(),
                        skin,
                    );
                }
                None => self.pairs.build(
                    &self.particles.position,
                    &self.radius,
                    &self.particles.id,
                    &self.bounds,
                    skin,
                ),
            }
            self.separating_axes = vec![Vector3::zeros(); self.pairs.pairs.len()];
            self.dirty = false;
        }
        self.timers.neighbor += t0.elapsed().as_secs_f64();
    }
}
