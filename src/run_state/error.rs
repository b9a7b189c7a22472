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
    /// agreed through [`RunState::agree`](super::RunState::agree): a stability stop, a
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

/// Which contact a failed evaluation names: of all whose geometry failed in one step, the one of
/// the smallest key. A particle pair's key is its global ids, lower first; a particle–wall
/// contact's is the particle's id and the wall's index. Keys are global, not positions in a
/// list, so the CPU, the GPU (whose list builds reorder the particles) and any local order name
/// the same contact. Pairs are evaluated before walls, and a pair's failure is reported first.
pub type FailureKey = (u64, u64);

/// The [`FailureKey`] of the pair of particles with global ids `a` and `b`.
pub fn pair_failure_key(a: u64, b: u64) -> FailureKey {
    (a.min(b), a.max(b))
}

/// The failure of the smallest key ([`FailureKey`]) offered by the jobs of a parallel stage,
/// whatever the threads' timing and the list's order (the pair and wall stages).
#[derive(Default)]
pub(crate) struct FirstFailure(std::sync::Mutex<Option<(FailureKey, SimulationError)>>);

impl FirstFailure {
    /// Records a failure; the one of the smallest key is kept.
    pub(crate) fn offer(&self, key: FailureKey, error: SimulationError) {
        // A poisoned lock means a job panicked, which ends the run anyway.
        let mut slot = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if slot.as_ref().is_none_or(|(k, _)| key < *k) {
            *slot = Some((key, error));
        }
    }

    /// `Ok` when nothing failed, else the kept failure.
    pub(crate) fn into_result(self) -> Result<(), SimulationError> {
        match self.0.into_inner().unwrap_or_else(|e| e.into_inner()) {
            Some((_, error)) => Err(error),
            None => Ok(()),
        }
    }
}

/// Of the failures a list-ordered scan found, (position, key) each, the position of the one
/// the CPU stages report (smallest key): for a backend that learns of its failures by scanning flags.
pub fn first_failure_position(
    failures: impl IntoIterator<Item = (usize, FailureKey)>,
) -> Option<usize> {
    failures
        .into_iter()
        .min_by_key(|&(_, key)| key)
        .map(|(position, _)| position)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn failed(step: u64, a: u64, b: u64) -> Result<(), (FailureKey, SimulationError)> {
        Err((
            pair_failure_key(a, b),
            SimulationError::Geometry {
                step,
                what: format!("particles {a} and {b}"),
                message: String::new(),
            },
        ))
    }

    #[test]
    fn the_failure_of_the_smallest_ids_is_reported_whatever_the_list_order() {
        // In list order the pair (9, 4) comes first; by ids (2, 7) is smaller, and a list
        // built in another particle order would have listed it first.
        // Offered in any order, the same one is kept.
        for order in [[0, 1, 2], [2, 1, 0], [1, 2, 0]] {
            let pairs = [(9, 4), (7, 2), (2, 8)];
            let kept = FirstFailure::default();
            for k in order {
                let (a, b) = pairs[k];
                if let Err((key, error)) = failed(0, a, b) {
                    kept.offer(key, error);
                }
            }
            match kept.into_result() {
                Err(SimulationError::Geometry { what, .. }) => {
                    assert_eq!(what, "particles 7 and 2")
                }
                other => panic!("expected the pair (2, 7), got {other:?}"),
            }
        }
        assert!(FirstFailure::default().into_result().is_ok());
        // The flag scan of the GPU picks the same one.
        let flags = [(0, (4, 9)), (3, (2, 7)), (4, (2, 8))];
        assert_eq!(first_failure_position(flags), Some(3));
        assert_eq!(first_failure_position([]), None);
    }
}
