//! From TOML text to a resolved [`Scene`]: syntax, schema (serde), then every value checked
//! with its full dotted key. Checking goes on after a problem so one run lists them all.

use super::insertion::{DEFAULT_MAX_ATTEMPTS, Insertion, InsertionMode};
use super::schema::{self, SceneFile, SpanIndex, Vec3};
use super::walls::Wall;
use super::*;
use crate::shape::ConvexTemplate;
use nalgebra::Unit;
use std::collections::HashMap;

/// Default gravity (m/s²): standard gravity along −z.
pub const DEFAULT_GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];
/// Default per-particle output fields.
pub const DEFAULT_FIELDS: [&str; 5] = ["id", "type", "velocity", "angular_velocity", "rank"];
/// Default steps between progress log lines.
pub const DEFAULT_LOG_INTERVAL: u64 = 1000;

/// The finest position difference contacts need, as a fraction of the smallest particle
/// radius: overlaps of 1e-6 R are typical at rest under gravity, so the f64 spacing of every
/// coordinate of the domain must be at most this.
pub const POSITION_RESOLUTION: f64 = 1e-6;

/// The most a wall's fastest point may move in one step, as a fraction of the smallest
/// particle's volume-equivalent radius: a wall that jumps further passes through contacts in a
/// few steps, which no contact law resolves.
pub const MAX_WALL_STEP_FRACTION: f64 = 0.1;

/// Host memory a particle takes at the least (bytes): its state in [`crate::state::Particles`]
/// (id, kind, scale, mass, position, velocity, angular velocity, force, torque, inertia,
/// orientation) plus its bounding radius and the neighbour list's reference position. The run
/// needs more (pair list, contact history, output copies): this bound only refuses what
/// certainly cannot run.
pub const HOST_BYTES_PER_PARTICLE: u64 = {
    use std::mem::size_of;
    (size_of::<u64>()
        + size_of::<u32>()
        + 3 * size_of::<f64>()
        + 7 * size_of::<Vector3<f64>>()
        + size_of::<nalgebra::UnitQuaternion<f64>>()) as u64
};

/// Physical memory of this machine in bytes (`MemTotal` of `/proc/meminfo`); `None` where it
/// cannot be read, and then no memory bound is applied.
pub fn physical_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

pub(super) fn build(text: &str, base: &Path, file_name: &str) -> Result<Scene, SceneError> {
    let index = match toml::de::DeTable::parse(text) {
        Ok(doc) => SpanIndex::new(text, doc.get_ref()),
        Err(e) => {
            let empty = SpanIndex::new(text, &Default::default());
            let (line, column) = empty.line_col(text, e.span().map_or(0, |s| s.start));
            return Err(SceneError::Syntax {
                file: file_name.to_string(),
                line,
                column,
                message: e.message().to_string(),
            });
        }
    };
    // Schema errors (unknown keys, wrong types) are collected one at a time: each offending
    // key is blanked out of the text (spaces, so every span and line stays where it was) and
    // the text is read again, so that all of them are listed together and the value checks
    // still run on what remains. A missing required key cannot be blanked away: reading stops
    // there with what was found.
    let mut errors: Vec<KeyError> = Vec::new();
    let mut current = text.to_string();
    let raw: SceneFile = loop {
        let e = match toml::from_str::<SceneFile>(&current) {
            Ok(raw) => break raw,
            Err(e) => e,
        };
        let span = e.span().unwrap_or(0..0);
        let path = index.path_at(&span);
        let (key, message) = schema::explain_serde_message(&path, e.message());
        // A missing section is nowhere in the file: no line to point at.
        let line = if schema::ROOT_REQUIRED.contains(&key.as_str()) {
            None
        } else {
            e.span().map(|s| index.line_col(text, s.start).0)
        };
        let missing = e.message().starts_with("missing field ");
        // A key blanked for its type is then missing: it was reported already.
        if !(missing && errors.iter().any(|k| k.key == key)) {
            errors.push(KeyError { key, line, message });
        }
        let blanked = (!missing && errors.len() < 100)
            .then(|| blank_key(&current, &index, &path))
            .flatten();
        match blanked {
            Some(t) if toml::de::DeTable::parse(&t).is_ok() => current = t,
            _ => {
                return Err(SceneError::Invalid {
                    file: file_name.to_string(),
                    errors,
                });
            }
        }
    };
    errors.sort_by_key(|e| e.line);
    let mut v = Validator {
        base,
        index: &index,
        errors,
    };
    let scene = v.scene(raw, file_name);
    if v.errors.is_empty() {
        Ok(scene)
    } else {
        Err(SceneError::Invalid {
            file: file_name.to_string(),
            errors: v.errors,
        })
    }
}

/// `text` with the key at `path` and its value replaced by spaces (newlines kept, so spans and
/// lines do not move), with the comma that separated it in an inline table or array, and with
/// its whole `[header]` line when it is a table header. `None` when `path` is not in the file.
fn blank_key(text: &str, index: &SpanIndex, path: &str) -> Option<String> {
    let (key, value) = index.spans_of(path)?;
    let bytes = text.as_bytes();
    let (mut start, mut end) = (key.start.min(value.start), key.end.max(value.end));
    let line_start = text[..key.start].rfind('\n').map_or(0, |i| i + 1);
    // A key whose line starts with `[` is a table header (an array element's path ends in `]`).
    if !path.ends_with(']') && text[line_start..].trim_start().starts_with('[') {
        // A table header: its keys follow it up to the next header, and would otherwise be
        // read as keys of the table before it.
        start = line_start;
        let mut pos = text[start..].find('\n').map_or(text.len(), |i| start + i);
        while pos < text.len() {
            let next = pos + 1;
            if text[next..].trim_start().starts_with('[') {
                break;
            }
            pos = text[next..].find('\n').map_or(text.len(), |i| next + i);
        }
        end = end.max(pos);
    } else {
        let mut after = end;
        while after < bytes.len() && (bytes[after] == b' ' || bytes[after] == b'\t') {
            after += 1;
        }
        if bytes.get(after) == Some(&b',') {
            end = after + 1;
        } else {
            let mut before = start;
            while before > 0 && (bytes[before - 1] == b' ' || bytes[before - 1] == b'\t') {
                before -= 1;
            }
            if before > 0 && bytes[before - 1] == b',' {
                start = before - 1;
            }
        }
    }
    if start >= end
        || end > text.len()
        || !text.is_char_boundary(start)
        || !text.is_char_boundary(end)
    {
        return None;
    }
    let blank: String = text[start..end]
        .chars()
        .map(|c| match c {
            '\n' => "\n".to_string(),
            // As many spaces as the character has bytes: offsets must not move.
            c => " ".repeat(c.len_utf8()),
        })
        .collect();
    Some(format!("{}{blank}{}", &text[..start], &text[end..]))
}

/// Collects key errors while turning the raw sections into resolved ones; section-specific
/// checks live beside their types (walls.rs, insertion.rs, schema.rs for mixed-type values).
pub(super) struct Validator<'a> {
    base: &'a Path,
    index: &'a SpanIndex,
    errors: Vec<KeyError>,
}

/// `"a", "b"` or `none`, for messages listing defined names.
pub(super) fn names<'a>(it: impl Iterator<Item = &'a String>) -> String {
    let v: Vec<String> = it.map(|s| format!("\"{s}\"")).collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

impl Validator<'_> {
    pub(super) fn err(&mut self, key: &str, message: impl Into<String>) {
        self.errors.push(KeyError {
            key: key.to_string(),
            line: self.index.line_of(key),
            message: message.into(),
        });
    }

    pub(super) fn positive(&mut self, key: &str, x: f64) -> f64 {
        if !(x > 0.0 && x.is_finite()) {
            self.err(key, format!("must be a positive finite number, got {x}"));
        }
        x
    }

    pub(super) fn non_negative(&mut self, key: &str, x: f64) -> f64 {
        if !(x >= 0.0 && x.is_finite()) {
            self.err(key, format!("must be a finite number ≥ 0, got {x}"));
        }
        x
    }

    pub(super) fn vector(&mut self, key: &str, v: Vec3) -> Vector3<f64> {
        if v.iter().any(|x| !x.is_finite()) {
            self.err(key, format!("components must be finite, got {v:?}"));
        }
        Vector3::from(v)
    }

    pub(super) fn direction(&mut self, key: &str, v: Vec3) -> Unit<Vector3<f64>> {
        let w = self.vector(key, v);
        Unit::try_new(w, 1e-300).unwrap_or_else(|| {
            self.err(key, "must be a non-zero vector");
            Vector3::z_axis()
        })
    }

    pub(super) fn resolve(&self, path: &str) -> PathBuf {
        self.base.join(path)
    }

    /// Errors for each present parameter that `kind` does not take.
    pub(super) fn only(
        &mut self,
        prefix: &str,
        kind: &str,
        present: &[(&str, bool)],
        allowed: &[&str],
    ) {
        for (name, is_set) in present {
            if *is_set && !allowed.contains(name) {
                let list = if allowed.is_empty() {
                    "none".into()
                } else {
                    allowed.join(", ")
                };
                self.err(
                    &format!("{prefix}.{name}"),
                    format!("not allowed for kind = \"{kind}\"; allowed: {list}"),
                );
            }
        }
    }

    pub(super) fn required<T: Copy>(
        &mut self,
        key: &str,
        kind: &str,
        x: Option<T>,
        fallback: T,
    ) -> T {
        x.unwrap_or_else(|| {
            self.err(key, format!("required for kind = \"{kind}\""));
            fallback
        })
    }

    fn scene(&mut self, raw: SceneFile, file_name: &str) -> Scene {
        let mut simulation = self.simulation(&raw.simulation);
        let domain = self.domain(&raw.domain);
        let gravity = self.vector("gravity", raw.gravity.unwrap_or(DEFAULT_GRAVITY));
        let materials = self.materials(&raw.materials);
        let mat_index: HashMap<String, usize> = materials
            .iter()
            .enumerate()
            .map(|(i, m)| (m.name.clone(), i))
            .collect();
        let (templates, particle_types, scale_distributions) =
            self.particle_types(&raw.particle_types, &mat_index);
        let walls = self.walls(&raw.walls, &mat_index);
        let pairs = self.pairs(&raw.material_pairs, &mat_index, &particle_types, &walls);
        let raw_output = raw.output.unwrap_or_default();
        let output = self.output(&raw_output);
        let parallel = self.parallel(raw.parallel.as_ref());
        let mut scene = Scene {
            file: self.base.join(file_name),
            simulation: simulation.clone(),
            domain,
            gravity,
            materials,
            pairs,
            templates,
            particle_types,
            scale_distributions,
            insertions: Vec::new(),
            walls,
            output,
            parallel,
            key_lines: self.index.key_lines(),
        };
        scene.insertions = self.insertions(&raw.insertions, &scene);
        if !self.errors.is_empty() {
            return scene;
        }
        // Defaults that depend on the loaded templates and the resolved time step.
        if raw
            .simulation
            .neighbor
            .as_ref()
            .and_then(|n| n.skin)
            .is_none()
        {
            // 0.1 × the largest circumscribed diameter.
            simulation.neighbor.skin = 0.2 * scene.max_bounding_radius();
            scene.simulation = simulation;
        }
        self.domain_resolution(&scene);
        let ts = critical_time_step(&scene);
        self.wall_speeds(&scene, ts.dt);
        if raw_output.series_interval.is_none() {
            scene.output.series_interval = scene.output.frame_interval.unwrap_or(100.0 * ts.dt);
        }
        if ts.fraction_of_rayleigh > 1.0 {
            tracing::warn!(
                "{file_name}: simulation.dt = {:.3e} s is {:.2} × the Rayleigh step {:.3e} s; \
                 the run is likely unstable",
                ts.dt,
                ts.fraction_of_rayleigh,
                ts.rayleigh
            );
        }
        scene
    }

    /// Refuses domains whose coordinates are too large for f64 to resolve the particles: the
    /// spacing of f64 near the largest coordinate must be at most [`POSITION_RESOLUTION`] of the
    /// smallest particle radius. Beyond it overlaps are rounding noise (false contacts at a
    /// half-width of 1e15 m; at ±1e308 the domain's width overflows and every contact is lost).
    fn domain_resolution(&mut self, scene: &Scene) {
        let r_min = scene.min_equivalent_radius();
        if !r_min.is_finite() {
            return;
        }
        let d = &scene.domain;
        let largest = |v: &Vector3<f64>| v.iter().map(|x| x.abs()).fold(0.0, f64::max);
        let (key, c) = if largest(&d.max) >= largest(&d.min) {
            ("domain.max", largest(&d.max))
        } else {
            ("domain.min", largest(&d.min))
        };
        let need = POSITION_RESOLUTION * r_min;
        let spacing = c * f64::EPSILON;
        let width_finite = (d.max - d.min).iter().all(|w| w.is_finite());
        if spacing > need || !width_finite {
            self.err(
                key,
                format!(
                    "coordinates up to {c:.4e} m are resolved in f64 only to {spacing:.4e} m, \
                     but contacts of the smallest particles (radius {r_min:.4e} m) need positions \
                     to {POSITION_RESOLUTION:e} of it, {need:.4e} m; allowed: |coordinates| ≤ \
                     {:.4e} m (shift the domain towards the origin or shrink it)",
                    need / f64::EPSILON
                ),
            );
        }
    }

    /// Refuses walls whose fastest point moves more than [`MAX_WALL_STEP_FRACTION`] of the
    /// smallest particle's radius in one step: a contact with such a wall is not resolved at
    /// all (at `rpm = 1e300` particles simply vanished).
    fn wall_speeds(&mut self, scene: &Scene, dt: f64) {
        let r_min = scene.min_equivalent_radius();
        if !(r_min.is_finite() && dt.is_finite()) {
            return;
        }
        let limit = MAX_WALL_STEP_FRACTION * r_min;
        for (i, w) in scene.walls.iter().enumerate() {
            let speed = w.motion.max_speed(&w.triangles);
            if speed * dt <= limit {
                continue;
            }
            let v_max = limit / dt;
            let (key, allowed) = match &w.motion {
                WallMotion::Rotate { rpm, .. } => (
                    "rpm",
                    format!("|rpm| ≤ {:.4e} at this step", rpm.abs() * v_max / speed),
                ),
                WallMotion::Sinusoidal { frequency, .. } => (
                    "frequency",
                    format!(
                        "2π × frequency × amplitude ≤ {v_max:.4e} m/s (frequency ≤ {:.4e} Hz at this amplitude)",
                        frequency * v_max / speed
                    ),
                ),
                _ => ("velocity", format!("|velocity| ≤ {v_max:.4e} m/s")),
            };
            self.err(
                &format!("walls[{i}].motion.{key}"),
                format!(
                    "wall \"{}\" moves too fast for the time step: its fastest point moves at \
                     {speed:.4e} m/s, {:.4e} m per step of dt = {dt:.4e} s, more than \
                     {MAX_WALL_STEP_FRACTION} × the smallest particle radius {r_min:.4e} m; \
                     allowed: {allowed} (or a smaller step)",
                    w.name,
                    speed * dt
                ),
            );
        }
    }

    fn simulation(&mut self, s: &schema::SimulationSection) -> SimulationSettings {
        let dt = match (s.dt, s.dt_fraction) {
            (Some(dt), None) => TimeStep::Fixed(self.positive("simulation.dt", dt)),
            (None, Some(f)) => {
                if !(f > 0.0 && f <= 1.0) {
                    self.err(
                        "simulation.dt_fraction",
                        format!("must be in (0, 1], got {f}"),
                    );
                }
                TimeStep::FractionOfCritical(f)
            }
            (Some(_), Some(_)) => {
                self.err(
                    "simulation.dt_fraction",
                    "give either dt or dt_fraction, not both",
                );
                TimeStep::FractionOfCritical(0.1)
            }
            // The default of docs/accuracy.md (DEFAULT_DT_FRACTION).
            (None, None) => TimeStep::FractionOfCritical(DEFAULT_DT_FRACTION),
        };
        let end_time = self.positive("simulation.end_time", s.end_time);
        let n = s.neighbor.as_ref();
        let skin = n
            .and_then(|n| n.skin)
            .map_or(0.0, |x| self.non_negative("simulation.neighbor.skin", x));
        let mode = match n
            .and_then(|n| n.mode)
            .unwrap_or(schema::NeighborModeName::Auto)
        {
            schema::NeighborModeName::Auto => NeighborMode::Auto,
            schema::NeighborModeName::Gpu => NeighborMode::Gpu,
            schema::NeighborModeName::Cpu => NeighborMode::Cpu,
            schema::NeighborModeName::Hybrid => NeighborMode::Hybrid,
        };
        let mut guard = GuardSettings::default();
        if let Some(g) = s.guard.as_ref() {
            guard.enabled = g.enabled.unwrap_or(true);
            if let Some(x) = g.max_overlap {
                guard.max_overlap = self.positive("simulation.guard.max_overlap", x);
            }
            if let Some(x) = g.max_speed {
                guard.max_speed = Some(self.positive("simulation.guard.max_speed", x));
            }
            if let Some(x) = g.speed_factor {
                guard.speed_factor = self.positive("simulation.guard.speed_factor", x);
            }
        }
        SimulationSettings {
            dt,
            end_time,
            seed: s.seed,
            neighbor: NeighborSettings { skin, mode },
            guard,
        }
    }

    fn domain(&mut self, d: &schema::DomainSection) -> Domain {
        let min = self.vector("domain.min", d.min);
        let max = self.vector("domain.max", d.max);
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            if max[a] <= min[a] {
                self.err(
                    "domain.max",
                    format!(
                        "must exceed domain.min on every axis; on {axis}: max {} ≤ min {}",
                        max[a], min[a]
                    ),
                );
            }
        }
        Domain {
            min,
            max,
            periodic: d.periodic,
            on_leaving: match d.on_leaving {
                Some(schema::LeavingName::Remove) => LeavingDomain::Remove,
                Some(schema::LeavingName::Error) | None => LeavingDomain::Error,
            },
        }
    }

    fn parallel(&mut self, p: Option<&schema::ParallelSection>) -> ParallelSettings {
        let mut out = ParallelSettings::default();
        let Some(p) = p else {
            return out;
        };
        let grid = p.grid;
        if let Some(g) = grid
            && g.contains(&0)
        {
            self.err(
                "parallel.grid",
                format!("ranks per axis must be ≥ 1, got {g:?}"),
            );
        }
        out.decomposition = match p.decomposition {
            Some(schema::DecompositionName::Grid) => Decomposition::Grid(grid),
            Some(schema::DecompositionName::Rcb) | None => {
                if grid.is_some() {
                    self.err(
                        "parallel.grid",
                        "only with decomposition = \"grid\" (recursive bisection places its own cuts)",
                    );
                }
                Decomposition::Rcb
            }
        };
        if let Some(w) = p.weight {
            out.weight = match w {
                schema::BalanceWeightName::Count => BalanceWeight::Count,
                schema::BalanceWeightName::Cost => BalanceWeight::Cost,
            };
        }
        if let Some(t) = p.imbalance_threshold {
            if !(t > 1.0 && t.is_finite()) {
                self.err(
                    "parallel.imbalance_threshold",
                    format!("must be a finite number > 1 (max load / mean load), got {t}"),
                );
            }
            out.imbalance_threshold = t;
        }
        if let Some(n) = p.balance_interval {
            if n == 0 {
                self.err(
                    "parallel.balance_interval",
                    "must be ≥ 1 (neighbour-list rebuilds)",
                );
            }
            out.balance_interval = n;
        }
        out
    }

    fn materials(&mut self, list: &[schema::MaterialSection]) -> Vec<Material> {
        if list.is_empty() {
            self.err("materials", "at least one [[materials]] entry is required");
        }
        let mut out: Vec<Material> = Vec::new();
        for (i, m) in list.iter().enumerate() {
            let k = |f: &str| format!("materials[{i}].{f}");
            if m.name.is_empty() {
                self.err(&k("name"), "must not be empty");
            } else if out.iter().any(|o| o.name == m.name) {
                self.err(
                    &k("name"),
                    format!("material \"{}\" is defined twice", m.name),
                );
            }
            self.positive(&k("youngs_modulus"), m.youngs_modulus);
            if !(m.poisson_ratio > -1.0 && m.poisson_ratio < 0.5) {
                self.err(
                    &k("poisson_ratio"),
                    format!(
                        "must be in the open interval (-1, 0.5), got {}",
                        m.poisson_ratio
                    ),
                );
            }
            self.positive(&k("density"), m.density);
            out.push(Material {
                name: m.name.clone(),
                youngs_modulus: m.youngs_modulus,
                poisson_ratio: m.poisson_ratio,
                density: m.density,
            });
        }
        out
    }

    pub(super) fn material_ref(
        &mut self,
        key: &str,
        name: &str,
        mats: &HashMap<String, usize>,
    ) -> usize {
        mats.get(name).copied().unwrap_or_else(|| {
            let mut defined: Vec<&String> = mats.keys().collect();
            defined.sort_by_key(|n| mats[*n]);
            self.err(
                key,
                format!(
                    "unknown material \"{name}\"; defined: {}",
                    names(defined.into_iter())
                ),
            );
            0
        })
    }

    fn particle_types(
        &mut self,
        list: &[schema::ParticleTypeSection],
        mats: &HashMap<String, usize>,
    ) -> (
        Vec<ConvexTemplate>,
        Vec<ParticleType>,
        Vec<ScaleDistribution>,
    ) {
        if list.is_empty() {
            self.err(
                "particle_types",
                "at least one [[particle_types]] entry is required",
            );
        }
        let (mut templates, mut types, mut scales) = (Vec::new(), Vec::new(), Vec::new());
        let mut sources: HashMap<String, usize> = HashMap::new();
        for (i, p) in list.iter().enumerate() {
            let k = |f: &str| format!("particle_types[{i}].{f}");
            if p.name.is_empty() {
                self.err(&k("name"), "must not be empty");
            } else if types.iter().any(|t: &ParticleType| t.name == p.name) {
                self.err(
                    &k("name"),
                    format!("particle type \"{}\" is defined twice", p.name),
                );
            }
            let material = self.material_ref(&k("material"), &p.material, mats);
            let (source, built) = match (&p.mesh, &p.generator) {
                (Some(m), None) => {
                    let path = self.resolve(m);
                    let key = format!("mesh:{}", path.display());
                    let built = (!sources.contains_key(&key))
                        .then(|| ConvexTemplate::from_file(&path).map_err(|e| (k("mesh"), e)));
                    (key, built)
                }
                (None, Some(g)) => {
                    let key = format!("generator:{g:?}");
                    let built = (!sources.contains_key(&key))
                        .then(|| g.build().map_err(|e| (k("generator"), e)));
                    (key, built)
                }
                _ => {
                    self.err(
                        &k("mesh"),
                        "give exactly one of mesh (a file) or generator (a table)",
                    );
                    (String::new(), None)
                }
            };
            let template = match built {
                Some(Ok(t)) => {
                    templates.push(t);
                    sources.insert(source, templates.len() - 1);
                    templates.len() - 1
                }
                Some(Err((key, e))) => {
                    self.err(&key, e.to_string());
                    0
                }
                None => sources.get(&source).copied().unwrap_or(0),
            };
            types.push(ParticleType {
                name: p.name.clone(),
                template,
                material,
            });
            scales.push(self.scale(&k("scale"), p.scale.as_ref()));
        }
        // The sphere fast path replaces the polyhedral stages for the whole scene (docs/design.md §1);
        // a sphere–polyhedron contact has no formula.
        let is_sphere = |t: &ParticleType| templates.get(t.template).is_some_and(|t| t.sphere);
        if let (Some(s), Some(q)) = (
            types.iter().position(is_sphere),
            types.iter().position(|t| !is_sphere(t)),
        ) {
            self.err(
                &format!("particle_types[{s}].generator"),
                format!(
                    "spheres (\"{}\") and polyhedra (\"{}\") cannot be mixed in one scene: \
                     sphere–polyhedron contacts are not supported; use only spheres, or a \
                     faceted polyhedron (e.g. kind = \"icosahedron\") in their place",
                    types[s].name, types[q].name
                ),
            );
        }
        (templates, types, scales)
    }

    fn pairs(
        &mut self,
        list: &[schema::PairSection],
        mats: &HashMap<String, usize>,
        types: &[ParticleType],
        walls: &[Wall],
    ) -> PairTable {
        let mut table = PairTable::new(mats.len());
        for (i, p) in list.iter().enumerate() {
            let k = |f: &str| format!("material_pairs[{i}].{f}");
            let a = self.material_ref(&k("materials"), &p.materials[0], mats);
            let b = self.material_ref(&k("materials"), &p.materials[1], mats);
            if !(p.restitution > 0.0 && p.restitution <= 1.0) {
                self.err(
                    &k("restitution"),
                    format!("must be in (0, 1], got {}", p.restitution),
                );
            }
            self.non_negative(&k("friction"), p.friction);
            if mats.contains_key(&p.materials[0]) && mats.contains_key(&p.materials[1]) {
                if table.try_get(a, b).is_some() {
                    self.err(
                        &k("materials"),
                        format!("pair {:?} is given twice", p.materials),
                    );
                }
                table.set(
                    a,
                    b,
                    PairParameters {
                        restitution: p.restitution,
                        friction: p.friction,
                    },
                );
            }
        }
        if !self.errors.is_empty() {
            return table; // unknown names would make the missing list misleading
        }
        let name_of: HashMap<usize, &String> = mats.iter().map(|(n, i)| (*i, n)).collect();
        let mut particle_mats: Vec<usize> = types.iter().map(|t| t.material).collect();
        particle_mats.sort_unstable();
        particle_mats.dedup();
        let mut wall_mats: Vec<usize> = walls.iter().map(|w| w.material).collect();
        wall_mats.sort_unstable();
        wall_mats.dedup();
        let mut missing = Vec::new();
        for (n, &a) in particle_mats.iter().enumerate() {
            let partners = particle_mats[n..].iter().map(|&b| (b, "particles")).chain(
                wall_mats
                    .iter()
                    .filter(|w| !particle_mats[..n].contains(w))
                    .map(|&b| (b, "walls")),
            );
            for (b, with) in partners {
                if table.try_get(a, b).is_none()
                    && !missing.iter().any(|(x, y, _)| (*x, *y) == (a, b))
                {
                    missing.push((a, b, with));
                }
            }
        }
        if !missing.is_empty() {
            let list: Vec<String> = missing
                .iter()
                .map(|(a, b, with)| {
                    format!(
                        "[\"{}\", \"{}\"] (particles meet {with})",
                        name_of[a], name_of[b]
                    )
                })
                .collect();
            self.err(
                "material_pairs",
                format!(
                    "missing material pair(s): {}; add a [[material_pairs]] entry with materials, restitution and friction for each",
                    list.join(", ")
                ),
            );
        }
        table
    }

    fn insertions(&mut self, list: &[schema::InsertionSection], scene: &Scene) -> Vec<Insertion> {
        let mut out = Vec::new();
        for (i, s) in list.iter().enumerate() {
            let k = |f: &str| format!("insertions[{i}].{f}");
            let particle_type = scene
                .particle_type_index(&s.particle_type)
                .unwrap_or_else(|| {
                    let defined = names(scene.particle_types.iter().map(|p| &p.name));
                    self.err(
                        &k("type"),
                        format!(
                            "unknown particle type \"{}\"; defined: {defined}",
                            s.particle_type
                        ),
                    );
                    usize::MAX
                });
            let region = self.region(&k("region"), &s.region, scene, particle_type);
            let rate_only = [
                ("start", s.start.is_some()),
                ("end", s.end.is_some()),
                ("total", s.total.is_some()),
            ];
            let mode = match (s.count, s.rate) {
                (Some(n), None) => {
                    if n == 0 {
                        self.err(&k("count"), "must be at least 1");
                    }
                    for (name, set) in rate_only {
                        if set {
                            self.err(&k(name), "only allowed with rate (a count insertion places all at the start)");
                        }
                    }
                    InsertionMode::Count(n)
                }
                (None, Some(r)) => {
                    let per_second = self.positive(&k("rate"), r);
                    let start = self.non_negative(&k("start"), s.start.unwrap_or(0.0));
                    if let Some(e) = s.end.filter(|e| !(*e > start && e.is_finite())) {
                        self.err(
                            &k("end"),
                            format!("must be finite and after start ({start}), got {e}"),
                        );
                    }
                    if s.total == Some(0) {
                        self.err(&k("total"), "must be at least 1");
                    }
                    InsertionMode::Rate {
                        per_second,
                        start,
                        end: s.end,
                        total: s.total,
                    }
                }
                _ => {
                    self.err(
                        &k("count"),
                        "give exactly one of count (all at the start) or rate (per second)",
                    );
                    InsertionMode::Count(0)
                }
            };
            let orientation = self.orientation(&k("orientation"), s.orientation.as_ref());
            let velocity = self.vector(&k("velocity"), s.velocity.unwrap_or_default());
            let angular_velocity = self.vector(
                &k("angular_velocity"),
                s.angular_velocity.unwrap_or_default(),
            );
            let max_attempts = s.max_attempts.unwrap_or(DEFAULT_MAX_ATTEMPTS);
            if max_attempts == 0 {
                self.err(&k("max_attempts"), "must be at least 1");
            }
            let lattice = s.lattice.map(|l| {
                let v = self.vector(&k("lattice"), l);
                if !(v.iter().all(|&x| x > 0.0 && x.is_finite())) {
                    self.err(&k("lattice"), format!("spacings must be positive, got {v:?}"));
                }
                if !matches!(mode, InsertionMode::Count(_)) {
                    self.err(&k("lattice"), "only allowed with count (a lattice is filled at the start)");
                }
                match (&region, &mode) {
                    (Region::Box { min, max }, InsertionMode::Count(n)) => {
                        let points: f64 = (0..3)
                            .map(|a| ((max[a] - min[a]) / v[a] + 1e-9).floor().max(0.0))
                            .product();
                        if (*n as f64) > points {
                            self.err(
                                &k("count"),
                                format!("{n} particles do not fit on the lattice: it has {points} points in the region"),
                            );
                        }
                    }
                    (Region::Box { .. }, _) => {}
                    _ => self.err(&k("lattice"), "only allowed with a box region"),
                }
                v
            });
            out.push(Insertion {
                particle_type,
                region,
                mode,
                orientation,
                velocity,
                angular_velocity,
                max_attempts,
                lattice,
            });
        }
        self.start_memory(&out);
        out
    }

    /// Refuses count insertions whose particles, all placed at the start, cannot fit in this
    /// machine's memory: they would otherwise be allocated one by one until the process is
    /// killed, long after `polydem check` said the scene was fine.
    fn start_memory(&mut self, insertions: &[Insertion]) {
        let counts: Vec<(usize, u64)> = insertions
            .iter()
            .enumerate()
            .filter_map(|(k, ins)| match ins.mode {
                InsertionMode::Count(n) => Some((k, n)),
                _ => None,
            })
            .collect();
        let total: u128 = counts.iter().map(|&(_, n)| n as u128).sum();
        let Some(&(largest, _)) = counts.iter().max_by_key(|&&(_, n)| n) else {
            return;
        };
        let need = total * HOST_BYTES_PER_PARTICLE as u128;
        let Some(have) = physical_memory() else {
            return;
        };
        if need > have as u128 {
            let gib = |b: f64| b / (1u64 << 30) as f64;
            self.err(
                &format!("insertions[{largest}].count"),
                format!(
                    "{total} particles placed at the start need at least {:.1} GiB of memory \
                     ({HOST_BYTES_PER_PARTICLE} bytes each for the particle state alone), more \
                     than this machine's {:.1} GiB; lower count",
                    gib(need as f64),
                    gib(have as f64)
                ),
            );
        }
    }

    fn output(&mut self, o: &schema::OutputSection) -> OutputSettings {
        let dir = self.resolve(o.dir.as_deref().unwrap_or("out"));
        let frame_interval = o
            .frame_interval
            .map(|x| self.positive("output.frame_interval", x));
        let formats_given = o.formats.clone().unwrap_or_else(|| vec!["vtu".into()]);
        if formats_given.is_empty() {
            self.err(
                "output.formats",
                format!(
                    "must name at least one format; allowed: {}",
                    OUTPUT_FORMATS.join(", ")
                ),
            );
        }
        let mut formats = OutputFormats {
            vtu: false,
            csv: false,
        };
        for (i, f) in formats_given.iter().enumerate() {
            let slot = match f.as_str() {
                "vtu" => &mut formats.vtu,
                "csv" => &mut formats.csv,
                _ => {
                    self.err(
                        &format!("output.formats[{i}]"),
                        format!(
                            "unknown format \"{f}\"; allowed: {}",
                            OUTPUT_FORMATS.join(", ")
                        ),
                    );
                    continue;
                }
            };
            if std::mem::replace(slot, true) {
                self.err(
                    &format!("output.formats[{i}]"),
                    format!("format \"{f}\" is listed twice"),
                );
            }
        }
        let fields = o
            .fields
            .clone()
            .unwrap_or_else(|| DEFAULT_FIELDS.iter().map(|s| s.to_string()).collect());
        for (i, f) in fields.iter().enumerate() {
            if !OUTPUT_FIELDS.contains(&f.as_str()) {
                self.err(
                    &format!("output.fields[{i}]"),
                    format!(
                        "unknown field \"{f}\"; allowed: {}",
                        OUTPUT_FIELDS.join(", ")
                    ),
                );
            } else if fields[..i].contains(f) {
                self.err(
                    &format!("output.fields[{i}]"),
                    format!("field \"{f}\" is listed twice"),
                );
            }
        }
        let checkpoint_interval = o
            .checkpoint_interval
            .map(|x| self.positive("output.checkpoint_interval", x));
        let series_interval = o
            .series_interval
            .map_or(0.0, |x| self.positive("output.series_interval", x));
        let log_interval_steps = o.log_interval_steps.unwrap_or(DEFAULT_LOG_INTERVAL);
        if log_interval_steps == 0 {
            self.err("output.log_interval_steps", "must be at least 1");
        }
        if o.checkpoint_keep == Some(0) {
            self.err(
                "output.checkpoint_keep",
                "must be at least 1 (leave it out to keep every checkpoint)",
            );
        }
        if o.checkpoint_keep.is_some() && checkpoint_interval.is_none() {
            self.err(
                "output.checkpoint_keep",
                "needs output.checkpoint_interval (there are no periodic checkpoints to keep)",
            );
        }
        OutputSettings {
            dir,
            frame_interval,
            formats,
            fields,
            checkpoint_interval,
            series_interval,
            log_interval_steps,
            checkpoint_keep: o.checkpoint_keep,
        }
    }
}
