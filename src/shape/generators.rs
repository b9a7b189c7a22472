//! Built-in particle shapes: the Platonic solids, cuboids, n-gon prisms (cylinders) and seeded
//! random hulls ("mineral grains"), as used in the seed paper's validation and application cases
//! (dodecahedra in Secs. 3.3–3.4, a 20-gon cylinder in Sec. 3.1, an 18-vertex mineral grain in
//! Sec. 4.2, 5.5 mm catalyst cylinders in Sec. 4.3).

use super::{ConvexTemplate, MAX_TEMPLATE_FACES, MeshFile, ShapeError};
use crate::rng::Rng;
use nalgebra::{Point3, Vector3};
use std::f64::consts::{PI, TAU};

/// The golden ratio φ = (1 + √5)/2, which fixes the dodecahedron's and icosahedron's vertices.
const PHI: f64 = 1.618_033_988_749_895;

/// A parametric particle shape. Regular solids are centred at the origin in their natural
/// orientation (cube axis-aligned; octahedron vertices on the axes; dodecahedron and icosahedron
/// in the standard golden-ratio coordinates), with `size` the diameter of the circumscribed sphere.
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Generator {
    /// Regular tetrahedron, vertices at alternate corners of a cube.
    Tetrahedron { size: f64 },
    /// Cube with edges along the axes (edge = size/√3).
    Cube { size: f64 },
    /// Rectangular box with edges a, b, c along x, y, z.
    Cuboid { a: f64, b: f64, c: f64 },
    /// Regular octahedron with vertices on the axes.
    Octahedron { size: f64 },
    /// Regular dodecahedron, vertices (±1,±1,±1), (0,±1/φ,±φ) and cyclic permutations.
    Dodecahedron { size: f64 },
    /// Regular icosahedron, vertices (0,±1,±φ) and cyclic permutations.
    Icosahedron { size: f64 },
    /// Right prism over a regular n-gon (a faceted cylinder) with its axis along z: `diameter` is
    /// the n-gon's circumscribed diameter, one vertex on +x; centred at the origin.
    Prism {
        sides: usize,
        diameter: f64,
        height: f64,
    },
    /// Convex hull of `points` seeded-random points on an ellipsoid whose semi-axes are in the
    /// ratio `aspect` with the largest equal to `size / 2`. Every point is an extreme point, so
    /// the hull has `points` vertices and, generically, 2·points − 4 triangular faces.
    RandomHull {
        points: usize,
        size: f64,
        seed: u64,
        aspect: [f64; 3],
    },
    /// Sphere of diameter `size`: an exact sphere for contacts and mass properties (the sphere
    /// fast path, [`crate::geometry::sphere`]), drawn as an 80-face geodesic polyhedron.
    Sphere { size: f64 },
}

/// Most sides of a [`Generator::Prism`]: it has `sides + 2` faces, at most
/// [`MAX_TEMPLATE_FACES`].
pub const MAX_PRISM_SIDES: usize = MAX_TEMPLATE_FACES - 2;

/// Most points of a [`Generator::RandomHull`]: all are extreme, so its hull has `2·points − 4`
/// faces, at most [`MAX_TEMPLATE_FACES`].
pub const MAX_RANDOM_HULL_POINTS: usize = (MAX_TEMPLATE_FACES + 4) / 2;

/// Names accepted by [`Generator::parse`].
pub const GENERATOR_NAMES: [&str; 6] = [
    "tetrahedron",
    "cube",
    "octahedron",
    "dodecahedron",
    "icosahedron",
    "sphere",
];

impl Generator {
    /// The regular solid called `name` (one of [`GENERATOR_NAMES`], case-insensitive) with
    /// circumscribed diameter `size`.
    pub fn parse(name: &str, size: f64) -> Result<Generator, ShapeError> {
        let g = match name.trim().to_ascii_lowercase().as_str() {
            "tetrahedron" => Generator::Tetrahedron { size },
            "cube" => Generator::Cube { size },
            "octahedron" => Generator::Octahedron { size },
            "dodecahedron" => Generator::Dodecahedron { size },
            "icosahedron" => Generator::Icosahedron { size },
            "sphere" => Generator::Sphere { size },
            _ => {
                return Err(ShapeError::BadParameter {
                    source_name: name.to_string(),
                    message: format!(
                        "unknown shape generator; allowed: {}",
                        GENERATOR_NAMES.join(", ")
                    ),
                });
            }
        };
        g.check()?;
        Ok(g)
    }

    /// Short name, used as the template's name and in errors (e.g. "dodecahedron", "prism20").
    pub fn name(&self) -> String {
        match self {
            Generator::Tetrahedron { .. } => "tetrahedron".into(),
            Generator::Cube { .. } => "cube".into(),
            Generator::Cuboid { .. } => "cuboid".into(),
            Generator::Octahedron { .. } => "octahedron".into(),
            Generator::Dodecahedron { .. } => "dodecahedron".into(),
            Generator::Icosahedron { .. } => "icosahedron".into(),
            Generator::Prism { sides, .. } => format!("prism{sides}"),
            Generator::RandomHull { points, seed, .. } => format!("random_hull{points}_seed{seed}"),
            Generator::Sphere { .. } => "sphere".into(),
        }
    }

    /// Validates the parameters: lengths positive and finite, 3 to [`MAX_PRISM_SIDES`] sides,
    /// 4 to [`MAX_RANDOM_HULL_POINTS`] points.
    fn check(&self) -> Result<(), ShapeError> {
        let bad = |message: String| ShapeError::BadParameter {
            source_name: self.name(),
            message,
        };
        let length = |what: &str, x: f64| {
            if x > 0.0 && x.is_finite() {
                Ok(())
            } else {
                Err(bad(format!("{what} must be positive and finite, got {x}")))
            }
        };
        match self {
            Generator::Tetrahedron { size }
            | Generator::Cube { size }
            | Generator::Octahedron { size }
            | Generator::Dodecahedron { size }
            | Generator::Icosahedron { size }
            | Generator::Sphere { size } => length("size", *size),
            Generator::Cuboid { a, b, c } => {
                length("a", *a)?;
                length("b", *b)?;
                length("c", *c)
            }
            Generator::Prism {
                sides,
                diameter,
                height,
            } => {
                if *sides < 3 {
                    return Err(bad(format!("a prism needs at least 3 sides, got {sides}")));
                }
                // Refused before the points are made: a prism has sides + 2 faces, and building
                // the hull of 10⁴ sides only to refuse it takes minutes.
                if *sides > MAX_PRISM_SIDES {
                    return Err(bad(format!(
                        "sides = {sides}: a prism has sides + 2 faces and a template at most \
                         {MAX_TEMPLATE_FACES} (MAX_TEMPLATE_FACES), so sides must be 3 to \
                         {MAX_PRISM_SIDES}"
                    )));
                }
                length("diameter", *diameter)?;
                length("height", *height)
            }
            Generator::RandomHull {
                points,
                size,
                aspect,
                ..
            } => {
                if *points < 4 {
                    return Err(bad(format!(
                        "a random hull needs at least 4 points, got {points}"
                    )));
                }
                // Every point is extreme, so the hull has 2·points − 4 faces: refused before
                // drawing them (10⁷ points would take minutes and gigabytes).
                if *points > MAX_RANDOM_HULL_POINTS {
                    return Err(bad(format!(
                        "points = {points}: a random hull of n points has 2n − 4 faces and a \
                         template at most {MAX_TEMPLATE_FACES} (MAX_TEMPLATE_FACES), so points \
                         must be 4 to {MAX_RANDOM_HULL_POINTS}"
                    )));
                }
                length("size", *size)?;
                for (k, a) in aspect.iter().enumerate() {
                    length(&format!("aspect[{k}]"), *a)?;
                }
                Ok(())
            }
        }
    }

    /// The generating points (not yet in the principal frame).
    pub fn points(&self) -> Result<Vec<Point3<f64>>, ShapeError> {
        self.check()?;
        let scaled = |pts: Vec<[f64; 3]>, circumradius: f64, size: f64| {
            let k = size / 2.0 / circumradius;
            pts.into_iter()
                .map(|p| Point3::new(p[0] * k, p[1] * k, p[2] * k))
                .collect()
        };
        let pts = match self {
            Generator::Tetrahedron { size } => scaled(
                vec![
                    [1.0, 1.0, 1.0],
                    [1.0, -1.0, -1.0],
                    [-1.0, 1.0, -1.0],
                    [-1.0, -1.0, 1.0],
                ],
                3f64.sqrt(),
                *size,
            ),
            Generator::Cube { size } => scaled(signs3(1.0, 1.0, 1.0), 3f64.sqrt(), *size),
            Generator::Cuboid { a, b, c } => signs3(a / 2.0, b / 2.0, c / 2.0)
                .into_iter()
                .map(|p| Point3::new(p[0], p[1], p[2]))
                .collect(),
            Generator::Octahedron { size } => {
                let mut v = Vec::new();
                for k in 0..3 {
                    for s in [1.0, -1.0] {
                        let mut p = [0.0; 3];
                        p[k] = s;
                        v.push(p);
                    }
                }
                scaled(v, 1.0, *size)
            }
            Generator::Dodecahedron { size } => {
                let mut v = signs3(1.0, 1.0, 1.0);
                v.extend(cyclic(0.0, 1.0 / PHI, PHI));
                scaled(v, 3f64.sqrt(), *size)
            }
            Generator::Icosahedron { size } => {
                scaled(cyclic(0.0, 1.0, PHI), (1.0 + PHI * PHI).sqrt(), *size)
            }
            Generator::Sphere { size } => geodesic_points(*size / 2.0),
            Generator::Prism {
                sides,
                diameter,
                height,
            } => prism_points(*sides, *diameter, *height),
            Generator::RandomHull {
                points,
                size,
                seed,
                aspect,
            } => {
                let amax = aspect.iter().fold(0.0f64, |m, a| m.max(*a));
                let semi = aspect.map(|a| a / amax * size / 2.0);
                let mut rng = Rng::new(*seed);
                (0..*points)
                    .map(|_| {
                        let u = rng.unit_vector();
                        Point3::new(u[0] * semi[0], u[1] * semi[1], u[2] * semi[2])
                    })
                    .collect()
            }
        };
        Ok(pts)
    }

    /// Builds the template (convex hull, merged faces, principal frame) of this shape.
    pub fn build(&self) -> Result<ConvexTemplate, ShapeError> {
        let t = ConvexTemplate::from_points(&self.name(), &self.points()?)?;
        Ok(match self {
            Generator::Sphere { size } => t.into_sphere(size / 2.0),
            _ => t,
        })
    }
}

/// The 42 vertices of the icosahedron with each edge split at its midpoint, projected onto the
/// sphere of radius `r` (a geodesic polyhedron of 80 triangles): the drawing of a sphere.
fn geodesic_points(r: f64) -> Vec<Point3<f64>> {
    let ico: Vec<Vector3<f64>> = cyclic(0.0, 1.0, PHI)
        .into_iter()
        .map(|p| Vector3::new(p[0], p[1], p[2]).normalize())
        .collect();
    let mut pts: Vec<Vector3<f64>> = ico.clone();
    // The 30 edges join the vertex pairs at the smallest distance.
    let mut edge = f64::MAX;
    for i in 0..ico.len() {
        for j in i + 1..ico.len() {
            edge = edge.min((ico[i] - ico[j]).norm());
        }
    }
    for i in 0..ico.len() {
        for j in i + 1..ico.len() {
            if (ico[i] - ico[j]).norm() < edge * 1.01 {
                pts.push((ico[i] + ico[j]).normalize());
            }
        }
    }
    pts.into_iter().map(|v| Point3::from(v * r)).collect()
}

/// The 8 points (±a, ±b, ±c).
fn signs3(a: f64, b: f64, c: f64) -> Vec<[f64; 3]> {
    let mut v = Vec::with_capacity(8);
    for sx in [1.0, -1.0] {
        for sy in [1.0, -1.0] {
            for sz in [1.0, -1.0] {
                v.push([sx * a, sy * b, sz * c]);
            }
        }
    }
    v
}

/// The points (a, ±b, ±c) and their cyclic permutations (12 points; `a` is not signed, as it is
/// 0 for the dodecahedron and icosahedron).
fn cyclic(a: f64, b: f64, c: f64) -> Vec<[f64; 3]> {
    let mut v = Vec::with_capacity(12);
    for sb in [1.0, -1.0] {
        for sc in [1.0, -1.0] {
            let p = [a, sb * b, sc * c];
            v.push(p);
            v.push([p[2], p[0], p[1]]);
            v.push([p[1], p[2], p[0]]);
        }
    }
    v
}

/// Vertices of a right n-gon prism about z, one vertex on +x, centred at the origin.
fn prism_points(sides: usize, diameter: f64, height: f64) -> Vec<Point3<f64>> {
    let r = diameter / 2.0;
    let mut v = Vec::with_capacity(2 * sides);
    for z in [-height / 2.0, height / 2.0] {
        for k in 0..sides {
            let t = TAU * k as f64 / sides as f64;
            v.push(Point3::new(r * t.cos(), r * t.sin(), z));
        }
    }
    v
}

impl MeshFile {
    /// A closed triangle mesh of an n-gon prism whose caps are fans around their centre points:
    /// 2n + 2 vertices and 4n triangles, outward-wound. With n = 20 this is the seed paper's
    /// cylinder (Sec. 3.1, Fig. 9: 42 vertices, 120 edges, 80 triangular faces); loading it
    /// gives a template of 2n vertices and n + 2 faces, the cap centres being interior to caps.
    pub fn prism_with_cap_centres(
        sides: usize,
        diameter: f64,
        height: f64,
    ) -> Result<MeshFile, ShapeError> {
        Generator::Prism {
            sides,
            diameter,
            height,
        }
        .check()?;
        let mut vertices = prism_points(sides, diameter, height);
        let n = sides as u32;
        let bottom_centre = 2 * n;
        let top_centre = 2 * n + 1;
        vertices.push(Point3::new(0.0, 0.0, -height / 2.0));
        vertices.push(Point3::new(0.0, 0.0, height / 2.0));
        let mut triangles = Vec::with_capacity(4 * sides);
        for k in 0..n {
            let k1 = (k + 1) % n;
            // Bottom cap seen from below (−z) is clockwise in the xy-plane.
            triangles.push([bottom_centre, k1, k]);
            triangles.push([top_centre, n + k, n + k1]);
            triangles.push([k, k1, n + k1]);
            triangles.push([k, n + k1, n + k]);
        }
        Ok(MeshFile {
            vertices,
            triangles,
        })
    }
}

/// Closed-form volume and principal moments (per unit density) of a regular n-gon prism of
/// circumscribed diameter `d` and height `h`, axis moment last when it is the largest:
/// `V = n/2 r² sin(2π/n) h`, `I_axis = V r² (1 + 2 cos²(π/n)) / 6`, `I_⊥ = I_axis/2 + V h²/12`.
/// Returns `(V, I_⊥, I_axis)`. Used by tests and to document the seed cylinder's numbers.
pub fn prism_mass_properties(sides: usize, d: f64, h: f64) -> (f64, f64, f64) {
    let n = sides as f64;
    let r = d / 2.0;
    let v = n / 2.0 * r * r * (TAU / n).sin() * h;
    let axis = v * r * r * (1.0 + 2.0 * (PI / n).cos().powi(2)) / 6.0;
    (v, axis / 2.0 + v * h * h / 12.0, axis)
}
