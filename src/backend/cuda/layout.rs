//! Every struct shared with the kernels, `#[repr(C)]` here and mirrored field for field in
//! `cuda/layout.cuh`. Their sizes and field offsets go to NVRTC as `PD_SIZEOF_<STRUCT>` and
//! `PD_OFFSETOF_<STRUCT>_<field>` defines ([`layout_defines`]), which `cuda/layout.cuh`
//! `static_assert`s (docs/design.md §3), so a layout drift fails the kernel compile check in CI.
//! Device pointers are `u64` ([`DevPtr`]); structs passed by value to a kernel (the `*Params`)
//! carry explicit `pad` fields where C would insert padding.

use super::kernels::Precision;
use crate::neighbor::Bounds;
use cudarc::driver::{DeviceRepr, ValidAsZeroBits};

/// The domain box and the neighbour grid (`cuda/state.cuh: GridParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GridParams {
    pub min: [f64; 3],
    pub max: [f64; 3],
    pub size: [f64; 3],
    pub dims: [i32; 3],
    pub periodic: [i32; 3],
}

// SAFETY: plain old data of f64 and i32, laid out as the C struct of the same name.
unsafe impl DeviceRepr for GridParams {}

impl GridParams {
    /// The grid of the CPU neighbour search ([`crate::neighbor::grid_layout`]) for `bounds` and
    /// cells at least `cutoff` wide, at most about `max(max_cells, 4096)` of them.
    pub fn new(bounds: &Bounds, cutoff: f64, max_cells: usize) -> Self {
        let (size, dims) = crate::neighbor::grid_layout(bounds, cutoff, max_cells);
        GridParams {
            min: bounds.min.into(),
            max: bounds.max.into(),
            size: size.into(),
            dims: dims.map(|d| d as i32),
            periodic: bounds.periodic.map(i32::from),
        }
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }
}

/// Doubles per contact in the device's contact history: the tangential spring `√k_t ξ` (3),
/// the current loading cycle's approach speed, signed by its phase, and the torsional spring
/// `√k_tw φ`
/// (`contact::ContactState`, in that order;
/// `cuda/contact_law.cuh: PD_HISTORY_WIDTH`).
pub const HISTORY_WIDTH: usize = 5;

/// The contact flag (pair `contact`, `wall_contact`) of a live contact.
pub const CONTACT_LIVE: u32 = 1;

/// The bit of a contact flag whose geometry failed this step, its status in the low byte
/// (`PD_CONTACT_FAILED` of cuda/contact.cu).
pub const CONTACT_FAILED: u32 = 0x100;

/// The history record of `state`, in the device's layout.
pub fn history_record(state: &crate::contact::ContactState) -> [f64; HISTORY_WIDTH] {
    let s = &state.spring;
    [s.x, s.y, s.z, state.approach_speed, state.twist]
}

/// The contact state of a device history record (`record` holds [`HISTORY_WIDTH`] doubles).
pub fn history_state(record: &[f64]) -> crate::contact::ContactState {
    crate::contact::ContactState {
        spring: nalgebra::Vector3::new(record[0], record[1], record[2]),
        approach_speed: record[3],
        twist: record[4],
    }
}

/// Contact parameters of one pair of materials (`cuda/layout.cuh: PairMaterial`): the
/// restitution, friction and the Hunt–Crossley coefficient ᾱ(e), with ln e and sqrt((ln e)² + π²) of the
/// tangential dashpot (`contact::law`), computed here so that the kernels take no logarithm per
/// contact and round as the CPU backend does, and the rolling friction μ_r.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairMaterial {
    pub restitution: f64,
    pub friction: f64,
    pub damping: f64,
    pub log_restitution: f64,
    pub log_norm: f64,
    pub rolling_friction: f64,
}

impl PairMaterial {
    /// The parameters of a pair with restitution `e`, friction coefficient `friction`, rolling
    /// friction `rolling_friction` and damping coefficient `damping` = ᾱ(e) (as
    /// `SimulationBuilder::build` computes it).
    pub fn new(restitution: f64, friction: f64, rolling_friction: f64, damping: f64) -> Self {
        // The same expressions as contact::law (`e.ln()`, `powi(2)`), for the same bits.
        let log_restitution = restitution.ln();
        let log_norm = (log_restitution.powi(2) + std::f64::consts::PI.powi(2)).sqrt();
        PairMaterial {
            restitution,
            friction,
            damping,
            log_restitution,
            log_norm,
            rolling_friction,
        }
    }
}

// SAFETY: plain old data of f64.
unsafe impl DeviceRepr for PairMaterial {}

/// A device pointer as the kernels' structs hold it (null: 0).
pub type DevPtr = u64;

/// The per-step status flags `kick_drift` reduces into (`cuda/layout.cuh: StepFlags`); the host
/// zeroes them (a memset, which needs no host buffer) and reads them back after the drift.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepFlags {
    /// Some particle moved more than half the skin since the last list build.
    pub rebuild: u32,
    /// Particles outside a closed domain box.
    pub outside: u32,
    /// A position or velocity is not finite, or a particle broke the guard's speed bound.
    pub unstable: u32,
    /// The bitwise complement of the smallest local index of such a particle (0: none), so
    /// that cleared flags are all zeros.
    pub first_unstable: u32,
    /// Some particle left the wall list's reach.
    pub wall_rebuild: u32,
    /// Some particle moved more than the snapshot distance since the list build: the next
    /// host-built list is due (docs/design.md §7).
    pub snapshot: u32,
}

impl StepFlags {
    /// The smallest local index of a particle that failed the checks.
    pub fn first_unstable(&self) -> usize {
        !self.first_unstable as usize
    }
}

// SAFETY: six u32, laid out as the C struct; all-zero bits are valid.
unsafe impl DeviceRepr for StepFlags {}
unsafe impl ValidAsZeroBits for StepFlags {}

/// The particle state the contact kernels read (`cuda/layout.cuh: ParticleView`): device
/// pointers, valid while the buffers they point into are alive and not reallocated.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct ParticleView {
    pub position: DevPtr,
    pub velocity: DevPtr,
    pub angular_velocity: DevPtr,
    pub orientation: DevPtr,
    pub mass: DevPtr,
    pub inertia: DevPtr,
    pub scale: DevPtr,
    pub radius: DevPtr,
    pub cn: DevPtr,
    pub ct: DevPtr,
    pub tmpl: DevPtr,
    pub material: DevPtr,
    /// Contacts at the last evaluation (u32; the dashpot caps' mass splitting).
    pub contacts: DevPtr,
}
// SAFETY: thirteen device pointers, laid out as the C struct.
unsafe impl DeviceRepr for ParticleView {}

/// Per-pair outputs (`cuda/layout.cuh: PairOutputs`): nine force and torque values, the
/// elastic energy and the contact flag per pair.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct PairOutputs {
    pub forces: DevPtr,
    pub energy: DevPtr,
    pub contact: DevPtr,
}
// SAFETY: three device pointers.
unsafe impl DeviceRepr for PairOutputs {}

/// Everything a pair evaluation reads and writes (`cuda/layout.cuh: PairArgs`): device pointers
/// into the pair list's and the particles' buffers, valid while those are alive.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct PairArgs {
    pub pairs: DevPtr,
    pub grid: GridParams,
    pub axes: DevPtr,
    pub p: ParticleView,
    pub materials: DevPtr,
    pub n_materials: i32,
    pub spring_in: DevPtr,
    pub spring_out: DevPtr,
    pub out: PairOutputs,
    pub dt: f64,
    pub max_overlap: f64,
    pub error: DevPtr,
}
// SAFETY: device pointers, a GridParams, an int and doubles, laid out as the C struct.
unsafe impl DeviceRepr for PairArgs {}

/// One wall mesh as the kernels read it (`cuda/layout.cuh: WallInfo`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct WallInfo {
    pub facet_offset: i32,
    pub n_facets: i32,
    pub cell_offset: i32,
    pub material: i32,
    pub grid_min: [f64; 3],
    pub grid_size: f64,
    pub dims: [i32; 3],
    pub pad: i32,
}
// SAFETY: plain old data laid out as the C struct.
unsafe impl DeviceRepr for WallInfo {}

/// A wall's pose and velocity field at the current time (`cuda/layout.cuh: WallState`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct WallState {
    pub rotation: [f64; 4],
    pub translation: [f64; 3],
    pub v0: [f64; 3],
    pub omega: [f64; 3],
    pub origin: [f64; 3],
}
// SAFETY: plain old data laid out as the C struct; all-zero bits are valid f64 values.
unsafe impl DeviceRepr for WallState {}
unsafe impl ValidAsZeroBits for WallState {}

/// The arguments of `kick_drift` (cuda/integrate.cu; `cuda/layout.cuh: KickDriftParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct KickDriftParams {
    pub n: i32,
    /// Nonzero: the periodic wrap.
    pub wrap: i32,
    /// Nonzero: the per-step checks against `reference`.
    pub checks: i32,
    pub pad: i32,
    pub ghost: DevPtr,
    pub position: DevPtr,
    pub velocity: DevPtr,
    pub orientation: DevPtr,
    pub angular_velocity: DevPtr,
    pub force: DevPtr,
    pub torque: DevPtr,
    pub mass: DevPtr,
    pub inertia: DevPtr,
    pub radius: DevPtr,
    pub gravity: [f64; 3],
    pub dt: f64,
    pub grid: GridParams,
    pub reference: DevPtr,
    pub half_skin: f64,
    /// `snapshot` is set when some particle moved farther than this (infinite: never).
    pub snapshot_distance: f64,
    /// Null: no wall list to check.
    pub wall_reference: DevPtr,
    pub wall_half_reach: f64,
    pub max_speed: f64,
    pub flags: DevPtr,
}
// SAFETY: ints, doubles, device pointers and a GridParams, laid out as the C struct.
unsafe impl DeviceRepr for KickDriftParams {}

/// The arguments of `reduce_and_kick` (cuda/integrate.cu; `cuda/layout.cuh:
/// ReduceKickParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ReduceKickParams {
    pub n: i32,
    /// Nonzero: the second half kick after the reduction.
    pub kick: i32,
    pub ref_offset: DevPtr,
    pub refs: DevPtr,
    pub pair_forces: DevPtr,
    /// Null without walls.
    pub wall_force: DevPtr,
    pub wall_torque: DevPtr,
    pub force: DevPtr,
    pub torque: DevPtr,
    pub ghost: DevPtr,
    pub velocity: DevPtr,
    pub angular_velocity: DevPtr,
    pub mass: DevPtr,
    pub inertia: DevPtr,
    pub orientation: DevPtr,
    /// The pair slots' contact flags (u32).
    pub pair_contact: DevPtr,
    /// The wall slots' contact flags (u32, particle-major); null without walls.
    pub wall_contact: DevPtr,
    /// Out: each particle's contacts, pairs and walls (u32).
    pub contacts: DevPtr,
    pub n_walls: i32,
    pub pad: i32,
    pub gravity: [f64; 3],
    pub dt: f64,
}
// SAFETY: ints, device pointers and doubles, laid out as the C struct.
unsafe impl DeviceRepr for ReduceKickParams {}

/// The particles and the grid of `count_pairs` and `fill_pairs` (cuda/neighbor.cu;
/// `cuda/layout.cuh: PairSearchParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct PairSearchParams {
    pub n: i32,
    /// 0 all pairs; in a decomposed run 1 those of two owned particles, 2 those with a ghost.
    pub part: i32,
    pub position: DevPtr,
    pub radius: DevPtr,
    pub id: DevPtr,
    pub ghost: DevPtr,
    pub cell_start: DevPtr,
    pub grid: GridParams,
    pub skin: f64,
}
// SAFETY: ints, device pointers, a GridParams and a double, laid out as the C struct.
unsafe impl DeviceRepr for PairSearchParams {}

/// The arguments of `wall_candidates` (cuda/contact.cu; `cuda/layout.cuh:
/// WallCandidatesParams`): null `offset` and `items` count, else list.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct WallCandidatesParams {
    pub n: i32,
    pub n_walls: i32,
    pub p: ParticleView,
    pub walls: DevPtr,
    pub states: DevPtr,
    pub triangles: DevPtr,
    pub cell_start: DevPtr,
    pub cell_items: DevPtr,
    pub skin: f64,
    pub counts: DevPtr,
    pub offset: DevPtr,
    pub items: DevPtr,
}
// SAFETY: ints, a ParticleView, device pointers and a double, laid out as the C struct.
unsafe impl DeviceRepr for WallCandidatesParams {}

/// The arguments of `wall_facet_overlaps` (cuda/contact.cu; `cuda/layout.cuh:
/// WallOverlapsParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct WallOverlapsParams {
    pub n_items: i32,
    pub n_walls: i32,
    pub items: DevPtr,
    pub p: ParticleView,
    pub states: DevPtr,
    pub triangles: DevPtr,
    pub prisms: DevPtr,
    pub overlaps: DevPtr,
    pub error: DevPtr,
}
// SAFETY: ints, a ParticleView and device pointers, laid out as the C struct.
unsafe impl DeviceRepr for WallOverlapsParams {}

/// The arguments of `wall_contacts` (cuda/contact.cu; `cuda/layout.cuh: WallContactsParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct WallContactsParams {
    pub n: i32,
    pub n_walls: i32,
    pub n_materials: i32,
    pub pad: i32,
    pub p: ParticleView,
    pub states: DevPtr,
    pub walls: DevPtr,
    pub item_offset: DevPtr,
    pub items: DevPtr,
    pub overlaps: DevPtr,
    pub materials: DevPtr,
    pub spring_in: DevPtr,
    pub spring_out: DevPtr,
    pub wall_force: DevPtr,
    pub wall_torque: DevPtr,
    pub wall_energy: DevPtr,
    pub per_wall_force: DevPtr,
    pub wall_contact: DevPtr,
    pub dt: f64,
    pub max_overlap: f64,
    pub error: DevPtr,
}
// SAFETY: ints, a ParticleView, device pointers and doubles, laid out as the C struct.
unsafe impl DeviceRepr for WallContactsParams {}

/// The template table of the probe kernels (cuda/probe.cu; `cuda/layout.cuh: ProbeTemplates`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ProbeTemplates {
    pub vertices: DevPtr,
    pub normals: DevPtr,
    pub offsets: DevPtr,
    pub counts: DevPtr,
    pub radius: DevPtr,
    pub face_start: DevPtr,
    pub face_points: DevPtr,
    pub max_vertices: i32,
    pub max_faces: i32,
    pub max_face_indices: i32,
}
// SAFETY: seven device pointers and three ints, laid out as the C struct.
unsafe impl DeviceRepr for ProbeTemplates {}

/// Bytes of one `StagedPlanes` record of cuda/contact.cu: `planes` planes (the enumeration's
/// limit, [`crate::scene::Scene::enum_planes`]; normal and offset in the
/// geometry's arithmetic), the frame origin in f64, two plane counts.
pub fn staged_planes_bytes(precision: Precision, planes: usize) -> usize {
    let real = match precision {
        Precision::Double => 8,
        Precision::Mixed => 4,
    };
    planes * 4 * real + 3 * 8 + 2 * 4
}

/// Declares the shared structs whose layout is checked: each as `Type => "C_NAME" { fields }`,
/// every field listed (`cuda/layout.cuh` checks the same ones).
macro_rules! checked_layouts {
    ($($ty:ty => $name:literal { $($field:ident),* $(,)? })*) => {
        /// The `-DPD_SIZEOF_<STRUCT>` and `-DPD_OFFSETOF_<STRUCT>_<field>` options for every
        /// shared struct (`cuda/layout.cuh` `static_assert`s them).
        pub fn layout_defines() -> Vec<String> {
            let mut d = Vec::new();
            $(
                d.push(format!("-DPD_SIZEOF_{}={}", $name, std::mem::size_of::<$ty>()));
                $(
                    d.push(format!(
                        "-DPD_OFFSETOF_{}_{}={}",
                        $name,
                        stringify!($field),
                        std::mem::offset_of!($ty, $field)
                    ));
                )*
            )*
            d
        }
    };
}

checked_layouts! {
    GridParams => "GRID_PARAMS" { min, max, size, dims, periodic }
    PairMaterial => "PAIR_MATERIAL" { restitution, friction, damping, log_restitution, log_norm, rolling_friction }
    StepFlags => "STEP_FLAGS" {
        rebuild, outside, unstable, first_unstable, wall_rebuild, snapshot,
    }
    ParticleView => "PARTICLE_VIEW" {
        position, velocity, angular_velocity, orientation, mass, inertia, scale, radius, cn, ct,
        tmpl, material, contacts,
    }
    PairOutputs => "PAIR_OUTPUTS" { forces, energy, contact }
    PairArgs => "PAIR_ARGS" {
        pairs, grid, axes, p, materials, n_materials, spring_in, spring_out, out, dt,
        max_overlap, error,
    }
    WallInfo => "WALL_INFO" {
        facet_offset, n_facets, cell_offset, material, grid_min, grid_size, dims, pad,
    }
    WallState => "WALL_STATE" { rotation, translation, v0, omega, origin }
    KickDriftParams => "KICK_DRIFT_PARAMS" {
        n, wrap, checks, pad, ghost, position, velocity, orientation, angular_velocity, force,
        torque, mass, inertia, radius, gravity, dt, grid, reference, half_skin,
        snapshot_distance, wall_reference, wall_half_reach, max_speed, flags,
    }
    ReduceKickParams => "REDUCE_KICK_PARAMS" {
        n, kick, ref_offset, refs, pair_forces, wall_force, wall_torque, force, torque, ghost,
        velocity, angular_velocity, mass, inertia, orientation, pair_contact, wall_contact,
        contacts, n_walls, pad, gravity, dt,
    }
    PairSearchParams => "PAIR_SEARCH_PARAMS" {
        n, part, position, radius, id, ghost, cell_start, grid, skin,
    }
    WallCandidatesParams => "WALL_CANDIDATES_PARAMS" {
        n, n_walls, p, walls, states, triangles, cell_start, cell_items, skin, counts, offset,
        items,
    }
    WallOverlapsParams => "WALL_OVERLAPS_PARAMS" {
        n_items, n_walls, items, p, states, triangles, prisms, overlaps, error,
    }
    WallContactsParams => "WALL_CONTACTS_PARAMS" {
        n, n_walls, n_materials, pad, p, states, walls, item_offset, items, overlaps, materials,
        spring_in, spring_out, wall_force, wall_torque, wall_energy, per_wall_force,
        wall_contact, dt, max_overlap, error,
    }
    ProbeTemplates => "PROBE_TEMPLATES" {
        vertices, normals, offsets, counts, radius, face_start, face_points, max_vertices,
        max_faces, max_face_indices,
    }
}

/// Templates packed as the kernels read them (`cuda/contact.cu` constants, `cuda/probe.cu`
/// `ProbeTemplates`): template t's vertices at `3 (t mv + i)`, its face normals at
/// `3 (t mf + i)` with offsets at `t mf + i`, the vertex and face counts at `2t`, `2t + 1`, and
/// the circumscribed radius at `t`; `nt` slots (at least the templates given). The face polygons
/// (`cuda/polytope.cuh: TemplateView`): face i's corners are points
/// `t mi + face_start[t (mf + 1) + i] ..` up to the next start of `face_points` (xyz, copies of
/// the vertices), with `mi = `[`max_face_indices`]`(mv)`; `face_mask[t mf + i]` holds the same
/// corners as a bit set of vertex indices (`TemplateView::face_mask`, zero for a template of
/// more than 64 vertices, which the kernels do not read).
pub struct TemplateTables {
    pub vertices: Vec<f64>,
    pub normals: Vec<f64>,
    pub offsets: Vec<f64>,
    pub counts: Vec<i32>,
    pub radius: Vec<f64>,
    pub equivalent: Vec<f64>,
    pub face_start: Vec<u16>,
    pub face_points: Vec<f64>,
    pub face_mask: Vec<u64>,
}

/// Room for the face polygons' vertex indices of a template of at most `max_vertices` vertices
/// (`PD_MAX_TEMPLATE_FACE_INDICES`): twice the edge count, at most `6V − 12` (Euler).
pub fn max_face_indices(max_vertices: usize) -> usize {
    (6 * max_vertices).saturating_sub(12).max(1)
}

impl TemplateTables {
    /// Packs `templates` into `nt` slots of `mv` vertices and `mf` faces.
    pub fn new<'a>(
        templates: impl IntoIterator<Item = &'a crate::shape::ConvexTemplate>,
        nt: usize,
        mv: usize,
        mf: usize,
    ) -> Self {
        let mi = max_face_indices(mv);
        let mut t = TemplateTables {
            vertices: vec![0.0; nt * mv * 3],
            normals: vec![0.0; nt * mf * 3],
            offsets: vec![0.0; nt * mf],
            counts: vec![0; nt * 2],
            radius: vec![0.0; nt],
            equivalent: vec![0.0; nt],
            face_start: vec![0; nt * (mf + 1)],
            face_points: vec![0.0; nt * mi * 3],
            face_mask: vec![0; nt * mf],
        };
        for (k, tpl) in templates.into_iter().enumerate() {
            for (i, v) in tpl.vertices.iter().enumerate() {
                t.vertices[(k * mv + i) * 3..(k * mv + i) * 3 + 3]
                    .copy_from_slice(v.coords.as_slice());
            }
            for (i, f) in tpl.faces.iter().enumerate() {
                t.normals[(k * mf + i) * 3..(k * mf + i) * 3 + 3]
                    .copy_from_slice(f.normal.as_slice());
                t.offsets[k * mf + i] = f.offset;
            }
            // Face polygons; a template within the vertex capacity has at most `mi` indices.
            let mut n = 0;
            for (i, f) in tpl.faces.iter().enumerate() {
                t.face_start[k * (mf + 1) + i] = n as u16;
                if tpl.vertices.len() <= 64 {
                    t.face_mask[k * mf + i] = f.vertices.iter().fold(0, |m, &v| m | 1 << v);
                }
                for &v in &f.vertices {
                    let at = (k * mi + n) * 3;
                    t.face_points[at..at + 3]
                        .copy_from_slice(tpl.vertices[v as usize].coords.as_slice());
                    n += 1;
                }
            }
            t.face_start[k * (mf + 1) + tpl.faces.len()] = n as u16;
            t.counts[2 * k] = tpl.vertices.len() as i32;
            t.counts[2 * k + 1] = tpl.faces.len() as i32;
            t.radius[k] = tpl.circumscribed_radius;
            t.equivalent[k] = tpl.equivalent_radius;
        }
        t
    }
}
