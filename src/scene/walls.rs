//! Walls: triangle meshes read from STL/OBJ, placed by scale → rotate → translate, and moved
//! by a prescribed rigid motion.
//!
//! Winding convention: each triangle `[a, b, c]` is counter-clockwise seen from the side the
//! particles are on, so `(b − a) × (c − a)` points towards the particles. A mesh exported the
//! other way round is fixed with `flip_normals = true` in the scene file.

use super::schema;
use crate::shape::{MeshFile, load_mesh};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::f64::consts::TAU;
use std::path::Path;

/// A wall: triangles at time 0 in world coordinates, a material and a motion.
#[derive(Clone, Debug)]
pub struct Wall {
    /// Name for output and logs (the `name` key, else the mesh file's stem).
    pub name: String,
    /// Triangles after scale, rotation and translation, wound counter-clockwise seen from the
    /// particles' side (normal `(b − a) × (c − a)` towards the particles).
    pub triangles: Vec<[Vector3<f64>; 3]>,
    /// Index into [`super::Scene::materials`].
    pub material: usize,
    /// Prescribed motion; the pose at time t is `motion.transform(t) * triangles`.
    pub motion: WallMotion,
}

impl Wall {
    /// The triangles at time `t` (world coordinates).
    pub fn triangles_at(&self, t: f64) -> Vec<[Vector3<f64>; 3]> {
        let pose = self.motion.transform(t);
        self.triangles
            .iter()
            .map(|tri| tri.map(|p| pose.transform_point(&p.into()).coords))
            .collect()
    }
}

/// A prescribed rigid wall motion. All motions start at t = 0 from the placed mesh.
#[derive(Clone, Debug, PartialEq)]
pub enum WallMotion {
    /// At rest.
    Fixed,
    /// Constant-rate rotation about the line through `origin` along `axis` (right-handed);
    /// ω = 2π·rpm/60 rad/s. Negative rpm turns the other way.
    Rotate {
        axis: Unit<Vector3<f64>>,
        origin: Vector3<f64>,
        rpm: f64,
    },
    /// Constant velocity (m/s).
    Translate { velocity: Vector3<f64> },
    /// Oscillation `x(t) = amplitude · sin(2π·frequency·t) · direction`.
    Sinusoidal {
        direction: Unit<Vector3<f64>>,
        /// (m)
        amplitude: f64,
        /// (Hz)
        frequency: f64,
    },
}

impl WallMotion {
    /// Whether the wall never moves.
    pub fn is_static(&self) -> bool {
        matches!(self, WallMotion::Fixed)
    }

    /// Angular speed ω (rad/s) of a rotation, from rpm.
    pub fn omega(rpm: f64) -> f64 {
        TAU * rpm / 60.0
    }

    /// Pose of the wall at time `t` relative to t = 0: a point `p` of the placed mesh is at
    /// `transform(t) * p`.
    pub fn transform(&self, t: f64) -> Isometry3<f64> {
        match self {
            WallMotion::Fixed => Isometry3::identity(),
            WallMotion::Rotate { axis, origin, rpm } => {
                // x' = o + R (x − o): rotation R followed by translation o − R o.
                let r = UnitQuaternion::from_axis_angle(axis, Self::omega(*rpm) * t);
                Isometry3::from_parts(Translation3::from(origin - r * origin), r)
            }
            WallMotion::Translate { velocity } => {
                Isometry3::from_parts(Translation3::from(velocity * t), UnitQuaternion::identity())
            }
            WallMotion::Sinusoidal {
                direction,
                amplitude,
                frequency,
            } => {
                let s = amplitude * (TAU * frequency * t).sin();
                Isometry3::from_parts(
                    Translation3::from(direction.into_inner() * s),
                    UnitQuaternion::identity(),
                )
            }
        }
    }

    /// Velocity at time `t` of the wall material point that is at `point_world` at that time.
    pub fn velocity_at(&self, t: f64, point_world: &Vector3<f64>) -> Vector3<f64> {
        match self {
            WallMotion::Fixed => Vector3::zeros(),
            // The axis line is fixed, so v = ω × (p − o) holds at every t.
            WallMotion::Rotate { axis, origin, rpm } => {
                (axis.into_inner() * Self::omega(*rpm)).cross(&(point_world - origin))
            }
            WallMotion::Translate { velocity } => *velocity,
            WallMotion::Sinusoidal {
                direction,
                amplitude,
                frequency,
            } => {
                direction.into_inner() * (TAU * frequency * amplitude * (TAU * frequency * t).cos())
            }
        }
    }

    /// The largest speed of a point of `triangles` under this motion (m/s): for a rotation, the
    /// point farthest from the axis; for an oscillation, the peak speed 2πfA.
    pub fn max_speed(&self, triangles: &[[Vector3<f64>; 3]]) -> f64 {
        match self {
            WallMotion::Fixed => 0.0,
            WallMotion::Translate { velocity } => velocity.norm(),
            WallMotion::Sinusoidal {
                amplitude,
                frequency,
                ..
            } => TAU * frequency * amplitude.abs(),
            WallMotion::Rotate { axis, origin, rpm } => {
                let omega = Self::omega(*rpm).abs();
                triangles
                    .iter()
                    .flatten()
                    .map(|x| {
                        let r = x - origin;
                        (r - axis.into_inner() * r.dot(axis)).norm() * omega
                    })
                    .fold(0.0, f64::max)
            }
        }
    }

    /// Angular velocity of the wall (rad/s) (zero except for rotation).
    pub fn angular_velocity(&self) -> Vector3<f64> {
        match self {
            WallMotion::Rotate { axis, rpm, .. } => axis.into_inner() * Self::omega(*rpm),
            _ => Vector3::zeros(),
        }
    }
}

/// How a wall mesh is placed: `x_world = translate + R (scale · x_file)`, then optional flip.
#[derive(Clone, Debug, PartialEq)]
pub struct WallPlacement {
    /// Uniform scale factor (> 0).
    pub scale: f64,
    /// Rotation applied after scaling.
    pub rotation: UnitQuaternion<f64>,
    /// Translation applied last (m).
    pub translation: Vector3<f64>,
    /// Reverse the winding of every triangle.
    pub flip_normals: bool,
}

impl Default for WallPlacement {
    fn default() -> Self {
        WallPlacement {
            scale: 1.0,
            rotation: UnitQuaternion::identity(),
            translation: Vector3::zeros(),
            flip_normals: false,
        }
    }
}

/// A wall mesh after placement, with what was dropped on the way.
#[derive(Clone, Debug)]
pub struct PlacedMesh {
    /// Placed triangles.
    pub triangles: Vec<[Vector3<f64>; 3]>,
    /// Triangles of the file with (numerically) zero area, left out because they have no normal.
    pub dropped_degenerate: usize,
}

/// Reads `path` (STL/OBJ) and places its triangles. Errors are plain messages; the caller adds
/// the file and key.
pub fn load_wall_mesh(path: &Path, placement: &WallPlacement) -> Result<PlacedMesh, String> {
    let mesh = load_mesh(path).map_err(|e| e.to_string())?;
    place_mesh(&mesh, placement)
}

/// Places the triangles of `mesh`; degenerate triangles are dropped and counted.
pub fn place_mesh(mesh: &MeshFile, placement: &WallPlacement) -> Result<PlacedMesh, String> {
    let mut triangles = Vec::with_capacity(mesh.triangles.len());
    let mut dropped = 0;
    for (k, t) in mesh.triangles.iter().enumerate() {
        let mut tri = [Vector3::zeros(); 3];
        for (slot, &i) in tri.iter_mut().zip(t.iter()) {
            let p = mesh.vertices.get(i as usize).ok_or_else(|| {
                format!(
                    "triangle {k} refers to vertex {i}, but the mesh has {} vertices",
                    mesh.vertices.len()
                )
            })?;
            if p.coords.iter().any(|x| !x.is_finite()) {
                return Err(format!(
                    "triangle {k} has a non-finite vertex coordinate {:?}",
                    p.coords.as_slice()
                ));
            }
            *slot = placement.translation + placement.rotation * (p.coords * placement.scale);
        }
        if placement.flip_normals {
            tri.swap(1, 2);
        }
        let area2 = (tri[1] - tri[0]).cross(&(tri[2] - tri[0])).norm();
        let size = (tri[1] - tri[0]).norm().max((tri[2] - tri[0]).norm());
        // Relative to the squared edge length, so the test does not depend on the units.
        if area2 <= 1e-12 * size * size {
            dropped += 1;
            continue;
        }
        triangles.push(tri);
    }
    if triangles.is_empty() {
        return Err(format!(
            "the mesh has no triangles of non-zero area ({} in the file)",
            mesh.triangles.len()
        ));
    }
    Ok(PlacedMesh {
        triangles,
        dropped_degenerate: dropped,
    })
}

/// Wall triangles at one time, each with its bounding box for a quick reject.
pub(super) struct WallTriangles {
    tris: Vec<BoxedTriangle>,
}

/// A triangle with its bounding box corners.
type BoxedTriangle = ([Vector3<f64>; 3], Vector3<f64>, Vector3<f64>);

impl WallTriangles {
    /// The walls' triangles at their poses at `t`, or those whose bounding box meets one of
    /// the boxes `near` (a sphere inside such a box is at least its radius from the others, so
    /// [`Self::is_free`] answers the same for it).
    pub(super) fn at(
        scene: &super::Scene,
        t: f64,
        near: Option<&[(Vector3<f64>, Vector3<f64>)]>,
    ) -> Self {
        let meets =
            |lo: &Vector3<f64>, hi: &Vector3<f64>, boxes: &[(Vector3<f64>, Vector3<f64>)]| {
                boxes
                    .iter()
                    .any(|(a, b)| (0..3).all(|k| lo[k] <= b[k] && hi[k] >= a[k]))
            };
        let bounds = |tri: &[Vector3<f64>; 3]| {
            (
                tri[0].inf(&tri[1]).inf(&tri[2]),
                tri[0].sup(&tri[1]).sup(&tri[2]),
            )
        };
        let mut tris = Vec::new();
        for w in &scene.walls {
            let pose = w.motion.transform(t);
            // The boxes in the wall's own frame (the bounding boxes of their preimages), so
            // that only the triangles that can meet them are moved to the pose.
            let local: Option<Vec<(Vector3<f64>, Vector3<f64>)>> = near.map(|boxes| {
                let inverse = pose.inverse();
                boxes
                    .iter()
                    .map(|(a, b)| {
                        let corners = (0..8).map(|c| {
                            let x = Vector3::new(
                                if c & 1 == 0 { a.x } else { b.x },
                                if c & 2 == 0 { a.y } else { b.y },
                                if c & 4 == 0 { a.z } else { b.z },
                            );
                            inverse.transform_point(&x.into()).coords
                        });
                        corners.fold(
                            (
                                Vector3::repeat(f64::INFINITY),
                                Vector3::repeat(f64::NEG_INFINITY),
                            ),
                            |(lo, hi), x| (lo.inf(&x), hi.sup(&x)),
                        )
                    })
                    .collect()
            });
            for tri in &w.triangles {
                if let Some(boxes) = &local {
                    let (lo, hi) = bounds(tri);
                    if !meets(&lo, &hi, boxes) {
                        continue;
                    }
                }
                let tri = tri.map(|p| pose.transform_point(&p.into()).coords);
                let (lo, hi) = bounds(&tri);
                if near.is_none_or(|boxes| meets(&lo, &hi, boxes)) {
                    tris.push((tri, lo, hi));
                }
            }
        }
        WallTriangles { tris }
    }

    pub(super) fn is_free(&self, c: &Vector3<f64>, r: f64) -> bool {
        self.tris.iter().all(|(tri, lo, hi)| {
            let outside_box = (0..3).any(|a| c[a] + r < lo[a] || c[a] - r > hi[a]);
            outside_box || crate::contact::wall::point_triangle_distance(c, tri) >= r
        })
    }
}

/// Validation of `[[walls]]`.
impl super::validate::Validator<'_> {
    pub(super) fn walls(
        &mut self,
        list: &[schema::WallSection],
        mats: &HashMap<String, usize>,
    ) -> Vec<Wall> {
        let mut out: Vec<Wall> = Vec::new();
        for (i, w) in list.iter().enumerate() {
            let k = |f: &str| format!("walls[{i}].{f}");
            let path = self.resolve(&w.mesh);
            let name = w.name.clone().unwrap_or_else(|| {
                path.file_stem()
                    .map_or(format!("wall{i}"), |s| s.to_string_lossy().into_owned())
            });
            if out.iter().any(|o| o.name == name) {
                self.err(
                    &k("name"),
                    format!("wall name \"{name}\" is used twice; give each wall a distinct name"),
                );
            }
            let material = self.material_ref(&k("material"), &w.material, mats);
            let scale = w.scale.map_or(1.0, |s| self.positive(&k("scale"), s));
            let rotation = match &w.rotate {
                Some(r) => {
                    let axis = self.direction(&k("rotate.axis"), r.axis);
                    if !r.angle.is_finite() {
                        self.err(&k("rotate.angle"), "must be a finite angle in degrees");
                    }
                    UnitQuaternion::from_axis_angle(&axis, r.angle.to_radians())
                }
                None => UnitQuaternion::identity(),
            };
            let translation = self.vector(&k("translate"), w.translate.unwrap_or_default());
            let motion = self.motion(i, w.motion.as_ref());
            let placement = WallPlacement {
                scale,
                rotation,
                translation,
                flip_normals: w.flip_normals,
            };
            let triangles = match load_wall_mesh(&path, &placement) {
                Ok(m) => {
                    if m.dropped_degenerate > 0 {
                        tracing::warn!(
                            "{}: {} zero-area triangles left out",
                            path.display(),
                            m.dropped_degenerate
                        );
                    }
                    m.triangles
                }
                Err(e) => {
                    self.err(&k("mesh"), e);
                    Vec::new()
                }
            };
            out.push(Wall {
                name,
                triangles,
                material,
                motion,
            });
        }
        out
    }

    fn motion(&mut self, i: usize, m: Option<&schema::MotionSection>) -> WallMotion {
        use schema::MotionKind as K;
        let Some(m) = m else {
            return WallMotion::Fixed;
        };
        let p = format!("walls[{i}].motion");
        let kind = match m.kind {
            K::Fixed => "fixed",
            K::Rotate => "rotate",
            K::Translate => "translate",
            K::Sinusoidal => "sinusoidal",
        };
        let present = [
            ("axis", m.axis.is_some()),
            ("origin", m.origin.is_some()),
            ("rpm", m.rpm.is_some()),
            ("velocity", m.velocity.is_some()),
            ("direction", m.direction.is_some()),
            ("amplitude", m.amplitude.is_some()),
            ("frequency", m.frequency.is_some()),
        ];
        let key = |f: &str| format!("{p}.{f}");
        match m.kind {
            K::Fixed => {
                self.only(&p, kind, &present, &[]);
                WallMotion::Fixed
            }
            K::Rotate => {
                self.only(&p, kind, &present, &["axis", "origin", "rpm"]);
                let axis = self.required(&key("axis"), kind, m.axis, [0.0, 0.0, 1.0]);
                let axis = self.direction(&key("axis"), axis);
                let origin = self.vector(&key("origin"), m.origin.unwrap_or_default());
                let rpm = self.required(&key("rpm"), kind, m.rpm, 0.0);
                if !rpm.is_finite() {
                    self.err(
                        &key("rpm"),
                        format!("must be a finite number (revolutions per minute), got {rpm}"),
                    );
                }
                WallMotion::Rotate { axis, origin, rpm }
            }
            K::Translate => {
                self.only(&p, kind, &present, &["velocity"]);
                let v = self.required(&key("velocity"), kind, m.velocity, [0.0; 3]);
                WallMotion::Translate {
                    velocity: self.vector(&key("velocity"), v),
                }
            }
            K::Sinusoidal => {
                self.only(&p, kind, &present, &["direction", "amplitude", "frequency"]);
                let d = self.required(&key("direction"), kind, m.direction, [0.0, 0.0, 1.0]);
                let direction = self.direction(&key("direction"), d);
                let a = self.required(&key("amplitude"), kind, m.amplitude, 1.0);
                let f = self.required(&key("frequency"), kind, m.frequency, 1.0);
                WallMotion::Sinusoidal {
                    direction,
                    amplitude: self.positive(&key("amplitude"), a),
                    frequency: self.positive(&key("frequency"), f),
                }
            }
        }
    }
}
