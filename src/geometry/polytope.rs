//! A convex template placed in a pair frame: its vertices (for support functions) and its face
//! planes (for the half-space intersection), in fixed-capacity storage.

use super::Real;
use crate::shape::{ConvexTemplate, MAX_TEMPLATE_FACES, MAX_TEMPLATE_VERTICES};
use nalgebra::{Isometry3, Vector3};

/// A half-space `normal · x <= offset` with a unit outward normal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Plane<T: Real> {
    /// Outward unit normal.
    pub normal: Vector3<T>,
    /// Offset along the normal: the plane is `normal · x = offset`.
    pub offset: T,
}

impl<T: Real> Plane<T> {
    /// Signed distance of `x` from the plane, positive outside.
    #[inline]
    pub fn distance(&self, x: &Vector3<T>) -> T {
        self.normal.dot(x) - self.offset
    }
}

/// Vertices and face planes of one convex body in a pair frame, without heap storage, so that
/// a pair evaluation allocates nothing (the shape the GPU kernel has).
#[derive(Clone, Debug)]
pub struct PosedPolytope<T: Real> {
    vertices: [Vector3<T>; MAX_TEMPLATE_VERTICES],
    n_vertices: usize,
    planes: [Plane<T>; MAX_TEMPLATE_FACES],
    /// Template face of each plane slot (planes can be culled, see
    /// [`PosedPolytope::retain_planes_cutting`]).
    face: [u16; MAX_TEMPLATE_FACES],
    n_planes: usize,
    /// The body's centroid (reference point of its pose) in the pair frame.
    pub centre: Vector3<T>,
}

impl<T: Real> Default for PosedPolytope<T> {
    fn default() -> Self {
        PosedPolytope {
            vertices: [Vector3::zeros(); MAX_TEMPLATE_VERTICES],
            n_vertices: 0,
            planes: [Plane::default(); MAX_TEMPLATE_FACES],
            face: [0; MAX_TEMPLATE_FACES],
            n_planes: 0,
            centre: Vector3::zeros(),
        }
    }
}

impl<T: Real> PosedPolytope<T> {
    /// Places `template`, scaled by `scale`, at `pose` (body frame → world), expressed in a frame
    /// whose origin is the world point `origin`: `x = R (s v) + (t − origin)`.
    ///
    /// The subtraction `t − origin` is done in f64 before rounding to `T`: this is the
    /// "relative coordinates" rule of DESIGN.md §3 that makes f32 pair geometry viable.
    pub fn place(
        &mut self,
        template: &ConvexTemplate,
        scale: f64,
        pose: &Isometry3<f64>,
        origin: &Vector3<f64>,
    ) {
        let rot = pose.rotation.to_rotation_matrix();
        let shift = pose.translation.vector - origin;
        self.n_vertices = template.vertices.len().min(MAX_TEMPLATE_VERTICES);
        for (dst, v) in self.vertices.iter_mut().zip(&template.vertices) {
            *dst = cast(&(rot * (v.coords * scale) + shift));
        }
        self.n_planes = template.faces.len().min(MAX_TEMPLATE_FACES);
        for (i, slot) in self.face[..self.n_planes].iter_mut().enumerate() {
            *slot = i as u16;
        }
        self.reposition_planes(template, scale, pose, origin);
    }

    /// Recomputes the planes in use (after culling, only those kept) for the frame origin
    /// `origin`; the vertices are left as they were.
    pub fn reposition_planes(
        &mut self,
        template: &ConvexTemplate,
        scale: f64,
        pose: &Isometry3<f64>,
        origin: &Vector3<f64>,
    ) {
        let rot = pose.rotation.to_rotation_matrix();
        let shift = pose.translation.vector - origin;
        self.centre = cast(&shift);
        for (dst, &k) in self.planes.iter_mut().zip(&self.face[..self.n_planes]) {
            let f = &template.faces[k as usize];
            let n = rot * f.normal;
            *dst = Plane {
                normal: cast(&n),
                offset: T::of(f.offset * scale + n.dot(&shift)),
            };
        }
    }

    /// A polytope given directly by its vertices and planes (already in the pair frame).
    /// Input beyond the fixed capacities is ignored; callers check sizes first.
    pub fn set(&mut self, vertices: &[Vector3<T>], planes: &[Plane<T>], centre: Vector3<T>) {
        self.n_vertices = vertices.len().min(MAX_TEMPLATE_VERTICES);
        self.vertices[..self.n_vertices].copy_from_slice(&vertices[..self.n_vertices]);
        self.n_planes = planes.len().min(MAX_TEMPLATE_FACES);
        self.planes[..self.n_planes].copy_from_slice(&planes[..self.n_planes]);
        for (i, slot) in self.face[..self.n_planes].iter_mut().enumerate() {
            *slot = i as u16;
        }
        self.centre = centre;
    }

    /// Drops the planes that cannot bound the intersection with a body whose vertices are
    /// `other`: a half-space that contains all of the other body contains the whole
    /// intersection. This is exact, and for a shallow contact it leaves only the few faces near
    /// it, which is what the dual hull's cost grows with. Planes within round-off of touching the
    /// other body are kept.
    pub fn retain_planes_cutting(&mut self, other: &[Vector3<T>]) {
        let tol = T::of(64.0) * T::EPSILON * self.radius();
        let mut kept = 0;
        for i in 0..self.n_planes {
            let p = self.planes[i];
            if other.iter().any(|v| p.distance(v) > -tol) {
                self.planes[kept] = p;
                self.face[kept] = self.face[i];
                kept += 1;
            }
        }
        self.n_planes = kept;
    }

    /// The placed vertices.
    pub fn vertices(&self) -> &[Vector3<T>] {
        &self.vertices[..self.n_vertices]
    }

    /// The placed face planes.
    pub fn planes(&self) -> &[Plane<T>] {
        &self.planes[..self.n_planes]
    }

    /// Largest distance from the centre to a vertex.
    pub fn radius(&self) -> T {
        self.vertices()
            .iter()
            .map(|v| (v - self.centre).norm())
            .fold(T::zero(), |a, b| a.max(b))
    }
}

/// Rounds an f64 vector to `T`.
#[inline]
pub fn cast<T: Real>(v: &Vector3<f64>) -> Vector3<T> {
    Vector3::new(T::of(v.x), T::of(v.y), T::of(v.z))
}

/// Widens a `T` vector to f64.
#[inline]
pub fn widen<T: Real>(v: &Vector3<T>) -> Vector3<f64> {
    Vector3::new(v.x.f64(), v.y.f64(), v.z.f64())
}
