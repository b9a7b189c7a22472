//! Checkpoints (docs/design.md §8): everything a run needs to continue bitwise as if never stopped.
//!
//! Binary format, all integers and floats little-endian, floats as their raw bits:
//!
//! ```text
//! "PDMCKPT1"            magic, 8 bytes
//! version: u32          FORMAT_VERSION
//! payload_len: u64      bytes of payload
//! payload:
//!   step u64, time f64, next_id u64, scene_hash u64, rng_state 4×u64
//!   n u64; then per field, all particles: id u64, kind u32, scale f64, position 3×f64,
//!     velocity 3×f64, orientation 4×f64 (nalgebra storage order i, j, k, w; not renormalised),
//!     angular_velocity 3×f64, force 3×f64, torque 3×f64, mass f64, inertia 3×f64
//!   contacts u64; per contact: a u64, b u64, spring 3×f64, approach_speed f64, twist f64
//!     (sorted by key; version 1 has the spring only, read with the other two 0; before
//!     version 3 spring and twist were stretches, read as 0: the energy-scaled states
//!     `√k ξ` of the current friction cannot be made from them)
//!   inserter: len u64, bytes
//!   extra: count u64; per entry: name len u64, UTF-8 name, data len u64, bytes
//! checksum: u64         FNV-1a 64 of everything before it
//! ```
//!
//! Written whole to `<path>.tmp-<pid>`, fsynced and renamed over `path` ([`super::write_atomic`]),
//! so a run killed while writing leaves the previous checkpoint intact.
//!
//! Reading checks the layout, then every field ([`Checkpoint::validate`]): a sound checksum
//! only proves that the bytes are those written. What needs the scene (particle kinds, masses,
//! the time step, the scene's identity) is checked by [`crate::scene::restart`].

use crate::contact::history::{ContactHistory, ContactKey, ContactState};
use crate::state::Particles;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};

/// First bytes of every checkpoint file.
pub const MAGIC: &[u8; 8] = b"PDMCKPT1";
/// Version of the layout above; bump it when the payload changes.
pub const FORMAT_VERSION: u32 = 3;
/// The oldest version this build still reads.
pub const OLDEST_VERSION: u32 = 1;
const HEADER_LEN: usize = 8 + 4 + 8;

/// The complete restartable state of one rank.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// Steps completed.
    pub step: u64,
    /// Simulated time after `step` steps.
    pub time: f64,
    /// Every particle field.
    pub particles: Particles,
    /// Live contacts with their tangential springs.
    pub history: ContactHistory,
    /// State of the random generator (xoshiro256 words).
    pub rng_state: [u64; 4],
    /// The scene inserter's state, serialized by the caller (opaque here).
    pub inserter: Vec<u8>,
    /// Next global id to hand out.
    pub next_id: u64,
    /// Hash of the scene, to refuse restarting another scene ([`Checkpoint::check_scene`]).
    pub scene_hash: u64,
    /// Named state of later stages (wall positions, timers), opaque here.
    pub extra: Vec<(String, Vec<u8>)>,
}

/// Why a checkpoint could not be written or read; every message names the file.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("checkpoint {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("checkpoint {path}: not a polydem checkpoint (the file does not start with PDMCKPT1)")]
    BadMagic { path: PathBuf },
    #[error("checkpoint {path}: format version {found}, this build reads versions 1 to {expected}")]
    Version {
        path: PathBuf,
        found: u32,
        expected: u32,
    },
    #[error("checkpoint {path}: truncated: {what}")]
    Truncated { path: PathBuf, what: String },
    #[error(
        "checkpoint {path}: checksum mismatch (stored {stored:016x}, computed {computed:016x}): \
         the file is corrupted"
    )]
    Checksum {
        path: PathBuf,
        stored: u64,
        computed: u64,
    },
    #[error("checkpoint {path}: {what}")]
    Corrupt { path: PathBuf, what: String },
    #[error(
        "checkpoint {path}: written for another scene (scene hash {found:016x}, this scene \
         {expected:016x})"
    )]
    SceneMismatch {
        path: PathBuf,
        found: u64,
        expected: u64,
    },
}

impl Checkpoint {
    /// Errors unless the checkpoint was written for the scene whose hash is `expected`.
    pub fn check_scene(&self, expected: u64, path: &Path) -> Result<(), CheckpointError> {
        if self.scene_hash == expected {
            Ok(())
        } else {
            Err(CheckpointError::SceneMismatch {
                path: path.to_path_buf(),
                found: self.scene_hash,
                expected,
            })
        }
    }
}

/// FNV-1a, 64 bit: cheap, dependency-free, and enough to catch truncation and bit rot (this is
/// not protection against deliberate tampering).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The file's bytes (layout in the module docs). Errors name `path` when the particle arrays
/// have different lengths.
pub fn encode_checkpoint(c: &Checkpoint, path: &Path) -> Result<Vec<u8>, CheckpointError> {
    let p = &c.particles;
    let n = super::particle_count(p).map_err(|what| CheckpointError::Corrupt {
        path: path.to_path_buf(),
        what,
    })?;
    let mut b = Vec::with_capacity(HEADER_LEN + 64 + n * 260 + c.history.len() * 40);
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    b.extend_from_slice(&0u64.to_le_bytes()); // payload length, patched below
    let u = |b: &mut Vec<u8>, v: u64| b.extend_from_slice(&v.to_le_bytes());
    let f = |b: &mut Vec<u8>, v: f64| b.extend_from_slice(&v.to_bits().to_le_bytes());
    let v3 = |b: &mut Vec<u8>, a: &[Vector3<f64>]| {
        for v in a {
            for x in [v.x, v.y, v.z] {
                b.extend_from_slice(&x.to_bits().to_le_bytes());
            }
        }
    };
    u(&mut b, c.step);
    f(&mut b, c.time);
    u(&mut b, c.next_id);
    u(&mut b, c.scene_hash);
    c.rng_state.iter().for_each(|&w| u(&mut b, w));
    u(&mut b, n as u64);
    p.id.iter().for_each(|&x| u(&mut b, x));
    p.kind
        .iter()
        .for_each(|&k| b.extend_from_slice(&k.to_le_bytes()));
    p.scale.iter().for_each(|&x| f(&mut b, x));
    v3(&mut b, &p.position);
    v3(&mut b, &p.velocity);
    for q in &p.orientation {
        q.coords.iter().for_each(|&x| f(&mut b, x));
    }
    v3(&mut b, &p.angular_velocity);
    v3(&mut b, &p.force);
    v3(&mut b, &p.torque);
    p.mass.iter().for_each(|&x| f(&mut b, x));
    v3(&mut b, &p.inertia);
    u(&mut b, c.history.len() as u64);
    for (k, s) in c.history.entries() {
        u(&mut b, k.a);
        u(&mut b, k.b);
        v3(&mut b, std::slice::from_ref(&s.spring));
        f(&mut b, s.approach_speed);
        f(&mut b, s.twist);
    }
    u(&mut b, c.inserter.len() as u64);
    b.extend_from_slice(&c.inserter);
    u(&mut b, c.extra.len() as u64);
    for (name, data) in &c.extra {
        u(&mut b, name.len() as u64);
        b.extend_from_slice(name.as_bytes());
        u(&mut b, data.len() as u64);
        b.extend_from_slice(data);
    }
    let payload_len = (b.len() - HEADER_LEN) as u64;
    b[12..20].copy_from_slice(&payload_len.to_le_bytes());
    let sum = fnv1a64(&b);
    b.extend_from_slice(&sum.to_le_bytes());
    Ok(b)
}

/// Writes `c` to `path` atomically (temporary file, fsync, rename, fsync of the directory).
pub fn write_checkpoint(path: &Path, c: &Checkpoint) -> Result<(), CheckpointError> {
    let bytes = encode_checkpoint(c, path)?;
    super::write_atomic(path, &bytes).map_err(|source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads the checkpoint at `path`, verifying magic, version, length and checksum first.
pub fn read_checkpoint(path: &Path) -> Result<Checkpoint, CheckpointError> {
    let bytes = std::fs::read(path).map_err(|source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    decode_checkpoint(&bytes, path)
}

/// Decodes checkpoint bytes; `path` only names the source in errors. Never panics.
pub fn decode_checkpoint(bytes: &[u8], path: &Path) -> Result<Checkpoint, CheckpointError> {
    let path_buf = || path.to_path_buf();
    let truncated = |what: String| CheckpointError::Truncated {
        path: path_buf(),
        what,
    };
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err(CheckpointError::BadMagic { path: path_buf() });
    }
    if bytes.len() < HEADER_LEN {
        return Err(truncated(format!(
            "{} bytes, shorter than the header",
            bytes.len()
        )));
    }
    let found = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    if !(OLDEST_VERSION..=FORMAT_VERSION).contains(&found) {
        return Err(CheckpointError::Version {
            path: path_buf(),
            found,
            expected: FORMAT_VERSION,
        });
    }
    let mut len8 = [0u8; 8];
    len8.copy_from_slice(&bytes[12..20]);
    let payload_len = u64::from_le_bytes(len8);
    let expected_total = (HEADER_LEN as u64)
        .checked_add(payload_len)
        .and_then(|x| x.checked_add(8));
    match expected_total {
        Some(t) if t == bytes.len() as u64 => {}
        Some(t) if t > bytes.len() as u64 => {
            return Err(truncated(format!(
                "{} bytes, the header announces {t}",
                bytes.len()
            )));
        }
        _ => {
            return Err(CheckpointError::Corrupt {
                path: path_buf(),
                what: format!(
                    "{} bytes, but the header announces a payload of {payload_len} bytes",
                    bytes.len()
                ),
            });
        }
    }
    let body_end = bytes.len() - 8;
    let mut sum8 = [0u8; 8];
    sum8.copy_from_slice(&bytes[body_end..]);
    let stored = u64::from_le_bytes(sum8);
    let computed = fnv1a64(&bytes[..body_end]);
    if stored != computed {
        return Err(CheckpointError::Checksum {
            path: path_buf(),
            stored,
            computed,
        });
    }
    let mut r = Reader {
        b: &bytes[HEADER_LEN..body_end],
        at: 0,
    };
    let c = decode_payload(&mut r, found).map_err(|what| match what {
        ReadFail::Short(what) => truncated(what),
        ReadFail::Bad(what) => CheckpointError::Corrupt {
            path: path_buf(),
            what,
        },
    })?;
    c.validate().map_err(|what| CheckpointError::Corrupt {
        path: path_buf(),
        what,
    })?;
    Ok(c)
}

/// Largest departure of a stored orientation's norm from 1: the integrator renormalises every
/// step, so a sound checkpoint is within round-off of it.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-6;

impl Checkpoint {
    /// Checks every field that does not need the scene: the time is finite, non-negative and
    /// zero exactly at step 0; every particle float is finite; scale, mass and inertia are
    /// positive; orientations have unit norm (within [`QUATERNION_NORM_TOLERANCE`]); ids are
    /// unique and below `next_id`; contact springs are finite. A checksum only proves that the
    /// file is the one written, not that what was written is a state that can be stepped, so
    /// [`decode_checkpoint`] runs this on every read. The message names the field and the
    /// first particle (index and id) or contact at fault, and what is allowed.
    pub fn validate(&self) -> Result<(), String> {
        let p = &self.particles;
        let n = super::particle_count(p)?;
        if !self.time.is_finite() || self.time < 0.0 {
            return Err(format!("`time` is {}, must be finite and >= 0", self.time));
        }
        if (self.step == 0) != (self.time == 0.0) {
            return Err(format!(
                "`step` {} and `time` {} disagree: the time is 0 exactly at step 0",
                self.step, self.time
            ));
        }
        let mut ids = std::collections::HashSet::with_capacity(n);
        for i in 0..n {
            let id = p.id[i];
            let at =
                |field: &str, what: String| format!("particle {i} (id {id}): `{field}` {what}");
            if id >= self.next_id {
                return Err(at(
                    "id",
                    format!("is not below `next_id` = {}", self.next_id),
                ));
            }
            if !ids.insert(id) {
                return Err(at("id", "appears twice; ids must be unique".into()));
            }
            let positive = |field: &str, x: f64| {
                if x.is_finite() && x > 0.0 {
                    Ok(())
                } else {
                    Err(at(field, format!("is {x}, must be finite and > 0")))
                }
            };
            positive("scale", p.scale[i])?;
            positive("mass", p.mass[i])?;
            for x in p.inertia[i].iter() {
                positive("inertia", *x)?;
            }
            for (field, v) in [
                ("position", &p.position[i]),
                ("velocity", &p.velocity[i]),
                ("angular_velocity", &p.angular_velocity[i]),
                ("force", &p.force[i]),
                ("torque", &p.torque[i]),
            ] {
                if !v.iter().all(|x| x.is_finite()) {
                    return Err(at(
                        field,
                        format!("is [{}, {}, {}], must be finite", v.x, v.y, v.z),
                    ));
                }
            }
            let q = p.orientation[i].quaternion();
            let norm = q.norm();
            if !(norm.is_finite() && (norm - 1.0).abs() <= QUATERNION_NORM_TOLERANCE) {
                return Err(at(
                    "orientation",
                    format!(
                        "is (w {}, i {}, j {}, k {}) of norm {norm}, must be a unit quaternion \
                         (norm within {QUATERNION_NORM_TOLERANCE} of 1)",
                        q.w, q.i, q.j, q.k
                    ),
                ));
            }
        }
        for (k, s) in self.history.entries() {
            let finite = s.spring.iter().all(|x| x.is_finite())
                && s.approach_speed.is_finite()
                && s.twist.is_finite();
            if !finite {
                return Err(format!(
                    "contact ({}, {}): spring, approach speed or twist is not finite",
                    k.a, k.b
                ));
            }
        }
        Ok(())
    }
}

enum ReadFail {
    Short(String),
    Bad(String),
}

/// A bounds-checked little-endian cursor: every read says what it was reading when it runs out.
struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ReadFail> {
        match self.at.checked_add(n) {
            Some(end) if end <= self.b.len() => {
                let s = &self.b[self.at..end];
                self.at = end;
                Ok(s)
            }
            _ => Err(ReadFail::Short(format!(
                "payload ends at byte {} while reading {what} ({n} bytes)",
                self.b.len()
            ))),
        }
    }
    fn u64(&mut self, what: &str) -> Result<u64, ReadFail> {
        let mut a = [0u8; 8];
        a.copy_from_slice(self.take(8, what)?);
        Ok(u64::from_le_bytes(a))
    }
    fn f64(&mut self, what: &str) -> Result<f64, ReadFail> {
        self.u64(what).map(f64::from_bits)
    }
    fn u32(&mut self, what: &str) -> Result<u32, ReadFail> {
        let mut a = [0u8; 4];
        a.copy_from_slice(self.take(4, what)?);
        Ok(u32::from_le_bytes(a))
    }
    fn v3(&mut self, what: &str) -> Result<Vector3<f64>, ReadFail> {
        Ok(Vector3::new(
            self.f64(what)?,
            self.f64(what)?,
            self.f64(what)?,
        ))
    }
    /// A count of items of `item_bytes` each, checked against what is left so that a corrupt
    /// count cannot request a huge allocation.
    fn count(&mut self, item_bytes: usize, what: &str) -> Result<usize, ReadFail> {
        let n = self.u64(what)?;
        let left = (self.b.len() - self.at) as u64;
        if n.checked_mul(item_bytes.max(1) as u64)
            .is_none_or(|t| t > left)
        {
            return Err(ReadFail::Short(format!(
                "{what} is {n}, more than the {left} bytes left hold"
            )));
        }
        Ok(n as usize)
    }
    fn vec<T>(
        &mut self,
        n: usize,
        what: &str,
        mut f: impl FnMut(&mut Self, &str) -> Result<T, ReadFail>,
    ) -> Result<Vec<T>, ReadFail> {
        (0..n).map(|_| f(self, what)).collect()
    }
}

fn decode_payload(r: &mut Reader, version: u32) -> Result<Checkpoint, ReadFail> {
    let step = r.u64("step")?;
    let time = r.f64("time")?;
    let next_id = r.u64("next_id")?;
    let scene_hash = r.u64("scene_hash")?;
    let mut rng_state = [0u64; 4];
    for w in &mut rng_state {
        *w = r.u64("rng_state")?;
    }
    // Smallest per-particle record: 8+4+8+24·6+32+8 bytes.
    let n = r.count(204, "particle count")?;
    let v3 = |r: &mut Reader, w: &str| r.v3(w);
    let mut particles = Particles {
        id: r.vec(n, "id", |r, w| r.u64(w))?,
        kind: r.vec(n, "kind", |r, w| r.u32(w))?,
        scale: r.vec(n, "scale", |r, w| r.f64(w))?,
        position: r.vec(n, "position", v3)?,
        velocity: r.vec(n, "velocity", v3)?,
        // Stored coordinates, not renormalised: the restart must see the same bits.
        orientation: r.vec(n, "orientation", |r, w| {
            let (i, j, k, s) = (r.f64(w)?, r.f64(w)?, r.f64(w)?, r.f64(w)?);
            Ok(UnitQuaternion::new_unchecked(Quaternion::new(s, i, j, k)))
        })?,
        angular_velocity: r.vec(n, "angular_velocity", v3)?,
        force: r.vec(n, "force", v3)?,
        torque: r.vec(n, "torque", v3)?,
        mass: r.vec(n, "mass", |r, w| r.f64(w))?,
        inertia: r.vec(n, "inertia", v3)?,
        contacts: Vec::new(),
    };
    let per_contact = if version >= 2 { 56 } else { 40 };
    let m = r.count(per_contact, "contact count")?;
    let entries = r.vec(m, "contact", |r, w| {
        let key = ContactKey {
            a: r.u64(w)?,
            b: r.u64(w)?,
        };
        let spring = r.v3(w)?;
        let (approach_speed, twist) = if version >= 2 {
            (r.f64(w)?, r.f64(w)?)
        } else {
            (0.0, 0.0)
        };
        // Before version 3 the springs held stretches (m, rad) of a law whose friction could
        // store energy no motion put in; the energy-scaled state of the current law
        // (`contact::friction::stretch`) cannot be made from them without the contact's area,
        // so they start unstretched: the lock re-forms a sticking contact's spring within a
        // few steps.
        let (spring, twist) = if version >= 3 {
            (spring, twist)
        } else {
            (Vector3::zeros(), 0.0)
        };
        let state = ContactState {
            spring,
            approach_speed,
            twist,
        };
        Ok((key, state))
    })?;
    if entries.windows(2).any(|e| e[0].0 >= e[1].0) {
        return Err(ReadFail::Bad("contact history is not sorted by key".into()));
    }
    let history = ContactHistory::from_entries(entries);
    particles.count_contacts(&history);
    let len = r.count(1, "inserter length")?;
    let inserter = r.take(len, "inserter state")?.to_vec();
    let count = r.count(16, "extra entry count")?;
    let mut extra = Vec::with_capacity(count);
    for _ in 0..count {
        let len = r.count(1, "extra name length")?;
        let name = std::str::from_utf8(r.take(len, "extra name")?)
            .map_err(|_| ReadFail::Bad("an extra entry's name is not UTF-8".into()))?
            .to_string();
        let len = r.count(1, "extra data length")?;
        extra.push((name, r.take(len, "extra data")?.to_vec()));
    }
    if r.at != r.b.len() {
        return Err(ReadFail::Bad(format!(
            "{} bytes left after the last field",
            r.b.len() - r.at
        )));
    }
    Ok(Checkpoint {
        step,
        time,
        particles,
        history,
        rng_state,
        inserter,
        next_id,
        scene_hash,
        extra,
    })
}
