//! Incremental Quickhull in fixed-capacity buffers (seed paper Alg. III–V).
//!
//! Builds the convex hull of the dual points of a pair. Everything lives in arrays sized from
//! [`MAX_HULL_POINTS`]: no allocation per pair, the shape the GPU kernel has. The hull is a
//! triangle mesh with adjacency (`adj[k]` is the triangle across edge `v[k] → v[k+1]`), which the
//! overlap computation walks to recover the primal faces.
//!
//! Robustness: a point counts as outside a triangle only when its distance exceeds `eps`, a small
//! multiple of machine epsilon times the largest point coordinate. Points within `eps` of the hull
//! are treated as inside. In the dual setting such a point is a plane that cuts off at most a
//! round-off-sized sliver of the intersection, so dropping it changes the volume by round-off.
//! Each iteration consumes one point as apex, so the loop ends after at most `n` iterations.

use super::Real;
use crate::shape::MAX_TEMPLATE_FACES;
use nalgebra::Vector3;

/// Largest number of points: the face planes of two templates plus a few wall planes.
pub const MAX_HULL_POINTS: usize = 2 * MAX_TEMPLATE_FACES + 8;
/// Largest number of triangle slots (a hull of n points has at most 2n − 4 triangles).
pub const MAX_HULL_FACES: usize = 2 * MAX_HULL_POINTS;

const NONE: u16 = u16::MAX;

/// Why a hull could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum HullError {
    #[error("more than {MAX_HULL_POINTS} points")]
    TooManyPoints,
    #[error("the points span less than three dimensions")]
    Degenerate,
    #[error("triangle capacity exhausted")]
    CapacityExceeded,
    #[error("inconsistent horizon (round-off on near-coplanar points)")]
    Topology,
}

/// One hull triangle.
#[derive(Clone, Copy, Debug, Default)]
pub struct HullTriangle<T: Real> {
    /// Vertex (point) indices, counter-clockwise seen from outside.
    pub v: [u16; 3],
    /// Neighbouring triangle across edge `v[k] → v[(k+1) % 3]`.
    pub adj: [u16; 3],
    /// Outward unit normal.
    pub normal: Vector3<T>,
    /// Plane offset: `normal · y = offset` on the triangle.
    pub offset: T,
    /// The vertex of smallest magnitude, from which distances are measured.
    anchor: u16,
    far: i32,
    far_dist: T,
    alive: bool,
    mark: u32,
}

/// Workspace and result of the incremental Quickhull.
#[derive(Clone, Debug)]
pub struct DualHull<T: Real> {
    pts: [Vector3<T>; MAX_HULL_POINTS],
    n_pts: usize,
    tri: [HullTriangle<T>; MAX_HULL_FACES],
    n_tri: usize,
    free: [u16; MAX_HULL_FACES],
    n_free: usize,
    /// Per point: the triangle it is outside of (≥ 0), -1 inside, -2 a hull vertex.
    conflict: [i32; MAX_HULL_POINTS],
    stack: [u16; MAX_HULL_FACES],
    horizon: [[u16; 3]; MAX_HULL_FACES],
    created: [u16; MAX_HULL_FACES],
    orphans: [u16; MAX_HULL_POINTS],
    epoch: u32,
    eps: T,
}

impl<T: Real> Default for DualHull<T> {
    fn default() -> Self {
        DualHull {
            pts: [Vector3::zeros(); MAX_HULL_POINTS],
            n_pts: 0,
            tri: [HullTriangle::default(); MAX_HULL_FACES],
            n_tri: 0,
            free: [0; MAX_HULL_FACES],
            n_free: 0,
            conflict: [-1; MAX_HULL_POINTS],
            stack: [0; MAX_HULL_FACES],
            horizon: [[0; 3]; MAX_HULL_FACES],
            created: [0; MAX_HULL_FACES],
            orphans: [0; MAX_HULL_POINTS],
            epoch: 0,
            eps: T::zero(),
        }
    }
}

impl<T: Real> DualHull<T> {
    /// The triangles of the finished hull: `(slot, triangle)` for every live slot.
    pub fn triangles(&self) -> impl Iterator<Item = (usize, &HullTriangle<T>)> {
        self.tri[..self.n_tri]
            .iter()
            .enumerate()
            .filter(|(_, t)| t.alive)
    }

    /// Number of triangle slots in use (live or free); slot indices are below this.
    pub fn slots(&self) -> usize {
        self.n_tri
    }

    /// The triangle in `slot`.
    pub fn triangle(&self, slot: usize) -> &HullTriangle<T> {
        &self.tri[slot]
    }

    /// Whether point `i` is a vertex of the hull.
    pub fn is_vertex(&self, i: usize) -> bool {
        self.conflict[i] == -2
    }

    /// The outside tolerance used by the last build.
    pub fn tolerance(&self) -> T {
        self.eps
    }

    /// Builds the hull of `points` (seed Alg. III: initial simplex, then repeated expansion).
    pub fn build(&mut self, points: &[Vector3<T>], eps_factor: T) -> Result<(), HullError> {
        if points.len() > MAX_HULL_POINTS {
            return Err(HullError::TooManyPoints);
        }
        if points.len() < 4 {
            return Err(HullError::Degenerate);
        }
        self.n_pts = points.len();
        self.pts[..points.len()].copy_from_slice(points);
        self.n_tri = 0;
        self.n_free = 0;
        let mut max_coord = T::zero();
        for p in points {
            max_coord = max_coord.max(p.x.abs()).max(p.y.abs()).max(p.z.abs());
        }
        self.eps = eps_factor * T::EPSILON * max_coord;
        for c in self.conflict[..self.n_pts].iter_mut() {
            *c = -1;
        }
        self.init_simplex()?;
        // Each iteration turns one outside point into a hull vertex: at most n iterations.
        for _ in 0..self.n_pts {
            // Expand from the globally farthest outside point (most robust choice).
            let mut best: Option<usize> = None;
            for (s, t) in self.tri[..self.n_tri].iter().enumerate() {
                if t.alive && t.far >= 0 && best.is_none_or(|b| t.far_dist > self.tri[b].far_dist) {
                    best = Some(s);
                }
            }
            let Some(base) = best else {
                return Ok(());
            };
            self.expand(base)?;
        }
        Ok(())
    }

    /// Signed distance of point `p` from triangle `slot`'s plane, measured from the triangle's
    /// smallest vertex: dual hulls of thin overlaps mix points of very different magnitude
    /// (a plane with small δ maps far out), and measuring from a far vertex would put round-off
    /// of that vertex's size on distances between nearby small points.
    fn distance(&self, slot: usize, p: usize) -> T {
        let t = &self.tri[slot];
        t.normal.dot(&(self.pts[p] - self.pts[t.anchor as usize]))
    }

    fn alloc(&mut self) -> Result<usize, HullError> {
        if self.n_free > 0 {
            self.n_free -= 1;
            return Ok(self.free[self.n_free] as usize);
        }
        if self.n_tri >= MAX_HULL_FACES {
            return Err(HullError::CapacityExceeded);
        }
        self.n_tri += 1;
        Ok(self.n_tri - 1)
    }

    /// Creates triangle (a, b, c) with its plane; adjacency is set by the caller.
    fn make(&mut self, a: u16, b: u16, c: u16) -> Result<usize, HullError> {
        let s = self.alloc()?;
        // Cross the two edges leaving the smallest vertex: their round-off is proportional to
        // the triangle's own edges rather than to the largest coordinate involved.
        let ids = [a, b, c];
        let mags = ids.map(|i| self.pts[i as usize].norm_squared());
        let k = if mags[0] <= mags[1] && mags[0] <= mags[2] {
            0
        } else if mags[1] <= mags[2] {
            1
        } else {
            2
        };
        let anchor = ids[k];
        let p0 = self.pts[anchor as usize];
        let p1 = self.pts[ids[(k + 1) % 3] as usize];
        let p2 = self.pts[ids[(k + 2) % 3] as usize];
        let n = (p1 - p0).cross(&(p2 - p0));
        let len = n.norm();
        // A zero-area triangle gets a zero normal: no point is ever outside it, and the
        // overlap computation gives it no area. It only arises from exactly collinear points.
        let normal = if len > T::zero() {
            n / len
        } else {
            Vector3::zeros()
        };
        let offset = normal.dot(&p0);
        self.tri[s] = HullTriangle {
            v: [a, b, c],
            adj: [NONE; 3],
            normal,
            offset,
            anchor,
            far: -1,
            far_dist: T::zero(),
            alive: true,
            mark: 0,
        };
        Ok(s)
    }

    fn init_simplex(&mut self) -> Result<(), HullError> {
        let n = self.n_pts;
        // Two points far apart: the widest pair among the axis extremes.
        let mut ext = [0usize; 6];
        for i in 0..n {
            let p = self.pts[i];
            for k in 0..3 {
                if p[k] < self.pts[ext[2 * k]][k] {
                    ext[2 * k] = i;
                }
                if p[k] > self.pts[ext[2 * k + 1]][k] {
                    ext[2 * k + 1] = i;
                }
            }
        }
        let (mut i0, mut i1, mut best) = (0, 0, T::zero());
        for a in 0..6 {
            for b in a + 1..6 {
                let d = (self.pts[ext[a]] - self.pts[ext[b]]).norm_squared();
                if d > best {
                    (i0, i1, best) = (ext[a], ext[b], d);
                }
            }
        }
        if best.sqrt() <= self.eps {
            return Err(HullError::Degenerate);
        }
        let (p0, p1) = (self.pts[i0], self.pts[i1]);
        let dir = (p1 - p0).normalize();
        let (mut i2, mut best) = (0, T::zero());
        for i in 0..n {
            let v = self.pts[i] - p0;
            let d = (v - dir * v.dot(&dir)).norm_squared();
            if d > best {
                (i2, best) = (i, d);
            }
        }
        if best.sqrt() <= self.eps {
            return Err(HullError::Degenerate);
        }
        let normal = (p1 - p0).cross(&(self.pts[i2] - p0)).normalize();
        let (mut i3, mut best) = (0, T::zero());
        for i in 0..n {
            let d = normal.dot(&(self.pts[i] - p0));
            if d.abs() > best.abs() {
                (i3, best) = (i, d);
            }
        }
        if best.abs() <= self.eps {
            return Err(HullError::Degenerate);
        }
        // Orient base (0,1,2) so that point 3 lies behind it.
        let (i1, i2) = if best > T::zero() { (i2, i1) } else { (i1, i2) };
        let ids = [i0 as u16, i1 as u16, i2 as u16, i3 as u16];
        let layout = [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]];
        let mut slots = [0usize; 4];
        for (f, l) in layout.iter().enumerate() {
            slots[f] = self.make(ids[l[0]], ids[l[1]], ids[l[2]])?;
        }
        // Adjacency: the twin of edge a→b is the edge b→a of another triangle; for the four
        // distinct points of this layout that is always the same triangle.
        const TWIN: [[usize; 3]; 4] = [[1, 2, 3], [3, 2, 0], [1, 3, 0], [2, 1, 0]];
        for (f, &s) in slots.iter().enumerate() {
            for k in 0..3 {
                self.tri[s].adj[k] = slots[TWIN[f][k]] as u16;
            }
        }
        for id in ids {
            self.conflict[id as usize] = -2;
        }
        for p in 0..n {
            if self.conflict[p] == -1 {
                let best = self.farthest_outside(p, slots.iter().copied());
                self.set_conflict(p, best);
            }
        }
        Ok(())
    }

    /// The candidate triangle that point `p` is farthest outside of, beyond the tolerance
    /// (seed Alg. IV).
    fn farthest_outside(
        &self,
        p: usize,
        candidates: impl Iterator<Item = usize>,
    ) -> Option<(usize, T)> {
        let mut best: Option<(usize, T)> = None;
        for s in candidates {
            if !self.tri[s].alive {
                continue;
            }
            let d = self.distance(s, p);
            if d > self.eps && best.is_none_or(|(_, bd)| d > bd) {
                best = Some((s, d));
            }
        }
        best
    }

    /// Records that `p` is outside triangle `best.0` (or inside the hull when `None`), keeping
    /// each triangle's farthest outside point.
    fn set_conflict(&mut self, p: usize, best: Option<(usize, T)>) {
        match best {
            Some((s, d)) => {
                self.conflict[p] = s as i32;
                let t = &mut self.tri[s];
                if t.far < 0 || d > t.far_dist {
                    t.far = p as i32;
                    t.far_dist = d;
                }
            }
            None => self.conflict[p] = -1,
        }
    }

    /// Adds the farthest outside point of triangle `base` to the hull (seed Alg. V).
    fn expand(&mut self, base: usize) -> Result<(), HullError> {
        let apex = self.tri[base].far as usize;
        self.conflict[apex] = -2;
        self.epoch = self.epoch.wrapping_add(1).max(1);
        let epoch = self.epoch;

        // Visible triangles by depth-first search from `base`; horizon edges are the edges
        // between a visible and a non-visible triangle.
        let mut n_stack = 1;
        self.stack[0] = base as u16;
        self.tri[base].mark = epoch;
        let mut n_horizon = 0;
        while n_stack > 0 {
            n_stack -= 1;
            let s = self.stack[n_stack] as usize;
            for k in 0..3 {
                let g = self.tri[s].adj[k] as usize;
                if self.tri[g].mark == epoch {
                    continue;
                }
                if self.distance(g, apex) > self.eps {
                    self.tri[g].mark = epoch;
                    self.stack[n_stack] = g as u16;
                    n_stack += 1;
                } else {
                    let t = &self.tri[s];
                    self.horizon[n_horizon] = [t.v[k], t.v[(k + 1) % 3], g as u16];
                    n_horizon += 1;
                }
            }
        }
        if n_horizon < 3 {
            return Err(HullError::Topology);
        }

        // Points that were outside a visible triangle must be re-assigned.
        let mut n_orphans = 0;
        for p in 0..self.n_pts {
            let c = self.conflict[p];
            if c >= 0 && self.tri[c as usize].mark == epoch {
                self.orphans[n_orphans] = p as u16;
                n_orphans += 1;
            }
        }
        // Delete the visible triangles.
        for s in 0..self.n_tri {
            if self.tri[s].alive && self.tri[s].mark == epoch {
                self.tri[s].alive = false;
                self.tri[s].mark = 0;
                self.free[self.n_free] = s as u16;
                self.n_free += 1;
            }
        }
        // New triangles (a, b, apex) on each horizon edge a→b, keeping the orientation.
        for h in 0..n_horizon {
            let [a, b, g] = self.horizon[h];
            let s = self.make(a, b, apex as u16)?;
            self.created[h] = s as u16;
            self.tri[s].adj[0] = g;
            let gt = &mut self.tri[g as usize];
            for j in 0..3 {
                if gt.v[j] == b && gt.v[(j + 1) % 3] == a {
                    gt.adj[j] = s as u16;
                }
            }
        }
        // Link the new triangles around the apex: edge b→apex of (a, b, apex) meets edge
        // apex→b of the triangle whose horizon edge starts at b. A horizon that is not a simple
        // cycle (each vertex once as a start and once as an end) is a round-off failure.
        for h in 0..n_horizon {
            let [a, b, _] = self.horizon[h];
            let (mut next, mut prev) = (NONE, NONE);
            for j in 0..n_horizon {
                if self.horizon[j][0] == b {
                    if next != NONE {
                        return Err(HullError::Topology);
                    }
                    next = self.created[j];
                }
                if self.horizon[j][1] == a {
                    if prev != NONE {
                        return Err(HullError::Topology);
                    }
                    prev = self.created[j];
                }
            }
            if next == NONE || prev == NONE {
                return Err(HullError::Topology);
            }
            let s = self.created[h] as usize;
            self.tri[s].adj[1] = next;
            self.tri[s].adj[2] = prev;
        }
        // Re-assign orphans to the new triangles; a point outside none of them may still be
        // outside an older triangle, so those fall back to a scan of every live triangle.
        for o in 0..n_orphans {
            let p = self.orphans[o] as usize;
            let new = (0..n_horizon).map(|h| self.created[h] as usize);
            let mut best = self.farthest_outside(p, new);
            if best.is_none() {
                best = self.farthest_outside(p, 0..self.n_tri);
            }
            self.set_conflict(p, best);
        }
        Ok(())
    }
}
