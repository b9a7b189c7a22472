//! Output and checkpoints (docs/design.md §8, stage 10 of §1).
//!
//! - [`vtk`]: hand-written VTK XML: per-rank `.vtu` pieces with one `VTK_POLYHEDRON` cell per
//!   particle, one `.pvtu` per frame, `frames.pvd` listing the frames with their times, and the
//!   walls as triangle meshes in their own `.vtu` files and `walls.pvd`.
//! - [`csv`]: per-frame particle tables and the time series of energies, contacts and wall forces.
//! - [`packing`]: a frozen periodic cell of particles (`polydem pack`), which insertions tile.
//! - [`checkpoint`]: a binary snapshot of every field, the contact history and the insertion and
//!   random state, from which a run continues bitwise as if never stopped.
//!
//! Every file that a reader may open while the run goes on (frames, collections, checkpoints) is
//! written whole to a temporary file beside it and renamed over the target, so a reader or a
//! restart never sees half a file; the time series is appended and flushed row by row instead.

pub mod checkpoint;
pub mod csv;
pub mod packing;
pub mod vtk;

pub use checkpoint::{
    Checkpoint, CheckpointError, decode_checkpoint, encode_checkpoint, read_checkpoint,
    write_checkpoint,
};
pub use csv::{ParticleRow, SeriesRow, SeriesWriter, read_particle_csv, write_particle_csv};
pub use packing::{PackedParticle, Packing, PackingError};
pub use vtk::{FRAME_FIELDS, FrameView, FrameWriter, WallView};

use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// The temporary name that [`write_atomic`] writes to before renaming: `<path>.tmp-<pid>`, so
/// two processes (ranks) never share one, and a leftover from a killed run is recognisable.
pub fn temporary_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_os_string();
    name.push(format!(".tmp-{}", std::process::id()));
    PathBuf::from(name)
}

/// Whether `name` is a temporary name of [`temporary_path`]: `<name>.tmp-<digits>`.
pub fn is_temporary_name(name: &str) -> bool {
    name.rsplit_once(".tmp-").is_some_and(|(stem, pid)| {
        !stem.is_empty() && !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit())
    })
}

/// Removes the temporary files ([`temporary_path`]) that killed writes left in `dir` and the
/// folders below it, and returns their paths. Only names of that exact pattern are touched;
/// symbolic links are neither removed nor followed. Meant for the start of a run, before it
/// writes anything: a folder that another running process writes to would lose its files in
/// progress.
pub fn remove_temporary_files(dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut removed = Vec::new();
    let mut dirs = vec![dir.to_path_buf()];
    while let Some(d) = dirs.pop() {
        let entries = match fs::read_dir(&d) {
            Ok(e) => e,
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            Err(e) => return Err(with_path(e, &d)),
        };
        for entry in entries {
            let entry = entry.map_err(|e| with_path(e, &d))?;
            let kind = entry.file_type().map_err(|e| with_path(e, &entry.path()))?;
            let path = entry.path();
            if kind.is_dir() {
                dirs.push(path);
            } else if kind.is_file() && entry.file_name().to_str().is_some_and(is_temporary_name) {
                fs::remove_file(&path).map_err(|e| with_path(e, &path))?;
                removed.push(path);
            }
        }
    }
    removed.sort();
    Ok(removed)
}

/// Writes `bytes` to `path` atomically: to [`temporary_path`], fsync, rename over `path`, fsync
/// the directory (so the rename itself survives a crash). A reader sees the old file or the new
/// one, never a mixture; on error the temporary file is removed and `path` is untouched.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let tmp = temporary_path(path);
    let result = (|| {
        let mut f = File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)?;
        sync_parent(path)
    })();
    if result.is_err() {
        // Best effort: the error that matters is the one returned.
        let _ = fs::remove_file(&tmp);
    }
    result.map_err(|e| with_path(e, path))
}

/// fsyncs the directory holding `path` (on Unix a rename is durable only once its directory is).
fn sync_parent(path: &Path) -> io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    #[cfg(unix)]
    {
        File::open(dir)?.sync_all()
    }
    #[cfg(not(unix))]
    {
        let _ = dir; // directories cannot be opened for syncing there
        Ok(())
    }
}

/// The same error with the file named in its message (std's I/O errors do not name it).
pub(crate) fn with_path(e: io::Error, path: &Path) -> io::Error {
    io::Error::new(e.kind(), format!("{}: {e}", path.display()))
}

/// An `InvalidInput` error naming `path`.
pub(crate) fn invalid_input(path: &Path, message: impl std::fmt::Display) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{}: {message}", path.display()),
    )
}

/// An `InvalidData` error naming `path`.
pub(crate) fn invalid_data(path: &Path, message: impl std::fmt::Display) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        format!("{}: {message}", path.display()),
    )
}

/// Text for an f64 that parses back to the same bits (Rust prints the shortest round-trip
/// digits): plain decimals in the readable range, exponent form outside it so that 1e-300 is not
/// 300 zeros. NaN and infinities print as `NaN`, `inf`, `-inf`, which numpy and pandas read.
pub fn format_f64(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || (1e-5..1e16).contains(&a) || !x.is_finite() {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// Standard base64 (RFC 4648) with padding, appended to `out`.
pub(crate) fn base64(data: &[u8], out: &mut String) {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    out.reserve(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        out.push(A[(n >> 18) as usize & 63] as char);
        out.push(A[(n >> 12) as usize & 63] as char);
        out.push(if c.len() > 1 {
            A[(n >> 6) as usize & 63] as char
        } else {
            '='
        });
        out.push(if c.len() > 2 {
            A[n as usize & 63] as char
        } else {
            '='
        });
    }
}

/// Checks that the arrays of `p` all have the same length and returns it.
pub(crate) fn particle_count(p: &crate::state::Particles) -> Result<usize, String> {
    let n = p.id.len();
    let lens = [
        ("kind", p.kind.len()),
        ("scale", p.scale.len()),
        ("position", p.position.len()),
        ("velocity", p.velocity.len()),
        ("orientation", p.orientation.len()),
        ("angular_velocity", p.angular_velocity.len()),
        ("force", p.force.len()),
        ("torque", p.torque.len()),
        ("mass", p.mass.len()),
        ("inertia", p.inertia.len()),
    ];
    match lens.iter().find(|(_, l)| *l != n) {
        Some((name, l)) => Err(format!(
            "inconsistent particle arrays: {n} ids but {l} entries in `{name}`"
        )),
        None => Ok(n),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporary_names_are_ours_only() {
        assert!(is_temporary_name("series.csv.tmp-123"));
        assert!(is_temporary_name(
            &temporary_path(Path::new("latest.ckpt")).to_string_lossy()
        ));
        for other in ["a.tmp", "a.tmp-", "a.tmp-12x", ".tmp-12", "notes.tmp-draft"] {
            assert!(!is_temporary_name(other), "{other}");
        }
    }

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            let mut s = String::new();
            base64(i.as_bytes(), &mut s);
            assert_eq!(s, o);
        }
    }

    #[test]
    fn f64_text_round_trips() {
        for x in [
            0.0,
            -0.0,
            0.1,
            1.0 / 3.0,
            1e-300,
            5e-324,
            f64::MAX,
            -2.5e17,
            123456.789,
            f64::INFINITY,
        ] {
            let s = format_f64(x);
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits(), "{s}");
        }
        assert_eq!(format_f64(1e-300), "1e-300");
        assert_eq!(format_f64(0.25), "0.25");
    }
}
