//! A convex polyhedron against one triangular wall facet (seed paper Sec. 2.4, Alg. VII).
//!
//! Two quantities are computed:
//!
//! 1. The overlap of the polyhedron's section by the facet plane with the triangle, by
//!    Sutherland–Hodgman clipping in the facet plane: its area and centroid (seed Alg. VII, Eq.
//!    10–11). The section itself is found the same way: a square that covers the polyhedron's
//!    shadow is clipped by the trace of every face plane.
//! 2. The penetrating volume: the part of the polyhedron behind the facet plane whose projection
//!    falls on the triangle, i.e. the intersection of the polyhedron with the half-infinite prism
//!    under the triangle. That is a convex intersection, evaluated exactly by the dual-space
//!    overlap ([`super::overlap`]), which also gives its gradient with respect to translating the
//!    particle. The prisms of the triangles of a flat wall tile the half-space behind it, so the
//!    volumes and gradients summed over a flat wall do not depend on how it is triangulated.
//!    The face of that intersection on the facet plane is the clipped section of item 1, which
//!    lets the two computations check each other.

use super::Real;
use super::interior::chebyshev_centre;
use super::overlap::{Overlap, OverlapError, OverlapWorkspace, overlap_about, overlap_volume};
use super::polytope::{Plane, PosedPolytope};
use crate::shape::{ConvexTemplate, MAX_TEMPLATE_FACES};
use nalgebra::{Isometry3, Vector2, Vector3};

/// Largest vertex count of a clipped polygon: a square clipped by every face plane plus the
/// three triangle edges.
pub const MAX_POLYGON: usize = MAX_TEMPLATE_FACES + 8;

/// A convex polygon in the facet plane's 2D coordinates, in fixed-capacity storage.
#[derive(Clone, Copy, Debug)]
pub struct Polygon2<T: Real> {
    pts: [Vector2<T>; MAX_POLYGON],
    n: usize,
}

impl<T: Real> Default for Polygon2<T> {
    fn default() -> Self {
        Polygon2 {
            pts: [Vector2::zeros(); MAX_POLYGON],
            n: 0,
        }
    }
}

impl<T: Real> Polygon2<T> {
    /// A polygon from its vertices (at most [`MAX_POLYGON`] are kept).
    pub fn from_points(points: &[Vector2<T>]) -> Self {
        let mut p = Self::default();
        for q in points.iter().take(MAX_POLYGON) {
            p.push(*q);
        }
        p
    }

    fn push(&mut self, q: Vector2<T>) {
        if self.n < MAX_POLYGON {
            self.pts[self.n] = q;
            self.n += 1;
        }
    }

    /// The vertices in order.
    pub fn points(&self) -> &[Vector2<T>] {
        &self.pts[..self.n]
    }

    /// Signed area (positive for counter-clockwise) and area centroid (shoelace formula).
    pub fn area_centroid(&self) -> (T, Vector2<T>) {
        let pts = self.points();
        if pts.len() < 3 {
            return (T::zero(), Vector2::zeros());
        }
        // Relative to the first vertex, to keep round-off proportional to the polygon's size.
        let o = pts[0];
        let mut twice = T::zero();
        let mut c = Vector2::zeros();
        for w in pts[1..].windows(2) {
            let (p, q) = (w[0] - o, w[1] - o);
            let cr = p.x * q.y - p.y * q.x;
            twice += cr;
            c += (p + q) * cr;
        }
        if twice == T::zero() {
            return (T::zero(), o);
        }
        (twice * T::of(0.5), o + c / (T::of(3.0) * twice))
    }

    /// Keeps the part on the inner side of the line `a · p <= b` (one Sutherland–Hodgman pass,
    /// seed Alg. VII lines 4–21 with the intersection point of Eq. 10–11).
    pub fn clip(&self, a: Vector2<T>, b: T) -> Self {
        let mut out = Self::default();
        let pts = self.points();
        let Some(&last) = pts.last() else {
            return out;
        };
        let mut prev = last;
        let mut prev_d = a.dot(&prev) - b;
        for &cur in pts {
            let cur_d = a.dot(&cur) - b;
            let (cur_in, prev_in) = (cur_d <= T::zero(), prev_d <= T::zero());
            if cur_in != prev_in {
                let t = prev_d / (prev_d - cur_d);
                out.push(prev + (cur - prev) * t);
            }
            if cur_in {
                out.push(cur);
            }
            prev = cur;
            prev_d = cur_d;
        }
        out
    }
}

/// Clips `subject` by the convex polygon `clip` given counter-clockwise (seed Alg. VII).
pub fn sutherland_hodgman<T: Real>(subject: &Polygon2<T>, clip: &Polygon2<T>) -> Polygon2<T> {
    let c = clip.points();
    let mut p = *subject;
    for i in 0..c.len() {
        let (v0, v1) = (c[i], c[(i + 1) % c.len()]);
        let e = v1 - v0;
        // Inside is the left of a counter-clockwise edge: outward normal (e.y, −e.x).
        let a = Vector2::new(e.y, -e.x);
        p = p.clip(a, a.dot(&v0));
    }
    p
}

/// An orthonormal frame in the facet plane: origin, in-plane axes, unit normal.
#[derive(Clone, Copy, Debug)]
pub struct FacetFrame<T: Real> {
    pub origin: Vector3<T>,
    pub e1: Vector3<T>,
    pub e2: Vector3<T>,
    pub normal: Vector3<T>,
}

impl<T: Real> FacetFrame<T> {
    /// The frame of triangle (p0, p1, p2); its normal is `(p1 − p0) × (p2 − p0)` normalised
    /// (the side the particles are on). `None` for a degenerate triangle.
    pub fn of_triangle(tri: &[Vector3<T>; 3]) -> Option<Self> {
        let n = (tri[1] - tri[0]).cross(&(tri[2] - tri[0]));
        let e = tri[1] - tri[0];
        if n.norm() <= T::zero() || e.norm() <= T::zero() {
            return None;
        }
        let normal = n.normalize();
        let e1 = e.normalize();
        Some(FacetFrame {
            origin: tri[0],
            e1,
            e2: normal.cross(&e1),
            normal,
        })
    }

    /// 2D coordinates of a point of the plane.
    pub fn to_2d(&self, x: &Vector3<T>) -> Vector2<T> {
        let d = x - self.origin;
        Vector2::new(d.dot(&self.e1), d.dot(&self.e2))
    }

    /// The 3D point of 2D coordinates `p`.
    pub fn to_3d(&self, p: &Vector2<T>) -> Vector3<T> {
        self.origin + self.e1 * p.x + self.e2 * p.y
    }
}

/// The section of `body` by the plane of `frame`, as a polygon in the frame's coordinates
/// (empty when the plane misses the body).
pub fn section_polygon<T: Real>(body: &PosedPolytope<T>, frame: &FacetFrame<T>) -> Polygon2<T> {
    let c = frame.to_2d(&body.centre);
    let r = body.radius() * T::of(2.0) + T::one() * T::EPSILON;
    let mut poly = Polygon2::from_points(&[
        c + Vector2::new(-r, -r),
        c + Vector2::new(r, -r),
        c + Vector2::new(r, r),
        c + Vector2::new(-r, r),
    ]);
    for p in body.planes() {
        // Trace of n·x <= h on the plane x = o + u e1 + v e2.
        let a = Vector2::new(p.normal.dot(&frame.e1), p.normal.dot(&frame.e2));
        let b = p.offset - p.normal.dot(&frame.origin);
        if a.norm() <= T::EPSILON {
            // Face parallel to the plane: the whole plane is inside or outside.
            if b < T::zero() {
                return Polygon2::default();
            }
            continue;
        }
        poly = poly.clip(a, b);
        if poly.n == 0 {
            break;
        }
    }
    poly
}

/// Contact geometry of a polyhedron with one triangular facet.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FacetContact<T: Real> {
    /// Area of the section of the polyhedron by the facet plane, clipped to the triangle.
    pub area: T,
    /// Centroid of that clipped section.
    pub centroid: Vector3<T>,
    /// Volume of the polyhedron behind the facet plane, over the triangle.
    pub volume: T,
    /// Centroid of that volume.
    pub volume_centroid: Vector3<T>,
    /// Gradient of `volume` with respect to translating the particle.
    pub dv_dx: Vector3<T>,
    /// Area of the penetrating region's face on the facet plane, from the volume computation
    /// (equals `area` up to round-off: an internal cross-check).
    pub cap_area: T,
}

/// The half-infinite prism under triangle `tri`: its plane (outward normal towards the side the
/// particles are on) and a side plane through each edge, perpendicular to the facet, facing out.
pub fn facet_prism<T: Real>(tri: &[Vector3<T>; 3]) -> Option<[Plane<T>; 4]> {
    let frame = FacetFrame::of_triangle(tri)?;
    let mut prism = [Plane {
        normal: frame.normal,
        offset: frame.normal.dot(&frame.origin),
    }; 4];
    for k in 0..3 {
        let (p, q) = (tri[k], tri[(k + 1) % 3]);
        let n = (q - p).cross(&frame.normal).normalize();
        prism[k + 1] = Plane {
            normal: n,
            offset: n.dot(&p),
        };
    }
    Some(prism)
}

/// Whether a plane of the prism has every vertex of the body on its outer side, which separates
/// the two: nothing to compute. This cheap test rejects most facets near a particle (those it
/// passes over sideways, or hovers above).
fn prism_separates<T: Real>(body: &PosedPolytope<T>, prism: &[Plane<T>; 4]) -> bool {
    prism.iter().any(|plane| {
        body.vertices()
            .iter()
            .all(|v| plane.distance(v) >= T::zero())
    })
}

/// Overlap of `body` with a facet's prism `[facet plane, side planes…]` (planes of B): the
/// penetrating volume, its centroid, `S` (so `dV/dx_body = −S`) and the moment of the prism's
/// part of the surface.
pub fn prism_overlap<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    body: &PosedPolytope<T>,
    prism: &[Plane<T>; 4],
) -> Result<Overlap<T>, OverlapError> {
    let facet = &prism[0];
    if prism_separates(body, prism) {
        return Ok(Overlap::default());
    }
    // Start the interior-point search on the facet plane under the body's centre.
    let start = body.centre - facet.normal * facet.distance(&body.centre);
    let mut out = overlap_volume(ws, body.planes(), prism, start)?;
    facet_thickness(ws, facet, &mut out);
    Ok(out)
}

/// A facet overlap's thickness is its penetration behind the facet, along the facet's normal
/// ([`OverlapWorkspace::extent_along`]), not along its own `−S/|S|`: where a contact
/// straddles facets, each part's S leans on the prism's side planes, and the contact law's
/// local power law (`contact::law`) needs the depth of the whole contact.
fn facet_thickness<T: Real>(ws: &OverlapWorkspace<T>, facet: &Plane<T>, out: &mut Overlap<T>) {
    if out.volume > T::zero() {
        out.thickness = ws.extent_along(&facet.normal);
    }
}

/// [`prism_overlap`] on the planes that can bound it (the wall stage's evaluation). The body
/// must be placed from `placed_from` (template, scale, pose) in the frame whose origin is the
/// point `origin` of the pose's frame (as [`PosedPolytope::place`] takes them), with its planes
/// in template order, which it has again on return.
///
/// - A body plane whose face has no corner behind the facet plane (by more than round-off)
///   supports no face of the overlap, which lies behind that plane: it is set aside. For a
///   dodecahedron resting on a wall that leaves 4–6 of its 12 planes.
/// - A side plane of the prism that holds the ball around the part of the body's bounding ball
///   behind the facet plane (the cap's ball: base disk radius `√(r² − d²)` about the foot of the
///   centre when the centre is in front, the whole ball otherwise) holds the whole overlap: it
///   is dropped. This is exact.
/// - Setting body planes aside is exact when the overlap has an interior point (a segment from
///   it to a point beyond a set-aside plane would leave the body through that plane's face,
///   behind the facet plane). The Chebyshev centre of the planes kept proves it when it lies
///   strictly inside every plane set aside; then the overlap is evaluated about it on the
///   planes kept (few enough for the vertex enumeration instead of the dual hull). Otherwise
///   (a touching or empty overlap) every body plane is used, as in [`prism_overlap`].
pub fn prism_overlap_culled<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    body: &mut PosedPolytope<T>,
    placed_from: (&ConvexTemplate, f64, &Isometry3<f64>),
    origin: &Vector3<f64>,
    prism: &[Plane<T>; 4],
) -> Result<Overlap<T>, OverlapError> {
    let facet = &prism[0];
    if prism_separates(body, prism) {
        return Ok(Overlap::default());
    }
    let (template, scale, _) = placed_from;
    let r = T::of(template.circumscribed_radius * scale);
    let tol = T::of(64.0) * T::EPSILON * r;
    body.set_aside_beyond(placed_from, origin, &prism[..1], &[], tol);
    let d = facet.distance(&body.centre);
    let (cap_centre, cap_radius) = if d >= T::zero() {
        (
            body.centre - facet.normal * d,
            (r * r - d * d).max(T::zero()).sqrt(),
        )
    } else {
        (body.centre, r)
    };
    let mut kept = [prism[0]; 4];
    let mut n_kept = 1;
    for plane in &prism[1..] {
        if plane.distance(&cap_centre) + cap_radius > -tol {
            kept[n_kept] = *plane;
            n_kept += 1;
        }
    }
    let kept = &kept[..n_kept];
    let start = body.centre - facet.normal * d;
    let centre = chebyshev_centre(body.planes(), kept, start);
    let proven = centre.radius > tol
        && body
            .aside_planes()
            .iter()
            .all(|p| p.distance(&centre.point) < -tol);
    let out = if proven {
        let enumerate_up_to = ws.enum_planes;
        overlap_about(ws, body.planes(), kept, centre.point, enumerate_up_to)
    } else {
        body.restore_aside();
        overlap_volume(ws, body.planes(), kept, start)
    };
    body.restore_template_order();
    let mut out = out?;
    facet_thickness(ws, facet, &mut out);
    Ok(out)
}

/// Contact of `body` with triangle `tri` (counter-clockwise seen from the side the particles
/// are on). Returns a zero contact for a degenerate triangle or when the body lies entirely in
/// front of the facet plane.
pub fn facet_contact<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    body: &PosedPolytope<T>,
    tri: &[Vector3<T>; 3],
) -> Result<FacetContact<T>, OverlapError> {
    let Some(frame) = FacetFrame::of_triangle(tri) else {
        return Ok(FacetContact::default());
    };
    let h = frame.normal.dot(&frame.origin);
    if body.vertices().iter().all(|v| frame.normal.dot(v) >= h) {
        return Ok(FacetContact::default());
    }
    // 1. Section ∩ triangle by Sutherland–Hodgman.
    let section = section_polygon(body, &frame);
    let tri2 = Polygon2::from_points(&[
        frame.to_2d(&tri[0]),
        frame.to_2d(&tri[1]),
        frame.to_2d(&tri[2]),
    ]);
    let clipped = sutherland_hodgman(&section, &tri2);
    let (area, c2) = clipped.area_centroid();
    // 2. Penetrating volume: body ∩ prism below the triangle.
    let Some(prism) = facet_prism(tri) else {
        return Ok(FacetContact::default());
    };
    let ov = prism_overlap(ws, body, &prism)?;
    let n_body = body.planes().len();
    Ok(FacetContact {
        area: area.max(T::zero()),
        centroid: frame.to_3d(&c2),
        volume: ov.volume,
        volume_centroid: ov.centroid,
        dv_dx: -ov.dv_dxb,
        // The workspace holds this evaluation's faces only when it computed an overlap
        // (prism_overlap returns early for a separated body).
        cap_area: if ov.volume > T::zero() {
            ws.face_area(n_body)
        } else {
            T::zero()
        },
    })
}
