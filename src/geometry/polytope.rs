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
    /// [`PosedPolytope::retain_planes_reaching`]).
    face: [u16; MAX_TEMPLATE_FACES],
    n_planes: usize,
    /// Planes set aside by [`set_aside_faces_apart`], with their template faces.
    aside: [Plane<T>; MAX_TEMPLATE_FACES],
    aside_face: [u16; MAX_TEMPLATE_FACES],
    n_aside: usize,
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
            aside: [Plane::default(); MAX_TEMPLATE_FACES],
            aside_face: [0; MAX_TEMPLATE_FACES],
            n_aside: 0,
            centre: Vector3::zeros(),
        }
    }
}

impl<T: Real> PosedPolytope<T> {
    /// Places `template`, scaled by `scale`, at `pose` (body frame → world), expressed in a frame
    /// whose origin is the world point `origin`: `x = R (s v) + (t − origin)`.
    ///
    /// The subtraction `t − origin` is done in f64 before rounding to `T`: this is the
    /// "relative coordinates" rule of docs/design.md §3 that makes f32 pair geometry viable.
    pub fn place(
        &mut self,
        template: &ConvexTemplate,
        scale: f64,
        pose: &Isometry3<f64>,
        origin: &Vector3<f64>,
    ) {
        self.place_vertices(template, scale, pose, origin);
        self.place_planes(template, scale, pose, origin);
    }

    /// The vertex half of [`Self::place`] (for the support functions of GJK and the wall
    /// clipping); the planes are left as they were.
    pub fn place_vertices(
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
    }

    /// The face-plane half of [`Self::place`]: every plane in use, none set aside; the
    /// vertices are left as they were.
    pub fn place_planes(
        &mut self,
        template: &ConvexTemplate,
        scale: f64,
        pose: &Isometry3<f64>,
        origin: &Vector3<f64>,
    ) {
        self.n_planes = template.faces.len().min(MAX_TEMPLATE_FACES);
        self.n_aside = 0;
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
        self.n_aside = 0;
        for (i, slot) in self.face[..self.n_planes].iter_mut().enumerate() {
            *slot = i as u16;
        }
        self.centre = centre;
    }

    /// Drops the planes that cannot bound the intersection with a body inside the ball
    /// (`centre`, `radius`): a half-space that contains the ball contains the whole
    /// intersection. This is exact; planes within `tol` of touching the ball are kept. One
    /// distance per plane: the face test of [`set_aside_faces_apart`] does the fine culling.
    pub fn retain_planes_reaching(&mut self, centre: &Vector3<T>, radius: T, tol: T) {
        let mut kept = 0;
        for i in 0..self.n_planes {
            let p = self.planes[i];
            if p.distance(centre) + radius > -tol {
                self.planes[kept] = p;
                self.face[kept] = self.face[i];
                kept += 1;
            }
        }
        self.n_planes = kept;
        self.n_aside = 0;
    }

    /// The planes set aside by [`set_aside_faces_apart`] (not in [`PosedPolytope::planes`]).
    pub fn aside_planes(&self) -> &[Plane<T>] {
        &self.aside[..self.n_aside]
    }

    /// Puts the planes set aside by [`set_aside_faces_apart`] back in use, after those kept.
    pub fn restore_aside(&mut self) {
        for j in 0..self.n_aside {
            self.planes[self.n_planes] = self.aside[j];
            self.face[self.n_planes] = self.aside_face[j];
            self.n_planes += 1;
        }
        self.n_aside = 0;
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

/// Sets aside every plane of `a` whose face polygon lies strictly beyond one plane of `b` (by
/// more than round-off), and likewise for `b`: such a face does not meet the other body, so its
/// plane supports no facet of `A ∩ B`. When `A ∩ B` has an interior its facet-defining planes
/// alone define it, and the set-aside planes are redundant; for a dense packing of dodecahedra
/// this leaves 5–6 of the 12–16 planes that [`PosedPolytope::retain_planes_reaching`] keeps,
/// and the interior-point LP and the dual hull cost in proportion. When `A ∩ B` is empty or flat
/// the remaining planes can bound a larger region, so the caller keeps the result only after
/// checking an interior point against [`PosedPolytope::aside_planes`], and otherwise restores
/// them ([`PosedPolytope::restore_aside`]).
///
/// Each body comes with the template, scale and pose it was placed from, and `origin` is the
/// frame's origin: the faces are tested in the body's own frame, from the template's corners,
/// against the other body's planes carried into that frame, in f64 (one transform per plane
/// instead of one placement per corner, and the first corner settles most tests). `tol` is the
/// round-off margin (a face within it of a plane is kept). Both bodies are tested against all of
/// the other's planes in use on entry.
pub fn set_aside_faces_apart<T: Real>(
    a: &mut PosedPolytope<T>,
    body_a: (&ConvexTemplate, f64, &Isometry3<f64>),
    b: &mut PosedPolytope<T>,
    body_b: (&ConvexTemplate, f64, &Isometry3<f64>),
    origin: &Vector3<f64>,
    tol: T,
) {
    a.set_aside_beyond(body_a, origin, b.planes(), &[], tol);
    b.set_aside_beyond(
        body_b,
        origin,
        &a.planes[..a.n_planes],
        &a.aside[..a.n_aside],
        tol,
    );
}

impl<T: Real> PosedPolytope<T> {
    /// Puts the planes in use and those set aside back in template order (the order
    /// [`PosedPolytope::place`] gives), so that a body reused for the next facet is evaluated as
    /// if freshly placed.
    pub fn restore_template_order(&mut self) {
        self.restore_aside();
        for i in 1..self.n_planes {
            let mut j = i;
            while j > 0 && self.face[j - 1] > self.face[j] {
                self.face.swap(j - 1, j);
                self.planes.swap(j - 1, j);
                j -= 1;
            }
        }
    }

    /// Moves the planes whose face lies beyond one of `p ∪ q` by more than `tol` to the
    /// set-aside list, keeping both lists in order. A plane `n·x <= o` of the pair frame is, for
    /// a corner `v` of this body's template, `s (Rᵀ n)·v − (o − n·(t − origin))` from the plane.
    pub fn set_aside_beyond(
        &mut self,
        (template, scale, pose): (&ConvexTemplate, f64, &Isometry3<f64>),
        origin: &Vector3<f64>,
        p: &[Plane<T>],
        q: &[Plane<T>],
        tol: T,
    ) {
        let rot = pose.rotation.to_rotation_matrix();
        let r = rot.matrix();
        let shift = pose.translation.vector - origin;
        let tol = tol.f64();
        let mut apart = [false; MAX_TEMPLATE_FACES];
        for pl in p.iter().chain(q) {
            let n = widen(&pl.normal);
            // Rᵀ n written out (column k of R dotted with n), then the scale.
            let body_normal = Vector3::new(
                r[(0, 0)] * n.x + r[(1, 0)] * n.y + r[(2, 0)] * n.z,
                r[(0, 1)] * n.x + r[(1, 1)] * n.y + r[(2, 1)] * n.z,
                r[(0, 2)] * n.x + r[(1, 2)] * n.y + r[(2, 2)] * n.z,
            ) * scale;
            let body_offset = pl.offset.f64() - n.dot(&shift);
            for (i, apart) in apart[..self.n_planes].iter_mut().enumerate() {
                if *apart {
                    continue;
                }
                let face = &template.faces[self.face[i] as usize];
                *apart = face.vertices.iter().all(|&v| {
                    body_normal.dot(&template.vertices[v as usize].coords) - body_offset > tol
                });
            }
        }
        let mut kept = 0;
        self.n_aside = 0;
        for (i, &apart) in apart[..self.n_planes].iter().enumerate() {
            if apart {
                self.aside[self.n_aside] = self.planes[i];
                self.aside_face[self.n_aside] = self.face[i];
                self.n_aside += 1;
            } else {
                self.planes[kept] = self.planes[i];
                self.face[kept] = self.face[i];
                kept += 1;
            }
        }
        self.n_planes = kept;
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
