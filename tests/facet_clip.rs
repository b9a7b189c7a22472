//! Polyhedron against triangular wall facets: Sutherland–Hodgman clipping against an independent
//! polygon clipper, the penetrating volume against closed forms and finite differences, and
//! independence of how a flat wall is triangulated.

mod common;

use common::*;
use nalgebra::{Isometry3, UnitQuaternion, Vector2, Vector3};
use polydem::geometry::clip::{FacetFrame, facet_contact};
use polydem::geometry::overlap::OverlapWorkspace;
use polydem::geometry::polytope::PosedPolytope;
use polydem::rng::Rng;
use polydem::shape::{ConvexTemplate, Generator};

/// 2D convex hull (Andrew's monotone chain), counter-clockwise.
fn hull2(mut pts: Vec<Vector2<f64>>) -> Vec<Vector2<f64>> {
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup_by(|a, b| (*a - *b).norm() < 1e-14);
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>| (a - o).perp(&(b - o));
    let mut lower: Vec<Vector2<f64>> = Vec::new();
    for &p in &pts {
        while lower.len() >= 2 && cross(lower[lower.len() - 2], lower[lower.len() - 1], p) <= 0.0 {
            lower.pop();
        }
        lower.push(p);
    }
    let mut upper: Vec<Vector2<f64>> = Vec::new();
    for &p in pts.iter().rev() {
        while upper.len() >= 2 && cross(upper[upper.len() - 2], upper[upper.len() - 1], p) <= 0.0 {
            upper.pop();
        }
        upper.push(p);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

fn area2(p: &[Vector2<f64>]) -> f64 {
    (0..p.len())
        .map(|i| p[i].perp(&p[(i + 1) % p.len()]))
        .sum::<f64>()
        / 2.0
}

fn inside(poly: &[Vector2<f64>], q: Vector2<f64>) -> bool {
    (0..poly.len()).all(|i| (poly[(i + 1) % poly.len()] - poly[i]).perp(&(q - poly[i])) >= -1e-14)
}

/// Independent reference: the section from the polyhedron's edges crossing the plane, then the
/// intersection with the triangle by vertex enumeration (vertices inside the other polygon and
/// all edge–edge crossings), hulled.
fn reference_clip(
    t: &ConvexTemplate,
    pose: &Isometry3<f64>,
    frame: &FacetFrame<f64>,
    tri2: &[Vector2<f64>],
) -> f64 {
    let verts = world_vertices(t, pose);
    let mut section = Vec::new();
    for e in &t.edges {
        let (p, q) = (verts[e[0] as usize], verts[e[1] as usize]);
        let (dp, dq) = (
            (p - frame.origin).dot(&frame.normal),
            (q - frame.origin).dot(&frame.normal),
        );
        if (dp < 0.0) != (dq < 0.0) {
            let x = p + (q - p) * (dp / (dp - dq));
            section.push(frame.to_2d(&x));
        }
    }
    let section = hull2(section);
    if section.len() < 3 {
        return 0.0;
    }
    let mut pts: Vec<Vector2<f64>> = section
        .iter()
        .copied()
        .filter(|&p| inside(tri2, p))
        .collect();
    pts.extend(tri2.iter().copied().filter(|&p| inside(&section, p)));
    for i in 0..section.len() {
        let (a, b) = (section[i], section[(i + 1) % section.len()]);
        for j in 0..3 {
            let (c, d) = (tri2[j], tri2[(j + 1) % 3]);
            let den = (b - a).perp(&(d - c));
            if den.abs() < 1e-300 {
                continue;
            }
            let s = (c - a).perp(&(d - c)) / den;
            let u = (c - a).perp(&(b - a)) / den;
            if (0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&u) {
                pts.push(a + (b - a) * s);
            }
        }
    }
    let h = hull2(pts);
    if h.len() < 3 { 0.0 } else { area2(&h) }
}

fn placed(t: &ConvexTemplate, pose: &Isometry3<f64>) -> Box<PosedPolytope<f64>> {
    let mut p = Box::<PosedPolytope<f64>>::default();
    p.place(t, 1.0, pose, &Vector3::zeros());
    p
}

#[test]
fn clipped_section_matches_an_independent_clipper() {
    let shapes = test_shapes();
    let mut rng = Rng::new(11);
    let mut ws = OverlapWorkspace::<f64>::boxed();
    let (mut n, mut worst, mut worst_cap) = (0, 0.0f64, 0.0f64);
    for i in 0..1200 {
        let t = &shapes[i % shapes.len()].template;
        let r = t.circumscribed_radius;
        let pose = pose(
            Vector3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ),
            random_rotation(&mut rng),
        );
        // A triangle in a random plane through the body, of random size and placement.
        let normal = Vector3::from(rng.unit_vector());
        let through = pose.translation.vector + normal * (rng.range(-0.9, 0.9) * r);
        let e1 = normal.cross(&Vector3::from(rng.unit_vector())).normalize();
        let e2 = normal.cross(&e1);
        let corner =
            |rng: &mut Rng| through + e1 * rng.range(-1.5, 1.5) * r + e2 * rng.range(-1.5, 1.5) * r;
        let mut tri = [corner(&mut rng), corner(&mut rng), corner(&mut rng)];
        if (tri[1] - tri[0]).cross(&(tri[2] - tri[0])).dot(&normal) < 0.0 {
            tri.swap(1, 2);
        }
        let Some(frame) = FacetFrame::of_triangle(&tri) else {
            continue;
        };
        let tri2: Vec<_> = tri.iter().map(|p| frame.to_2d(p)).collect();
        let tri_area = area2(&tri2);
        if tri_area < 1e-3 * r * r {
            continue;
        }
        let body = placed(t, &pose);
        let c = facet_contact(&mut ws, &body, &tri).unwrap();
        let reference = reference_clip(t, &pose, &frame, &tri2);
        let e = (c.area - reference).abs() / tri_area;
        assert!(
            e <= 1e-12,
            "case {i} ({}): area {:e} vs reference {reference:e}, error {e:e} of the triangle",
            shapes[i % shapes.len()].name,
            c.area
        );
        // The penetrating volume's face on the facet plane is the same polygon.
        let ec = (c.cap_area - c.area).abs() / tri_area;
        assert!(
            ec <= 1e-10,
            "case {i}: cap area {:e} vs clipped area {:e}",
            c.cap_area,
            c.area
        );
        worst = worst.max(e);
        worst_cap = worst_cap.max(ec);
        n += usize::from(reference > 0.0);
    }
    println!(
        "{n} clipped sections; worst area error {worst:e}, cap area vs clip {worst_cap:e} (relative to the triangle)"
    );
    assert!(n > 500, "too few non-empty sections: {n}");
}

/// Square wall z = 0 over [-1, 1]², facing +z, cut into triangles in several ways.
fn wall_triangulations() -> Vec<Vec<[Vector3<f64>; 3]>> {
    let p = |x: f64, y: f64| Vector3::new(x, y, 0.0);
    let two = vec![
        [p(-1.0, -1.0), p(1.0, -1.0), p(1.0, 1.0)],
        [p(-1.0, -1.0), p(1.0, 1.0), p(-1.0, 1.0)],
    ];
    let c = p(0.13, -0.07);
    let corners = [p(-1.0, -1.0), p(1.0, -1.0), p(1.0, 1.0), p(-1.0, 1.0)];
    let fan: Vec<_> = (0..4)
        .map(|i| [c, corners[i], corners[(i + 1) % 4]])
        .collect();
    // A fine irregular mesh: a 5×5 grid with jittered interior nodes, two triangles per cell.
    let mut rng = Rng::new(3);
    let n = 5;
    let node = |i: usize, j: usize, rng: &mut Rng| {
        let jitter = if i > 0 && i < n && j > 0 && j < n {
            0.15
        } else {
            0.0
        };
        p(
            -1.0 + 2.0 * i as f64 / n as f64 + rng.range(-jitter, jitter) / n as f64,
            -1.0 + 2.0 * j as f64 / n as f64 + rng.range(-jitter, jitter) / n as f64,
        )
    };
    let grid: Vec<Vec<_>> = (0..=n)
        .map(|i| (0..=n).map(|j| node(i, j, &mut rng)).collect())
        .collect();
    let mut fine = Vec::new();
    for i in 0..n {
        for j in 0..n {
            fine.push([grid[i][j], grid[i + 1][j], grid[i + 1][j + 1]]);
            fine.push([grid[i][j], grid[i + 1][j + 1], grid[i][j + 1]]);
        }
    }
    vec![two, fan, fine]
}

#[test]
fn flat_wall_volume_and_gradient_do_not_depend_on_triangulation() {
    let mut ws = OverlapWorkspace::<f64>::boxed();
    let mut rng = Rng::new(8);
    for t in [
        Generator::Dodecahedron { size: 0.6 }.build().unwrap(),
        Generator::Cube { size: 0.6 }.build().unwrap(),
        Generator::Prism {
            sides: 20,
            diameter: 0.5,
            height: 0.4,
        }
        .build()
        .unwrap(),
    ] {
        for _ in 0..20 {
            let q = random_rotation(&mut rng);
            let depth = rng.range(1e-6, 0.2);
            // Lowest vertex at z = −depth.
            let low = t
                .vertices
                .iter()
                .map(|v| q.transform_vector(&v.coords).z)
                .fold(f64::MAX, f64::min);
            let pose = Isometry3::from_parts(
                Vector3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), -depth - low).into(),
                q,
            );
            let body = placed(&t, &pose);
            let sums: Vec<(f64, Vector3<f64>, f64)> = wall_triangulations()
                .iter()
                .map(|tris| {
                    tris.iter()
                        .fold((0.0, Vector3::zeros(), 0.0), |(v, g, a), tri| {
                            let c = facet_contact(&mut ws, &body, tri).unwrap();
                            (v + c.volume, g + c.dv_dx, a + c.area)
                        })
                })
                .collect();
            // Independent reference for the total: the body below z = 0 by the brute-force oracle.
            let mut planes = world_planes(&t, &pose);
            planes.push((Vector3::z(), 0.0));
            let reference = oracle_intersection(&planes, 1.0).volume;
            for (v, g, a) in &sums {
                assert!(
                    (v - sums[0].0).abs() <= 1e-12 * sums[0].0.max(1e-300),
                    "{}: volume {v:e} vs {:e}",
                    t.name,
                    sums[0].0
                );
                assert!(
                    (g - sums[0].1).norm() <= 1e-12 * sums[0].1.norm(),
                    "{}: gradient differs",
                    t.name
                );
                assert!(
                    (a - sums[0].2).abs() <= 1e-12 * sums[0].2,
                    "{}: area differs",
                    t.name
                );
                // Lateral gradient terms of neighbouring prisms cancel: dV/dx = (0, 0, −A) (lifting
                // the body off the wall reduces the penetration at the rate of its section area).
                assert!(
                    g.x.abs() + g.y.abs() <= 1e-10 * a,
                    "{}: lateral gradient {g:?}",
                    t.name
                );
                assert!(
                    (g.z + a).abs() <= 1e-10 * a,
                    "{}: dV/dz {:e} vs section area {a:e}",
                    t.name,
                    g.z
                );
            }
            if reference > 1e-9 {
                assert!(
                    (sums[0].0 - reference).abs() <= 1e-9 * reference,
                    "{}: wall volume {:e} vs oracle {reference:e}",
                    t.name,
                    sums[0].0
                );
            }
        }
    }
}

#[test]
fn cube_face_down_and_gradient_by_finite_differences() {
    let cube = Generator::Cuboid {
        a: 1.0,
        b: 1.0,
        c: 1.0,
    }
    .build()
    .unwrap();
    let mut ws = OverlapWorkspace::<f64>::boxed();
    let tri = [
        Vector3::new(-0.2, -0.3, 0.0),
        Vector3::new(0.9, -0.1, 0.0),
        Vector3::new(0.1, 0.8, 0.0),
    ];
    let tri_area = ((tri[1] - tri[0]).cross(&(tri[2] - tri[0]))).norm() / 2.0;
    // A face-down 2×2×1 box covering the whole triangle, pressed in by d: V = A_tri d, and the
    // clipped section is the triangle itself.
    let slab = Generator::Cuboid {
        a: 2.0,
        b: 2.0,
        c: 1.0,
    }
    .build()
    .unwrap();
    for d in [0.3, 1e-4, 1e-7] {
        let body = placed(&slab, &Isometry3::translation(0.3, 0.2, 0.5 - d));
        let c = facet_contact(&mut ws, &body, &tri).unwrap();
        assert!(
            (c.volume - tri_area * d).abs() <= 1e-9 * tri_area * d,
            "d {d}: V {:e}",
            c.volume
        );
        assert!(
            (c.area - tri_area).abs() <= 1e-12 * tri_area,
            "d {d}: area {:e}",
            c.area
        );
        let centroid = (tri[0] + tri[1] + tri[2]) / 3.0;
        assert!(
            (c.centroid - centroid).norm() <= 1e-12,
            "d {d}: centroid {:?}",
            c.centroid
        );
    }
    // A tilted cube partly over the triangle: the full gradient (including the prism sides)
    // against central differences.
    let q = UnitQuaternion::from_euler_angles(0.4, -0.3, 0.9);
    for z in [0.3, 0.45] {
        let pose = Isometry3::from_parts(Vector3::new(0.6, 0.5, z).into(), q);
        let v = |dx: Vector3<f64>, ws: &mut OverlapWorkspace<f64>| {
            let p = Isometry3::from_parts((pose.translation.vector + dx).into(), q);
            facet_contact(ws, &placed(&cube, &p), &tri).unwrap().volume
        };
        let c = facet_contact(&mut ws, &placed(&cube, &pose), &tri).unwrap();
        assert!(
            c.volume > 1e-3,
            "z {z}: the case should penetrate ({:e})",
            c.volume
        );
        let h = 1e-6;
        let fd = Vector3::from_fn(|k, _| {
            (v(Vector3::ith(k, h), &mut ws) - v(Vector3::ith(k, -h), &mut ws)) / (2.0 * h)
        });
        assert!(
            (c.dv_dx - fd).norm() <= 1e-6 * fd.norm(),
            "z {z}: gradient {:?} vs {fd:?}",
            c.dv_dx
        );
    }
}

#[test]
fn bodies_in_front_of_or_beside_the_facet_do_not_touch_it() {
    let cube = Generator::Cuboid {
        a: 1.0,
        b: 1.0,
        c: 1.0,
    }
    .build()
    .unwrap();
    let mut ws = OverlapWorkspace::<f64>::boxed();
    let tri = [
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
    ];
    for (x, y, z) in [
        (0.3, 0.3, 0.5),
        (0.3, 0.3, 0.5 + 1e-9),
        (3.0, 0.0, 0.2),
        (0.3, 0.3, 2.0),
    ] {
        let c = facet_contact(
            &mut ws,
            &placed(&cube, &Isometry3::translation(x, y, z)),
            &tri,
        )
        .unwrap();
        assert_eq!((c.area, c.volume), (0.0, 0.0), "cube at ({x}, {y}, {z})");
    }
    // A degenerate (zero-area) facet is ignored rather than producing NaN.
    let flat = [
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(2.0, 0.0, 0.0),
    ];
    let c = facet_contact(
        &mut ws,
        &placed(&cube, &Isometry3::translation(0.5, 0.0, 0.0)),
        &flat,
    )
    .unwrap();
    assert_eq!(c.volume, 0.0);
}

/// The wall stage's prism overlap on the planes that can bound it (`prism_overlap_culled`)
/// against the same overlap on every plane (`prism_overlap`, whose dual hull and vertex
/// enumeration are tested against independent oracles in overlap_oracle.rs): the Platonic
/// solids, the seed's faceted cylinder and the mineral grain, in random orientations, at
/// penetrations from 1e-9 to half the size, over the facet's middle, its edges and corners,
/// and resting faces tilted by 1e-12 rad. Every field within 1e-13 of the body's scale (its
/// powers for V, S and M), and the body's planes back in template order after each call.
#[test]
fn culled_prism_overlap_matches_every_plane() {
    use polydem::geometry::clip::{facet_prism, prism_overlap, prism_overlap_culled};
    let root = repo_root();
    let mut templates: Vec<ConvexTemplate> = [
        "tetrahedron",
        "cube",
        "octahedron",
        "dodecahedron",
        "icosahedron",
    ]
    .iter()
    .map(|k| Generator::parse(k, 1.0).unwrap().build().unwrap())
    .collect();
    for f in ["cylinder_42.stl", "mineral_grain.stl"] {
        let t = ConvexTemplate::from_file(&root.join("meshes/particles").join(f)).unwrap();
        let s = 1.0 / (2.0 * t.circumscribed_radius);
        templates.push(t.scaled(s).unwrap());
    }
    let tri = [
        Vector3::new(-0.7, -0.6, 0.0),
        Vector3::new(0.9, -0.5, 0.0),
        Vector3::new(0.1, 0.8, 0.0),
    ];
    let prism = facet_prism(&tri).unwrap();
    let mut ws = OverlapWorkspace::<f64>::boxed();
    let mut rng = Rng::new(17);
    let (mut cases, mut culled_fewer, mut worst, mut worst_conditioned) = (0, 0, 0.0f64, 0.0f64);
    for t in &templates {
        let r = t.circumscribed_radius;
        for k in 0..240 {
            let q = if k % 8 == 7 {
                // A face resting on the wall, tilted by round-off.
                let f = &t.faces[k % t.faces.len()];
                let down = UnitQuaternion::rotation_between(&f.normal, &-Vector3::z())
                    .unwrap_or_else(UnitQuaternion::identity);
                UnitQuaternion::from_euler_angles(1e-12, -1e-12, 0.0) * down
            } else {
                let [w, x, y, z] = rng.unit_quaternion();
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
            };
            // Lowest point of the body in this orientation, then a penetration 1e-9 … 0.5 r.
            let low = t
                .vertices
                .iter()
                .map(|v| q.transform_vector(&v.coords).z)
                .fold(f64::MAX, f64::min);
            let depth = r * 10f64.powf(rng.range(-9.0, -0.3));
            let (x, y) = match k % 4 {
                0 => (rng.range(-0.2, 0.3), rng.range(-0.3, 0.3)),
                1 => (rng.range(-0.9, 1.1), rng.range(-0.8, 1.0)),
                2 => (0.9 + rng.range(-0.3, 0.3), -0.5 + rng.range(-0.3, 0.3)),
                _ => (0.5 + rng.range(-0.2, 0.2), 0.15 + rng.range(-0.2, 0.2)),
            };
            let pose = Isometry3::from_parts(Vector3::new(x, y, -low - depth).into(), q);
            let mut body = placed(t, &pose);
            let all = prism_overlap(&mut ws, &body, &prism).unwrap();
            let planes_before: Vec<_> = body.planes().to_vec();
            let culled = prism_overlap_culled(
                &mut ws,
                &mut body,
                (t, 1.0, &pose),
                &Vector3::zeros(),
                &prism,
            )
            .unwrap();
            assert_eq!(body.planes(), &planes_before[..], "planes not restored");
            let err = [
                (all.volume - culled.volume).abs() / r.powi(3),
                (all.centroid - culled.centroid).norm() / r
                    * if all.volume > 0.0 { 1.0 } else { 0.0 },
                (all.dv_dxb - culled.dv_dxb).norm() / r.powi(2),
                (all.moment_b - culled.moment_b).norm() / r.powi(3),
                (all.thickness - culled.thickness).abs() / r,
            ]
            .into_iter()
            .fold(0.0, f64::max);
            // A slab of thickness δ fixes its centroid and moment only to about ε r/δ of the
            // scale (the lateral faces are δ wide): the bound follows that conditioning.
            let conditioning = if all.volume > 0.0 {
                r / all.thickness
            } else {
                1.0
            };
            let bound = 1e-13 + 64.0 * f64::EPSILON * conditioning;
            assert!(
                err <= bound,
                "{} case {k}: error {err:e} (bound {bound:e})\nall    {all:?}\nculled {culled:?}",
                t.name
            );
            if all.thickness > 1e-3 * r {
                worst = worst.max(err);
            }
            worst_conditioned = worst_conditioned.max(err / conditioning);
            cases += 1;
            if all.volume > 0.0 {
                culled_fewer += 1;
            }
        }
    }
    println!(
        "culled prism overlap: {cases} cases ({culled_fewer} overlapping); largest difference \
         {worst:e} of the scale where δ > 1e-3 r, {worst_conditioned:e} × r/δ over all"
    );
    assert!(worst <= 1e-13, "{worst:e}");
}
