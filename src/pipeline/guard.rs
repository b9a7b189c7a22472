//! The stability guard's checks (`crate::stability`): speeds and finiteness after the drift,
//! overlaps after the force evaluation, finiteness after the step; and the error that names a
//! particle's contacts.

use super::{Simulation, SimulationError};
use crate::stability::{Instability, SpeedScale, StabilityGuard};
use rayon::prelude::*;

impl Simulation {
    /// Resolves the stability guard's bounds for the particles now placed (their speeds and
    /// the elastic energy of the last force evaluation count in the scene's speed scale).
    ///
    /// In a decomposed run the scale is the largest over the ranks (a collective call), so
    /// that every rank holds the bounds of the single-rank run and a stop does not depend on
    /// which rank owns the particle.
    pub fn reset_guard(&mut self) {
        if self.radius.len() != self.particles.len() {
            self.refresh_radii();
        }
        let mut scale = SpeedScale::of(
            &self.scene,
            &self.particles,
            &self.radius,
            self.stats.elastic_energy,
        );
        if let Some(par) = self.parallel.as_deref() {
            let mine = [scale.driven, scale.placed, scale.elastic, scale.lightest];
            let parts: Vec<SpeedScale> = par
                .comm
                .all_gather(&crate::domain::pack::f64s(&mine))
                .iter()
                .map(|b| {
                    let x: Vec<f64> = crate::domain::pack::read_f64s(b).collect();
                    SpeedScale {
                        driven: x[0],
                        placed: x[1],
                        elastic: x[2],
                        lightest: x[3],
                    }
                })
                .collect();
            scale = SpeedScale::merged(&parts);
        }
        self.guard = StabilityGuard::new(&self.scene.simulation.guard, scale.value());
    }

    /// Particle `i`'s circumscribed radius, from its type and scale (the cached radii follow
    /// the order of the last list build, which a GPU run's synced state need not share).
    pub(super) fn circumscribed_radius(&self, i: usize) -> f64 {
        let kind = self.scene.particle_types[self.particles.kind[i] as usize].template;
        self.scene.templates[kind].circumscribed_radius * self.particles.scale[i]
    }

    /// [`Self::check_finite`] for a restored state, whose cause is the checkpoint.
    pub(super) fn check_restored(&self) -> Result<(), SimulationError> {
        self.check_finite().map_err(|e| match e {
            SimulationError::NonFinite { step, id, .. } => SimulationError::Domain {
                step,
                message: format!(
                    "the checkpoint holds particle {id} with a non-finite position or velocity"
                ),
            },
            other => other,
        })
    }

    /// The stability guard's finiteness and speed checks after the drift: the first particle
    /// (by index) past a bound stops the step.
    pub fn check_motion(&self) -> Result<(), SimulationError> {
        let p = &self.particles;
        let n = p.len().min(self.radius.len());
        let found = (0..n)
            .into_par_iter()
            .with_min_len(crate::par::CHEAP)
            .find_first(|&i| self.guard.check_motion(p, self.radius[i], i).is_some());
        match found {
            Some(i) => Err(self.unstable(i, self.guard.check_motion(p, self.radius[i], i))),
            None => Ok(()),
        }
    }

    /// What the stability guard finds wrong with particle `i` now (finiteness and speed).
    pub fn instability_of(&self, i: usize) -> Option<Instability> {
        (i < self.particles.len())
            .then(|| {
                self.guard
                    .check_motion(&self.particles, self.circumscribed_radius(i), i)
            })
            .flatten()
    }

    /// The stability guard's overlap check on the last force evaluation.
    pub(super) fn check_overlaps(&self) -> Result<(), SimulationError> {
        match &self.too_deep {
            Some((i, partner, volume, particle)) => Err(self.unstable(
                *i,
                Some(Instability::Overlap {
                    partner: partner.clone(),
                    volume: *volume,
                    particle_volume: *particle,
                    fraction: self.guard.max_overlap,
                }),
            )),
            None => Ok(()),
        }
    }

    /// This rank's outcome of a step's checks, agreed among the ranks of a decomposed run (one
    /// gather of a byte per rank; nothing in a single-rank run): a rank whose checks failed
    /// keeps its own error, and the others get [`SimulationError::Stopped`] naming those
    /// ranks. So every rank leaves the step with an error, after the same step, and they can
    /// write the stopped state together (`crate::run`) instead of one rank ending all others
    /// mid-collective. Every error of the guard, of a non-finite value and of a particle that
    /// left through a closed face goes through here, which is what lets the run treat those
    /// errors as common to all ranks ([`SimulationError::stops_every_rank`]).
    pub fn agree(&self, local: Result<(), SimulationError>) -> Result<(), SimulationError> {
        if self.parallel.is_none() {
            return local;
        }
        let stopped = self.stopped_by(local.is_err());
        match local {
            Err(e) => Err(e),
            Ok(()) => stopped.map_or(Ok(()), Err),
        }
    }

    /// The collective of [`Simulation::agree`]: each rank says whether it `failed` (one gather
    /// of a byte per rank); [`SimulationError::Stopped`] naming the ranks that did, if any.
    /// Every rank of a decomposed run must call it at the same point.
    pub(crate) fn stopped_by(&self, failed: bool) -> Option<SimulationError> {
        let par = self.parallel.as_deref()?;
        let ranks: Vec<usize> = par
            .comm
            .all_gather(&[u8::from(failed)])
            .iter()
            .enumerate()
            .filter(|(_, b)| b.first() == Some(&1))
            .map(|(r, _)| r)
            .collect();
        (!ranks.is_empty()).then_some(SimulationError::Stopped {
            step: self.step,
            ranks,
        })
    }

    /// The guard's error for particle `i` (an index of this rank's particles), naming its
    /// contacts from the history.
    pub fn unstable(&self, i: usize, problem: Option<Instability>) -> SimulationError {
        let id = self.particles.id[i];
        let mut contacts: Vec<String> = self
            .history
            .entries()
            .iter()
            .filter(|(k, _)| k.a == id || (k.wall_index().is_none() && k.b == id))
            .map(|(k, st)| {
                let what = match k.wall_index() {
                    Some(w) => format!(
                        "wall \"{}\"",
                        self.scene.walls.get(w).map_or("?", |w| w.name.as_str())
                    ),
                    None => format!("particle {}", if k.a == id { k.b } else { k.a }),
                };
                if st.approach_speed.abs() > 1e-300 {
                    let phase = if st.approach_speed > 0.0 {
                        "loading"
                    } else {
                        "unloading"
                    };
                    format!(
                        "{what} ({phase}, approached at {:.3e} m/s)",
                        st.approach_speed.abs()
                    )
                } else {
                    format!("{what} (in contact from rest)")
                }
            })
            .collect();
        if contacts.is_empty() {
            contacts.push("none".into());
        }
        let p = &self.particles;
        SimulationError::Unstable {
            step: self.step,
            id,
            problem: format!(
                "{} (position {:?}, velocity {:?}, angular velocity {:?})",
                problem.map_or_else(|| "no bound is past now".to_string(), |p| p.to_string()),
                p.position[i].as_slice(),
                p.velocity[i].as_slice(),
                p.angular_velocity[i].as_slice()
            ),
            contacts: contacts.join(", "),
        }
    }

    /// The finiteness check at the end of a step: the first particle (by index) with a
    /// non-finite position or velocity stops the run.
    pub(super) fn check_finite(&self) -> Result<(), SimulationError> {
        let p = &self.particles;
        if let Some(i) = (0..p.len()).find(|&i| {
            !(p.position[i].iter().all(|x| x.is_finite())
                && p.velocity[i].iter().all(|x| x.is_finite()))
        }) {
            return Err(SimulationError::NonFinite {
                step: self.step,
                id: p.id[i],
                field: "position or velocity",
            });
        }
        Ok(())
    }
}
