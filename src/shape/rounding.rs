//! Rounded edges and corners: a template with each edge and corner cut by one tangent plane, the
//! sharpness of a grain as a setting (`[[particle_types]] rounding`, docs/scene.md).
//!
//! Real grains are never sharp: dice have rounded edges, crushed rock worn corners, and how far a
//! grain can roll over its edges sets how loosely it packs (docs/validation.md §6b). A rounded
//! grain is the template `T` dilated by a ball, `T ⊕ B_ρ` (the sphere-swept solid of Chrono and
//! of sphero-polyhedra). polydem's contact geometry takes plane-bounded grains, so the rounded
//! solid is replaced by the polytope that circumscribes it with one plane per face, per edge and
//! per corner of `T`: the support plane of `T ⊕ B_ρ`, `n·x = h_T(n) + ρ`, whose normal `n` is
//!
//! - a face's normal (the face moved out by ρ),
//! - the normalised sum of an edge's two face normals (the edge cut at 45° for a right angle),
//! - the normalised sum of a corner's face normals (the corner cut across),
//!
//! each inside the normal cone of its face, edge or corner, so that `h_T(n) = n·v` for any vertex
//! `v` of that feature. The polytope touches `T ⊕ B_ρ` on every plane and contains it; it is then
//! scaled about its centroid back to the volume of `T`, so that a rounded grain has the mass and
//! volume-equivalent size of the sharp one and only its edges change. A dodecahedron becomes a
//! polytope of 12 + 30 + 20 = 62 faces.

use super::{ConvexTemplate, MAX_TEMPLATE_FACES, ShapeError};
use nalgebra::{Matrix3, Point3, Vector3};
use std::collections::HashMap;

/// Largest rounding, as a fraction of the circumscribed radius: past it the cut planes of the
/// corners and edges take over the faces and the result no longer resembles the template.
pub const MAX_ROUNDING: f64 = 0.5;

/// `t` with its edges and corners rounded by `ρ = fraction × R` (R its circumscribed radius) as
/// the module describes, at the volume of `t`. `fraction` must be in (0, [`MAX_ROUNDING`]]; the
/// planes, faces + edges + corners of `t`, must number at most [`MAX_TEMPLATE_FACES`].
pub fn rounded(t: &ConvexTemplate, fraction: f64) -> Result<ConvexTemplate, ShapeError> {
    let name = format!("{} rounded {fraction}", t.name);
    let refuse = |message: String| ShapeError::BadParameter {
        source_name: t.name.clone(),
        message,
    };
    if t.sphere {
        return Err(refuse("rounding: a sphere has no edges to round".into()));
    }
    if !(fraction > 0.0 && fraction <= MAX_ROUNDING) {
        return Err(refuse(format!(
            "rounding {fraction} must be in (0, {MAX_ROUNDING}] (a fraction of the \
             circumscribed radius)"
        )));
    }
    let planes = tangent_planes(t, fraction * t.circumscribed_radius);
    if planes.len() > MAX_TEMPLATE_FACES {
        return Err(ShapeError::TooLarge {
            source_name: t.name.clone(),
            message: format!(
                "rounding gives one face per face, edge and corner: {} faces, {} edges and {} \
                 corners make {} faces, more than the limit {MAX_TEMPLATE_FACES} \
                 (MAX_TEMPLATE_FACES)",
                t.faces.len(),
                edge_faces(t).len(),
                t.vertices.len(),
                planes.len()
            ),
        });
    }
    let corners = intersection_vertices(&planes, t.circumscribed_radius);
    let dilated = ConvexTemplate::from_points(&name, &corners)?;
    dilated.scaled((t.volume / dilated.volume).cbrt())
}

/// The support planes `(n, h_T(n) + ρ)` of `T ⊕ B_ρ` at the faces, edges and corners of `t`
/// (its body frame), in that order.
pub fn tangent_planes(t: &ConvexTemplate, rho: f64) -> Vec<(Vector3<f64>, f64)> {
    let mut planes: Vec<_> = t.faces.iter().map(|f| (f.normal, f.offset + rho)).collect();
    for ([v, _], faces) in edge_faces(t) {
        let n = faces
            .iter()
            .map(|&f| t.faces[f].normal)
            .sum::<Vector3<f64>>()
            .normalize();
        planes.push((n, n.dot(&t.vertices[v].coords) + rho));
    }
    for (v, x) in t.vertices.iter().enumerate() {
        let n = t
            .faces
            .iter()
            .filter(|f| f.vertices.contains(&(v as u32)))
            .map(|f| f.normal)
            .sum::<Vector3<f64>>()
            .normalize();
        planes.push((n, n.dot(&x.coords) + rho));
    }
    planes
}

/// Each edge of `t`'s polygon faces (vertex indices, lower first) with the faces that share it,
/// in order of first appearance.
fn edge_faces(t: &ConvexTemplate) -> Vec<([usize; 2], Vec<usize>)> {
    let mut index: HashMap<[usize; 2], usize> = HashMap::new();
    let mut edges: Vec<([usize; 2], Vec<usize>)> = Vec::new();
    for (f, face) in t.faces.iter().enumerate() {
        let n = face.vertices.len();
        for k in 0..n {
            let (a, b) = (
                face.vertices[k] as usize,
                face.vertices[(k + 1) % n] as usize,
            );
            let key = [a.min(b), a.max(b)];
            let slot = *index.entry(key).or_insert_with(|| {
                edges.push((key, Vec::new()));
                edges.len() - 1
            });
            edges[slot].1.push(f);
        }
    }
    edges
}

/// The vertices of `{x : n·x ≤ o}` over `planes` (a bounded polytope of size about `size`): every
/// point where three planes meet that lies inside all of them, within `1e-9 size`, once each.
fn intersection_vertices(planes: &[(Vector3<f64>, f64)], size: f64) -> Vec<Point3<f64>> {
    let tol = 1e-9 * size;
    let mut out: Vec<Point3<f64>> = Vec::new();
    let m = planes.len();
    for i in 0..m {
        for j in i + 1..m {
            for k in j + 1..m {
                let (a, b, c) = (planes[i], planes[j], planes[k]);
                let rows = Matrix3::from_rows(&[a.0.transpose(), b.0.transpose(), c.0.transpose()]);
                // Three planes nearly parallel to one line meet far away or nowhere.
                if rows.determinant().abs() < 1e-9 {
                    continue;
                }
                let Some(x) = rows.lu().solve(&Vector3::new(a.1, b.1, c.1)) else {
                    continue;
                };
                if planes.iter().all(|(n, o)| n.dot(&x) <= o + tol)
                    && !out.iter().any(|p| (p.coords - x).norm() <= 10.0 * tol)
                {
                    out.push(Point3::from(x));
                }
            }
        }
    }
    out
}
