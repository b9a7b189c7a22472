//! Mesh import (STL binary/ASCII through stl_io, OBJ by a small parser) and template building
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
    let bytes = std::fs::read(path).map_err(|e| unreadable(path, e.to_string()))?;
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

/// STL via stl_io. A binary STL whose 80-byte header happens to begin with "solid " (some CAD
/// exporters write that) would be taken for ASCII; when the size matches the binary layout
/// exactly (84 + 50 × count bytes) the header is blanked so stl_io reads it as binary.
fn parse_stl(bytes: &[u8]) -> std::io::Result<MeshFile> {
    let mut data = bytes.to_vec();
    if data.len() >= 84 {
        let count = u32::from_le_bytes([data[80], data[81], data[82], data[83]]) as usize;
        if data.len() == 84 + 50 * count && data.starts_with(b"solid") {
            data[..5].copy_from_slice(b"     ");
        }
    }
    let mesh = stl_io::read_stl(&mut std::io::Cursor::new(data))?;
    let vertices = mesh
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let mut triangles = Vec::with_capacity(mesh.faces.len());
    for f in &mesh.faces {
        let t = f.vertices;
        triangles.push([t[0] as u32, t[1] as u32, t[2] as u32]);
    }
    Ok(MeshFile {
        vertices,
        triangles,
    })
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
