//! The step on the GPU: [`CudaSimulation`] keeps the particle state, the pair list and the
//! contact history resident on the device and launches the kernels of `cuda/` stage by stage in
//! the order of docs/design.md §1 (the GPU twin of [`Simulation`], as HOOMD-blue pairs a GPU class
//! with each expensive CPU class). The host copy in [`CudaSimulation::host`] is refreshed only
//! when it is read (output, checkpoint) or changed (insertion, removal), so an ordinary step
//! copies nothing back but its status flags and error word (28 bytes).

use super::error::CudaError;
use super::gpu::{Gpu, StageClock, WallStream};
use super::halo::HaloStage;
use super::integrator::{DriftChecks, Integrator};
use super::kernels::{KernelConfig, Precision};
use super::launch::Kernels;
use super::layout::{GridParams, PairMaterial};
use super::list_builder::ListBuilder;
use super::pairs::PairStage;
use super::particles::DeviceParticles;
use super::walls::WallStage;
use crate::contact::hunt_crossley_alpha;
use crate::neighbor::Bounds;
use crate::pipeline::{Simulation, SimulationError};
use cudarc::driver::CudaContext;
use std::time::Instant;

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

/// The binning grid of `host`'s domain and a list builder on it. A rank of a decomposed run
/// bins on the whole domain's grid (ghosts keep their true centroids), sized for the whole
/// run's particles.
fn domain_grid(host: &Simulation) -> (GridParams, ListBuilder) {
    let s = &host.scene;
    let bounds = Bounds {
        min: s.domain.min,
        max: s.domain.max,
        periodic: s.domain.periodic,
    };
    let particles = match host.parallel.as_deref() {
        Some(par) => par.comm.sum_u64(&[host.particles.len() as u64])[0] as usize,
        None => host.particles.len(),
    };
    let grid = GridParams::new(&bounds, s.cutoff(), 4 * particles.max(1));
    let list_builder = ListBuilder::new(s, grid, host.parallel.is_some(), particles);
    (grid, list_builder)
}

impl CudaSimulation {
    /// Follows a change of the host's domain (a rescaled periodic box,
    /// [`Simulation::rescale_periodic_box`]): the binning grid, the periodic wrap and the list
    /// builder are made again for it (an `auto` neighbour mode starts its trials afresh); the
    /// next step rebuilds the pair list.
    pub(super) fn domain_changed(&mut self) {
        let (grid, list_builder) = domain_grid(&self.host);
        self.gpu.grid = grid;
        self.list_builder = list_builder;
        self.pairs.rebuild = true;
    }
}

/// A simulation stepped on the GPU. See the module docs.
pub struct CudaSimulation {
    /// Host copy: scene, inserter, time, step, statistics, and (when synced) the state.
    pub host: Simulation,
    /// Device name.
    pub device: String,
    /// Arithmetic of the pair geometry.
    pub precision: Precision,
    /// The device, its streams and kernels, and the scene's constants.
    pub(super) gpu: Gpu,
    /// The particle arrays (with a decomposed run's ghosts).
    pub(super) particles: DeviceParticles,
    /// Stage 2: the pair list, and everything indexed by pair.
    pub(super) pairs: PairStage,
    /// Stage 2: who builds the pair list (`[simulation.neighbor] mode`).
    pub(super) list_builder: ListBuilder,
    /// Stage 6: the walls, `None` without walls.
    pub(super) walls: Option<WallStage>,
    /// A decomposed run's halo ([`super::halo`]).
    pub(super) halo: HaloStage,
    /// Stage 9: the two passes over the particle state.
    pub(super) integrator: Integrator,
    /// The host copy holds the device state (no step since the last sync or upload).
    pub(super) host_current: bool,
}

impl CudaSimulation {
    /// Moves `host` (freshly created or restored, forces evaluated or restored) onto GPU
    /// `ordinal`, compiling the kernels for it with the scene's configuration.
    pub(crate) fn new(
        host: Simulation,
        ordinal: usize,
        precision: Precision,
    ) -> Result<Self, CudaError> {
        let ctx = CudaContext::new(ordinal)?;
        // SAFETY: nothing has been allocated yet. Every buffer is used on the main stream but
        // the wall list's, which the wall stream also uses between the two events of
        // `WallStream`, which order it after the list's allocation and writes and before the
        // main stream's next use or free (`CudaSimulation::forces`). Without event tracking a
        // second stream adds no event per buffer use to every launch.
        unsafe { ctx.disable_event_tracking() };
        let stream = ctx.default_stream();
        let wall_stream = WallStream {
            stream: ctx.new_stream()?,
            poses_ready: ctx.new_event(None)?,
            overlaps_done: ctx.new_event(None)?,
        };
        let (major, minor) = ctx.compute_capability()?;
        let arch = (major * 10 + minor) as u32;
        let mut config = KernelConfig::for_scene(&host.scene, precision);
        config.ghosts = host.parallel.is_some();
        // A GPU that other processes fill can run out before the particles arrive: named too.
        let set_up = |e: CudaError| {
            e.out_of_memory(
                || "the kernels and the step's fixed buffers".to_string(),
                None,
            )
        };
        let k = Kernels::load(&ctx, &config, arch).map_err(set_up)?;
        let device = ctx.name().unwrap_or_else(|_| format!("GPU {ordinal}"));
        let s = &host.scene;
        // Materials: restitution, friction and damping coefficient per pair (as `SimulationBuilder::build` does).
        let n_mat = s.materials.len();
        let mut materials = Vec::with_capacity(n_mat * n_mat);
        for a in 0..n_mat {
            for b in 0..n_mat {
                let pp = s.pairs.get(a, b);
                let e = s.pairs.try_get(a, b).map_or(1.0, |p| p.restitution);
                materials.push(PairMaterial::new(
                    pp.restitution,
                    pp.friction,
                    hunt_crossley_alpha(e),
                ));
            }
        }
        let materials = stream
            .clone_htod(&materials)
            .map_err(|e| set_up(e.into()))?;
        let skin = s.simulation.neighbor.skin;
        let (grid, list_builder) = domain_grid(&host);
        let error = stream.alloc_zeros::<u32>(3).map_err(|e| set_up(e.into()))?;
        let clock = StageClock::new(&ctx).map_err(set_up)?;
        let gpu = Gpu {
            _ctx: ctx,
            clock,
            stream,
            wall_stream,
            k,
            config,
            grid,
            skin,
            materials,
            error,
        };
        let mut sim = CudaSimulation {
            device,
            precision,
            particles: DeviceParticles::empty(&gpu.stream).map_err(set_up)?,
            pairs: PairStage::new(&gpu).map_err(set_up)?,
            list_builder,
            walls: None,
            halo: HaloStage::default(),
            integrator: Integrator::new(&gpu).map_err(set_up)?,
            host_current: true,
            gpu,
            host,
        };
        sim.upload_templates().map_err(set_up)?;
        sim.upload_walls().map_err(|e| {
            e.out_of_memory(|| "the walls' facets and facet grid".to_string(), None)
        })?;
        sim.upload_from_host()?;
        Ok(sim)
    }

    /// A new simulation of `scene` on `comm`'s ranks, this one on GPU `ordinal`: particles of count insertions placed on
    /// the host, the first forces evaluated on the device (as [`Simulation::builder`] does on the
    /// CPU, advancing the springs by one step).
    pub(crate) fn from_scene(
        scene: crate::scene::Scene,
        comm: std::sync::Arc<dyn crate::domain::Comm>,
        ordinal: usize,
        precision: Precision,
    ) -> Result<Self, CudaError> {
        let host = Simulation::builder(scene)
            .comm(comm)
            .evaluate_forces(false)
            .build()?;
        let mut sim = CudaSimulation::new(host, ordinal, precision)?;
        sim.evaluate_first_forces()?;
        Ok(sim)
    }

    /// The first force evaluation of a new simulation (see [`CudaSimulation::from_scene`]).
    fn evaluate_first_forces(&mut self) -> Result<(), CudaError> {
        let dt = self.host.dt;
        let n = self.host.particles.len();
        self.forces(dt, false).map_err(|e| {
            e.out_of_memory(
                || format!("the first force evaluation of {n} particles"),
                None,
            )
        })
    }

    /// Bytes of device memory held by this simulation's buffers (particles, pair list and
    /// everything indexed by pair, walls), excluding the CUDA context and the kernels.
    pub fn device_bytes(&self) -> usize {
        self.particles.bytes()
            + self.pairs.bytes()
            + self.walls.as_ref().map_or(0, WallStage::bytes)
    }

    /// Particles this rank owns now: the host's count, or after a decomposed run's rebuild on
    /// the device (which leaves the host's copy stale) the device's slots less its ghosts.
    pub fn particle_count(&self) -> usize {
        match self.host.parallel.as_deref() {
            Some(par) if !self.host_current => self.particles.n - par.ghosts.particles.len(),
            _ => self.host.particles.len(),
        }
    }

    /// Pairs in the current candidate list.
    pub fn candidate_pairs(&self) -> usize {
        self.pairs.list.as_ref().map_or(0, |p| p.n)
    }

    /// The current wall list: (particle–facet items, particles with at least one); zeros
    /// without walls or before the first list.
    pub fn wall_candidates(&self) -> Result<(u64, u64), CudaError> {
        let Some(list) = self.walls.as_ref().and_then(|w| w.list.as_ref()) else {
            return Ok((0, 0));
        };
        let offset = self.gpu.stream.clone_dtoh(&list.offset)?;
        let touched = offset.windows(2).filter(|w| w[1] > w[0]).count();
        Ok((list.n_items as u64, touched as u64))
    }

    /// Pair lists built so far (the first one included).
    pub fn pair_list_builds(&self) -> u64 {
        self.pairs.builds
    }

    /// Who built the pair lists so far, with the seed's timings (docs/design.md §7).
    pub fn neighbor_report(&self) -> crate::neighbor::NeighborReport {
        self.list_builder.report()
    }

    /// Makes every host-built list fail its consistency check from now on, so that each is
    /// replaced by a device build: the fallback of `hybrid`, forced (for tests).
    #[doc(hidden)]
    pub fn force_stale_host_lists(&mut self, on: bool) {
        self.list_builder.force_stale(on);
    }

    /// Wall lists built so far (at each pair-list build, and when a particle or a wall moved
    /// half the skin since the last one); 0 without walls.
    pub fn wall_list_builds(&self) -> u64 {
        self.walls.as_ref().map_or(0, |w| w.list_builds)
    }
}

impl CudaSimulation {
    /// Advances one time step: the stage order of [`Simulation::step`], in two passes over the
    /// particle state (`kick_drift` and, after the contacts, `reduce_and_kick` of
    /// cuda/integrate.cu).
    pub fn step(&mut self) -> Result<(), CudaError> {
        let t0 = Instant::now();
        // The device state changes from here on: the host copy is stale until synced again.
        self.host_current = false;
        let g = self.host.scene.gravity;
        let dt = self.host.dt;
        // The checks need the list's reference positions; before the first build there are none.
        let checks = self.particles.n > 0 && self.pairs.list.is_some();
        let (wall_reference, wall_half_reach) = match &mut self.walls {
            Some(w) if checks => w.check(&self.gpu, &self.host.scene, self.host.time + dt),
            _ => (0u64, 0.0),
        };
        let limits = DriftChecks {
            reference: &self.pairs.reference,
            half_skin: self.pairs.half_skin,
            snapshot_distance: self.list_builder.snapshot_distance(),
            wall_reference,
            wall_half_reach,
            max_speed: self.host.guard.max_speed,
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
        self.host.time += dt;
        self.host.step += 1;
        self.host.timers.integrate += t0.elapsed().as_secs_f64();
        // Stage 1: the periodic wrap and the per-step checks ran on the device with the drift;
        // insertion and removal on the host (rare steps).
        let t0 = Instant::now();
        let motion = if flags.unstable != 0 {
            self.sync_host()?;
            let i = flags.first_unstable();
            Err(if i < self.host.particles.len() {
                let problem = self.host.instability_of(i);
                self.host.unstable(i, problem)
            } else {
                SimulationError::NonFinite {
                    step: self.host.step,
                    id: 0,
                    field: "position or velocity (of a ghost)",
                }
            })
        } else {
            Ok(())
        };
        // In a decomposed run every rank stops after this step if one does
        // ([`Simulation::agree`]).
        self.host.agree(motion)?;
        let pending = self.host.inserter_pending();
        if let Some(par) = self.host.parallel.as_deref_mut() {
            // All ranks rebuild together: when some rank inserts, removes or has a particle
            // that moved half the skin.
            let local = flags.rebuild != 0 || flags.outside > 0 || self.pairs.rebuild;
            let t_wait = Instant::now();
            let rebuild = par.comm.any(local) || pending;
            par.timers.wait += t_wait.elapsed().as_secs_f64();
            if rebuild && self.rebuild_stays_on_device(pending, flags.outside > 0) {
                // Migration and the ghosts' choice with the state left on the device
                // ([`super::exchange`]).
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
                let inside = self.host.check_inside();
                self.host.agree(inside)?;
                self.host.rebuild_exchange_on_host()?;
                let t_upload = Instant::now();
                self.upload_walls()?;
                self.upload_from_host()?;
                if let Some(par) = self.host.parallel.as_deref_mut() {
                    par.timers.device_download += download;
                    par.timers.device_upload += t_upload.elapsed().as_secs_f64();
                }
            }
            // Ghosts were not integrated: between rebuilds their owners' motion comes through
            // the halo, overlapped with the pairs of owned particles ([`Self::forces`]).
            self.halo.due = !rebuild;
        } else {
            if flags.outside > 0 || self.host.inserter_pending() {
                // Insertion or removal: the host does it on a synced copy, then everything
                // goes back up (with the history) and the list is rebuilt.
                self.sync_host()?;
                self.host.exchange_on_host()?;
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
        self.host.timers.exchange += t0.elapsed().as_secs_f64();
        // The contacts, then the reduction with the second half kick.
        self.forces(dt, true)?;
        Ok(())
    }
}
