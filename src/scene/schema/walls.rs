//! Walls and their motion as written.

use super::Vec3;
use serde::Deserialize;

/// `[[walls]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSection {
    /// Defaults to the mesh file's stem.
    pub name: Option<String>,
    /// STL or OBJ file, relative to the scene file.
    pub mesh: String,
    pub material: String,
    /// Uniform scale applied first (e.g. 0.001 for a mesh in millimetres).
    pub scale: Option<f64>,
    /// Rotation applied after scaling.
    pub rotate: Option<AxisAngleSection>,
    /// Translation applied last (m).
    pub translate: Option<Vec3>,
    /// Reverse every triangle's winding (for meshes wound with normals away from particles).
    #[serde(default)]
    pub flip_normals: bool,
    pub motion: Option<MotionSection>,
}
/// A rotation `{ axis = [x, y, z], angle = degrees }`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisAngleSection {
    pub axis: Vec3,
    /// Degrees, right-handed about `axis`.
    pub angle: f64,
}
/// Kinds of wall motion.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum MotionKind {
    Fixed,
    Rotate,
    Translate,
    Sinusoidal,
}
/// `walls[i].motion`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionSection {
    pub kind: MotionKind,
    pub axis: Option<Vec3>,
    pub origin: Option<Vec3>,
    pub rpm: Option<f64>,
    pub velocity: Option<Vec3>,
    pub direction: Option<Vec3>,
    pub amplitude: Option<f64>,
    pub frequency: Option<f64>,
}
