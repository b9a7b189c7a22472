//! Making a [`CudaSimulation`]: the host's simulation moved onto a GPU with its kernels
//! compiled for the scene, the first forces evaluated there, the binning grid of the domain;
//! and what it reports (device bytes, counts, the list builds).

use super::CudaSimulation;
use super::error::CudaError;
use super::gpu::{Gpu, StageClock, WallStream};
use super::halo::HaloStage;
use super::integrator::Integrator;
use super::kernels::{KernelConfig, Precision};
use super::launch::Kernels;
use super::layout::{GridParams, PairMaterial};
use super::list_builder::ListBuilder;
use super::pairs::PairStage;
use super::particles::DeviceParticles;
use super::walls::WallStage;
use crate::contact::hunt_crossley_alpha;
use crate::neighbor::Bounds;
use crate::pipeline::Simulation;
use crate::run_state::RunState;
use cudarc::driver::CudaContext;

/// The binning grid of `host`'s domain and a list builder on it. A rank of a decomposed run
/// bins on the whole domain's grid (ghosts keep their true centroids), sized for the whole
/// run's particles.
fn domain_grid(host: &RunState) -> (GridParams, ListBuilder) {
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
    /// [`RunState::rescale_periodic_box`]): the binning grid, the periodic wrap and the list
    /// builder are made again for it (an `auto` neighbour mode starts its trials afresh); the
    /// next step rebuilds the pair list.
    pub(super) fn domain_changed(&mut self) {
        let (grid, list_builder) = domain_grid(&self.state);
        self.gpu.grid = grid;
        self.list_builder = list_builder;
        self.pairs.rebuild = true;
    }
}

impl CudaSimulation {
    /// Moves `host` (freshly created or restored, forces evaluated or restored) onto GPU
    /// `ordinal`, compiling the kernels for it with the scene's configuration.
    pub(crate) fn new(
        host: RunState,
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
        // Materials: restitution, friction, rolling friction and damping coefficient per pair
        // (as `SimulationBuilder::build` does).
        let n_mat = s.materials.len();
        let mut materials = Vec::with_capacity(n_mat * n_mat);
        for a in 0..n_mat {
            for b in 0..n_mat {
                let pp = s.pairs.get(a, b);
                let e = s.pairs.try_get(a, b).map_or(1.0, |p| p.restitution);
                materials.push(PairMaterial::new(
                    pp.restitution,
                    pp.friction,
                    pp.rolling_friction,
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
            state: host,
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
        let host = Simulation::builder(scene).comm(comm).state()?;
        let mut sim = CudaSimulation::new(host, ordinal, precision)?;
        sim.evaluate_first_forces()?;
        Ok(sim)
    }

    /// The first force evaluation of a new simulation (see [`CudaSimulation::from_scene`]).
    fn evaluate_first_forces(&mut self) -> Result<(), CudaError> {
        let dt = self.state.dt;
        let n = self.state.particles.len();
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
        match self.state.parallel.as_deref() {
            Some(par) if !self.host_current => self.particles.n - par.ghosts.particles.len(),
            _ => self.state.particles.len(),
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
