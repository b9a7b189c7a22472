//! Overlap volume, centroid and S = dV/dx_B against independent references: a brute-force
//! half-space intersection (tests/common), closed forms, finite differences, and parry3d-f64's
//! intersection test.

mod common;

use common::*;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use polydem::geometry::gjk_intersect;
use polydem::geometry::pair::{PairWorkspace, overlap_pair};
use polydem::rng::Rng;

/// One random pair of the acceptance set.
struct Case {
    a: usize,
    b: usize,
    pose_a: Isometry3<f64>,
    pose_b: Isometry3<f64>,
}

/// `n` random pairs cycling through every ordered pair of shapes: random orientations, B's centre
/// at a random direction and a distance uniform in [0, 1.05 (r_A + r_B)], so that deep, shallow and
/// missed contacts all occur.
fn random_cases(shapes: &[Shape], n: usize, seed: u64) -> Vec<Case> {
    let mut rng = Rng::new(seed);
    let k = shapes.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i % k, (i / k) % k);
            let ra = shapes[a].template.circumscribed_radius;
            let rb = shapes[b].template.circumscribed_radius;
            let pa = Vector3::new(
                rng.range(-2.0, 2.0),
                rng.range(-2.0, 2.0),
                rng.range(-2.0, 2.0),
            );
            let dir = Vector3::from(rng.unit_vector());
            let dist = rng.uniform() * 1.05 * (ra + rb);
            Case {
                a,
                b,
                pose_a: pose(pa, random_rotation(&mut rng)),
                pose_b: pose(pa + dir * dist, random_rotation(&mut rng)),
            }
        })
        .collect()
}

fn oracle(shapes: &[Shape], c: &Case) -> (OracleOverlap, f64) {
    let (ta, tb) = (&shapes[c.a].template, &shapes[c.b].template);
    let mut planes = world_planes(ta, &c.pose_a);
    planes.extend(world_planes(tb, &c.pose_b));
    let scale = ta.circumscribed_radius.max(tb.circumscribed_radius);
    (oracle_intersection(&planes, scale), scale)
}

#[test]
fn random_pairs_match_the_exact_oracle_in_f64_and_f32() {
    let shapes = test_shapes();
    let cases = random_cases(&shapes, 2420, 2026);
    let mut ws64 = PairWorkspace::<f64>::boxed();
    let mut ws32 = PairWorkspace::<f32>::boxed();
    let (mut checked, mut overlapping, mut worst64, mut worst32, mut worst_c) =
        (0, 0, 0.0f64, 0.0f64, 0.0f64);
    let mut failures = Vec::new();
    for (i, c) in cases.iter().enumerate() {
        let (ta, tb) = (&shapes[c.a].template, &shapes[c.b].template);
        let (reference, scale) = oracle(&shapes, c);
        let v_small = ta.volume.min(tb.volume);
        let r64 = overlap_pair(&mut ws64, (ta, 1.0, &c.pose_a), (tb, 1.0, &c.pose_b)).unwrap();
        let r32 = overlap_pair(&mut ws32, (ta, 1.0, &c.pose_a), (tb, 1.0, &c.pose_b)).unwrap();
        let label = format!("case {i}: {} vs {}", shapes[c.a].name, shapes[c.b].name);
        let v = r64.overlap.volume;
        assert!(
            v.is_finite() && r32.overlap.volume.is_finite(),
            "{label}: non-finite volume"
        );
        // No missed contact: the oracle sees a non-negligible overlap (above round-off of the
        // brute force, 1e-12 of the smaller volume) and we report none; no phantom: we report an
        // overlap where the oracle's intersection has no volume at all.
        if reference.volume > 1e-12 * v_small && v == 0.0 {
            failures.push(format!(
                "{label}: missed contact, oracle V = {:e}",
                reference.volume
            ));
        }
        if reference.volume == 0.0 && v > 0.0 {
            failures.push(format!("{label}: phantom contact V = {v:e}"));
        }
        // GJK's verdict agrees with V > 0 away from touching (1e-9 of the smaller volume).
        if reference.volume > 1e-9 * v_small && !r64.intersects {
            failures.push(format!(
                "{label}: GJK says apart, oracle V = {:e}",
                reference.volume
            ));
        }
        if reference.volume > 1e-6 * v_small {
            overlapping += 1;
            let e64 = (v - reference.volume).abs() / reference.volume;
            let e32 = (r32.overlap.volume - reference.volume).abs() / reference.volume;
            let ec = (r64.overlap.centroid - reference.centroid).norm() / scale;
            worst64 = worst64.max(e64);
            worst32 = worst32.max(e32);
            worst_c = worst_c.max(ec);
            if e64 > 1e-9 {
                failures.push(format!(
                    "{label}: f64 relative error {e64:e} (V = {v:e}, oracle {:e})",
                    reference.volume
                ));
            }
            if e32 > 1e-4 {
                failures.push(format!("{label}: f32 relative error {e32:e}"));
            }
            if ec > 1e-9 {
                failures.push(format!("{label}: centroid off by {ec:e} of the size"));
            }
        }
        checked += 1;
    }
    println!(
        "{checked} pairs, {overlapping} with V > 1e-6 V_small; worst relative error f64 {worst64:e}, f32 {worst32:e}; worst centroid {worst_c:e}"
    );
    assert!(
        overlapping > 1000,
        "too few overlapping pairs ({overlapping}) for a meaningful test"
    );
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn gjk_agrees_with_parry_intersection_test() {
    let shapes = test_shapes();
    let cases = random_cases(&shapes, 2420, 77);
    let parry_shapes: Vec<_> = shapes.iter().map(|s| parry_hull(&s.template)).collect();
    let to_pose = parry_pose;
    let (mut disagreements, mut near) = (Vec::new(), 0);
    for (i, c) in cases.iter().enumerate() {
        let (ta, tb) = (&shapes[c.a].template, &shapes[c.b].template);
        let va = world_vertices(ta, &c.pose_a);
        let vb = world_vertices(tb, &c.pose_b);
        let ours = gjk_intersect(
            &va,
            &vb,
            c.pose_b.translation.vector - c.pose_a.translation.vector,
        );
        let (pa, pb) = (to_pose(&c.pose_a), to_pose(&c.pose_b));
        let theirs =
            parry3d_f64::query::intersection_test(&pa, &parry_shapes[c.a], &pb, &parry_shapes[c.b])
                .unwrap()
                .intersecting;
        // Pairs closer than 1e-9 of the size to touching are legitimately ambiguous.
        let dist = parry3d_f64::query::distance(&pa, &parry_shapes[c.a], &pb, &parry_shapes[c.b])
            .unwrap()
            .distance;
        let (reference, _) = oracle(&shapes, c);
        let ambiguous = (dist > 0.0 && dist < 1e-9) || (dist == 0.0 && reference.volume < 1e-12);
        if ambiguous {
            near += 1;
            continue;
        }
        if ours != theirs {
            disagreements.push(format!(
                "case {i}: ours {ours}, parry {theirs}, distance {dist:e}"
            ));
        }
    }
    println!(
        "{} pairs, {near} within 1e-9 of touching skipped",
        cases.len()
    );
    assert!(disagreements.is_empty(), "{}", disagreements.join("\n"));
}

/// S = dV/dx_B against central differences of V, and the moment M_B against central differences
/// of V under small rotations of B about its centre (dV/dθ = M_B + (c − x_B) × S).
#[test]
fn gradient_and_moment_match_central_differences() {
    let shapes = test_shapes();
    let cases = random_cases(&shapes, 600, 5);
    let mut ws = PairWorkspace::<f64>::boxed();
    let (mut n, mut worst_s, mut worst_m) = (0, 0.0f64, 0.0f64);
    let mut failures = Vec::new();
    for (i, c) in cases.iter().enumerate() {
        let (ta, tb) = (&shapes[c.a].template, &shapes[c.b].template);
        let mut vol = |pb: &Isometry3<f64>| {
            overlap_pair(&mut ws, (ta, 1.0, &c.pose_a), (tb, 1.0, pb))
                .unwrap()
                .overlap
        };
        let base = vol(&c.pose_b);
        if base.volume < 1e-3 * ta.volume.min(tb.volume) {
            continue;
        }
        n += 1;
        let size = ta.circumscribed_radius.min(tb.circumscribed_radius);
        let h = 1e-6 * size;
        let mut fd = Vector3::zeros();
        let mut fd_rot = Vector3::zeros();
        for k in 0..3 {
            let e = Vector3::ith(k, 1.0);
            let shift = |s: f64| {
                Isometry3::from_parts(
                    (c.pose_b.translation.vector + e * s).into(),
                    c.pose_b.rotation,
                )
            };
            fd[k] = (vol(&shift(h)).volume - vol(&shift(-h)).volume) / (2.0 * h);
            let angle = h / size;
            let turn = |s: f64| {
                Isometry3::from_parts(
                    c.pose_b.translation,
                    UnitQuaternion::from_scaled_axis(e * s) * c.pose_b.rotation,
                )
            };
            fd_rot[k] = (vol(&turn(angle)).volume - vol(&turn(-angle)).volume) / (2.0 * angle);
        }
        let s = base.dv_dxb;
        // Relative to |S|, or to the overlap's own area scale V^(2/3) when B's surface barely
        // takes part (S → 0 when A lies inside B).
        let area_scale = s.norm().max(base.volume.powf(2.0 / 3.0));
        let es = (s - fd).norm() / area_scale;
        let torque_arm = base.moment_b + (base.centroid - c.pose_b.translation.vector).cross(&s);
        let em = (torque_arm - fd_rot).norm() / (area_scale * size);
        worst_s = worst_s.max(es);
        worst_m = worst_m.max(em);
        if es > 1e-6 || em > 1e-6 {
            failures.push(format!(
                "case {i} ({} vs {}): S error {es:e}, moment error {em:e}; S {:?} fd {:?} V {:e}",
                shapes[c.a].name,
                shapes[c.b].name,
                s.as_slice(),
                fd.as_slice(),
                base.volume
            ));
        }
    }
    println!("{n} pairs; worst relative error of S {worst_s:e}, of the moment {worst_m:e}");
    assert!(n > 150, "too few overlapping pairs ({n})");
    assert!(
        failures.is_empty(),
        "{} of {n} pairs fail:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
