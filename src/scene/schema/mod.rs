//! The scene file as written: serde structs mirroring the TOML layout one to one.
//!
//! Every struct denies unknown keys, so a misspelt key is an error that names it rather than a
//! silently ignored setting. Values are checked and turned into the resolved [`super::Scene`] by
//! `validate/`; nothing here applies defaults that depend on other sections.
//!
//! Variant-bearing tables (wall motion, insertion regions) are flat structs with a `kind` key and
//! optional parameters instead of serde's internally tagged enums: tagged enums buffer their
//! content, which loses the source position of a bad value and lets a unit variant accept any
//! extra key. The validator checks which parameters each kind allows.

mod particles;
mod simulation;
mod spans;
mod values;
mod walls;

use serde::Deserialize;

pub use particles::{
    InsertionSection, MaterialSection, PairSection, ParticleTypeSection, RegionKind, RegionSection,
};
pub use simulation::{
    BalanceWeightName, DecompositionName, DomainSection, FaceWindowName, LeavingName,
    NeighborModeName, OutputSection, ParallelSection, SimulationSection,
};
pub use spans::{SpanIndex, explain_serde_message};
pub use walls::{AxisAngleSection, MotionKind, MotionSection, WallSection};

/// A 3-vector as written in the file: `[x, y, z]`.
pub type Vec3 = [f64; 3];

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// `[simulation]`.
    pub simulation: SimulationSection,
    /// `[domain]`.
    pub domain: DomainSection,
    /// Top-level `gravity = [gx, gy, gz]` (m/s²); must precede the first `[section]`.
    #[serde(default)]
    pub gravity: Option<Vec3>,
    /// `[[materials]]`.
    #[serde(default)]
    pub materials: Vec<MaterialSection>,
    /// `[[material_pairs]]`.
    #[serde(default)]
    pub material_pairs: Vec<PairSection>,
    /// `[[particle_types]]`.
    #[serde(default)]
    pub particle_types: Vec<ParticleTypeSection>,
    /// `[[insertions]]`.
    #[serde(default)]
    pub insertions: Vec<InsertionSection>,
    /// `[[walls]]`.
    #[serde(default)]
    pub walls: Vec<WallSection>,
    /// `[output]`.
    #[serde(default)]
    pub output: Option<OutputSection>,
    /// `[parallel]`: the domain decomposition over MPI ranks.
    #[serde(default)]
    pub parallel: Option<ParallelSection>,
}

/// The sections every scene file must have: fields of [`SceneFile`] only.
pub const ROOT_REQUIRED: [&str; 2] = ["simulation", "domain"];
