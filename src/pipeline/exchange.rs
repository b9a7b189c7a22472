//! Stage 1 on this rank: insertion of due particles, removal of those that left a closed domain,
//! periodic wrapping; in a decomposed run the decomposition's part
//! ([`crate::domain::Parallel::exchange`]) follows, and what it changes here (radii, wall
//! facets) is brought up to date.

use super::{Simulation, SimulationError};
use crate::contact::WallMesh;
use crate::domain::Exchanged;
use crate::scene::LeavingDomain;
use std::time::Instant;

impl Simulation {
    /// Whether insertions are due at the current time (see [`crate::scene::Inserter::pending`]).
    pub fn inserter_pending(&self) -> bool {
        self.inserter.pending(self.time, &self.scene)
    }

    /// Stage 1 on the host copy of another backend's state: insertion of due particles and
    /// removal of those outside a closed domain, as in [`Simulation::step`].
    pub fn exchange_on_host(&mut self) -> Result<(), SimulationError> {
        self.exchange()
    }

    /// Stage 1 of a rebuild step on the host copy of a GPU rank's state: insertion, removal,
    /// and in a decomposed run balancing, migration and the ghosts chosen afresh (all ranks
    /// call it in the same step).
    pub fn rebuild_exchange_on_host(&mut self) -> Result<(), SimulationError> {
        self.dirty = true;
        self.exchange()
    }

    /// Stage 1: insert due particles, drop those outside a closed domain, wrap periodic axes;
    /// in a decomposed run also migration and the halo exchange.
    pub(super) fn exchange(&mut self) -> Result<(), SimulationError> {
        let t0 = Instant::now();
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
            self.dirty = true;
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
            self.dirty = true;
        }
        self.refresh_radii();
        if self.parallel.is_some() {
            self.parallel_exchange()?;
        }
        self.timers.exchange += t0.elapsed().as_secs_f64();
        Ok(())
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

    /// The decomposed part of stage 1 ([`crate::domain::Parallel::exchange`]): this rank needs a rebuild when
    /// it inserted or removed particles or one moved half the skin. After a rebuild the radii
    /// follow the migrated particles and, if the boxes were redrawn, the walls the new box.
    pub(super) fn parallel_exchange(&mut self) -> Result<(), SimulationError> {
        let need = self.dirty
            || self
                .pairs
                .moved_beyond_half_skin(&self.particles.position, &self.bounds);
        let par = self.parallel.as_deref_mut().expect("a decomposed run");
        let exchanged = par.exchange(
            need,
            &mut self.particles,
            &mut self.history,
            &self.scene,
            self.step,
        )?;
        if let Exchanged::Rebuilt { redrawn } = exchanged {
            self.dirty = true;
            self.refresh_radii();
            if redrawn {
                self.restrict_walls();
            }
        }
        Ok(())
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

    /// Each particle's bounding (circumscribed) radius, for the broad phase.
    pub(super) fn refresh_radii(&mut self) {
        self.radius = (0..self.particles.len())
            .map(|i| self.circumscribed_radius(i))
            .collect();
    }
}
