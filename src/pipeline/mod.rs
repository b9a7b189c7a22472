//! The simulation and its step: every stage of docs/design.md §1, in order.
//!
//! The translational and rotational integration is velocity Verlet: forces at the start of a
//! step are those of the previous force evaluation, so [`Simulation::step`] runs
//!
//! - 9a: half kick and drift (integrate, first half; `integration.rs`);
//! - 1: exchange (insertion of due particles, removal of those that left a closed domain,
//!   periodic wrapping; in a decomposed run migration and the halo exchange of
//!   [`crate::domain`]; `exchange.rs`);
//! - 2: neighbour list (rebuilt when some particle moved half the skin; `neighbors.rs`);
//! - 3–7: per pair, bounding-sphere broad phase, narrow phase (the interior-point LP's proof of an
//!   intersection, GJK where it proves none), dual-space overlap, contact law (`pairs.rs`); per
//!   particle and wall, facet contacts and the contact law (stage 6, `walls.rs`);
//! - 8: deterministic per-particle reduction (pairs in partner-id order, then walls in order;
//!   `reduction.rs`);
//! - 9b: second half kick (integrate, second half);
//!
//! with the stability guard's checks between them (`guard.rs`); output (stage 10) is driven by
//! the caller between steps ([`crate::run`]). Stages a scene does not need are skipped: no
//! walls, no wall stage; μ = 0, no tangential history. A simulation starts from a
//! [`SimulationBuilder`] ([`Simulation::builder`]).

mod builder;
mod exchange;
mod guard;
mod integration;
mod neighbors;
mod pairs;
mod reduction;
mod walls;

pub use crate::run_state::{
    FailureKey, RunState, SimulationError, StageTimers, StepStats, first_failure_position,
    pair_failure_key,
};
pub use builder::{RestoredState, SimulationBuilder};

use crate::neighbor::PairList;
use nalgebra::Vector3;
use std::time::Instant;

/// A running simulation on the CPU backend: the run's state and the pipeline's workspace.
pub struct Simulation {
    /// What the run is (scene, particles, history, clock, decomposition, guard, observables),
    /// as either backend holds it.
    pub state: RunState,
    work: Workspace,
}

/// What the CPU pipeline keeps between steps besides the run's state: the candidate pair
/// list and what is indexed by it, the particles' bounding radii, the contact law's damping
/// table, and the last evaluation's deepest contact.
struct Workspace {
    pairs: PairList,
    /// Per pair of `pairs`, the axis that separated it at the last evaluation (zero: none
    /// known), tried before GJK ([`crate::geometry::pair::axis_separates`]); cleared when
    /// the list is rebuilt.
    separating_axes: Vec<Vector3<f64>>,
    /// Each particle's circumscribed radius, in the order of the particle arrays (with a
    /// decomposed run's ghosts appended during a force evaluation).
    radius: Vec<f64>,
    /// Hunt–Crossley `ᾱ(e)` per material pair (`a * materials + b`).
    damping: Vec<f64>,
    /// The pair list must be rebuilt at the next evaluation.
    dirty: bool,
    /// The contact of the last force evaluation past the guard's overlap bound, if any:
    /// (particle index, what it overlaps, overlap volume, the smaller particle volume).
    too_deep: Option<(usize, String, f64, f64)>,
    /// The pair stage's outcome buffer, kept between evaluations for its capacity
    /// ([`Simulation::pair_stage`]).
    pair_outcomes: Vec<pairs::PairOutcome>,
    /// Arithmetic of the polyhedral pair geometry: f64, or the GPU's mixed precision
    /// ([`crate::geometry::pair::overlap_pair_mixed`]), so that a mixed-precision run can be
    /// reproduced and checked without a GPU.
    pair_precision: crate::geometry::pair::Precision,
    /// The scene's limit of the vertex enumeration ([`crate::scene::Scene::enum_planes`]), set
    /// on the thread's workspaces before each overlap.
    enum_planes: usize,
}

impl Simulation {
    /// Advances one time step (the stage order of docs/design.md §1; see the module docs).
    ///
    /// The guard's checks run twice: after the drift (speed, finiteness, a particle leaving
    /// through a closed face), and at the end (overlaps, finiteness). In a decomposed run the
    /// ranks agree on each outcome ([`RunState::agree`]), so that all stop after the same step.
    pub fn step(&mut self) -> Result<(), SimulationError> {
        self.half_kick_and_drift(); // 9a
        let moved = self.check_motion().and_then(|()| self.state.check_inside());
        self.state.agree(moved)?;
        self.exchange()?; // 1
        self.forces(self.state.dt)?; // 2–8
        self.second_half_kick(); // 9b
        let end = self
            .check_overlaps()
            .and_then(|()| self.state.check_finite());
        self.state.agree(end)
    }

    /// Stages 2–8 at the current state, advancing the contact history by `dt` (zero: the
    /// forces of the state as it is, the history left to the caller).
    fn forces(&mut self, dt: f64) -> Result<(), SimulationError> {
        let t_forces = Instant::now();
        let owned = self.join_ghosts();
        self.neighbor_list(owned); // 2
        let pair_outcomes = self.pair_stage(dt, owned)?; // 3–7 (ghosts dropped again)
        let wall_outcomes = self.wall_stage(dt)?; // 6
        self.reduce(owned, &pair_outcomes, &wall_outcomes); // 8
        self.work.pair_outcomes = pair_outcomes;
        if let Some(par) = self.state.parallel.as_deref_mut() {
            par.cost += t_forces.elapsed().as_secs_f64();
        }
        Ok(())
    }

    /// Re-evaluates forces after the particle state was edited directly (tests, set-up
    /// tools): neighbour lists and radii are rebuilt, the contact history is kept as is.
    pub fn refresh(&mut self) -> Result<(), SimulationError> {
        self.work.dirty = true;
        self.refresh_radii();
        self.state.reset_guard();
        if self.state.parallel.is_some() {
            self.parallel_exchange()?;
        }
        let saved = self.state.history.clone();
        self.forces(0.0)?;
        self.state.history = saved;
        self.state.reset_guard();
        Ok(())
    }

    /// The arithmetic of the polyhedral pair geometry ([`SimulationBuilder::pair_precision`]).
    pub fn pair_precision(&self) -> crate::geometry::pair::Precision {
        self.work.pair_precision
    }

    /// Sets the arithmetic of the polyhedral pair geometry from the next force evaluation on
    /// (a checkpoint does not record it: a restart chooses again).
    pub fn set_pair_precision(&mut self, precision: crate::geometry::pair::Precision) {
        self.work.pair_precision = precision;
    }

    /// Pair lists built so far (the first one included).
    pub fn pair_list_builds(&self) -> u64 {
        self.work.pairs.builds
    }

    /// The candidate pair list of stage 2 as global-id pairs (lower id first), sorted: what the
    /// GPU's list must equal after a build from the same positions.
    pub fn candidate_pair_ids(&self) -> Vec<(u64, u64)> {
        let id = &self.state.particles.id;
        let mut v: Vec<(u64, u64)> = self
            .work
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
}
