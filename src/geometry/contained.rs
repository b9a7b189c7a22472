//! A body wholly inside the other: the pair query's defined answer for coincident and contained
//! bodies, the same in every precision (docs/contact.md §6).
//!
//! When one body lies inside the other, the overlap is the inner body itself and moving it
//! changes nothing: `S = dV/dx_B` is zero and what the dual hull returns is round-off. In f64
//! that round-off happened to cancel for most poses, but not for all (a random 12-point hull on
//! itself: f64 gave a normal and 4.6 % off in f32), and f32 put two coincident hulls' volume
//! 2.8–5.6 % low with a normal. [`contained_overlap`] answers before any plane is placed, in
//! f64 whatever the pair's precision: the inner body's volume (from its faces, exactly), its
//! centroid, `S = 0` and no surface moment; the contact law then pushes the bodies apart along
//! the line of centres ([`crate::contact::law::wholly_inside`]). The CUDA twin is
//! `contained_overlap` in cuda/pair.cuh, with the same operations in the same order.

use super::overlap::Overlap;
use crate::shape::ConvexTemplate;
use nalgebra::{Isometry3, Vector3};

/// The overlap of two bodies one of which lies wholly inside the other (every vertex of it
/// within `64 ε (r_A + r_B)` of the other's planes, r the circumscribed radii), or `None`.
/// Only a body whose centre lies within the other's circumscribed ball (one distance, which
/// most touching bodies fail) and that could fit (`|d| + ρ_i ≤ R_o`, ρ the least face offset, up
/// to round-off: a necessary condition) is tested vertex by vertex.
pub fn contained_overlap(
    a: (&ConvexTemplate, f64, &Isometry3<f64>),
    b: (&ConvexTemplate, f64, &Isometry3<f64>),
) -> Option<Overlap<f64>> {
    inside(b, a).or_else(|| inside(a, b))
}

fn inside(
    (ti, si, pi): (&ConvexTemplate, f64, &Isometry3<f64>),
    (to, so, po): (&ConvexTemplate, f64, &Isometry3<f64>),
) -> Option<Overlap<f64>> {
    let (xi, xo) = (pi.translation.vector, po.translation.vector);
    let (ri, ro) = (ti.circumscribed_radius * si, to.circumscribed_radius * so);
    let d = xi - xo;
    let tol = 64.0 * f64::EPSILON * (ri + ro);
    // The ball first: it costs one distance, the fit two scans of the faces.
    if d.dot(&d) > ro * ro
        || !could_be_inside(&d, ti, si, to, so, tol)
        || !vertices_inside((ti, si, pi), (to, so, po), tol)
    {
        return None;
    }
    Some(Overlap {
        volume: face_volume(ti) * (si * si * si),
        centroid: xi,
        dv_dxb: Vector3::zeros(),
        moment_b: Vector3::zeros(),
        depth: least_offset(ti) * si,
        thickness: 0.0,
    })
}

/// Whether every vertex of the inner body lies within `tol` of the outer body's planes.
fn vertices_inside(
    (ti, si, pi): (&ConvexTemplate, f64, &Isometry3<f64>),
    (to, so, po): (&ConvexTemplate, f64, &Isometry3<f64>),
    tol: f64,
) -> bool {
    let d = pi.translation.vector - po.translation.vector;
    ti.vertices.iter().all(|v| {
        // nalgebra's rotation is cuda/common.cuh's `rotate`, bit for bit.
        let w = po
            .rotation
            .inverse_transform_vector(&(pi.rotation * (v.coords * si) + d));
        to.faces
            .iter()
            .all(|f| f.normal.dot(&w) - f.offset * so <= tol)
    })
}

/// A template's least face offset: the radius of the ball about its centre that it contains.
fn least_offset(t: &ConvexTemplate) -> f64 {
    t.faces
        .iter()
        .map(|f| f.offset)
        .fold(f64::INFINITY, f64::min)
}

/// Whether the inner body (template `ti` at scale `si`, its centre `d` from the outer body's)
/// can lie inside the outer one as [`inside`] tests it: a necessary condition, so that the
/// vertex test runs only where it may pass. The inner body contains the ball of radius
/// `ρ_i` (its least face offset) about its centre, so its support along `d/|d|` reaches
/// `|d| + ρ_i` from the outer centre; every point within `tol` of the outer body's planes lies
/// in that body scaled by `1 + tol/ρ_o` about its centre (each offset is at least `ρ_o`), whose
/// circumscribed radius is `R_o (1 + tol/ρ_o)`. So `|d| + ρ_i ≤ R_o (1 + tol/ρ_o)`, with `tol`
/// more for the rounding of this test. The ball `|d| ≤ R_o` alone let elongated grains through
/// with many of their neighbours: the mineral grains' settled packing has centres closer than
/// the circumscribed radius for many touching pairs.
fn could_be_inside(
    d: &Vector3<f64>,
    ti: &ConvexTemplate,
    si: f64,
    to: &ConvexTemplate,
    so: f64,
    tol: f64,
) -> bool {
    let (rho_i, rho_o) = (least_offset(ti) * si, least_offset(to) * so);
    let ro = to.circumscribed_radius * so;
    let reach = ro + ro * (tol / rho_o) + tol - rho_i;
    reach >= 0.0 && d.dot(d) <= reach * reach
}

/// A template's volume from its faces, `Σ offset · area / 3`, each face's area by a fan from
/// its first corner (the GPU's order: it reads the same corners from its face polygons).
fn face_volume(t: &ConvexTemplate) -> f64 {
    let mut volume = 0.0;
    for f in &t.faces {
        let p0 = t.vertices[f.vertices[0] as usize].coords;
        let mut twice_area = 0.0;
        for k in 1..f.vertices.len().saturating_sub(1) {
            let p1 = t.vertices[f.vertices[k] as usize].coords;
            let p2 = t.vertices[f.vertices[k + 1] as usize].coords;
            twice_area += f.normal.dot(&(p1 - p0).cross(&(p2 - p0)));
        }
        volume += f.offset * (0.5 * twice_area);
    }
    volume / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Generator;
    use nalgebra::{Translation3, UnitQuaternion};

    /// The faces' volume is the template's, a body on itself is contained with S = 0, a small
    /// body well inside a large one is found from either side, and touching bodies are not.
    #[test]
    fn coincident_and_contained_bodies_are_answered_and_touching_ones_are_not() {
        let d = Generator::Dodecahedron { size: 1.0 }.build().unwrap();
        assert!((face_volume(&d) - d.volume).abs() <= 1e-14 * d.volume);
        let q = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.1);
        let pose = Isometry3::from_parts(Translation3::new(1.0, -2.0, 0.5), q);
        let o = contained_overlap((&d, 0.02, &pose), (&d, 0.02, &pose)).unwrap();
        assert!((o.volume - d.volume * 8e-6).abs() <= 1e-12 * o.volume);
        assert_eq!(o.dv_dxb, Vector3::zeros());
        assert_eq!(o.centroid, pose.translation.vector);
        let small = Isometry3::from_parts(Translation3::new(1.001, -2.0, 0.5), q.inverse());
        for (x, y) in [
            ((&d, 0.02, &pose), (&d, 0.002, &small)),
            ((&d, 0.002, &small), (&d, 0.02, &pose)),
        ] {
            let o = contained_overlap(x, y).unwrap();
            assert!((o.volume - d.volume * 8e-9).abs() <= 1e-12 * o.volume);
            assert_eq!(o.centroid, small.translation.vector);
        }
        let apart = Isometry3::from_parts(Translation3::new(1.0 + 0.03, -2.0, 0.5), q);
        assert!(contained_overlap((&d, 0.02, &pose), (&d, 0.02, &apart)).is_none());
    }

    /// The necessary condition never refuses a body the vertex test accepts: inner bodies of
    /// four shapes at three scales and random orientations, pushed from the outer centre along
    /// random directions until the vertex test first fails (the tightest fits, one vertex on
    /// the outer surface), are all let through; and it does refuse touching neighbours.
    #[test]
    fn the_necessary_condition_keeps_every_contained_body() {
        let shapes = [
            Generator::Tetrahedron { size: 1.0 }.build().unwrap(),
            Generator::Cube { size: 1.0 }.build().unwrap(),
            Generator::Octahedron { size: 1.0 }.build().unwrap(),
            Generator::Dodecahedron { size: 1.0 }.build().unwrap(),
        ];
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut tight, mut refused) = (0, 0);
        for outer in &shapes {
            for inner in &shapes {
                for scale in [0.2, 0.45, 0.9] {
                    for _ in 0..20 {
                        let mut angle = || std::f64::consts::TAU * uniform();
                        let qi = UnitQuaternion::from_euler_angles(angle(), angle(), angle());
                        let qo = UnitQuaternion::from_euler_angles(angle(), angle(), angle());
                        let dir = Vector3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5)
                            .normalize();
                        let po = Isometry3::from_parts(Translation3::new(0.1, -0.2, 0.3), qo);
                        let (so, si) = (1.0, scale);
                        let tol = 64.0
                            * f64::EPSILON
                            * (inner.circumscribed_radius * si + outer.circumscribed_radius * so);
                        let at = |t: f64| {
                            Isometry3::from_parts(
                                Translation3::from(po.translation.vector + dir * t),
                                qi,
                            )
                        };
                        // Bisect the largest shift the vertex test accepts.
                        let fits =
                            |t: f64| vertices_inside((inner, si, &at(t)), (outer, so, &po), tol);
                        if !fits(0.0) {
                            continue;
                        }
                        let (mut lo, mut hi) = (0.0, 2.0);
                        for _ in 0..60 {
                            let mid = 0.5 * (lo + hi);
                            if fits(mid) { lo = mid } else { hi = mid }
                        }
                        for t in [0.0, 0.5 * lo, lo] {
                            let d = dir * t;
                            assert!(
                                could_be_inside(&d, inner, si, outer, so, tol),
                                "{} in {} at scale {scale}, shift {t}: refused",
                                inner.name,
                                outer.name
                            );
                        }
                        tight += 1;
                        // A neighbour touching from outside (shifted past the outer's
                        // circumscribed radius plus the inner's) is refused.
                        let d =
                            dir * (outer.circumscribed_radius + inner.circumscribed_radius * si);
                        if !could_be_inside(&d, inner, si, outer, so, tol) {
                            refused += 1;
                        }
                    }
                }
            }
        }
        assert!(tight > 300, "only {tight} fitting cases");
        assert_eq!(refused, tight);
    }
}
