//! CSV output (docs/design.md §8): per-frame particle tables and the time series of energies,
//! contact counts and wall forces.
//!
//! Numbers are written with the shortest digits that parse back to the same f64 bits
//! ([`super::format_f64`]), so a table read with numpy or pandas holds exactly the simulated
//! values. Plain RFC 4180 CSV: one header line, comma separated, `\n` line ends.

use super::{FrameView, format_f64, invalid_data, invalid_input, particle_count, with_path};
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// Header of a particle table. `time` repeats the frame time on every row so that tables of
/// several frames can be concatenated; the quaternion is body → world, scalar first.
pub const PARTICLE_CSV_HEADER: &str = "time,id,x,y,z,vx,vy,vz,wx,wy,wz,qw,qx,qy,qz";

/// Writes the particles of `view` (local order) as a CSV table at `time`, atomically.
pub fn write_particle_csv(path: &Path, time: f64, view: &FrameView) -> io::Result<()> {
    let p = view.particles;
    let n = particle_count(p).map_err(|m| invalid_input(path, m))?;
    let mut s = String::with_capacity(64 + 300 * n);
    s.push_str(PARTICLE_CSV_HEADER);
    s.push('\n');
    let t = format_f64(time);
    for i in 0..n {
        let q = p.orientation[i].quaternion();
        let (x, v, w) = (p.position[i], p.velocity[i], p.angular_velocity[i]);
        let _ = write!(s, "{t},{}", p.id[i]);
        for c in [
            x.x, x.y, x.z, v.x, v.y, v.z, w.x, w.y, w.z, q.w, q.i, q.j, q.k,
        ] {
            s.push(',');
            s.push_str(&format_f64(c));
        }
        s.push('\n');
    }
    super::write_atomic(path, s.as_bytes())
}

/// One row of a particle table ([`write_particle_csv`]): what frame analyses read back.
#[derive(Clone, Debug, PartialEq)]
pub struct ParticleRow {
    pub time: f64,
    pub id: u64,
    pub position: Vector3<f64>,
    pub velocity: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
}

/// Reads a particle table written by [`write_particle_csv`]. A file with another header, a
/// row of another width or a field that is not a finite number is an error naming the file,
/// the line and the field.
pub fn read_particle_csv(path: &Path) -> io::Result<Vec<ParticleRow>> {
    let text = fs::read_to_string(path).map_err(|e| with_path(e, path))?;
    let mut lines = text.lines();
    match lines.next() {
        Some(h) if h == PARTICLE_CSV_HEADER => {}
        h => {
            return Err(invalid_data(
                path,
                format!(
                    "line 1: header {:?}, expected {PARTICLE_CSV_HEADER:?} (a polydem particle table)",
                    h.unwrap_or("")
                ),
            ));
        }
    }
    let names: Vec<&str> = PARTICLE_CSV_HEADER.split(',').collect();
    let mut rows = Vec::new();
    for (k, line) in lines.enumerate() {
        let at = k + 2;
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != names.len() {
            return Err(invalid_data(
                path,
                format!(
                    "line {at}: {} fields, expected {}",
                    fields.len(),
                    names.len()
                ),
            ));
        }
        let id = fields[1].parse::<u64>().map_err(|_| {
            invalid_data(path, format!("line {at}: id {:?} is not an id", fields[1]))
        })?;
        let mut v = [0.0; 15];
        for (j, f) in fields.iter().enumerate() {
            if j == 1 {
                continue;
            }
            v[j] = f
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    invalid_data(
                        path,
                        format!("line {at}: {} {f:?} is not a finite number", names[j]),
                    )
                })?;
        }
        rows.push(ParticleRow {
            time: v[0],
            id,
            position: Vector3::new(v[2], v[3], v[4]),
            velocity: Vector3::new(v[5], v[6], v[7]),
            angular_velocity: Vector3::new(v[8], v[9], v[10]),
        });
    }
    Ok(rows)
}

/// One row of the time series.
#[derive(Clone, Debug, PartialEq)]
pub struct SeriesRow {
    pub step: u64,
    pub time: f64,
    /// Σ ½ m v².
    pub kinetic_translational: f64,
    /// Σ ½ ωᵀ I ω.
    pub kinetic_rotational: f64,
    /// Σ −m g·x.
    pub potential_gravity: f64,
    /// Elastic energy stored in the contacts.
    pub elastic: f64,
    /// Particle–particle contacts.
    pub contacts: u64,
    /// Particle–wall contacts.
    pub wall_contacts: u64,
    /// Total force on each wall, in the order of the writer's wall names.
    pub wall_forces: Vec<Vector3<f64>>,
}

/// Appends rows to a CSV time series: `step,time,kinetic_translational,kinetic_rotational,
/// potential_gravity,elastic,contacts,wall_contacts` then `<wall>_fx,<wall>_fy,<wall>_fz` per
/// wall. Every row is flushed to the file as it is appended, so a killed run loses no row it
/// reported.
pub struct SeriesWriter {
    path: PathBuf,
    walls: usize,
    out: BufWriter<File>,
}

impl SeriesWriter {
    /// Creates (or truncates) the file at `path` and writes the header.
    pub fn new(path: &Path, wall_names: &[String]) -> io::Result<Self> {
        let header = series_header(wall_names);
        super::write_atomic(path, header.as_bytes())?;
        Self::open_append(path, wall_names.len())
    }

    /// Continues the series of a run restarted at step `after_step`: keeps the header and the
    /// rows of steps up to `after_step`, each step once (an older build wrote a run's last row
    /// twice), drops the later ones (and a last row cut short by a kill), and appends from
    /// there. Rows are matched by step, an integer, not by time, whose printed digits the
    /// restart would have to reproduce. A missing file starts a new series; a file whose header
    /// does not match `wall_names` is an error (another scene's series).
    pub fn resume(path: &Path, wall_names: &[String], after_step: u64) -> io::Result<Self> {
        let text = match fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Self::new(path, wall_names),
            Err(e) => return Err(with_path(e, path)),
        };
        let header = series_header(wall_names);
        if !text.starts_with(&header) {
            return Err(invalid_data(
                path,
                format!(
                    "its header is not the one of this scene; expected `{}`",
                    header.trim_end()
                ),
            ));
        }
        let mut kept = header.clone();
        let mut last: Option<u64> = None;
        for (k, line) in text[header.len()..].split_inclusive('\n').enumerate() {
            if !line.ends_with('\n') {
                break; // a row cut short by a kill: the restart writes it again
            }
            let step = line
                .split(',')
                .next()
                .and_then(|t| t.trim().parse::<u64>().ok())
                .ok_or_else(|| invalid_data(path, format!("row {}: no step column", k + 1)))?;
            if step > after_step {
                break;
            }
            if last.is_some_and(|l| step <= l) {
                continue; // a repeated row
            }
            last = Some(step);
            kept.push_str(line);
        }
        super::write_atomic(path, kept.as_bytes())?;
        Self::open_append(path, wall_names.len())
    }

    fn open_append(path: &Path, walls: usize) -> io::Result<Self> {
        let f = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| with_path(e, path))?;
        Ok(SeriesWriter {
            path: path.to_path_buf(),
            walls,
            out: BufWriter::new(f),
        })
    }

    /// Appends `row` and flushes it. `row.wall_forces` must have one entry per wall.
    pub fn append(&mut self, row: &SeriesRow) -> io::Result<()> {
        if row.wall_forces.len() != self.walls {
            return Err(invalid_input(
                &self.path,
                format!(
                    "row of step {} has {} wall forces, the series has {} walls",
                    row.step,
                    row.wall_forces.len(),
                    self.walls
                ),
            ));
        }
        let mut s = format!("{},", row.step);
        for x in [
            row.time,
            row.kinetic_translational,
            row.kinetic_rotational,
            row.potential_gravity,
            row.elastic,
        ] {
            s.push_str(&format_f64(x));
            s.push(',');
        }
        let _ = write!(s, "{},{}", row.contacts, row.wall_contacts);
        for f in &row.wall_forces {
            for c in [f.x, f.y, f.z] {
                s.push(',');
                s.push_str(&format_f64(c));
            }
        }
        s.push('\n');
        self.out
            .write_all(s.as_bytes())
            .map_err(|e| with_path(e, &self.path))?;
        self.out.flush().map_err(|e| with_path(e, &self.path))
    }
}

fn series_header(wall_names: &[String]) -> String {
    let mut h = String::from(
        "step,time,kinetic_translational,kinetic_rotational,potential_gravity,elastic,\
         contacts,wall_contacts",
    );
    for name in wall_names {
        for c in ["fx", "fy", "fz"] {
            h.push(',');
            h.push_str(&csv_field(&format!("{name}_{c}")));
        }
    }
    h.push('\n');
    h
}

/// A CSV field, quoted (RFC 4180) when it holds a comma, quote or line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}
