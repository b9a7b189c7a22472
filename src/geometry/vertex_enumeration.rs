//! The faces of a small intersection of half-spaces by vertex enumeration: the exact alternative
//! to the dual hull ([`super::quickhull`]) when only a few planes remain.
//!
//! After culling, a dense packing's pair keeps about 5–6 planes (at most 8), the faces of the
//! overlap itself. For so few planes the combinatorics that the dual hull recovers are cheaper
//! to enumerate directly, in a workspace of a few hundred bytes instead of the hull's triangle
//! mesh (which on the GPU is what bounds the pair kernel: its memory latency, not its
//! arithmetic). Many-faced grains keep more (the mineral grain 10 at the median, the 24-gon
//! cylinder 11, the overlap's own faces); their scenes take the enumeration up to 16 planes
//! ([`enum_planes_for`]; `POLYDEM_ENUM_PLANES` overrides), on the CPU and the GPU alike.
//!
//! With every plane `n_u·x <= δ_u` written about an interior point (`δ_u > 0`):
//!
//! 1. **Vertices.** Every triple of planes with independent normals meets in one point (Cramer's
//!    rule, as the hull path recomputes its vertices); the point is a vertex of the intersection
//!    when it lies inside every other plane, within `tol`. Each vertex remembers the three planes
//!    it was computed from. A vertex where more than three planes meet is found once per triple:
//!    the copies coincide and add nothing below.
//! 2. **Faces.** The face on plane `u` is the convex polygon of the vertices computed from a
//!    triple containing `u` (all of them lie on `u`, inside every other plane). They are ordered
//!    counter-clockwise seen from outside by a pseudo-angle about their mean and fanned from the
//!    foot `δ_u n_u` of the interior point, as the hull path fans its faces. A plane that only
//!    touches the intersection along an edge or at a vertex gets collinear or coincident points
//!    and so no area, which keeps the result continuous where the combinatorics change.
//!
//! Planes that coincide within the dual hull's tolerance must be removed by the caller (one copy
//! kept), as the hull keeps one copy of coincident dual points: two copies would each carry the
//! full face.

use super::Real;
use nalgebra::Vector3;

/// Most planes handled by enumeration by default; more go to the dual hull. `C(m, 3)` triples
/// are tested against `m − 3` planes each, so the cost grows as `m⁴`; at 8 planes it is still
/// well below the hull's. Many-faced scenes raise it (see [`enum_planes_for`]).
pub const ENUM_MAX_PLANES: usize = 8;
/// The most planes the enumeration takes at any setting (`POLYDEM_ENUM_PLANES` at its largest).
pub const ENUM_PLANES_CAPACITY: usize = 16;
/// Most vertices kept: `C(8, 3) = 56` holds every triple of 8 planes. Past 8 planes a
/// polytope of `m` faces has at most `2m − 4` vertices where three planes meet at each, plus a
/// copy for every further triple where more meet (a vertex of a triangulated grain inside the
/// other, five faces through it, is found ten times); an enumeration that finds more declines,
/// and the hull takes the pair.
pub const ENUM_MAX_VERTICES: usize = 96;
/// Most vertices on one face: `C(7, 2) = 21` for 8 planes; an enumeration that puts more on
/// one face declines.
const ENUM_MAX_FACE_VERTICES: usize = 32;

/// The planes up to which pairs take the enumeration rather than the hull when no scene says
/// otherwise: [`ENUM_MAX_PLANES`], or `POLYDEM_ENUM_PLANES` (8–[`ENUM_PLANES_CAPACITY`]). A
/// run takes its scene's limit instead ([`enum_planes_for`], `Scene::enum_planes`), the same on
/// the CPU and the GPU, so that GPU double stays bitwise the CPU at any setting.
pub fn enum_planes() -> usize {
    crate::tuning::Tuning::get()
        .enum_planes
        .map_or(ENUM_MAX_PLANES, |n| n as usize)
}

/// Templates with more faces than this are many-faced: their scenes enumerate up to
/// [`ENUM_PLANES_CAPACITY`] planes by default ([`enum_planes_for`]). The dodecahedron (12)
/// is the most-faced shape below it.
pub const MANY_FACES: usize = 12;

/// The enumeration's limit for a scene whose most-faced polyhedral template has `max_faces`
/// faces: `POLYDEM_ENUM_PLANES` where set, else [`ENUM_PLANES_CAPACITY`] past [`MANY_FACES`]
/// and [`ENUM_MAX_PLANES`] up to it.
///
/// Why (docs/performance.md, "How many planes the many-faced contacts keep"): three quarters of
/// the mineral grains' contacts (32 faces) and four fifths of the 24-gon cylinders' (26 faces)
/// keep 9–16 planes, which at the limit 8 leave the GPU's lean passes for the deferred dual
/// hull, whose per-thread workspace sits in local memory. At 16 the settled 1e6 packings ran
/// 1.11× (mineral grains) and 1.48× (cylinders) faster on one H100 in mixed precision. The CPU
/// pays for it (the hull is the faster path there past 8 planes: 0.68× on the settled cell of
/// mineral grains), and the results move in their last bits; `POLYDEM_ENUM_PLANES=8` restores both.
/// Up to 12 faces (the dodecahedra: 92.5 % of contacts at most 8 planes) the default stays 8,
/// which keeps those scenes bitwise as they were.
pub fn enum_planes_for(max_faces: usize) -> usize {
    match crate::tuning::Tuning::get().enum_planes {
        Some(n) => n as usize,
        None if max_faces > MANY_FACES => ENUM_PLANES_CAPACITY,
        None => ENUM_MAX_PLANES,
    }
}

/// Workspace and result of one enumeration.
#[derive(Clone, Debug)]
pub struct FaceEnumeration<T: Real> {
    vertex: [Vector3<T>; ENUM_MAX_VERTICES],
    /// Bit `u` set: the vertex was computed from plane `u`.
    on: [u16; ENUM_MAX_VERTICES],
    n_vertices: usize,
    order: [u8; ENUM_MAX_FACE_VERTICES],
    key: [T; ENUM_MAX_FACE_VERTICES],
}

impl<T: Real> Default for FaceEnumeration<T> {
    fn default() -> Self {
        FaceEnumeration {
            vertex: [Vector3::zeros(); ENUM_MAX_VERTICES],
            on: [0; ENUM_MAX_VERTICES],
            n_vertices: 0,
            order: [0; ENUM_MAX_FACE_VERTICES],
            key: [T::zero(); ENUM_MAX_FACE_VERTICES],
        }
    }
}

/// Monotone stand-in for the angle of `(s, t)` in `[0, 4)`, counter-clockwise from `+s`: the
/// position on the diamond `|s| + |t| = 1`. Zero for the zero vector.
fn pseudo_angle<T: Real>(s: T, t: T) -> T {
    let r = s.abs() + t.abs();
    if r > T::zero() {
        let q = s / r;
        if t >= T::zero() {
            T::one() - q
        } else {
            T::of(3.0) + q
        }
    } else {
        T::zero()
    }
}

impl<T: Real> FaceEnumeration<T> {
    /// The vertices found by the last [`Self::enumerate`] (copies of a vertex where more than
    /// three planes meet included).
    pub fn vertices(&self) -> &[Vector3<T>] {
        &self.vertex[..self.n_vertices]
    }

    /// Step 1: the vertices of `{x : normal[u]·x <= delta[u]}` over the planes `u < m` whose bit
    /// is set in `active`; `tol` is how far outside a plane a vertex may lie (round-off).
    /// Triples whose normals are nearly dependent (`|det| <= 64 ε`) are skipped, as the hull
    /// path skips them when it recomputes a vertex. Returns `false`, declining, when more than
    /// [`ENUM_MAX_VERTICES`] vertices are found.
    pub fn enumerate(&mut self, normal: &[Vector3<T>], delta: &[T], active: u32, tol: T) -> bool {
        let m = normal.len().min(ENUM_PLANES_CAPACITY);
        let is_active = |u: usize| active & (1 << u) != 0;
        let singular = T::of(64.0) * T::EPSILON;
        self.n_vertices = 0;
        for i in 0..m {
            if !is_active(i) {
                continue;
            }
            for j in i + 1..m {
                if !is_active(j) {
                    continue;
                }
                let cij = normal[i].cross(&normal[j]);
                for k in j + 1..m {
                    if !is_active(k) {
                        continue;
                    }
                    let (ni, nj, nk) = (normal[i], normal[j], normal[k]);
                    let cjk = nj.cross(&nk);
                    let det = ni.dot(&cjk);
                    if det.abs() <= singular {
                        continue;
                    }
                    let cki = nk.cross(&ni);
                    // det · x, with det made positive (exact negations): the tests below are
                    // scaled by det, so only the vertices kept pay for the division.
                    let mut scaled = cjk * delta[i] + cki * delta[j] + cij * delta[k];
                    let mut det = det;
                    if det < T::zero() {
                        scaled = -scaled;
                        det = -det;
                    }
                    let margin = tol * det;
                    let mut inside = true;
                    for l in 0..m {
                        if l != i && l != j && l != k && is_active(l) {
                            inside = normal[l].dot(&scaled) - delta[l] * det <= margin;
                            if !inside {
                                break;
                            }
                        }
                    }
                    if inside {
                        if self.n_vertices == ENUM_MAX_VERTICES {
                            return false;
                        }
                        self.vertex[self.n_vertices] = scaled / det;
                        self.on[self.n_vertices] = (1 << i) | (1 << j) | (1 << k);
                        self.n_vertices += 1;
                    }
                }
            }
        }
        true
    }

    /// Step 2: area and first moment (`Σ area × centroid` of the fan triangles) of the face on
    /// plane `u` (unit normal `n`, distance `delta` from the interior point), from the vertices of
    /// the last [`Self::enumerate`]. Both are zero when fewer than three vertices lie on `u`;
    /// `None`, declining, when more than `ENUM_MAX_FACE_VERTICES` (32) do.
    pub fn face(&mut self, u: usize, n: Vector3<T>, delta: T) -> Option<(T, Vector3<T>)> {
        let bit = 1u16 << u;
        let mut count = 0;
        let mut mean = Vector3::zeros();
        for v in 0..self.n_vertices {
            if self.on[v] & bit != 0 {
                if count == ENUM_MAX_FACE_VERTICES {
                    return None;
                }
                self.order[count] = v as u8;
                mean += self.vertex[v];
                count += 1;
            }
        }
        if count < 3 {
            return Some((T::zero(), Vector3::zeros()));
        }
        mean /= T::of(count as f64);
        // A basis (e1, e2 = n × e1) of the plane, so that increasing angle is counter-clockwise
        // seen from outside; e1 is orthogonal to n from the axis least aligned with it.
        let (ax, ay, az) = (n.x.abs(), n.y.abs(), n.z.abs());
        let axis = if ax <= ay && ax <= az {
            Vector3::x()
        } else if ay <= az {
            Vector3::y()
        } else {
            Vector3::z()
        };
        let e1 = axis.cross(&n);
        let e2 = n.cross(&e1);
        // Insertion sort by pseudo-angle; ties keep the enumeration order.
        for c in 0..count {
            let v = self.order[c];
            let d = self.vertex[v as usize] - mean;
            let key = pseudo_angle(d.dot(&e1), d.dot(&e2));
            let mut p = c;
            while p > 0 && self.key[p - 1] > key {
                self.key[p] = self.key[p - 1];
                self.order[p] = self.order[p - 1];
                p -= 1;
            }
            self.key[p] = key;
            self.order[p] = v;
        }
        let foot = n * delta;
        let third = T::of(1.0 / 3.0);
        let mut area = T::zero();
        let mut first_moment = Vector3::zeros();
        for c in 0..count {
            let p = self.vertex[self.order[c] as usize];
            let q = self.vertex[self.order[if c + 1 < count { c + 1 } else { 0 }] as usize];
            let twice = n.dot(&(p - foot).cross(&(q - foot)));
            let tri_area = twice * T::of(0.5);
            area += tri_area;
            first_moment += (foot + p + q) * (tri_area * third);
        }
        Some((area, first_moment))
    }
}
