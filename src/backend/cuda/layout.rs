//! Structs shared with the kernels, `#[repr(C)]` on both sides. Their sizes go to NVRTC as
//! `PD_SIZEOF_*` defines, and the `.cu`/`.cuh` side `static_assert`s them (DESIGN.md §3), so a
//! layout drift fails the kernel compile check in CI.

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

/// Contact parameters of one pair of materials (`cuda/contact_law.cuh: PairMaterial`): the
/// restitution, friction and the damping table γ(e, p).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairMaterial {
    pub restitution: f64,
    pub friction: f64,
    pub damping: [f64; crate::contact::restitution::TABLE_SIZE],
}

// SAFETY: plain old data of f64.
unsafe impl DeviceRepr for PairMaterial {}

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
    ]
}
