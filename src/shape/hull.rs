//! Convex hull of a point set with coplanar hull triangles merged into polygon faces.
//!
//! The seed paper (Sec. 2.1) stores a template as faces with one outward normal each, merging the
//! adjacent triangles that share a normal. Here the triangle hull comes from parry3d-f64's
//! quickhull (a closed, outward-wound triangle mesh); then
//!
//! 1. hull points closer than the tolerance are welded (near-duplicates of one corner);
//! 2. faces are grown as regions of adjacent triangles: from the largest unassigned triangle,
//!    a neighbour joins while all its vertices lie within `PLANE_TOL × size` of the seed
//!    triangle's plane (a fixed plane, so the tolerance cannot chain across a gently curved
//!    surface); regions of negligible area (slivers along an edge) join a neighbour;
//! 3. a hull vertex is a template vertex when three or more faces meet at it: a point inside a
//!    face (one face) or in the middle of an edge (two faces) is dropped, so each face's loop,
//!    read from the region's boundary, has no interior or collinear middle vertices;
//! 4. the result is checked to be a closed, consistently oriented 2-manifold with
//!    V − E + F = 2 (Euler), so consumers can rely on the topology.
//!
//! Because the faces come from the quickhull's own triangle adjacency, the topology is consistent
//! by construction even for noisy input near the tolerance.

use super::faces::merge_regions;
use super::{Face, MAX_INPUT_POINTS, MAX_TEMPLATE_FACES, MAX_TEMPLATE_VERTICES, ShapeError};
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// Points within this fraction of the bounding-box diagonal of a plane count as on it. It is set
/// by the coarsest input precision the importer must accept: STL stores f32 (relative 6e-8 per
/// coordinate) and OBJ exporters often write 6 decimals, so the vertices of one face of a
/// dodecahedron read from a file are coplanar only to about 1e-7 of its size. Two genuine faces
/// closer than 1e-6 rad to coplanar do not occur in a DEM particle.
pub(crate) const PLANE_TOL: f64 = 1e-6;

/// A point set thinner than this fraction of its bounding-box diagonal has no usable volume.
pub(crate) const FLAT_TOL: f64 = 1e-5;

/// A convex polytope with merged faces, in the input's coordinates.
pub(crate) struct Polytope {
    pub vertices: Vec<Point3<f64>>,
    pub faces: Vec<Face>,
    pub edges: Vec<[u32; 2]>,
    /// Volume of the exact (unmerged) triangle hull, for comparison with an input mesh's volume.
    pub exact_hull_volume: f64,
}

fn degenerate(src: &str, message: String) -> ShapeError {
    ShapeError::Degenerate {
        source_name: src.to_string(),
        message,
    }
}

/// Builds the convex polytope of `points`; `src` names the input in errors.
pub(crate) fn convex_polytope(points: &[Point3<f64>], src: &str) -> Result<Polytope, ShapeError> {
    let n = points.len();
    if n < 4 {
        return Err(degenerate(
            src,
            format!("a convex particle needs at least 4 points, got {n}"),
        ));
    }
    // Refused before any work: the hull of this many points takes seconds to minutes and
    // gigabytes, and a template could not hold it anyway (see MAX_INPUT_POINTS).
    if n > MAX_INPUT_POINTS {
        return Err(ShapeError::TooLarge {
            source_name: src.to_string(),
            message: format!(
                "{n} points, more than the limit {MAX_INPUT_POINTS} (MAX_INPUT_POINTS) a particle \
                 template is built from; a template has at most {MAX_TEMPLATE_FACES} faces and \
                 {MAX_TEMPLATE_VERTICES} vertices, so decimate the mesh first"
            ),
        });
    }
    for (i, p) in points.iter().enumerate() {
        if !p.iter().all(|x| x.is_finite()) {
            return Err(degenerate(
                src,
                format!(
                    "point {i} has a non-finite coordinate ({}, {}, {})",
                    p.x, p.y, p.z
                ),
            ));
        }
    }
    let size = check_extent(points, src)?;
    let tol = PLANE_TOL * size;

    // Quickhull and face merging can fail on exactly degenerate or tolerance-scale noisy input
    // (coplanar points: parry's quickhull may drop a point or emit a non-manifold mesh; welding
    // near-duplicates may pinch the mesh). Each result is checked (closed manifold, Euler, every
    // input point inside), and on failure retried without welding, then on points perturbed far
    // below the tolerance (the hull's combinatorics from the perturbed points, its coordinates
    // the original ones).
    let attempts = [
        (true, None),
        (false, None),
        (true, Some(1)),
        (false, Some(2)),
        (false, Some(3)),
    ];
    let mut why = String::new();
    for (welded, perturb) in attempts {
        match attempt(points, tol, welded, perturb) {
            Ok(poly) => match outside_point(points, &poly, 2.0 * tol) {
                None => return Ok(poly),
                Some(i) => why = format!("input point {i} is outside the computed hull"),
            },
            // Not retried: perturbing the points cannot remove faces, and finishing the build
            // of a hull with thousands of faces costs O(faces × vertices).
            Err(AttemptError::TooManyFaces(faces)) => {
                return Err(too_many_faces(src, faces));
            }
            Err(AttemptError::Failed(e)) => why = e,
        }
    }
    Err(degenerate(
        src,
        format!("convex hull construction failed ({why}); simplify or clean the point set"),
    ))
}

/// The error for a hull with more than [`MAX_TEMPLATE_FACES`] merged faces.
pub(crate) fn too_many_faces(src: &str, faces: usize) -> ShapeError {
    ShapeError::TooLarge {
        source_name: src.to_string(),
        message: format!(
            "convex hull has {faces} faces after merging coplanar triangles, more than the limit \
             {MAX_TEMPLATE_FACES} (MAX_TEMPLATE_FACES); simplify the mesh (decimate it or use \
             fewer facets)"
        ),
    }
}

/// Why one hull construction failed.
pub(super) enum AttemptError {
    /// The merged faces are more than a template may have: final, not worth a retry.
    TooManyFaces(usize),
    /// A numerical or topological failure that a retry (unwelded, perturbed) may avoid.
    Failed(String),
}

impl From<String> for AttemptError {
    fn from(e: String) -> Self {
        AttemptError::Failed(e)
    }
}

impl From<&str> for AttemptError {
    fn from(e: &str) -> Self {
        AttemptError::Failed(e.to_string())
    }
}

/// The first input point farther than `tol` outside a face plane, if any. Skipped (None) for
/// hulls with more faces than a template may have: those are rejected anyway, by count.
fn outside_point(points: &[Point3<f64>], poly: &Polytope, tol: f64) -> Option<usize> {
    if poly.faces.len() > MAX_TEMPLATE_FACES {
        return None;
    }
    points.iter().position(|p| {
        poly.faces
            .iter()
            .any(|f| f.normal.dot(&p.coords) > f.offset + tol)
    })
}

/// One hull construction: quickhull (optionally on perturbed points), optional welding, face
/// merging, vertex selection and topology check.
fn attempt(
    points: &[Point3<f64>],
    tol: f64,
    welded: bool,
    perturb: Option<u64>,
) -> Result<Polytope, AttemptError> {
    let (hull_pts, hull_tris) = match perturb {
        None => parry_hull(points)?,
        Some(seed) => {
            let mut rng = crate::rng::Rng::new(seed);
            let moved: Vec<Point3<f64>> = points
                .iter()
                .map(|p| {
                    let u = rng.unit_vector();
                    p + Vector3::new(u[0], u[1], u[2]) * (1e-3 * tol)
                })
                .collect();
            let key = |p: &Point3<f64>| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
            let index: HashMap<[u64; 3], usize> =
                moved.iter().enumerate().map(|(i, p)| (key(p), i)).collect();
            let (hv, ht) = parry_hull(&moved)?;
            let orig = hv
                .iter()
                .map(|p| index.get(&key(p)).map(|&i| points[i]))
                .collect::<Option<Vec<_>>>()
                .ok_or("quickhull returned a point not in its input")?;
            (orig, ht)
        }
    };
    let exact_hull_volume = super::MassProperties::from_triangles(&hull_pts, &hull_tris)
        .map(|m| m.volume)
        .ok_or("the convex hull has zero volume")?;

    // Weld hull points closer than the tolerance, so that near-duplicates of one corner do not
    // become zero-length edges.
    let (hull, remap) = weld(&hull_pts, if welded { tol } else { 0.0 });
    let tris: Vec<[usize; 3]> = hull_tris
        .iter()
        .filter_map(|t| {
            let a = *remap.get(t[0] as usize)?;
            let b = *remap.get(t[1] as usize)?;
            let c = *remap.get(t[2] as usize)?;
            (a != b && b != c && a != c).then_some([a, b, c])
        })
        .collect();
    let faces = merge_regions(&hull, &tris, tol)?;

    // Template vertices: hull vertices where three or more faces meet.
    let mut new_index = vec![u32::MAX; hull.len()];
    let mut vertices = Vec::new();
    let mut face_count = vec![0usize; hull.len()];
    for f in &faces {
        for &v in &f.boundary {
            face_count[v] += 1;
        }
    }
    for (i, p) in hull.iter().enumerate() {
        if face_count[i] >= 3 {
            new_index[i] = vertices.len() as u32;
            vertices.push(*p);
        }
    }
    let mut out_faces = Vec::with_capacity(faces.len());
    for f in &faces {
        let loop_idx: Vec<u32> = f
            .boundary
            .iter()
            .filter(|&&v| face_count[v] >= 3)
            .map(|&v| new_index[v])
            .collect();
        if loop_idx.len() < 3 {
            return Err("a merged face has fewer than 3 corners".into());
        }
        out_faces.push(Face {
            normal: f.normal,
            offset: 0.0,
            vertices: loop_idx,
        });
    }
    // Offset = support value over all vertices (largest n·v): no vertex is outside any face
    // plane. For exact input this is n·v of the face's own vertices to rounding.
    for f in &mut out_faces {
        f.offset = vertices
            .iter()
            .map(|v| f.normal.dot(&v.coords))
            .fold(f64::NEG_INFINITY, f64::max);
        // Each face's own vertices must lie on its plane (merged within `tol` of the seed plane,
        // so within a few `tol` of the fitted one): otherwise the quickhull mesh was not convex.
        let depth = f
            .vertices
            .iter()
            .map(|&v| f.offset - f.normal.dot(&vertices[v as usize].coords))
            .fold(0.0, f64::max);
        if depth > 4.0 * tol {
            return Err(AttemptError::Failed(format!(
                "a merged face is not planar ({depth:.3e} > {:.3e}): the quickhull mesh is not convex",
                4.0 * tol
            )));
        }
    }
    let edges = check_topology(vertices.len(), &out_faces)?;
    Ok(Polytope {
        vertices,
        faces: out_faces,
        edges,
        exact_hull_volume,
    })
}

/// Checks that the points span a volume and returns their bounding-box diagonal.
fn check_extent(points: &[Point3<f64>], src: &str) -> Result<f64, ShapeError> {
    let mut lo = points[0].coords;
    let mut hi = lo;
    for p in points {
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
    }
    let size = (hi - lo).norm();
    if size == 0.0 {
        return Err(degenerate(
            src,
            format!("all {} points coincide", points.len()),
        ));
    }
    if !(1e-100..=1e100).contains(&size) {
        return Err(ShapeError::BadParameter {
            source_name: src.to_string(),
            message: format!(
                "bounding-box diagonal {size:e} is outside the supported range 1e-100..1e100"
            ),
        });
    }
    // Affine rank: farthest point from p0, farthest from that line, extent normal to that plane.
    let p0 = points[0];
    let far = |f: &dyn Fn(&Point3<f64>) -> f64| points.iter().map(f).fold(0.0f64, f64::max);
    let argfar = |f: &dyn Fn(&Point3<f64>) -> f64| {
        points
            .iter()
            .copied()
            .max_by(|a, b| f(a).total_cmp(&f(b)))
            .unwrap_or(p0)
    };
    let p1 = argfar(&|p| (p - p0).norm());
    let axis = (p1 - p0).normalize();
    let off_line = |p: &Point3<f64>| {
        let d = p - p0;
        (d - axis * axis.dot(&d)).norm()
    };
    let p2 = argfar(&off_line);
    let line_dist = off_line(&p2);
    if line_dist <= FLAT_TOL * size {
        return Err(degenerate(
            src,
            format!(
                "all {} points are collinear (largest distance from a line {line_dist:.3e}, size {size:.3e}); a particle needs volume",
                points.len()
            ),
        ));
    }
    let normal = axis.cross(&(p2 - p0)).normalize();
    let above = far(&|p| normal.dot(&(p - p0)));
    let below = far(&|p| -normal.dot(&(p - p0)));
    let thickness = above + below;
    if thickness <= FLAT_TOL * size {
        return Err(degenerate(
            src,
            format!(
                "all {} points are coplanar (thickness {thickness:.3e} is below {FLAT_TOL:e} of the size {size:.3e}); a particle needs volume",
                points.len()
            ),
        ));
    }
    Ok(size)
}

type HullMesh = (Vec<Point3<f64>>, Vec<[u32; 3]>);

/// parry3d-f64's quickhull, with failures (including panics inside it) turned into errors.
fn parry_hull(points: &[Point3<f64>]) -> Result<HullMesh, String> {
    use parry3d_f64::math::Vector;
    let pts: Vec<Vector> = points.iter().map(|p| Vector::new(p.x, p.y, p.z)).collect();
    let result = std::panic::catch_unwind(|| parry3d_f64::transformation::try_convex_hull(&pts));
    match result {
        Ok(Ok((verts, tris))) => Ok((
            verts.iter().map(|v| Point3::new(v.x, v.y, v.z)).collect(),
            tris,
        )),
        Ok(Err(e)) => Err(format!("quickhull failed: {e:?}")),
        Err(_) => Err("quickhull aborted".to_string()),
    }
}

/// Merges points closer than `tol` (sweep along x); returns the kept points and, for each input
/// point, its index among them.
fn weld(points: &[Point3<f64>], tol: f64) -> (Vec<Point3<f64>>, Vec<usize>) {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a].x.total_cmp(&points[b].x));
    let mut rep: Vec<usize> = (0..points.len()).collect();
    for (k, &i) in order.iter().enumerate() {
        if rep[i] != i {
            continue;
        }
        for &j in &order[k + 1..] {
            if points[j].x - points[i].x > tol {
                break;
            }
            if rep[j] == j && (points[j] - points[i]).norm() <= tol {
                rep[j] = i;
            }
        }
    }
    let mut index = vec![usize::MAX; points.len()];
    let mut kept = Vec::new();
    for i in 0..points.len() {
        if rep[i] == i {
            index[i] = kept.len();
            kept.push(points[i]);
        }
    }
    let remap = (0..points.len()).map(|i| index[rep[i]]).collect();
    (kept, remap)
}

/// Checks that the faces form a closed, consistently oriented 2-manifold of genus 0 and returns
/// its undirected edges (lower index first, sorted).
pub(crate) fn check_topology(num_vertices: usize, faces: &[Face]) -> Result<Vec<[u32; 2]>, String> {
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    let mut used = vec![false; num_vertices];
    for (fi, f) in faces.iter().enumerate() {
        if f.vertices.len() < 3 {
            return Err(format!("face {fi} has {} vertices", f.vertices.len()));
        }
        for k in 0..f.vertices.len() {
            let a = f.vertices[k];
            let b = f.vertices[(k + 1) % f.vertices.len()];
            if a as usize >= num_vertices || b as usize >= num_vertices {
                return Err(format!("face {fi} has an out-of-range vertex"));
            }
            used[a as usize] = true;
            if directed.insert((a, b), fi).is_some() {
                return Err(format!("edge {a}-{b} is used twice in the same direction"));
            }
        }
    }
    if let Some(v) = used.iter().position(|u| !u) {
        return Err(format!("vertex {v} is on no face"));
    }
    let mut edges = Vec::with_capacity(directed.len() / 2);
    for &(a, b) in directed.keys() {
        if !directed.contains_key(&(b, a)) {
            return Err(format!("edge {a}-{b} has only one face"));
        }
        if a < b {
            edges.push([a, b]);
        }
    }
    edges.sort_unstable();
    let euler = num_vertices as i64 - edges.len() as i64 + faces.len() as i64;
    if euler != 2 {
        return Err(format!(
            "V - E + F = {} - {} + {} = {euler}, not 2",
            num_vertices,
            edges.len(),
            faces.len()
        ));
    }
    Ok(edges)
}
