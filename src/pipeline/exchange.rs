//! Stage 1 on the CPU pipeline: the run state's exchange ([`RunState::exchange`]: insertion,
//! removal, wrapping, the decomposition's part), with the pair list's rebuild decided by it and
//! the radii brought up to date.
//!
//! [`RunState::exchange`]: crate::run_state::RunState::exchange

use super::{Simulation, SimulationError};

impl Simulation {
    /// Stage 1: insert due particles, drop those outside a closed domain, wrap periodic axes;
    /// in a decomposed run also migration and the halo exchange.
    pub(super) fn exchange(&mut self) -> Result<(), SimulationError> {
        let pairs = &self.work.pairs;
        self.work.dirty = self.state.exchange(self.work.dirty, |x, bounds| {
            pairs.moved_beyond_half_skin(x, bounds)
        })?;
        self.refresh_radii();
        Ok(())
    }

    /// The decomposed part of stage 1 alone ([`RunState::exchange_decomposed`]), for a state
    /// edited in place ([`Simulation::refresh`]).
    ///
    /// [`RunState::exchange_decomposed`]: crate::run_state::RunState::exchange_decomposed
    pub(super) fn parallel_exchange(&mut self) -> Result<(), SimulationError> {
        let need = self.work.dirty
            || self
                .work
                .pairs
                .moved_beyond_half_skin(&self.state.particles.position, &self.state.bounds);
        if self.state.exchange_decomposed(need)? {
            self.work.dirty = true;
            self.refresh_radii();
        }
        Ok(())
    }

    /// Each particle's bounding (circumscribed) radius, for the broad phase.
    pub(super) fn refresh_radii(&mut self) {
        self.work.radius = self.state.radii();
    }
}
