//! Walls: triangulated surfaces (STL/OBJ) as rigid bodies, their facets binned in the wall's own
//! frame, and the contact of a particle with a whole wall.
//!
//! Each facet owns the part of space behind it that lies within its three side planes
//! (seed paper Sec. 2.4 computes the overlap area facet by facet; we compute the penetrating
//! volume, [`crate::geometry::clip`]). A side plane on an edge shared with another facet is the
//! bisector of the two facets' side planes, so that the regions of neighbouring facets meet on
//! one plane: behind a flat wall they tile the half-space whatever the triangulation, behind a
//! convex edge they leave no gap, and in a concave corner they do not overlap. A particle's
//! contact with a wall sums the penetrating volumes `V = Σ V_f`, their gradients and surface
//! moments over the facets it reaches, and the contact law is applied once to the total: the
//! force is then independent of how the wall is meshed and is never counted twice across shared
//! edges and vertices.

use super::facet_grid::{FacetGrid, triangle_meets_box};
use crate::geometry::clip::{facet_prism, prism_overlap_culled};
use crate::geometry::overlap::{OverlapError, OverlapWorkspace};
use crate::geometry::sphere::sphere_facet;
use crate::geometry::{Overlap, Plane, PosedPolytope};
use crate::shape::ConvexTemplate;
use nalgebra::{Isometry3, Point3, Vector3};
use std::collections::HashMap;

/// A vertex's coordinates as bits, to find shared edges exactly.
type VertexKey = [u64; 3];

/// A wall mesh in its own (t = 0) frame, ready for contact queries.
#[derive(Clone, Debug)]
pub struct WallMesh {
    /// Triangles, counter-clockwise seen from the side particles are on.
    pub triangles: Vec<[Vector3<f64>; 3]>,
    /// Per facet: its plane, then the side planes of edges (0→1, 1→2, 2→0).
    pub prisms: Vec<[Plane<f64>; 4]>,
    grid: FacetGrid,
}

impl WallMesh {
    /// Builds the prisms (with bisector side planes on shared edges) and the facet grid, with
    /// grid cells about `cell` wide (the particles' cutoff is a good choice). Degenerate
    /// (zero-area) triangles are dropped: they bound no region.
    pub fn new(triangles: &[[Vector3<f64>; 3]], cell: f64) -> Self {
        let mut tris = Vec::with_capacity(triangles.len());
        let mut prisms = Vec::with_capacity(triangles.len());
        for t in triangles {
            if let Some(p) = facet_prism(t) {
                tris.push(*t);
                prisms.push(p);
            }
        }
        // Edge → facets sharing it, by exact vertex coordinates (shared vertices of a mesh are
        // bitwise equal in STL and OBJ files).
        let key = |v: &Vector3<f64>| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
        let mut edges: HashMap<(VertexKey, VertexKey), Vec<(usize, usize)>> = HashMap::new();
        for (f, t) in tris.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (key(&t[k]), key(&t[(k + 1) % 3]));
                edges
                    .entry(if a < b { (a, b) } else { (b, a) })
                    .or_default()
                    .push((f, k));
            }
        }
        let mut edge_list: Vec<_> = edges.into_values().collect();
        edge_list.sort(); // deterministic order
        for sharing in edge_list {
            if let [(f, kf), (g, kg)] = sharing[..] {
                let (sf, sg) = (prisms[f][kf + 1].normal, prisms[g][kg + 1].normal);
                let m = sf - sg;
                if m.norm() > 1e-9 {
                    let m = m.normalize();
                    let p = tris[f][kf];
                    prisms[f][kf + 1] = Plane {
                        normal: m,
                        offset: m.dot(&p),
                    };
                    prisms[g][kg + 1] = Plane {
                        normal: -m,
                        offset: -m.dot(&p),
                    };
                }
            }
        }
        let grid = FacetGrid::new(&tris, cell);
        WallMesh {
            triangles: tris,
            prisms,
            grid,
        }
    }

    /// The facets that meet the box `lo..hi`, with their prisms as built on the whole mesh
    /// (bisector side planes need the facets' neighbours, which may lie outside), in the
    /// original order, and a grid of cells about `cell` wide over them: for any point whose
    /// reach stays inside the box, [`WallMesh::facets_near`] then lists the same facets in the
    /// same order as on the whole mesh, so sums over them are bitwise the same. A rank of a
    /// decomposed run keeps only the facets that reach its subdomain plus the halo.
    pub fn restricted(&self, lo: &Vector3<f64>, hi: &Vector3<f64>, cell: f64) -> WallMesh {
        let centre = 0.5 * (lo + hi);
        let half = 0.5 * (hi - lo) * (1.0 + 1e-9);
        let keep: Vec<usize> = (0..self.triangles.len())
            .filter(|&f| triangle_meets_box(&self.triangles[f], &centre, &half))
            .collect();
        let triangles: Vec<_> = keep.iter().map(|&f| self.triangles[f]).collect();
        let prisms = keep.iter().map(|&f| self.prisms[f]).collect();
        let grid = FacetGrid::new(&triangles, cell);
        WallMesh {
            triangles,
            prisms,
            grid,
        }
    }

    /// Number of facets.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether the mesh has no facets.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The facet grid as flat arrays, for the GPU backend.
    pub fn grid_parts(&self) -> FacetGridParts<'_> {
        let g = &self.grid;
        FacetGridParts {
            min: g.min,
            size: g.size,
            dims: g.dims,
            start: &g.start,
            items: &g.items,
        }
    }

    /// Facets within `reach` of point `x` (wall frame), in increasing index order.
    pub fn facets_near(&self, x: &Vector3<f64>, reach: f64, out: &mut Vec<u32>) {
        out.clear();
        self.grid.candidates(x, reach, out);
        out.sort_unstable();
        out.dedup();
        out.retain(|&f| point_triangle_distance(x, &self.triangles[f as usize]) <= reach);
    }

    /// The contact of `body` (placed in the wall frame) with the facets `facets`: total
    /// penetrating volume, its centroid, `S = Σ S_f` (derivative with respect to moving the wall;
    /// `−S` for the particle) and the wall's surface moment about the centroid. The body is
    /// placed from `placed_from` (template, scale, pose in the wall frame), each facet clipped
    /// on the planes that can bound its overlap ([`prism_overlap_culled`]).
    pub fn contact(
        &self,
        ws: &mut OverlapWorkspace<f64>,
        body: &mut PosedPolytope<f64>,
        placed_from: (&ConvexTemplate, f64, &Isometry3<f64>),
        facets: &[u32],
    ) -> Result<Overlap<f64>, OverlapError> {
        let mut sum = FacetSum::default();
        for &f in facets {
            sum.add(&prism_overlap_culled(
                ws,
                body,
                placed_from,
                &Vector3::zeros(),
                &self.prisms[f as usize],
            )?);
        }
        Ok(sum.total())
    }

    /// As [`WallMesh::contact`] for an exact sphere of radius `r` centred at `c` (wall frame):
    /// each facet's share of the cap behind its plane ([`sphere_facet`], the sphere fast path).
    pub fn sphere_contact(&self, c: &Vector3<f64>, r: f64, facets: &[u32]) -> Overlap<f64> {
        let mut sum = FacetSum::default();
        for &f in facets {
            let f = f as usize;
            sum.add(&sphere_facet(
                c,
                r,
                &self.triangles[f],
                &self.prisms[f][0].normal,
            ));
        }
        sum.total()
    }
}

/// The sum of a particle's facet overlaps in facet order: volumes, first moments and `S` add;
/// the surface moments are carried about the origin and moved to the total centroid.
#[derive(Default)]
struct FacetSum {
    total: Overlap<f64>,
    first_moment: Vector3<f64>,
    moment_origin: Vector3<f64>, // Σ (M_f + c_f × S_f), about the origin
}

impl FacetSum {
    fn add(&mut self, o: &Overlap<f64>) {
        if o.volume > 0.0 {
            self.total.volume += o.volume;
            self.first_moment += o.centroid * o.volume;
            self.total.dv_dxb += o.dv_dxb;
            self.moment_origin += o.moment_b + o.centroid.cross(&o.dv_dxb);
            self.total.depth = self.total.depth.max(o.depth);
            self.total.thickness = self.total.thickness.max(o.thickness);
        }
    }

    fn total(self) -> Overlap<f64> {
        let mut total = self.total;
        if total.volume > 0.0 {
            total.centroid = self.first_moment / total.volume;
            total.moment_b = self.moment_origin - total.centroid.cross(&total.dv_dxb);
        }
        total
    }
}

/// A wall's facet grid as flat arrays: cell `(x, y, z)` is
/// `(z · dims[1] + y) · dims[0] + x`, of width `size` from `min`, and holds the facets
/// `items[start[c] .. start[c + 1]]`.
pub struct FacetGridParts<'a> {
    pub min: Vector3<f64>,
    pub size: f64,
    pub dims: [usize; 3],
    pub start: &'a [u32],
    pub items: &'a [u32],
}

/// The most any point of the box `lo..hi` (world frame) moved in a wall's own frame between the
/// wall's poses `from` and `to`: max over the box of |to⁻¹ x − from⁻¹ x|. The displacement is
/// an affine function of x and its norm is convex, so the maximum is at one of the box's eight
/// corners. A list of facets near each particle, built with a skin at pose `from`, stays
/// complete while a particle's own motion plus this stays within the skin's margin (the GPU's
/// wall list).
pub fn frame_drift(
    from: &Isometry3<f64>,
    to: &Isometry3<f64>,
    lo: &Vector3<f64>,
    hi: &Vector3<f64>,
) -> f64 {
    if from == to {
        return 0.0;
    }
    (0..8)
        .map(|c: usize| {
            let corner = Point3::from(Vector3::from_fn(|k, _| {
                if c >> k & 1 == 0 { lo[k] } else { hi[k] }
            }));
            (to.inverse_transform_point(&corner) - from.inverse_transform_point(&corner)).norm()
        })
        .fold(0.0, f64::max)
}

/// Distance from `x` to triangle `t` (Ericson, "Real-Time Collision Detection" §5.1.5).
pub fn point_triangle_distance(x: &Vector3<f64>, t: &[Vector3<f64>; 3]) -> f64 {
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (b - a, c - a, x - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.norm();
    }
    let bp = x - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.norm();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (x - (a + ab * (d1 / (d1 - d3)))).norm();
    }
    let cp = x - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.norm();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (x - (a + ac * (d2 / (d2 - d6)))).norm();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (x - (b + (c - b) * w)).norm();
    }
    let denom = 1.0 / (va + vb + vc);
    (x - (a + ab * (vb * denom) + ac * (vc * denom))).norm()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Generator;
    use nalgebra::UnitQuaternion;

    /// `frame_drift` bounds the displacement in the wall's frame of every point of the box
    /// (10 000 random points per pose pair, random rotations and translations) and is reached
    /// at a corner (its value is a corner's displacement, so no smaller bound holds).
    #[test]
    fn frame_drift_bounds_every_point_of_the_box() {
        let mut rng = crate::rng::Rng::new(5);
        let (lo, hi) = (Vector3::new(-0.2, -0.1, 0.0), Vector3::new(0.3, 0.1, 0.4));
        let pose = |rng: &mut crate::rng::Rng, size: f64| {
            let axis = nalgebra::Unit::new_normalize(Vector3::from_fn(|_, _| rng.uniform() - 0.5));
            Isometry3::from_parts(
                Vector3::from_fn(|_, _| size * (rng.uniform() - 0.5)).into(),
                UnitQuaternion::from_axis_angle(&axis, size * (rng.uniform() - 0.5)),
            )
        };
        assert_eq!(
            frame_drift(&pose(&mut rng, 0.0), &pose(&mut rng, 0.0), &lo, &hi),
            0.0
        );
        for size in [1e-4, 1e-2, 1.0] {
            for _ in 0..20 {
                let (a, b) = (pose(&mut rng, size), pose(&mut rng, size));
                let bound = frame_drift(&a, &b, &lo, &hi);
                assert!(bound > 0.0);
                let mut worst = 0.0f64;
                for _ in 0..10_000 {
                    let x = Point3::from(Vector3::from_fn(|k, _| {
                        lo[k] + (hi[k] - lo[k]) * rng.uniform()
                    }));
                    let d = (b.inverse_transform_point(&x) - a.inverse_transform_point(&x)).norm();
                    worst = worst.max(d);
                }
                assert!(worst <= bound * (1.0 + 1e-12), "{worst} > {bound}");
                // Random points come within a few per cent of the corners' value.
                assert!(worst > 0.8 * bound, "{worst} vs {bound}");
            }
        }
    }

    /// The facets the grid finds near a point are exactly those within reach (brute force over
    /// every facet), on a cone of long slanted slivers (a hopper) where the triangle–cell test
    /// lists each facet in far fewer cells than its bounding box spans.
    #[test]
    fn facets_near_finds_every_facet_within_reach_of_a_cone() {
        let n = 64;
        let ring = |r: f64, z: f64, k: usize| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            Vector3::new(r * a.cos(), r * a.sin(), z)
        };
        let mut tris = Vec::new();
        for k in 0..n {
            let (a, b) = (ring(0.02, 0.0, k), ring(0.02, 0.0, k + 1));
            let (c, d) = (ring(0.3, 0.3, k), ring(0.3, 0.3, k + 1));
            tris.push([a, d, c]);
            tris.push([a, b, d]);
        }
        let mesh = WallMesh::new(&tris, 0.01);
        let listed = mesh.grid.items.len();
        let mut rng = crate::rng::Rng::new(11);
        let (mut found, mut out) = (0, Vec::new());
        for _ in 0..4000 {
            let x = Vector3::new(
                rng.range(-0.32, 0.32),
                rng.range(-0.32, 0.32),
                rng.range(-0.02, 0.32),
            );
            let reach = rng.range(0.001, 0.02);
            mesh.facets_near(&x, reach, &mut out);
            let brute: Vec<u32> = (0..tris.len() as u32)
                .filter(|&f| point_triangle_distance(&x, &mesh.triangles[f as usize]) <= reach)
                .collect();
            assert_eq!(out, brute, "at {x}, reach {reach}");
            found += out.len();
        }
        assert!(found > 500, "{found} facets found in all");
        // Bounding-box binning lists each sliver in the ~2500 cells of its box (3e5 entries).
        println!("cone: {listed} cell entries for {} facets", tris.len());
        assert!(listed < 40_000, "{listed} cell entries");
    }

    /// A slender mesh (a reactor tube 25 mm wide and 1.8 m tall, as in the fixed-bed scene) is
    /// binned in cells of the particles' size, not 1/64 of its height, and the grid still finds
    /// exactly the facets within reach.
    #[test]
    fn a_slender_tube_is_binned_at_the_particles_size() {
        let (n, bands, r, h) = (64, 90, 0.0125, 1.8);
        let at = |k: usize, j: usize| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            Vector3::new(r * a.cos(), r * a.sin(), h * j as f64 / bands as f64)
        };
        let mut tris = Vec::new();
        for j in 0..bands {
            for k in 0..n {
                let (a, b, c, d) = (at(k, j), at(k + 1, j), at(k + 1, j + 1), at(k, j + 1));
                tris.push([a, d, c]);
                tris.push([a, c, b]);
            }
        }
        let cell = 0.0086;
        let mesh = WallMesh::new(&tris, cell);
        assert_eq!(mesh.grid.size, cell);
        assert_eq!(mesh.grid.dims, [3, 3, 210]);
        let mut rng = crate::rng::Rng::new(5);
        let (mut found, mut out, mut candidates) = (0, Vec::new(), 0);
        for _ in 0..2000 {
            let x = Vector3::new(
                rng.range(-0.012, 0.012),
                rng.range(-0.012, 0.012),
                rng.range(0.0, h),
            );
            let reach = 0.0039;
            mesh.grid.candidates(&x, reach, &mut out);
            candidates += out.len();
            mesh.facets_near(&x, reach, &mut out);
            let brute: Vec<u32> = (0..tris.len() as u32)
                .filter(|&f| point_triangle_distance(&x, &mesh.triangles[f as usize]) <= reach)
                .collect();
            assert_eq!(out, brute, "at {x}");
            found += out.len();
        }
        assert!(found > 1000, "{found} facets found in all");
        println!("tube: {} candidates per query", candidates / 2000);
        // Cells of 1/64 of the height (28 mm) held whole rings: about 350 candidates a query.
        assert!(
            candidates < 2000 * 200,
            "{} candidates per query",
            candidates / 2000
        );
    }

    /// A mesh restricted to a box lists, for points whose reach stays in the box, the same
    /// facets in the same order as the whole mesh (mapped back to the whole mesh's indices).
    #[test]
    fn restricted_mesh_finds_the_same_facets_in_the_same_order() {
        let n = 48;
        let ring = |r: f64, z: f64, k: usize| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            Vector3::new(r * a.cos(), r * a.sin(), z)
        };
        let mut tris = Vec::new();
        for k in 0..n {
            let (a, b) = (ring(0.05, 0.0, k), ring(0.05, 0.0, k + 1));
            let (c, d) = (ring(0.3, 0.3, k), ring(0.3, 0.3, k + 1));
            tris.push([a, d, c]);
            tris.push([a, b, d]);
        }
        let full = WallMesh::new(&tris, 0.02);
        let (lo, hi) = (Vector3::new(0.0, -0.1, 0.0), Vector3::new(0.35, 0.2, 0.35));
        let part = full.restricted(&lo, &hi, 0.02);
        assert!(
            part.len() < full.len() && part.len() > 10,
            "{} facets",
            part.len()
        );
        let index: Vec<usize> = part
            .triangles
            .iter()
            .map(|t| full.triangles.iter().position(|u| u == t).unwrap())
            .collect();
        assert!(index.windows(2).all(|w| w[0] < w[1]), "original order kept");
        let mut rng = crate::rng::Rng::new(5);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let mut found = 0;
        for _ in 0..3000 {
            let reach = rng.range(0.005, 0.03);
            let x = Vector3::from_fn(|k, _| rng.range(lo[k] + reach, hi[k] - reach));
            full.facets_near(&x, reach, &mut a);
            part.facets_near(&x, reach, &mut b);
            let mapped: Vec<u32> = b.iter().map(|&f| index[f as usize] as u32).collect();
            assert_eq!(a, mapped, "at {x}");
            for (&f, &g) in a.iter().zip(&b) {
                assert_eq!(full.prisms[f as usize], part.prisms[g as usize]);
            }
            found += a.len();
        }
        assert!(found > 300, "{found}");
    }

    fn cube() -> ConvexTemplate {
        Generator::Cube { size: 3f64.sqrt() }.build().unwrap() // unit edge
    }

    fn body(pose: &Isometry3<f64>) -> Box<PosedPolytope<f64>> {
        let mut b = Box::<PosedPolytope<f64>>::default();
        b.place(&cube(), 1.0, pose, &Vector3::zeros());
        b
    }

    /// A unit cube pushed into the concave corner of an L-shaped wall (floor z = 0 and side
    /// x = 0): the penetrating volumes of the two walls add up without double counting, and a
    /// convex step edge leaves no gap.
    #[test]
    fn corners_neither_double_count_nor_leave_gaps() {
        let v = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        // Floor for x ≥ 0 and a side wall for z ≥ 0, meeting on the y axis (concave edge).
        let floor = [
            [v(0.0, -2.0, 0.0), v(3.0, -2.0, 0.0), v(3.0, 2.0, 0.0)],
            [v(0.0, -2.0, 0.0), v(3.0, 2.0, 0.0), v(0.0, 2.0, 0.0)],
        ];
        let side = [
            [v(0.0, -2.0, 0.0), v(0.0, 2.0, 0.0), v(0.0, 2.0, 3.0)],
            [v(0.0, -2.0, 0.0), v(0.0, 2.0, 3.0), v(0.0, -2.0, 3.0)],
        ];
        let mesh = WallMesh::new(&[floor[0], floor[1], side[0], side[1]], 1.0);
        let mut ws = OverlapWorkspace::<f64>::boxed();
        // Cube centred at (0.5 − a, 0, 0.5 − b): it pokes a into the side wall and b into the
        // floor. The solid behind an L corner is {x < 0} ∪ {z < 0}: the volume behind it is
        // a·1·1 + b·1·1 − a·b·1 (the corner column counted once).
        for (a, b) in [(0.1, 0.2), (0.05, 0.05), (0.3, 0.01)] {
            let pose = Isometry3::translation(0.5 - a, 0.0, 0.5 - b);
            let mut bb = body(&pose);
            let mut facets = Vec::new();
            mesh.facets_near(&Vector3::new(0.5 - a, 0.0, 0.5 - b), 0.9, &mut facets);
            let o = mesh
                .contact(&mut ws, &mut bb, (&cube(), 1.0, &pose), &facets)
                .unwrap();
            let expected = a + b - a * b;
            assert!(
                (o.volume - expected).abs() < 1e-12,
                "a {a}, b {b}: V {} vs {expected}",
                o.volume
            );
        }
        // A flat floor cut into many triangles pushes like the same floor in two.
        let fine: Vec<_> = (0..8)
            .flat_map(|i| {
                let x0 = -2.0 + 0.5 * i as f64;
                [
                    [
                        v(x0, -2.0, 0.0),
                        v(x0 + 0.5, -2.0, 0.0),
                        v(x0 + 0.5, 2.0, 0.0),
                    ],
                    [v(x0, -2.0, 0.0), v(x0 + 0.5, 2.0, 0.0), v(x0, 2.0, 0.0)],
                ]
            })
            .collect();
        let coarse = [
            [v(-2.0, -2.0, 0.0), v(2.0, -2.0, 0.0), v(2.0, 2.0, 0.0)],
            [v(-2.0, -2.0, 0.0), v(2.0, 2.0, 0.0), v(-2.0, 2.0, 0.0)],
        ];
        let q = UnitQuaternion::from_euler_angles(0.3, 0.5, -0.2);
        let pose = Isometry3::from_parts(Vector3::new(0.13, -0.4, 0.6).into(), q);
        let mut bb = body(&pose);
        let mut results = Vec::new();
        for tris in [&fine[..], &coarse[..]] {
            let mesh = WallMesh::new(tris, 1.0);
            let mut facets = Vec::new();
            mesh.facets_near(&pose.translation.vector, 0.9, &mut facets);
            results.push(
                mesh.contact(&mut ws, &mut bb, (&cube(), 1.0, &pose), &facets)
                    .unwrap(),
            );
        }
        assert!(results[0].volume > 1e-3);
        assert!((results[0].volume - results[1].volume).abs() < 1e-12 * results[0].volume);
        assert!((results[0].dv_dxb - results[1].dv_dxb).norm() < 1e-12);
        assert!((results[0].moment_b - results[1].moment_b).norm() < 1e-12);
    }
}
