//! Invariants of the overlap volume under symmetry, rigid motion and scaling (property tests).

mod common;

use common::*;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use polydem::geometry::pair::{PairWorkspace, overlap_pair};
use proptest::prelude::*;
use std::sync::OnceLock;

fn shapes() -> &'static [Shape] {
    static SHAPES: OnceLock<Vec<Shape>> = OnceLock::new();
    SHAPES.get_or_init(test_shapes)
}

fn rotation() -> impl Strategy<Value = UnitQuaternion<f64>> {
    (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64)
        .prop_filter("non-degenerate", |(w, x, y, z)| {
            w * w + x * x + y * y + z * z > 1e-3
        })
        .prop_map(|(w, x, y, z)| UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z)))
}

/// A pair: two shape indices, poses with B at a fraction of the bounding-sphere reach from A.
fn pair() -> impl Strategy<Value = (usize, usize, Isometry3<f64>, Isometry3<f64>)> {
    let k = shapes().len();
    (
        0..k,
        0..k,
        rotation(),
        rotation(),
        (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64),
        0.0..0.9f64,
    )
        .prop_map(move |(a, b, qa, qb, (x, y, z), frac)| {
            let s = shapes();
            let reach = s[a].template.circumscribed_radius + s[b].template.circumscribed_radius;
            let dir = Vector3::new(x, y, z)
                .try_normalize(1e-9)
                .unwrap_or(Vector3::x());
            let pa = Isometry3::from_parts(Translation3::new(0.3, -0.2, 0.1), qa);
            let pb = Isometry3::from_parts((pa.translation.vector + dir * frac * reach).into(), qb);
            (a, b, pa, pb)
        })
}

fn volume_and_s(
    a: usize,
    pa: &Isometry3<f64>,
    sa: f64,
    b: usize,
    pb: &Isometry3<f64>,
    sb: f64,
) -> (f64, Vector3<f64>) {
    let s = shapes();
    let mut ws = PairWorkspace::<f64>::boxed();
    let g = overlap_pair(&mut ws, (&s[a].template, sa, pa), (&s[b].template, sb, pb)).unwrap();
    (g.overlap.volume, g.overlap.dv_dxb)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// V(A, B) = V(B, A), and S swaps sign (dV/dx_A = −dV/dx_B), within 1e-11 of the smaller body.
    #[test]
    fn swapping_the_bodies((a, b, pa, pb) in pair()) {
        let (v1, s1) = volume_and_s(a, &pa, 1.0, b, &pb, 1.0);
        let (v2, s2) = volume_and_s(b, &pb, 1.0, a, &pa, 1.0);
        let vs = shapes()[a].template.volume.min(shapes()[b].template.volume);
        prop_assert!((v1 - v2).abs() <= 1e-11 * vs, "V {} vs {}", v1, v2);
        let scale = vs.powf(2.0 / 3.0);
        prop_assert!((s1 + s2).norm() <= 1e-9 * scale, "S {:?} vs {:?}", s1, s2);
    }

    /// A rigid motion of both bodies leaves V unchanged and rotates S.
    #[test]
    fn rigid_motion_of_both((a, b, pa, pb) in pair(), q in rotation(), (x, y, z) in (-50.0..50.0f64, -50.0..50.0f64, -50.0..50.0f64)) {
        let m = Isometry3::from_parts(Translation3::new(x, y, z), q);
        let (v1, s1) = volume_and_s(a, &pa, 1.0, b, &pb, 1.0);
        let (v2, s2) = volume_and_s(a, &(m * pa), 1.0, b, &(m * pb), 1.0);
        let vs = shapes()[a].template.volume.min(shapes()[b].template.volume);
        prop_assert!((v1 - v2).abs() <= 1e-10 * vs, "V {} vs {}", v1, v2);
        prop_assert!((q * s1 - s2).norm() <= 1e-8 * vs.powf(2.0 / 3.0), "S {:?} vs {:?}", q * s1, s2);
    }

    /// Scaling both bodies and their positions by s scales V by s³ and S by s².
    #[test]
    fn scaling_both((a, b, pa, pb) in pair(), log_s in -3.0..3.0f64) {
        let s = 10f64.powf(log_s);
        let scale = |p: &Isometry3<f64>| Isometry3::from_parts((p.translation.vector * s).into(), p.rotation);
        let (v1, s1) = volume_and_s(a, &pa, 1.0, b, &pb, 1.0);
        let (v2, s2) = volume_and_s(a, &scale(&pa), s, b, &scale(&pb), s);
        let vs = shapes()[a].template.volume.min(shapes()[b].template.volume);
        prop_assert!((v1 * s * s * s - v2).abs() <= 1e-10 * vs * s * s * s, "V {} s³ vs {}", v1, v2);
        prop_assert!((s1 * s * s - s2).norm() <= 1e-8 * vs.powf(2.0 / 3.0) * s * s);
    }
}
