//! Coplanar hull triangles merged into polygon faces (step 2 of [`super::hull`]): regions of
//! adjacent triangles grown from the largest, against the seed triangle's fixed plane, with
//! slivers joined to a neighbour, each region's boundary read as its face loop.

use super::MAX_TEMPLATE_FACES;
use super::hull::AttemptError;
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// One merged face before vertex selection.
pub(super) struct Region {
    /// Unit outward normal: the normalised sum of the member triangles' area vectors.
    pub(super) normal: Vector3<f64>,
    /// Boundary loop (hull vertex indices), counter-clockwise seen from outside.
    pub(super) boundary: Vec<usize>,
}

/// Groups the closed triangle mesh `tris` into planar regions (step 2 of [`super::hull`]'s
/// module docs): regions grown from the largest triangles, slivers joined to a neighbour, each
/// region's boundary read as its face loop.
pub(super) fn merge_regions(
    hull: &[Point3<f64>],
    tris: &[[usize; 3]],
    tol: f64,
) -> Result<Vec<Region>, AttemptError> {
    let mesh = Mesh::new(hull, tris)?;
    let (mut region, count) = mesh.grow_regions(tol);
    mesh.join_slivers(&mut region, count, tol)?;
    mesh.boundary_loops(&region)
}

/// The hull's triangles with their directed edges: each edge's triangle, whose twin (the edge
/// reversed) is the neighbour across it.
struct Mesh<'a> {
    hull: &'a [Point3<f64>],
    tris: &'a [[usize; 3]],
    edge_tri: HashMap<(usize, usize), usize>,
}

impl<'a> Mesh<'a> {
    /// The directed edge map; the quickhull output must be a closed, oriented manifold.
    fn new(hull: &'a [Point3<f64>], tris: &'a [[usize; 3]]) -> Result<Self, AttemptError> {
        let mut edge_tri: HashMap<(usize, usize), usize> = HashMap::with_capacity(3 * tris.len());
        for (ti, t) in tris.iter().enumerate() {
            for k in 0..3 {
                if edge_tri.insert((t[k], t[(k + 1) % 3]), ti).is_some() {
                    return Err("quickhull mesh has a repeated edge".into());
                }
            }
        }
        let mesh = Mesh {
            hull,
            tris,
            edge_tri,
        };
        if mesh
            .edge_tri
            .keys()
            .any(|&(a, b)| mesh.twin(a, b).is_none())
        {
            return Err("quickhull mesh is not closed".into());
        }
        Ok(mesh)
    }

    /// The triangle across directed edge (a, b).
    fn twin(&self, a: usize, b: usize) -> Option<usize> {
        self.edge_tri.get(&(b, a)).copied()
    }

    /// Twice the area vector of triangle `t`.
    fn area_vec(&self, t: &[usize; 3]) -> Vector3<f64> {
        let h = self.hull;
        (h[t[1]] - h[t[0]]).cross(&(h[t[2]] - h[t[0]]))
    }

    /// Region growing from the largest triangles, against the seed's fixed plane: each
    /// triangle's region, and how many regions.
    fn grow_regions(&self, tol: f64) -> (Vec<usize>, usize) {
        let (hull, tris) = (self.hull, self.tris);
        let mut order: Vec<usize> = (0..tris.len()).collect();
        order.sort_by(|&s, &t| {
            self.area_vec(&tris[t])
                .norm()
                .total_cmp(&self.area_vec(&tris[s]).norm())
        });
        let mut region = vec![usize::MAX; tris.len()];
        let mut count = 0;
        for &seed in &order {
            if region[seed] != usize::MAX {
                continue;
            }
            let r = count;
            count += 1;
            region[seed] = r;
            let Some(n0) = self.area_vec(&tris[seed]).try_normalize(0.0) else {
                continue; // zero-area triangle: left alone here, merged below
            };
            let d0 = tris[seed]
                .iter()
                .map(|&v| n0.dot(&hull[v].coords))
                .sum::<f64>()
                / 3.0;
            let mut stack = vec![seed];
            while let Some(t) = stack.pop() {
                for k in 0..3 {
                    let Some(nb) = self.twin(tris[t][k], tris[t][(k + 1) % 3]) else {
                        continue;
                    };
                    let on_plane = tris[nb]
                        .iter()
                        .all(|&v| (n0.dot(&hull[v].coords) - d0).abs() <= tol);
                    if region[nb] == usize::MAX && on_plane {
                        region[nb] = r;
                        stack.push(nb);
                    }
                }
            }
        }
        (region, count)
    }

    /// Slivers: a region whose area is below tol × its longest edge joins the neighbouring
    /// region with which it shares the most edges (its vertices lie on that region's boundary).
    /// Refuses a hull of more than [`MAX_TEMPLATE_FACES`] faces first.
    fn join_slivers(
        &self,
        region: &mut [usize],
        count: usize,
        tol: f64,
    ) -> Result<(), AttemptError> {
        let (hull, tris) = (self.hull, self.tris);
        let mut area = vec![Vector3::zeros(); count];
        let mut longest = vec![0.0f64; count];
        for (ti, t) in tris.iter().enumerate() {
            area[region[ti]] += self.area_vec(t);
            for k in 0..3 {
                longest[region[ti]] =
                    longest[region[ti]].max((hull[t[(k + 1) % 3]] - hull[t[k]]).norm());
            }
        }
        let sliver: Vec<bool> = (0..count)
            .map(|r| 0.5 * area[r].norm() <= tol * longest[r])
            .collect();
        // Every region that is not a sliver stays one face (slivers only join others), so the
        // face count is known here: a hull with too many faces is refused before the work below
        // and the vertex selection, which grow with the square of the hull's size.
        let faces = sliver.iter().filter(|s| !**s).count();
        if faces > MAX_TEMPLATE_FACES {
            return Err(AttemptError::TooManyFaces(faces));
        }
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); count];
        for (ti, &r) in region.iter().enumerate() {
            members[r].push(ti);
        }
        // `target` is a union-find forest: a merged sliver points at the region it joined.
        let mut target: Vec<usize> = (0..count).collect();
        let root = |target: &[usize], mut r: usize| {
            while target[r] != r {
                r = target[r];
            }
            r
        };
        for r in (0..count).filter(|&r| sliver[r]) {
            let mut shared: HashMap<usize, usize> = HashMap::new();
            for t in members[r].iter().map(|&ti| &tris[ti]) {
                for k in 0..3 {
                    if let Some(nb) = self.twin(t[k], t[(k + 1) % 3]) {
                        let q = root(&target, region[nb]);
                        if q != r {
                            *shared.entry(q).or_insert(0) += 1;
                        }
                    }
                }
            }
            if let Some((&q, _)) = shared
                .iter()
                .max_by_key(|(q, n)| (**n, std::cmp::Reverse(**q)))
            {
                target[r] = q;
            }
        }
        for r in region.iter_mut() {
            *r = root(&target, *r);
        }
        Ok(())
    }

    /// Boundary loops: per region, the directed edges whose twin lies in another region, read
    /// as one loop from its lowest vertex, with the region's normal.
    fn boundary_loops(&self, region: &[usize]) -> Result<Vec<Region>, AttemptError> {
        let tris = self.tris;
        let mut ids: Vec<usize> = region.to_vec();
        ids.sort_unstable();
        ids.dedup();
        let slot = |r: usize| ids.binary_search(&r).unwrap_or(0);
        let mut next: Vec<HashMap<usize, usize>> = vec![HashMap::new(); ids.len()];
        let mut sum = vec![Vector3::zeros(); ids.len()];
        for (ti, t) in tris.iter().enumerate() {
            let r = slot(region[ti]);
            sum[r] += self.area_vec(t);
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let inside = self.twin(a, b).is_some_and(|nb| region[nb] == region[ti]);
                if !inside && next[r].insert(a, b).is_some() {
                    return Err("a merged face touches itself at a vertex".into());
                }
            }
        }
        let mut out = Vec::with_capacity(ids.len());
        for (r, edges) in next.iter().enumerate() {
            let Some(&start) = edges.keys().min() else {
                return Err("a merged face has no boundary".into());
            };
            let mut boundary = vec![start];
            let mut v = start;
            while let Some(&w) = edges.get(&v) {
                if w == start || boundary.len() > edges.len() {
                    break;
                }
                boundary.push(w);
                v = w;
            }
            if boundary.len() != edges.len() {
                return Err("a merged face is not a disk".into());
            }
            let normal = sum[r]
                .try_normalize(0.0)
                .ok_or("a merged face has zero area")?;
            out.push(Region { normal, boundary });
        }
        Ok(out)
    }
}
