//! What a running simulation reports besides its state: its errors and its stage timers.

use crate::domain::{DecompositionError, ExchangeError};
use crate::scene::SceneError;

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
    /// A decomposed run's other ranks stopped it at this step: their own errors (the guard's,
    /// a non-finite value, a particle leaving the domain) name the cause.
    #[error(
        "step {step}: the run stops at this step with rank(s) {ranks:?}, whose error names the particle and the cause"
    )]
    Stopped { step: u64, ranks: Vec<usize> },
}

impl SimulationError {
    /// Whether every rank of a decomposed run left the same step with an error of this kind,
    /// agreed through [`Simulation::agree`](super::Simulation::agree): a stability stop, a
    /// non-finite value, a particle leaving through a closed face, or another rank's stop.
    /// The ranks can then still work together (write the stopped state, end MPI in order);
    /// after any other error the failing rank ends them all.
    pub fn stops_every_rank(&self) -> bool {
        matches!(
            self,
            SimulationError::Unstable { .. }
                | SimulationError::NonFinite { .. }
                | SimulationError::LeftDomain { .. }
                | SimulationError::Stopped { .. }
        )
    }
}

/// The decomposition's exchange errors as the variants a single-rank run would report: a
/// scene or decomposition error as is, inconsistent ghosts as a domain error of the step.
impl From<ExchangeError> for SimulationError {
    fn from(e: ExchangeError) -> Self {
        match e {
            ExchangeError::Scene(e) => SimulationError::Scene(e),
            ExchangeError::Decomposition(e) => SimulationError::Decomposition(e),
            ExchangeError::Ghosts { step, message } => SimulationError::Domain { step, message },
        }
    }
}
