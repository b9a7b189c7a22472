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
mod error;
mod exchange;
mod guard;
mod integration;
mod neighbors;
mod pairs;
mod reduction;
mod walls;

pub use crate::state::StepStats;
pub use builder::{RestoredState, SimulationBuilder};
pub use error::{
    FailureKey, SimulationError, StageTimers, first_failure_position, pair_failure_key,
};

use crate::contact::{ContactHistory, WallMesh};
use crate::domain::Parallel;
use crate::domain::collect::RankState;
use crate::neighbor::{Bounds, PairList};
use crate::scene::{Inserter, Scene};
use crate::stability::StabilityGuard;
use crate::state::Particles;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::time::Instant;

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
    /// The last evaluation's elastic energy and wall forces as exact sums, which the ranks of a
    /// decomposed run merge into the whole run's (`crate::exact_sum`).
    pub sums: crate::exact_sum::DiagnosticSums,
    /// This rank's part of a decomposed run (`None`: one rank, the whole domain).
    pub parallel: Option<Box<Parallel>>,
    pairs: PairList,
    /// Per pair of `pairs`, the axis that separated it at the last evaluation (zero: none
    /// known), tried before GJK ([`crate::geometry::pair::axis_separates`]); cleared when
    /// the list is rebuilt.
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
    /// The pair stage's outcome buffer, kept between evaluations for its capacity
    /// ([`Simulation::pair_stage`]).
    pair_outcomes: Vec<pairs::PairOutcome>,
    /// Arithmetic of the polyhedral pair geometry: f64, or the GPU's mixed precision
    /// ([`crate::geometry::pair::overlap_pair_mixed`]), so that a mixed-precision run can be
    /// reproduced and checked without a GPU.
    pair_precision: crate::geometry::pair::Precision,
}

impl Simulation {
    /// Advances one time step (the stage order of docs/design.md §1; see the module docs).
    ///
    /// The guard's checks run twice: after the drift (speed, finiteness, a particle leaving
    /// through a closed face), and at the end (overlaps, finiteness). In a decomposed run the
    /// ranks agree on each outcome ([`Self::agree`]), so that all stop after the same step.
    pub fn step(&mut self) -> Result<(), SimulationError> {
        self.half_kick_and_drift(); // 9a
        let moved = self.check_motion().and_then(|()| self.check_inside());
        self.agree(moved)?;
        self.exchange()?; // 1
        self.forces(self.dt)?; // 2–8
        self.second_half_kick(); // 9b
        let end = self.check_overlaps().and_then(|()| self.check_finite());
        self.agree(end)
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
        self.pair_outcomes = pair_outcomes;
        if let Some(par) = self.parallel.as_deref_mut() {
            par.cost += t_forces.elapsed().as_secs_f64();
        }
        Ok(())
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
        self.forces(0.0)?;
        self.history = saved;
        self.reset_guard();
        Ok(())
    }

    /// Scales a fully periodic box and every particle centre about the box's lower corner by
    /// `factor` (below 1 compresses), then re-evaluates the forces as [`Simulation::refresh`]
    /// does: the affine step of a compression packing (`polydem pack`, [`crate::run::pack`]).
    /// Velocities and the contact history are the caller's. Refused for a box that is not
    /// periodic on every axis, a scene with walls, or a decomposed run, where a uniform
    /// rescaling would move particles through walls or across ranks.
    pub fn rescale_periodic_box(&mut self, factor: f64) -> Result<(), SimulationError> {
        let step = self.step;
        let refuse = |message: String| Err(SimulationError::Domain { step, message });
        if !(factor > 0.0 && factor.is_finite()) {
            return refuse(format!("box scale factor must be positive, got {factor}"));
        }
        if self.bounds.periodic != [true; 3] || !self.scene.walls.is_empty() {
            return refuse(
                "only a box periodic on every axis and without walls can be rescaled".into(),
            );
        }
        if self.parallel.is_some() {
            return refuse("a decomposed run cannot be rescaled".into());
        }
        let min = self.bounds.min;
        let max = min + (self.bounds.max - min) * factor;
        // As scene validation requires: no particle may touch two images of another.
        let least = self.scene.least_periodic_extent();
        if let Some(k) = (0..3).find(|&k| max[k] - min[k] < least) {
            return refuse(format!(
                "the box would be {:.6e} m along axis {k}, less than twice the reach of a \
                 contact ({:.6e} m): a particle could touch two images of another",
                max[k] - min[k],
                least
            ));
        }
        for x in self.particles.position.iter_mut() {
            *x = min + (*x - min) * factor;
        }
        self.bounds.max = max;
        self.scene.domain.max = max;
        self.refresh()
    }

    /// The arithmetic of the polyhedral pair geometry ([`SimulationBuilder::pair_precision`]).
    pub fn pair_precision(&self) -> crate::geometry::pair::Precision {
        self.pair_precision
    }

    /// Sets the arithmetic of the polyhedral pair geometry from the next force evaluation on
    /// (a checkpoint does not record it: a restart chooses again).
    pub fn set_pair_precision(&mut self, precision: crate::geometry::pair::Precision) {
        self.pair_precision = precision;
    }

    /// Pair lists built so far (the first one included).
    pub fn pair_list_builds(&self) -> u64 {
        self.pairs.builds
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
        let [kt, kr, pg] = self.energy_sums();
        (kt.value(), kr.value(), pg.value())
    }

    /// The energies of [`Simulation::energies`] as exact sums, which ranks merge.
    pub fn energy_sums(&self) -> [crate::exact_sum::ExactSum; 3] {
        let p = &self.particles;
        let g = self.scene.gravity;
        let terms: Vec<[f64; 3]> = (0..p.len())
            .into_par_iter()
            .with_min_len(crate::par::CHEAP)
            .map(|i| {
                let wb = p.orientation[i].inverse_transform_vector(&p.angular_velocity[i]);
                [
                    0.5 * p.mass[i] * p.velocity[i].norm_squared(),
                    0.5 * wb.component_mul(&p.inertia[i]).dot(&wb),
                    -p.mass[i] * g.dot(&p.position[i]),
                ]
            })
            .collect();
        // Exact sums: the same bits whatever the order of the particles, their grouping into
        // threads or ranks, the backend or a restart.
        let mut sums: [crate::exact_sum::ExactSum; 3] = Default::default();
        for t in &terms {
            for (s, x) in sums.iter_mut().zip(t) {
                s.add(*x);
            }
        }
        sums
    }
}

/// The whole-run views of a decomposed run read a rank's state through this.
impl RankState for Simulation {
    fn owned_particles(&self) -> &Particles {
        &self.particles
    }

    fn contact_history(&self) -> &ContactHistory {
        &self.history
    }

    fn step_stats(&self) -> &StepStats {
        &self.stats
    }

    fn energy_sums(&self) -> [crate::exact_sum::ExactSum; 3] {
        Simulation::energy_sums(self)
    }

    fn diagnostic_sums(&self) -> &crate::exact_sum::DiagnosticSums {
        &self.sums
    }
}
