//! Scheduling of insertions: a fresh or restored [`Inserter`], its checkpoint state, and the
//! `insert` call that works out which particles are due and hands each to the placement code.

use super::super::walls::WallTriangles;
use super::super::{Scene, SceneError};
use super::placement::{Occupancy, type_name};
use super::{InsertReport, Inserter, InserterState, Insertion, InsertionMode, Region};
use crate::rng::Rng;
use crate::state::Particles;
use nalgebra::{UnitQuaternion, Vector3};

impl Inserter {
    /// A fresh inserter, its generator seeded from `simulation.seed`.
    pub fn new(scene: &Scene) -> Self {
        let n = scene.insertions.len();
        Inserter {
            rng: Rng::new(scene.simulation.seed),
            inserted: vec![0; n],
            count_done: vec![false; n],
            last_insertion_time: None,
            dt: scene.time_step(),
        }
    }

    /// The state to checkpoint.
    pub fn state(&self) -> InserterState {
        InserterState {
            rng: self.rng.state(),
            inserted: self.inserted.clone(),
            count_done: self.count_done.clone(),
            last_insertion_time: self.last_insertion_time,
        }
    }

    /// Restores a checkpointed state. If the scene's insertion list changed length since, the
    /// counters are cut or padded with zeros (new insertions start afresh);
    /// [`Inserter::try_restore`] refuses that instead.
    pub fn restore(scene: &Scene, state: &InserterState) -> Self {
        let n = scene.insertions.len();
        let mut inserted = state.inserted.clone();
        inserted.resize(n, 0);
        let mut count_done = state.count_done.clone();
        count_done.resize(n, false);
        Inserter {
            rng: Rng::from_state(state.rng),
            inserted,
            count_done,
            last_insertion_time: state.last_insertion_time,
            dt: scene.time_step(),
        }
    }

    /// As [`Inserter::restore`], but an error when the state does not match the scene.
    pub fn try_restore(scene: &Scene, state: &InserterState) -> Result<Self, SceneError> {
        let n = scene.insertions.len();
        if state.inserted.len() != n || state.count_done.len() != n {
            return Err(SceneError::Insertion {
                file: scene.file.display().to_string(),
                key: "insertions".into(),
                message: format!(
                    "the checkpoint's insertion state has {} entries, the scene {n}",
                    state.inserted.len()
                ),
            });
        }
        Ok(Self::restore(scene, state))
    }

    /// Particles placed so far by each insertion.
    pub fn inserted(&self) -> &[u64] {
        &self.inserted
    }

    /// Time of the last call that placed a particle.
    pub fn last_insertion_time(&self) -> Option<f64> {
        self.last_insertion_time
    }

    /// Whether [`Inserter::insert`] at time `t` would place particles (some are due), without
    /// placing them: the GPU backend syncs the state to the host only then.
    pub fn pending(&self, t: f64, scene: &Scene) -> bool {
        let n_ins = scene.insertions.len().min(self.inserted.len());
        (0..n_ins).any(|k| {
            let ins = &scene.insertions[k];
            let done = matches!(ins.mode, InsertionMode::Count(_)) && self.count_done[k];
            !done && ins.due_by(t) > self.inserted[k] && !self.between_batches(k, t, scene)
        })
    }

    /// Whether rate insertion `k`, fed in batches (`interval`), skips the step that ends at
    /// `t` because the step does not cross a multiple of the interval. A function of `t` and
    /// the time step alone, so restarts, ranks and both backends batch at the same steps.
    fn between_batches(&self, k: usize, t: f64, scene: &Scene) -> bool {
        match scene.insertions[k].mode {
            InsertionMode::Rate {
                interval: Some(every),
                ..
            } => (t / every).floor() == ((t - self.dt) / every).floor(),
            _ => false,
        }
    }

    /// The particles `first .. first + n` of an insertion whose positions are given rather
    /// than drawn (`None` for random placement): a lattice or a packing tiled over the region
    /// (box or cylinder, bottom up in a cylinder) or a checkpoint's state. Each comes with its
    /// scale and orientation when those are given too (packing, state; a lattice draws them),
    /// and with its velocity and angular velocity when the state gives them.
    #[allow(clippy::type_complexity)]
    fn fixed_placements(
        ins: &Insertion,
        scene: &Scene,
        first: u64,
        n: u64,
    ) -> Option<
        Vec<(
            Vector3<f64>,
            Option<(f64, UnitQuaternion<f64>)>,
            Option<(Vector3<f64>, Vector3<f64>)>,
        )>,
    > {
        let range = first as usize..(first + n) as usize;
        // The part of a list of `len` in the range (validation checked that it holds them all).
        let part = |len: usize| range.start.min(len)..range.end.min(len);
        if let Some(state) = &ins.state {
            return Some(
                state.bodies[part(state.bodies.len())]
                    .iter()
                    .map(|b| {
                        let motion = Some((b.velocity, b.angular_velocity));
                        (b.position, Some((b.scale, b.orientation)), motion)
                    })
                    .collect(),
            );
        }
        match (&ins.region, ins.lattice, &ins.packing) {
            (Region::Box { min, .. }, _, Some(tiled)) => Some(
                range
                    .map(|j| {
                        let (c, orientation, scale) = tiled.particle(j as u64, min);
                        (c, Some((scale, orientation)), None)
                    })
                    .collect(),
            ),
            (Region::Box { min, max }, Some(spacing), None) => {
                // The 1e-9 absorbs the rounding of a region sized as an exact multiple of the
                // spacing.
                let dims = [0, 1, 2]
                    .map(|a| ((max[a] - min[a]) / spacing[a] + 1e-9).floor().max(1.0) as u64);
                Some(
                    range
                        .map(|j| {
                            let j = j as u64;
                            let cell = [
                                j % dims[0],
                                (j / dims[0]) % dims[1],
                                j / (dims[0] * dims[1]),
                            ];
                            let c = Vector3::from_fn(|a, _| {
                                min[a] + spacing[a] * (cell[a] as f64 + 0.5)
                            });
                            (c, None, None)
                        })
                        .collect(),
                )
            }
            (
                Region::Cylinder {
                    base,
                    axis,
                    radius,
                    height,
                },
                Some(spacing),
                None,
            ) => {
                let sites = super::cylinder_sites(base, axis, *radius, *height, &spacing);
                let sites = sites.get(range.start.min(sites.len())..range.end.min(sites.len()));
                Some(
                    sites
                        .unwrap_or(&[])
                        .iter()
                        .map(|&c| (c, None, None))
                        .collect(),
                )
            }
            (
                Region::Cylinder {
                    base,
                    axis,
                    radius,
                    height,
                },
                _,
                Some(tiled),
            ) => {
                let bound = scene.templates[scene.particle_types[ins.particle_type].template]
                    .circumscribed_radius;
                let kept = tiled.in_cylinder(base, axis, *radius, *height, bound);
                Some(
                    kept[part(kept.len())]
                        .iter()
                        .map(|&(c, orientation, scale)| (c, Some((scale, orientation)), None))
                        .collect(),
                )
            }
            _ => None,
        }
    }

    /// Inserts every particle due by time `t`: count insertions on the first call, rate
    /// insertions as they fall due. New particles overlap no existing or new particle and no
    /// wall (at its pose at `t`), judged by bounding spheres, and lie inside their region and
    /// therefore inside the domain. Ids are taken from `next_id`, which is advanced.
    ///
    /// Rate particles that find no place in `max_attempts` tries are deferred to later calls.
    /// A count insertion that cannot place all its particles is an error that says how many fit.
    pub fn insert(
        &mut self,
        t: f64,
        particles: &mut Particles,
        scene: &Scene,
        next_id: &mut u64,
    ) -> Result<InsertReport, SceneError> {
        let mut report = InsertReport::default();
        let n_ins = scene.insertions.len().min(self.inserted.len());
        let due: Vec<u64> = (0..n_ins)
            .map(|k| {
                let ins = &scene.insertions[k];
                let done = matches!(ins.mode, InsertionMode::Count(_)) && self.count_done[k];
                if done || self.between_batches(k, t, scene) {
                    0
                } else {
                    ins.due_by(t).saturating_sub(self.inserted[k])
                }
            })
            .collect();
        if due.iter().all(|&d| d == 0) {
            return Ok(report);
        }
        // A new particle's bounding sphere lies inside its region, so only the particles within
        // two bounding radii of a region and the wall triangles that reach into one can stop
        // it: the others are left out of the searches, which then give the same answers at a
        // cost that does not grow with the whole bed and the whole silo. Periodic images could
        // reach in from anywhere, so a periodic domain keeps everything.
        let near = if scene.domain.periodic.iter().any(|&p| p) {
            None
        } else {
            let reach = scene.insertion_reach();
            Some(
                scene
                    .insertions
                    .iter()
                    .map(|i| {
                        let (lo, hi) = i.region.aabb();
                        (lo.add_scalar(-reach), hi.add_scalar(reach))
                    })
                    .collect::<Vec<_>>(),
            )
        };
        let mut occupied = Occupancy::new(scene, particles, near.as_deref());
        let walls = WallTriangles::at(scene, t, near.as_deref());
        for (k, &n_due) in due.iter().enumerate() {
            let ins = &scene.insertions[k];
            let is_count = matches!(ins.mode, InsertionMode::Count(_));
            if let Some(placements) = Self::fixed_placements(ins, scene, self.inserted[k], n_due) {
                // Validation checked that the lattice, the packing or the state holds the count.
                for (c, body, motion) in placements {
                    match body {
                        Some(body) => Self::push(ins, particles, scene, body, c, next_id),
                        None => self.place_at(ins, particles, scene, c, next_id),
                    }
                    if let Some((v, w)) = motion {
                        let i = particles.len() - 1;
                        particles.velocity[i] = v;
                        particles.angular_velocity[i] = w;
                    }
                    self.inserted[k] += 1;
                    report.inserted += 1;
                }
                self.last_insertion_time = Some(t);
                self.count_done[k] = true;
                continue;
            }
            for placed in 0..n_due {
                if self.place_one(ins, particles, scene, &mut occupied, &walls, next_id) {
                    self.inserted[k] += 1;
                    report.inserted += 1;
                    self.last_insertion_time = Some(t);
                } else if is_count {
                    let name = type_name(scene, ins.particle_type);
                    return Err(SceneError::Insertion {
                        file: scene.file.display().to_string(),
                        key: format!("insertions[{k}].count"),
                        message: format!(
                            "only {placed} of {n_due} particles of type '{name}' fit in the region: \
                             particle {} found no free position in {} random tries \
                             (bounding-sphere test against particles and walls); enlarge the \
                             region, lower `count`, or feed with `rate`",
                            placed + 1,
                            ins.max_attempts
                        ),
                    });
                } else {
                    report.deferred += n_due - placed;
                    break;
                }
            }
            if is_count {
                self.count_done[k] = true;
            }
        }
        if report.deferred > 0 {
            tracing::debug!(
                t,
                deferred = report.deferred,
                "insertion region full; retrying later"
            );
        }
        Ok(report)
    }
}
