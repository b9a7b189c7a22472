//! Mesh import (STL binary/ASCII and OBJ by small parsers whose errors name the line or size) and template building
//! from files, with a warning when a non-convex mesh is replaced by its convex hull.

use super::{ConvexTemplate, MassProperties, ShapeError, ShapeSource};
use nalgebra::Point3;
use std::collections::HashMap;
use std::path::Path;

/// Relative volume difference above which a closed mesh is reported as non-convex.
const CONVEXITY_TOL: f64 = 1e-9;

/// As [`CONVEXITY_TOL`] for STL, whose f32 coordinates make a convex polygon split into
/// triangles fold by rounding (about 1e-8 of the volume for a dodecahedron): only dents larger
/// than f32 precision are reported.
const CONVEXITY_TOL_F32: f64 = 1e-6;

/// File extensions [`load_mesh`] accepts (case-insensitive).
pub const MESH_EXTENSIONS: [&str; 2] = ["stl", "obj"];

/// A triangle mesh as read from a file, in the file's coordinates and units.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshFile {
    /// Vertex positions (STL: deduplicated exact f32 values; OBJ: every `v` line, in order).
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as vertex indices (OBJ polygons fan-triangulated).
    pub triangles: Vec<[u32; 3]>,
}

impl MeshFile {
    /// Whether the mesh is closed and consistently oriented: every directed edge appears once and
    /// its reverse once (each edge shared by exactly two triangles wound oppositely). Only then
    /// does it bound a solid whose volume [`MeshFile::mass_properties`] can measure.
    /// Vertices at bitwise-equal positions count as one (OBJ exporters often repeat seam vertices).
    pub fn is_closed(&self) -> bool {
        let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &self.welded_triangles() {
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        !directed.is_empty()
            && directed
                .iter()
                .all(|(&(a, b), &n)| n == 1 && a != b && directed.get(&(b, a)) == Some(&1))
    }

    /// Mass properties of the solid the mesh bounds (signed tetrahedra, which is valid for
    /// non-convex closed meshes too), or `None` if it is not closed or has no volume.
    pub fn mass_properties(&self) -> Option<MassProperties> {
        if !self.is_closed() {
            return None;
        }
        MassProperties::from_triangles(&self.vertices, &self.welded_triangles())
    }

    /// Triangles with each index replaced by the first vertex at the same position; triangles
    /// with an out-of-range index map to a repeated index, which `is_closed` rejects.
    fn welded_triangles(&self) -> Vec<[u32; 3]> {
        let mut first: HashMap<[u64; 3], u32> = HashMap::new();
        let canon: Vec<u32> = self
            .vertices
            .iter()
            .enumerate()
            .map(|(i, p)| {
                // +0.0 turns −0.0 into +0.0 so that the two zeros weld.
                let key = [
                    (p.x + 0.0).to_bits(),
                    (p.y + 0.0).to_bits(),
                    (p.z + 0.0).to_bits(),
                ];
                *first.entry(key).or_insert(i as u32)
            })
            .collect();
        let map = |i: u32| canon.get(i as usize).copied().unwrap_or(u32::MAX);
        self.triangles
            .iter()
            .map(|t| {
                let m = [map(t[0]), map(t[1]), map(t[2])];
                if m.contains(&u32::MAX) { [0, 0, 0] } else { m }
            })
            .collect()
    }

    /// Writes the mesh as binary STL (coordinates rounded to f32, as the format stores them).
    pub fn write_stl(&self, path: &Path) -> std::io::Result<()> {
        let mut tris = Vec::with_capacity(self.triangles.len());
        for t in &self.triangles {
            let p = |k: usize| -> std::io::Result<Point3<f64>> {
                self.vertices.get(t[k] as usize).copied().ok_or_else(|| {
                    std::io::Error::new(
                        std::io::ErrorKind::InvalidInput,
                        "triangle index out of range",
                    )
                })
            };
            let (a, b, c) = (p(0)?, p(1)?, p(2)?);
            let n = (b - a)
                .cross(&(c - a))
                .try_normalize(0.0)
                .unwrap_or_default();
            let v = |q: Point3<f64>| stl_io::Vertex::new([q.x as f32, q.y as f32, q.z as f32]);
            tris.push(stl_io::Triangle {
                normal: stl_io::Normal::new([n.x as f32, n.y as f32, n.z as f32]),
                vertices: [v(a), v(b), v(c)],
            });
        }
        let mut file = std::io::BufWriter::new(std::fs::File::create(path)?);
        stl_io::write_stl(&mut file, tris.iter())?;
        std::io::Write::flush(&mut file)
    }
}

/// What [`ConvexTemplate::from_file_with_report`] found about the input mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImportReport {
    /// The mesh's own volume when it is closed and consistently oriented.
    pub mesh_volume: Option<f64>,
    /// Volume of the convex hull of its vertices (before merging near-coplanar faces).
    pub hull_volume: f64,
    /// `hull_volume − mesh_volume` when the mesh is closed, else 0.
    pub added_volume: f64,
}

fn unreadable(path: &Path, message: String) -> ShapeError {
    ShapeError::Unreadable {
        source_name: path.display().to_string(),
        message,
    }
}

/// Reads a triangle mesh from an STL (binary or ASCII) or OBJ file, chosen by extension.
pub fn load_mesh(path: &Path) -> Result<MeshFile, ShapeError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    if !MESH_EXTENSIONS.contains(&ext.as_str()) {
        return Err(unreadable(
            path,
            format!(
                "unsupported mesh file extension {:?}; allowed: .stl, .obj (case-insensitive)",
                ext
            ),
        ));
    }
    let bytes = crate::input::read_bounded(path, crate::input::InputKind::Mesh)
        .map_err(|e| unreadable(path, e.to_string()))?;
    let mesh = if ext == "stl" {
        parse_stl(&bytes).map_err(|e| unreadable(path, format!("invalid STL: {e}")))?
    } else {
        parse_obj(&String::from_utf8_lossy(&bytes)).map_err(|e| unreadable(path, e))?
    };
    if mesh.vertices.is_empty() {
        return Err(ShapeError::Degenerate {
            source_name: path.display().to_string(),
            message: "the mesh file contains no vertices".to_string(),
        });
    }
    Ok(mesh)
}

/// Size of a binary STL's header (free text) and of the triangle count that follows it.
const STL_HEADER: usize = 80;
/// Bytes of one binary STL triangle: normal and three vertices (12 f32), a 2-byte attribute.
const STL_TRIANGLE: u64 = 50;

/// Reads binary or ASCII STL. The size decides first: a file of exactly 84 + 50 × count bytes
/// (count = the u32 after the 80-byte header) is binary, even when its header begins with
/// "solid", as some CAD exporters write. Otherwise a text file (no NUL byte) beginning with
/// "solid" is ASCII, and anything else is a binary STL whose size does not match its count:
/// the error gives both sizes, so that a truncated file, a wrong count or extra data is named,
/// never read partially.
fn parse_stl(bytes: &[u8]) -> Result<MeshFile, String> {
    let len = bytes.len() as u64;
    if len == 0 {
        return Err(
            "the file is empty (0 bytes); a binary STL has at least 84 bytes (an 80-byte \
                    header and a 4-byte triangle count), an ASCII STL begins with \"solid\""
                .to_string(),
        );
    }
    let count = bytes
        .get(STL_HEADER..STL_HEADER + 4)
        .map(|c| u64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]])));
    let expected = count.map(|n| STL_HEADER as u64 + 4 + STL_TRIANGLE * n);
    if let (Some(n), Some(size)) = (count, expected)
        && size == len
    {
        return Ok(parse_binary_stl(bytes, n as usize));
    }
    let text = bytes.trim_ascii_start();
    if text.starts_with(b"solid") && !bytes.contains(&0) {
        return parse_ascii_stl(&String::from_utf8_lossy(bytes));
    }
    let (Some(n), Some(size)) = (count, expected) else {
        return Err(format!(
            "{len} bytes: too short for a binary STL, which has at least 84 (an 80-byte header \
             and a 4-byte triangle count), and not an ASCII STL (it does not begin with \"solid\")"
        ));
    };
    let data = len - 84;
    let (whole, rest) = (data / STL_TRIANGLE, data % STL_TRIANGLE);
    let relation = if len < size {
        format!(
            "{} bytes fewer (truncated, or the count is too large)",
            size - len
        )
    } else {
        format!(
            "{} bytes more (the count is too small, or data follow the triangles)",
            len - size
        )
    };
    Err(format!(
        "binary STL size mismatch: the header gives {n} triangles, which take 84 + 50 × {n} = \
         {size} bytes, but the file has {len} bytes, {relation}; its {data} data bytes hold \
         {whole} whole triangles and {rest} bytes more. (Not an ASCII STL either: it {}.)",
        if text.starts_with(b"solid") {
            "begins with \"solid\" but contains NUL bytes"
        } else {
            "does not begin with \"solid\""
        }
    ))
}

/// Indexes triangles by vertex, merging vertices of bitwise-equal f32 coordinates (the same
/// corner written once per triangle, as STL does), in order of first appearance.
#[derive(Default)]
struct VertexIndex {
    mesh: MeshFile,
    index: HashMap<[u32; 3], u32>,
}

impl VertexIndex {
    fn push(&mut self, tri: [[f32; 3]; 3]) {
        let mut t = [0u32; 3];
        for (slot, v) in t.iter_mut().zip(tri) {
            let next = self.mesh.vertices.len() as u32;
            *slot = *self.index.entry(v.map(f32::to_bits)).or_insert_with(|| {
                self.mesh
                    .vertices
                    .push(Point3::new(v[0] as f64, v[1] as f64, v[2] as f64));
                next
            });
        }
        self.mesh.triangles.push(t);
    }
}

/// Binary STL of `count` triangles; the caller has checked the size.
fn parse_binary_stl(bytes: &[u8], count: usize) -> MeshFile {
    let mut mesh = VertexIndex::default();
    for k in 0..count {
        let at = STL_HEADER + 4 + STL_TRIANGLE as usize * k + 12;
        let f = |i: usize| {
            let b = &bytes[at + 4 * i..at + 4 * i + 4];
            f32::from_le_bytes([b[0], b[1], b[2], b[3]])
        };
        mesh.push([[f(0), f(1), f(2)], [f(3), f(4), f(5)], [f(6), f(7), f(8)]]);
    }
    mesh.mesh
}

/// ASCII STL: `solid [name]`, then per facet `facet normal nx ny nz`, `outer loop`, three
/// `vertex x y z`, `endloop`, `endfacet`, and `endsolid [name]`; several solids may follow one
/// another. The normals are not used (the winding is). Errors name the line.
fn parse_ascii_stl(text: &str) -> Result<MeshFile, String> {
    let mut mesh = VertexIndex::default();
    let mut in_solid = false;
    let mut facet: Option<Vec<[f32; 3]>> = None;
    let mut last = 0;
    for (lineno, raw) in text.lines().enumerate() {
        let line_no = lineno + 1;
        last = line_no;
        let mut tokens = raw.split_whitespace();
        let Some(keyword) = tokens.next() else {
            continue;
        };
        let args: Vec<&str> = tokens.collect();
        let unexpected = || format!("line {line_no}: unexpected {keyword:?}: {:?}", raw.trim());
        match keyword {
            "solid" if !in_solid => in_solid = true,
            "endsolid" if in_solid && facet.is_none() => in_solid = false,
            "facet" if in_solid && facet.is_none() => facet = Some(Vec::with_capacity(3)),
            "outer" | "endloop" if facet.is_some() => {}
            "vertex" if facet.is_some() => {
                if args.len() != 3 {
                    return Err(format!(
                        "line {line_no}: a vertex needs 3 coordinates, got {}: {:?}",
                        args.len(),
                        raw.trim()
                    ));
                }
                let mut v = [0f32; 3];
                for (x, a) in v.iter_mut().zip(&args) {
                    *x = stl_coordinate(a).map_err(|e| format!("line {line_no}: {e}"))?;
                }
                if let Some(f) = facet.as_mut() {
                    f.push(v);
                }
            }
            "endfacet" => match facet.take() {
                Some(f) if f.len() == 3 => mesh.push([f[0], f[1], f[2]]),
                Some(f) => {
                    return Err(format!(
                        "line {line_no}: a facet has {} vertices, an STL facet needs 3",
                        f.len()
                    ));
                }
                None => return Err(unexpected()),
            },
            _ => return Err(unexpected()),
        }
    }
    if in_solid {
        return Err(format!(
            "ASCII STL ends at line {last} inside a {} (truncated?): \"endsolid\" is missing",
            if facet.is_some() { "facet" } else { "solid" }
        ));
    }
    Ok(mesh.mesh)
}

/// One ASCII STL coordinate as the f32 STL stores. A nonzero value that f32 would turn into 0
/// or infinity is an error: silently, distinct vertices would collapse into one.
fn stl_coordinate(text: &str) -> Result<f32, String> {
    let x: f64 = text
        .parse()
        .map_err(|_| format!("{text:?} is not a number"))?;
    let y = x as f32;
    if x.is_finite() && x != 0.0 && y == 0.0 {
        return Err(format!(
            "coordinate {text} underflows to 0 in f32 (STL stores 32-bit floats, whose smallest \
             nonzero magnitude is 1.4e-45); rescale the mesh (e.g. write it in smaller units)"
        ));
    }
    if x.is_finite() && y.is_infinite() {
        return Err(format!(
            "coordinate {text} overflows f32 (STL stores 32-bit floats, at most 3.4e38 in \
             magnitude); rescale the mesh (e.g. write it in larger units)"
        ));
    }
    Ok(y)
}

/// OBJ statements that carry no geometry polydem needs; skipped.
const OBJ_IGNORED: [&str; 27] = [
    "vt", "vn", "vp", "o", "g", "s", "l", "p", "mtllib", "usemtl", "usemap", "maplib", "mg",
    "cstype", "deg", "bmat", "step", "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp",
    "end", "lod",
];

/// Parses OBJ text: `v x y z [w]` (extra colour columns tolerated) and `f a b c ...` with
/// `a`, `a/t`, `a//n`, `a/t/n` and negative (relative) indices. Errors name the line.
fn parse_obj(text: &str) -> Result<MeshFile, String> {
    let mut mesh = MeshFile::default();
    for (lineno, raw) in text.lines().enumerate() {
        let line_no = lineno + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut tokens = line.split_whitespace();
        let Some(keyword) = tokens.next() else {
            continue;
        };
        let args: Vec<&str> = tokens.collect();
        match keyword {
            "v" => {
                if !matches!(args.len(), 3 | 4 | 6 | 7) {
                    return Err(format!(
                        "line {line_no}: a vertex needs 3 coordinates (optionally w or r g b), got {} values: {line:?}",
                        args.len()
                    ));
                }
                let mut xyz = [0.0; 3];
                for (k, a) in args.iter().enumerate() {
                    let x: f64 = a
                        .parse()
                        .map_err(|_| format!("line {line_no}: {a:?} is not a number: {line:?}"))?;
                    if k < 3 {
                        xyz[k] = x;
                    }
                }
                mesh.vertices.push(Point3::new(xyz[0], xyz[1], xyz[2]));
            }
            "f" => {
                if args.len() < 3 {
                    return Err(format!(
                        "line {line_no}: a face needs at least 3 vertices: {line:?}"
                    ));
                }
                let count = mesh.vertices.len();
                let mut idx = Vec::with_capacity(args.len());
                for a in &args {
                    let first = a.split('/').next().unwrap_or("");
                    let i: i64 = first.parse().map_err(|_| {
                        format!("line {line_no}: bad face vertex reference {a:?}: {line:?}")
                    })?;
                    let resolved = if i > 0 { i - 1 } else { count as i64 + i };
                    if i == 0 || resolved < 0 || resolved >= count as i64 {
                        return Err(format!(
                            "line {line_no}: vertex index {i} out of range ({count} vertices defined so far)"
                        ));
                    }
                    idx.push(resolved as u32);
                }
                for k in 1..idx.len() - 1 {
                    mesh.triangles.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            k if OBJ_IGNORED.contains(&k) => {}
            other => {
                return Err(format!("line {line_no}: unknown OBJ statement {other:?}"));
            }
        }
    }
    Ok(mesh)
}

impl ConvexTemplate {
    /// Template of the convex hull of the mesh in `path` (STL or OBJ), named by the file stem.
    /// A closed mesh whose volume is below its hull's warns, as the particle will be the hull.
    pub fn from_file(path: &Path) -> Result<ConvexTemplate, ShapeError> {
        Self::from_file_with_report(path).map(|(t, _)| t)
    }

    /// As [`ConvexTemplate::from_file`], also returning the mesh's own and its hull's volume.
    pub fn from_file_with_report(
        path: &Path,
    ) -> Result<(ConvexTemplate, ImportReport), ShapeError> {
        let mesh = load_mesh(path)?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string());
        let source = ShapeSource::File(path.to_path_buf());
        // STL stores f32: moments and volumes that agree to f32 precision are taken as equal.
        let is_stl = path
            .extension()
            .is_some_and(|e| e.to_string_lossy().eq_ignore_ascii_case("stl"));
        let (moment_tol, convexity_tol) = if is_stl {
            (super::MOMENT_TOL_F32, CONVEXITY_TOL_F32)
        } else {
            (super::MOMENT_TOL, CONVEXITY_TOL)
        };
        let (template, hull_volume) =
            ConvexTemplate::build(&name, &mesh.vertices, &source, moment_tol)?;
        let mesh_volume = mesh.mass_properties().map(|m| m.volume);
        let added_volume = mesh_volume.map_or(0.0, |v| hull_volume - v);
        if let Some(v) = mesh_volume {
            if added_volume > convexity_tol * hull_volume {
                tracing::warn!(
                    "{}: mesh is not convex; using its convex hull, which adds {:.6e} to its volume {:.6e} ({:.4}%)",
                    path.display(),
                    added_volume,
                    v,
                    100.0 * added_volume / v
                );
            } else if added_volume < -convexity_tol * hull_volume {
                tracing::warn!(
                    "{}: mesh volume {:.6e} exceeds its convex hull's {:.6e}: the mesh self-intersects",
                    path.display(),
                    v,
                    hull_volume
                );
            }
        } else {
            tracing::debug!(
                "{}: mesh is not closed; its volume is not compared with the hull's",
                path.display()
            );
        }
        Ok((
            template,
            ImportReport {
                mesh_volume,
                hull_volume,
                added_volume,
            },
        ))
    }
}
