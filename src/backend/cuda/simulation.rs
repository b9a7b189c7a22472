//! The step on the GPU: [`CudaSimulation`] keeps the particle state, the pair list and the
//! contact history resident on the device and launches the kernels of `cuda/` stage by stage in
//! the order of DESIGN.md §1 (the GPU twin of [`Simulation`], as HOOMD-blue pairs a GPU class
//! with each expensive CPU class). The host copy in [`CudaSimulation::host`] is refreshed only
//! when it is read (output, checkpoint) or changed (insertion, removal), so an ordinary step
//! copies nothing back but its status flags and error word (28 bytes).

use super::kernels::{KernelConfig, Precision, compile};
#[cfg(doc)]
use super::layout::staged_planes_bytes;
use super::layout::{GridParams, PairMaterial};
use crate::contact::hunt_crossley_alpha;
use crate::geometry::vertex_enumeration::ENUM_MAX_PLANES;
use crate::neighbor::Bounds;
use crate::pipeline::{Simulation, SimulationError};
use cudarc::driver::{
    CudaContext, CudaEvent, CudaFunction, CudaModule, CudaSlice, CudaStream, DeviceRepr,
    LaunchConfig, PushKernelArg, ValidAsZeroBits,
};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

/// Threads per block of the per-particle and per-pair kernels.
const BLOCK: u32 = 256;

/// Threads per block of the sphere pair kernel. Its 94 registers per thread allow two blocks of
/// 256 per multiprocessor (16 warps) but five of 128 (20 warps), and the kernel waits on memory:
/// on an H200, 1e6 dense spheres took 0.50 ms per step in the pair stage with 128, 0.61 ms with
/// 256 (docs/performance.md). The polyhedral passes keep [`BLOCK`]: their per-thread workspace
/// lives in local memory, and with one pass for the whole pair, 128 was 40 % slower than 256
/// (the two passes now are about equal either way).
pub(super) const SPHERE_PAIR_BLOCK: u32 = 128;

/// Errors of the CUDA backend, each saying what failed.
#[derive(Debug, thiserror::Error)]
pub enum CudaError {
    #[error("CUDA driver: {0}")]
    Driver(#[from] cudarc::driver::DriverError),
    #[error("{0}")]
    Compile(String),
    #[error(transparent)]
    Simulation(#[from] SimulationError),
    #[error("{0}")]
    Halo(String),
}

/// Launch configuration for `n` threads in blocks of [`BLOCK`] (see [`cfg_with`]).
pub(super) fn cfg(n: usize) -> LaunchConfig {
    cfg_with(n, BLOCK)
}

/// Launch configuration for `n` threads in blocks of `preferred`. Small launches get smaller
/// blocks, so that they still spread over the GPU's multiprocessors (a 2000-particle scene in
/// blocks of 128 would occupy 16 of an H100's 132); `POLYDEM_CUDA_BLOCK` fixes the block size
/// of every kernel instead (for tuning).
pub(super) fn cfg_with(n: usize, preferred: u32) -> LaunchConfig {
    let fixed = crate::tuning::Tuning::get().cuda_block;
    // Enough blocks for two per multiprocessor of the largest current GPUs (132 SMs).
    let block = fixed.unwrap_or(if n >= 264 * preferred as usize {
        preferred
    } else if n >= 264 * 64 {
        64
    } else {
        32
    });
    LaunchConfig {
        grid_dim: ((n as u32).div_ceil(block).max(1), 1, 1),
        block_dim: (block, 1, 1),
        shared_mem_bytes: 0,
    }
}

/// One wall mesh as the kernels read it (`cuda/contact.cu: WallInfo`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct WallInfo {
    pub(super) facet_offset: i32,
    pub(super) n_facets: i32,
    pub(super) cell_offset: i32,
    pub(super) material: i32,
    pub(super) grid_min: [f64; 3],
    pub(super) grid_size: f64,
    pub(super) dims: [i32; 3],
    pub(super) pad: i32,
}
// SAFETY: plain old data laid out as the C struct.
unsafe impl DeviceRepr for WallInfo {}

/// A wall's pose and velocity field at the current time (`cuda/contact.cu: WallState`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct WallState {
    pub(super) rotation: [f64; 4],
    pub(super) translation: [f64; 3],
    pub(super) v0: [f64; 3],
    pub(super) omega: [f64; 3],
    pub(super) origin: [f64; 3],
}
// SAFETY: plain old data laid out as the C struct.
unsafe impl DeviceRepr for WallState {}
// SAFETY: all-zero bits are valid f64 values.
unsafe impl ValidAsZeroBits for WallState {}

/// The particle state the contact kernels read (`cuda/contact.cu: ParticleView`): device
/// pointers, valid while the buffers they point into are alive and not reallocated.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(super) struct ParticleView {
    pub(super) ptrs: [u64; 12],
}
// SAFETY: twelve device pointers, laid out as the C struct of twelve pointers.
unsafe impl DeviceRepr for ParticleView {}

/// Per-pair outputs (`cuda/contact.cu: PairOutputs`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(super) struct PairOutputs {
    pub(super) ptrs: [u64; 3],
}
// SAFETY: three device pointers.
unsafe impl DeviceRepr for PairOutputs {}

/// Everything a pair evaluation reads and writes (`cuda/contact.cu: PairArgs`): device pointers
/// into the pair list's and the particles' buffers, valid while those are alive.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(super) struct PairArgs {
    pub(super) pairs: u64,
    pub(super) grid: GridParams,
    pub(super) axes: u64,
    pub(super) p: ParticleView,
    pub(super) materials: u64,
    pub(super) n_materials: i32,
    pub(super) spring_in: u64,
    pub(super) spring_out: u64,
    pub(super) out: PairOutputs,
    pub(super) dt: f64,
    pub(super) max_overlap: f64,
    pub(super) error: u64,
}
// SAFETY: device pointers, a GridParams, an int and a double, laid out as the C struct (the
// size is checked by static_assert in cuda/contact.cu).
unsafe impl DeviceRepr for PairArgs {}

pub(super) fn ptr<T>(s: &CudaSlice<T>, stream: &CudaStream) -> u64 {
    use cudarc::driver::DevicePtr;
    let (p, _sync) = s.device_ptr(stream);
    p
}

/// Kernel handles.
pub(super) struct Kernels {
    pub(super) _modules: Vec<Arc<CudaModule>>,
    pub(super) contact: Arc<CudaModule>,
    pub(super) f: HashMap<&'static str, CudaFunction>,
}

impl Kernels {
    pub(super) fn get(&self, name: &str) -> &CudaFunction {
        &self.f[name]
    }
}

/// Particle arrays on the device (xyz-interleaved vectors, quaternions as x, y, z, w).
pub(super) struct DeviceParticles {
    pub(super) id: CudaSlice<u64>,
    pub(super) tmpl: CudaSlice<u32>,
    pub(super) material: CudaSlice<u32>,
    pub(super) kind: CudaSlice<u32>,
    pub(super) scale: CudaSlice<f64>,
    pub(super) radius: CudaSlice<f64>,
    pub(super) cn: CudaSlice<f64>,
    pub(super) ct: CudaSlice<f64>,
    pub(super) mass: CudaSlice<f64>,
    pub(super) position: CudaSlice<f64>,
    pub(super) velocity: CudaSlice<f64>,
    pub(super) angular_velocity: CudaSlice<f64>,
    pub(super) orientation: CudaSlice<f64>,
    pub(super) force: CudaSlice<f64>,
    pub(super) torque: CudaSlice<f64>,
    pub(super) inertia: CudaSlice<f64>,
    /// 1 for a ghost (a neighbour rank's particle), 0 for an owned one.
    pub(super) ghost: CudaSlice<u32>,
}

/// The pair list and everything indexed by pair.
pub(super) struct DevicePairs {
    pub(super) n: usize,
    /// In a decomposed run, the pairs `0..n_interior` have two owned members and need nothing
    /// from the halo; the rest have a ghost. Otherwise `n`.
    pub(super) n_interior: usize,
    /// Per particle, its pairs as first member (`offset[i]..offset[i + 1]`): the history source
    /// of the next build; `None` for a decomposed run's two-part list.
    pub(super) offset: Option<CudaSlice<u32>>,
    pub(super) pairs: CudaSlice<i32>,
    pub(super) axes: CudaSlice<f64>,
    pub(super) spring_in: CudaSlice<f64>,
    pub(super) spring_out: CudaSlice<f64>,
    pub(super) forces: CudaSlice<f64>,
    pub(super) energy: CudaSlice<f64>,
    pub(super) contact: CudaSlice<u32>,
    pub(super) ref_offset: CudaSlice<u32>,
    pub(super) refs: CudaSlice<u32>,
    /// The pairs the lean passes leave to the full evaluation (GJK, the dual hull), and their
    /// count.
    pub(super) deferred: CudaSlice<u32>,
    pub(super) deferred_count: CudaSlice<u32>,
    /// Between the two lean passes of polyhedral pairs (`pair_planes`, `pair_faces`): each
    /// staged pair's planes (`StagedPlanes` of cuda/contact.cu, [`staged_planes_bytes`] each),
    /// its plane-count bucket, the staged pairs listed bucket by bucket, and per bucket the
    /// count and the fill cursor ([`PLANE_BUCKETS`] values each).
    pub(super) staged: CudaSlice<u8>,
    pub(super) bucket: CudaSlice<u8>,
    pub(super) order: CudaSlice<u32>,
    pub(super) bucket_count: CudaSlice<u32>,
    pub(super) bucket_fill: CudaSlice<u32>,
}

/// Plane-count buckets of the lean pair passes: counts 0..=ENUM_MAX_PLANES (`PD_PLANE_BUCKETS`).
pub(super) const PLANE_BUCKETS: usize = ENUM_MAX_PLANES + 1;

/// Wall meshes and per-particle wall outputs.
pub(super) struct DeviceWalls {
    pub(super) n: usize,
    pub(super) info: CudaSlice<WallInfo>,
    pub(super) states: CudaSlice<WallState>,
    pub(super) triangles: CudaSlice<f64>,
    pub(super) prisms: CudaSlice<f64>,
    pub(super) cell_start: CudaSlice<u32>,
    pub(super) cell_items: CudaSlice<u32>,
    pub(super) spring_in: CudaSlice<f64>,
    pub(super) spring_out: CudaSlice<f64>,
    pub(super) force: CudaSlice<f64>,
    pub(super) torque: CudaSlice<f64>,
    pub(super) energy: CudaSlice<f64>,
    pub(super) per_wall_force: CudaSlice<f64>,
    pub(super) contact: CudaSlice<u32>,
    /// The particles' candidate facets, built when due ([`WallList`]); `None` when due.
    pub(super) list: Option<WallList>,
    /// Wall lists built so far.
    pub(super) list_builds: u64,
}

/// The stream on which the walls' facet overlaps run alongside the pair kernels of the main
/// stream, with the two events that order it: after the main stream's poses, before its wall
/// sums ([`CudaSimulation::forces`]).
pub(super) struct WallStream {
    pub(super) stream: Arc<CudaStream>,
    /// Recorded on the main stream once the walls' states and the list are queued.
    pub(super) poses_ready: CudaEvent,
    /// Recorded on the wall stream after the facet overlaps.
    pub(super) overlaps_done: CudaEvent,
}

/// The wall list: per particle and wall, the facets within its bounding radius plus the skin
/// when it was built, in the order of their sums (`wall_candidates` of cuda/contact.cu), with
/// room for their overlaps. It stays valid while every particle is within half the skin of
/// where it was in every wall's frame: its own motion (`kick_drift`'s check against
/// `reference`) plus the walls' motion since `poses` (bounded on the host,
/// [`CudaSimulation::wall_check`]). The CPU queries the facet grid every step instead; both
/// evaluate the same facets in the same order.
pub(super) struct WallList {
    /// Per particle, its items `offset[i]..offset[i + 1]`.
    pub(super) offset: CudaSlice<u32>,
    /// (particle · walls + wall, facet) per item, in summation order.
    pub(super) items: CudaSlice<u32>,
    pub(super) n_items: usize,
    /// Twelve values per item, written each step by `wall_facet_overlaps`.
    pub(super) overlaps: CudaSlice<f64>,
    /// The particles' positions at the build.
    pub(super) reference: CudaSlice<f64>,
    /// The walls' poses at the build.
    pub(super) poses: Vec<nalgebra::Isometry3<f64>>,
}

/// The contact history handed to the next list build: for each particle in the numbering
/// before the build's reordering, its pairs' partner ids and springs (CSR).
pub(super) struct HistorySource {
    pub(super) offset: CudaSlice<u32>,
    pub(super) partner: CudaSlice<u64>,
    pub(super) spring: CudaSlice<f64>,
}

/// Waits for the wall stream before anything is freed: the fields drop in declaration order,
/// and a step that failed between the walls' two events (a CUDA error, a guard stop) can leave
/// `wall_facet_overlaps` queued on it, reading particle arrays and the wall list that would
/// otherwise be freed under it. The main stream is waited for too (cudarc frees a slice on its
/// own stream, but the wall stream's kernels read the main stream's slices).
impl Drop for CudaSimulation {
    fn drop(&mut self) {
        // Errors here have nowhere to go; the context reports them on its next use.
        let _ = self.wall_stream.stream.synchronize();
        let _ = self.stream.synchronize();
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
    pub(super) _ctx: Arc<CudaContext>,
    pub(super) stream: Arc<CudaStream>,
    pub(super) wall_stream: WallStream,
    pub(super) k: Kernels,
    pub(super) config: KernelConfig,
    pub(super) grid: GridParams,
    pub(super) skin: f64,
    pub(super) n: usize,
    pub(super) p: DeviceParticles,
    pub(super) pairs: Option<DevicePairs>,
    pub(super) walls: Option<DeviceWalls>,
    pub(super) materials: CudaSlice<PairMaterial>,
    pub(super) reference: CudaSlice<f64>,
    pub(super) flags: CudaSlice<u32>,
    pub(super) error: CudaSlice<u32>,
    pub(super) pending_history: Option<HistorySource>,
    pub(super) host_current: bool,
    pub(super) rebuild: bool,
    /// Pair lists built so far.
    pub(super) list_builds: u64,
    /// A decomposed run's device halo ([`super::halo`]).
    pub(super) halo: Option<super::halo::DeviceHalo>,
    /// The ghosts await this step's halo refresh (set by the exchange, done by the forces).
    pub(super) halo_due: bool,
}

impl CudaSimulation {
    /// Moves `host` (freshly created or restored, forces evaluated or restored) onto GPU
    /// `ordinal`, compiling the kernels for it with the scene's configuration.
    pub fn new(host: Simulation, ordinal: usize, precision: Precision) -> Result<Self, CudaError> {
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
        let mut modules = Vec::new();
        let mut f = HashMap::new();
        let mut contact = None;
        let names: &[(&str, &[&'static str])] = &[
            ("scan.cu", &["scan_blocks", "scan_add"]),
            ("integrate.cu", &["kick_drift", "reduce_and_kick"]),
            (
                "neighbor.cu",
                &[
                    "bin_particles",
                    "scatter_by_cell",
                    "sort_cells",
                    "gather_f64",
                    "gather_u64",
                    "gather_u32",
                    "count_pairs",
                    "fill_pairs",
                    "count_refs",
                    "fill_refs",
                    "sort_refs",
                    "history_partners",
                    "remap_history",
                ],
            ),
            (
                "contact.cu",
                &[
                    "pair_contacts",
                    "pair_planes",
                    "bucket_pairs",
                    "pair_faces",
                    "pair_contacts_deferred",
                    "wall_candidates",
                    "wall_facet_overlaps",
                    "wall_contacts",
                ],
            ),
            ("halo.cu", &["pack_motion", "unpack_motion"]),
        ];
        for (file, kernels) in names {
            let ptx = compile(file, &config, arch).map_err(CudaError::Compile)?;
            let module = ctx.load_module(ptx)?;
            for &name in *kernels {
                if name.starts_with("wall_") && !config.walls {
                    continue;
                }
                f.insert(name, module.load_function(name)?);
            }
            if *file == "contact.cu" {
                contact = Some(module.clone());
            }
            modules.push(module);
        }
        let contact = contact.expect("contact.cu is compiled above");
        let k = Kernels {
            _modules: modules,
            contact,
            f,
        };
        let device = ctx.name().unwrap_or_else(|_| format!("GPU {ordinal}"));
        let s = &host.scene;
        // Materials: restitution, friction and damping coefficient per pair (as Simulation::new).
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
        let materials = stream.clone_htod(&materials)?;
        let bounds = Bounds {
            min: s.domain.min,
            max: s.domain.max,
            periodic: s.domain.periodic,
        };
        let skin = s.simulation.neighbor.skin;
        let cutoff = s.cutoff();
        // A rank of a decomposed run bins on the whole domain's grid (ghosts keep their true
        // centroids), sized for the whole run's particles.
        let particles = match host.parallel.as_deref() {
            Some(par) => par.comm.sum_u64(&[host.particles.len() as u64])[0] as usize,
            None => host.particles.len(),
        };
        let grid = GridParams::new(&bounds, cutoff, 4 * particles.max(1));
        let empty_p = DeviceParticles::empty(&stream)?;
        let mut sim = CudaSimulation {
            device,
            precision,
            flags: stream.alloc_zeros::<u32>(5)?,
            error: stream.alloc_zeros::<u32>(3)?,
            reference: stream.alloc_zeros::<f64>(1)?,
            _ctx: ctx,
            k,
            config,
            grid,
            skin,
            n: 0,
            p: empty_p,
            pairs: None,
            walls: None,
            materials,
            pending_history: None,
            host_current: true,
            rebuild: true,
            list_builds: 0,
            halo: None,
            halo_due: false,
            stream,
            wall_stream,
            host,
        };
        sim.upload_templates()?;
        sim.upload_walls()?;
        sim.upload_from_host()?;
        Ok(sim)
    }

    /// A new simulation of `scene` on GPU `ordinal`: particles of count insertions placed on
    /// the host, the first forces evaluated on the device (as [`Simulation::builder`] does on the
    /// CPU, advancing the springs by one step).
    pub fn from_scene(
        scene: crate::scene::Scene,
        ordinal: usize,
        precision: Precision,
    ) -> Result<Self, CudaError> {
        let host = Simulation::builder(scene).evaluate_forces(false).build()?;
        let mut sim = CudaSimulation::new(host, ordinal, precision)?;
        sim.evaluate_first_forces()?;
        Ok(sim)
    }

    /// The first force evaluation of a new simulation (see [`CudaSimulation::from_scene`]).
    pub fn evaluate_first_forces(&mut self) -> Result<(), CudaError> {
        let dt = self.host.dt;
        self.forces(dt, false)
    }

    /// Bytes of device memory held by this simulation's buffers (particles, pair list and
    /// everything indexed by pair, walls), excluding the CUDA context and the kernels.
    pub fn device_bytes(&self) -> usize {
        fn b<T>(s: &CudaSlice<T>) -> usize {
            s.len() * std::mem::size_of::<T>()
        }
        let p = &self.p;
        let mut total = b(&p.id)
            + b(&p.tmpl)
            + b(&p.material)
            + b(&p.kind)
            + b(&p.scale)
            + b(&p.radius)
            + b(&p.cn)
            + b(&p.ct)
            + b(&p.mass)
            + b(&p.position)
            + b(&p.velocity)
            + b(&p.angular_velocity)
            + b(&p.orientation)
            + b(&p.force)
            + b(&p.torque)
            + b(&p.inertia)
            + b(&p.ghost)
            + b(&self.reference);
        if let Some(q) = &self.pairs {
            total += q.offset.as_ref().map_or(0, b)
                + b(&q.pairs)
                + b(&q.deferred)
                + b(&q.deferred_count)
                + b(&q.staged)
                + b(&q.bucket)
                + b(&q.order)
                + b(&q.bucket_count)
                + b(&q.bucket_fill)
                + b(&q.axes)
                + b(&q.spring_in)
                + b(&q.spring_out)
                + b(&q.forces)
                + b(&q.energy)
                + b(&q.contact)
                + b(&q.ref_offset)
                + b(&q.refs);
        }
        if let Some(w) = &self.walls {
            total += b(&w.triangles)
                + b(&w.prisms)
                + b(&w.cell_start)
                + b(&w.cell_items)
                + b(&w.spring_in)
                + b(&w.spring_out)
                + b(&w.force)
                + b(&w.torque)
                + b(&w.energy)
                + b(&w.per_wall_force)
                + b(&w.contact);
            if let Some(l) = &w.list {
                total += b(&l.offset) + b(&l.items) + b(&l.overlaps) + b(&l.reference);
            }
        }
        total
    }

    /// Pairs in the current candidate list.
    pub fn candidate_pairs(&self) -> usize {
        self.pairs.as_ref().map_or(0, |p| p.n)
    }

    /// Pair lists built so far (the first one included).
    pub fn pair_list_builds(&self) -> u64 {
        self.list_builds
    }

    /// Wall lists built so far (at each pair-list build, and when a particle or a wall moved
    /// half the skin since the last one); 0 without walls.
    pub fn wall_list_builds(&self) -> u64 {
        self.walls.as_ref().map_or(0, |w| w.list_builds)
    }
}

impl DeviceParticles {
    fn empty(st: &Arc<CudaStream>) -> Result<Self, CudaError> {
        Ok(DeviceParticles {
            id: st.alloc_zeros(1)?,
            tmpl: st.alloc_zeros(1)?,
            material: st.alloc_zeros(1)?,
            kind: st.alloc_zeros(1)?,
            scale: st.alloc_zeros(1)?,
            radius: st.alloc_zeros(1)?,
            cn: st.alloc_zeros(1)?,
            ct: st.alloc_zeros(1)?,
            mass: st.alloc_zeros(1)?,
            position: st.alloc_zeros(1)?,
            velocity: st.alloc_zeros(1)?,
            angular_velocity: st.alloc_zeros(1)?,
            orientation: st.alloc_zeros(1)?,
            force: st.alloc_zeros(1)?,
            torque: st.alloc_zeros(1)?,
            inertia: st.alloc_zeros(1)?,
            ghost: st.alloc_zeros(1)?,
        })
    }
}

pub(super) fn zeros<T: DeviceRepr + ValidAsZeroBits>(
    st: &Arc<CudaStream>,
    n: usize,
) -> Result<CudaSlice<T>, CudaError> {
    Ok(st.alloc_zeros::<T>(n.max(1))?)
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
        let (dt, ni) = (self.host.dt, self.n as i32);
        let grid = self.grid;
        let wrap = i32::from(self.config.periodic);
        // The checks need the list's reference positions; before the first build there are none.
        let checks = i32::from(self.n > 0 && self.pairs.is_some());
        let half_skin = 0.5 * self.skin;
        let (wall_reference, wall_half_reach) = if checks != 0 {
            self.wall_check(self.host.time + dt)
        } else {
            (0u64, 0.0)
        };
        let mut flags = [0u32, 0, 0, u32::MAX, 0];
        if checks != 0 {
            self.stream.memcpy_htod(&flags, &mut self.flags)?;
        }
        {
            let p = &mut self.p;
            // SAFETY: `kick_drift` of cuda/integrate.cu; every state buffer holds 3n (4n)
            // values, `reference` 3n since the last list build (read only when `checks`), and
            // `wall_reference` is null or the wall list's 3n positions; `flags` holds five.
            unsafe {
                self.stream
                    .launch_builder(self.k.get("kick_drift"))
                    .arg(&ni)
                    .arg(&p.ghost)
                    .arg(&mut p.position)
                    .arg(&mut p.velocity)
                    .arg(&mut p.orientation)
                    .arg(&mut p.angular_velocity)
                    .arg(&p.force)
                    .arg(&p.torque)
                    .arg(&p.mass)
                    .arg(&p.inertia)
                    .arg(&g.x)
                    .arg(&g.y)
                    .arg(&g.z)
                    .arg(&dt)
                    .arg(&wrap)
                    .arg(&grid)
                    .arg(&checks)
                    .arg(&self.reference)
                    .arg(&half_skin)
                    .arg(&wall_reference)
                    .arg(&wall_half_reach)
                    .arg(&p.radius)
                    .arg(&self.host.guard.max_speed)
                    .arg(&mut self.flags)
                    .launch(cfg(self.n))?;
            }
        }
        self.host.time += dt;
        self.host.step += 1;
        if checks != 0 {
            self.stream.memcpy_dtoh(&self.flags, &mut flags)?;
        }
        self.stream.synchronize()?;
        self.host.timers.integrate += t0.elapsed().as_secs_f64();
        // Stage 1: the periodic wrap and the per-step checks ran on the device with the drift;
        // insertion and removal on the host (rare steps).
        let t0 = Instant::now();
        if flags[2] != 0 {
            self.sync_host()?;
            let i = flags[3] as usize;
            if i < self.host.particles.len() {
                let problem = self.host.instability_of(i);
                return Err(self.host.unstable(i, problem).into());
            }
            return Err(SimulationError::NonFinite {
                step: self.host.step,
                id: 0,
                field: "position or velocity (of a ghost)",
            }
            .into());
        }
        let pending = self.host.inserter_pending();
        if let Some(par) = self.host.parallel.as_deref_mut() {
            // All ranks rebuild together: when some rank inserts, removes or has a particle
            // that moved half the skin. The rebuild is a round trip through the host, where
            // migration, balancing and the choice of ghosts run as on the CPU backend.
            let local = flags[0] != 0 || flags[1] > 0 || self.rebuild;
            let t_wait = Instant::now();
            let rebuild = par.comm.any(local) || pending;
            par.timers.wait += t_wait.elapsed().as_secs_f64();
            if rebuild {
                self.sync_host()?;
                self.host.rebuild_exchange_on_host()?;
                self.upload_walls()?;
                self.upload_from_host()?;
            }
            // Ghosts were not integrated: between rebuilds their owners' motion comes through
            // the halo, overlapped with the pairs of owned particles ([`Self::forces`]).
            self.halo_due = !rebuild;
        } else {
            if flags[1] > 0 || self.host.inserter_pending() {
                // Insertion or removal: the host does it on a synced copy, then everything
                // goes back up (with the history) and the list is rebuilt.
                self.sync_host()?;
                self.host.exchange_on_host()?;
                self.upload_from_host()?;
            }
            if flags[0] != 0 {
                self.rebuild = true;
            }
        }
        if flags[4] != 0
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
