//! Overlap of two convex polyhedra by dual-space Quickhull (seed paper Alg. II–VI, Eq. 4–9).
//!
//! The intersection `A ∩ B` is the set of points below every face plane of A and of B. With an
//! interior point `x₀` (the Chebyshev centre, [`super::interior`]) each plane `n·x <= h` has a
//! positive distance `δ = h − n·x₀` and a dual point `y = n / δ` (Eq. 4–5). The convex hull of
//! the dual points is the polar of the intersection: its triangles are the intersection's
//! vertices, its vertices are the planes that bound it (points inside the dual hull are redundant
//! planes), and its edges are the intersection's edges.
//!
//! For the few planes a culled pair keeps (at most [`ENUM_MAX_PLANES`](super::vertex_enumeration::ENUM_MAX_PLANES), or `POLYDEM_ENUM_PLANES`) the faces are found by
//! vertex enumeration instead ([`super::vertex_enumeration`]): the same faces, fanned the same
//! way, from a workspace of a few hundred bytes; the hull takes over for more planes and
//! wherever the enumerated faces do not close. [`overlap_volume_by_hull`] forces the hull, the
//! reference the enumeration is tested against.
//!
//! We use the hull for the combinatorics only. Each intersection vertex is recomputed from the
//! three original planes of its dual triangle (`n_i · m = δ_i`, Cramer's rule), which is better
//! conditioned than unpolarising the dual plane (Eq. 6–8) when some `δ` are small. Each
//! intersection face (a dual vertex `u`) is then traversed through the triangle adjacency
//! without sorting: the half-edge `u → w` of dual triangle `t` is the primal edge from `m_t` to
//! `m_t'`, `t'` the triangle across it. Fanning each face from the foot `δ_u n_u` of `x₀` gives
//! its area `A_u` and area centroid `c_u`, and:
//!
//! - volume `V = Σ_u δ_u A_u / 3` (pyramids from `x₀`, Eq. 9);
//! - centroid `Σ_u (δ_u A_u / 3)(3/4) c_u / V`;
//! - `S = dV/dx_B = Σ_{u ∈ B} A_u n_u`, the vector area of the part of the intersection surface
//!   lying on B (Feng, Han & Owen 2012; `|S| = A_n`, `−S/|S|` the normal from A to B); a face
//!   lying on coincident planes of A and B counts half to each;
//! - `M_B = Σ_{u ∈ B} A_u (c_u − c) × n_u`, the moment of that surface about the overlap
//!   centroid `c`, from which the energy-conserving torque on B about its centre `x_B` is
//!   `−U'(V) (M_B + (c − x_B) × S)` (docs/contact.md §1, seed paper Eq. 13). For A the moment is
//!   `−M_B` (the closed surface has zero vector moment).

use super::Real;
use super::interior::chebyshev_centre;
use super::polytope::{Plane, widen};
use super::quickhull::{DualHull, HullError, MAX_HULL_FACES, MAX_HULL_POINTS};
use super::vertex_enumeration::{ENUM_PLANES_CAPACITY, FaceEnumeration, enum_planes};
use nalgebra::Vector3;

/// Geometric result of an overlap evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Overlap<T: Real> {
    /// Overlap volume `V`.
    pub volume: T,
    /// Centroid of the overlap region.
    pub centroid: Vector3<T>,
    /// `S = dV/dx_B`: vector area of the overlap surface lying on B.
    pub dv_dxb: Vector3<T>,
    /// `M_B = ∫_{∂(A∩B) ∩ ∂B} (x − centroid) × n dA`: moment of B's part of the overlap surface.
    pub moment_b: Vector3<T>,
    /// Radius of the largest ball inside the overlap (half-thickness of a thin lens); negative
    /// when the bodies are apart.
    pub depth: T,
    /// The penetration δ of a vertex, edge or face into the other body along the normal
    /// `−S/|S|`, measured from the geometry rather than from history: the distance to
    /// separation the overlap's vertices give where one face of A carries it
    /// ([`OverlapWorkspace::separation_along`]), else the overlap's extent along the normal; for
    /// a wall facet, the penetration behind the facet.
    pub thickness: T,
}

impl<T: Real> Overlap<T> {
    /// Projected contact area `A_n = |S|`.
    pub fn area(&self) -> T {
        self.dv_dxb.norm()
    }

    /// Unit contact normal from A towards B, `−S/|S|`; `None` when there is no overlap.
    pub fn normal(&self) -> Option<Vector3<T>> {
        let a = self.area();
        (self.volume > T::zero() && a > T::zero()).then(|| -self.dv_dxb / a)
    }

    /// The same overlap expressed in f64 and shifted by `origin` (back to world coordinates).
    pub fn to_world(&self, origin: &Vector3<f64>) -> Overlap<f64> {
        Overlap {
            volume: self.volume.f64(),
            centroid: widen(&self.centroid) + origin,
            dv_dxb: widen(&self.dv_dxb),
            moment_b: widen(&self.moment_b),
            depth: self.depth.f64(),
            thickness: self.thickness.f64(),
        }
    }
}

/// Why an overlap could not be evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum OverlapError {
    #[error("{0} planes exceed the capacity of {MAX_HULL_POINTS}")]
    TooManyPlanes(usize),
    #[error("dual hull failed: {0}")]
    Hull(#[from] HullError),
}

/// Buffers of one overlap evaluation, allocated once per thread and reused for every pair.
#[derive(Clone, Debug)]
pub struct OverlapWorkspace<T: Real> {
    hull: DualHull<T>,
    faces: FaceEnumeration<T>,
    /// The last evaluation would have used the enumeration, but its faces did not close.
    declined: bool,
    dual: [Vector3<T>; MAX_HULL_POINTS],
    normal: [Vector3<T>; MAX_HULL_POINTS],
    delta: [T; MAX_HULL_POINTS],
    area: [T; MAX_HULL_POINTS],
    first_moment: [Vector3<T>; MAX_HULL_POINTS],
    vertex: [Vector3<T>; MAX_HULL_FACES],
    share_b: [T; MAX_HULL_POINTS],
    x0: Vector3<T>,
    /// Planes of the last evaluation.
    m: usize,
    /// The last evaluation's faces came from the dual hull (not the enumeration).
    by_hull: bool,
    /// The most planes whose faces come from the vertex enumeration (the run's
    /// `Scene::enum_planes`; [`enum_planes`] until set).
    pub(crate) enum_planes: usize,
}

impl<T: Real> Default for OverlapWorkspace<T> {
    fn default() -> Self {
        OverlapWorkspace {
            hull: DualHull::default(),
            faces: FaceEnumeration::default(),
            declined: false,
            dual: [Vector3::zeros(); MAX_HULL_POINTS],
            normal: [Vector3::zeros(); MAX_HULL_POINTS],
            delta: [T::zero(); MAX_HULL_POINTS],
            area: [T::zero(); MAX_HULL_POINTS],
            first_moment: [Vector3::zeros(); MAX_HULL_POINTS],
            vertex: [Vector3::zeros(); MAX_HULL_FACES],
            share_b: [T::zero(); MAX_HULL_POINTS],
            x0: Vector3::zeros(),
            m: 0,
            by_hull: false,
            enum_planes: enum_planes(),
        }
    }
}

impl<T: Real> OverlapWorkspace<T> {
    /// A workspace on the heap (it is tens of kilobytes).
    pub fn boxed() -> Box<Self> {
        Box::default()
    }

    /// Sets the most planes whose overlap faces come from the vertex enumeration rather than
    /// the dual hull (the run's `Scene::enum_planes`). Panics past
    /// [`ENUM_PLANES_CAPACITY`], which the enumeration's buffers are sized for.
    pub fn set_enum_planes(&mut self, n: usize) {
        assert!(
            n <= ENUM_PLANES_CAPACITY,
            "{n} planes exceed the enumeration's capacity"
        );
        self.enum_planes = n;
    }

    /// The farthest that a vertex of the last evaluation's intersection lies outside one of its
    /// planes, `max over vertices v and planes u of n_u · v − δ_u` (in the frame of the planes),
    /// when its faces came from the dual hull; zero when they came from the vertex enumeration,
    /// whose vertices satisfy every plane by construction, or when there was no overlap.
    ///
    /// Every vertex of a correct hull lies on three planes and inside the others up to
    /// round-off. A hull that round-off bent (an apex joined to the wrong horizon, as an f32
    /// hull can be where the dual points span three orders of magnitude: the two large faces of
    /// a face resting on a face map a thousand times farther out than its sides) has vertices
    /// outside by as much as the particle size, and its volume is wrong by as much.
    pub fn hull_vertex_excess(&self) -> T {
        let mut worst = T::zero();
        if self.by_hull {
            for (s, _) in self.hull.triangles() {
                let v = self.vertex[s];
                for u in 0..self.m {
                    worst = worst.max(self.normal[u].dot(&v) - self.delta[u]);
                }
            }
        }
        worst
    }

    /// Extent of the last evaluation's overlap along the unit vector `n` (the spread of its
    /// vertices' heights): the penetration behind a wall facet when `n` is the facet's normal.
    /// The `thickness` an evaluation returns is along `−S/|S|`, which for a facet's part of a
    /// contact that straddles facets leans on the prism's side planes.
    pub fn extent_along(&self, n: &Vector3<T>) -> T {
        let (mut lo, mut hi) = (
            T::max_value().unwrap_or(T::one()),
            -T::max_value().unwrap_or(T::one()),
        );
        self.for_each_vertex(|v| {
            let h = n.dot(v);
            lo = lo.min(h);
            hi = hi.max(h);
        });
        (hi - lo).max(T::zero())
    }

    /// Calls `visit` on each vertex of the last evaluation's overlap, in the frame of the
    /// planes: the dual hull's triangles or the enumeration's vertices, whichever built it.
    fn for_each_vertex(&self, mut visit: impl FnMut(&Vector3<T>)) {
        if self.by_hull {
            self.hull
                .triangles()
                .for_each(|(s, _)| visit(&self.vertex[s]));
        } else {
            self.faces.vertices().iter().for_each(visit);
        }
    }

    /// How far B must move along the unit vector `n` (from A towards B) to leave A, as the
    /// vertices of the last evaluation's overlap see it: the largest over the vertices `v` of
    /// the least `(δ_i − n_i·v)/(n_i·n)` over A's planes `i < na` that bound the overlap and
    /// face along `n`. A vertex of B inside A (a vertex or an edge on a face) rises by its depth
    /// behind A's face; two faces meeting with a lateral offset overlap in a box whose `S`
    /// leans by `c/b` (the penetration over the width), where the extent along the normal is
    /// about `3c` and this is `c` (docs/contact.md §1). The largest exit time over the overlap
    /// lies at one of its vertices where one face of A carries the overlap's side towards A
    /// (its area projected on `n` at least [`FACE_SHARE`] of `|S|` = `s_norm`); elsewhere it
    /// may lie inside an edge of the overlap (two crossing edges, a vertex of B near an edge of
    /// A), the vertices underestimate it, and this is zero: the caller keeps the extent there.
    pub fn separation_along(&self, n: &Vector3<T>, na: usize, s_norm: T) -> T {
        let carried = (0..na).any(|i| {
            self.area[i] > T::zero()
                && self.area[i] * self.normal[i].dot(n) >= T::of(FACE_SHARE) * s_norm
        });
        if !carried {
            return T::zero();
        }
        let mut deepest = T::zero();
        self.for_each_vertex(|v| {
            let mut depth = T::max_value().unwrap_or(T::one());
            for i in 0..na {
                if self.area[i] > T::zero() {
                    let w = self.normal[i].dot(n);
                    if w > T::zero() {
                        depth = depth.min((self.delta[i] - self.normal[i].dot(v)) / w);
                    }
                }
            }
            deepest = deepest.max(depth);
        });
        deepest
    }

    /// Area of the intersection face lying on plane `i` of the last evaluation (planes of A
    /// first, then of B); zero for planes that do not bound the intersection.
    pub fn face_area(&self, i: usize) -> T {
        self.area[i]
    }

    /// Area centroid of the intersection face on plane `i` of the last evaluation, in the frame
    /// of the planes; `None` when that face has no area.
    pub fn face_centroid(&self, i: usize) -> Option<Vector3<T>> {
        (self.area[i] > T::zero()).then(|| self.x0 + self.first_moment[i] / self.area[i])
    }
}

/// Outside tolerance of the dual hull, in units of machine epsilon times the largest dual
/// coordinate; the retry uses a coarser one when round-off breaks the first attempt.
const HULL_EPS: [f64; 2] = [32.0, 4096.0];

/// Overlap of the polytopes `{x : n·x <= h for every plane of a}` and likewise `b`, both
/// bounded, in one common frame. `start` seeds the interior-point search (any point; the
/// midpoint of the centres is a good choice). Returns a zero overlap when the interiors are
/// disjoint or only touch (inscribed radius below round-off).
pub fn overlap_volume<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    a: &[Plane<T>],
    b: &[Plane<T>],
    start: Vector3<T>,
) -> Result<Overlap<T>, OverlapError> {
    let enumerate_up_to = ws.enum_planes;
    overlap_about_centre(ws, a, b, start, enumerate_up_to)
}

/// [`overlap_volume`] with the faces always taken from the dual hull, also for the few planes
/// that [`overlap_volume`] hands to the vertex enumeration: the reference the enumeration is
/// tested against.
pub fn overlap_volume_by_hull<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    a: &[Plane<T>],
    b: &[Plane<T>],
    start: Vector3<T>,
) -> Result<Overlap<T>, OverlapError> {
    overlap_about_centre(ws, a, b, start, 0)
}

/// [`overlap_volume`] with the faces from the vertex enumeration only, for as many planes as it
/// can take ([`ENUM_PLANES_CAPACITY`], whatever `POLYDEM_ENUM_PLANES` says): `None` where there
/// are more, or where it declines (faces that do not close, more vertices than it holds). For
/// tests of the enumeration and of how often it declines.
pub fn overlap_volume_by_enumeration<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    a: &[Plane<T>],
    b: &[Plane<T>],
    start: Vector3<T>,
) -> Option<Overlap<T>> {
    if a.len() + b.len() > ENUM_PLANES_CAPACITY {
        return None;
    }
    ws.declined = false;
    let o = overlap_about_centre(ws, a, b, start, ENUM_PLANES_CAPACITY).ok()?;
    (!ws.declined).then_some(o)
}

/// [`overlap_about`] about the Chebyshev centre of the planes, the LP started at `start`.
fn overlap_about_centre<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    a: &[Plane<T>],
    b: &[Plane<T>],
    start: Vector3<T>,
    enumerate_up_to: usize,
) -> Result<Overlap<T>, OverlapError> {
    let m = a.len() + b.len();
    if m > MAX_HULL_POINTS {
        return Err(OverlapError::TooManyPlanes(m));
    }
    let centre = chebyshev_centre(a, b, start);
    overlap_about(ws, a, b, centre.point, enumerate_up_to)
}

/// [`overlap_volume`] about a given interior point `x0` (normally the Chebyshev centre). The
/// faces come from the vertex enumeration for at most `enumerate_up_to` planes (normally
/// [`OverlapWorkspace::set_enum_planes`], 0 for never), else from the dual hull.
pub(crate) fn overlap_about<T: Real>(
    ws: &mut OverlapWorkspace<T>,
    a: &[Plane<T>],
    b: &[Plane<T>],
    x0: Vector3<T>,
    enumerate_up_to: usize,
) -> Result<Overlap<T>, OverlapError> {
    let m = a.len() + b.len();
    if m > MAX_HULL_POINTS {
        return Err(OverlapError::TooManyPlanes(m));
    }
    let (scale, radius) = ws.place_about(a, b, x0);
    let none = Overlap {
        depth: radius,
        ..Overlap::default()
    };
    if radius <= T::of(16.0) * T::EPSILON * scale {
        return Ok(none);
    }
    ws.polar_transform(radius);
    let na = a.len();
    ws.find_faces(na, scale, enumerate_up_to)?;
    let Some(o) = ws.volume_and_moments() else {
        return Ok(none);
    };
    Ok(Overlap {
        centroid: o.centroid + x0,
        depth: radius,
        thickness: ws.thickness(&o.dv_dxb, na, o.volume),
        ..o
    })
}

impl<T: Real> OverlapWorkspace<T> {
    /// The planes of `a` then `b` about `x0`: their normals and distances δ from it, the areas
    /// cleared; returns the largest δ (the scale of round-off) and the smallest (the radius of
    /// the ball about `x0` inside all of them, negative when `x0` is outside one).
    fn place_about(&mut self, a: &[Plane<T>], b: &[Plane<T>], x0: Vector3<T>) -> (T, T) {
        let m = a.len() + b.len();
        self.x0 = x0;
        self.m = m;
        self.by_hull = false;
        let mut scale = T::zero();
        let mut radius = T::max_value().unwrap_or(T::one());
        for (i, p) in a.iter().chain(b).enumerate() {
            self.normal[i] = p.normal;
            self.delta[i] = p.offset - p.normal.dot(&x0);
            scale = scale.max(self.delta[i]);
            radius = radius.min(self.delta[i]);
        }
        for i in 0..m {
            self.area[i] = T::zero();
        }
        (scale, radius)
    }

    /// Polar transform (seed Alg. II): each plane's dual point `n / δ`. Every δ is at least
    /// the inscribed `radius`, so every dual point is finite.
    fn polar_transform(&mut self, radius: T) {
        for i in 0..self.m {
            self.delta[i] = self.delta[i].max(radius);
            self.dual[i] = self.normal[i] / self.delta[i];
        }
    }

    /// Every face's area and first moment: by the vertex enumeration for at most
    /// `enumerate_up_to` planes (where it declines, and for more, by the dual hull).
    fn find_faces(
        &mut self,
        na: usize,
        scale: T,
        enumerate_up_to: usize,
    ) -> Result<(), OverlapError> {
        let m = self.m;
        let enumerate = m <= enumerate_up_to.min(ENUM_PLANES_CAPACITY);
        let enumerated = enumerate && enumerate_faces(self, m, na, scale);
        self.declined = enumerate && !enumerated;
        if !enumerated {
            for i in 0..m {
                self.area[i] = T::zero();
            }
            hull_faces(self, m, na)?;
            self.by_hull = true;
        }
        Ok(())
    }

    /// The volume `Σ δ A / 3`, the centroid about x₀ (`Σ δ/4 × first moment / V`), S and the
    /// surface moment about the centroid, from the faces (depth and thickness left zero);
    /// `None` for no volume. The hull's traversal orientation is a global convention, so its
    /// areas are made positive here (the enumeration's are by construction).
    fn volume_and_moments(&mut self) -> Option<Overlap<T>> {
        let m = self.m;
        let third = T::of(1.0 / 3.0);
        let mut volume = T::zero();
        for i in 0..m {
            volume += self.delta[i] * self.area[i];
        }
        if volume < T::zero() {
            for i in 0..m {
                self.area[i] = -self.area[i];
                self.first_moment[i] = -self.first_moment[i];
            }
            volume = -volume;
        }
        volume *= third;
        if volume <= T::zero() {
            return None;
        }
        let mut centroid = Vector3::zeros();
        let mut dv_dxb = Vector3::zeros();
        let mut moment_b = Vector3::zeros();
        for i in 0..m {
            centroid += self.first_moment[i] * (self.delta[i] * T::of(0.25));
            let share = self.share_b[i];
            if share > T::zero() {
                dv_dxb += self.normal[i] * (self.area[i] * share);
                moment_b += self.first_moment[i].cross(&self.normal[i]) * share;
            }
        }
        centroid /= volume;
        // Moment about the overlap centroid rather than x₀.
        moment_b -= centroid.cross(&dv_dxb);
        Some(Overlap {
            volume,
            centroid,
            dv_dxb,
            moment_b,
            ..Overlap::default()
        })
    }

    /// The depth along the normal −S/|S|: the distance to separation the overlap's vertices
    /// give where it is at least half the face value V/|S| (which no convex overlap's depth is
    /// below), else its extent; zero where S vanishes.
    fn thickness(&self, dv_dxb: &Vector3<T>, na: usize, volume: T) -> T {
        let area = dv_dxb.norm();
        if area > T::zero() {
            let n = dv_dxb / area;
            let extent = self.extent_along(&n);
            let separation = self.separation_along(&(-n), na, area);
            if separation * area >= T::of(0.5) * volume {
                separation.min(extent)
            } else {
                extent
            }
        } else {
            T::zero()
        }
    }
}

/// The share of `|S|` that one face of A, projected on the normal, must carry for the depth to
/// be taken from the overlap's vertices ([`OverlapWorkspace::separation_along`]): a face of A
/// against a face, an edge or a vertex of B well inside it.
pub const FACE_SHARE: f64 = 0.9;

/// Share of each plane's face in S: 1 for B's planes, 0 for A's, except that a plane of A and a
/// plane of B that coincide (dual points within `tol`: aligned faces, a cube on a cube) bound
/// the overlap with one face, of which the hull (or the enumeration) keeps one copy. V is not
/// differentiable there (moving B one way grows the overlap, the other way does not); we take the
/// mean of the one-sided derivatives, half the face to each body, so that S does not depend on
/// which copy was kept.
fn set_shares<T: Real>(ws: &mut OverlapWorkspace<T>, m: usize, na: usize, tol: T) {
    for i in 0..m {
        ws.share_b[i] = if i < na { T::zero() } else { T::one() };
    }
    for i in 0..na {
        for j in na..m {
            if (ws.dual[i] - ws.dual[j]).norm_squared() <= tol * tol {
                ws.share_b[i] = T::of(0.5);
                ws.share_b[j] = T::of(0.5);
            }
        }
    }
}

/// Face areas and first moments of the intersection of the `m` planes in `ws` (the first `na`
/// of A) by vertex enumeration ([`super::vertex_enumeration`]), for `m <= ENUM_PLANES_CAPACITY`.
/// Coincident planes (dual points within the dual hull's first tolerance) keep the first copy.
/// `scale`: the largest distance δ, to which the vertex tolerance is relative.
///
/// Returns whether the faces close: `|Σ_u A_u n_u| <= 256 ε Σ_u |A_u|` (the vector area of a
/// closed surface is zero). A face given an area it does not have, or one that lost a vertex
/// (a triple skipped as singular, as where two planes cross at an angle of round-off size and
/// both would claim the whole face), leaves the surface open; the caller then uses the hull,
/// as it does when the enumeration finds more vertices than it holds.
fn enumerate_faces<T: Real>(ws: &mut OverlapWorkspace<T>, m: usize, na: usize, scale: T) -> bool {
    let mut max_coord = T::zero();
    for y in &ws.dual[..m] {
        max_coord = max_coord.max(y.x.abs()).max(y.y.abs()).max(y.z.abs());
    }
    let tol = T::of(HULL_EPS[0]) * T::EPSILON * max_coord;
    set_shares(ws, m, na, tol);
    let mut active = 0u32;
    for j in 0..m {
        let copy = (0..j).any(|i| (ws.dual[i] - ws.dual[j]).norm_squared() <= tol * tol);
        if !copy {
            active |= 1 << j;
        }
    }
    let vertex_tol = T::of(64.0) * T::EPSILON * scale;
    if !ws
        .faces
        .enumerate(&ws.normal[..m], &ws.delta[..m], active, vertex_tol)
    {
        return false;
    }
    let mut closure = Vector3::zeros();
    let mut total = T::zero();
    for u in 0..m {
        ws.first_moment[u] = Vector3::zeros();
        if active & (1 << u) != 0 {
            let Some(face) = ws.faces.face(u, ws.normal[u], ws.delta[u]) else {
                return false;
            };
            (ws.area[u], ws.first_moment[u]) = face;
            closure += ws.normal[u] * ws.area[u];
            total += ws.area[u].abs();
        }
    }
    let closure_tol = T::of(256.0) * T::EPSILON * total;
    closure.norm_squared() <= closure_tol * closure_tol
}

/// Face areas and first moments of the intersection of the `m` planes in `ws` (the first `na`
/// of A) from the dual hull of their dual points (seed Alg. III–VI).
fn hull_faces<T: Real>(ws: &mut OverlapWorkspace<T>, m: usize, na: usize) -> Result<(), HullError> {
    let mut result = Err(HullError::Degenerate);
    for eps in HULL_EPS {
        result = ws.hull.build(&ws.dual[..m], T::of(eps));
        if result.is_ok() {
            break;
        }
    }
    result?;
    let tol = ws.hull.tolerance();
    set_shares(ws, m, na, tol);

    // Intersection vertices, one per dual triangle (seed Alg. VI, by Cramer's rule).
    for (s, t) in ws.hull.triangles() {
        let [i, j, k] = t.v.map(usize::from);
        let (ni, nj, nk) = (ws.normal[i], ws.normal[j], ws.normal[k]);
        let (cjk, cki, cij) = (nj.cross(&nk), nk.cross(&ni), ni.cross(&nj));
        let det = ni.dot(&cjk);
        ws.vertex[s] = if det.abs() > T::of(64.0) * T::EPSILON {
            (cjk * ws.delta[i] + cki * ws.delta[j] + cij * ws.delta[k]) / det
        } else if t.offset > T::zero() {
            // Nearly dependent normals: unpolarise the dual plane instead (seed Eq. 6–8).
            t.normal / t.offset
        } else {
            Vector3::zeros()
        };
    }

    // Faces of the intersection: fan every face from the foot of x₀ on its plane.
    for i in 0..m {
        ws.first_moment[i] = Vector3::zeros();
    }
    let third = T::of(1.0 / 3.0);
    for (s, t) in ws.hull.triangles() {
        for k in 0..3 {
            let u = t.v[k] as usize;
            let p = ws.vertex[s];
            let q = ws.vertex[t.adj[k] as usize];
            let foot = ws.normal[u] * ws.delta[u];
            let twice = ws.normal[u].dot(&(p - foot).cross(&(q - foot)));
            let tri_area = twice * T::of(0.5);
            ws.area[u] += tri_area;
            ws.first_moment[u] += (foot + p + q) * (tri_area * third);
        }
    }
    Ok(())
}
