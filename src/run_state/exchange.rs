//! The host part of stage 1 on a run's state: insertion of due particles, removal of those that
//! left a closed domain, periodic wrapping, and in a decomposed run the decomposition's part
//! ([`crate::domain::Parallel::exchange`]): migration, balancing, the ghosts chosen, the walls
//! restricted to a redrawn box. The CPU pipeline runs it every step; the GPU backend on its host
//! copy when particles are inserted or leave, and for a decomposed run's rebuilds through the
//! host.

use super::{RunState, SimulationError};
use crate::contact::WallMesh;
use crate::domain::Exchanged;
use crate::neighbor::Bounds;
use crate::scene::LeavingDomain;
use nalgebra::Vector3;
use std::time::Instant;

impl RunState {
    /// Whether insertions are due at the current time (see [`crate::scene::Inserter::pending`]).
    pub fn inserter_pending(&self) -> bool {
        self.inserter.pending(self.time, &self.scene)
    }

    /// Stage 1 on this rank's state: insert due particles, drop those outside a closed domain,
    /// wrap periodic axes; in a decomposed run also migration and the halo exchange.
    ///
    /// `stale` says that the backend's pair list must be rebuilt already; `moved` whether some
    /// particle moved half the skin since its last build (the centroids, the domain), asked
    /// only in a decomposed run whose list is not stale: its ranks rebuild together when any
    /// needs it. Returns whether the list must be rebuilt: `stale`, or particles were inserted,
    /// removed or migrated, or the ghosts chosen afresh.
    pub fn exchange(
        &mut self,
        stale: bool,
        moved: impl FnOnce(&[Vector3<f64>], &Bounds) -> bool,
    ) -> Result<bool, SimulationError> {
        let t0 = Instant::now();
        let mut rebuild = stale;
        let before = self.particles.len();
        let inserted = if let Some(par) = self.parallel.as_deref_mut() {
            par.insert_distributed(
                &mut self.inserter,
                self.time,
                &mut self.particles,
                &self.scene,
                &mut self.next_id,
            )?
        } else {
            self.inserter
                .insert(
                    self.time,
                    &mut self.particles,
                    &self.scene,
                    &mut self.next_id,
                )?
                .inserted
        };
        if inserted > 0 || self.particles.len() != before {
            rebuild = true;
        }
        let b = self.bounds;
        for x in self.particles.position.iter_mut() {
            b.wrap(x);
        }
        let outside = self.outside_domain();
        if !outside.is_empty() {
            if self.scene.domain.on_leaving == LeavingDomain::Error {
                return Err(self.left_domain(&outside));
            }
            tracing::debug!(
                step = self.step,
                removed = outside.len(),
                "particles left the domain and were removed"
            );
            self.particles.remove(&outside);
            self.stats.removed += outside.len() as u64;
            rebuild = true;
        }
        if self.parallel.is_some() {
            let need = rebuild || moved(&self.particles.position, &self.bounds);
            rebuild |= self.exchange_decomposed(need)?;
        }
        self.timers.exchange += t0.elapsed().as_secs_f64();
        Ok(rebuild)
    }

    /// The decomposed part of stage 1 ([`crate::domain::Parallel::exchange`]) alone: with
    /// `need` (this rank's list must be rebuilt) the ranks decide together whether to rebuild,
    /// and if they do, particles migrate, the boxes may be redrawn (the walls follow) and the
    /// ghosts are chosen afresh. Returns whether they rebuilt. Every rank calls it at the same
    /// point; nothing happens in a single-rank run.
    pub fn exchange_decomposed(&mut self, need: bool) -> Result<bool, SimulationError> {
        let Some(par) = self.parallel.as_deref_mut() else {
            return Ok(false);
        };
        let exchanged = par.exchange(
            need,
            &mut self.particles,
            &mut self.history,
            &self.scene,
            self.step,
        )?;
        Ok(match exchanged {
            Exchanged::Rebuilt { redrawn } => {
                if redrawn {
                    self.restrict_walls();
                }
                true
            }
            Exchanged::Refreshed => false,
        })
    }

    /// The local indices of the particles outside a closed face of the domain (periodic axes
    /// do not count: their wrap moves a particle back in).
    fn outside_domain(&self) -> Vec<usize> {
        let b = &self.bounds;
        (0..self.particles.len())
            .filter(|&i| {
                let x = self.particles.position[i];
                (0..3).any(|k| !b.periodic[k] && (x[k] < b.min[k] || x[k] > b.max[k]))
            })
            .collect()
    }

    /// The closed-face check of stage 1 on its own, before the exchange: a particle outside
    /// a closed face stops the run ([`SimulationError::LeftDomain`]) unless the scene lets
    /// particles out (`domain.on_leaving = "remove"`). Run after the drift, where the ranks
    /// of a decomposed run can agree on it before the exchange's collectives.
    pub fn check_inside(&self) -> Result<(), SimulationError> {
        if self.scene.domain.on_leaving != LeavingDomain::Error {
            return Ok(());
        }
        let outside = self.outside_domain();
        if outside.is_empty() {
            Ok(())
        } else {
            Err(self.left_domain(&outside))
        }
    }

    /// The error for the particles at local indices `outside`, which left the domain through
    /// a closed face: up to five of them by id, each with its position and the face crossed.
    fn left_domain(&self, outside: &[usize]) -> SimulationError {
        const SHOWN: usize = 5;
        let (b, p) = (&self.bounds, &self.particles);
        let mut by_id = outside.to_vec();
        by_id.sort_by_key(|&i| p.id[i]);
        let mut named: Vec<String> = by_id
            .iter()
            .take(SHOWN)
            .map(|&i| {
                let x = p.position[i];
                let face = (0..3)
                    .find_map(|k| {
                        let axis = ["x", "y", "z"][k];
                        if b.periodic[k] {
                            None
                        } else if x[k] < b.min[k] {
                            Some(format!("{axis} min face ({axis} = {} m)", b.min[k]))
                        } else if x[k] > b.max[k] {
                            Some(format!("{axis} max face ({axis} = {} m)", b.max[k]))
                        } else {
                            None
                        }
                    })
                    .unwrap_or_default();
                format!(
                    "particle {} at {:?} m (velocity {:?} m/s) crossed the {face}",
                    p.id[i],
                    x.as_slice(),
                    p.velocity[i].as_slice()
                )
            })
            .collect();
        if outside.len() > SHOWN {
            named.push(format!("and {} more", outside.len() - SHOWN));
        }
        SimulationError::LeftDomain {
            step: self.step,
            count: outside.len(),
            particles: named.join("; "),
        }
    }

    /// The wall meshes this rank needs: in a decomposed run, of each wall that does not move,
    /// the facets that reach the rank's box plus the halo; moving walls and single-rank runs
    /// keep every facet.
    pub(crate) fn restrict_walls(&mut self) {
        let cell = self.scene.cutoff();
        let region = self.parallel.as_deref().map(|p| {
            let b = p.own_box().grown(p.subdomains.halo);
            (b.lo, b.hi)
        });
        self.walls = self
            .scene
            .walls
            .iter()
            .map(|w| {
                let full = WallMesh::new(&w.triangles, cell);
                match &region {
                    Some((lo, hi)) if w.motion.is_static() => full.restricted(lo, hi, cell),
                    _ => full,
                }
            })
            .collect();
    }
}
