//! Hard contact configurations with closed-form overlap volumes, in f64 and f32: parallel
//! face–face, vertex–face, edge–face, edge–edge, containment, coincident bodies, plates and
//! needles, a 1:20 size ratio, touching and just-separated bodies, and depths down to 1e-7 of the
//! size.

mod common;

use common::*;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use polydem::geometry::Real;
use polydem::geometry::pair::{PairGeometry, PairWorkspace, overlap_pair};
use polydem::shape::{ConvexTemplate, Generator};
use std::f64::consts::{FRAC_PI_4, SQRT_2};

fn unit_cube() -> ConvexTemplate {
    Generator::Cuboid {
        a: 1.0,
        b: 1.0,
        c: 1.0,
    }
    .build()
    .unwrap()
}

/// Poses here place shapes in the coordinates they were generated in (a prism along z, say);
/// templates live in their principal frame, so the pose is composed with `file_to_body⁻¹`.
fn eval<T: Real>(
    a: &ConvexTemplate,
    pa: &Isometry3<f64>,
    b: &ConvexTemplate,
    pb: &Isometry3<f64>,
) -> PairGeometry {
    let mut ws = PairWorkspace::<T>::boxed();
    let pa = pa * a.file_to_body.inverse();
    let pb = pb * b.file_to_body.inverse();
    overlap_pair(&mut ws, (a, 1.0, &pa), (b, 1.0, &pb)).unwrap()
}

/// Checks f64 against `expected` within `tol64`, and f32 within `tol32` (skipped when `tol32` is
/// None: below f32 resolution).
fn check(
    label: &str,
    (a, pa): (&ConvexTemplate, &Isometry3<f64>),
    (b, pb): (&ConvexTemplate, &Isometry3<f64>),
    expected: f64,
    (tol64, tol32): (f64, Option<f64>),
) {
    let r = eval::<f64>(a, pa, b, pb);
    let e = (r.overlap.volume - expected).abs() / expected.max(f64::MIN_POSITIVE);
    assert!(
        e <= tol64,
        "{label}: f64 V = {:e}, expected {expected:e} (relative error {e:e})",
        r.overlap.volume
    );
    assert!(r.intersects, "{label}: GJK misses an overlapping pair");
    if let Some(t32) = tol32 {
        let r = eval::<f32>(a, pa, b, pb);
        let e = (r.overlap.volume - expected).abs() / expected;
        assert!(
            e <= t32,
            "{label}: f32 V = {:e}, expected {expected:e} (relative error {e:e})",
            r.overlap.volume
        );
    }
}

fn at(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::translation(x, y, z)
}

#[test]
fn parallel_face_face_from_deep_to_1e_minus_7() {
    let cube = unit_cube();
    for (d, dy, dz) in [
        (0.5f64, 0.0f64, 0.0f64),
        (0.3, 0.25, -0.4),
        (1e-3, 0.1, 0.2),
        (1e-5, 0.0, 0.5),
        (1e-7, 0.3, 0.3),
    ] {
        let expected = d * (1.0 - dy.abs()) * (1.0 - dz.abs());
        // f32 resolves a 1e-7 layer only to its own epsilon: its tolerance follows 1e-7/d.
        let t32 = if d >= 1e-5 { Some(1e-4) } else { None };
        check(
            &format!("face-face depth {d}"),
            (&cube, &at(0.0, 0.0, 0.0)),
            (&cube, &at(1.0 - d, dy, dz)),
            expected,
            (1e-9, t32),
        );
        let r = eval::<f64>(&cube, &at(0.0, 0.0, 0.0), &cube, &at(1.0 - d, dy, dz));
        // S = dV/dx_B of V = d (1 − |dy|)(1 − |dz|), with d = 1 − x_B.
        let area = (1.0 - dy.abs()) * (1.0 - dz.abs());
        let grad = Vector3::new(
            -area,
            -d * (1.0 - dz.abs()) * dy.signum() * (dy != 0.0) as i32 as f64,
            -d * (1.0 - dy.abs()) * dz.signum() * (dz != 0.0) as i32 as f64,
        );
        assert!(
            (r.overlap.dv_dxb - grad).norm() <= 1e-9 * area,
            "S = {:?}, expected {grad:?}",
            r.overlap.dv_dxb
        );
    }
    // The same in a rotated, translated frame far from the origin.
    let q = UnitQuaternion::from_euler_angles(0.3, -1.1, 2.0);
    let far = Vector3::new(1e3, -2e3, 5e2);
    let pa = Isometry3::from_parts(far.into(), q);
    let pb = Isometry3::from_parts((far + q * Vector3::new(1.0 - 1e-4, 0.2, 0.0)).into(), q);
    check(
        "rotated face-face",
        (&cube, &pa),
        (&cube, &pb),
        1e-4 * 0.8,
        (1e-7, Some(1e-3)),
    );
}

#[test]
fn touching_and_just_separated_pairs_have_no_volume() {
    let cube = unit_cube();
    for gap in [0.0, 1e-12, 1e-9, 1e-6] {
        let r = eval::<f64>(&cube, &at(0.0, 0.0, 0.0), &cube, &at(1.0 + gap, 0.3, 0.0));
        assert_eq!(r.overlap.volume, 0.0, "gap {gap}");
        if gap >= 1e-9 {
            assert!(!r.intersects, "GJK reports a contact at gap {gap}");
        }
        let r32 = eval::<f32>(&cube, &at(0.0, 0.0, 0.0), &cube, &at(1.0 + gap, 0.3, 0.0));
        assert_eq!(r32.overlap.volume, 0.0, "f32, gap {gap}");
    }
    // Vertex exactly on a face, and edge exactly on a face.
    let diag = UnitQuaternion::rotation_between(
        &Vector3::new(1.0, 1.0, 1.0),
        &Vector3::new(-1.0, 0.0, 0.0),
    )
    .unwrap();
    let vertex_reach = 3f64.sqrt() / 2.0;
    let r = eval::<f64>(
        &cube,
        &at(0.0, 0.0, 0.0),
        &cube,
        &Isometry3::from_parts(Vector3::new(0.5 + vertex_reach, 0.1, 0.1).into(), diag),
    );
    assert!(
        r.overlap.volume <= 1e-15,
        "vertex touching: V = {:e}",
        r.overlap.volume
    );
}

#[test]
fn vertex_face_edge_face_and_edge_edge_follow_their_power_laws() {
    let cube = unit_cube();
    let origin = at(0.0, 0.0, 0.0);
    // Vertex into a face: the corner {x+y+z <= √3 d} of B, volume (√3/2) d³ (F ∝ δ³ regime).
    let diag = UnitQuaternion::rotation_between(
        &Vector3::new(1.0, 1.0, 1.0),
        &Vector3::new(-1.0, 0.0, 0.0),
    )
    .unwrap();
    let reach = 3f64.sqrt() / 2.0;
    for d in [0.2, 0.01, 1e-3] {
        let pb = Isometry3::from_parts(Vector3::new(0.5 + reach - d, 0.05, -0.1).into(), diag);
        let expected = 3f64.sqrt() / 2.0 * d * d * d;
        let t32 = (expected > 1e-6).then_some(1e-4);
        check(
            &format!("vertex-face {d}"),
            (&cube, &origin),
            (&cube, &pb),
            expected,
            (1e-9, t32),
        );
    }
    // Edge into a face: B turned 45° about z, its edge (length 1) enters by d: a wedge of
    // cross-section d² and length 1.
    let turn_z = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), FRAC_PI_4);
    for d in [0.3, 0.01, 1e-4] {
        let pb = Isometry3::from_parts(
            Vector3::new(0.5 + SQRT_2 / 2.0 - d, 0.1, 0.0).into(),
            turn_z,
        );
        check(
            &format!("edge-face {d}"),
            (&cube, &origin),
            (&cube, &pb),
            d * d,
            (1e-9, Some(1e-4)),
        );
    }
    // Edge across edge: A's edge along z at x = √2/2, B's edge along y at x = x_B − √2/2; the
    // overlap {b + |z| <= x <= a − |y|} has volume 2d³/3 with d = a − b.
    let turn_y = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), FRAC_PI_4);
    let pa = Isometry3::from_parts(Vector3::zeros().into(), turn_z);
    for d in [0.2, 0.01, 1e-3] {
        let pb = Isometry3::from_parts(Vector3::new(SQRT_2 - d, 0.0, 0.0).into(), turn_y);
        let expected = 2.0 * d * d * d / 3.0;
        let t32 = (expected > 1e-6).then_some(1e-4);
        check(
            &format!("edge-edge {d}"),
            (&cube, &pa),
            (&cube, &pb),
            expected,
            (1e-9, t32),
        );
    }
}

#[test]
fn containment_and_coincident_bodies() {
    let cube = unit_cube();
    let small = Generator::Dodecahedron { size: 0.05 }.build().unwrap();
    let q = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
    // 1:20, one inside the other: V is the small body's volume, and B's surface takes no part.
    let inside = Isometry3::from_parts(Vector3::new(0.2, -0.1, 0.3).into(), q);
    check(
        "small inside cube",
        (&cube, &at(0.0, 0.0, 0.0)),
        (&small, &inside),
        small.volume,
        (1e-12, Some(1e-5)),
    );
    let r = eval::<f64>(&small, &inside, &cube, &at(0.0, 0.0, 0.0));
    assert!((r.overlap.volume - small.volume).abs() <= 1e-12 * small.volume);
    // S is the vector area of the cube's surface inside the overlap: none.
    assert!(
        r.overlap.dv_dxb.norm() <= 1e-12,
        "S = {:?}",
        r.overlap.dv_dxb
    );
    // Coincident bodies: every plane appears twice; V is the body's volume.
    for t in [
        cube.clone(),
        Generator::Dodecahedron { size: 1.0 }.build().unwrap(),
        Generator::Prism {
            sides: 20,
            diameter: 1.0,
            height: 0.6,
        }
        .build()
        .unwrap(),
    ] {
        let p = Isometry3::from_parts(Vector3::new(0.3, 0.2, -5.0).into(), q);
        check(
            &format!("coincident {}", t.name),
            (&t, &p),
            (&t, &p),
            t.volume,
            (1e-12, Some(1e-5)),
        );
    }
}

#[test]
fn plates_needles_and_size_ratio_twenty() {
    let plate = Generator::Cuboid {
        a: 1.0,
        b: 0.8,
        c: 0.04,
    }
    .build()
    .unwrap();
    // Plates stacked face to face, overlapping by d through their thickness.
    for d in [0.02, 1e-4, 1e-6] {
        let t32 = (d >= 1e-4).then_some(1e-4);
        check(
            &format!("plate on plate {d}"),
            (&plate, &at(0.0, 0.0, 0.0)),
            (&plate, &at(0.1, 0.0, 0.04 - d)),
            0.9 * 0.8 * d,
            (1e-9, t32),
        );
    }
    // A needle (hexagonal prism along z, circumscribed diameter 0.05) pushed end-first into the
    // plate: a hexagonal column of depth d.
    let needle = Generator::Prism {
        sides: 6,
        diameter: 0.05,
        height: 1.0,
    }
    .build()
    .unwrap();
    let hexagon = 3.0 * 3f64.sqrt() / 2.0 * 0.025 * 0.025;
    for d in [0.01, 1e-4] {
        check(
            &format!("needle into plate {d}"),
            (&plate, &at(0.0, 0.0, 0.0)),
            (&needle, &at(0.2, 0.1, 0.02 + 0.5 - d)),
            hexagon * d,
            (1e-9, Some(1e-4)),
        );
    }
    // Needles crossing at right angles, through each other's axis: a square-ish overlap checked
    // against the brute-force oracle.
    let across = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
    let pb = Isometry3::from_parts(Vector3::new(0.0, 0.0, 0.01).into(), across);
    let mut planes = world_planes(&needle, &needle.file_to_body.inverse());
    planes.extend(world_planes(&needle, &(pb * needle.file_to_body.inverse())));
    let reference = oracle_intersection(&planes, 0.5).volume;
    check(
        "crossed needles",
        (&needle, &at(0.0, 0.0, 0.0)),
        (&needle, &pb),
        reference,
        (1e-9, Some(1e-4)),
    );
    // 1:20: a small dodecahedron (size 0.05) face-down into a unit cube by d. Near a face the
    // dodecahedron's sections are pentagons whose apothem grows by h·cot(π − dihedral) = h/2
    // (the dihedral angle is 2·atan φ), so V = A_f (d + d²/(2a₀) + d³/(12a₀²)).
    let small = Generator::Dodecahedron { size: 0.05 }.build().unwrap();
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let edge = 0.05 / (3f64.sqrt() * phi);
    let apothem = edge / (2.0 * (std::f64::consts::PI / 5.0).tan());
    let face_area = 5.0 * apothem * edge / 2.0;
    let face = small.faces[0].normal;
    let down = UnitQuaternion::rotation_between(&face, &(-Vector3::x())).unwrap();
    let inradius = small.faces[0].offset;
    for d in [0.01, 1e-4, 1e-6] {
        let pb = Isometry3::from_parts(
            Vector3::new(0.5 + inradius - d, 0.1, 0.2).into(),
            down * small.file_to_body.rotation,
        );
        let expected =
            face_area * (d + d * d / (2.0 * apothem) + d * d * d / (12.0 * apothem * apothem));
        let t32 = (d >= 1e-4).then_some(1e-4);
        check(
            &format!("1:20 face-down {d}"),
            (&unit_cube(), &at(0.0, 0.0, 0.0)),
            (&small, &pb),
            expected,
            (1e-9, t32),
        );
    }
}

/// Finite input of any kind gives a finite answer or an error, never a panic, NaN or hang.
#[test]
fn extreme_inputs_give_finite_answers() {
    let shapes = test_shapes();
    let mut rng = polydem::rng::Rng::new(99);
    let mut ws = PairWorkspace::<f64>::boxed();
    let mut ws32 = PairWorkspace::<f32>::boxed();
    for i in 0..3000 {
        let a = &shapes[i % shapes.len()].template;
        let b = &shapes[(i / shapes.len()) % shapes.len()].template;
        let far = [0.0, 1.0, 1e6, 1e9][i % 4];
        let sa = [1.0, 1e-6, 1e3, 1.0][(i / 4) % 4];
        let sb = [1.0, 1.0, 1e-3, 1e6][(i / 16) % 4];
        let base = Vector3::new(far, -far, 0.5 * far);
        // Offsets on the scale of the bodies, sometimes exactly zero (coincident centres).
        let r = (a.circumscribed_radius * sa + b.circumscribed_radius * sb) * rng.uniform();
        let off = if i % 7 == 0 {
            Vector3::zeros()
        } else {
            Vector3::from(rng.unit_vector()) * r
        };
        let pa = pose(base, random_rotation(&mut rng));
        let pb = pose(
            base + off,
            if i % 5 == 0 {
                pa.rotation
            } else {
                random_rotation(&mut rng)
            },
        );
        for res in [
            overlap_pair(&mut ws, (a, sa, &pa), (b, sb, &pb)),
            overlap_pair(&mut ws32, (a, sa, &pa), (b, sb, &pb)),
        ] {
            // An error is an acceptable outcome for pathological input, but none of these is.
            let g = res.unwrap_or_else(|e| panic!("case {i}: {e}"));
            let o = g.overlap;
            assert!(
                o.volume.is_finite() && o.volume >= 0.0,
                "case {i}: V = {}",
                o.volume
            );
            assert!(
                o.dv_dxb
                    .iter()
                    .chain(o.centroid.iter())
                    .chain(o.moment_b.iter())
                    .all(|x| x.is_finite()),
                "case {i}: non-finite output"
            );
            let bound = (a.volume * sa.powi(3)).min(b.volume * sb.powi(3));
            assert!(
                o.volume <= bound * (1.0 + 1e-4) + 1e-300,
                "case {i}: V {} exceeds the smaller body {bound}",
                o.volume
            );
        }
    }
}

/// A 2 cm cube resting face-down 0.56 nm deep on a two-triangle wall, in the pose (to the last
/// bit) a cube carried on a turntable had when its contact vanished for a step: tilted by
/// 1e-12 rad, its overlap with the facet's prism is a slab whose thick end is 1e-14 m thicker.
/// The inscribed-ball LP's projected objective then points along the slab with a norm of 1e-13
/// and the ratio test asks for a step of 1e10, whose rounding carried the point 4e-6 m out of
/// the slab: the contact was reported empty. The volume must be the slab's, A δ, within 1e-6.
#[test]
fn a_resting_face_tilted_by_round_off_keeps_its_wall_contact() {
    use nalgebra::{Point3, Quaternion, Translation3};
    use polydem::contact::WallMesh;
    use polydem::geometry::OverlapWorkspace;
    let template = ConvexTemplate::from_points(
        "cube",
        &[-0.01, 0.01]
            .iter()
            .flat_map(|&x| {
                [-0.01, 0.01]
                    .iter()
                    .flat_map(move |&y| [-0.01, 0.01].map(move |z| Point3::new(x, y, z)))
            })
            .collect::<Vec<_>>(),
    )
    .unwrap();
    let q = UnitQuaternion::new_unchecked(Quaternion::new(
        1.0000000000000002,
        6.129213575310238e-18,
        5.065286064447026e-13,
        -8.470329472543003e-21,
    ));
    let pose = Isometry3::from_parts(
        Translation3::new(
            0.050000000007180974,
            -8.113622722630536e-17,
            0.009999999436878541,
        ),
        q,
    );
    let a = Vector3::new(-0.25, -0.25, 0.0);
    let b = Vector3::new(0.25, -0.25, 0.0);
    let c = Vector3::new(0.25, 0.25, 0.0);
    let d = Vector3::new(-0.25, 0.25, 0.0);
    let wall = WallMesh::new(&[[a, b, c], [a, c, d]], 0.05);
    let mut ws = PairWorkspace::<f64>::boxed();
    ws.a.place(&template, 1.0, &pose, &Vector3::zeros());
    let mut facets = Vec::new();
    wall.facets_near(&pose.translation.vector, 0.0174, &mut facets);
    let o = wall
        .contact(
            &mut OverlapWorkspace::default(),
            &mut ws.a,
            (&template, 1.0, &pose),
            &facets,
        )
        .unwrap();
    let depth = 0.01 - pose.translation.vector.z;
    let expect = 4e-4 * depth;
    assert!(
        (o.volume - expect).abs() < 1e-6 * expect,
        "volume {:e} vs the slab's {expect:e}",
        o.volume
    );
}

/// Two cubes of a poured pile (1.10 and 1.23 cm, turned) that touch along a sliver GJK counts
/// as intersecting but whose Chebyshev centre finds no interior thicker than 2e-17 m (1.7e-15
/// of the pair's size): the dual points of an overlap that thin span less than three
/// dimensions to f64, and the pair query stopped the run ("dual hull failed: the points span
/// less than three dimensions", step 1 976 866 of the pile). It is a touching pair: no volume,
/// in f64, f32 and mixed precision alike (poses as the run reported them).
#[test]
fn touching_below_what_the_dual_resolves_has_no_volume() {
    use polydem::geometry::pair::overlap_pair_mixed;
    let (cube, [(sa, pa), (sb, pb)]) = pile_touching_pair();
    let (a, b) = ((&cube, sa, &pa), (&cube, sb, &pb));
    let r64 = overlap_pair(&mut PairWorkspace::<f64>::boxed(), a, b).expect("f64");
    let r32 = overlap_pair(&mut PairWorkspace::<f32>::boxed(), a, b).expect("f32");
    let mixed = overlap_pair_mixed(
        &mut PairWorkspace::<f32>::boxed(),
        &mut PairWorkspace::<f64>::boxed(),
        a,
        b,
    )
    .expect("mixed");
    for (what, r) in [("f64", &r64), ("f32", &r32), ("mixed", &mixed)] {
        assert_eq!(r.overlap.volume, 0.0, "{what}");
    }
    assert!(r64.intersects && mixed.intersects);
}

/// A body on itself and a body wholly inside another have one defined answer in every
/// precision (geometry/contained.rs): the inner body's volume, its centroid, `S = 0`. Random
/// 12-point hulls (20 faces) on themselves at random poses, and a small one inside a large one
/// from either side, in f64, f32 and mixed: the volume is the template's to 1e-12, S is zero
/// and the three agree bit for bit. (f32 once gave two coincident hulls 2.8–5.6 % too little
/// volume and a normal; f64 a normal for some poses.)
#[test]
fn coincident_and_contained_bodies_give_one_answer_in_every_precision() {
    use polydem::geometry::pair::overlap_pair_mixed;
    use polydem::rng::Rng;
    let mut rng = Rng::new(31);
    let mut w64 = PairWorkspace::<f64>::boxed();
    let mut w32 = PairWorkspace::<f32>::boxed();
    for seed in 0..40u64 {
        let t = Generator::RandomHull {
            points: 12,
            size: 1.0,
            seed,
            aspect: [1.0, 0.8, 0.6],
        }
        .build()
        .unwrap();
        let x = Vector3::new(
            rng.range(-5.0, 5.0),
            rng.range(-5.0, 5.0),
            rng.range(-5.0, 5.0),
        );
        let big = pose(x, random_rotation(&mut rng));
        let small = pose(
            x + Vector3::new(0.0005, -0.0005, 0.0003),
            random_rotation(&mut rng),
        );
        for ((sa, pa), (sb, pb), inner) in [
            ((0.02, &big), (0.02, &big), 0.02),
            ((0.02, &big), (0.002, &small), 0.002),
            ((0.002, &small), (0.02, &big), 0.002),
        ] {
            let (a, b) = ((&t, sa, pa), (&t, sb, pb));
            let results = [
                overlap_pair(&mut w64, a, b).unwrap(),
                overlap_pair(&mut w32, a, b).unwrap(),
                overlap_pair_mixed(&mut w32, &mut w64, a, b).unwrap(),
            ];
            let want = t.volume * inner * inner * inner;
            for g in &results {
                assert!(g.intersects);
                assert!(
                    (g.overlap.volume - want).abs() <= 1e-12 * want,
                    "hull {seed}: volume {} vs {want}",
                    g.overlap.volume
                );
                assert_eq!(g.overlap.dv_dxb, Vector3::zeros(), "hull {seed}");
                assert!(g.overlap.normal().is_none());
                assert_eq!(g.overlap, results[0].overlap, "hull {seed}");
            }
        }
    }
}
