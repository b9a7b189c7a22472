//! The particles of a state as solids in space: which points they cover and how high they
//! reach along a vertical line. Packing observables ([`super::fill`], [`super::porosity`]) are
//! built on these two queries.

use crate::shape::ConvexTemplate;
use crate::state::{ParticleType, Particles};
use nalgebra::Vector3;

/// One particle in world coordinates: a convex polyhedron as the intersection of its face
/// half-spaces `n · x ≤ d`, or an exact sphere.
#[derive(Clone, Debug)]
enum Solid {
    Polyhedron { planes: Vec<(Vector3<f64>, f64)> },
    Sphere,
}

/// The particles of a state, placed, with a uniform grid over their centres for the queries.
#[derive(Clone, Debug)]
pub struct PackedSolids {
    solids: Vec<Solid>,
    centre: Vec<Vector3<f64>>,
    radius: Vec<f64>,
    volume: Vec<f64>,
    /// Highest point of each particle (its topmost vertex, or the sphere's pole).
    top: Vec<f64>,
    /// Grid: lower corner, cell size (twice the largest radius), dimensions, and the particles
    /// of each cell (counting-sort layout: `order[start[c]..start[c + 1]]`).
    lo: Vector3<f64>,
    cell: f64,
    dims: [usize; 3],
    start: Vec<u32>,
    order: Vec<u32>,
}

impl PackedSolids {
    /// Places every particle of `particles` (types `types`, templates `templates`) at its pose:
    /// face planes rotated and scaled into the world, spheres as centre and radius.
    pub fn new(
        templates: &[ConvexTemplate],
        types: &[ParticleType],
        particles: &Particles,
    ) -> Self {
        Self::within(templates, types, particles, |_| true)
    }

    /// Places the particles of `particles` whose centre `keep` accepts: the contents of one
    /// container of a scene that holds several side by side.
    pub fn within(
        templates: &[ConvexTemplate],
        types: &[ParticleType],
        particles: &Particles,
        keep: impl Fn(&Vector3<f64>) -> bool,
    ) -> Self {
        let kept: Vec<usize> = (0..particles.len())
            .filter(|&i| keep(&particles.position[i]))
            .collect();
        let n = kept.len();
        let mut solids = Vec::with_capacity(n);
        let mut radius = Vec::with_capacity(n);
        let mut volume = Vec::with_capacity(n);
        let mut top = Vec::with_capacity(n);
        for &i in &kept {
            let t = &templates[types[particles.kind[i] as usize].template];
            let (s, q, x) = (
                particles.scale[i],
                particles.orientation[i],
                particles.position[i],
            );
            radius.push(t.circumscribed_radius * s);
            top.push(if t.sphere {
                x.z + t.circumscribed_radius * s
            } else {
                let up = t.vertices.iter().map(|v| (q * (v.coords * s)).z);
                x.z + up.fold(f64::NEG_INFINITY, f64::max)
            });
            // A sphere template's volume is the exact ball's (`ConvexTemplate::into_sphere`).
            volume.push(t.volume * s * s * s);
            solids.push(if t.sphere {
                Solid::Sphere
            } else {
                Solid::Polyhedron {
                    planes: t
                        .faces
                        .iter()
                        .map(|f| {
                            let nw = q.transform_vector(&f.normal);
                            (nw, f.offset * s + nw.dot(&x))
                        })
                        .collect(),
                }
            });
        }
        let centre: Vec<Vector3<f64>> = kept.iter().map(|&i| particles.position[i]).collect();
        let r_max = radius.iter().cloned().fold(0.0, f64::max);
        let cell = if r_max > 0.0 { 2.0 * r_max } else { 1.0 };
        let (mut lo, mut hi) = (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        );
        for x in &centre {
            lo = lo.inf(x);
            hi = hi.sup(x);
        }
        if n == 0 {
            lo = Vector3::zeros();
            hi = Vector3::zeros();
        }
        let dims = [0, 1, 2].map(|k| (((hi[k] - lo[k]) / cell).floor() as usize + 1).min(1 << 12));
        let mut grid = PackedSolids {
            solids,
            centre,
            radius,
            volume,
            top,
            lo,
            cell,
            dims,
            start: Vec::new(),
            order: Vec::new(),
        };
        let cells: Vec<usize> = (0..n)
            .map(|i| grid.cell_index(&grid.cell_of(&grid.centre[i])))
            .collect();
        let mut start = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        for &c in &cells {
            start[c + 1] += 1;
        }
        for c in 1..start.len() {
            start[c] += start[c - 1];
        }
        let mut fill = start.clone();
        let mut order = vec![0u32; n];
        for (i, &c) in cells.iter().enumerate() {
            order[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        grid.start = start;
        grid.order = order;
        grid
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.solids.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.solids.is_empty()
    }

    /// Volume of particle `i`.
    pub fn volume(&self, i: usize) -> f64 {
        self.volume[i]
    }

    fn cell_of(&self, x: &Vector3<f64>) -> [usize; 3] {
        [0, 1, 2].map(|k| {
            let c = ((x[k] - self.lo[k]) / self.cell).floor();
            (c.max(0.0) as usize).min(self.dims[k] - 1)
        })
    }

    fn cell_index(&self, c: &[usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// The particles whose centre lies in the cells from `a` to `b` (inclusive, per axis).
    fn in_cells(&self, a: [usize; 3], b: [usize; 3], mut visit: impl FnMut(usize)) {
        for z in a[2]..=b[2] {
            for y in a[1]..=b[1] {
                for x in a[0]..=b[0] {
                    let c = self.cell_index(&[x, y, z]);
                    for &i in &self.order[self.start[c] as usize..self.start[c + 1] as usize] {
                        visit(i as usize);
                    }
                }
            }
        }
    }

    /// The range of cells a ball of radius `r` about `x` may reach particles from.
    fn cells_near(&self, x: &Vector3<f64>, r: f64) -> ([usize; 3], [usize; 3]) {
        (
            self.cell_of(&(x - Vector3::repeat(r))),
            self.cell_of(&(x + Vector3::repeat(r))),
        )
    }

    /// Whether particle `i` covers the point `x` (its closed solid).
    pub fn particle_contains(&self, i: usize, x: &Vector3<f64>) -> bool {
        match &self.solids[i] {
            Solid::Sphere => (x - self.centre[i]).norm_squared() <= self.radius[i] * self.radius[i],
            Solid::Polyhedron { planes } => planes.iter().all(|(n, d)| n.dot(x) <= *d),
        }
    }

    /// Whether any particle covers the point `x`.
    pub fn contains(&self, x: &Vector3<f64>) -> bool {
        if self.is_empty() {
            return false;
        }
        let (a, b) = self.cells_near(x, self.cell / 2.0);
        let mut hit = false;
        self.in_cells(a, b, |i| {
            hit = hit
                || ((x - self.centre[i]).norm_squared() <= self.radius[i] * self.radius[i]
                    && self.particle_contains(i, x));
        });
        hit
    }

    /// The highest point of particle `i` on the vertical line through `(x, y)`, if the line
    /// meets it: the smallest upper bound `z ≤ (d − n_x x − n_y y)/n_z` over faces facing up,
    /// provided it is above every lower bound of the faces facing down and the line is inside
    /// every vertical face.
    pub fn particle_top_at(&self, i: usize, x: f64, y: f64) -> Option<f64> {
        match &self.solids[i] {
            Solid::Sphere => {
                let c = self.centre[i];
                let h2 = self.radius[i].powi(2) - (x - c.x).powi(2) - (y - c.y).powi(2);
                (h2 >= 0.0).then(|| c.z + h2.sqrt())
            }
            Solid::Polyhedron { planes } => {
                let (mut upper, mut lower) = (f64::INFINITY, f64::NEG_INFINITY);
                for (n, d) in planes {
                    let c = d - n.x * x - n.y * y;
                    if n.z > 1e-12 {
                        upper = upper.min(c / n.z);
                    } else if n.z < -1e-12 {
                        lower = lower.max(c / n.z);
                    } else if c < 0.0 {
                        return None;
                    }
                }
                (upper >= lower && upper.is_finite()).then_some(upper)
            }
        }
    }

    /// The highest solid point on the vertical line through `(x, y)`, if any particle meets it.
    pub fn top_at(&self, x: f64, y: f64) -> Option<f64> {
        if self.is_empty() {
            return None;
        }
        let half = self.cell / 2.0;
        let a = self.cell_of(&Vector3::new(x - half, y - half, f64::NEG_INFINITY));
        let b = self.cell_of(&Vector3::new(x + half, y + half, f64::INFINITY));
        let mut top: Option<f64> = None;
        self.in_cells(a, b, |i| {
            let c = self.centre[i];
            if (x - c.x).powi(2) + (y - c.y).powi(2) > self.radius[i].powi(2) {
                return;
            }
            if let Some(z) = self.particle_top_at(i, x, y) {
                top = Some(top.map_or(z, |t: f64| t.max(z)));
            }
        });
        top
    }

    /// The highest point of any particle (its topmost vertex, or a sphere's pole); `None`
    /// without particles.
    pub fn highest_point(&self) -> Option<f64> {
        self.top.iter().cloned().reduce(f64::max)
    }
}
