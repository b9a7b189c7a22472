//! Scene files (TOML): schema, validation, wall meshes, and particle insertion.
//!
//! [`load_scene`] reads a file, checks every key and value (unknown keys are errors; every error
//! names the file, the full dotted key such as `walls[1].motion.rpm`, its line, and what is
//! allowed), loads the particle templates and wall meshes (paths relative to the scene file) and
//! returns a resolved [`Scene`]. `docs/scene.md` documents every key.

mod insertion;
pub mod restart;
mod schema;
mod validate;
mod walls;

pub use insertion::{
    DEFAULT_MAX_ATTEMPTS, InsertReport, Inserter, InserterState, Insertion, InsertionMode,
    OrientationMode, Region,
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

/// How subdomains are laid out over the ranks (`[parallel] decomposition`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decomposition {
    /// Recursive coordinate bisection, recomputed when the load is imbalanced.
    Rcb,
    /// A fixed Cartesian grid: ranks per axis, or `None` to choose from the domain's shape.
    Grid(Option<[u32; 3]>),
}

/// What recursive bisection balances (`[parallel] weight`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BalanceWeight {
    /// Owned particles per rank.
    Count,
    /// Measured seconds of force evaluation per rank, spread over its particles.
    Cost,
}

/// `[parallel]`, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParallelSettings {
    pub decomposition: Decomposition,
    pub weight: BalanceWeight,
    /// Rebalance when max load / mean load exceeds this.
    pub imbalance_threshold: f64,
    /// Neighbour-list rebuilds between load checks.
    pub balance_interval: u64,
}

impl Default for ParallelSettings {
    fn default() -> Self {
        ParallelSettings {
            decomposition: Decomposition::Rcb,
            weight: BalanceWeight::Count,
            imbalance_threshold: 1.2,
            balance_interval: 1,
        }
    }
}

/// `[simulation]`, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulationSettings {
    /// Time step rule.
    pub dt: TimeStep,
    /// Simulated end time (s).
    pub end_time: f64,
    /// Seed of all random choices.
    pub seed: u64,
    /// Neighbour-list settings.
    pub neighbor: NeighborSettings,
    /// Stability guard settings.
    pub guard: GuardSettings,
}

/// `[simulation.guard]`, resolved (`crate::stability`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuardSettings {
    /// Whether speeds and overlaps are checked (finiteness always is).
    pub enabled: bool,
    /// Largest overlap volume of a contact, as a fraction of the smaller particle's volume.
    pub max_overlap: f64,
    /// Largest `|v| + |ω| R` (m/s), when given.
    pub max_speed: Option<f64>,
    /// Multiple of the scene's speed scale that bounds the speed otherwise.
    pub speed_factor: f64,
}

impl GuardSettings {
    /// Default largest overlap: a tenth of the smaller particle's volume.
    pub const MAX_OVERLAP: f64 = 0.1;
    /// Default speed bound: ten times the scene's speed scale.
    pub const SPEED_FACTOR: f64 = 10.0;
}

impl Default for GuardSettings {
    fn default() -> Self {
        GuardSettings {
            enabled: true,
            max_overlap: Self::MAX_OVERLAP,
            max_speed: None,
            speed_factor: Self::SPEED_FACTOR,
        }
    }
}

/// `simulation.dt_fraction` when neither `dt` nor `dt_fraction` is given: the largest fraction
/// of the critical step at which every reference case of `polydem bench accuracy` is within
/// 1 % of its reference and no elastic face impact gains more than 1e-3 of its energy
/// (docs/accuracy.md).
pub const DEFAULT_DT_FRACTION: f64 = 0.025;

/// How the time step is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TimeStep {
    /// This step (s).
    Fixed(f64),
    /// This fraction of the Rayleigh step ([`critical_time_step`]).
    FractionOfCritical(f64),
}

/// `[simulation.neighbor]`, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeighborSettings {
    /// Verlet skin, an absolute length (m); default 0.1 × the largest circumscribed diameter.
    pub skin: f64,
    /// Who builds the neighbour list (docs/design.md §7).
    pub mode: NeighborMode,
}

/// `simulation.neighbor.mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NeighborMode {
    /// Measure and choose.
    Auto,
    /// Lists built on the GPU.
    Gpu,
    /// Lists built on the CPU.
    Cpu,
    /// CPU pre-builds the next list while the GPU steps.
    Hybrid,
}

/// `[domain]`, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Domain {
    /// Lower corner (m).
    pub min: Vector3<f64>,
    /// Upper corner (m).
    pub max: Vector3<f64>,
    /// Periodic along x, y, z.
    pub periodic: [bool; 3],
    /// What a particle that leaves through a closed face does (`domain.on_leaving`).
    pub on_leaving: LeavingDomain,
}

/// What a particle whose centroid leaves the domain through a closed (non-periodic) face does
/// (`domain.on_leaving`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LeavingDomain {
    /// The run stops with [`crate::pipeline::SimulationError::LeftDomain`] before the particle
    /// is removed: a particle lost through a wall or a closed face is a fault of the scene.
    #[default]
    Error,
    /// The particle is removed (an outflow): counted in `summary.json` and the log.
    Remove,
}

/// Which output formats are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputFormats {
    /// VTU/PVTU/PVD frames.
    pub vtu: bool,
    /// Per-particle CSV frames.
    pub csv: bool,
}

/// `[output]`, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputSettings {
    /// Output directory (resolved against the scene file's directory).
    pub dir: PathBuf,
    /// Seconds between frames; `None`: no frames.
    pub frame_interval: Option<f64>,
    /// Frame formats.
    pub formats: OutputFormats,
    /// Per-particle fields (a subset of [`OUTPUT_FIELDS`], in the order given).
    pub fields: Vec<String>,
    /// Seconds between checkpoints; `None`: none.
    pub checkpoint_interval: Option<f64>,
    /// Seconds between rows of the energy/contacts/wall-force CSV series; default the frame
    /// interval, else 100 time steps.
    pub series_interval: f64,
    /// Steps between progress log lines.
    pub log_interval_steps: u64,
    /// Periodic checkpoints kept, the newest (`latest.ckpt` and the checkpoints of a stop are
    /// always kept); `None`: all.
    pub checkpoint_keep: Option<u64>,
}

/// Contact parameters for every pair of materials, symmetric.
#[derive(Clone, Debug, PartialEq)]
pub struct PairTable {
    n: usize,
    entries: Vec<Option<PairParameters>>,
}

impl PairTable {
    /// An empty table for `n` materials.
    pub fn new(n: usize) -> Self {
        PairTable {
            n,
            entries: vec![None; n * n],
        }
    }

    /// Number of materials.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are no materials.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Sets the parameters of `(m1, m2)` and `(m2, m1)`; out-of-range indices are ignored.
    pub fn set(&mut self, m1: usize, m2: usize, p: PairParameters) {
        if m1 < self.n && m2 < self.n {
            self.entries[m1 * self.n + m2] = Some(p);
            self.entries[m2 * self.n + m1] = Some(p);
        }
    }

    /// Whether some given pair has friction (μ > 0): the tangential history is needed.
    pub fn any_friction(&self) -> bool {
        self.entries.iter().flatten().any(|p| p.friction > 0.0)
    }

    /// The parameters of `(m1, m2)` if given.
    pub fn try_get(&self, m1: usize, m2: usize) -> Option<PairParameters> {
        if m1 < self.n && m2 < self.n {
            self.entries[m1 * self.n + m2]
        } else {
            None
        }
    }

    /// The parameters of `(m1, m2)` (symmetric). Validation guarantees every pair that can
    /// meet is present; for a pair that cannot meet (say two wall materials) this returns
    /// [`PairTable::ABSENT`], which no contact of a validated scene uses.
    pub fn get(&self, m1: usize, m2: usize) -> PairParameters {
        self.try_get(m1, m2).unwrap_or(Self::ABSENT)
    }

    /// Returned by [`PairTable::get`] for pairs not given: elastic and frictionless.
    pub const ABSENT: PairParameters = PairParameters {
        restitution: 1.0,
        friction: 0.0,
    };
}

/// A key-level problem found in a scene file.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyError {
    /// Full dotted key, e.g. `walls[1].motion.rpm` (empty for the document itself).
    pub key: String,
    /// 1-based line of the key in the file, when it is in the file.
    pub line: Option<usize>,
    /// What is wrong and what is allowed.
    pub message: String,
}

/// Errors reading a scene or inserting its particles. Every one names the scene file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{file}: cannot read the scene file: {message}")]
    Read { file: String, message: String },
    /// Not valid TOML.
    #[error("{file}:{line}:{column}: TOML syntax error: {message}")]
    Syntax {
        file: String,
        line: usize,
        column: usize,
        message: String,
    },
    /// Valid TOML, but keys or values are wrong; all problems found are listed.
    #[error("{}", format_key_errors(file, errors))]
    Invalid { file: String, errors: Vec<KeyError> },
    /// Particles could not be placed as asked.
    #[error("{file}: {key}: {message}")]
    Insertion {
        file: String,
        key: String,
        message: String,
    },
}

impl SceneError {
    /// The dotted keys the error names (empty for read and syntax errors).
    pub fn keys(&self) -> Vec<&str> {
        match self {
            SceneError::Invalid { errors, .. } => errors.iter().map(|e| e.key.as_str()).collect(),
            SceneError::Insertion { key, .. } => vec![key.as_str()],
            _ => Vec::new(),
        }
    }
}

fn format_key_errors(file: &str, errors: &[KeyError]) -> String {
    let one = |e: &KeyError| {
        let loc = e
            .line
            .map_or_else(|| file.to_string(), |l| format!("{file}:{l}"));
        if e.key.is_empty() {
            format!("{loc}: {}", e.message)
        } else {
            format!("{loc}: {}: {}", e.key, e.message)
        }
    };
    match errors {
        [e] => one(e),
        _ => {
            let mut s = format!("{file}: {} errors in the scene file:", errors.len());
            for e in errors {
                s.push_str("\n  ");
                s.push_str(&one(e));
            }
            s
        }
    }
}

/// Reads, validates and resolves the scene in `path`, loading its templates and wall meshes
/// (paths in the file are relative to its directory).
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::Read {
        file: path.display().to_string(),
        message: e.to_string(),
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

impl Scene {
    /// Whether every particle is a sphere: the scene then takes the sphere fast path (docs/design.md
    /// §1), and validation guarantees it has no polyhedra.
    pub fn spheres_only(&self) -> bool {
        !self.templates.is_empty() && self.templates.iter().all(|t| t.sphere)
    }

    /// The time step (s): the fixed one, or the fraction of the Rayleigh step.
    pub fn time_step(&self) -> f64 {
        match self.simulation.dt {
            TimeStep::Fixed(dt) => dt,
            TimeStep::FractionOfCritical(_) => critical_time_step(self).dt,
        }
    }

    /// Largest bounding (circumscribed) radius any particle type can have at its largest scale.
    pub fn max_bounding_radius(&self) -> f64 {
        self.particle_types
            .iter()
            .zip(&self.scale_distributions)
            .filter_map(|(p, d)| {
                self.templates
                    .get(p.template)
                    .map(|t| t.circumscribed_radius * d.max_scale())
            })
            .fold(0.0, f64::max)
    }

    /// The neighbour cutoff: the farthest two particles' centroids can be and still be listed
    /// as a candidate pair, `2 r_max + skin` (the largest bounding diameter plus the skin). It
    /// sizes the binning cells, the facet grids of the walls and the decomposition's halo.
    pub fn cutoff(&self) -> f64 {
        2.0 * self.max_bounding_radius() + self.simulation.neighbor.skin
    }

    /// Smallest volume-equivalent radius any particle type can have at its smallest scale
    /// (infinite without particle types).
    pub fn min_equivalent_radius(&self) -> f64 {
        self.particle_types
            .iter()
            .zip(&self.scale_distributions)
            .filter_map(|(p, d)| {
                self.templates
                    .get(p.template)
                    .map(|t| t.equivalent_radius * d.min_scale())
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// 1-based line of `key` in the scene file, or of its nearest ancestor that is there.
    pub fn line_of(&self, key: &str) -> Option<usize> {
        let mut p = key;
        loop {
            if let Some((_, line)) = self.key_lines.iter().find(|(k, _)| k == p) {
                return Some(*line);
            }
            let cut = p.rfind(['.', '['])?;
            p = &p[..cut];
        }
    }

    /// An error about `key` found after validation (say by the domain decomposition, which
    /// needs the rank count), in the same `file:line: key: message` form as validation's.
    pub fn key_error(&self, key: &str, message: impl Into<String>) -> SceneError {
        SceneError::Invalid {
            file: self.file.display().to_string(),
            errors: vec![KeyError {
                key: key.to_string(),
                line: self.line_of(key),
                message: message.into(),
            }],
        }
    }

    /// Index of the particle type called `name`.
    pub fn particle_type_index(&self, name: &str) -> Option<usize> {
        self.particle_types.iter().position(|p| p.name == name)
    }

    /// Index of the material called `name`.
    pub fn material_index(&self, name: &str) -> Option<usize> {
        self.materials.iter().position(|m| m.name == name)
    }
}

/// Face-to-face contact time of each particle type with itself at the impact speed `v`
/// (validation.md §6; see [`crate::contact::restitution::face_contact_time`]): its largest face,
/// its smallest scale. For a sphere, the head-on sphere–sphere time
/// ([`crate::contact::restitution::sphere_contact_time`]).
pub fn face_contact_times(scene: &Scene, v: f64) -> Vec<(String, f64)> {
    scene
        .particle_types
        .iter()
        .zip(&scene.scale_distributions)
        .map(|(ty, dist)| {
            let t = &scene.templates[ty.template];
            let m = &scene.materials[ty.material];
            let s = dist.min_scale();
            let area = t
                .faces
                .iter()
                .map(|f| {
                    let v: Vec<_> = f
                        .vertices
                        .iter()
                        .map(|&k| t.vertices[k as usize].coords)
                        .collect();
                    (1..v.len().saturating_sub(1))
                        .map(|k| (v[k] - v[0]).cross(&(v[k + 1] - v[0])).norm() / 2.0)
                        .sum::<f64>()
                })
                .fold(0.0, f64::max)
                * s
                * s;
            let mass = m.density * t.volume * s.powi(3);
            let c = 2.0 * m.youngs_modulus / (t.equivalent_radius * s);
            let time = if t.sphere {
                let r_eff = 0.5 * t.circumscribed_radius * s;
                crate::contact::restitution::sphere_contact_time(0.5 * mass, c, r_eff, v)
            } else {
                crate::contact::restitution::face_contact_time(0.5 * mass, c, area, v)
            };
            (ty.name.clone(), time)
        })
        .collect()
}

/// The impact speed the contact-time estimate assumes: free fall over the domain's height, at
/// least 1 m/s.
pub fn impact_speed(scene: &Scene) -> f64 {
    let height = scene.domain.max.z - scene.domain.min.z;
    (2.0 * scene.gravity.norm() * height).sqrt().max(1.0)
}

/// The Rayleigh step of one material.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RayleighStep {
    /// Material name.
    pub material: String,
    /// Smallest volume-equivalent radius of any particle type of this material at its smallest
    /// scale (m).
    pub radius: f64,
    /// `Δt_R = π R √(ρ/G) / (0.1631 ν + 0.8766)` with `G = E / (2 (1 + ν))` (s).
    pub step: f64,
}

/// Time-step stability figures of a scene.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TimeStepReport {
    /// Smallest Rayleigh step over the particle materials (s) (infinite without particle types).
    pub rayleigh: f64,
    /// Rayleigh step per material that some particle type uses.
    pub per_material: Vec<RayleighStep>,
    /// Contact-time estimate (Hertz or linear spring); not computed here yet.
    pub contact_time: Option<f64>,
    /// The chosen time step (s).
    pub dt: f64,
    /// `dt / rayleigh`.
    pub fraction_of_rayleigh: f64,
}

/// Rayleigh step of a material with radius `r`.
pub fn rayleigh_step(m: &Material, r: f64) -> f64 {
    let g = m.youngs_modulus / (2.0 * (1.0 + m.poisson_ratio));
    std::f64::consts::PI * r * (m.density / g).sqrt() / (0.1631 * m.poisson_ratio + 0.8766)
}

/// The Rayleigh step per particle material and the chosen time step.
pub fn critical_time_step(scene: &Scene) -> TimeStepReport {
    let mut per_material = Vec::new();
    for (mi, m) in scene.materials.iter().enumerate() {
        let radius = scene
            .particle_types
            .iter()
            .zip(&scene.scale_distributions)
            .filter(|(p, _)| p.material == mi)
            .filter_map(|(p, d)| {
                scene
                    .templates
                    .get(p.template)
                    .map(|t| t.equivalent_radius * d.min_scale())
            })
            .fold(f64::INFINITY, f64::min);
        if radius.is_finite() {
            per_material.push(RayleighStep {
                material: m.name.clone(),
                radius,
                step: rayleigh_step(m, radius),
            });
        }
    }
    let rayleigh = per_material
        .iter()
        .map(|r| r.step)
        .fold(f64::INFINITY, f64::min);
    // The volume law's face-to-face contact is far stiffer at first touch than the Rayleigh
    // estimate assumes (it is derived for Hertzian spheres), so the critical step is the
    // smaller of the two.
    let contact = face_contact_times(scene, impact_speed(scene))
        .iter()
        .map(|t| t.1)
        .fold(f64::INFINITY, f64::min);
    let dt = match scene.simulation.dt {
        TimeStep::Fixed(dt) => dt,
        TimeStep::FractionOfCritical(f) => f * rayleigh.min(contact),
    };
    TimeStepReport {
        rayleigh,
        per_material,
        contact_time: contact.is_finite().then_some(contact),
        dt,
        fraction_of_rayleigh: dt / rayleigh,
    }
}

/// The motion of a wall as JSON: its kind and parameters.
fn motion_json(m: &WallMotion) -> serde_json::Value {
    use serde_json::json;
    match m {
        WallMotion::Fixed => json!({ "kind": "fixed" }),
        WallMotion::Rotate { axis, origin, rpm } => json!({
            "kind": "rotate", "axis": axis.as_slice(), "origin": origin.as_slice(), "rpm": rpm,
        }),
        WallMotion::Translate { velocity } => {
            json!({ "kind": "translate", "velocity": velocity.as_slice() })
        }
        WallMotion::Sinusoidal {
            direction,
            amplitude,
            frequency,
        } => json!({
            "kind": "sinusoidal", "direction": direction.as_slice(), "amplitude": amplitude,
            "frequency": frequency,
        }),
    }
}

/// A summary for `polydem check`: particles to insert, wall facets, templates, time steps.
pub fn check_report(scene: &Scene) -> serde_json::Value {
    use serde_json::json;
    let ts = critical_time_step(scene);
    let end = scene.simulation.end_time;
    let insertions: Vec<_> = scene
        .insertions
        .iter()
        .map(|ins| {
            json!({
                "type": scene.particle_types.get(ins.particle_type).map(|p| p.name.clone()),
                "mode": match ins.mode { InsertionMode::Count(_) => "count", InsertionMode::Rate { .. } => "rate" },
                "particles": ins.planned_count(end),
                "region_volume": ins.region.volume(),
            })
        })
        .collect();
    let total: u64 = scene.insertions.iter().map(|i| i.planned_count(end)).sum();
    let walls: Vec<_> = scene
        .walls
        .iter()
        .map(|w| {
            json!({
                "name": w.name,
                "facets": w.triangles.len(),
                "material": scene.materials.get(w.material).map(|m| m.name.clone()),
                "motion": motion_json(&w.motion),
            })
        })
        .collect();
    let templates: Vec<_> = scene
        .templates
        .iter()
        .map(|t| {
            json!({
                "name": t.name,
                "vertices": t.vertices.len(),
                "faces": t.faces.len(),
                "volume": t.volume,
                "circumscribed_radius": t.circumscribed_radius,
                "equivalent_radius": t.equivalent_radius,
            })
        })
        .collect();
    let finite = |x: f64| if x.is_finite() { Some(x) } else { None };
    json!({
        "file": scene.file.display().to_string(),
        "particles_to_insert": total,
        "insertions": insertions,
        "walls": walls,
        "templates": templates,
        "time_step": {
            "rayleigh": finite(ts.rayleigh),
            "per_material": ts.per_material,
            "contact_time": ts.contact_time,
            "dt": finite(ts.dt),
            "fraction_of_rayleigh": finite(ts.fraction_of_rayleigh),
            "steps": finite((end / ts.dt).ceil()),
        },
        "neighbor_skin": scene.simulation.neighbor.skin,
    })
}
