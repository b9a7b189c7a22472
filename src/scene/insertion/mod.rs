//! Particle insertion: regions, scale distributions, and the [`Inserter`] that places particles
//! at the start (count) or continuously (rate), never overlapping what is already there.
//!
//! Overlap is tested with bounding spheres (circumscribed radius × scale), which is conservative:
//! a placed particle touches no other particle and no wall triangle. Every random choice comes
//! from one [`Rng`] seeded by `simulation.seed`, drawn in a fixed order (insertion by insertion,
//! particle by particle: scale, orientation, then positions), and its state is part of
//! [`InserterState`], so a restart continues the exact same sequence.
//!
//! This file holds the resolved insertion types and the inserter's state; `region` the
//! insertion regions and their validation, `inserter` the scheduling (what is due when, restore
//! from a checkpoint), and `placement` how one particle is drawn and placed.

mod inserter;
mod placement;
mod region;

pub use region::{Region, cylinder_frame, cylinder_sites};

use crate::io::Packing;
use crate::rng::Rng;
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Default number of random positions tried per particle.
pub const DEFAULT_MAX_ATTEMPTS: u32 = 1000;

/// When particles are inserted.
#[derive(Clone, Debug, PartialEq)]
pub enum InsertionMode {
    /// This many particles, all at the first [`Inserter::insert`] call.
    Count(u64),
    /// Continuous feeding: `floor((min(t, end) − start) · per_second)` particles are due by
    /// time t, at most `total`; with an `interval`, placed in batches at the steps that cross
    /// its multiples (those due since the last batch, and any that found no place then)
    /// rather than each in the step it falls due.
    Rate {
        per_second: f64,
        start: f64,
        end: Option<f64>,
        total: Option<u64>,
        interval: Option<f64>,
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
    /// Index into [`Scene::particle_types`](super::Scene::particle_types).
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
    /// region, x fastest, then y, then z (count only); in a cylinder region, the sites whose
    /// centre lies inside the cylinder, bottom up ([`cylinder_sites`]). No overlap
    /// test: the spacing decides, so a lattice can start as a dense packing in contact
    /// (benchmarks, compaction).
    pub lattice: Option<Vector3<f64>>,
    /// A frozen packing tiled over the box region (count only): particle `j` is particle
    /// `j mod n` of the cell in tile `j div n` (x fastest), with the cell's orientation and
    /// scale; in a cylinder region, the tiles' particles whose bounding sphere lies inside it,
    /// bottom up ([`TiledPacking::in_cylinder`]). No overlap test and no random draw: the
    /// packing decides.
    pub packing: Option<TiledPacking>,
    /// Particles of another run's checkpoint, those with their centre inside the region,
    /// placed as they were (count only): a state filled once and reused, e.g. a silo filled
    /// and then discharged through outlets of several sizes.
    pub state: Option<ImportedState>,
}

/// One particle of an [`ImportedState`] as the checkpoint holds it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImportedBody {
    pub position: Vector3<f64>,
    pub orientation: UnitQuaternion<f64>,
    pub velocity: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
    pub scale: f64,
}

/// The particles an insertion takes from a checkpoint (`[[insertions]] state`).
#[derive(Clone, PartialEq)]
pub struct ImportedState {
    /// The checkpoint it was read from.
    pub file: std::path::PathBuf,
    /// Its particles inside the region, in the checkpoint's order.
    pub bodies: std::sync::Arc<Vec<ImportedBody>>,
}

/// The particles' count and a hash of every value, not the path: the restart fingerprint
/// hashes this text, so a changed checkpoint is another scene while a moved one is not.
impl std::fmt::Debug for ImportedState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // FNV-1a over the bits of every value, in order.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |x: f64| {
            for b in x.to_bits().to_le_bytes() {
                h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
            }
        };
        for b in self.bodies.iter() {
            let q = b.orientation.quaternion();
            for x in [
                b.position.x,
                b.position.y,
                b.position.z,
                q.w,
                q.i,
                q.j,
                q.k,
                b.velocity.x,
                b.velocity.y,
                b.velocity.z,
                b.angular_velocity.x,
                b.angular_velocity.y,
                b.angular_velocity.z,
                b.scale,
            ] {
                eat(x);
            }
        }
        f.debug_struct("ImportedState")
            .field("bodies", &self.bodies.len())
            .field("hash", &h)
            .finish()
    }
}

/// A [`Packing`] and how many times its cell repeats along x, y and z to fill a box region.
#[derive(Clone, PartialEq)]
pub struct TiledPacking {
    /// The file it was read from.
    pub file: std::path::PathBuf,
    /// The cell's particles.
    pub packing: std::sync::Arc<Packing>,
    /// Copies of the cell along x, y and z.
    pub tiles: [u64; 3],
}

/// The packing's contents and the tiling, not the file's path: the restart fingerprint hashes
/// this text ([`crate::scene::restart::SceneFingerprint`]), and a run restarted from another directory,
/// or with the scene given by another path, reads the same packing.
impl std::fmt::Debug for TiledPacking {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TiledPacking")
            .field("packing", &self.packing)
            .field("tiles", &self.tiles)
            .finish()
    }
}

impl TiledPacking {
    /// Particles of the whole tiling.
    pub fn count(&self) -> u64 {
        self.tiles.iter().product::<u64>() * self.packing.particles.len() as u64
    }

    /// Particle `j` of the tiling placed in the box whose lower corner is `min`: its centre,
    /// orientation and scale.
    pub fn particle(&self, j: u64, min: &Vector3<f64>) -> (Vector3<f64>, UnitQuaternion<f64>, f64) {
        let n = self.packing.particles.len() as u64;
        let (tile, k) = (j / n, (j % n) as usize);
        let t = [
            tile % self.tiles[0],
            (tile / self.tiles[0]) % self.tiles[1],
            tile / (self.tiles[0] * self.tiles[1]),
        ];
        let p = &self.packing.particles[k];
        let c =
            Vector3::from_fn(|a, _| min[a] + self.packing.cell[a] * t[a] as f64 + p.position[a]);
        (c, p.orientation, p.scale)
    }

    /// The tiling of a cylinder region: the cell repeated over the square prism around it in
    /// its [`cylinder_frame`] (`self.tiles` copies from its corner `(−radius, −radius,
    /// 0)`), turned into the world by that frame, keeping the particles whose bounding sphere
    /// (radius `bound × scale`) lies inside the cylinder; tile by tile bottom up, each tile's
    /// particles in the file's order.
    pub fn in_cylinder(
        &self,
        base: &Vector3<f64>,
        axis: &Vector3<f64>,
        radius: f64,
        height: f64,
        bound: f64,
    ) -> Vec<(Vector3<f64>, UnitQuaternion<f64>, f64)> {
        let f = cylinder_frame(axis);
        let q = UnitQuaternion::from_rotation_matrix(&f);
        let corner = Vector3::new(-radius, -radius, 0.0);
        let mut out = Vec::new();
        for j in 0..self.count() {
            let (l, o, s) = self.particle(j, &corner);
            let r = bound * s;
            if l.xy().norm() <= radius - r && l.z >= r && l.z <= height - r {
                out.push((base + f * l, q * o, s));
            }
        }
        out
    }
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
                ..
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
    /// The time step (from the scene, not checkpointed): batches of a rate insertion with an
    /// `interval` go at the steps that cross its multiples.
    dt: f64,
}
