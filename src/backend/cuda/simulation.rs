//! The step on the GPU: [`CudaSimulation`] keeps the particle state, the pair list and the
//! contact history resident on the device and launches the kernels of `cuda/` stage by stage in
//! the order of DESIGN.md §1 (the GPU twin of [`Simulation`], as HOOMD-blue pairs a GPU class
//! with each expensive CPU class). The host copy in [`CudaSimulation::host`] is refreshed only
//! when it is read (output, checkpoint) or changed (insertion, removal), so an ordinary step
//! copies nothing but a 16-byte status word back.

use super::kernels::{KernelConfig, Precision, compile};
use super::layout::{GridParams, PairMaterial};
use crate::contact::{ContactHistory, ContactKey, ContactState, DampingTable, WallMesh};
use crate::neighbor::Bounds;
use crate::pipeline::{Simulation, SimulationError};
use crate::scene::WallMotion;
use cudarc::driver::{
    CudaContext, CudaFunction, CudaModule, CudaSlice, CudaStream, DeviceRepr, LaunchConfig,
    PushKernelArg, ValidAsZeroBits,
};
use nalgebra::{UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

/// Threads per block of the per-particle and per-pair kernels.
const BLOCK: u32 = 128;
/// Elements per block of `scan.cu` (its PD_SCAN_BLOCK).
const SCAN_BLOCK: usize = 1024;

/// Errors of the CUDA backend, each saying what failed.
#[derive(Debug, thiserror::Error)]
pub enum CudaError {
    #[error("CUDA driver: {0}")]
    Driver(#[from] cudarc::driver::DriverError),
    #[error("{0}")]
    Compile(String),
    #[error(transparent)]
    Simulation(#[from] SimulationError),
}

fn cfg(n: usize) -> LaunchConfig {
    LaunchConfig {
        grid_dim: ((n as u32).div_ceil(BLOCK).max(1), 1, 1),
        block_dim: (BLOCK, 1, 1),
        shared_mem_bytes: 0,
    }
}

/// One wall mesh as the kernels read it (`cuda/contact.cu: WallInfo`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
struct WallInfo {
    facet_offset: i32,
    n_facets: i32,
    cell_offset: i32,
    material: i32,
    grid_min: [f64; 3],
    grid_size: f64,
    dims: [i32; 3],
    pad: i32,
}
// SAFETY: plain old data laid out as the C struct.
unsafe impl DeviceRepr for WallInfo {}

/// A wall's pose and velocity field at the current time (`cuda/contact.cu: WallState`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
struct WallState {
    rotation: [f64; 4],
    translation: [f64; 3],
    v0: [f64; 3],
    omega: [f64; 3],
    origin: [f64; 3],
}
// SAFETY: plain old data laid out as the C struct.
unsafe impl DeviceRepr for WallState {}
// SAFETY: all-zero bits are valid f64 values.
unsafe impl ValidAsZeroBits for WallState {}

/// The particle state the contact kernels read (`cuda/contact.cu: ParticleView`): device
/// pointers, valid while the buffers they point into are alive and not reallocated.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct ParticleView {
    ptrs: [u64; 12],
}
// SAFETY: twelve device pointers, laid out as the C struct of twelve pointers.
unsafe impl DeviceRepr for ParticleView {}

/// Per-pair outputs (`cuda/contact.cu: PairOutputs`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct PairOutputs {
    ptrs: [u64; 3],
}
// SAFETY: three device pointers.
unsafe impl DeviceRepr for PairOutputs {}

fn ptr<T>(s: &CudaSlice<T>, stream: &CudaStream) -> u64 {
    use cudarc::driver::DevicePtr;
    let (p, _sync) = s.device_ptr(stream);
    p
}

/// Kernel handles.
struct Kernels {
    _modules: Vec<Arc<CudaModule>>,
    contact: Arc<CudaModule>,
    f: HashMap<&'static str, CudaFunction>,
}

impl Kernels {
    fn get(&self, name: &str) -> &CudaFunction {
        &self.f[name]
    }
}

/// Particle arrays on the device (xyz-interleaved vectors, quaternions as x, y, z, w).
struct DeviceParticles {
    id: CudaSlice<u64>,
    tmpl: CudaSlice<u32>,
    material: CudaSlice<u32>,
    kind: CudaSlice<u32>,
    scale: CudaSlice<f64>,
    radius: CudaSlice<f64>,
    cn: CudaSlice<f64>,
    ct: CudaSlice<f64>,
    mass: CudaSlice<f64>,
    position: CudaSlice<f64>,
    velocity: CudaSlice<f64>,
    angular_velocity: CudaSlice<f64>,
    orientation: CudaSlice<f64>,
    force: CudaSlice<f64>,
    torque: CudaSlice<f64>,
    inertia: CudaSlice<f64>,
}

/// The pair list and everything indexed by pair.
struct DevicePairs {
    n: usize,
    offset: CudaSlice<u32>,
    pairs: CudaSlice<i32>,
    shift: CudaSlice<f64>,
    axes: CudaSlice<f64>,
    spring_in: CudaSlice<f64>,
    spring_out: CudaSlice<f64>,
    forces: CudaSlice<f64>,
    energy: CudaSlice<f64>,
    contact: CudaSlice<u32>,
    ref_offset: CudaSlice<u32>,
    refs: CudaSlice<u32>,
}

/// Wall meshes and per-particle wall outputs.
struct DeviceWalls {
    n: usize,
    info: CudaSlice<WallInfo>,
    states: CudaSlice<WallState>,
    triangles: CudaSlice<f64>,
    prisms: CudaSlice<f64>,
    cell_start: CudaSlice<u32>,
    cell_items: CudaSlice<u32>,
    spring_in: CudaSlice<f64>,
    spring_out: CudaSlice<f64>,
    force: CudaSlice<f64>,
    torque: CudaSlice<f64>,
    energy: CudaSlice<f64>,
    per_wall_force: CudaSlice<f64>,
    contact: CudaSlice<u32>,
}

/// The contact history handed to the next list build: for each particle in the numbering
/// before the build's reordering, its pairs' partner ids and springs (CSR).
struct HistorySource {
    offset: CudaSlice<u32>,
    partner: CudaSlice<u64>,
    spring: CudaSlice<f64>,
}

/// A simulation stepped on the GPU. See the module docs.
pub struct CudaSimulation {
    /// Host copy: scene, inserter, time, step, statistics, and (when synced) the state.
    pub host: Simulation,
    /// Device name.
    pub device: String,
    /// Arithmetic of the pair geometry.
    pub precision: Precision,
    _ctx: Arc<CudaContext>,
    stream: Arc<CudaStream>,
    k: Kernels,
    config: KernelConfig,
    grid: GridParams,
    skin: f64,
    n: usize,
    p: DeviceParticles,
    pairs: Option<DevicePairs>,
    walls: Option<DeviceWalls>,
    materials: CudaSlice<PairMaterial>,
    reference: CudaSlice<f64>,
    flags: CudaSlice<u32>,
    error: CudaSlice<u32>,
    pending_history: Option<HistorySource>,
    host_current: bool,
    rebuild: bool,
}

impl CudaSimulation {
    /// Moves `host` (freshly created or restored, forces evaluated or restored) onto GPU
    /// `ordinal`, compiling the kernels for it with the scene's configuration.
    pub fn new(host: Simulation, ordinal: usize, precision: Precision) -> Result<Self, CudaError> {
        let ctx = CudaContext::new(ordinal)?;
        let stream = ctx.default_stream();
        let (major, minor) = ctx.compute_capability()?;
        let arch = (major * 10 + minor) as u32;
        let config = KernelConfig::for_scene(&host.scene, precision);
        let mut modules = Vec::new();
        let mut f = HashMap::new();
        let mut contact = None;
        let names: &[(&str, &[&'static str])] = &[
            ("scan.cu", &["scan_blocks", "scan_add"]),
            (
                "integrate.cu",
                &["half_kick", "drift", "step_checks", "wrap_periodic"],
            ),
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
                &["pair_contacts", "wall_contacts", "reduce_forces"],
            ),
        ];
        for (file, kernels) in names {
            let ptx = compile(file, &config, arch).map_err(CudaError::Compile)?;
            let module = ctx.load_module(ptx)?;
            for &name in *kernels {
                if name == "wall_contacts" && !config.walls {
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
        // Materials: restitution, friction and damping table per pair (as Simulation::new).
        let n_mat = s.materials.len();
        let mut materials = Vec::with_capacity(n_mat * n_mat);
        for a in 0..n_mat {
            for b in 0..n_mat {
                let pp = s.pairs.get(a, b);
                let e = s.pairs.try_get(a, b).map_or(1.0, |p| p.restitution);
                materials.push(PairMaterial {
                    restitution: pp.restitution,
                    friction: pp.friction,
                    damping: *DampingTable::new(e).values(),
                });
            }
        }
        let materials = stream.clone_htod(&materials)?;
        let bounds = Bounds {
            min: s.domain.min,
            max: s.domain.max,
            periodic: s.domain.periodic,
        };
        let skin = s.simulation.neighbor.skin;
        let cutoff = 2.0 * s.max_bounding_radius() + skin;
        let grid = GridParams::new(&bounds, cutoff, 4 * host.particles.len().max(1));
        let empty_p = DeviceParticles::empty(&stream)?;
        let mut sim = CudaSimulation {
            device,
            precision,
            flags: stream.alloc_zeros::<u32>(4)?,
            error: stream.alloc_zeros::<u32>(2)?,
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
            stream,
            host,
        };
        sim.upload_templates()?;
        sim.upload_walls()?;
        sim.upload_from_host()?;
        Ok(sim)
    }

    /// A new simulation of `scene` on GPU `ordinal`: particles of count insertions placed on
    /// the host, the first forces evaluated on the device (as [`Simulation::new`] does on the
    /// CPU, advancing the springs by one step).
    pub fn from_scene(
        scene: crate::scene::Scene,
        ordinal: usize,
        precision: Precision,
    ) -> Result<Self, CudaError> {
        let host = Simulation::new_unevaluated(scene)?;
        let mut sim = CudaSimulation::new(host, ordinal, precision)?;
        sim.evaluate_first_forces()?;
        Ok(sim)
    }

    /// The first force evaluation of a new simulation (see [`CudaSimulation::from_scene`]).
    pub fn evaluate_first_forces(&mut self) -> Result<(), CudaError> {
        let dt = self.host.dt;
        self.forces(dt)
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
            + b(&self.reference);
        if let Some(q) = &self.pairs {
            total += b(&q.offset)
                + b(&q.pairs)
                + b(&q.shift)
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
        }
        total
    }

    /// Pairs in the current candidate list.
    pub fn candidate_pairs(&self) -> usize {
        self.pairs.as_ref().map_or(0, |p| p.n)
    }

    fn upload_templates(&mut self) -> Result<(), CudaError> {
        let s = &self.host.scene;
        let (nt, mv, mf) = (
            self.config.templates,
            self.config.max_vertices,
            self.config.max_faces,
        );
        let mut vertices = vec![0.0f64; nt * mv * 3];
        let mut normals = vec![0.0f64; nt * mf * 3];
        let mut offsets = vec![0.0f64; nt * mf];
        let mut counts = vec![0i32; nt * 2];
        let mut radius = vec![0.0f64; nt];
        for (t, tpl) in s.templates.iter().enumerate() {
            for (i, v) in tpl.vertices.iter().enumerate() {
                vertices[(t * mv + i) * 3..(t * mv + i) * 3 + 3]
                    .copy_from_slice(v.coords.as_slice());
            }
            for (i, f) in tpl.faces.iter().enumerate() {
                normals[(t * mf + i) * 3..(t * mf + i) * 3 + 3]
                    .copy_from_slice(f.normal.as_slice());
                offsets[t * mf + i] = f.offset;
            }
            counts[2 * t] = tpl.vertices.len() as i32;
            counts[2 * t + 1] = tpl.faces.len() as i32;
            radius[t] = tpl.circumscribed_radius;
        }
        fn set<T: DeviceRepr>(
            module: &Arc<CudaModule>,
            stream: &Arc<CudaStream>,
            name: &str,
            data: &[T],
        ) -> Result<(), CudaError> {
            let mut view = module.get_global(name, stream)?;
            // SAFETY: the symbol holds at least data.len() values of T (sized by the same
            // KernelConfig that sized `data`).
            let mut typed = unsafe { view.transmute_mut::<T>(data.len()) }.ok_or_else(|| {
                CudaError::Compile(format!("constant {name} is smaller than expected"))
            })?;
            stream.memcpy_htod(data, &mut typed)?;
            Ok(())
        }
        let m = &self.k.contact;
        set(m, &self.stream, "pd_template_vertices", &vertices)?;
        set(m, &self.stream, "pd_template_normals", &normals)?;
        set(m, &self.stream, "pd_template_offsets", &offsets)?;
        set(m, &self.stream, "pd_template_counts", &counts)?;
        set(m, &self.stream, "pd_template_radius", &radius)?;
        Ok(())
    }

    fn upload_walls(&mut self) -> Result<(), CudaError> {
        let s = &self.host.scene;
        if s.walls.is_empty() {
            return Ok(());
        }
        let cell = 2.0 * s.max_bounding_radius() + self.skin;
        let mut info = Vec::new();
        let (mut triangles, mut prisms, mut starts, mut items) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for w in &s.walls {
            let mesh = WallMesh::new(&w.triangles, cell);
            let g = mesh.grid_parts();
            let facet_offset = (triangles.len() / 9) as i32;
            for t in &mesh.triangles {
                for v in t {
                    triangles.extend_from_slice(v.as_slice());
                }
            }
            for p in &mesh.prisms {
                for plane in p {
                    prisms.extend_from_slice(plane.normal.as_slice());
                    prisms.push(plane.offset);
                }
            }
            let cell_offset = starts.len() as i32;
            let item_base = items.len() as u32;
            starts.extend(g.start.iter().map(|&x| x + item_base));
            items.extend_from_slice(g.items);
            info.push(WallInfo {
                facet_offset,
                n_facets: mesh.len() as i32,
                cell_offset,
                material: w.material as i32,
                grid_min: g.min.into(),
                grid_size: g.size,
                dims: g.dims.map(|d| d as i32),
                pad: 0,
            });
        }
        let st = &self.stream;
        let n_walls = info.len();
        let one = |v: &mut Vec<u32>| {
            if v.is_empty() {
                v.push(0);
            }
        };
        one(&mut items);
        self.walls = Some(DeviceWalls {
            n: n_walls,
            info: st.clone_htod(&info)?,
            states: st.alloc_zeros::<WallState>(n_walls)?,
            triangles: st.clone_htod(&triangles)?,
            prisms: st.clone_htod(&prisms)?,
            cell_start: st.clone_htod(&starts)?,
            cell_items: st.clone_htod(&items)?,
            spring_in: st.alloc_zeros::<f64>(1)?,
            spring_out: st.alloc_zeros::<f64>(1)?,
            force: st.alloc_zeros::<f64>(1)?,
            torque: st.alloc_zeros::<f64>(1)?,
            energy: st.alloc_zeros::<f64>(1)?,
            per_wall_force: st.alloc_zeros::<f64>(1)?,
            contact: st.alloc_zeros::<u32>(1)?,
        });
        Ok(())
    }

    /// Uploads the host state (particles, forces, contact history) and schedules a list build.
    fn upload_from_host(&mut self) -> Result<(), CudaError> {
        let st = self.stream.clone();
        let h = &self.host;
        let p = &h.particles;
        let s = &h.scene;
        let n = p.len();
        self.n = n;
        let flat =
            |v: &[Vector3<f64>]| -> Vec<f64> { v.iter().flat_map(|x| [x.x, x.y, x.z]).collect() };
        let quats = |v: &[UnitQuaternion<f64>]| -> Vec<f64> {
            v.iter()
                .flat_map(|q| {
                    let c = q.coords;
                    [c.x, c.y, c.z, c.w]
                })
                .collect()
        };
        let mut tmpl = Vec::with_capacity(n);
        let mut material = Vec::with_capacity(n);
        let (mut radius, mut cn, mut ct) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..n {
            let ty = &s.particle_types[p.kind[i] as usize];
            let t = &s.templates[ty.template];
            let m = &s.materials[ty.material];
            tmpl.push(ty.template as u32);
            material.push(ty.material as u32);
            radius.push(t.circumscribed_radius * p.scale[i]);
            let r = t.equivalent_radius * p.scale[i];
            cn.push(m.youngs_modulus / r);
            ct.push(m.youngs_modulus / (2.0 * (1.0 + m.poisson_ratio) * r));
        }
        let pad = |mut v: Vec<f64>| {
            if v.is_empty() {
                v.push(0.0);
            }
            v
        };
        let pad32 = |mut v: Vec<u32>| {
            if v.is_empty() {
                v.push(0);
            }
            v
        };
        let mut ids = p.id.clone();
        if ids.is_empty() {
            ids.push(0);
        }
        self.p = DeviceParticles {
            id: st.clone_htod(&ids)?,
            tmpl: st.clone_htod(&pad32(tmpl))?,
            material: st.clone_htod(&pad32(material))?,
            kind: st.clone_htod(&pad32(p.kind.clone()))?,
            scale: st.clone_htod(&pad(p.scale.clone()))?,
            radius: st.clone_htod(&pad(radius))?,
            cn: st.clone_htod(&pad(cn))?,
            ct: st.clone_htod(&pad(ct))?,
            mass: st.clone_htod(&pad(p.mass.clone()))?,
            position: st.clone_htod(&pad(flat(&p.position)))?,
            velocity: st.clone_htod(&pad(flat(&p.velocity)))?,
            angular_velocity: st.clone_htod(&pad(flat(&p.angular_velocity)))?,
            orientation: st.clone_htod(&pad(quats(&p.orientation)))?,
            force: st.clone_htod(&pad(flat(&p.force)))?,
            torque: st.clone_htod(&pad(flat(&p.torque)))?,
            inertia: st.clone_htod(&pad(flat(&p.inertia)))?,
        };
        // History, as a CSR over the uploaded order, for the coming list build.
        let index: HashMap<u64, usize> = p.id.iter().enumerate().map(|(i, &g)| (g, i)).collect();
        let mut per: Vec<Vec<(u64, Vector3<f64>)>> = vec![Vec::new(); n];
        let n_walls = self.walls.as_ref().map_or(0, |w| w.n);
        let mut wall_spring = vec![0.0f64; (n * n_walls * 3).max(1)];
        for (key, state) in h.history.entries() {
            let Some(&i) = index.get(&key.a) else {
                continue;
            };
            match key.wall_index() {
                Some(k) if k < n_walls => {
                    let slot = (i * n_walls + k) * 3;
                    wall_spring[slot..slot + 3].copy_from_slice(state.spring.as_slice());
                }
                Some(_) => {}
                None => per[i].push((key.b, state.spring)),
            }
        }
        let mut offset = vec![0u32; n + 1];
        let (mut partner, mut spring) = (Vec::new(), Vec::new());
        for i in 0..n {
            for (b, sp) in &per[i] {
                partner.push(*b);
                spring.extend_from_slice(sp.as_slice());
            }
            offset[i + 1] = partner.len() as u32;
        }
        if partner.is_empty() {
            partner.push(u64::MAX);
            spring.extend_from_slice(&[0.0; 3]);
        }
        self.pending_history = Some(HistorySource {
            offset: st.clone_htod(&offset)?,
            partner: st.clone_htod(&partner)?,
            spring: st.clone_htod(&spring)?,
        });
        if let Some(w) = &mut self.walls {
            let nw = (n * n_walls).max(1);
            w.spring_in = st.clone_htod(&wall_spring)?;
            w.spring_out = st.alloc_zeros::<f64>(3 * nw)?;
            w.force = st.alloc_zeros::<f64>(3 * n.max(1))?;
            w.torque = st.alloc_zeros::<f64>(3 * n.max(1))?;
            w.energy = st.alloc_zeros::<f64>(n.max(1))?;
            w.per_wall_force = st.alloc_zeros::<f64>(3 * nw)?;
            w.contact = st.alloc_zeros::<u32>(nw)?;
        }
        self.pairs = None;
        self.rebuild = true;
        self.host_current = true;
        Ok(())
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
        })
    }
}

fn zeros<T: DeviceRepr + ValidAsZeroBits>(
    st: &Arc<CudaStream>,
    n: usize,
) -> Result<CudaSlice<T>, CudaError> {
    Ok(st.alloc_zeros::<T>(n.max(1))?)
}

impl CudaSimulation {
    /// Exclusive prefix sum of `input[..len]` into `out[..len + 1]` (out[len] = total), with
    /// `scan.cu`; returns the total.
    fn scan(
        &self,
        input: &CudaSlice<u32>,
        len: usize,
        out: &mut CudaSlice<u32>,
    ) -> Result<u32, CudaError> {
        // Scan len + 1 elements, the last read as 0 (scan_blocks zero-fills past n only for the
        // padding of the last block, so a copy with a trailing zero is scanned).
        let m = len + 1;
        let mut padded = self.stream.alloc_zeros::<u32>(m)?;
        if len > 0 {
            self.stream
                .memcpy_dtod(&input.slice(0..len), &mut padded.slice_mut(0..len))?;
        }
        self.scan_inplace(&padded, m, out)?;
        let mut total = [0u32; 1];
        self.stream
            .memcpy_dtoh(&out.slice(len..len + 1), &mut total)?;
        Ok(total[0])
    }

    /// Exclusive scan of `input[..m]` into `out[..m]`.
    fn scan_inplace(
        &self,
        input: &CudaSlice<u32>,
        m: usize,
        out: &mut CudaSlice<u32>,
    ) -> Result<(), CudaError> {
        let blocks = m.div_ceil(SCAN_BLOCK).max(1);
        let mut sums = self.stream.alloc_zeros::<u32>(blocks)?;
        let lc = LaunchConfig {
            grid_dim: (blocks as u32, 1, 1),
            block_dim: (SCAN_BLOCK as u32, 1, 1),
            shared_mem_bytes: 0,
        };
        let mi = m as i32;
        let f = self.k.get("scan_blocks");
        // SAFETY: argument types and counts match the kernel; buffers hold m (out, input) and
        // `blocks` (sums) elements.
        unsafe {
            self.stream
                .launch_builder(f)
                .arg(&mi)
                .arg(input)
                .arg(&mut *out)
                .arg(&mut sums)
                .launch(lc)?;
        }
        if blocks > 1 {
            let mut scanned = self.stream.alloc_zeros::<u32>(blocks)?;
            self.scan_inplace(&sums, blocks, &mut scanned)?;
            let f = self.k.get("scan_add");
            // SAFETY: as above.
            unsafe {
                self.stream
                    .launch_builder(f)
                    .arg(&mi)
                    .arg(&mut *out)
                    .arg(&scanned)
                    .launch(lc)?;
            }
        }
        Ok(())
    }

    fn particle_view(&self) -> ParticleView {
        let st = &self.stream;
        let p = &self.p;
        ParticleView {
            ptrs: [
                ptr(&p.position, st),
                ptr(&p.velocity, st),
                ptr(&p.angular_velocity, st),
                ptr(&p.orientation, st),
                ptr(&p.mass, st),
                ptr(&p.inertia, st),
                ptr(&p.scale, st),
                ptr(&p.radius, st),
                ptr(&p.cn, st),
                ptr(&p.ct, st),
                ptr(&p.tmpl, st),
                ptr(&p.material, st),
            ],
        }
    }

    /// Stage 2: bins, reorders the particle arrays by cell, builds the pair list and the
    /// per-particle references, and carries the contact history over.
    fn build_pairs(&mut self) -> Result<(), CudaError> {
        let st = self.stream.clone();
        let n = self.n;
        let ni = n as i32;
        // History of the current list (or the one uploaded from the host), in the numbering
        // before this build.
        let history = match (self.pending_history.take(), self.pairs.take()) {
            (Some(h), _) => h,
            (None, Some(old)) => {
                let mut partner = zeros::<u64>(&st, old.n)?;
                let npi = old.n as i32;
                // SAFETY: argument types match `history_partners`.
                unsafe {
                    st.launch_builder(self.k.get("history_partners"))
                        .arg(&npi)
                        .arg(&old.pairs)
                        .arg(&self.p.id)
                        .arg(&mut partner)
                        .launch(cfg(old.n))?;
                }
                HistorySource {
                    offset: old.offset,
                    partner,
                    // The latest springs: `forces` swapped them into `spring_in`.
                    spring: old.spring_in,
                }
            }
            (None, None) => HistorySource {
                offset: zeros::<u32>(&st, n + 1)?,
                partner: zeros::<u64>(&st, 1)?,
                spring: zeros::<f64>(&st, 3)?,
            },
        };
        // Bin and sort by cell (global id within a cell).
        let cells = self.grid.cells();
        let mut cell = zeros::<u32>(&st, n)?;
        let mut cell_count = zeros::<u32>(&st, cells)?;
        let g = self.grid;
        // SAFETY (all launches below): argument lists match the kernels' signatures in cuda/,
        // and every buffer holds the element counts the kernels index.
        unsafe {
            st.launch_builder(self.k.get("bin_particles"))
                .arg(&ni)
                .arg(&self.p.position)
                .arg(&g)
                .arg(&mut cell)
                .arg(&mut cell_count)
                .launch(cfg(n))?;
        }
        let mut cell_start = zeros::<u32>(&st, cells + 1)?;
        self.scan(&cell_count, cells, &mut cell_start)?;
        let mut fill = zeros::<u32>(&st, cells)?;
        let mut order = zeros::<u32>(&st, n)?;
        let ci = cells as i32;
        unsafe {
            st.launch_builder(self.k.get("scatter_by_cell"))
                .arg(&ni)
                .arg(&cell)
                .arg(&cell_start)
                .arg(&mut fill)
                .arg(&mut order)
                .launch(cfg(n))?;
            st.launch_builder(self.k.get("sort_cells"))
                .arg(&ci)
                .arg(&cell_start)
                .arg(&mut order)
                .arg(&self.p.id)
                .launch(cfg(cells))?;
        }
        // Reorder every particle array (and the wall springs) by `order`.
        self.gather_all(&order)?;
        // Pairs: count, exclusive prefix sum, fill.
        let mut counts = zeros::<u32>(&st, n)?;
        let skin = self.skin;
        unsafe {
            st.launch_builder(self.k.get("count_pairs"))
                .arg(&ni)
                .arg(&self.p.position)
                .arg(&self.p.radius)
                .arg(&self.p.id)
                .arg(&cell_start)
                .arg(&g)
                .arg(&skin)
                .arg(&mut counts)
                .launch(cfg(n))?;
        }
        let mut offset = zeros::<u32>(&st, n + 1)?;
        let np = self.scan(&counts, n, &mut offset)? as usize;
        let mut pairs = zeros::<i32>(&st, 2 * np)?;
        let mut shift = zeros::<f64>(&st, if self.config.periodic { 3 * np } else { 1 })?;
        let periodic = i32::from(self.config.periodic);
        unsafe {
            st.launch_builder(self.k.get("fill_pairs"))
                .arg(&ni)
                .arg(&self.p.position)
                .arg(&self.p.radius)
                .arg(&self.p.id)
                .arg(&cell_start)
                .arg(&g)
                .arg(&skin)
                .arg(&offset)
                .arg(&mut pairs)
                .arg(&mut shift)
                .arg(&periodic)
                .launch(cfg(n))?;
        }
        // References per particle, sorted by partner id.
        let npi = np as i32;
        let mut ref_count = zeros::<u32>(&st, n)?;
        unsafe {
            st.launch_builder(self.k.get("count_refs"))
                .arg(&npi)
                .arg(&pairs)
                .arg(&mut ref_count)
                .launch(cfg(np))?;
        }
        let mut ref_offset = zeros::<u32>(&st, n + 1)?;
        self.scan(&ref_count, n, &mut ref_offset)?;
        let mut ref_fill = zeros::<u32>(&st, n)?;
        let mut refs = zeros::<u32>(&st, 2 * np)?;
        unsafe {
            st.launch_builder(self.k.get("fill_refs"))
                .arg(&npi)
                .arg(&pairs)
                .arg(&ref_offset)
                .arg(&mut ref_fill)
                .arg(&mut refs)
                .launch(cfg(np))?;
            st.launch_builder(self.k.get("sort_refs"))
                .arg(&ni)
                .arg(&ref_offset)
                .arg(&mut refs)
                .arg(&pairs)
                .arg(&self.p.id)
                .launch(cfg(n))?;
        }
        // The springs of pairs that survive, found by (lower-id member, partner id).
        let mut spring_in = zeros::<f64>(&st, 3 * np)?;
        unsafe {
            st.launch_builder(self.k.get("remap_history"))
                .arg(&npi)
                .arg(&pairs)
                .arg(&self.p.id)
                .arg(&order)
                .arg(&history.offset)
                .arg(&history.partner)
                .arg(&history.spring)
                .arg(&mut spring_in)
                .launch(cfg(np))?;
        }
        self.pairs = Some(DevicePairs {
            n: np,
            offset,
            pairs,
            shift,
            axes: zeros::<f64>(&st, 3 * np)?,
            spring_in,
            spring_out: zeros::<f64>(&st, 3 * np)?,
            forces: zeros::<f64>(&st, 9 * np)?,
            energy: zeros::<f64>(&st, np)?,
            contact: zeros::<u32>(&st, np)?,
            ref_offset,
            refs,
        });
        self.reference = st.clone_dtod(&self.p.position)?;
        self.rebuild = false;
        Ok(())
    }

    fn gather_all(&mut self, order: &CudaSlice<u32>) -> Result<(), CudaError> {
        let st = self.stream.clone();
        let n = self.n;
        let ni = n as i32;
        let g64 = self.k.get("gather_f64").clone();
        let gather = |src: &mut CudaSlice<f64>, width: usize| -> Result<(), CudaError> {
            let mut dst = zeros::<f64>(&st, width * n)?;
            let w = width as i32;
            // SAFETY: `gather_f64(n, width, src, dst, order)`; both buffers hold width·n values.
            unsafe {
                st.launch_builder(&g64)
                    .arg(&ni)
                    .arg(&w)
                    .arg(&*src)
                    .arg(&mut dst)
                    .arg(order)
                    .launch(cfg(n))?;
            }
            *src = dst;
            Ok(())
        };
        let p = &mut self.p;
        for (buf, w) in [
            (&mut p.scale, 1),
            (&mut p.radius, 1),
            (&mut p.cn, 1),
            (&mut p.ct, 1),
            (&mut p.mass, 1),
            (&mut p.position, 3),
            (&mut p.velocity, 3),
            (&mut p.angular_velocity, 3),
            (&mut p.orientation, 4),
            (&mut p.force, 3),
            (&mut p.torque, 3),
            (&mut p.inertia, 3),
        ] {
            gather(buf, w)?;
        }
        if let Some(w) = &mut self.walls {
            let width = 3 * w.n;
            gather(&mut w.spring_in, width)?;
        }
        let g32 = self.k.get("gather_u32").clone();
        for buf in [&mut p.tmpl, &mut p.material, &mut p.kind] {
            let mut dst = zeros::<u32>(&st, n)?;
            // SAFETY: `gather_u32(n, src, dst, order)`.
            unsafe {
                st.launch_builder(&g32)
                    .arg(&ni)
                    .arg(&*buf)
                    .arg(&mut dst)
                    .arg(order)
                    .launch(cfg(n))?;
            }
            *buf = dst;
        }
        let mut id = zeros::<u64>(&st, n)?;
        // SAFETY: `gather_u64(n, src, dst, order)`.
        unsafe {
            st.launch_builder(self.k.get("gather_u64"))
                .arg(&ni)
                .arg(&p.id)
                .arg(&mut id)
                .arg(order)
                .launch(cfg(n))?;
        }
        p.id = id;
        Ok(())
    }
}

impl CudaSimulation {
    /// Stages 2–8 on the device at the current state, advancing the springs by `dt`.
    fn forces(&mut self, dt: f64) -> Result<(), CudaError> {
        let t0 = Instant::now();
        if self.rebuild || self.pairs.is_none() {
            self.build_pairs()?;
        }
        self.stream.synchronize()?;
        self.host.timers.neighbor += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let st = self.stream.clone();
        let view = self.particle_view();
        let n = self.n;
        let ni = n as i32;
        let n_mat = self.host.scene.materials.len() as i32;
        let pairs = self.pairs.as_mut().expect("built above");
        let np = pairs.n;
        let npi = np as i32;
        let outputs = PairOutputs {
            ptrs: [
                ptr(&pairs.forces, &st),
                ptr(&pairs.energy, &st),
                ptr(&pairs.contact, &st),
            ],
        };
        // SAFETY (all launches): argument lists match the kernels of cuda/contact.cu; the
        // pointer structs point into buffers alive for the whole call.
        unsafe {
            st.launch_builder(self.k.get("pair_contacts"))
                .arg(&npi)
                .arg(&pairs.pairs)
                .arg(&pairs.shift)
                .arg(&mut pairs.axes)
                .arg(&view)
                .arg(&self.materials)
                .arg(&n_mat)
                .arg(&pairs.spring_in)
                .arg(&mut pairs.spring_out)
                .arg(&outputs)
                .arg(&dt)
                .arg(&mut self.error)
                .launch(cfg(np))?;
        }
        // Kernels run asynchronously: wait for the stage so that its timer measures it (a few
        // microseconds per stage, negligible against the step).
        st.synchronize()?;
        self.host.timers.pairs += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        if let Some(w) = &mut self.walls {
            let states: Vec<WallState> = self
                .host
                .scene
                .walls
                .iter()
                .map(|wall| wall_state(&wall.motion, self.host.time))
                .collect();
            st.memcpy_htod(&states, &mut w.states)?;
            let nw = w.n as i32;
            unsafe {
                st.launch_builder(self.k.get("wall_contacts"))
                    .arg(&ni)
                    .arg(&view)
                    .arg(&nw)
                    .arg(&w.info)
                    .arg(&w.states)
                    .arg(&w.triangles)
                    .arg(&w.prisms)
                    .arg(&w.cell_start)
                    .arg(&w.cell_items)
                    .arg(&self.materials)
                    .arg(&n_mat)
                    .arg(&w.spring_in)
                    .arg(&mut w.spring_out)
                    .arg(&mut w.force)
                    .arg(&mut w.torque)
                    .arg(&mut w.energy)
                    .arg(&mut w.per_wall_force)
                    .arg(&mut w.contact)
                    .arg(&dt)
                    .arg(&mut self.error)
                    .launch(cfg(n))?;
            }
        }
        st.synchronize()?;
        self.host.timers.walls += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let (wf, wt) = match &self.walls {
            Some(w) => (&w.force, &w.torque),
            None => (&self.p.force, &self.p.torque), // not read without walls
        };
        let (mut force, mut torque) = (zeros::<f64>(&st, 3 * n)?, zeros::<f64>(&st, 3 * n)?);
        unsafe {
            st.launch_builder(self.k.get("reduce_forces"))
                .arg(&ni)
                .arg(&pairs.ref_offset)
                .arg(&pairs.refs)
                .arg(&pairs.forces)
                .arg(wf)
                .arg(wt)
                .arg(&mut force)
                .arg(&mut torque)
                .launch(cfg(n))?;
        }
        self.p.force = force;
        self.p.torque = torque;
        // The springs just computed are the history of the next evaluation.
        std::mem::swap(&mut pairs.spring_in, &mut pairs.spring_out);
        if let Some(w) = &mut self.walls {
            std::mem::swap(&mut w.spring_in, &mut w.spring_out);
        }
        let mut error = [0u32; 2];
        st.memcpy_dtoh(&self.error, &mut error)?;
        self.host.timers.reduce += t0.elapsed().as_secs_f64();
        if error[0] != 0 {
            return Err(SimulationError::Geometry {
                step: self.host.step,
                what: format!("pair or particle slot {} on the GPU", error[1]),
                message: format!(
                    "geometry status {} (cuda/polytope.cuh status codes)",
                    error[0]
                ),
            }
            .into());
        }
        self.host_current = false;
        Ok(())
    }

    fn half_kick(&mut self) -> Result<(), CudaError> {
        let g = self.host.scene.gravity;
        let (dt, ni) = (self.host.dt, self.n as i32);
        let p = &mut self.p;
        // SAFETY: `half_kick` of cuda/integrate.cu; every buffer holds 3n (4n) values.
        unsafe {
            self.stream
                .launch_builder(self.k.get("half_kick"))
                .arg(&ni)
                .arg(&mut p.velocity)
                .arg(&mut p.angular_velocity)
                .arg(&p.force)
                .arg(&p.torque)
                .arg(&p.mass)
                .arg(&p.inertia)
                .arg(&p.orientation)
                .arg(&g.x)
                .arg(&g.y)
                .arg(&g.z)
                .arg(&dt)
                .launch(cfg(self.n))?;
        }
        Ok(())
    }

    /// Advances one time step: the stage order of [`Simulation::step`].
    pub fn step(&mut self) -> Result<(), CudaError> {
        let t0 = Instant::now();
        // The device state changes from here on: the host copy is stale until synced again.
        self.host_current = false;
        self.half_kick()?;
        let (dt, ni) = (self.host.dt, self.n as i32);
        {
            let p = &mut self.p;
            // SAFETY: `drift` of cuda/integrate.cu.
            unsafe {
                self.stream
                    .launch_builder(self.k.get("drift"))
                    .arg(&ni)
                    .arg(&mut p.position)
                    .arg(&p.velocity)
                    .arg(&mut p.orientation)
                    .arg(&mut p.angular_velocity)
                    .arg(&p.inertia)
                    .arg(&dt)
                    .launch(cfg(self.n))?;
            }
        }
        self.host.time += dt;
        self.host.step += 1;
        self.stream.synchronize()?;
        self.host.timers.integrate += t0.elapsed().as_secs_f64();
        // Stage 1: periodic wrap and the per-step checks on the device; insertion and removal
        // on the host (rare steps).
        let t0 = Instant::now();
        let g = self.grid;
        if self.config.periodic {
            // SAFETY: `wrap_periodic`.
            unsafe {
                self.stream
                    .launch_builder(self.k.get("wrap_periodic"))
                    .arg(&ni)
                    .arg(&mut self.p.position)
                    .arg(&g)
                    .launch(cfg(self.n))?;
            }
        }
        let mut flags = [0u32, 0, 0, u32::MAX];
        self.stream.memcpy_htod(&flags, &mut self.flags)?;
        if self.n > 0 && self.pairs.is_some() {
            let half_skin = 0.5 * self.skin;
            // SAFETY: `step_checks`; `reference` holds 3n values since the last list build.
            unsafe {
                self.stream
                    .launch_builder(self.k.get("step_checks"))
                    .arg(&ni)
                    .arg(&self.p.position)
                    .arg(&self.p.velocity)
                    .arg(&self.reference)
                    .arg(&g)
                    .arg(&half_skin)
                    .arg(&mut self.flags)
                    .launch(cfg(self.n))?;
            }
            self.stream.memcpy_dtoh(&self.flags, &mut flags)?;
        }
        if flags[2] != 0 {
            self.sync_host()?;
            let i = flags[3] as usize;
            return Err(SimulationError::NonFinite {
                step: self.host.step,
                id: self.host.particles.id.get(i).copied().unwrap_or(0),
                field: "position or velocity",
            }
            .into());
        }
        if flags[1] > 0 || self.host.inserter_pending() {
            // Insertion or removal: the host does it on a synced copy, then everything goes
            // back up (with the history) and the list is rebuilt.
            self.sync_host()?;
            self.host.exchange_on_host()?;
            self.upload_from_host()?;
        }
        if flags[0] != 0 {
            self.rebuild = true;
        }
        self.host.timers.exchange += t0.elapsed().as_secs_f64();
        self.forces(dt)?;
        let t0 = Instant::now();
        self.half_kick()?;
        self.stream.synchronize()?;
        self.host.timers.integrate += t0.elapsed().as_secs_f64();
        Ok(())
    }

    /// Copies the device state into [`CudaSimulation::host`] (particles in the device's
    /// current order, forces, contact history, statistics and wall forces), when it is stale.
    pub fn sync_host(&mut self) -> Result<&Simulation, CudaError> {
        if self.host_current {
            return Ok(&self.host);
        }
        let st = &self.stream;
        let n = self.n;
        let get = |s: &CudaSlice<f64>| st.clone_dtoh(s);
        let vec3 = |v: Vec<f64>| -> Vec<Vector3<f64>> {
            v.chunks_exact(3)
                .take(n)
                .map(|c| Vector3::new(c[0], c[1], c[2]))
                .collect()
        };
        let p = &mut self.host.particles;
        let mut id = st.clone_dtoh(&self.p.id)?;
        id.truncate(n);
        p.id = id;
        let mut kind = st.clone_dtoh(&self.p.kind)?;
        kind.truncate(n);
        p.kind = kind;
        let mut scale = get(&self.p.scale)?;
        scale.truncate(n);
        p.scale = scale;
        let mut mass = get(&self.p.mass)?;
        mass.truncate(n);
        p.mass = mass;
        p.position = vec3(get(&self.p.position)?);
        p.velocity = vec3(get(&self.p.velocity)?);
        p.angular_velocity = vec3(get(&self.p.angular_velocity)?);
        p.force = vec3(get(&self.p.force)?);
        p.torque = vec3(get(&self.p.torque)?);
        p.inertia = vec3(get(&self.p.inertia)?);
        p.orientation = get(&self.p.orientation)?
            .chunks_exact(4)
            .take(n)
            .map(|c| {
                UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(c[3], c[0], c[1], c[2]))
            })
            .collect();
        // History and statistics from the last evaluation (springs are in `spring_in` after
        // the swap at its end).
        let mut entries = Vec::new();
        let (mut contacts, mut wall_contacts, mut energy) = (0u64, 0u64, 0.0f64);
        if let Some(pairs) = &self.pairs {
            let pr = st.clone_dtoh(&pairs.pairs)?;
            let contact = st.clone_dtoh(&pairs.contact)?;
            let spring = get(&pairs.spring_in)?;
            let e = get(&pairs.energy)?;
            for k in 0..pairs.n {
                energy += e[k];
                if contact[k] != 0 {
                    contacts += 1;
                    let (a, b) = (pr[2 * k] as usize, pr[2 * k + 1] as usize);
                    entries.push((
                        ContactKey::particles(p.id[a], p.id[b]),
                        ContactState {
                            spring: Vector3::new(
                                spring[3 * k],
                                spring[3 * k + 1],
                                spring[3 * k + 2],
                            ),
                        },
                    ));
                }
            }
        }
        let mut wall_forces = vec![Vector3::zeros(); self.walls.as_ref().map_or(0, |w| w.n)];
        if let Some(w) = &self.walls {
            let contact = st.clone_dtoh(&w.contact)?;
            let spring = get(&w.spring_in)?;
            let e = get(&w.energy)?;
            let f = get(&w.per_wall_force)?;
            for i in 0..n {
                energy += e[i];
                for k in 0..w.n {
                    let s = i * w.n + k;
                    if contact[s] != 0 {
                        wall_contacts += 1;
                        wall_forces[k] += Vector3::new(f[3 * s], f[3 * s + 1], f[3 * s + 2]);
                        entries.push((
                            ContactKey::wall(p.id[i], k),
                            ContactState {
                                spring: Vector3::new(
                                    spring[3 * s],
                                    spring[3 * s + 1],
                                    spring[3 * s + 2],
                                ),
                            },
                        ));
                    }
                }
            }
        }
        self.host.history = ContactHistory::from_entries(entries);
        self.host.stats.contacts = contacts;
        self.host.stats.wall_contacts = wall_contacts;
        self.host.stats.elastic_energy = energy;
        self.host.wall_forces = wall_forces;
        self.host_current = true;
        Ok(&self.host)
    }
}

/// A wall's pose and velocity field at time `t` (the GPU form of [`WallMotion::transform`],
/// `velocity_at` and `angular_velocity`: v(c) = v0 + ω × (c − origin)).
fn wall_state(motion: &WallMotion, t: f64) -> WallState {
    let pose = motion.transform(t);
    let c = pose.rotation.coords;
    let (v0, omega, origin) = match motion {
        WallMotion::Rotate { origin, .. } => (Vector3::zeros(), motion.angular_velocity(), *origin),
        _ => (
            motion.velocity_at(t, &Vector3::zeros()),
            Vector3::zeros(),
            Vector3::zeros(),
        ),
    };
    WallState {
        rotation: [c.x, c.y, c.z, c.w],
        translation: pose.translation.vector.into(),
        v0: v0.into(),
        omega: omega.into(),
        origin: origin.into(),
    }
}
