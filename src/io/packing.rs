//! A frozen packing: the particles of one periodic cell, written by `polydem pack` and read by
//! insertions that tile it (`[[insertions]] packing = "…"`, docs/scene.md).
//!
//! The format is text, one particle per line, so that a committed packing diffs and can be read
//! by any tool:
//!
//! ```text
//! # polydem packing 1
//! # free comment lines (how it was made)
//! cell 0.0161 0.0161 0.0161
//! particles 4000
//! x y z qw qx qy qz scale
//! …
//! ```
//!
//! `cell` is the edge lengths of the periodic box, which spans `[0, L)` on each axis; each line
//! gives a particle's centre (m, inside the cell), its orientation (body → world, a unit
//! quaternion, renormalised on read) and its scale. Positions and quaternions are written with
//! 12 significant digits: a packing is a starting state, not a bitwise snapshot (that is what a
//! checkpoint is), and 12 digits resolve a cell of 10^4 particles to about 1e-10 of a diameter.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::fmt::Write as _;
use std::path::Path;

/// First line of every packing file.
pub const HEADER: &str = "# polydem packing 1";

/// One particle of a [`Packing`].
#[derive(Clone, Debug, PartialEq)]
pub struct PackedParticle {
    /// Centre inside the cell (m).
    pub position: Vector3<f64>,
    /// Body → world rotation.
    pub orientation: UnitQuaternion<f64>,
    /// Scale applied to the particle type's template.
    pub scale: f64,
}

/// The particles of one periodic cell `[0, cell)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Packing {
    /// Edge lengths of the cell (m).
    pub cell: Vector3<f64>,
    /// The particles, in file order.
    pub particles: Vec<PackedParticle>,
}

/// Why a packing file could not be read or written; every message names the file and, for a
/// bad line, its number.
#[derive(Debug, thiserror::Error)]
pub enum PackingError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Format {
        path: String,
        line: usize,
        message: String,
    },
}

impl Packing {
    /// The packing as text (see the module docs), with `comments` as `#` lines after the header.
    pub fn to_text(&self, comments: &[String]) -> String {
        let mut s = String::with_capacity(96 * self.particles.len() + 256);
        let _ = writeln!(s, "{HEADER}");
        for c in comments {
            for line in c.lines() {
                let _ = writeln!(s, "# {line}");
            }
        }
        let _ = writeln!(
            s,
            "cell {:e} {:e} {:e}",
            self.cell.x, self.cell.y, self.cell.z
        );
        let _ = writeln!(s, "particles {}", self.particles.len());
        for p in &self.particles {
            let q = p.orientation.quaternion();
            let _ = writeln!(
                s,
                "{:.11e} {:.11e} {:.11e} {:.11e} {:.11e} {:.11e} {:.11e} {:e}",
                p.position.x, p.position.y, p.position.z, q.w, q.i, q.j, q.k, p.scale
            );
        }
        s
    }

    /// Writes the packing atomically (a temporary file renamed over `path`).
    pub fn write(&self, path: &Path, comments: &[String]) -> Result<(), PackingError> {
        super::write_atomic(path, self.to_text(comments).as_bytes()).map_err(|source| {
            PackingError::Io {
                path: path.display().to_string(),
                source,
            }
        })
    }

    /// Reads a packing file.
    pub fn read(path: &Path) -> Result<Self, PackingError> {
        let text = crate::input::read_bounded_text(path, crate::input::InputKind::Packing)
            .map_err(|source| PackingError::Io {
                path: path.display().to_string(),
                source,
            })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses packing text; `path` names it in errors. Every value is checked: a finite
    /// positive cell, the stated particle count, centres inside the cell, non-zero quaternions
    /// and finite positive scales.
    pub fn parse(text: &str, path: &str) -> Result<Self, PackingError> {
        let err = |line: usize, message: String| PackingError::Format {
            path: path.to_string(),
            line,
            message,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty());
        match lines.next() {
            Some((_, l)) if l == HEADER => {}
            Some((n, l)) => {
                return Err(err(
                    n,
                    format!("expected the header \"{HEADER}\", found \"{l}\""),
                ));
            }
            None => return Err(err(1, "empty file, not a polydem packing".into())),
        }
        let mut lines = lines.filter(|(_, l)| !l.starts_with('#'));
        let numbers =
            |n: usize, l: &str, key: &str, want: usize| -> Result<Vec<f64>, PackingError> {
                let rest = if key.is_empty() {
                    l
                } else {
                    l.strip_prefix(key)
                        .ok_or_else(|| err(n, format!("expected \"{key} …\", found \"{l}\"")))?
                };
                let v: Vec<f64> = rest
                    .split_whitespace()
                    .map(|w| {
                        w.parse::<f64>()
                            .map_err(|_| err(n, format!("\"{w}\" is not a number")))
                    })
                    .collect::<Result<_, _>>()?;
                if v.len() != want {
                    return Err(err(
                        n,
                        format!("expected {want} numbers, found {}", v.len()),
                    ));
                }
                if let Some(x) = v.iter().find(|x| !x.is_finite()) {
                    return Err(err(n, format!("{x} is not finite")));
                }
                Ok(v)
            };
        let (n, l) = lines
            .next()
            .ok_or_else(|| err(2, "missing the \"cell Lx Ly Lz\" line".into()))?;
        let c = numbers(n, l, "cell", 3)?;
        if c.iter().any(|&x| x <= 0.0) {
            return Err(err(n, format!("cell edges must be positive, got {c:?}")));
        }
        let cell = Vector3::new(c[0], c[1], c[2]);
        let (n, l) = lines
            .next()
            .ok_or_else(|| err(n + 1, "missing the \"particles N\" line".into()))?;
        let count: usize = l
            .strip_prefix("particles")
            .and_then(|w| w.trim().parse().ok())
            .filter(|&c| c > 0)
            .ok_or_else(|| {
                err(
                    n,
                    format!("expected \"particles N\" with N ≥ 1, found \"{l}\""),
                )
            })?;
        let mut particles = Vec::with_capacity(count);
        for (n, l) in lines {
            if particles.len() == count {
                return Err(err(
                    n,
                    format!("more particle lines than the {count} the file states"),
                ));
            }
            let v = numbers(n, l, "", 8)?;
            let position = Vector3::new(v[0], v[1], v[2]);
            if (0..3).any(|a| !(0.0..cell[a]).contains(&position[a])) {
                return Err(err(
                    n,
                    format!("centre {position:?} lies outside the cell [0, {cell:?})"),
                ));
            }
            let q = Quaternion::new(v[3], v[4], v[5], v[6]);
            if q.norm() < 0.5 {
                return Err(err(
                    n,
                    format!("orientation {:?} is not a unit quaternion", &v[3..7]),
                ));
            }
            if v[7] <= 0.0 {
                return Err(err(n, format!("scale must be positive, got {}", v[7])));
            }
            particles.push(PackedParticle {
                position,
                orientation: UnitQuaternion::from_quaternion(q),
                scale: v[7],
            });
        }
        if particles.len() != count {
            return Err(err(
                text.lines().count(),
                format!(
                    "the file states {count} particles but holds {}",
                    particles.len()
                ),
            ));
        }
        Ok(Packing { cell, particles })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Packing {
        Packing {
            cell: Vector3::new(0.01, 0.02, 0.03),
            particles: vec![
                PackedParticle {
                    position: Vector3::new(0.001, 0.019, 0.0),
                    orientation: UnitQuaternion::from_euler_angles(0.3, -1.2, 2.0),
                    scale: 0.001,
                },
                PackedParticle {
                    position: Vector3::new(0.0099, 0.0, 0.02999),
                    orientation: UnitQuaternion::identity(),
                    scale: 0.001,
                },
            ],
        }
    }

    #[test]
    fn text_round_trip_keeps_twelve_digits() {
        let p = sample();
        let back = Packing::parse(&p.to_text(&["made by a test".into()]), "t").unwrap();
        assert_eq!(back.cell, p.cell);
        for (a, b) in p.particles.iter().zip(&back.particles) {
            assert!((a.position - b.position).norm() <= 1e-12 * 0.03);
            assert!(a.orientation.angle_to(&b.orientation) <= 1e-10);
            assert_eq!(a.scale, b.scale);
        }
    }

    #[test]
    fn bad_files_name_the_line() {
        let good = sample().to_text(&[]);
        let cases = [
            (
                good.replace(HEADER, "# something else"),
                ":1: expected the header",
            ),
            (
                good.replace("particles 2", "particles 3"),
                "states 3 particles but holds 2",
            ),
            (
                good.replace("particles 2", "particles 1"),
                "more particle lines than the 1",
            ),
            (
                good.replace("cell 1e-2", "cell -1e-2"),
                ":2: cell edges must be positive",
            ),
            (
                good.replacen("1.00000000000e-3 1.90000000000e-2", "5.0e-2 1.9e-2", 1),
                ":4: centre",
            ),
            (
                good.replacen(" 1e-3\n", " 0e0\n", 1),
                ":4: scale must be positive",
            ),
            (
                good.replacen("1.00000000000e-3 ", "x ", 1),
                ":4: \"x\" is not a number",
            ),
        ];
        for (text, want) in cases {
            let e = Packing::parse(&text, "bed.packing")
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with("bed.packing:") && e.contains(want),
                "{e} (want {want})"
            );
        }
    }
}
