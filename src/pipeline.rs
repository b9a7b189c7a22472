//! The simulation and its step: every stage of DESIGN.md §1, in order.
//!
//! The translational and rotational integration is velocity Verlet: forces at the start of a
//! step are those of the previous force evaluation, so [`Simulation::step`] runs
//!
//! - 9a: half kick and drift (integrate, first half);
//! - 1: exchange (insertion of due particles, removal of those that left a closed domain,
//!   periodic wrapping; migration between ranks comes with the MPI decomposition);
//! - 2: neighbour list (rebuilt when some particle moved half the skin);
//! - 3–7: per pair, bounding-sphere broad phase, narrow phase (the interior-point LP's proof of an
//!   intersection, GJK where it proves none), dual-space overlap, contact law; per
//!   particle and wall, facet contacts and the contact law;
//! - 8: deterministic per-particle reduction (pairs in partner-id order, then walls in order);
//! - 9b: second half kick (integrate, second half);
//!
//! and output (stage 10) is driven by the caller between steps ([`crate::run`]). Stages a scene
//! does not need are skipped: no walls, no wall stage; μ = 0, no tangential history.

use crate::contact::{
    ContactForces, ContactHistory, ContactKey, ContactKinematics, ContactParameters, ContactState,
    WallMesh, contact_forces, hunt_crossley_alpha,
};
use crate::domain::halo::{build_ghosts, refresh_ghosts};
use crate::domain::migration::{read_particle, write_particle};
use crate::domain::pack::{Reader, Writer};
use crate::domain::{Aabb, Comm, DecompositionError, Parallel};
use crate::geometry::overlap::{PairWorkspace, axis_separates, overlap_pair};
use crate::geometry::sphere::sphere_lens;
use crate::geometry::{Overlap, PosedPolytope};
use crate::integrate::{drift, half_kick};
use crate::neighbor::{Bounds, PairList};
use crate::scene::{Inserter, LeavingDomain, Scene, SceneError};
use crate::stability::{Instability, StabilityGuard};
use crate::state::Particles;
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// Seconds spent in each stage, cumulative.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimers {
    pub integrate: f64,
    pub exchange: f64,
    pub neighbor: f64,
    pub pairs: f64,
    pub walls: f64,
    pub reduce: f64,
}

/// Per-step observables.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StepStats {
    /// Particle pairs with a positive overlap.
    pub contacts: u64,
    /// Particle–wall contacts with a positive overlap.
    pub wall_contacts: u64,
    /// Elastic energy stored in all contacts.
    pub elastic_energy: f64,
    /// Particles removed because they left a non-periodic domain, cumulative.
    pub removed: u64,
}

/// Errors of a running simulation.
#[derive(Debug, thiserror::Error)]
pub enum SimulationError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("step {step}: contact geometry failed for {what}: {message}")]
    Geometry {
        step: u64,
        what: String,
        message: String,
    },
    #[error(transparent)]
    Decomposition(#[from] DecompositionError),
    #[error(
        "step {step}: {count} particle(s) left the domain through a closed face: {particles}. Nothing in the scene lets particles out there: close the gap in the walls, enlarge [domain], lower the step (`polydem check`), or set domain.on_leaving = \"remove\" for an outflow (removed particles are counted in summary.json)"
    )]
    LeftDomain {
        step: u64,
        count: usize,
        /// Up to five of them, by id: id, position and the face crossed.
        particles: String,
    },
    #[error("step {step}: {message}")]
    Domain { step: u64, message: String },
    #[error(
        "step {step}: particle {id} has a non-finite {field}; the time step is probably too large for the contact stiffness (see `polydem check`)"
    )]
    NonFinite {
        step: u64,
        id: u64,
        field: &'static str,
    },
    #[error(
        "step {step}: particle {id} is blowing up: {problem}; its contacts: {contacts}. The time step is probably too large for the contact stiffness (`polydem check` estimates the safe one); [simulation.guard] sets the bounds"
    )]
    Unstable {
        step: u64,
        id: u64,
        problem: String,
        contacts: String,
    },
}

/// The result of one pair's contact evaluation.
#[derive(Clone, Copy, Debug, Default)]
struct PairOutcome {
    /// GJK's separating axis for a disjoint pair (zero otherwise).
    separating_axis: Vector3<f64>,
    forces: ContactForces,
    state: Option<(ContactKey, ContactState)>,
    /// The overlap's volume over the smaller particle's volume (the stability guard's measure).
    penetration: f64,
}

/// A particle's total wall contribution.
#[derive(Clone, Debug, Default)]
struct WallOutcome {
    force: Vector3<f64>,
    torque: Vector3<f64>,
    energy: f64,
    per_wall: Vec<(usize, Vector3<f64>)>,
    states: Vec<(ContactKey, ContactState)>,
    /// The deepest wall contact: overlap volume over the particle's volume, and the wall.
    penetration: (f64, usize),
}

/// A running simulation on the CPU backend.
pub struct Simulation {
    /// The scene it runs.
    pub scene: Scene,
    /// Particle state.
    pub particles: Particles,
    /// Live contacts' history.
    pub history: ContactHistory,
    /// Wall meshes in their t = 0 frames.
    pub walls: Vec<WallMesh>,
    /// Simulated time (s).
    pub time: f64,
    /// Steps done.
    pub step: u64,
    /// Time step (s).
    pub dt: f64,
    /// Next global id to give.
    pub next_id: u64,
    /// Places particles.
    pub inserter: Inserter,
    /// Stage timers.
    pub timers: StageTimers,
    /// Observables of the last force evaluation.
    pub stats: StepStats,
    /// Force on each wall from the last force evaluation (this rank's particles' share in a
    /// decomposed run).
    pub wall_forces: Vec<Vector3<f64>>,
    /// This rank's part of a decomposed run (`None`: one rank, the whole domain).
    pub parallel: Option<Box<Parallel>>,
    pairs: PairList,
    /// Per pair of `pairs`, the axis that separated it at the last evaluation (zero: none
    /// known), tried before GJK ([`axis_separates`]); cleared when the list is rebuilt.
    separating_axes: Vec<Vector3<f64>>,
    bounds: Bounds,
    radius: Vec<f64>,
    /// Hunt–Crossley `ᾱ(e)` per material pair (`a * materials + b`).
    damping: Vec<f64>,
    dirty: bool,
    /// The stability guard's bounds (`crate::stability`), set when particles are placed.
    pub guard: StabilityGuard,
    /// The contact of the last force evaluation past the guard's overlap bound, if any:
    /// (particle index, what it overlaps, overlap volume, the smaller particle volume).
    too_deep: Option<(usize, String, f64, f64)>,
}

impl Simulation {
    /// A simulation at t = 0: particles of count insertions placed, forces evaluated.
    pub fn new(scene: Scene) -> Result<Self, SimulationError> {
        Self::new_in(scene, None)
    }

    /// [`Simulation::new`] for this rank of a run decomposed over `comm`'s ranks
    /// (DESIGN.md §6): the rank owns the particles in its subdomain and holds ghosts of its
    /// neighbours' outer regions. On one rank it is [`Simulation::new`].
    pub fn new_parallel(scene: Scene, comm: Arc<dyn Comm>) -> Result<Self, SimulationError> {
        if comm.size() == 1 {
            return Self::new(scene);
        }
        let par = Parallel::new(comm, &scene)?;
        Self::new_in(scene, Some(Box::new(par)))
    }

    fn new_in(scene: Scene, parallel: Option<Box<Parallel>>) -> Result<Self, SimulationError> {
        let n_mat = scene.materials.len();
        let damping = (0..n_mat * n_mat)
            .map(|k| {
                let e = scene
                    .pairs
                    .try_get(k / n_mat, k % n_mat)
                    .map_or(1.0, |p| p.restitution);
                hunt_crossley_alpha(e)
            })
            .collect();
        let cell = scene.cutoff();
        let walls = scene
            .walls
            .iter()
            .map(|w| WallMesh::new(&w.triangles, cell))
            .collect::<Vec<_>>();
        let bounds = Bounds {
            min: scene.domain.min,
            max: scene.domain.max,
            periodic: scene.domain.periodic,
        };
        let dt = scene.time_step();
        let inserter = Inserter::new(&scene);
        let n_walls = walls.len();
        let mut sim = Simulation {
            scene,
            particles: Particles::default(),
            history: ContactHistory::default(),
            walls,
            time: 0.0,
            step: 0,
            dt,
            next_id: 0,
            inserter,
            timers: StageTimers::default(),
            stats: StepStats::default(),
            wall_forces: vec![Vector3::zeros(); n_walls],
            parallel,
            pairs: PairList::default(),
            separating_axes: Vec::new(),
            bounds,
            radius: Vec::new(),
            damping,
            dirty: true,
            guard: StabilityGuard {
                enabled: false,
                max_speed: f64::INFINITY,
                max_overlap: f64::INFINITY,
                speed_scale: 0.0,
            },
            too_deep: None,
        };
        sim.restrict_walls();
        sim.exchange()?;
        sim.reset_guard();
        sim.forces()?;
        // Again with the initial contacts' elastic energy, which a compressed start releases.
        sim.reset_guard();
        Ok(sim)
    }

    /// A simulation at t = 0 with the particles of count insertions placed but no force
    /// evaluated yet: for a backend that evaluates the first forces itself
    /// ([`crate::backend::cuda::CudaSimulation::from_scene`]).
    pub fn new_unevaluated(scene: Scene) -> Result<Self, SimulationError> {
        let mut sim = Simulation::new_empty(scene, None)?;
        sim.exchange()?;
        sim.reset_guard();
        Ok(sim)
    }

    /// Restores a simulation from checkpointed state (the inserter and RNG come with it).
    #[allow(clippy::too_many_arguments)]
    pub fn restore(
        scene: Scene,
        particles: Particles,
        history: ContactHistory,
        inserter: Inserter,
        time: f64,
        step: u64,
        next_id: u64,
    ) -> Result<Self, SimulationError> {
        let sim = Simulation::new_empty(scene, None)?;
        sim.restored(particles, history, inserter, time, step, next_id)
    }

    /// [`Simulation::restore`] for this rank of a decomposed run: rank 0 passes the
    /// checkpoint's particles and history, the other ranks none; the first step's exchange
    /// sends every particle to its owner. The stored forces are kept as on one rank, so the run
    /// continues bitwise, on any rank count.
    #[allow(clippy::too_many_arguments)]
    pub fn restore_parallel(
        scene: Scene,
        comm: Arc<dyn Comm>,
        particles: Particles,
        history: ContactHistory,
        inserter: Inserter,
        time: f64,
        step: u64,
        next_id: u64,
    ) -> Result<Self, SimulationError> {
        if comm.size() == 1 {
            return Self::restore(scene, particles, history, inserter, time, step, next_id);
        }
        let par = Parallel::new(comm, &scene)?;
        let sim = Simulation::new_empty(scene, Some(Box::new(par)))?;
        sim.restored(particles, history, inserter, time, step, next_id)
    }

    /// `self` (without particles) holding a checkpoint's state. The checkpoint holds the forces
    /// and torques of the last evaluation, which the next half kick uses: they are kept as
    /// stored (re-evaluating them would advance the tangential springs a second time), so the
    /// restarted run continues bitwise.
    fn restored(
        mut self,
        particles: Particles,
        history: ContactHistory,
        inserter: Inserter,
        time: f64,
        step: u64,
        next_id: u64,
    ) -> Result<Self, SimulationError> {
        self.particles = particles;
        self.step = step;
        // A state that cannot be stepped (or owned by any rank) is refused, not carried.
        self.check_restored()?;
        self.history = history;
        self.inserter = inserter;
        self.time = time;
        self.next_id = next_id;
        self.dirty = true;
        self.refresh_radii();
        self.reset_guard();
        Ok(self)
    }

    /// Resolves the stability guard's bounds for the particles now placed (their speeds and
    /// the elastic energy of the last force evaluation count in the scene's speed scale).
    pub fn reset_guard(&mut self) {
        if self.radius.len() != self.particles.len() {
            self.refresh_radii();
        }
        self.guard = StabilityGuard::new(
            &self.scene.simulation.guard,
            &self.scene,
            &self.particles,
            &self.radius,
            self.stats.elastic_energy,
        );
    }

    /// Re-evaluates forces after the particle state was edited directly (tests, set-up
    /// tools): neighbour lists and radii are rebuilt, the contact history is kept as is.
    pub fn refresh(&mut self) -> Result<(), SimulationError> {
        self.dirty = true;
        self.refresh_radii();
        self.reset_guard();
        if self.parallel.is_some() {
            self.parallel_exchange()?;
        }
        let saved = self.history.clone();
        self.forces_with_history_step(0.0)?;
        self.history = saved;
        self.reset_guard();
        Ok(())
    }

    /// A simulation of `scene` with no particle placed yet (its insertions still to come).
    fn new_empty(scene: Scene, parallel: Option<Box<Parallel>>) -> Result<Self, SimulationError> {
        let mut s = scene.clone();
        s.insertions.clear();
        let mut sim = Simulation::new_in(s, parallel)?;
        sim.scene = scene;
        sim.inserter = Inserter::new(&sim.scene);
        Ok(sim)
    }

    /// Advances one time step (the stage order of DESIGN.md §1; see the module docs).
    pub fn step(&mut self) -> Result<(), SimulationError> {
        let t0 = Instant::now();
        half_kick(&mut self.particles, &self.scene.gravity, self.dt);
        drift(&mut self.particles, self.dt);
        self.time += self.dt;
        self.step += 1;
        self.timers.integrate += t0.elapsed().as_secs_f64();
        self.check_motion()?;
        self.exchange()?;
        self.forces()?;
        self.check_overlaps()?;
        let t0 = Instant::now();
        half_kick(&mut self.particles, &self.scene.gravity, self.dt);
        self.timers.integrate += t0.elapsed().as_secs_f64();
        self.check_finite()
    }

    /// Whether insertions are due at the current time (see [`Inserter::pending`]).
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

    /// [`Simulation::new_parallel`] without the first force evaluation, for a backend that
    /// evaluates it itself: particles of count insertions placed and, in a decomposed run,
    /// sent to their owners with the ghosts chosen.
    pub fn new_parallel_unevaluated(
        scene: Scene,
        comm: Arc<dyn Comm>,
    ) -> Result<Self, SimulationError> {
        if comm.size() == 1 {
            return Self::new_unevaluated(scene);
        }
        let par = Parallel::new(comm, &scene)?;
        let mut sim = Simulation::new_empty(scene, Some(Box::new(par)))?;
        sim.dirty = true;
        sim.exchange()?;
        Ok(sim)
    }

    /// Stage 1: insert due particles, drop those outside a closed domain, wrap periodic axes;
    /// in a decomposed run also migration and the halo exchange.
    fn exchange(&mut self) -> Result<(), SimulationError> {
        let t0 = Instant::now();
        let before = self.particles.len();
        let inserted = if self.parallel.is_some() {
            self.insert_distributed()?
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
        let outside: Vec<usize> = (0..self.particles.len())
            .filter(|&i| {
                let x = self.particles.position[i];
                (0..3).any(|k| !b.periodic[k] && (x[k] < b.min[k] || x[k] > b.max[k]))
            })
            .collect();
        if !outside.is_empty() {
            if self.scene.domain.on_leaving == LeavingDomain::Error {
                return Err(self.left_domain(&outside));
            }
            tracing::debug!(
                step = self.step,
                removed = outside.len(),
                "particles left the domain and were removed"
            );
            remove_particles(&mut self.particles, &outside);
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

    /// Insertion in a decomposed run: every rank runs the same inserter (same generator, same
    /// draws) against the bounding spheres of all ranks' particles near the insertion regions,
    /// gathered from every rank, so it places exactly the particles one rank would; each rank
    /// keeps those whose centroid is in its box. Returns how many were placed in all.
    fn insert_distributed(&mut self) -> Result<u64, SimulationError> {
        if !self.inserter.pending(self.time, &self.scene) {
            return Ok(0);
        }
        let t0 = Instant::now();
        let par = self.parallel.as_deref().expect("a decomposed run");
        let s = &self.scene;
        // A new sphere inside its region can touch spheres up to 2 r_max from it.
        let reach = 2.0 * s.max_bounding_radius() * (1.0 + 1e-9) + 1e-12;
        let regions: Vec<Aabb> = s
            .insertions
            .iter()
            .map(|ins| {
                let (lo, hi) = ins.region.aabb();
                Aabb { lo, hi }.grown(reach)
            })
            .collect();
        let offsets = par.subdomains.image_offsets(None);
        let shifts: Vec<Vector3<f64>> = offsets.iter().map(|o| par.subdomains.shift(o)).collect();
        let p = &self.particles;
        let mut w = Writer::default();
        for i in 0..p.len() {
            let near = shifts.iter().any(|sh| {
                let x = p.position[i] + sh;
                regions.iter().any(|r| r.distance(&x) == 0.0)
            });
            if near {
                w.u64(p.id[i]);
                w.u32(p.kind[i]);
                w.f64(p.scale[i]);
                w.v3(&p.position[i]);
            }
        }
        let mut occupied = Particles::default();
        for buf in par.comm.all_gather(&w.buf) {
            let mut r = Reader::new(&buf);
            while !r.done() {
                let (id, kind, scale, x) = (r.u64(), r.u32(), r.f64(), r.v3());
                let ty = &s.particle_types[kind as usize];
                occupied.push(
                    id,
                    kind,
                    scale,
                    x,
                    nalgebra::UnitQuaternion::identity(),
                    &s.templates[ty.template],
                    0.0,
                );
            }
        }
        let first_new = occupied.len();
        let report = self
            .inserter
            .insert(self.time, &mut occupied, s, &mut self.next_id)?;
        let me = par.rank();
        let mut w = Writer::default();
        let mut kept = 0;
        for i in first_new..occupied.len() {
            if par.subdomains.contains(me, &occupied.position[i]) {
                write_particle(&mut w, &occupied, i);
                kept += 1;
            }
        }
        let mut r = Reader::new(&w.buf);
        for _ in 0..kept {
            read_particle(&mut r, &mut self.particles);
        }
        if let Some(par) = self.parallel.as_deref_mut() {
            par.timers.insert += t0.elapsed().as_secs_f64();
        }
        Ok(report.inserted)
    }

    /// The decomposed part of stage 1. All ranks decide together whether the neighbour lists
    /// are rebuilt (some rank inserted, removed, or has a particle that moved half the skin);
    /// at a rebuild the boxes may be redrawn, particles migrate and the ghosts are chosen
    /// afresh, otherwise the same ghosts are refreshed.
    fn parallel_exchange(&mut self) -> Result<(), SimulationError> {
        let need = self.dirty
            || self
                .pairs
                .moved_beyond_half_skin(&self.particles.position, &self.bounds);
        let step = self.step;
        let domain_error = |message: String| SimulationError::Domain { step, message };
        let par = self.parallel.as_deref_mut().expect("a decomposed run");
        let t0 = Instant::now();
        // The first collective of the step: time spent here is waiting for the slowest rank.
        let rebuild = par.comm.any(need);
        par.timers.wait += t0.elapsed().as_secs_f64();
        if !rebuild {
            let t0 = Instant::now();
            refresh_ghosts(&*par.comm, &par.plan, &self.particles, &mut par.ghosts);
            par.timers.halo += t0.elapsed().as_secs_f64();
            return Ok(());
        }
        let t0 = Instant::now();
        let redrawn = par.rebalance_if_needed(&self.particles)?;
        par.timers.balance += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let moved = crate::domain::migration::migrate(
            &*par.comm,
            &par.subdomains,
            &mut self.particles,
            &mut self.history,
        );
        par.timers.migrated += moved as u64;
        par.timers.migrate += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        par.plan = crate::domain::halo::HaloPlan::new(
            &par.subdomains,
            par.rank(),
            &self.particles.position,
        );
        par.ghosts = build_ghosts(&*par.comm, &par.plan, &self.particles, &self.scene);
        par.timers.rebuilds += 1;
        par.check_ghosts(&self.particles).map_err(domain_error)?;
        par.timers.halo += t0.elapsed().as_secs_f64();
        self.dirty = true;
        self.refresh_radii();
        if redrawn {
            self.restrict_walls();
        }
        Ok(())
    }

    /// The wall meshes this rank needs: in a decomposed run, of each wall that does not move,
    /// the facets that reach the rank's box plus the halo; moving walls and single-rank runs
    /// keep every facet.
    fn restrict_walls(&mut self) {
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

    fn refresh_radii(&mut self) {
        let types = &self.scene.particle_types;
        let templates = &self.scene.templates;
        self.radius = (0..self.particles.len())
            .map(|i| {
                templates[types[self.particles.kind[i] as usize].template].circumscribed_radius
                    * self.particles.scale[i]
            })
            .collect();
    }

    /// Stages 2–8 at the current state, advancing the contact history by one step.
    fn forces(&mut self) -> Result<(), SimulationError> {
        self.forces_with_history_step(self.dt)
    }

    fn forces_with_history_step(&mut self, dt: f64) -> Result<(), SimulationError> {
        let t_forces = Instant::now();
        // Ghosts join the particle arrays after the owned ones for the pair stages.
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
        // Stage 2: neighbour list.
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

        // Stages 3–7 for particle pairs.
        let t0 = Instant::now();
        let outcomes = self.pair_contacts(dt);
        self.particles.truncate(owned);
        self.radius.truncate(owned);
        let outcomes = outcomes?;
        for (axis, o) in self.separating_axes.iter_mut().zip(&outcomes) {
            *axis = o.separating_axis;
        }
        self.timers.pairs += t0.elapsed().as_secs_f64();

        // Stage 6 (walls) per particle.
        let t0 = Instant::now();
        let wall_outcomes = self.wall_contacts(dt)?;
        self.timers.walls += t0.elapsed().as_secs_f64();

        // Stage 8: deterministic reduction.
        let t0 = Instant::now();
        let pairs = &self.pairs;
        let p = &mut self.particles;
        p.force
            .par_iter_mut()
            .zip(p.torque.par_iter_mut())
            .enumerate()
            .for_each(|(i, (f, t))| {
                let mut force = Vector3::zeros();
                let mut torque = Vector3::zeros();
                for r in pairs.of(i) {
                    let o = &outcomes[r.pair as usize].forces;
                    if r.is_b {
                        force += o.force_b;
                        torque += o.torque_b;
                    } else {
                        force -= o.force_b;
                        torque += o.torque_a;
                    }
                }
                if let Some(w) = wall_outcomes.get(i) {
                    force += w.force;
                    torque += w.torque;
                }
                *f = force;
                *t = torque;
            });
        let mut entries: Vec<(ContactKey, ContactState)> =
            outcomes.iter().filter_map(|o| o.state).collect();
        let mut wall_forces = vec![Vector3::zeros(); self.walls.len()];
        // A pair across two ranks is evaluated on both; it counts where its lower-id member
        // (the pair's first) is owned, so that sums over ranks count it once.
        let counted = |k: usize| self.pairs.pairs[k][0] < owned as u32;
        // Summed per particle in local order, each particle's pairs by partner id (the order
        // of the force reduction above), not in pair-list order: the list's order depends on
        // the step it was built at, which a restart changes, and the energy must not.
        let listed = owned.min(pairs.offsets.len().saturating_sub(1));
        let mut energy: f64 = 0.0;
        for i in 0..listed {
            for r in pairs.of(i) {
                if !r.is_b && counted(r.pair as usize) {
                    energy += outcomes[r.pair as usize].forces.elastic_energy;
                }
            }
        }
        let mut wall_contacts = 0;
        for w in &wall_outcomes {
            energy += w.energy;
            wall_contacts += w.states.len() as u64;
            entries.extend_from_slice(&w.states);
            for (k, f) in &w.per_wall {
                wall_forces[*k] += f;
            }
        }
        self.stats.contacts = outcomes
            .iter()
            .enumerate()
            .filter(|(k, o)| o.state.is_some() && counted(*k))
            .count() as u64;
        self.stats.wall_contacts = wall_contacts;
        self.stats.elastic_energy = energy;
        self.wall_forces = wall_forces;
        self.history = ContactHistory::from_entries(entries);
        // The guard's overlap bound: the first pair past it, else the first particle with a
        // wall contact past it (deterministic, whatever the thread count).
        let limit = self.guard.max_overlap;
        self.too_deep = None;
        if limit.is_finite() {
            // Id and volume ((4π/3) R³ of the volume-equivalent radius) of an owned particle
            // or a ghost.
            let member = |x: usize| {
                let s = &self.scene;
                let p = if x < owned {
                    (&self.particles, x)
                } else {
                    let par = self
                        .parallel
                        .as_deref()
                        .expect("ghosts only in a decomposed run");
                    (&par.ghosts.particles, x - owned)
                };
                let (p, x) = p;
                let t = &s.templates[s.particle_types[p.kind[x] as usize].template];
                (
                    p.id[x],
                    crate::stability::ball_volume(t.equivalent_radius * p.scale[x]),
                )
            };
            let volume = |i: usize| member(i).1;
            if let Some(k) = outcomes.iter().position(|o| o.penetration > limit) {
                let [a, b] = self.pairs.pairs[k].map(|x| x as usize);
                // The owned member is named (a ghost's id is still the partner's).
                let (i, j) = if a < owned { (a, b) } else { (b, a) };
                let size = volume(i).min(volume(j));
                self.too_deep = Some((
                    i,
                    format!("particle {}", member(j).0),
                    outcomes[k].penetration * size,
                    size,
                ));
            } else if let Some(i) = wall_outcomes.iter().position(|w| w.penetration.0 > limit) {
                let (depth, k) = wall_outcomes[i].penetration;
                let size = volume(i);
                self.too_deep = Some((
                    i,
                    format!("wall \"{}\"", self.scene.walls[k].name),
                    depth * size,
                    size,
                ));
            }
        }
        self.timers.reduce += t0.elapsed().as_secs_f64();
        if let Some(par) = self.parallel.as_deref_mut() {
            par.cost += t_forces.elapsed().as_secs_f64();
        }
        Ok(())
    }

    /// The volume of particle `i`, as `(4π/3) R³` of its volume-equivalent radius (the
    /// stability guard's measure, computed alike on the GPU).
    fn equivalent_volume(&self, i: usize) -> f64 {
        let s = &self.scene;
        let p = &self.particles;
        let r = s.templates[s.particle_types[p.kind[i] as usize].template].equivalent_radius
            * p.scale[i];
        crate::stability::ball_volume(r)
    }

    fn contact_parameters(
        &self,
        i: usize,
        other: Option<usize>,
        wall_material: usize,
    ) -> ContactParameters {
        let s = &self.scene;
        let p = &self.particles;
        let side = |k: usize| {
            let ty = &s.particle_types[p.kind[k] as usize];
            let m = &s.materials[ty.material];
            let r = s.templates[ty.template].equivalent_radius * p.scale[k];
            (
                ty.material,
                m.youngs_modulus / r,
                m.youngs_modulus / (2.0 * (1.0 + m.poisson_ratio) * r),
            )
        };
        let (ma, cn_a, ct_a) = side(i);
        // A wall is flat: its radius is infinite and only the particle's term remains.
        let (mb, cn_b, ct_b) = match other {
            Some(j) => side(j),
            None => (wall_material, 0.0, 0.0),
        };
        let pair = s.pairs.get(ma, mb);
        ContactParameters {
            normal_stiffness: cn_a + cn_b,
            tangential_stiffness: ct_a + ct_b,
            restitution: pair.restitution,
            friction: pair.friction,
            damping: self.damping[ma * s.materials.len() + mb],
            rocking: !s.templates[s.particle_types[p.kind[i] as usize].template].sphere,
        }
    }

    fn pair_contacts(&self, dt: f64) -> Result<Vec<PairOutcome>, SimulationError> {
        let p = &self.particles;
        let s = &self.scene;
        let step = self.step;
        let spheres = s.spheres_only();
        let periodic = self.bounds.periodic.iter().any(|&k| k);
        let bounds = self.bounds;
        self.pairs
            .pairs
            .par_iter()
            .zip(self.separating_axes.par_iter())
            .map(|(pair, axis)| {
                let (a, b) = (pair[0] as usize, pair[1] as usize);
                // B's periodic image from the current centroids by the list build's minimum-image
                // arithmetic (not the build's shift: a particle wrapped across a periodic face
                // since the build keeps its contacts); no shift without periodic axes.
                let xb = if periodic {
                    let (xa, xb) = (p.position[a], p.position[b]);
                    xb + (bounds.displacement(&xa, &xb) - (xb - xa))
                } else {
                    p.position[b]
                };
                let d = xb - p.position[a];
                let reach = self.radius[a] + self.radius[b];
                // Stage 3: bounding spheres.
                if d.norm_squared() >= reach * reach {
                    return Ok(PairOutcome::default());
                }
                let overlap = if spheres {
                    // Stages 4–5 for spheres: the lens in closed form.
                    let o =
                        sphere_lens(self.radius[a], self.radius[b], &d).to_world(&p.position[a]);
                    if o.volume <= 0.0 {
                        return Ok(PairOutcome::default());
                    }
                    o
                } else {
                    let ta = &s.templates[s.particle_types[p.kind[a] as usize].template];
                    let tb = &s.templates[s.particle_types[p.kind[b] as usize].template];
                    let pose_a = Isometry3::from_parts(p.position[a].into(), p.orientation[a]);
                    let pose_b = Isometry3::from_parts(xb.into(), p.orientation[b]);
                    let (body_a, body_b) = ((ta, p.scale[a], &pose_a), (tb, p.scale[b], &pose_b));
                    // Stage 4 shortcut: last step's separating axis, with a margin far above
                    // GJK's touching tolerance (1e-12 of the size in f64), so the verdict is
                    // GJK's.
                    if *axis != Vector3::zeros()
                        && axis_separates(body_a, body_b, axis, 1e-9 * reach)
                    {
                        return Ok(PairOutcome {
                            separating_axis: *axis,
                            ..PairOutcome::default()
                        });
                    }
                    // Stages 4–5: the narrow phase (GJK where the Chebyshev centre proves no
                    // intersection), then the overlap.
                    let g = with_workspace(|ws| overlap_pair(ws, body_a, body_b)).map_err(|e| {
                        SimulationError::Geometry {
                            step,
                            what: format!("particles {} and {}", p.id[a], p.id[b]),
                            message: e.to_string(),
                        }
                    })?;
                    if g.overlap.volume <= 0.0 {
                        return Ok(PairOutcome {
                            separating_axis: g.separating_axis.unwrap_or_default(),
                            ..PairOutcome::default()
                        });
                    }
                    g.overlap
                };
                // Stage 7: contact law.
                let params = self.contact_parameters(a, Some(b), 0);
                let key = ContactKey::particles(p.id[a], p.id[b]);
                let mut state = self.history.get(&key).copied().unwrap_or_default();
                let kin = ContactKinematics {
                    x_a: p.position[a],
                    x_b: xb,
                    v_a: p.velocity[a],
                    v_b: p.velocity[b],
                    w_a: p.angular_velocity[a],
                    w_b: p.angular_velocity[b],
                    // A lens's centroid is on the line of centres: no rotational term.
                    effective_mass: if spheres {
                        1.0 / (1.0 / p.mass[a] + 1.0 / p.mass[b])
                    } else {
                        normal_effective_mass(p, &[(a, p.position[a]), (b, xb)], &overlap)
                    },
                    q_a: p.orientation[a],
                    q_b: p.orientation[b],
                    inverse_inertia_a: p.inertia[a].map(|x| 1.0 / x),
                    inverse_inertia_b: p.inertia[b].map(|x| 1.0 / x),
                    sphere_radius_a: if spheres { self.radius[a] } else { 0.0 },
                    sphere_radius_b: if spheres { self.radius[b] } else { 0.0 },
                };
                let forces = contact_forces(&params, &overlap, &kin, &mut state, dt);
                Ok(PairOutcome {
                    separating_axis: Vector3::zeros(),
                    forces,
                    state: Some((key, state)),
                    penetration: overlap.volume
                        / self.equivalent_volume(a).min(self.equivalent_volume(b)),
                })
            })
            .collect::<Vec<_>>()
            // The first failing pair in list order, whatever the threads' timing.
            .into_iter()
            .collect()
    }

    fn wall_contacts(&self, dt: f64) -> Result<Vec<WallOutcome>, SimulationError> {
        if self.walls.is_empty() {
            return Ok(Vec::new());
        }
        let p = &self.particles;
        let s = &self.scene;
        let (t, step) = (self.time, self.step);
        let poses: Vec<Isometry3<f64>> = s.walls.iter().map(|w| w.motion.transform(t)).collect();
        (0..p.len())
            .into_par_iter()
            .map_init(Vec::new, |facets, i| {
                with_workspace(|ws| {
                    let mut out = WallOutcome::default();
                    let tmpl = &s.templates[s.particle_types[p.kind[i] as usize].template];
                    let pose = Isometry3::from_parts(p.position[i].into(), p.orientation[i]);
                    for (k, (mesh, wall_pose)) in self.walls.iter().zip(&poses).enumerate() {
                        // Work in the wall's own frame, where its facets are binned.
                        let local = wall_pose.inverse() * pose;
                        mesh.facets_near(&local.translation.vector, self.radius[i], facets);
                        if facets.is_empty() {
                            continue;
                        }
                        let o = if tmpl.sphere {
                            mesh.sphere_contact(&local.translation.vector, self.radius[i], facets)
                        } else {
                            let body: &mut PosedPolytope<f64> = &mut ws.a;
                            body.place(tmpl, p.scale[i], &local, &Vector3::zeros());
                            mesh.contact(&mut ws.overlap, body, (tmpl, p.scale[i], &local), facets)
                                .map_err(|e| SimulationError::Geometry {
                                    step,
                                    what: format!(
                                        "particle {} and wall {}",
                                        p.id[i], s.walls[k].name
                                    ),
                                    message: e.to_string(),
                                })?
                        };
                        if o.volume <= 0.0 {
                            continue;
                        }
                        let rot = wall_pose.rotation;
                        let world = Overlap {
                            volume: o.volume,
                            centroid: (wall_pose * nalgebra::Point3::from(o.centroid)).coords,
                            dv_dxb: rot * o.dv_dxb,
                            moment_b: rot * o.moment_b,
                            depth: o.depth,
                            thickness: o.thickness,
                        };
                        let params = self.contact_parameters(i, None, s.walls[k].material);
                        let key = ContactKey::wall(p.id[i], k);
                        let mut state = self.history.get(&key).copied().unwrap_or_default();
                        let c = world.centroid;
                        let kin = ContactKinematics {
                            x_a: p.position[i],
                            x_b: c,
                            v_a: p.velocity[i],
                            v_b: s.walls[k].motion.velocity_at(t, &c),
                            w_a: p.angular_velocity[i],
                            w_b: s.walls[k].motion.angular_velocity(),
                            effective_mass: normal_effective_mass(p, &[(i, p.position[i])], &world),
                            q_a: p.orientation[i],
                            q_b: nalgebra::UnitQuaternion::identity(),
                            inverse_inertia_a: p.inertia[i].map(|x| 1.0 / x),
                            inverse_inertia_b: Vector3::zeros(),
                            sphere_radius_a: if tmpl.sphere { self.radius[i] } else { 0.0 },
                            sphere_radius_b: 0.0,
                        };
                        let f = contact_forces(&params, &world, &kin, &mut state, dt);
                        let depth = world.volume / self.equivalent_volume(i);
                        if depth > out.penetration.0 {
                            out.penetration = (depth, k);
                        }
                        out.force -= f.force_b;
                        out.torque += f.torque_a;
                        out.energy += f.elastic_energy;
                        out.per_wall.push((k, f.force_b));
                        out.states.push((key, state));
                    }
                    Ok(out)
                })
            })
            .collect::<Vec<_>>()
            // The first failing particle in index order, whatever the threads' timing.
            .into_iter()
            .collect()
    }

    /// [`Self::check_finite`] for a restored state, whose cause is the checkpoint.
    fn check_restored(&self) -> Result<(), SimulationError> {
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
            .find_first(|&i| self.guard.check_motion(p, &self.radius, i).is_some());
        match found {
            Some(i) => Err(self.unstable(i, self.guard.check_motion(p, &self.radius, i))),
            None => Ok(()),
        }
    }

    /// What the stability guard finds wrong with particle `i` now (finiteness and speed).
    pub fn instability_of(&self, i: usize) -> Option<Instability> {
        if self.radius.len() != self.particles.len() {
            return None;
        }
        self.guard.check_motion(&self.particles, &self.radius, i)
    }

    /// The stability guard's overlap check on the last force evaluation.
    fn check_overlaps(&self) -> Result<(), SimulationError> {
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
                if st.approach_speed > 1e-300 {
                    format!("{what} (first touched at {:.3e} m/s)", st.approach_speed)
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

    fn check_finite(&self) -> Result<(), SimulationError> {
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

    /// The candidate pair list of stage 2 as global-id pairs (lower id first), sorted: what the
    /// GPU's list must equal after a build from the same positions.
    pub fn candidate_pair_ids(&self) -> Vec<(u64, u64)> {
        let id = &self.particles.id;
        let mut v: Vec<(u64, u64)> = self
            .pairs
            .pairs
            .iter()
            .map(|&[a, b]| {
                let (x, y) = (id[a as usize], id[b as usize]);
                (x.min(y), x.max(y))
            })
            .collect();
        v.sort_unstable();
        v
    }

    /// Kinetic, gravitational and elastic energy together (J): what an elastic, frictionless
    /// run conserves.
    pub fn total_energy(&self) -> f64 {
        let (kt, kr, pg) = self.energies();
        kt + kr + pg + self.stats.elastic_energy
    }

    /// Kinetic energy (translational, rotational) and gravitational potential energy
    /// (relative to the origin).
    pub fn energies(&self) -> (f64, f64, f64) {
        let p = &self.particles;
        let g = self.scene.gravity;
        let mut terms: Vec<(u64, [f64; 3])> = (0..p.len())
            .into_par_iter()
            .map(|i| {
                let wb = p.orientation[i].inverse_transform_vector(&p.angular_velocity[i]);
                (
                    p.id[i],
                    [
                        0.5 * p.mass[i] * p.velocity[i].norm_squared(),
                        0.5 * wb.component_mul(&p.inertia[i]).dot(&wb),
                        -p.mass[i] * g.dot(&p.position[i]),
                    ],
                )
            })
            .collect();
        // Summed one by one in id order: a parallel reduction's grouping varies with the
        // threads' work stealing, and the local order with the backend and a restart, either of
        // which would change the last bits of a value that the state alone determines.
        if !terms.windows(2).all(|w| w[0].0 < w[1].0) {
            terms.sort_unstable_by_key(|t| t.0);
        }
        terms.iter().fold((0.0, 0.0, 0.0), |a, (_, e)| {
            (a.0 + e[0], a.1 + e[1], a.2 + e[2])
        })
    }
}

thread_local! {
    /// One pair workspace per worker thread, made on first use: the workspace holds the
    /// fixed-capacity overlap buffers (tens of kilobytes), too big to build per rayon job.
    static WORKSPACE: std::cell::RefCell<Option<Box<PairWorkspace<f64>>>> =
        const { std::cell::RefCell::new(None) };
}

/// Runs `f` with this thread's pair workspace (a fresh one if it is already in use, which only
/// a nested call could cause).
fn with_workspace<R>(f: impl FnOnce(&mut PairWorkspace<f64>) -> R) -> R {
    WORKSPACE.with(|cell| match cell.try_borrow_mut() {
        Ok(mut slot) => f(slot.get_or_insert_with(PairWorkspace::boxed)),
        Err(_) => f(&mut PairWorkspace::boxed()),
    })
}

/// The mass a contact's normal impulse sees: `1/m* = Σ 1/m + (r × n)·I⁻¹(r × n)` over the
/// bodies touching (centres `x`, lever arms `r` from them to the overlap centroid). The damping
/// is scaled with it, so that the prescribed restitution holds for eccentric impacts too, where
/// the contact point also turns the body (seed Eq. 15 uses the translational mass only, which
/// over-damps such impacts: 4 % too little spin after the cylinder–wall impact at 75°).
fn normal_effective_mass(p: &Particles, bodies: &[(usize, Vector3<f64>)], o: &Overlap<f64>) -> f64 {
    let Some(n) = o.normal() else {
        return bodies
            .iter()
            .map(|&(i, _)| p.mass[i])
            .fold(f64::MAX, f64::min);
    };
    let mut inverse = 0.0;
    for &(i, x) in bodies {
        let arm = (o.centroid - x).cross(&n);
        let body = p.orientation[i].inverse_transform_vector(&arm);
        inverse += 1.0 / p.mass[i] + body.component_div(&p.inertia[i]).dot(&body);
    }
    1.0 / inverse
}

/// Removes the particles at the (sorted) local indices `remove`, keeping the others' order.
pub(crate) fn remove_particles(p: &mut Particles, remove: &[usize]) {
    let mut keep = vec![true; p.len()];
    for &i in remove {
        keep[i] = false;
    }
    let kept: Vec<usize> = (0..p.len()).filter(|&i| keep[i]).collect();
    *p = p.select(&kept);
}
