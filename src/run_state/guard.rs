//! The stability guard on a run's state (`crate::stability`): its bounds for the particles
//! placed, what it finds wrong with a particle, the finiteness check, and the agreement of a
//! decomposed run's ranks on a step's outcome, with the error that names a particle's contacts.

use super::{RunState, SimulationError};
use crate::geometry::pair::{PairWorkspace, overlap_pair};
use crate::geometry::sphere::sphere_lens;
use crate::stability::{Instability, SpeedScale, StabilityGuard};
use nalgebra::Isometry3;
use rayon::prelude::*;

impl RunState {
    /// Particle `i`'s circumscribed radius, from its type and scale.
    pub fn circumscribed_radius(&self, i: usize) -> f64 {
        let kind = self.scene.particle_types[self.particles.kind[i] as usize].template;
        self.scene.templates[kind].circumscribed_radius * self.particles.scale[i]
    }

    /// Every particle's circumscribed radius, in the particles' order.
    pub fn radii(&self) -> Vec<f64> {
        (0..self.particles.len())
            .map(|i| self.circumscribed_radius(i))
            .collect()
    }

    /// Resolves the stability guard's bounds for the particles now placed (their speeds and
    /// the elastic energy of the last force evaluation count in the scene's speed scale).
    ///
    /// In a decomposed run the scale is the largest over the ranks (a collective call), so
    /// that every rank holds the bounds of the single-rank run and a stop does not depend on
    /// which rank owns the particle.
    pub fn reset_guard(&mut self) {
        let radius = self.radii();
        let mut scale = SpeedScale::of(
            &self.scene,
            &self.particles,
            &radius,
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

    /// [`Self::check_finite`] for a restored state, whose cause is the checkpoint.
    pub(crate) fn check_restored(&self) -> Result<(), SimulationError> {
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

    /// What the stability guard finds wrong with particle `i` now (finiteness and speed).
    pub fn instability_of(&self, i: usize) -> Option<Instability> {
        (i < self.particles.len())
            .then(|| {
                self.guard
                    .check_motion(&self.particles, self.circumscribed_radius(i), i)
            })
            .flatten()
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

    /// The collective of [`RunState::agree`]: each rank says whether it `failed` (one gather
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
    pub(crate) fn check_finite(&self) -> Result<(), SimulationError> {
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

    /// The volume of particle `i`, as `(4π/3) R³` of its volume-equivalent radius (the
    /// stability guard's measure, computed alike on the GPU).
    pub(crate) fn equivalent_volume(&self, i: usize) -> f64 {
        let s = &self.scene;
        let p = &self.particles;
        let r = s.templates[s.particle_types[p.kind[i] as usize].template].equivalent_radius
            * p.scale[i];
        crate::stability::ball_volume(r)
    }

    /// The deepest overlap of owned particle `i` with any other owned particle, evaluated
    /// now in f64 by the narrow phase of stages 4–5 (`pair_contacts`) over every particle within
    /// reach (no list): (the partner's id, its overlap volume over the smaller particle's
    /// volume, as the stability guard measures it). For the GPU guard's report, which names
    /// no partner; `None` when no particle overlaps it.
    pub fn deepest_particle_overlap(&self, i: usize) -> Option<(u64, f64)> {
        let p = &self.particles;
        let s = &self.scene;
        if i >= p.len() {
            return None;
        }
        // Bounding radii from the templates: a GPU run's host copy need not hold them.
        let template = |k: usize| &s.templates[s.particle_types[p.kind[k] as usize].template];
        let radius = |k: usize| template(k).circumscribed_radius * p.scale[k];
        let periodic = self.bounds.periodic.iter().any(|&k| k);
        let xa = p.position[i];
        let ta = template(i);
        let pose_a = Isometry3::from_parts(xa.into(), p.orientation[i]);
        (0..p.len())
            .into_par_iter()
            .filter(|&j| j != i)
            .filter_map(|j| {
                let xb = if periodic {
                    xa + self.bounds.displacement(&xa, &p.position[j])
                } else {
                    p.position[j]
                };
                let reach = radius(i) + radius(j);
                if (xb - xa).norm_squared() >= reach * reach {
                    return None;
                }
                let volume = if s.spheres_only() {
                    sphere_lens(radius(i), radius(j), &(xb - xa)).volume
                } else {
                    let tb = template(j);
                    let pose_b = Isometry3::from_parts(xb.into(), p.orientation[j]);
                    // A diagnostic after a failed step: a workspace of its own per pair.
                    let mut ws = PairWorkspace::<f64>::boxed();
                    ws.set_enum_planes(s.enum_planes());
                    let g = overlap_pair(
                        &mut ws,
                        (ta, p.scale[i], &pose_a),
                        (tb, p.scale[j], &pose_b),
                    )
                    .ok()?;
                    if !g.intersects {
                        return None;
                    }
                    g.overlap.volume
                };
                (volume > 0.0).then(|| {
                    let size = self.equivalent_volume(i).min(self.equivalent_volume(j));
                    (p.id[j], volume / size)
                })
            })
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
    }
}
