//! The scene file as written: serde structs mirroring the TOML layout one to one.
//!
//! Every struct denies unknown keys, so a misspelt key is an error that names it rather than a
//! silently ignored setting. Values are checked and turned into the resolved [`super::Scene`] by
//! `validate.rs`; nothing here applies defaults that depend on other sections.
//!
//! Variant-bearing tables (wall motion, insertion regions) are flat structs with a `kind` key and
//! optional parameters instead of serde's internally tagged enums: tagged enums buffer their
//! content, which loses the source position of a bad value and lets a unit variant accept any
//! extra key. The validator checks which parameters each kind allows.

use super::{OrientationMode, ScaleDistribution};
use nalgebra::UnitQuaternion;
use serde::Deserialize;

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

/// `[parallel]`: how the domain is split over MPI ranks (ignored on one rank).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParallelSection {
    /// `"rcb"` (recursive coordinate bisection, rebalanced) or `"grid"` (fixed Cartesian grid).
    pub decomposition: Option<DecompositionName>,
    /// Ranks per axis for `decomposition = "grid"`; their product must equal the rank count.
    pub grid: Option<[u32; 3]>,
    /// What the bisection balances: `"count"` (particles) or `"cost"` (measured step time).
    pub weight: Option<BalanceWeightName>,
    /// Rebalance when the largest rank load exceeds this multiple of the mean (> 1).
    pub imbalance_threshold: Option<f64>,
    /// Neighbour-list rebuilds between load checks (≥ 1).
    pub balance_interval: Option<u64>,
}

/// Values of `parallel.decomposition`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum DecompositionName {
    Rcb,
    Grid,
}

/// Values of `parallel.weight`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BalanceWeightName {
    Count,
    Cost,
}

/// `[simulation]`: time stepping and the random seed.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSection {
    /// Fixed time step (s); exclusive with `dt_fraction`.
    pub dt: Option<f64>,
    /// Time step as a fraction of the Rayleigh step; exclusive with `dt`.
    pub dt_fraction: Option<f64>,
    /// Simulated end time (s).
    pub end_time: f64,
    /// Seed of every random choice (insertion positions, orientations, scales).
    #[serde(default)]
    pub seed: u64,
    /// `[simulation.neighbor]`.
    #[serde(default)]
    pub neighbor: Option<NeighborSection>,
    /// `[simulation.guard]`.
    #[serde(default)]
    pub guard: Option<GuardSection>,
}

/// `[simulation.guard]`: the stability guard's bounds (`crate::stability`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GuardSection {
    /// Check speeds and overlaps (default true).
    pub enabled: Option<bool>,
    /// Largest overlap volume of a contact, as a fraction of the smaller particle's volume.
    pub max_overlap: Option<f64>,
    /// Largest `|v| + |ω| R` (m/s); default `speed_factor` × the scene's speed scale.
    pub max_speed: Option<f64>,
    /// Multiple of the scene's speed scale that bounds the speed when `max_speed` is not given.
    pub speed_factor: Option<f64>,
}

/// `[simulation.neighbor]`: neighbour-list settings.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NeighborSection {
    /// Verlet skin (m).
    pub skin: Option<f64>,
    /// Who builds the list.
    pub mode: Option<NeighborModeName>,
}

/// Values of `simulation.neighbor.mode`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum NeighborModeName {
    Auto,
    Gpu,
    Cpu,
    Hybrid,
}

/// `[domain]`: the simulated box.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DomainSection {
    /// Lower corner (m).
    pub min: Vec3,
    /// Upper corner (m).
    pub max: Vec3,
    /// Periodic axes `[x, y, z]`.
    #[serde(default)]
    pub periodic: [bool; 3],
    /// What a particle leaving through a closed (non-periodic) face does: `"error"` (the
    /// default) stops the run, `"remove"` removes it and counts it.
    pub on_leaving: Option<LeavingName>,
}

/// Values of `domain.on_leaving`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum LeavingName {
    Error,
    Remove,
}

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

/// `[output]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    pub dir: Option<String>,
    pub frame_interval: Option<f64>,
    pub formats: Option<Vec<String>>,
    pub fields: Option<Vec<String>>,
    pub checkpoint_interval: Option<f64>,
    pub series_interval: Option<f64>,
    pub log_interval_steps: Option<u64>,
    /// Periodic checkpoints kept (the newest; ≥ 1); default all.
    pub checkpoint_keep: Option<u64>,
}

/// Source positions of every key and value in a parsed document, by full dotted path
/// (`walls[1].motion.rpm`): turns serde's byte spans into key names, and key names into lines.
pub struct SpanIndex {
    entries: Vec<SpanEntry>,
    line_starts: Vec<usize>,
}

struct SpanEntry {
    path: String,
    key: std::ops::Range<usize>,
    value: std::ops::Range<usize>,
}

impl SpanIndex {
    /// Indexes `doc`, parsed from `text`.
    pub fn new(text: &str, doc: &toml::de::DeTable<'_>) -> Self {
        let mut entries = Vec::new();
        walk_table("", doc, &mut entries);
        let line_starts = std::iter::once(0)
            .chain(text.match_indices('\n').map(|(i, _)| i + 1))
            .collect();
        SpanIndex {
            entries,
            line_starts,
        }
    }

    /// 1-based (line, column) of byte offset `pos`.
    pub fn line_col(&self, text: &str, pos: usize) -> (usize, usize) {
        let line = self.line_starts.partition_point(|&s| s <= pos).max(1);
        let start = self.line_starts[line - 1];
        let col = text
            .get(start..pos.min(text.len()))
            .map_or(1, |s| s.chars().count() + 1);
        (line, col)
    }

    /// Every path in the file with the 1-based line of its key (kept by [`super::Scene`] so
    /// that errors found after validation, such as the domain decomposition's, name a line).
    pub fn key_lines(&self) -> Vec<(String, usize)> {
        self.entries
            .iter()
            .map(|e| {
                let line = self
                    .line_starts
                    .partition_point(|&s| s <= e.key.start)
                    .max(1);
                (e.path.clone(), line)
            })
            .collect()
    }

    /// Byte spans of the key and the value at exactly `path`.
    pub fn spans_of(&self, path: &str) -> Option<(std::ops::Range<usize>, std::ops::Range<usize>)> {
        self.entries
            .iter()
            .find(|e| e.path == path)
            .map(|e| (e.key.clone(), e.value.clone()))
    }

    /// 1-based line of `path`, or of its nearest ancestor that is in the file.
    pub fn line_of(&self, path: &str) -> Option<usize> {
        let mut p = path;
        loop {
            if let Some(e) = self.entries.iter().find(|e| e.path == p) {
                return Some(
                    self.line_starts
                        .partition_point(|&s| s <= e.key.start)
                        .max(1),
                );
            }
            // Strip the last `.key` or `[i]`.
            let cut = p.rfind(['.', '['])?;
            p = &p[..cut];
        }
    }

    /// The path whose key or value is at `span`: an exact key match, else an exact value match,
    /// else the smallest value containing it; the deepest path on ties.
    pub fn path_at(&self, span: &std::ops::Range<usize>) -> String {
        let deepest = |it: &mut dyn Iterator<Item = &SpanEntry>| {
            it.max_by_key(|e| e.path.len()).map(|e| e.path.clone())
        };
        if let Some(p) = deepest(&mut self.entries.iter().filter(|e| e.key == *span)) {
            return p;
        }
        if let Some(p) = deepest(&mut self.entries.iter().filter(|e| e.value == *span)) {
            return p;
        }
        self.entries
            .iter()
            .filter(|e| e.value.start <= span.start && span.end <= e.value.end)
            .min_by_key(|e| (e.value.end - e.value.start, usize::MAX - e.path.len()))
            .map(|e| e.path.clone())
            .unwrap_or_default()
    }
}

fn join(prefix: &str, key: &str) -> String {
    if prefix.is_empty() {
        key.to_string()
    } else {
        format!("{prefix}.{key}")
    }
}

fn walk_table(prefix: &str, table: &toml::de::DeTable<'_>, out: &mut Vec<SpanEntry>) {
    for (k, v) in table.iter() {
        let path = join(prefix, k.get_ref());
        out.push(SpanEntry {
            path: path.clone(),
            key: k.span(),
            value: v.span(),
        });
        walk_value(&path, v.get_ref(), out);
    }
}

fn walk_value(path: &str, v: &toml::de::DeValue<'_>, out: &mut Vec<SpanEntry>) {
    match v {
        toml::de::DeValue::Table(t) => walk_table(path, t, out),
        toml::de::DeValue::Array(a) => {
            for (i, e) in a.iter().enumerate() {
                let p = format!("{path}[{i}]");
                out.push(SpanEntry {
                    path: p.clone(),
                    key: e.span(),
                    value: e.span(),
                });
                walk_value(&p, e.get_ref(), out);
            }
        }
        _ => {}
    }
}

/// The sections every scene file must have: fields of [`SceneFile`] only.
pub const ROOT_REQUIRED: [&str; 2] = ["simulation", "domain"];

/// Rewrites a serde message about the key at `path` into (full key, message in scene terms).
pub fn explain_serde_message(path: &str, message: &str) -> (String, String) {
    let quoted = |rest: &str| rest.split('`').nth(1).unwrap_or("").to_string();
    let allowed = |rest: &str| {
        rest.split_once(", expected ")
            .map(|(_, e)| e.trim_start_matches("one of ").replace(" or ", ", "))
            .unwrap_or_default()
    };
    let full = |name: &str| {
        let last = path.rsplit(['.', '[']).next().unwrap_or("");
        if last == name {
            path.to_string()
        } else {
            join(path, name)
        }
    };
    if let Some(rest) = message.strip_prefix("unknown field ") {
        let name = quoted(rest);
        let key = full(&name);
        let mut msg = match allowed(rest) {
            a if a.is_empty() => "unknown key; this table takes no keys".to_string(),
            a => format!("unknown key; allowed keys: {a}"),
        };
        if rest.contains("`kind`") {
            msg.push_str(" (each kind takes only some of them; see docs/scene.md)");
        }
        if name == "gravity" && key != "gravity" {
            msg.push_str(" (gravity is a top-level key: write it before the first [section])");
        }
        return (key, msg);
    }
    if let Some(rest) = message.strip_prefix("missing field ") {
        let name = quoted(rest);
        // The document's span can equal its only section's, which would make a missing
        // section look like a key of that section (`simulation.domain`).
        if ROOT_REQUIRED.contains(&name.as_str()) {
            return (name.clone(), format!("missing required section [{name}]"));
        }
        return (full(&name), "missing required key".to_string());
    }
    if let Some(rest) = message.strip_prefix("unknown variant ") {
        return (
            path.to_string(),
            format!(
                "unknown value `{}`; allowed: {}",
                quoted(rest),
                allowed(rest)
            ),
        );
    }
    let msg = message
        .replace("expected f64", "expected a number")
        .replace("expected u64", "expected a non-negative integer")
        .replace("expected u32", "expected a non-negative integer below 2^32")
        .replace("expected usize", "expected a non-negative integer");
    (path.to_string(), msg)
}

/// Values that are one of several TOML types (a number or a table, a string or a table), which
/// serde structs cannot express with good errors: parsed here from `toml::Value`.
impl super::validate::Validator<'_> {
    pub(super) fn scale(&mut self, key: &str, v: Option<&toml::Value>) -> ScaleDistribution {
        let number = |v: &toml::Value| match v {
            toml::Value::Float(x) => Some(*x),
            toml::Value::Integer(i) => Some(*i as f64),
            _ => None,
        };
        let Some(v) = v else {
            return ScaleDistribution::Fixed(1.0);
        };
        if let Some(x) = number(v) {
            return ScaleDistribution::Fixed(self.positive(key, x));
        }
        let Some(t) = v.as_table() else {
            self.err(key, "must be a number or a table { distribution = \"uniform\" | \"normal\" | \"fixed\", ... }");
            return ScaleDistribution::Fixed(1.0);
        };
        let dist = t.get("distribution").and_then(|d| d.as_str()).unwrap_or("");
        let allowed: &[&str] = match dist {
            "fixed" => &["distribution", "value"],
            "uniform" => &["distribution", "min", "max"],
            "normal" => &["distribution", "mean", "std", "min", "max"],
            _ => {
                self.err(
                    &format!("{key}.distribution"),
                    "required; allowed: \"fixed\", \"uniform\", \"normal\"",
                );
                return ScaleDistribution::Fixed(1.0);
            }
        };
        let get = |s: &mut Self, name: &str| -> f64 {
            let sub = format!("{key}.{name}");
            match t.get(name).map(number) {
                Some(Some(x)) => s.positive(&sub, x),
                Some(None) => {
                    s.err(&sub, "must be a number");
                    1.0
                }
                None => {
                    s.err(&sub, format!("required for distribution = \"{dist}\""));
                    1.0
                }
            }
        };
        for name in t.keys() {
            if !allowed.contains(&name.as_str()) {
                self.err(
                    &format!("{key}.{name}"),
                    format!(
                        "unknown key for distribution = \"{dist}\"; allowed keys: {}",
                        allowed.join(", ")
                    ),
                );
            }
        }
        match dist {
            "fixed" => ScaleDistribution::Fixed(get(self, "value")),
            "uniform" => {
                let (min, max) = (get(self, "min"), get(self, "max"));
                if min >= max {
                    self.err(
                        &format!("{key}.max"),
                        format!("must exceed min ({min}), got {max}"),
                    );
                }
                ScaleDistribution::Uniform { min, max }
            }
            _ => {
                let (mean, std, min, max) = (
                    get(self, "mean"),
                    get(self, "std"),
                    get(self, "min"),
                    get(self, "max"),
                );
                if !(min <= mean && mean <= max && min < max) {
                    self.err(key, format!("need min < max and min ≤ mean ≤ max, got min {min}, mean {mean}, max {max}"));
                }
                ScaleDistribution::Normal {
                    mean,
                    std,
                    min,
                    max,
                }
            }
        }
    }

    pub(super) fn orientation(&mut self, key: &str, v: Option<&toml::Value>) -> OrientationMode {
        let allowed = "allowed: \"random\", \"identity\", or { axis = [x, y, z], angle = degrees }";
        match v {
            None => OrientationMode::Random,
            Some(toml::Value::String(s)) if s == "random" => OrientationMode::Random,
            Some(toml::Value::String(s)) if s == "identity" => {
                OrientationMode::Fixed(UnitQuaternion::identity())
            }
            Some(toml::Value::Table(t)) => {
                let r: Result<AxisAngleSection, _> = toml::Value::Table(t.clone()).try_into();
                match r {
                    Ok(aa) => {
                        let axis = self.direction(&format!("{key}.axis"), aa.axis);
                        if !aa.angle.is_finite() {
                            self.err(&format!("{key}.angle"), "must be a finite angle in degrees");
                        }
                        OrientationMode::Fixed(UnitQuaternion::from_axis_angle(
                            &axis,
                            aa.angle.to_radians(),
                        ))
                    }
                    Err(e) => {
                        let (k, m) = explain_serde_message(key, e.message());
                        self.err(&k, m);
                        OrientationMode::Random
                    }
                }
            }
            Some(other) => {
                self.err(key, format!("got {other}; {allowed}"));
                OrientationMode::Random
            }
        }
    }
}
