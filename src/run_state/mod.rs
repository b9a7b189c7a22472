//! What a run is, whichever backend steps it: the scene, the particles and their contact
//! history, the clock, the inserter, the decomposition, the stability guard and the last
//! evaluation's observables.
//!
//! Both backends own one [`RunState`]: the CPU pipeline ([`crate::pipeline::Simulation`]) beside
//! its workspace (pair list, radii, separating axes), the GPU one
//! ([`crate::backend::cuda::CudaSimulation`]) as its host copy, current after a sync. What
//! either does to it between force evaluations lives here, once: the host part of stage 1
//! (insertion, removal, the decomposition's exchange; `exchange.rs`), the guard's agreement
//! among ranks and its errors (`guard.rs`), the energies, a periodic box's rescaling.

mod error;
mod exchange;
mod guard;

pub(crate) use error::FirstFailure;
pub use error::{
    FailureKey, SimulationError, StageTimers, first_failure_position, pair_failure_key,
};

use crate::contact::{ContactHistory, WallMesh};
use crate::domain::Parallel;
use crate::domain::collect::RankState;
use crate::neighbor::Bounds;
use crate::scene::{Inserter, Scene};
use crate::stability::StabilityGuard;
use crate::state::Particles;
pub use crate::state::StepStats;
use nalgebra::Vector3;
use rayon::prelude::*;

/// The state of a run, as both backends hold it (see the module docs).
pub struct RunState {
    /// The scene it runs.
    pub scene: Scene,
    /// Particle state (this rank's owned particles in a decomposed run).
    pub particles: Particles,
    /// Live contacts' history.
    pub history: ContactHistory,
    /// Wall meshes in their t = 0 frames (in a decomposed run the facets this rank needs:
    /// those within reach of its box).
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
    /// The stability guard's bounds (`crate::stability`), set when particles are placed.
    pub guard: StabilityGuard,
    /// The domain's box and periodicity (the scene's `[domain]`, rescaled with it).
    pub bounds: Bounds,
}

impl RunState {
    /// This rank's part of a decomposed run, on paths that only a decomposed run takes.
    ///
    /// # Panics
    /// In a single-rank run.
    pub fn part(&self) -> &Parallel {
        self.parallel.as_deref().expect("a decomposed run")
    }

    /// This rank's part of a decomposed run, mutable (see [`RunState::part`]).
    ///
    /// # Panics
    /// In a single-rank run.
    pub fn part_mut(&mut self) -> &mut Parallel {
        self.parallel.as_deref_mut().expect("a decomposed run")
    }

    /// The state of `scene` at t = 0 before anything is placed: no particles, the walls meshed
    /// for this rank, the guard off until [`RunState::reset_guard`].
    pub(crate) fn new(scene: Scene, parallel: Option<Box<Parallel>>) -> Self {
        let bounds = Bounds {
            min: scene.domain.min,
            max: scene.domain.max,
            periodic: scene.domain.periodic,
        };
        let dt = scene.time_step();
        let inserter = Inserter::new(&scene);
        let n_walls = scene.walls.len();
        let mut state = RunState {
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
            guard: StabilityGuard {
                enabled: false,
                max_speed: f64::INFINITY,
                max_overlap: f64::INFINITY,
                speed_scale: 0.0,
            },
            bounds,
        };
        state.restrict_walls();
        state
    }

    /// Scales a fully periodic box and every particle centre about the box's lower corner by
    /// `factor` (below 1 compresses): the affine step of a compression packing (`polydem
    /// pack`, [`crate::run::pack`]). The forces are then those of the old box until the
    /// backend evaluates them again ([`crate::backend::Backend::refresh`]). Velocities and the
    /// contact history are the caller's. Refused for a box that is not periodic on every axis,
    /// a scene with walls, or a decomposed run, where a uniform rescaling would move particles
    /// through walls or across ranks.
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
        Ok(())
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

    /// The energies of [`RunState::energies`] as exact sums, which ranks merge.
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
impl RankState for RunState {
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
        RunState::energy_sums(self)
    }

    fn diagnostic_sums(&self) -> &crate::exact_sum::DiagnosticSums {
        &self.sums
    }
}
