//! Stages 2–8 of a step on the GPU, in order: the pair list (rebuilt when due), the pair
//! contacts ([`super::pair_contacts`]) and the wall contacts ([`super::walls`]), overlapped
//! with a decomposed run's halo refresh ([`super::halo`]), and the deterministic reduction
//! fused with the second half kick ([`super::integrator`]); then the step's geometry errors.

use super::CudaSimulation;
use super::error::CudaError;
use super::layout::CONTACT_FAILED;
use super::pairs::ListSource;
use crate::pipeline::{SimulationError, first_failure_position, pair_failure_key};
use std::time::Instant;

impl CudaSimulation {
    /// Stage 2: the pair list built (the particle arrays reordered), and a decomposed run's
    /// halo set up for the new order.
    pub(super) fn build_pairs(&mut self) -> Result<(), CudaError> {
        let decomposed = self.state.parallel.is_some();
        self.list_builder.begin_build(self.state.step);
        let t0 = Instant::now();
        let host_list =
            self.list_builder
                .source(&self.gpu, &self.particles, self.pairs.generation)?;
        let source = match &host_list {
            Some((list, snapshot)) => ListSource::Host { list, snapshot },
            None => self.list_builder.device_source(),
        };
        let order = self.pairs.build(
            &self.gpu,
            &mut self.particles,
            self.walls.as_mut(),
            decomposed,
            source,
        )?;
        self.gpu.stream.synchronize()?;
        self.list_builder
            .count_build(host_list.is_some(), t0.elapsed().as_secs_f64());
        self.list_builder.end_build();
        if host_list.is_none() {
            self.list_builder.after_build(&self.gpu, &self.particles)?;
        }
        if let Some(par) = self.state.parallel.as_deref() {
            self.halo.setup(&self.gpu, self.particles.n, par, &order)?;
        }
        Ok(())
    }

    /// Stages 2–8: the list (rebuilt when due), the pair and wall contacts and the reduction
    /// into the particles' forces and torques, followed by the second half kick of the step
    /// when `kick` (fused into the reduction's pass over the particles).
    pub(super) fn forces(&mut self, dt: f64, kick: bool) -> Result<(), CudaError> {
        let t0 = Instant::now();
        if self.pairs.rebuild || self.pairs.list.is_none() {
            // The build waits for the device (its counts come back to size the list).
            self.build_pairs()?;
        }
        self.state.timers.neighbor += t0.elapsed().as_secs_f64();
        let st = self.gpu.stream.clone();
        // From here to the error word the host queues work without waiting; the device's
        // stage times come from events (`StageClock`).
        self.gpu.clock.mark(0, &st)?;
        let view = self.particles.view(&st);
        let n_mat = self.state.scene.materials.len() as i32;
        let max_overlap = self.state.guard.max_overlap;
        // A decomposed run between rebuilds: the ghosts' motion is in flight while the pairs of
        // two owned particles are evaluated; the pairs with a ghost follow its arrival.
        let overlap = std::mem::take(&mut self.halo.due);
        let (np, n_interior) = {
            let q = self.pairs.list.as_ref().expect("built above");
            (q.n, if overlap { q.n_interior } else { q.n })
        };
        let args = self.pairs.args(&self.gpu, &view, n_mat, dt, max_overlap);
        self.pairs.clear_deferred(&self.gpu)?;
        // The walls' facet overlaps read only the particles' poses, final for this step once
        // the ghosts' have arrived: they run on the wall stream alongside the pairs. In a
        // decomposed run they are queued behind the interior pairs (the ghosts arrive while
        // those run), so they overlap only the ghosts' and the deferred pairs.
        let mut wall_host = 0.0;
        if !overlap {
            wall_host += self.start_wall_overlaps(&view)?;
        }
        if overlap {
            self.halo.start(&self.gpu, &self.particles)?;
        }
        self.pairs.launch(&self.gpu, 0, n_interior, &args)?;
        if overlap {
            if let Some(par) = self.state.parallel.as_deref_mut() {
                self.halo.finish(&self.gpu, &mut self.particles, par)?;
            }
            wall_host += self.start_wall_overlaps(&view)?;
            self.pairs.launch(&self.gpu, n_interior, np, &args)?;
        }
        let spheres_only = self.state.scene.spheres_only();
        self.pairs.launch_deferred(&self.gpu, &args, spheres_only)?;
        self.gpu.clock.mark(1, &st)?;
        if super::kernels::phase_clocks() {
            self.gpu.report_phase_clocks()?;
        }
        if let Some(w) = self.walls.as_mut() {
            w.finish(&self.gpu, self.particles.n, &view, n_mat, dt, max_overlap)?;
        }
        self.gpu.clock.mark(2, &st)?;
        let g = self.state.scene.gravity;
        let pairs = self.pairs.list.as_mut().expect("built above");
        self.integrator.reduce_and_kick(
            &self.gpu,
            &mut self.particles,
            pairs,
            self.walls.as_ref(),
            g,
            dt,
            kick,
        )?;
        // The walls' springs just computed are the history of the next evaluation (the pairs'
        // were updated in place, `PairList::spring`).
        if let Some(w) = &mut self.walls {
            std::mem::swap(&mut w.spring_in, &mut w.spring_out);
        }
        self.gpu.clock.mark(3, &st)?;
        let mut error = [0u32; 3];
        st.memcpy_dtoh(&self.gpu.error, &mut error)?;
        // The pairs' span includes the host's wall work queued inside it (a wall list build
        // waits for its count); that is the walls' time.
        let [pairs, walls, reduce] = self.gpu.clock.spans()?;
        self.state.timers.pairs += (pairs - wall_host).max(0.0);
        self.state.timers.walls += walls + wall_host;
        self.state.timers.reduce += reduce;
        // A geometry error fails the step; the fused kick has already applied this step's
        // forces to the velocities on the device (the run stops with the error: `engine.step()?`).
        if error[0] != 0 || error[1] != 0 {
            return Err(self.geometry_error(error).into());
        }
        self.host_current = false;
        let overlaps = if error[2] != 0 {
            // The stability guard's overlap bound (cuda/contact.cu `guard_overlap`).
            self.sync_host()?;
            Err(self.too_deep((u32::MAX - error[2]) as usize))
        } else {
            Ok(())
        };
        // In a decomposed run every rank stops after this step if one does
        // ([`RunState::agree`]).
        Ok(self.state.agree(overlaps)?)
    }

    /// The guard's error for the device's report that a contact of slot `i` overlaps past the
    /// bound, from the synced host state.
    fn too_deep(&self, i: usize) -> SimulationError {
        let step = self.state.step;
        let n = self.state.particles.len();
        if i >= n {
            // A pair is reported by its lower slot, and ghosts follow the owned particles, so
            // this is not expected; should it happen, the ghost is named by its global id and
            // its owner's contacts are that rank's.
            let ghosts = self
                .state
                .parallel
                .as_deref()
                .map(|p| &p.ghosts.particles.id);
            return SimulationError::Unstable {
                step,
                id: ghosts
                    .and_then(|g| g.get(i - n).copied())
                    .unwrap_or(u64::MAX),
                problem: format!(
                    "a contact of this ghost overlaps more than {} of the smaller particle's \
                     volume (simulation.guard.max_overlap)",
                    self.state.guard.max_overlap
                ),
                contacts: "on its owner's rank".into(),
            };
        }
        // The device names no partner: the host evaluates the particle's overlaps with
        // the others in f64 from the same positions (those of the force evaluation; the
        // fused kick changed only velocities), which tells a deep contact from a device
        // geometry that differs from f64.
        let host = self
            .state
            .deepest_particle_overlap(i)
            .map(|(id, x)| (format!("particle {id}"), x));
        let problem = crate::stability::Instability::DeepContact {
            fraction: self.state.guard.max_overlap,
            host,
        };
        self.state.unstable(i, Some(problem))
    }

    /// Stage 6, first part ([`super::walls::WallStage::start_overlaps`]) at the current time;
    /// returns the host seconds spent (a list build waits for its count).
    fn start_wall_overlaps(
        &mut self,
        view: &super::layout::ParticleView,
    ) -> Result<f64, CudaError> {
        let t0 = Instant::now();
        let Some(w) = self.walls.as_mut() else {
            return Ok(0.0);
        };
        w.start_overlaps(
            &self.gpu,
            &self.particles,
            view,
            &self.state.scene,
            self.state.time,
        )?;
        Ok(t0.elapsed().as_secs_f64())
    }

    /// The geometry error the kernels recorded (`report_error` of cuda/contact.cu): a failed
    /// pair if any failed, else a failed particle–wall contact; of those, the one of the
    /// smallest global ids ([`FailureKey`](crate::pipeline::FailureKey)), found from the
    /// contact flags the kernels set on failure (`PD_CONTACT_FAILED`), so the CPU and the GPU,
    /// whatever its particle order, name the same contact.
    fn geometry_error(&self, error: [u32; 3]) -> SimulationError {
        let key = !(u64::from(error[0]) | (u64::from(error[1]) << 32));
        // The error word's own choice (smallest list slot), should the flags not be readable.
        let (source, index, status) = (key >> 40, (key >> 8) & 0xffff_ffff, key & 0xff);
        let step = self.state.step;
        let st = &self.gpu.stream;
        let ids = st.clone_dtoh(&self.particles.id).unwrap_or_default();
        let id = |slot: usize| {
            ids.get(slot)
                .map_or(format!("slot {slot}"), |g| g.to_string())
        };
        let failed = |flag: u32| (flag & CONTACT_FAILED != 0).then_some(flag & 0xff);
        let (what, status) = if source == 0 {
            let flagged = self.pairs.list.as_ref().and_then(|p| {
                let (slots, flags) = (p.slots(st).ok()?, p.flags(st).ok()?);
                let failures = (0..slots.len())
                    .filter(|&k| failed(flags[k]).is_some())
                    .map(|k| {
                        let [a, b] = slots[k];
                        let key = match (ids.get(a), ids.get(b)) {
                            (Some(&ia), Some(&ib)) => pair_failure_key(ia, ib),
                            _ => (u64::MAX, k as u64),
                        };
                        (k, key)
                    });
                let k = first_failure_position(failures)?;
                let [a, b] = slots[k];
                Some((a, b, failed(flags[k])?))
            });
            match flagged {
                Some((a, b, status)) => (
                    format!("particles {} and {}", id(a), id(b)),
                    u64::from(status),
                ),
                None => (format!("pair slot {index}"), status),
            }
        } else {
            let walls = self.state.scene.walls.len().max(1);
            let flagged = self.walls.as_ref().and_then(|w| {
                let flags = w.flags(st).ok()?;
                // The CPU evaluates the walls of its owned particles only: a decomposed run's
                // ghosts, whose walls the device evaluates too, are their owners' to name.
                let ghost = st.clone_dtoh(&self.particles.ghost).ok()?;
                let n = self.particles.n * walls;
                let failures = (0..n.min(flags.len()))
                    .filter(|&s| failed(flags[s]).is_some() && ghost.get(s / walls) == Some(&0))
                    .map(|s| {
                        let particle = ids.get(s / walls).copied().unwrap_or(u64::MAX);
                        (s, (particle, (s % walls) as u64))
                    });
                let s = first_failure_position(failures)?;
                Some((s, failed(flags[s])?))
            });
            let (slot, status) =
                flagged.map_or((index, status), |(s, st)| (s as u64, u64::from(st)));
            let (i, k) = (slot as usize / walls, slot as usize % walls);
            let name = self
                .state
                .scene
                .walls
                .get(k)
                .map_or("?", |w| w.name.as_str());
            (format!("particle {} and wall {name}", id(i)), status)
        };
        let message = format!("geometry status {status} (cuda/polytope.cuh status codes)");
        SimulationError::Geometry {
            step,
            what,
            message,
        }
    }
}
