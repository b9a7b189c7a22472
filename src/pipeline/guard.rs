//! The stability guard's checks on the CPU pipeline (`crate::stability`): speeds and
//! finiteness after the drift, with the cached radii, and overlaps after the force evaluation.
//! The guard's bounds, its agreement among ranks and its errors are the run state's
//! ([`crate::run_state::RunState::agree`]).

use super::{Simulation, SimulationError};
use crate::stability::Instability;
use rayon::prelude::*;

impl Simulation {
    /// The stability guard's finiteness and speed checks after the drift: the first particle
    /// (by index) past a bound stops the step.
    pub fn check_motion(&self) -> Result<(), SimulationError> {
        let (s, radius) = (&self.state, &self.work.radius);
        let p = &s.particles;
        let n = p.len().min(radius.len());
        let found = (0..n)
            .into_par_iter()
            .with_min_len(crate::par::CHEAP)
            .find_first(|&i| s.guard.check_motion(p, radius[i], i).is_some());
        match found {
            Some(i) => Err(s.unstable(i, s.guard.check_motion(p, radius[i], i))),
            None => Ok(()),
        }
    }

    /// The stability guard's overlap check on the last force evaluation.
    pub(super) fn check_overlaps(&self) -> Result<(), SimulationError> {
        match &self.work.too_deep {
            Some((i, partner, volume, particle)) => Err(self.state.unstable(
                *i,
                Some(Instability::Overlap {
                    partner: partner.clone(),
                    volume: *volume,
                    particle_volume: *particle,
                    fraction: self.state.guard.max_overlap,
                }),
            )),
            None => Ok(()),
        }
    }
}
