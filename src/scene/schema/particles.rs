//! Materials, pairs, particle types and insertions (with their regions) as written.

use super::Vec3;
use serde::Deserialize;

/// `[[materials]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSection {
    pub name: String,
    /// E (Pa).
    pub youngs_modulus: f64,
    /// ν.
    pub poisson_ratio: f64,
    /// ρ (kg/m³).
    pub density: f64,
}
/// `[[material_pairs]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PairSection {
    /// The two material names (may be equal).
    pub materials: [String; 2],
    pub restitution: f64,
    pub friction: f64,
    /// Rolling friction coefficient μ_r (default 0: none).
    pub rolling_friction: Option<f64>,
}
/// `[[particle_types]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParticleTypeSection {
    pub name: String,
    pub material: String,
    /// Mesh file (STL/OBJ) of the template; exclusive with `generator`.
    pub mesh: Option<String>,
    /// Built-in shape; exclusive with `mesh`.
    pub generator: Option<crate::shape::Generator>,
    /// A number (fixed scale) or a distribution table; parsed by the validator.
    pub scale: Option<toml::Value>,
    /// Edges and corners rounded by this fraction of the circumscribed radius
    /// ([`crate::shape::rounded`]).
    pub rounding: Option<f64>,
}
/// `[[insertions]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InsertionSection {
    /// Particle type name.
    #[serde(rename = "type")]
    pub particle_type: String,
    pub region: RegionSection,
    /// Particles placed at the start; exclusive with `rate`.
    pub count: Option<u64>,
    /// Particles per second; exclusive with `count`.
    pub rate: Option<f64>,
    /// Start of feeding (s) (rate only).
    pub start: Option<f64>,
    /// End of feeding (s) (rate only).
    pub end: Option<f64>,
    /// Most particles fed (rate only).
    pub total: Option<u64>,
    /// Feed in batches this many seconds apart instead of each particle as it falls due
    /// (rate only).
    pub interval: Option<f64>,
    /// `"random"`, `"identity"` or `{ axis, angle }`; parsed by the validator.
    pub orientation: Option<toml::Value>,
    /// Initial velocity (m/s).
    pub velocity: Option<Vec3>,
    /// Initial angular velocity (rad/s).
    pub angular_velocity: Option<Vec3>,
    /// Random positions tried per particle before giving up.
    pub max_attempts: Option<u32>,
    /// Lattice spacing (m) along x, y, z: particles go to the points of a simple cubic lattice
    /// filling the box region instead of random positions (count only; no overlap test).
    pub lattice: Option<Vec3>,
    /// A packing file (`polydem pack`) whose periodic cell is tiled over the box region
    /// (count only; orientations and scales from the file).
    pub packing: Option<String>,
    /// A checkpoint of another run whose particles with their centre inside the region are
    /// placed as they were (count only: positions, orientations, velocities and scales).
    pub state: Option<String>,
}
/// Kinds of insertion region.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RegionKind {
    Box,
    Cylinder,
}
/// `insertions[i].region`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSection {
    pub kind: RegionKind,
    pub min: Option<Vec3>,
    pub max: Option<Vec3>,
    pub base: Option<Vec3>,
    pub axis: Option<Vec3>,
    pub radius: Option<f64>,
    pub height: Option<f64>,
}
