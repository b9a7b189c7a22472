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
//! `contained_overlap` in cuda/overlap.cuh, with the same operations in the same order.

use super::overlap::Overlap;
use crate::shape::ConvexTemplate;
use nalgebra::{Isometry3, Vector3};

/// The overlap of two bodies one of which lies wholly inside the other (every vertex of it
/// within `64 ε (r_A + r_B)` of the other's planes, r the circumscribed radii), or `None`.
/// Only a body whose centre lies within the other's circumscribed ball is tested, so that
/// touching bodies cost one distance.
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
    if d.dot(&d) > ro * ro {
        return None;
    }
    let tol = 64.0 * f64::EPSILON * (ri + ro);
    for v in &ti.vertices {
        // nalgebra's rotation is cuda/common.cuh's `rotate`, bit for bit.
        let w = po
            .rotation
            .inverse_transform_vector(&(pi.rotation * (v.coords * si) + d));
        if to
            .faces
            .iter()
            .any(|f| f.normal.dot(&w) - f.offset * so > tol)
        {
            return None;
        }
    }
    Some(Overlap {
        volume: face_volume(ti) * (si * si * si),
        centroid: xi,
        dv_dxb: Vector3::zeros(),
        moment_b: Vector3::zeros(),
        depth: ti
            .faces
            .iter()
            .map(|f| f.offset)
            .fold(f64::INFINITY, f64::min)
            * si,
        thickness: 0.0,
    })
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
}
