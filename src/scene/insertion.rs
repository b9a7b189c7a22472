//! Particle insertion: regions, scale distributions, and the [`Inserter`] that places particles
//! at the start (count) or continuously (rate), never overlapping what is already there.
//!
//! Overlap is tested with bounding spheres (circumscribed radius × scale), which is conservative:
//! a placed particle touches no other particle and no wall triangle. Every random choice comes
//! from one [`Rng`] seeded by `simulation.seed`, drawn in a fixed order (insertion by insertion,
//! particle by particle: scale, orientation, then positions), and its state is part of
//! [`InserterState`], so a restart continues the exact same sequence.

use super::schema;
use super::walls::WallTriangles;
use super::{Scene, SceneError};
use crate::rng::Rng;
use crate::state::Particles;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::f64::consts::TAU;

/// Default number of random positions tried per particle.
pub const DEFAULT_MAX_ATTEMPTS: u32 = 1000;

/// Where particles are inserted. Whole bounding spheres are kept inside the region.
#[derive(Clone, Debug, PartialEq)]
pub enum Region {
    /// Axis-aligned box (m).
    Box {
        min: Vector3<f64>,
        max: Vector3<f64>,
    },
    /// Cylinder from `base` along the unit `axis` for `height`, of `radius` (m).
    Cylinder {
        base: Vector3<f64>,
        axis: Vector3<f64>,
        radius: f64,
        height: f64,
    },
}

impl Region {
    /// Axis-aligned bounding box `(min, max)`.
    pub fn aabb(&self) -> (Vector3<f64>, Vector3<f64>) {
        match self {
            Region::Box { min, max } => (*min, *max),
            Region::Cylinder {
                base,
                axis,
                radius,
                height,
            } => {
                // A disk of radius R normal to unit a extends R·√(1 − a_i²) along axis i.
                let ext = axis.map(|a| radius * (1.0 - a * a).max(0.0).sqrt());
                let top = base + axis * *height;
                (base.inf(&top) - ext, base.sup(&top) + ext)
            }
        }
    }

    /// Volume (m³).
    pub fn volume(&self) -> f64 {
        match self {
            Region::Box { min, max } => (max - min).product(),
            Region::Cylinder { radius, height, .. } => 0.5 * TAU * radius * radius * height,
        }
    }

    /// Whether a sphere of radius `r` fits inside at all.
    pub fn fits(&self, r: f64) -> bool {
        match self {
            Region::Box { min, max } => (max - min).min() > 2.0 * r,
            Region::Cylinder { radius, height, .. } => *radius > r && *height > 2.0 * r,
        }
    }

    /// A uniformly random centre such that a sphere of radius `r` lies inside; `None` when it
    /// cannot fit. Draws exactly three uniforms when it fits.
    pub fn sample_centre(&self, rng: &mut Rng, r: f64) -> Option<Vector3<f64>> {
        if !self.fits(r) {
            return None;
        }
        match self {
            Region::Box { min, max } => {
                let x = rng.range(min.x + r, max.x - r);
                let y = rng.range(min.y + r, max.y - r);
                let z = rng.range(min.z + r, max.z - r);
                Some(Vector3::new(x, y, z))
            }
            Region::Cylinder {
                base,
                axis,
                radius,
                height,
            } => {
                let (u, v) = perpendicular_basis(axis);
                let rho = (radius - r) * rng.uniform().sqrt();
                let phi = TAU * rng.uniform();
                let h = rng.range(r, height - r);
                Some(base + axis * h + u * (rho * phi.cos()) + v * (rho * phi.sin()))
            }
        }
    }
}

/// Two unit vectors completing the unit `a` to a right-handed orthonormal basis.
fn perpendicular_basis(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    // Cross with the coordinate axis least aligned with a: never near-parallel.
    let i = a.iamin();
    let mut e = Vector3::zeros();
    e[i] = 1.0;
    let u = a.cross(&e).normalize();
    (u, a.cross(&u))
}

/// When particles are inserted.
#[derive(Clone, Debug, PartialEq)]
pub enum InsertionMode {
    /// This many particles, all at the first [`Inserter::insert`] call.
    Count(u64),
    /// Continuous feeding: `floor((min(t, end) − start) · per_second)` particles are due by
    /// time t, at most `total`.
    Rate {
        per_second: f64,
        start: f64,
        end: Option<f64>,
        total: Option<u64>,
    },
}

/// Orientation of inserted particles (body → world).
#[derive(Clone, Debug, PartialEq)]
pub enum OrientationMode {
    /// Uniform over all rotations ([`Rng::unit_quaternion`]).
    Random,
    /// This rotation for every particle.
    Fixed(UnitQuaternion<f64>),
}

/// One `[[insertions]]` entry, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct Insertion {
    /// Index into [`Scene::particle_types`].
    pub particle_type: usize,
    /// Where.
    pub region: Region,
    /// When and how many.
    pub mode: InsertionMode,
    /// Orientation of each particle.
    pub orientation: OrientationMode,
    /// Initial velocity (m/s).
    pub velocity: Vector3<f64>,
    /// Initial angular velocity (rad/s).
    pub angular_velocity: Vector3<f64>,
    /// Random positions tried per particle before it counts as not placed.
    pub max_attempts: u32,
    /// Lattice spacing: particles at the points of a simple cubic lattice filling the box
    /// region, x fastest, then y, then z (count only). No overlap test: the spacing decides,
    /// so a lattice can start as a dense packing in contact (benchmarks, compaction).
    pub lattice: Option<Vector3<f64>>,
}

impl Insertion {
    /// Particles due by time `t` in total (not only new ones).
    pub fn due_by(&self, t: f64) -> u64 {
        match self.mode {
            InsertionMode::Count(n) => n,
            InsertionMode::Rate {
                per_second,
                start,
                end,
                total,
            } => {
                let t_end = end.map_or(t, |e| t.min(e));
                if t.is_nan() || t_end < start {
                    return 0;
                }
                // `as` saturates, so a huge product cannot wrap.
                let n = ((t_end - start) * per_second).floor() as u64;
                total.map_or(n, |cap| n.min(cap))
            }
        }
    }

    /// Particles this insertion will have placed by `end_time` if every one fits.
    pub fn planned_count(&self, end_time: f64) -> u64 {
        self.due_by(end_time)
    }
}

/// What one [`Inserter::insert`] call did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct InsertReport {
    /// Particles placed by this call.
    pub inserted: u64,
    /// Rate particles that were due but found no free position; they are tried again later.
    pub deferred: u64,
}

/// Everything an [`Inserter`] needs to continue exactly after a restart.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InserterState {
    /// Raw [`Rng`] state.
    pub rng: [u64; 4],
    /// Particles placed so far, per insertion.
    pub inserted: Vec<u64>,
    /// Whether each count insertion has run.
    pub count_done: Vec<bool>,
    /// Time of the last call that placed a particle.
    pub last_insertion_time: Option<f64>,
}

/// Places particles as the scene's insertions ask (see the module docs).
#[derive(Clone, Debug)]
pub struct Inserter {
    rng: Rng,
    inserted: Vec<u64>,
    count_done: Vec<bool>,
    last_insertion_time: Option<f64>,
}

impl Inserter {
    /// A fresh inserter, its generator seeded from `simulation.seed`.
    pub fn new(scene: &Scene) -> Self {
        let n = scene.insertions.len();
        Inserter {
            rng: Rng::new(scene.simulation.seed),
            inserted: vec![0; n],
            count_done: vec![false; n],
            last_insertion_time: None,
        }
    }

    /// The state to checkpoint.
    pub fn state(&self) -> InserterState {
        InserterState {
            rng: self.rng.state(),
            inserted: self.inserted.clone(),
            count_done: self.count_done.clone(),
            last_insertion_time: self.last_insertion_time,
        }
    }

    /// Restores a checkpointed state. If the scene's insertion list changed length since, the
    /// counters are cut or padded with zeros (new insertions start afresh);
    /// [`Inserter::try_restore`] refuses that instead.
    pub fn restore(scene: &Scene, state: &InserterState) -> Self {
        let n = scene.insertions.len();
        let mut inserted = state.inserted.clone();
        inserted.resize(n, 0);
        let mut count_done = state.count_done.clone();
        count_done.resize(n, false);
        Inserter {
            rng: Rng::from_state(state.rng),
            inserted,
            count_done,
            last_insertion_time: state.last_insertion_time,
        }
    }

    /// As [`Inserter::restore`], but an error when the state does not match the scene.
    pub fn try_restore(scene: &Scene, state: &InserterState) -> Result<Self, SceneError> {
        let n = scene.insertions.len();
        if state.inserted.len() != n || state.count_done.len() != n {
            return Err(SceneError::Insertion {
                file: scene.file.display().to_string(),
                key: "insertions".into(),
                message: format!(
                    "the checkpoint's insertion state has {} entries, the scene {n}",
                    state.inserted.len()
                ),
            });
        }
        Ok(Self::restore(scene, state))
    }

    /// Particles placed so far by each insertion.
    pub fn inserted(&self) -> &[u64] {
        &self.inserted
    }

    /// Time of the last call that placed a particle.
    pub fn last_insertion_time(&self) -> Option<f64> {
        self.last_insertion_time
    }

    /// Whether [`Inserter::insert`] at time `t` would place particles (some are due), without
    /// placing them: the GPU backend syncs the state to the host only then.
    pub fn pending(&self, t: f64, scene: &Scene) -> bool {
        let n_ins = scene.insertions.len().min(self.inserted.len());
        (0..n_ins).any(|k| {
            let ins = &scene.insertions[k];
            let done = matches!(ins.mode, InsertionMode::Count(_)) && self.count_done[k];
            !done && ins.due_by(t) > self.inserted[k]
        })
    }

    /// Inserts every particle due by time `t`: count insertions on the first call, rate
    /// insertions as they fall due. New particles overlap no existing or new particle and no
    /// wall (at its pose at `t`), judged by bounding spheres, and lie inside their region and
    /// therefore inside the domain. Ids are taken from `next_id`, which is advanced.
    ///
    /// Rate particles that find no place in `max_attempts` tries are deferred to later calls.
    /// A count insertion that cannot place all its particles is an error that says how many fit.
    pub fn insert(
        &mut self,
        t: f64,
        particles: &mut Particles,
        scene: &Scene,
        next_id: &mut u64,
    ) -> Result<InsertReport, SceneError> {
        let mut report = InsertReport::default();
        let n_ins = scene.insertions.len().min(self.inserted.len());
        let due: Vec<u64> = (0..n_ins)
            .map(|k| {
                let ins = &scene.insertions[k];
                let done = matches!(ins.mode, InsertionMode::Count(_)) && self.count_done[k];
                if done {
                    0
                } else {
                    ins.due_by(t).saturating_sub(self.inserted[k])
                }
            })
            .collect();
        if due.iter().all(|&d| d == 0) {
            return Ok(report);
        }
        let mut occupied = Occupancy::new(scene, particles);
        let walls = WallTriangles::at(scene, t);
        for (k, &n_due) in due.iter().enumerate() {
            let ins = &scene.insertions[k];
            let is_count = matches!(ins.mode, InsertionMode::Count(_));
            if let (Some(spacing), Region::Box { min, max }) = (ins.lattice, &ins.region) {
                // Validation checked that the lattice holds the count.
                // The 1e-9 absorbs the rounding of a region sized as an exact multiple of the spacing.
                let dims = [0, 1, 2]
                    .map(|a| ((max[a] - min[a]) / spacing[a] + 1e-9).floor().max(1.0) as u64);
                for _ in 0..n_due {
                    let j = self.inserted[k];
                    let cell = [
                        j % dims[0],
                        (j / dims[0]) % dims[1],
                        j / (dims[0] * dims[1]),
                    ];
                    let c = Vector3::from_fn(|a, _| min[a] + spacing[a] * (cell[a] as f64 + 0.5));
                    self.place_at(ins, particles, scene, c, next_id);
                    self.inserted[k] += 1;
                    report.inserted += 1;
                }
                self.last_insertion_time = Some(t);
                self.count_done[k] = true;
                continue;
            }
            for placed in 0..n_due {
                if self.place_one(ins, particles, scene, &mut occupied, &walls, next_id) {
                    self.inserted[k] += 1;
                    report.inserted += 1;
                    self.last_insertion_time = Some(t);
                } else if is_count {
                    let name = type_name(scene, ins.particle_type);
                    return Err(SceneError::Insertion {
                        file: scene.file.display().to_string(),
                        key: format!("insertions[{k}].count"),
                        message: format!(
                            "only {placed} of {n_due} particles of type '{name}' fit in the region: \
                             particle {} found no free position in {} random tries \
                             (bounding-sphere test against particles and walls); enlarge the \
                             region, lower `count`, or feed with `rate`",
                            placed + 1,
                            ins.max_attempts
                        ),
                    });
                } else {
                    report.deferred += n_due - placed;
                    break;
                }
            }
            if is_count {
                self.count_done[k] = true;
            }
        }
        if report.deferred > 0 {
            tracing::debug!(
                t,
                deferred = report.deferred,
                "insertion region full; retrying later"
            );
        }
        Ok(report)
    }

    /// Draws one particle's scale and orientation (in this order, from the insertion stream);
    /// `None` for a type the scene does not define (validation prevents it).
    fn draw(&mut self, ins: &Insertion, scene: &Scene) -> Option<(f64, UnitQuaternion<f64>)> {
        let dist = scene.scale_distributions.get(ins.particle_type)?;
        let scale = dist.sample(&mut self.rng);
        let orientation = match &ins.orientation {
            OrientationMode::Random => {
                let q = self.rng.unit_quaternion();
                UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
            }
            OrientationMode::Fixed(q) => *q,
        };
        Some((scale, orientation))
    }

    /// Appends a particle of the insertion's type at `c` with the insertion's velocities.
    fn push(
        ins: &Insertion,
        particles: &mut Particles,
        scene: &Scene,
        (scale, orientation): (f64, UnitQuaternion<f64>),
        c: Vector3<f64>,
        next_id: &mut u64,
    ) {
        let kind = ins.particle_type;
        let ptype = &scene.particle_types[kind];
        let density = scene
            .materials
            .get(ptype.material)
            .map_or(0.0, |m| m.density);
        particles.push(
            *next_id,
            kind as u32,
            scale,
            c,
            orientation,
            &scene.templates[ptype.template],
            density,
        );
        let i = particles.len() - 1;
        particles.velocity[i] = ins.velocity;
        particles.angular_velocity[i] = ins.angular_velocity;
        *next_id += 1;
    }

    /// Draws one particle and places it at `c` without any test (lattice insertion).
    fn place_at(
        &mut self,
        ins: &Insertion,
        particles: &mut Particles,
        scene: &Scene,
        c: Vector3<f64>,
        next_id: &mut u64,
    ) {
        if let Some(body) = self.draw(ins, scene) {
            Self::push(ins, particles, scene, body, c, next_id);
        }
    }

    /// Draws one particle and tries to place it; false if no position was free.
    fn place_one(
        &mut self,
        ins: &Insertion,
        particles: &mut Particles,
        scene: &Scene,
        occupied: &mut Occupancy,
        walls: &WallTriangles,
        next_id: &mut u64,
    ) -> bool {
        let Some(template) = scene
            .particle_types
            .get(ins.particle_type)
            .and_then(|p| scene.templates.get(p.template))
        else {
            return false;
        };
        let Some(body) = self.draw(ins, scene) else {
            return false;
        };
        let r = template.circumscribed_radius * body.0;
        for _ in 0..ins.max_attempts {
            let Some(c) = ins.region.sample_centre(&mut self.rng, r) else {
                return false;
            };
            if occupied.is_free(&c, r) && walls.is_free(&c, r) {
                Self::push(ins, particles, scene, body, c, next_id);
                occupied.add(c, r);
                return true;
            }
        }
        false
    }
}

fn type_name(scene: &Scene, kind: usize) -> &str {
    scene
        .particle_types
        .get(kind)
        .map_or("?", |p| p.name.as_str())
}

/// Bounding radius of a particle of type `kind` at `scale`; the scene's largest when the type is
/// unknown (conservative).
fn bounding_radius(scene: &Scene, kind: usize, scale: f64) -> f64 {
    scene
        .particle_types
        .get(kind)
        .and_then(|p| scene.templates.get(p.template))
        .map_or(scene.max_bounding_radius(), |t| {
            t.circumscribed_radius * scale
        })
}

/// Bounding spheres of present particles in a uniform hash grid of cell size ≥ 2 r_max, so a
/// query looks at no more than 2 cells per axis (times periodic images).
struct Occupancy {
    cell: f64,
    r_max: f64,
    cells: HashMap<[i64; 3], Vec<(Vector3<f64>, f64)>>,
    /// Shifts of the periodic axes (zero for the others): the domain's extent.
    period: Vector3<f64>,
    periodic: [bool; 3],
    domain_min: Vector3<f64>,
    domain_max: Vector3<f64>,
}

impl Occupancy {
    fn new(scene: &Scene, particles: &Particles) -> Self {
        let mut r_max = scene.max_bounding_radius();
        let radii: Vec<f64> = (0..particles.len())
            .map(|i| {
                let kind = particles.kind.get(i).copied().unwrap_or(u32::MAX) as usize;
                let s = particles.scale.get(i).copied().unwrap_or(1.0);
                bounding_radius(scene, kind, s)
            })
            .collect();
        for &r in &radii {
            r_max = r_max.max(r);
        }
        let cell = (2.0 * r_max).max(f64::MIN_POSITIVE);
        let d = &scene.domain;
        let mut occ = Occupancy {
            cell,
            r_max,
            cells: HashMap::new(),
            period: d.max - d.min,
            periodic: d.periodic,
            domain_min: d.min,
            domain_max: d.max,
        };
        for (p, r) in particles.position.iter().zip(radii) {
            occ.add(*p, r);
        }
        occ
    }

    fn key(&self, p: &Vector3<f64>) -> [i64; 3] {
        // `as` saturates (NaN → 0): a particle far outside still gets a cell, never a panic.
        p.map(|x| (x / self.cell).floor() as i64).into()
    }

    fn add(&mut self, p: Vector3<f64>, r: f64) {
        let k = self.key(&p);
        self.cells.entry(k).or_default().push((p, r));
    }

    /// No present sphere within `r` of `c`, including periodic images.
    fn is_free(&self, c: &Vector3<f64>, r: f64) -> bool {
        let reach = r + self.r_max;
        // Images of c across each periodic axis whose boundary is within reach.
        let mut images = vec![*c];
        for a in 0..3 {
            if !self.periodic[a] {
                continue;
            }
            let mut shifted = Vec::new();
            for img in &images {
                if img[a] - self.domain_min[a] < reach {
                    let mut s = *img;
                    s[a] += self.period[a];
                    shifted.push(s);
                }
                if self.domain_max[a] - img[a] < reach {
                    let mut s = *img;
                    s[a] -= self.period[a];
                    shifted.push(s);
                }
            }
            images.extend(shifted);
        }
        images.iter().all(|q| self.is_free_at(q, r, reach))
    }

    fn is_free_at(&self, q: &Vector3<f64>, r: f64, reach: f64) -> bool {
        let lo = self.key(&q.add_scalar(-reach));
        let hi = self.key(&q.add_scalar(reach));
        for i in lo[0]..=hi[0] {
            for j in lo[1]..=hi[1] {
                for k in lo[2]..=hi[2] {
                    let Some(list) = self.cells.get(&[i, j, k]) else {
                        continue;
                    };
                    for (p, rp) in list {
                        let d = r + rp;
                        if (p - q).norm_squared() < d * d {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }
}

/// Validation of `insertions[i].region`.
impl super::validate::Validator<'_> {
    pub(super) fn region(
        &mut self,
        p: &str,
        r: &schema::RegionSection,
        scene: &Scene,
        kind: usize,
    ) -> Region {
        let present = [
            ("min", r.min.is_some()),
            ("max", r.max.is_some()),
            ("base", r.base.is_some()),
            ("axis", r.axis.is_some()),
            ("radius", r.radius.is_some()),
            ("height", r.height.is_some()),
        ];
        let key = |f: &str| format!("{p}.{f}");
        let region = match r.kind {
            schema::RegionKind::Box => {
                self.only(p, "box", &present, &["min", "max"]);
                let min = self.required(&key("min"), "box", r.min, [0.0; 3]);
                let max = self.required(&key("max"), "box", r.max, [1.0; 3]);
                let (min, max) = (self.vector(&key("min"), min), self.vector(&key("max"), max));
                if (0..3).any(|a| max[a] <= min[a]) {
                    self.err(&key("max"), "must exceed min on every axis");
                }
                Region::Box { min, max }
            }
            schema::RegionKind::Cylinder => {
                let k = "cylinder";
                self.only(p, k, &present, &["base", "axis", "radius", "height"]);
                let base = self.required(&key("base"), k, r.base, [0.0; 3]);
                let axis = self.required(&key("axis"), k, r.axis, [0.0, 0.0, 1.0]);
                let radius = self.required(&key("radius"), k, r.radius, 1.0);
                let height = self.required(&key("height"), k, r.height, 1.0);
                Region::Cylinder {
                    base: self.vector(&key("base"), base),
                    axis: self.direction(&key("axis"), axis).into_inner(),
                    radius: self.positive(&key("radius"), radius),
                    height: self.positive(&key("height"), height),
                }
            }
        };
        let (lo, hi) = region.aabb();
        let d = &scene.domain;
        if (0..3).any(|a| lo[a] < d.min[a] || hi[a] > d.max[a]) {
            self.err(
                p,
                format!(
                    "region (bounding box {:?} to {:?}) is not inside the domain {:?} to {:?}",
                    lo.as_slice(),
                    hi.as_slice(),
                    d.min.as_slice(),
                    d.max.as_slice()
                ),
            );
        }
        let fits = scene.particle_types.get(kind).and_then(|t| {
            let tpl = scene.templates.get(t.template)?;
            Some((
                tpl.circumscribed_radius * scene.scale_distributions.get(kind)?.max_scale(),
                t,
            ))
        });
        if let Some((r, t)) = fits.filter(|(r, _)| !region.fits(*r)) {
            self.err(
                p,
                format!(
                    "too small for particles of type \"{}\" (bounding diameter up to {:.4e} m)",
                    t.name,
                    2.0 * r
                ),
            );
        }
        region
    }
}
