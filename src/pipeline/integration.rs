//! Stage 9, velocity Verlet: the half kick and drift that open a step (9a) and the half kick
//! that closes it (9b) with the forces the step evaluated (`crate::integrate`).

use super::Simulation;
use crate::integrate::{drift, half_kick};
use std::time::Instant;

impl Simulation {
    /// Stage 9a: half kick with the previous evaluation's forces, then drift; the clock
    /// advances by one step.
    pub(super) fn half_kick_and_drift(&mut self) {
        let t0 = Instant::now();
        half_kick(
            &mut self.state.particles,
            &self.state.scene.gravity,
            self.state.dt,
        );
        drift(&mut self.state.particles, self.state.dt);
        self.state.time += self.state.dt;
        self.state.step += 1;
        self.state.timers.integrate += t0.elapsed().as_secs_f64();
    }

    /// Stage 9b: the second half kick, with this step's forces.
    pub(super) fn second_half_kick(&mut self) {
        let t0 = Instant::now();
        half_kick(
            &mut self.state.particles,
            &self.state.scene.gravity,
            self.state.dt,
        );
        self.state.timers.integrate += t0.elapsed().as_secs_f64();
    }
}
