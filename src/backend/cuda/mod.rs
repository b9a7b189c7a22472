//! The CUDA backend: host side (cudarc). Kernels live in `cuda/` and are compiled at run time by
//! NVRTC ([`kernels`]); the structs they share with Rust are in [`layout`].
//!
//! [`CudaSimulation`] is composed of one part per expensive stage, each owning its device
//! buffers (as HOOMD-blue pairs a GPU class with each expensive CPU class): the particle arrays
//! (`particles`, declared by one field table), the pair list (`pairs`, evaluated in
//! `pair_contacts`), the walls (`walls`), a decomposed run's halo (`halo`) and the time
//! integration (`integrator`), over what they all share (`gpu`: context, streams, the kernels
//! of `launch`, the scene's constants). `forces` runs stages 2–8 in order, `upload` and `sync`
//! move the state between host and device, `history` converts the contact history between
//! the device's slots and the host's keys, and `simulation` makes one and reports on it.
//!
//! The step on the GPU: [`CudaSimulation`] keeps the particle state, the pair list and the
//! contact history resident on the device and launches the kernels of `cuda/` stage by stage in
//! the order of docs/design.md §1, as [`Simulation::step`](crate::pipeline::Simulation::step) runs them on the CPU (kick and drift,
//! the ranks' agreement, the exchange, the forces). The host copy in [`CudaSimulation::state`]
//! is refreshed only when it is read (output, checkpoint) or changed (insertion, removal), so an
//! ordinary step copies nothing back but its status flags and error word (28 bytes).

mod backend;
mod error;
mod exchange;
mod forces;
mod gpu;
mod halo;
mod history;
mod integrator;
pub mod kernels;
mod launch;
pub mod layout;
mod list_builder;
mod pair_contacts;
mod pair_list;
mod pairs;
mod particles;
pub mod probe;
mod rebuild_records;
mod simulation;
mod sync;
mod upload;
mod walls;

pub use error::{CudaError, HaloError};
pub use kernels::{CompileError, KernelConfig, Precision};

use crate::run_state::{RunState, SimulationError};
use gpu::Gpu;
use halo::HaloStage;
use integrator::{DriftChecks, Integrator};
use layout::StepFlags;
use list_builder::ListBuilder;
use pairs::PairStage;
use particles::DeviceParticles;
use std::time::Instant;
use walls::WallStage;

/// Waits for the wall stream before anything is freed: the fields drop in declaration order,
/// and a step that failed between the walls' two events (a CUDA error, a guard stop) can leave
/// `wall_facet_overlaps` queued on it, reading particle arrays and the wall list that would
/// otherwise be freed under it. The main stream is waited for too (cudarc frees a slice on its
/// own stream, but the wall stream's kernels read the main stream's slices).
impl Drop for CudaSimulation {
    fn drop(&mut self) {
        // Errors here have nowhere to go; the context reports them on its next use.
        let _ = self.gpu.wall_stream.stream.synchronize();
        let _ = self.gpu.stream.synchronize();
    }
}

/// A simulation stepped on the GPU. See the module docs.
pub struct CudaSimulation {
    /// The run's state on the host: scene, inserter, time, step, statistics, and (when
    /// synced) the particles and their contact history.
    pub state: RunState,
    /// Device name.
    pub device: String,
    /// Arithmetic of the pair geometry.
    pub precision: Precision,
    /// The device, its streams and kernels, and the scene's constants.
    gpu: Gpu,
    /// The particle arrays (with a decomposed run's ghosts).
    particles: DeviceParticles,
    /// Stage 2: the pair list, and everything indexed by pair.
    pairs: PairStage,
    /// Stage 2: who builds the pair list (`[simulation.neighbor] mode`).
    list_builder: ListBuilder,
    /// Stage 6: the walls, `None` without walls.
    walls: Option<WallStage>,
    /// A decomposed run's halo ([`super::halo`]).
    halo: HaloStage,
    /// Stage 9: the two passes over the particle state.
    integrator: Integrator,
    /// The host copy holds the device state (no step since the last sync or upload).
    host_current: bool,
}

impl CudaSimulation {
    /// Advances one time step: the stage order of [`Simulation::step`](crate::pipeline::Simulation::step), in two passes over the
    /// particle state (`kick_drift` and, after the contacts, `reduce_and_kick` of
    /// cuda/integrate.cu).
    pub fn step(&mut self) -> Result<(), CudaError> {
        let dt = self.state.dt;
        let flags = self.half_kick_and_drift()?; // 9a, with stage 1's wrap and the checks
        let t0 = Instant::now();
        let moved = self.check_motion(&flags)?;
        // In a decomposed run every rank stops after this step if one does
        // ([`RunState::agree`]).
        self.state.agree(moved)?;
        self.exchange(&flags)?; // 1
        self.state.timers.exchange += t0.elapsed().as_secs_f64();
        // The contacts (2–8), then the reduction with the second half kick (9b).
        self.forces(dt, true)
    }

    /// Stage 9a on the device: the first half kick and the drift, with the periodic wrap and
    /// the per-step checks (the list's validity, a particle leaving, speed and finiteness)
    /// reduced into the step's flags; the host's clock advances.
    fn half_kick_and_drift(&mut self) -> Result<StepFlags, CudaError> {
        let t0 = Instant::now();
        // The device state changes from here on: the host copy is stale until synced again.
        self.host_current = false;
        let g = self.state.scene.gravity;
        let dt = self.state.dt;
        // The checks need the list's reference positions; before the first build there are none.
        let checks = self.particles.n > 0 && self.pairs.list.is_some();
        let (wall_reference, wall_half_reach) = match &mut self.walls {
            Some(w) if checks => w.check(&self.gpu, &self.state.scene, self.state.time + dt),
            _ => (0u64, 0.0),
        };
        let limits = DriftChecks {
            reference: &self.pairs.reference,
            half_skin: self.pairs.half_skin,
            snapshot_distance: self.list_builder.snapshot_distance(),
            wall_reference,
            wall_half_reach,
            max_speed: self.state.guard.max_speed,
        };
        let wrap = self.gpu.config.periodic;
        let flags = self.integrator.kick_drift(
            &self.gpu,
            &mut self.particles,
            g,
            dt,
            wrap,
            checks,
            limits,
        )?;
        self.state.time += dt;
        self.state.step += 1;
        self.state.timers.integrate += t0.elapsed().as_secs_f64();
        Ok(flags)
    }

    /// The guard's verdict on the motion: the first particle the device flagged as unstable,
    /// named from a synced host copy (the outer error: that copy failed).
    fn check_motion(
        &mut self,
        flags: &StepFlags,
    ) -> Result<Result<(), SimulationError>, CudaError> {
        if flags.unstable == 0 {
            return Ok(Ok(()));
        }
        self.sync_host()?;
        let i = flags.first_unstable();
        Ok(Err(if i < self.state.particles.len() {
            let problem = self.state.instability_of(i);
            self.state.unstable(i, problem)
        } else {
            SimulationError::NonFinite {
                step: self.state.step,
                id: 0,
                field: "position or velocity (of a ghost)",
            }
        }))
    }

    /// Stage 1: the periodic wrap ran on the device with the drift; insertion, removal and a
    /// decomposed run's migration and ghosts at a rebuild (on the device where it can stay
    /// there, [`exchange`], else through the host), and the next list build scheduled.
    fn exchange(&mut self, flags: &StepFlags) -> Result<(), CudaError> {
        if self.state.parallel.is_some() {
            self.exchange_decomposed(flags)?;
        } else {
            if flags.outside > 0 || self.state.inserter_pending() {
                // Insertion or removal: the host does it on a synced copy, then everything
                // goes back up (with the history) and the list is rebuilt.
                self.sync_host()?;
                self.state.exchange(true, |_, _| true)?;
                self.upload_from_host()?;
            }
            if flags.rebuild != 0 {
                self.pairs.rebuild = true;
            } else if flags.snapshot != 0 && !self.pairs.rebuild {
                // The hybrid list's snapshot (seed Fig. 1B, B4): the host builds the next list
                // while the GPU steps on this one.
                let generation = self.pairs.generation;
                self.list_builder
                    .start_prebuild(&self.gpu, &self.particles, generation)?;
            }
        }
        if flags.wall_rebuild != 0
            && let Some(w) = &mut self.walls
        {
            w.list = None;
        }
        Ok(())
    }

    /// Stage 1 of a decomposed run: all ranks rebuild together, when some rank inserts,
    /// removes or has a particle that moved half the skin; between rebuilds the ghosts come
    /// through the halo.
    fn exchange_decomposed(&mut self, flags: &StepFlags) -> Result<(), CudaError> {
        let pending = self.state.inserter_pending();
        let par = self.state.part_mut();
        let local = flags.rebuild != 0 || flags.outside > 0 || self.pairs.rebuild;
        let t_wait = Instant::now();
        let rebuild = par.comm.any(local) || pending;
        par.timers.wait += t_wait.elapsed().as_secs_f64();
        if rebuild && self.rebuild_stays_on_device(pending, flags.outside > 0) {
            // Migration and the ghosts' choice with the state left on the device
            // ([`exchange`]).
            self.rebuild_on_device()?;
        } else if rebuild {
            // A round trip through the host, where insertion, removal, migration,
            // balancing and the choice of ghosts run as on the CPU backend.
            let t_download = Instant::now();
            self.sync_host()?;
            let download = t_download.elapsed().as_secs_f64();
            // A particle that left through a closed face stops every rank together, before
            // the exchange's collectives (on the CPU backend the step checks it after the
            // drift; here the host sees positions at rebuilds, which an exit forces).
            let inside = self.state.check_inside();
            self.state.agree(inside)?;
            self.state.exchange(true, |_, _| true)?;
            let t_upload = Instant::now();
            self.upload_walls()?;
            self.upload_from_host()?;
            if let Some(par) = self.state.parallel.as_deref_mut() {
                par.timers.device_download += download;
                par.timers.device_upload += t_upload.elapsed().as_secs_f64();
            }
        }
        // Ghosts were not integrated: between rebuilds their owners' motion comes through
        // the halo, overlapped with the pairs of owned particles ([`Self::forces`]).
        self.halo.due = !rebuild;
        Ok(())
    }
}
