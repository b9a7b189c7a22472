//! Structs shared with the kernels, `#[repr(C)]` on both sides. Their sizes go to NVRTC as
//! `PD_SIZEOF_*` defines, and the `.cu`/`.cuh` side `static_assert`s them (DESIGN.md §3), so a
//! layout drift fails the kernel compile check in CI.

use super::kernels::Precision;
use crate::geometry::vertex_enumeration::ENUM_MAX_PLANES;
use crate::neighbor::Bounds;
use cudarc::driver::DeviceRepr;

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

/// Doubles per contact in the device's contact history: the tangential spring ξ (3), the
/// approach speed at first touch and the twist angle (`contact::ContactState`, in that order;
/// `cuda/contact_law.cuh: PD_HISTORY_WIDTH`).
pub const HISTORY_WIDTH: usize = 5;

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

/// Contact parameters of one pair of materials (`cuda/contact_law.cuh: PairMaterial`): the
/// restitution, friction and the Hunt–Crossley coefficient ᾱ(e), with ln e and sqrt((ln e)² + π²) of the
/// tangential dashpot (`contact::law`), computed here so that the kernels take no logarithm per
/// contact and round as the CPU backend does.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairMaterial {
    pub restitution: f64,
    pub friction: f64,
    pub damping: f64,
    pub log_restitution: f64,
    pub log_norm: f64,
}

impl PairMaterial {
    /// The parameters of a pair with restitution `e`, friction coefficient `friction` and
    /// damping coefficient `damping` = ᾱ(e) (as `Simulation::new` computes it).
    pub fn new(restitution: f64, friction: f64, damping: f64) -> Self {
        // The same expressions as contact::law (`e.ln()`, `powi(2)`), for the same bits.
        let log_restitution = restitution.ln();
        let log_norm = (log_restitution.powi(2) + std::f64::consts::PI.powi(2)).sqrt();
        PairMaterial {
            restitution,
            friction,
            damping,
            log_restitution,
            log_norm,
        }
    }
}

// SAFETY: plain old data of f64.
unsafe impl DeviceRepr for PairMaterial {}

/// Bytes of one `StagedPlanes` record of cuda/contact.cu: ENUM_MAX_PLANES planes (normal and
/// offset in the geometry's arithmetic), the frame origin in f64, two plane counts.
pub fn staged_planes_bytes(precision: Precision) -> usize {
    let real = match precision {
        Precision::Double => 8,
        Precision::Mixed => 4,
    };
    ENUM_MAX_PLANES * 4 * real + 3 * 8 + 2 * 4
}

/// The `-DPD_SIZEOF_…` options for every shared struct.
pub fn size_defines() -> Vec<String> {
    vec![
        format!(
            "-DPD_SIZEOF_GRID_PARAMS={}",
            std::mem::size_of::<GridParams>()
        ),
        format!(
            "-DPD_SIZEOF_PAIR_MATERIAL={}",
            std::mem::size_of::<PairMaterial>()
        ),
        format!(
            "-DPD_SIZEOF_PAIR_ARGS={}",
            std::mem::size_of::<super::simulation::PairArgs>()
        ),
    ]
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
