//! VTK XML output of frames (docs/design.md §8): `frames.pvd` → per-step `.pvtu` → per-rank `.vtu`,
//! and `walls.pvd` → per-step walls `.vtu`. Written by hand (no VTK dependency).
//!
//! Layout under the output directory:
//!
//! ```text
//! frames.pvd                      Collection: one DataSet (timestep, file) per frame
//! walls.pvd                       the same for the walls, when there are walls
//! frames/step_<step>.pvtu         PUnstructuredGrid naming the rank pieces
//! frames/step_<step>_r<rank>.vtu  UnstructuredGrid: one VTK_POLYHEDRON cell per particle
//! frames/walls_<step>.vtu         UnstructuredGrid: one VTK_TRIANGLE cell per wall facet
//! ```
//!
//! Files are named by step, not by a frame counter, so a restarted run writes exactly the
//! files (and collection entries) of the uninterrupted one.
//!
//! Encoding: `format="binary"`, i.e. base64 of a UInt64 byte count followed by the raw
//! little-endian array, uncompressed (`header_type="UInt64"`, file version 1.0). Polyhedra use
//! the legacy `faces` / `faceoffsets` layout (per cell: face count, then per face its point
//! count and point ids; `faceoffsets` holds each cell's end in `faces`), which VTK/ParaView
//! read and which is the only polyhedron layout meshio 5 reads.

use super::{
    base64, format_f64, invalid_data, invalid_input, particle_count, with_path, write_atomic,
};
use crate::shape::ConvexTemplate;
use crate::state::Particles;
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

/// The per-particle cell arrays a frame can carry, in the order they are written. `id` and
/// `type` are always written; `template` is the template index, `orientation` the quaternion
/// body → world as (w, x, y, z), `rank` the writing rank.
pub const FRAME_FIELDS: [&str; 9] = [
    "id",
    "type",
    "template",
    "velocity",
    "angular_velocity",
    "force",
    "torque",
    "orientation",
    "rank",
];

/// VTK cell type of a polyhedron.
const VTK_POLYHEDRON: u8 = 42;
/// VTK cell type of a triangle.
const VTK_TRIANGLE: u8 = 5;

/// One rank's particles as they go into its `.vtu` piece.
pub struct FrameView<'a> {
    /// The particles (owned ones only: ghosts belong to their own rank's piece).
    pub particles: &'a Particles,
    /// All templates of the simulation.
    pub templates: &'a [ConvexTemplate],
    /// Particle kind (`Particles::kind`) → index into `templates`.
    pub type_template: &'a [usize],
    /// The rank this piece belongs to (names the piece file).
    pub rank: u32,
    /// The cell arrays to write, a subset of [`FRAME_FIELDS`]; `id` and `type` always are.
    pub fields: &'a [String],
}

/// A wall as it goes into the frame's walls file.
pub struct WallView<'a> {
    /// The wall's name (scene file), listed in a comment of the walls file.
    pub name: &'a str,
    /// Facets in their current world positions.
    pub triangles: &'a [[Vector3<f64>; 3]],
    /// Total force on the wall, written on each of its facets.
    pub force: Vector3<f64>,
}

/// One `<DataSet>` of a `.pvd` collection.
#[derive(Clone, Debug, PartialEq)]
struct PvdEntry {
    time: f64,
    /// Relative to the collection's directory.
    file: String,
}

/// Writes frames into one output directory and keeps its collections current.
///
/// Rank 0 (or the single rank) writes the `.pvtu` and both `.pvd` files and the walls; every
/// rank writes its own pieces. A `.pvtu` names all `ranks` pieces: in a parallel run the pieces
/// of the other ranks must be written before a reader opens the frame (the caller's barrier).
pub struct FrameWriter {
    dir: PathBuf,
    ranks: u32,
    root: bool,
    frames: Vec<PvdEntry>,
    walls: Vec<PvdEntry>,
}

impl FrameWriter {
    /// A writer for rank 0 of `ranks` in `dir` (created), starting new collections.
    pub fn new(dir: &Path, ranks: u32) -> io::Result<Self> {
        Self::new_rank(dir, ranks, 0)
    }

    /// A writer for `rank` of `ranks`; only rank 0 writes the collections and walls.
    pub fn new_rank(dir: &Path, ranks: u32, rank: u32) -> io::Result<Self> {
        if ranks == 0 || rank >= ranks {
            return Err(invalid_input(dir, format!("rank {rank} of {ranks} ranks")));
        }
        fs::create_dir_all(dir.join("frames")).map_err(|e| with_path(e, dir))?;
        Ok(FrameWriter {
            dir: dir.to_path_buf(),
            ranks,
            root: rank == 0,
            frames: Vec::new(),
            walls: Vec::new(),
        })
    }

    /// Rank 0's writer for a run restarted from a checkpoint at time `after_time`: keeps the
    /// collection entries with `time <= after_time`, drops later ones (frames the stopped run
    /// wrote after its checkpoint; the restarted run rewrites them under the same names) and
    /// rewrites the collections at once. A missing collection counts as empty.
    pub fn resume(dir: &Path, ranks: u32, after_time: f64) -> io::Result<Self> {
        Self::resume_rank(dir, ranks, 0, after_time)
    }

    /// [`FrameWriter::resume`] for any rank; ranks other than 0 read and write no collection.
    pub fn resume_rank(dir: &Path, ranks: u32, rank: u32, after_time: f64) -> io::Result<Self> {
        let mut w = Self::new_rank(dir, ranks, rank)?;
        if w.root {
            for (name, entries) in [("frames.pvd", &mut w.frames), ("walls.pvd", &mut w.walls)] {
                let path = dir.join(name);
                *entries = match fs::read_to_string(&path) {
                    Ok(text) => parse_pvd(&text, &path)?,
                    Err(e) if e.kind() == io::ErrorKind::NotFound => Vec::new(),
                    Err(e) => return Err(with_path(e, &path)),
                };
                entries.retain(|e| e.time <= after_time);
            }
            w.write_collections()?;
        }
        Ok(w)
    }

    /// Number of frames in the particle collection.
    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    /// The output directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Writes one frame: a `.vtu` per piece in `pieces` (each named by its rank), and on rank 0
    /// the `.pvtu`, the walls file (when `walls` is not empty) and the updated collections.
    /// A frame of a step already in a collection replaces that entry.
    pub fn write_frame(
        &mut self,
        step: u64,
        time: f64,
        pieces: &[FrameView],
        walls: &[WallView],
    ) -> io::Result<()> {
        let stem = format!("step_{step:010}");
        let fields = match pieces.first() {
            Some(p) => selected_fields(p.fields, &self.dir)?,
            None => selected_fields(&[], &self.dir)?,
        };
        let mut seen = Vec::new();
        for p in pieces {
            if p.rank >= self.ranks || seen.contains(&p.rank) {
                return Err(invalid_input(
                    &self.dir,
                    format!("piece of rank {} (ranks: {}, twice?)", p.rank, self.ranks),
                ));
            }
            seen.push(p.rank);
            if selected_fields(p.fields, &self.dir)? != fields {
                return Err(invalid_input(
                    &self.dir,
                    "pieces of one frame select different fields",
                ));
            }
            let path = self.dir.join("frames").join(piece_name(&stem, p.rank));
            let xml = piece_xml(p, &fields).map_err(|m| invalid_input(&path, m))?;
            write_atomic(&path, xml.as_bytes())?;
        }
        if !self.root {
            return Ok(());
        }
        let pvtu = format!("{stem}.pvtu");
        write_atomic(
            &self.dir.join("frames").join(&pvtu),
            pvtu_xml(&stem, self.ranks, &fields).as_bytes(),
        )?;
        upsert(&mut self.frames, time, format!("frames/{pvtu}"));
        if !walls.is_empty() {
            let name = format!("walls_{step:010}.vtu");
            write_atomic(
                &self.dir.join("frames").join(&name),
                walls_xml(walls).as_bytes(),
            )?;
            upsert(&mut self.walls, time, format!("frames/{name}"));
        }
        self.write_collections()
    }

    fn write_collections(&self) -> io::Result<()> {
        write_atomic(
            &self.dir.join("frames.pvd"),
            pvd_xml(&self.frames).as_bytes(),
        )?;
        if !self.walls.is_empty() || self.dir.join("walls.pvd").exists() {
            write_atomic(&self.dir.join("walls.pvd"), pvd_xml(&self.walls).as_bytes())?;
        }
        Ok(())
    }
}

fn piece_name(stem: &str, rank: u32) -> String {
    format!("{stem}_r{rank:04}.vtu")
}

/// Replaces the entry for `file` (a rewritten step) or appends one.
fn upsert(entries: &mut Vec<PvdEntry>, time: f64, file: String) {
    entries.retain(|e| e.file != file);
    entries.push(PvdEntry { time, file });
}

/// The selected fields in [`FRAME_FIELDS`] order, `id` and `type` included; unknown names are
/// errors that list the allowed ones.
fn selected_fields(fields: &[String], dir: &Path) -> io::Result<Vec<&'static str>> {
    if let Some(bad) = fields.iter().find(|f| !FRAME_FIELDS.contains(&f.as_str())) {
        return Err(invalid_input(
            dir,
            format!(
                "unknown frame field `{bad}`; allowed: {}",
                FRAME_FIELDS.join(", ")
            ),
        ));
    }
    Ok(FRAME_FIELDS
        .iter()
        .copied()
        .filter(|n| *n == "id" || *n == "type" || fields.iter().any(|f| f == n))
        .collect())
}

/// The `.vtu` of one piece. Errors (inconsistent input) are messages for the caller to attach
/// the file name to.
fn piece_xml(view: &FrameView, fields: &[&str]) -> Result<String, String> {
    let p = view.particles;
    let n = particle_count(p)?;
    let mut tmpl = Vec::with_capacity(n);
    let mut tidx = Vec::with_capacity(n);
    for i in 0..n {
        let kind = p.kind[i];
        let t = view
            .type_template
            .get(kind as usize)
            .copied()
            .ok_or_else(|| {
                format!(
                    "particle {} has type {kind}, which has no template",
                    p.id[i]
                )
            })?;
        let template = view
            .templates
            .get(t)
            .ok_or_else(|| format!("type {kind} names template {t}, which does not exist"))?;
        tmpl.push(template);
        tidx.push(t);
    }
    // Cells grouped by vertex count (stable): meshio 5 splits polyhedra into blocks by vertex
    // count in order of first appearance but slices the cell data by sorted count, so other
    // orders would pair a block with another block's data. Each cell carries its id.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| tmpl[i].vertices.len());

    let n_points: usize = tmpl.iter().map(|t| t.vertices.len()).sum();
    let mut points = Vec::with_capacity(3 * n_points);
    let mut connectivity = Vec::with_capacity(n_points);
    let mut offsets = Vec::with_capacity(n);
    let mut faces: Vec<u64> = Vec::new();
    let mut faceoffsets = Vec::with_capacity(n);
    for &i in &order {
        let t = tmpl[i];
        let base = connectivity.len() as u64;
        for v in &t.vertices {
            // World position R(q)·(s·v) + x (docs/design.md §3: template + scale + pose).
            let w = p.orientation[i].transform_vector(&(v.coords * p.scale[i])) + p.position[i];
            points.extend_from_slice(&[w.x, w.y, w.z]);
        }
        connectivity.extend((0..t.vertices.len() as u64).map(|k| base + k));
        offsets.push(connectivity.len() as u64);
        faces.push(t.faces.len() as u64);
        for f in &t.faces {
            faces.push(f.vertices.len() as u64);
            for &k in &f.vertices {
                if k as usize >= t.vertices.len() {
                    return Err(format!(
                        "template `{}`: face vertex {k} out of range",
                        t.name
                    ));
                }
                faces.push(base + k as u64);
            }
        }
        faceoffsets.push(faces.len() as u64);
    }

    let mut x = header("UnstructuredGrid");
    let _ = writeln!(x, "  <UnstructuredGrid>");
    let _ = writeln!(
        x,
        "    <Piece NumberOfPoints=\"{n_points}\" NumberOfCells=\"{n}\">"
    );
    x.push_str("      <Points>\n");
    data_array(&mut x, "Float64", "Points", 3, &f64_bytes(&points));
    x.push_str("      </Points>\n      <Cells>\n");
    // Int32 ids when they fit halve the largest arrays; VTK and meshio convert on reading.
    let wide = faces.len().max(n_points) > i32::MAX as usize;
    int_array(&mut x, "connectivity", &connectivity, wide);
    int_array(&mut x, "offsets", &offsets, wide);
    data_array(&mut x, "UInt8", "types", 1, &vec![VTK_POLYHEDRON; n]);
    int_array(&mut x, "faces", &faces, wide);
    int_array(&mut x, "faceoffsets", &faceoffsets, wide);
    x.push_str("      </Cells>\n      <CellData>\n");
    for &field in fields {
        let (ty, nc, bytes) = cell_field(view, field, &order, &tidx)?;
        data_array(&mut x, ty, field, nc, &bytes);
    }
    x.push_str("      </CellData>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
    Ok(x)
}

/// One cell array: VTK type name, components, little-endian bytes in cell order.
fn cell_field(
    view: &FrameView,
    field: &str,
    order: &[usize],
    tidx: &[usize],
) -> Result<(&'static str, usize, Vec<u8>), String> {
    let p = view.particles;
    let vec3 = |a: &[Vector3<f64>]| {
        let v: Vec<f64> = order
            .iter()
            .flat_map(|&i| [a[i].x, a[i].y, a[i].z])
            .collect();
        ("Float64", 3, f64_bytes(&v))
    };
    let int32 = |f: &dyn Fn(usize) -> u64, what: &str| -> Result<_, String> {
        let mut b = Vec::with_capacity(4 * order.len());
        for &i in order {
            let v = i32::try_from(f(i)).map_err(|_| format!("{what} {} exceeds Int32", f(i)))?;
            b.extend_from_slice(&v.to_le_bytes());
        }
        Ok(("Int32", 1, b))
    };
    Ok(match field {
        "id" => (
            "UInt64",
            1,
            order.iter().flat_map(|&i| p.id[i].to_le_bytes()).collect(),
        ),
        "type" => int32(&|i| p.kind[i] as u64, "type")?,
        "template" => int32(&|i| tidx[i] as u64, "template")?,
        "velocity" => vec3(&p.velocity),
        "angular_velocity" => vec3(&p.angular_velocity),
        "force" => vec3(&p.force),
        "torque" => vec3(&p.torque),
        "orientation" => {
            let v: Vec<f64> = order
                .iter()
                .flat_map(|&i| {
                    let q = p.orientation[i].quaternion();
                    [q.w, q.i, q.j, q.k]
                })
                .collect();
            ("Float64", 4, f64_bytes(&v))
        }
        "rank" => int32(&|_| view.rank as u64, "rank")?,
        other => return Err(format!("unknown frame field `{other}`")),
    })
}

/// The `.pvtu` of a frame: the arrays every piece has and the piece files.
fn pvtu_xml(stem: &str, ranks: u32, fields: &[&str]) -> String {
    let mut x = header("PUnstructuredGrid");
    x.push_str("  <PUnstructuredGrid GhostLevel=\"0\">\n    <PPoints>\n");
    x.push_str("      <PDataArray type=\"Float64\" Name=\"Points\" NumberOfComponents=\"3\"/>\n");
    x.push_str("    </PPoints>\n    <PCellData>\n");
    for &f in fields {
        let (ty, nc) = match f {
            "id" => ("UInt64", 1),
            "type" | "template" | "rank" => ("Int32", 1),
            "orientation" => ("Float64", 4),
            _ => ("Float64", 3),
        };
        let _ = match nc {
            1 => writeln!(x, "      <PDataArray type=\"{ty}\" Name=\"{f}\"/>"),
            _ => writeln!(
                x,
                "      <PDataArray type=\"{ty}\" Name=\"{f}\" NumberOfComponents=\"{nc}\"/>"
            ),
        };
    }
    x.push_str("    </PCellData>\n");
    for r in 0..ranks {
        let _ = writeln!(x, "    <Piece Source=\"{}\"/>", piece_name(stem, r));
    }
    x.push_str("  </PUnstructuredGrid>\n</VTKFile>\n");
    x
}

/// The walls of a frame: one triangle cell per facet (three points each, not shared), with the
/// wall's index and total force as cell data. Wall names are listed in a comment because
/// string arrays are not portable (meshio rejects them).
fn walls_xml(walls: &[WallView]) -> String {
    let n: usize = walls.iter().map(|w| w.triangles.len()).sum();
    let mut points = Vec::with_capacity(9 * n);
    let mut wall_id = Vec::with_capacity(4 * n);
    let mut force = Vec::with_capacity(3 * n);
    for (k, w) in walls.iter().enumerate() {
        for t in w.triangles {
            for v in t {
                points.extend_from_slice(&[v.x, v.y, v.z]);
            }
            wall_id.extend_from_slice(&(k as i32).to_le_bytes());
            force.extend_from_slice(&[w.force.x, w.force.y, w.force.z]);
        }
    }
    let connectivity: Vec<u64> = (0..3 * n as u64).collect();
    let offsets: Vec<u64> = (1..=n as u64).map(|c| 3 * c).collect();
    let mut x = header("UnstructuredGrid");
    x.push_str("  <!-- wall_id:");
    for (k, w) in walls.iter().enumerate() {
        let name: String = w
            .name
            .chars()
            .map(|c| {
                if c.is_alphanumeric() || "_.+".contains(c) {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let _ = write!(x, " {k}={name}");
    }
    x.push_str(" -->\n  <UnstructuredGrid>\n");
    let _ = writeln!(
        x,
        "    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{n}\">",
        3 * n
    );
    x.push_str("      <Points>\n");
    data_array(&mut x, "Float64", "Points", 3, &f64_bytes(&points));
    x.push_str("      </Points>\n      <Cells>\n");
    let wide = 3 * n > i32::MAX as usize;
    int_array(&mut x, "connectivity", &connectivity, wide);
    int_array(&mut x, "offsets", &offsets, wide);
    data_array(&mut x, "UInt8", "types", 1, &vec![VTK_TRIANGLE; n]);
    x.push_str("      </Cells>\n      <CellData>\n");
    data_array(&mut x, "Int32", "wall_id", 1, &wall_id);
    data_array(&mut x, "Float64", "force", 3, &f64_bytes(&force));
    x.push_str("      </CellData>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
    x
}

fn pvd_xml(entries: &[PvdEntry]) -> String {
    let mut x = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" \
         byte_order=\"LittleEndian\">\n  <Collection>\n",
    );
    for e in entries {
        let _ = writeln!(
            x,
            "    <DataSet timestep=\"{}\" group=\"\" part=\"0\" file=\"{}\"/>",
            format_f64(e.time),
            e.file
        );
    }
    x.push_str("  </Collection>\n</VTKFile>\n");
    x
}

/// Reads back a collection this module wrote (one `<DataSet .../>` per line).
fn parse_pvd(text: &str, path: &Path) -> io::Result<Vec<PvdEntry>> {
    let attr = |line: &str, name: &str| -> Option<String> {
        let key = format!("{name}=\"");
        let start = line.find(&key)? + key.len();
        let len = line[start..].find('"')?;
        Some(line[start..start + len].to_string())
    };
    let mut out = Vec::new();
    for (k, line) in text.lines().enumerate() {
        if !line.contains("<DataSet") {
            continue;
        }
        let time = attr(line, "timestep").and_then(|t| t.parse::<f64>().ok());
        match (time, attr(line, "file")) {
            (Some(time), Some(file)) => out.push(PvdEntry { time, file }),
            _ => {
                return Err(invalid_data(
                    path,
                    format!(
                        "line {}: DataSet without a numeric timestep and a file",
                        k + 1
                    ),
                ));
            }
        }
    }
    Ok(out)
}

fn header(kind: &str) -> String {
    format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"{kind}\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
    )
}

/// A `format="binary"` DataArray: base64 of (UInt64 byte count ‖ data), one stream.
/// `NumberOfComponents` only when not 1 (VTK's default): meshio reshapes arrays that have it to
/// two dimensions, which its polyhedron reader cannot index.
fn data_array(x: &mut String, ty: &str, name: &str, components: usize, data: &[u8]) {
    let _ = write!(x, "        <DataArray type=\"{ty}\" Name=\"{name}\"");
    if components != 1 {
        let _ = write!(x, " NumberOfComponents=\"{components}\"");
    }
    x.push_str(" format=\"binary\">");
    let mut raw = Vec::with_capacity(8 + data.len());
    raw.extend_from_slice(&(data.len() as u64).to_le_bytes());
    raw.extend_from_slice(data);
    base64(&raw, x);
    x.push_str("</DataArray>\n");
}

/// An index array as Int32 (`wide == false`; the caller checked the range) or Int64.
fn int_array(x: &mut String, name: &str, values: &[u64], wide: bool) {
    let bytes: Vec<u8> = if wide {
        values
            .iter()
            .flat_map(|&v| (v as i64).to_le_bytes())
            .collect()
    } else {
        values
            .iter()
            .flat_map(|&v| (v as i32).to_le_bytes())
            .collect()
    };
    data_array(x, if wide { "Int64" } else { "Int32" }, name, 1, &bytes);
}

fn f64_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pvd_round_trips() {
        let e = vec![
            PvdEntry {
                time: 0.1,
                file: "frames/a.pvtu".into(),
            },
            PvdEntry {
                time: 1e-300,
                file: "frames/b.pvtu".into(),
            },
        ];
        assert_eq!(parse_pvd(&pvd_xml(&e), Path::new("x.pvd")).unwrap(), e);
    }
}
