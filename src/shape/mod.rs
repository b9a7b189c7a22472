//! Convex particle templates: hull, merged faces, mass properties, generators, STL/OBJ import.
//!
//! A [`ConvexTemplate`] is stored in its principal frame (centroid at the origin, axes along the
//! principal axes of inertia), with the rigid transform from the coordinates it was given in kept
//! in [`ConvexTemplate::file_to_body`]. Coplanar hull triangles are merged into one polygon face
//! with one outward normal (seed paper Sec. 2.1), which is what the contact kernels consume.

mod faces;
mod generators;
mod hull;
mod import;
mod mass;
mod rounding;

pub use generators::Generator;
pub use generators::{
    GENERATOR_NAMES, MAX_PRISM_SIDES, MAX_RANDOM_HULL_POINTS, prism_mass_properties,
};
pub use import::{ImportReport, MESH_EXTENSIONS};
pub use import::{MeshFile, load_mesh};
pub use mass::MassProperties;
pub use rounding::{MAX_ROUNDING, rounded, tangent_planes};

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};

/// Largest number of merged faces a template may have. The overlap kernels keep the planes of
/// both particles of a pair in fixed-capacity buffers (no allocation per pair), sized from this.
pub const MAX_TEMPLATE_FACES: usize = 128;

/// Largest number of hull vertices a template may have (support-function loops in GJK).
pub const MAX_TEMPLATE_VERTICES: usize = 256;

/// Largest number of input points (mesh vertices, a vertex list) a template is built from. A
/// template keeps at most [`MAX_TEMPLATE_VERTICES`] of them; the others lie inside or on its
/// faces, as in a finely tessellated mesh of a flat-faced particle. The hull of this many points
/// takes about a second in the worst case (every point extreme, the hull then refused by its
/// face count); a larger input is refused before any work, since its hull could take minutes
/// and gigabytes.
pub const MAX_INPUT_POINTS: usize = 100_000;

/// Principal moments equal within this fraction of the largest count as equal (degenerate
/// eigenspace: the input axes are kept there), for inputs given in f64.
pub const MOMENT_TOL: f64 = 1e-9;

/// As [`MOMENT_TOL`] for STL input, whose f32 coordinates (relative precision 6e-8) break the
/// symmetry of a cube or dodecahedron at about 1e-7.
pub const MOMENT_TOL_F32: f64 = 1e-6;

/// One merged face: a convex polygon with an outward unit normal.
#[derive(Clone, Debug, PartialEq)]
pub struct Face {
    /// Outward unit normal in the body frame.
    pub normal: Vector3<f64>,
    /// Plane offset: points x of the template satisfy `normal · x <= offset`.
    pub offset: f64,
    /// Indices into [`ConvexTemplate::vertices`], counter-clockwise seen from outside.
    pub vertices: Vec<u32>,
}

/// A convex polyhedral particle shape in its principal frame.
#[derive(Clone, Debug)]
pub struct ConvexTemplate {
    /// Human-readable name (file stem or generator name).
    pub name: String,
    /// Hull vertices in the body frame (centroid at the origin, principal axes).
    pub vertices: Vec<Point3<f64>>,
    /// Merged polygon faces with outward normals.
    pub faces: Vec<Face>,
    /// Hull edges as vertex index pairs (lower index first), each once.
    pub edges: Vec<[u32; 2]>,
    /// Volume.
    pub volume: f64,
    /// Principal moments of inertia per unit density, ascending, about the centroid.
    pub principal_inertia: Vector3<f64>,
    /// Rigid transform taking input (file) coordinates to the body frame:
    /// `x_body = file_to_body * x_file`.
    pub file_to_body: Isometry3<f64>,
    /// Largest distance from the centroid to a vertex.
    pub circumscribed_radius: f64,
    /// Radius of the sphere with the same volume, `(3V / 4π)^(1/3)`.
    pub equivalent_radius: f64,
    /// Whether the particle is an exact sphere of radius `circumscribed_radius` (the sphere fast
    /// path, docs/design.md §1): contacts use [`crate::geometry::sphere`], and `vertices`/`faces` are
    /// only its drawing.
    pub sphere: bool,
}

/// Errors building a template. Each names the source (file or generator) and the problem.
#[derive(Debug, thiserror::Error)]
pub enum ShapeError {
    #[error("{source_name}: cannot read mesh file: {message}")]
    Unreadable {
        source_name: String,
        message: String,
    },
    #[error("{source_name}: {message}")]
    Degenerate {
        source_name: String,
        message: String,
    },
    #[error("{source_name}: {message}")]
    TooLarge {
        source_name: String,
        message: String,
    },
    #[error("{source_name}: {message}")]
    BadParameter {
        source_name: String,
        message: String,
    },
}

/// Where a template came from, for error messages.
#[derive(Clone, Debug)]
pub enum ShapeSource {
    File(PathBuf),
    Named(String),
}

impl ShapeSource {
    /// The name errors use: the file path, or the generator's name.
    pub fn display_name(&self) -> String {
        match self {
            ShapeSource::File(p) => p.display().to_string(),
            ShapeSource::Named(n) => n.clone(),
        }
    }
}

impl ConvexTemplate {
    /// Template of the convex hull of `points` (seed paper Sec. 2.1): coplanar hull triangles
    /// merged into polygon faces, mass properties by signed tetrahedra, stored in the principal
    /// frame. Errors name `name` as the source.
    pub fn from_points(name: &str, points: &[Point3<f64>]) -> Result<ConvexTemplate, ShapeError> {
        Self::from_source(name, points, &ShapeSource::Named(name.to_string()))
    }

    /// As [`ConvexTemplate::from_points`], with errors naming `source` (e.g. the file read).
    pub fn from_source(
        name: &str,
        points: &[Point3<f64>],
        source: &ShapeSource,
    ) -> Result<ConvexTemplate, ShapeError> {
        Self::build(name, points, source, MOMENT_TOL).map(|(t, _)| t)
    }

    /// Builds the template; also returns the exact (unmerged) hull volume in input coordinates.
    ///
    /// Principal frame: with centroid c and principal axes as the columns of R (a proper
    /// rotation, moments ascending), `x_body = Rᵀ (x_file − c)`.
    pub(crate) fn build(
        name: &str,
        points: &[Point3<f64>],
        source: &ShapeSource,
        moment_tol: f64,
    ) -> Result<(ConvexTemplate, f64), ShapeError> {
        let src = source.display_name();
        let poly = hull::convex_polytope(points, &src)?;
        // The hull refuses more faces while it is built; a face that only appeared after the
        // sliver merge would still be caught here.
        if poly.faces.len() > MAX_TEMPLATE_FACES {
            return Err(hull::too_many_faces(&src, poly.faces.len()));
        }
        if poly.vertices.len() > MAX_TEMPLATE_VERTICES {
            return Err(ShapeError::TooLarge {
                source_name: src.clone(),
                message: format!(
                    "convex hull has {} vertices, more than the limit {MAX_TEMPLATE_VERTICES} \
                     (MAX_TEMPLATE_VERTICES); simplify the mesh (decimate it or use fewer facets)",
                    poly.vertices.len()
                ),
            });
        }
        let mass =
            MassProperties::from_triangles(&poly.vertices, &fan(&poly.faces)).ok_or_else(|| {
                ShapeError::Degenerate {
                    source_name: src.clone(),
                    message: "the convex hull has no volume".to_string(),
                }
            })?;
        let (axes, moments) = mass::principal_frame(&mass.inertia, moment_tol);
        let rot = Rotation3::from_matrix_unchecked(axes.transpose());
        let c = mass.centroid.coords;
        let file_to_body = Isometry3::from_parts(
            Translation3::from(-(rot * c)),
            UnitQuaternion::from_rotation_matrix(&rot),
        );
        let vertices: Vec<Point3<f64>> = poly
            .vertices
            .iter()
            .map(|p| Point3::from(rot * (p.coords - c)))
            .collect();
        let faces = poly
            .faces
            .iter()
            .map(|f| {
                let normal = (rot * f.normal).normalize();
                Face {
                    offset: plane_offset(&normal, &vertices),
                    normal,
                    vertices: f.vertices.clone(),
                }
            })
            .collect();
        let circumscribed_radius = vertices.iter().map(|v| v.coords.norm()).fold(0.0, f64::max);
        let template = ConvexTemplate {
            name: name.to_string(),
            vertices,
            faces,
            edges: poly.edges,
            volume: mass.volume,
            principal_inertia: moments,
            file_to_body,
            circumscribed_radius,
            equivalent_radius: (3.0 * mass.volume / (4.0 * std::f64::consts::PI)).cbrt(),
            sphere: false,
        };
        Ok((template, poly.exact_hull_volume))
    }

    /// The template scaled uniformly by `s` about its centroid: lengths × s, volume × s³,
    /// inertia per unit density × s⁵. `file_to_body` then maps the input coordinates scaled by
    /// `s` (its translation is scaled). `s` must be positive and finite.
    pub fn scaled(&self, s: f64) -> Result<ConvexTemplate, ShapeError> {
        if !(s > 0.0 && s.is_finite()) {
            return Err(ShapeError::BadParameter {
                source_name: self.name.clone(),
                message: format!("scale factor {s} must be a positive finite number"),
            });
        }
        let mut t = self.clone();
        for v in &mut t.vertices {
            v.coords *= s;
        }
        for f in &mut t.faces {
            f.offset *= s;
        }
        t.volume *= s * s * s;
        t.principal_inertia *= s.powi(5);
        t.file_to_body.translation.vector *= s;
        t.circumscribed_radius *= s;
        t.equivalent_radius *= s;
        Ok(t)
    }

    /// This polyhedron as the drawing of an exact sphere of radius `r` about the centroid: the
    /// mass properties become the sphere's (`V = 4πr³/3`, `I = 2Vr²/5` per unit density), both
    /// radii `r`, and contacts use the sphere formulas.
    pub(crate) fn into_sphere(mut self, r: f64) -> ConvexTemplate {
        let volume = 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
        self.volume = volume;
        self.principal_inertia = Vector3::repeat(0.4 * volume * r * r);
        self.circumscribed_radius = r;
        self.equivalent_radius = r;
        self.file_to_body = Isometry3::identity();
        self.sphere = true;
        self
    }

    /// Largest number of vertices on one face (sizes the clipping buffers).
    pub fn max_face_vertices(&self) -> usize {
        self.faces
            .iter()
            .map(|f| f.vertices.len())
            .max()
            .unwrap_or(0)
    }

    /// Fan triangulation of the faces (each face (v0, v1, …, vk) → (v0, vi, vi+1)), outward-wound;
    /// the faces are strictly convex, so every fan triangle has positive area.
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        fan(&self.faces)
    }

    /// Inertia tensor per unit density in the body frame: `diag(principal_inertia)`.
    pub fn inertia_tensor(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal(&self.principal_inertia)
    }

    /// The body-frame surface as a triangle mesh ([`ConvexTemplate::triangles`]).
    pub fn mesh(&self) -> MeshFile {
        MeshFile {
            vertices: self.vertices.clone(),
            triangles: self.triangles(),
        }
    }

    /// Writes the body-frame surface as binary STL (fan-triangulated faces, f32 coordinates).
    pub fn write_stl(&self, path: &Path) -> std::io::Result<()> {
        self.mesh().write_stl(path)
    }
}

/// Fan triangulation of polygon faces.
fn fan(faces: &[Face]) -> Vec<[u32; 3]> {
    let mut tris = Vec::new();
    for f in faces {
        for k in 1..f.vertices.len().saturating_sub(1) {
            tris.push([f.vertices[0], f.vertices[k], f.vertices[k + 1]]);
        }
    }
    tris
}

/// Plane offset of a face: the support value `max_v n · v` over all vertices. For an exactly
/// planar face this is `n · v` of its own vertices to rounding; for a face merged within the
/// coplanarity tolerance it keeps every vertex inside every face plane (`n · v <= offset` for all
/// vertices and faces), so the half-space and vertex descriptions contain each other and the
/// contact kernels can rely on it.
fn plane_offset(n: &Vector3<f64>, vertices: &[Point3<f64>]) -> f64 {
    vertices
        .iter()
        .map(|v| n.dot(&v.coords))
        .fold(f64::NEG_INFINITY, f64::max)
}
