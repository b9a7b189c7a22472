//! How a [`Simulation`] starts: from a scene at t = 0 or from a checkpoint's state, on one rank
//! or on this rank of a decomposed run, with or without the first force evaluation.
//!
//! ```no_run
//! # fn f(scene: polydem::scene::Scene, comm: std::sync::Arc<dyn polydem::domain::Comm>)
//! # -> Result<(), polydem::pipeline::SimulationError> {
//! use polydem::pipeline::Simulation;
//! let sim = Simulation::builder(scene).comm(comm).build()?;
//! # Ok(()) }
//! ```

use super::{Simulation, SimulationError, StageTimers};
use crate::contact::{ContactHistory, hunt_crossley_alpha};
use crate::domain::{Comm, Parallel};
use crate::geometry::pair::Precision;
use crate::neighbor::{Bounds, PairList};
use crate::scene::{Inserter, Scene};
use crate::stability::StabilityGuard;
use crate::state::{Particles, StepStats};
use nalgebra::Vector3;
use std::sync::Arc;

/// A checkpoint's state, which a simulation restarts from (the inserter and its RNG come with
/// it). On a rank other than 0 of a decomposed run, the particles and history are empty: the
/// first step's exchange sends every particle to its owner.
#[derive(Clone, Debug)]
pub struct RestoredState {
    /// The particles, with the forces and torques of the last evaluation.
    pub particles: Particles,
    /// Live contacts' history.
    pub history: ContactHistory,
    /// The inserter, its RNG and its progress.
    pub inserter: Inserter,
    /// Simulated time (s).
    pub time: f64,
    /// Steps done.
    pub step: u64,
    /// Next global id to give.
    pub next_id: u64,
}

/// Builds a [`Simulation`] ([`Simulation::builder`]).
///
/// - Without [`comm`](Self::comm), or with one of one rank, the simulation is the whole
///   domain on this process; with more ranks it is this rank's part of a run decomposed over
///   them (docs/design.md §6): it owns the particles in its subdomain and holds ghosts of its
///   neighbours' outer regions. All ranks build together (the exchange is collective).
/// - Without [`restore`](Self::restore), it starts at t = 0 with the particles of count
///   insertions placed and, unless [`evaluate_forces(false)`](Self::evaluate_forces), the
///   first forces evaluated.
/// - With [`restore`](Self::restore), it holds the checkpoint's state and its stored forces.
#[must_use]
pub struct SimulationBuilder {
    scene: Scene,
    comm: Option<Arc<dyn Comm>>,
    restore: Option<RestoredState>,
    evaluate_forces: bool,
    precision: Precision,
}

impl SimulationBuilder {
    /// The ranks to decompose the run over (one rank: no decomposition).
    pub fn comm(mut self, comm: Arc<dyn Comm>) -> Self {
        self.comm = Some(comm);
        self
    }

    /// Continues from a checkpoint's state. The checkpoint holds the forces and torques of the
    /// last evaluation, which the next half kick uses: they are kept as stored (re-evaluating
    /// them would advance the tangential springs a second time), so the restarted run continues
    /// bitwise, on any rank count. [`evaluate_forces`](Self::evaluate_forces) has no effect
    /// then.
    pub fn restore(mut self, state: RestoredState) -> Self {
        self.restore = Some(state);
        self
    }

    /// Whether a new simulation evaluates its first forces (default: yes). Without, the
    /// particles of count insertions are placed (and in a decomposed run sent to their owners
    /// with the ghosts chosen) and nothing more: for a backend that evaluates the first forces
    /// itself (a new GPU run through [`crate::backend::Engine::new`]).
    pub fn evaluate_forces(mut self, evaluate: bool) -> Self {
        self.evaluate_forces = evaluate;
        self
    }

    /// The arithmetic of the polyhedral pair geometry (default: f64). [`Precision::Mixed`]
    /// evaluates it as the GPU's mixed precision does ([`overlap_pair_mixed`]), pair by pair
    /// the same decisions: f32 in the contact-centred frame, f64 for the pairs f32 cannot
    /// resolve. Spheres and walls are f64 in both, as on the GPU.
    ///
    /// [`overlap_pair_mixed`]: crate::geometry::pair::overlap_pair_mixed
    pub fn pair_precision(mut self, precision: Precision) -> Self {
        self.precision = precision;
        self
    }

    /// The simulation. Fails for a decomposition that cannot be made, an insertion that cannot
    /// place its particles, a restored state that cannot be stepped, or a failed first force
    /// evaluation.
    pub fn build(self) -> Result<Simulation, SimulationError> {
        let SimulationBuilder {
            scene,
            comm,
            restore,
            evaluate_forces,
            precision,
        } = self;
        let parallel = match comm {
            Some(comm) if comm.size() > 1 => Some(Box::new(Parallel::new(comm, &scene)?)),
            _ => None,
        };
        match (restore, evaluate_forces) {
            (Some(state), _) => Simulation::empty(scene, parallel, precision)?.restored(state),
            (None, true) => Simulation::started(scene, parallel, precision),
            (None, false) if parallel.is_some() => {
                let mut sim = Simulation::empty(scene, parallel, precision)?;
                // Every rank takes part in the first exchange's rebuild.
                sim.dirty = true;
                sim.exchange()?;
                sim.reset_guard();
                Ok(sim)
            }
            (None, false) => {
                let mut sim = Simulation::empty(scene, None, precision)?;
                sim.exchange()?;
                sim.reset_guard();
                Ok(sim)
            }
        }
    }
}

impl Simulation {
    /// A builder of a simulation of `scene` (by default: at t = 0 on one rank, first forces
    /// evaluated).
    pub fn builder(scene: Scene) -> SimulationBuilder {
        SimulationBuilder {
            scene,
            comm: None,
            restore: None,
            evaluate_forces: true,
            precision: Precision::Double,
        }
    }

    /// A simulation at t = 0: particles of count insertions placed, forces evaluated.
    fn started(
        scene: Scene,
        parallel: Option<Box<Parallel>>,
        pair_precision: Precision,
    ) -> Result<Self, SimulationError> {
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
        let bounds = Bounds {
            min: scene.domain.min,
            max: scene.domain.max,
            periodic: scene.domain.periodic,
        };
        let dt = scene.time_step();
        let inserter = Inserter::new(&scene);
        let n_walls = scene.walls.len();
        let mut sim = Simulation {
            scene,
            particles: Particles::default(),
            history: ContactHistory::default(),
            // Meshed for this rank by `restrict_walls` below.
            walls: Vec::new(),
            time: 0.0,
            step: 0,
            dt,
            next_id: 0,
            inserter,
            timers: StageTimers::default(),
            stats: StepStats::default(),
            wall_forces: vec![Vector3::zeros(); n_walls],
            sums: crate::exact_sum::DiagnosticSums::new(n_walls),
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
            pair_outcomes: Vec::new(),
            pair_precision,
        };
        sim.restrict_walls();
        sim.exchange()?;
        sim.reset_guard();
        sim.forces(sim.dt)?;
        // Again with the initial contacts' elastic energy, which a compressed start releases.
        sim.reset_guard();
        Ok(sim)
    }

    /// A simulation of `scene` with no particle placed yet (its insertions still to come).
    fn empty(
        scene: Scene,
        parallel: Option<Box<Parallel>>,
        pair_precision: Precision,
    ) -> Result<Self, SimulationError> {
        let mut s = scene.clone();
        s.insertions.clear();
        let mut sim = Simulation::started(s, parallel, pair_precision)?;
        sim.scene = scene;
        sim.inserter = Inserter::new(&sim.scene);
        Ok(sim)
    }

    /// `self` (without particles) holding a checkpoint's state, its stored forces kept
    /// ([`SimulationBuilder::restore`]).
    fn restored(mut self, state: RestoredState) -> Result<Self, SimulationError> {
        let RestoredState {
            particles,
            history,
            inserter,
            time,
            step,
            next_id,
        } = state;
        self.particles = particles;
        self.step = step;
        // A state that cannot be stepped (or owned by any rank) is refused, not carried.
        self.check_restored()?;
        // The contact counts the last evaluation left, which the checkpoint's history holds.
        self.particles.count_contacts(&history);
        self.history = history;
        self.inserter = inserter;
        self.time = time;
        self.next_id = next_id;
        self.dirty = true;
        self.refresh_radii();
        self.reset_guard();
        Ok(self)
    }
}
