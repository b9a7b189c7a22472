//! How a [`Simulation`] starts: from a scene at t = 0 or from a checkpoint's state, on one rank
//! or on this rank of a decomposed run; and the [`RunState`] another backend starts from, the
//! first forces left to it.
//!
//! ```no_run
//! # fn f(scene: polydem::scene::Scene, comm: std::sync::Arc<dyn polydem::domain::Comm>)
//! # -> Result<(), polydem::pipeline::SimulationError> {
//! use polydem::pipeline::Simulation;
//! let sim = Simulation::builder(scene).comm(comm).build()?;
//! # Ok(()) }
//! ```

use super::{RunState, Simulation, SimulationError, Workspace};
use crate::contact::{ContactHistory, hunt_crossley_alpha};
use crate::domain::{Comm, Parallel};
use crate::geometry::pair::Precision;
use crate::neighbor::PairList;
use crate::scene::{Inserter, Scene};
use crate::state::Particles;
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

/// Builds a [`Simulation`] ([`Simulation::builder`]), or the [`RunState`] another backend
/// starts from ([`SimulationBuilder::state`]).
///
/// - Without [`comm`](Self::comm), or with one of one rank, the simulation is the whole
///   domain on this process; with more ranks it is this rank's part of a run decomposed over
///   them (docs/design.md §6): it owns the particles in its subdomain and holds ghosts of its
///   neighbours' outer regions. All ranks build together (the exchange is collective).
/// - Without [`restore`](Self::restore), it starts at t = 0 with the particles of count
///   insertions placed and (by [`build`](Self::build)) the first forces evaluated.
/// - With [`restore`](Self::restore), it holds the checkpoint's state and its stored forces.
#[must_use]
pub struct SimulationBuilder {
    scene: Scene,
    comm: Option<Arc<dyn Comm>>,
    restore: Option<RestoredState>,
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
    /// bitwise, on any rank count.
    pub fn restore(mut self, state: RestoredState) -> Self {
        self.restore = Some(state);
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

    /// The decomposition, when `comm` has more than one rank.
    fn parallel(
        comm: Option<Arc<dyn Comm>>,
        scene: &Scene,
    ) -> Result<Option<Box<Parallel>>, SimulationError> {
        Ok(match comm {
            Some(comm) if comm.size() > 1 => Some(Box::new(Parallel::new(comm, scene)?)),
            _ => None,
        })
    }

    /// The simulation. Fails for a decomposition that cannot be made, an insertion that cannot
    /// place its particles, a restored state that cannot be stepped, or a failed first force
    /// evaluation.
    pub fn build(self) -> Result<Simulation, SimulationError> {
        let SimulationBuilder {
            scene,
            comm,
            restore,
            precision,
        } = self;
        let parallel = Self::parallel(comm, &scene)?;
        match restore {
            Some(state) => Simulation::empty(scene, parallel, precision)?.restored(state),
            None => Simulation::started(scene, parallel, precision),
        }
    }

    /// The state a backend that evaluates the first forces itself starts from (a new GPU run
    /// through [`crate::backend::Engine::new`]): the particles of count insertions placed (in a
    /// decomposed run sent to their owners, with the ghosts chosen), or the checkpoint's state
    /// with its stored forces. Fails as [`build`](Self::build) does, but for the forces.
    pub fn state(self) -> Result<RunState, SimulationError> {
        let SimulationBuilder {
            scene,
            comm,
            restore,
            precision: _,
        } = self;
        let parallel = Self::parallel(comm, &scene)?;
        let mut state = RunState::empty(scene, parallel)?;
        match restore {
            Some(restored) => state.restore(restored)?,
            None => {
                // Every rank takes part in the first exchange's rebuild.
                state.exchange(true, |_, _| true)?;
                state.reset_guard();
            }
        }
        Ok(state)
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
            precision: Precision::Double,
        }
    }

    /// The CPU pipeline on `state`, with a fresh workspace: the pair list is built at the next
    /// force evaluation. A state's results do not depend on when its list was built (the
    /// contacts are keyed by global ids and reduced in partner-id order), so a state moved
    /// between backends continues bitwise.
    pub fn from_state(state: RunState, pair_precision: Precision) -> Self {
        let n_mat = state.scene.materials.len();
        let damping = (0..n_mat * n_mat)
            .map(|k| {
                let e = state
                    .scene
                    .pairs
                    .try_get(k / n_mat, k % n_mat)
                    .map_or(1.0, |p| p.restitution);
                hunt_crossley_alpha(e)
            })
            .collect();
        let radius = state.radii();
        let enum_planes = state.scene.enum_planes();
        Simulation {
            state,
            work: Workspace {
                pairs: PairList::default(),
                separating_axes: Vec::new(),
                radius,
                damping,
                dirty: true,
                too_deep: None,
                pair_outcomes: Vec::new(),
                pair_precision,
                enum_planes,
            },
        }
    }

    /// The run's state, the workspace dropped (for another backend).
    pub fn into_state(self) -> RunState {
        self.state
    }

    /// The CPU pipeline on `state` with its first forces evaluated (advancing the springs by
    /// one step, as every evaluation does) and the guard set again with the initial contacts'
    /// elastic energy, which a compressed start releases.
    fn evaluated(state: RunState, pair_precision: Precision) -> Result<Self, SimulationError> {
        let mut sim = Simulation::from_state(state, pair_precision);
        sim.forces(sim.state.dt)?;
        sim.state.reset_guard();
        Ok(sim)
    }

    /// A simulation at t = 0: particles of count insertions placed, forces evaluated.
    fn started(
        scene: Scene,
        parallel: Option<Box<Parallel>>,
        pair_precision: Precision,
    ) -> Result<Self, SimulationError> {
        Simulation::evaluated(RunState::started(scene, parallel)?, pair_precision)
    }

    /// A simulation of `scene` with no particle placed yet (its insertions still to come).
    fn empty(
        scene: Scene,
        parallel: Option<Box<Parallel>>,
        pair_precision: Precision,
    ) -> Result<Self, SimulationError> {
        Simulation::evaluated(RunState::empty(scene, parallel)?, pair_precision)
    }

    /// `self` (without particles) holding a checkpoint's state, its stored forces kept
    /// ([`SimulationBuilder::restore`]).
    fn restored(mut self, state: RestoredState) -> Result<Self, SimulationError> {
        self.state.restore(state)?;
        self.work.dirty = true;
        self.refresh_radii();
        Ok(self)
    }
}

impl RunState {
    /// The state of `scene` at t = 0 with the particles of count insertions placed (in a
    /// decomposed run sent to their owners) and the guard's bounds set; no forces evaluated.
    fn started(scene: Scene, parallel: Option<Box<Parallel>>) -> Result<Self, SimulationError> {
        let mut state = RunState::new(scene, parallel);
        state.exchange(true, |_, _| true)?;
        state.reset_guard();
        Ok(state)
    }

    /// The state of `scene` with no particle placed yet (its insertions still to come).
    fn empty(scene: Scene, parallel: Option<Box<Parallel>>) -> Result<Self, SimulationError> {
        let mut s = scene.clone();
        s.insertions.clear();
        let mut state = RunState::started(s, parallel)?;
        state.inserter = Inserter::new(&scene);
        state.scene = scene;
        Ok(state)
    }

    /// `self` (without particles) holding a checkpoint's state, its stored forces kept.
    fn restore(&mut self, state: RestoredState) -> Result<(), SimulationError> {
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
        self.reset_guard();
        Ok(())
    }
}
