//! The plane culling of the pair geometry (`PosedPolytope::retain_planes_reaching`,
//! `set_aside_faces_apart`) and the Chebyshev centre as the narrow-phase verdict
//! (`overlap_pair`): what they leave, that they change no overlap, and that the proof of an
//! intersection does not accept a false one.
//!
//! References: the overlap of all 24 planes of the pair (`overlap_volume`, itself held to the
//! brute-force oracle in tests/overlap_oracle.rs), and parry3d-f64's distance for disjointness.

mod common;

use common::*;
use nalgebra::{Isometry3, Vector3};
use polydem::geometry::interior::chebyshev_centre;
use polydem::geometry::overlap::{OverlapWorkspace, overlap_volume};
use polydem::geometry::pair::{PairWorkspace, overlap_pair};
use polydem::geometry::polytope::{PosedPolytope, set_aside_faces_apart};
use polydem::rng::Rng;
use polydem::shape::{ConvexTemplate, Generator};

/// The planes `overlap_pair` keeps for a pair (in its frame: origin where the bounding spheres
/// would touch), and the LP's inscribed radius over them.
fn culled(
    ta: &ConvexTemplate,
    pa: &Isometry3<f64>,
    tb: &ConvexTemplate,
    pb: &Isometry3<f64>,
) -> (PosedPolytope<f64>, PosedPolytope<f64>, f64) {
    let (xa, xb) = (pa.translation.vector, pb.translation.vector);
    let (ra, rb) = (ta.circumscribed_radius, tb.circumscribed_radius);
    let origin = xa + (xb - xa) * (ra / (ra + rb));
    let (mut a, mut b) = (
        PosedPolytope::<f64>::default(),
        PosedPolytope::<f64>::default(),
    );
    a.place(ta, 1.0, pa, &origin);
    b.place(tb, 1.0, pb, &origin);
    let tol = 64.0 * f64::EPSILON * (ra + rb);
    let (ca, cb) = (a.centre, b.centre);
    a.retain_planes_reaching(&cb, rb, tol);
    b.retain_planes_reaching(&ca, ra, tol);
    set_aside_faces_apart(&mut a, (ta, 1.0, pa), &mut b, (tb, 1.0, pb), &origin, tol);
    let r = chebyshev_centre(a.planes(), b.planes(), Vector3::zeros()).radius;
    (a, b, r)
}

/// Dense packing pairs (centres 0.87 circumscribed diameters apart, random orientations, the
/// bench scenes' lattice): the faces set aside leave the overlap's own 4–6 planes on average
/// (at most 8 in this sample, against 12–16 that reach the other body's ball), and the overlap
/// on them equals the overlap of all 24 planes to 1e-10 of the volume.
#[test]
fn faces_set_aside_leave_the_overlap_unchanged() {
    let t = Generator::Dodecahedron { size: 1.0 }.build().unwrap();
    let mut rng = Rng::new(5);
    let d = 2.0 * t.circumscribed_radius * 0.87;
    let mut ws = OverlapWorkspace::<f64>::boxed();
    let (mut kept, mut worst, mut overlapping, mut most) = (0usize, 0.0f64, 0usize, 0usize);
    for i in 0..3000 {
        let mut dir = Vector3::zeros();
        dir[i % 3] = 1.0;
        let pa = pose(Vector3::new(0.1, -0.2, 0.3), random_rotation(&mut rng));
        let pb = pose(pa.translation.vector + dir * d, random_rotation(&mut rng));
        let mut fa = PosedPolytope::<f64>::default();
        let mut fb = PosedPolytope::<f64>::default();
        fa.place(&t, 1.0, &pa, &Vector3::zeros());
        fb.place(&t, 1.0, &pb, &Vector3::zeros());
        let full = overlap_volume(&mut ws, fa.planes(), fb.planes(), Vector3::zeros()).unwrap();
        if full.volume <= 1e-12 * t.volume {
            continue;
        }
        let (a, b, _) = culled(&t, &pa, &t, &pb);
        let m = a.planes().len() + b.planes().len();
        let g = overlap_pair(
            &mut PairWorkspace::<f64>::boxed(),
            (&t, 1.0, &pa),
            (&t, 1.0, &pb),
        )
        .unwrap();
        assert!(
            g.intersects,
            "pair {i}: an overlap of V = {:e} not found",
            full.volume
        );
        let e = (g.overlap.volume - full.volume).abs() / full.volume;
        worst = worst.max(e);
        assert!(
            e <= 1e-10,
            "pair {i}: culled overlap {:e} vs all planes {:e}",
            g.overlap.volume,
            full.volume
        );
        overlapping += 1;
        kept += m;
        most = most.max(m);
    }
    let mean = kept as f64 / overlapping as f64;
    eprintln!(
        "{overlapping} overlapping pairs: {mean:.2} planes kept on average, at most {most}, worst volume error {worst:e}"
    );
    assert!(overlapping > 2500, "only {overlapping} overlapping pairs");
    assert!((4.0..=7.0).contains(&mean), "{mean} planes kept on average");
    assert!(most <= 10, "{most} planes kept for one pair");
}

/// Disjoint pairs close to touching, every ordered pair of the seed shapes: the planes left after
/// culling often bound a region with an interior (all of one body's faces lie beyond one plane of
/// the other when a face separates them), so the LP alone would claim an intersection; the proof
/// (the centre inside every plane of both bodies) must refuse it, and overlap_pair reports no
/// volume in f64 and f32, and the pair apart in f64. In f32 GJK may still call a pair within its
/// touching tolerance (1e3 ε of the pair's extent, large for a small body next to a big one)
/// intersecting, with a zero volume, as it did before the proof existed.
#[test]
fn the_centre_proves_no_false_intersection() {
    let shapes = test_shapes();
    let parry: Vec<_> = shapes.iter().map(|s| parry_hull(&s.template)).collect();
    let mut rng = Rng::new(31);
    let mut ws64 = PairWorkspace::<f64>::boxed();
    let mut ws32 = PairWorkspace::<f32>::boxed();
    let k = shapes.len();
    let (mut disjoint, mut lp_would_claim) = (0, 0);
    for i in 0..6000 {
        let (ia, ib) = (i % k, (i / k) % k);
        let (ta, tb) = (&shapes[ia].template, &shapes[ib].template);
        let dir = Vector3::from(rng.unit_vector());
        let dist =
            (0.3 + 0.8 * rng.uniform()) * (ta.circumscribed_radius + tb.circumscribed_radius);
        let pa = pose(Vector3::zeros(), random_rotation(&mut rng));
        let pb = pose(dir * dist, random_rotation(&mut rng));
        let gap = parry3d_f64::query::distance(
            &parry_pose(&pa),
            &parry[ia],
            &parry_pose(&pb),
            &parry[ib],
        )
        .unwrap()
        .distance;
        if gap <= 1e-9 * ta.circumscribed_radius.max(tb.circumscribed_radius) {
            continue;
        }
        disjoint += 1;
        let (_, _, r) = culled(ta, &pa, tb, &pb);
        if r > 0.0 {
            lp_would_claim += 1;
        }
        let g64 = overlap_pair(&mut ws64, (ta, 1.0, &pa), (tb, 1.0, &pb)).unwrap();
        let g32 = overlap_pair(&mut ws32, (ta, 1.0, &pa), (tb, 1.0, &pb)).unwrap();
        let label = format!(
            "pair {i}: {} vs {}, gap {gap:e}",
            shapes[ia].name, shapes[ib].name
        );
        assert!(
            !g64.intersects && g64.overlap.volume == 0.0,
            "{label}: f64 reports an intersection"
        );
        assert!(g32.overlap.volume == 0.0, "{label}: f32 reports a volume");
        let touching32 = 1e3
            * f64::from(f32::EPSILON)
            * 4.0
            * (ta.circumscribed_radius + tb.circumscribed_radius);
        assert!(
            !g32.intersects || gap < touching32,
            "{label}: f32 reports an intersection"
        );
        assert!(g64.separating_axis.is_some(), "{label}: no separating axis");
    }
    eprintln!(
        "{disjoint} disjoint pairs, {lp_would_claim} where the culled planes alone bound an interior"
    );
    assert!(disjoint > 1500, "only {disjoint} disjoint pairs");
    // The proof is exercised: without it these pairs would be phantom contacts.
    assert!(
        lp_would_claim > 100,
        "only {lp_would_claim} pairs test the proof"
    );
}
