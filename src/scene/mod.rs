//! Scene files (TOML): schema, validation, wall meshes, and particle insertion.
//!
//! [`load_scene`] reads a file, checks every key and value (unknown keys are errors; every error
//! names the file, the full dotted key such as `walls[1].motion.rpm`, its line, and what is
//! allowed), loads the particle templates and wall meshes (paths relative to the scene file) and
//! returns a resolved [`Scene`]. `docs/scene.md` documents every key.

mod error;
mod insertion;
mod report;
pub mod restart;
mod schema;
mod settings;
mod timestep;
mod validate;
mod walls;

pub use error::{KeyError, SceneError};
pub use insertion::{
    DEFAULT_MAX_ATTEMPTS, ImportedBody, ImportedState, InsertReport, Inserter, InserterState,
    Insertion, InsertionMode, OrientationMode, Region, TiledPacking, cylinder_frame,
    cylinder_sites,
};
pub use report::check_report;
pub use settings::{
    BalanceWeight, DEFAULT_DT_FRACTION, Decomposition, Domain, GuardSettings, LeavingDomain,
    NeighborMode, NeighborSettings, OutputFormats, OutputSettings, PairTable, ParallelSettings,
    SimulationSettings, TimeStep,
};
pub use timestep::{
    RayleighStep, TimeStepReport, critical_time_step, face_contact_times, impact_speed,
    rayleigh_step,
};
pub use validate::{
    DEFAULT_FIELDS, DEFAULT_GRAVITY, DEFAULT_LOG_INTERVAL, HOST_BYTES_PER_PARTICLE,
    MAX_WALL_STEP_FRACTION, POSITION_RESOLUTION, physical_memory,
};
pub use walls::{PlacedMesh, Wall, WallMotion, WallPlacement, load_wall_mesh, place_mesh};

use crate::rng::Rng;
use crate::shape::ConvexTemplate;
use crate::state::{Material, PairParameters, ParticleType};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// Per-particle output fields a scene may request in `output.fields`: exactly those the frame
/// writer knows.
pub use crate::io::FRAME_FIELDS as OUTPUT_FIELDS;

/// Output formats a scene may request in `output.formats`.
pub const OUTPUT_FORMATS: [&str; 2] = ["vtu", "csv"];

/// Tries of a truncated normal before falling back to a uniform draw in `[min, max]`.
const NORMAL_TRIES: usize = 1000;

/// Distribution of a particle type's scale factor (applied to its template).
#[derive(Clone, Debug, PartialEq)]
pub enum ScaleDistribution {
    /// Always this scale.
    Fixed(f64),
    /// Uniform in `[min, max)`.
    Uniform { min: f64, max: f64 },
    /// Normal with `mean` and `std`, truncated to `[min, max]` by rejection (after
    /// 1000 rejected draws, uniform in `[min, max]`, so sampling always ends).
    Normal {
        mean: f64,
        std: f64,
        min: f64,
        max: f64,
    },
}

impl ScaleDistribution {
    /// One scale. `Fixed` draws no random numbers.
    pub fn sample(&self, rng: &mut Rng) -> f64 {
        match *self {
            ScaleDistribution::Fixed(s) => s,
            ScaleDistribution::Uniform { min, max } => rng.range(min, max),
            ScaleDistribution::Normal {
                mean,
                std,
                min,
                max,
            } => {
                for _ in 0..NORMAL_TRIES {
                    let x = mean + std * rng.normal();
                    if (min..=max).contains(&x) {
                        return x;
                    }
                }
                rng.range(min, max)
            }
        }
    }

    /// Smallest scale the distribution can produce.
    pub fn min_scale(&self) -> f64 {
        match *self {
            ScaleDistribution::Fixed(s) => s,
            ScaleDistribution::Uniform { min, .. } | ScaleDistribution::Normal { min, .. } => min,
        }
    }

    /// Largest scale the distribution can produce.
    pub fn max_scale(&self) -> f64 {
        match *self {
            ScaleDistribution::Fixed(s) => s,
            ScaleDistribution::Uniform { max, .. } | ScaleDistribution::Normal { max, .. } => max,
        }
    }
}

/// A validated scene with its templates and wall meshes loaded.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The scene file (as given to [`load_scene`], or `base_dir/file_name` for [`parse_scene`]).
    pub file: PathBuf,
    /// `[simulation]`.
    pub simulation: SimulationSettings,
    /// `[domain]`.
    pub domain: Domain,
    /// Gravitational acceleration (m/s²).
    pub gravity: Vector3<f64>,
    /// `[[materials]]`, in file order.
    pub materials: Vec<Material>,
    /// `[[material_pairs]]`, symmetric, indexed by material.
    pub pairs: PairTable,
    /// Particle templates (unit scale; a particle's scale multiplies them). Types with the same
    /// mesh file or generator share one.
    pub templates: Vec<ConvexTemplate>,
    /// `[[particle_types]]`, in file order; `template` indexes `templates`.
    pub particle_types: Vec<ParticleType>,
    /// Scale distribution per particle type (same index).
    pub scale_distributions: Vec<ScaleDistribution>,
    /// `[[insertions]]`, in file order.
    pub insertions: Vec<Insertion>,
    /// `[[walls]]`, in file order; a wall's index is its id in contact keys.
    pub walls: Vec<Wall>,
    /// `[output]`.
    pub output: OutputSettings,
    /// `[parallel]`.
    pub parallel: ParallelSettings,
    /// The line of each key in the file, by full dotted path, for errors found after
    /// validation ([`Scene::key_error`]).
    pub key_lines: Vec<(String, usize)>,
}

/// Reads, validates and resolves the scene in `path`, loading its templates and wall meshes
/// (paths in the file are relative to its directory).
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let text =
        crate::input::read_bounded_text(path, crate::input::InputKind::Scene).map_err(|e| {
            SceneError::Read {
                file: path.display().to_string(),
                message: e.to_string(),
            }
        })?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut scene = validate::build(&text, base, &path.display().to_string())?;
    scene.file = path.to_path_buf();
    Ok(scene)
}

/// As [`load_scene`] for text in memory: relative paths are resolved against `base_dir`, and
/// errors name `file_name`.
pub fn parse_scene(text: &str, base_dir: &Path, file_name: &str) -> Result<Scene, SceneError> {
    validate::build(text, base_dir, file_name)
}

/// A minimal scene for unit tests: a box of 0.1 m with one material and spheres of 1 mm, no
/// particles placed, and `neighbor` as the body of its `[simulation.neighbor]`.
#[cfg(test)]
pub(crate) fn test_sphere_scene(neighbor: &str) -> Scene {
    let text = format!(
        r#"[simulation]
dt = 1e-6
end_time = 1.0
[simulation.neighbor]
{neighbor}
[domain]
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.1]
[[materials]]
name = "m"
youngs_modulus = 1e7
poisson_ratio = 0.3
density = 2500.0
[[material_pairs]]
materials = ["m", "m"]
restitution = 0.5
friction = 0.5
[[particle_types]]
name = "s"
material = "m"
generator = {{ kind = "sphere", size = 0.001 }}
"#
    );
    parse_scene(&text, Path::new("."), "test.toml").unwrap()
}
