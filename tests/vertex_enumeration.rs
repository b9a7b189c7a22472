//! The overlap's faces by vertex enumeration (`geometry::vertex_enumeration`, used by
//! `overlap_volume` and `overlap_pair` for at most `ENUM_MAX_PLANES` planes) against two
//! independent references: the dual hull on the same planes (`overlap_volume_by_hull`, itself
//! held to the brute-force oracle in tests/overlap_oracle.rs), and closed-form volumes of
//! degenerate configurations (planes through an edge or a vertex, four planes through one
//! vertex, coincident and nearly coincident planes) where a per-face polygon could be counted
//! twice or lost.

mod common;

use common::*;
use nalgebra::Vector3;
use polydem::geometry::overlap::{
    Overlap, OverlapWorkspace, overlap_volume, overlap_volume_by_enumeration,
    overlap_volume_by_hull,
};
use polydem::geometry::pair::{PairWorkspace, overlap_pair};
use polydem::geometry::polytope::Plane;
use polydem::geometry::vertex_enumeration::{ENUM_MAX_PLANES, ENUM_PLANES_CAPACITY};
use polydem::rng::Rng;
use polydem::shape::Generator;

/// Largest differences between two overlaps, each relative to its natural scale for a pair of
/// size `l`: V to `V + 1e-3 l³`, S to `|S| + 1e-2 l²`, the centroid and the thickness to `l`, the
/// moment to `|S| l + 1e-3 l³`. The additive parts keep a barely touching pair (whose tiny volume
/// carries round-off of ε × size × area, not ε × V) from failing on ill-conditioning alone. The
/// thickness is compared only where S has a direction (`|S| > 1e-6 l²`; a body inside the other
/// has S of round-off size).
fn difference(x: &Overlap<f64>, r: &Overlap<f64>, l: f64) -> f64 {
    let sv = r.volume + 1e-3 * l.powi(3);
    let ss = r.dv_dxb.norm() + 1e-2 * l * l;
    let thickness = if r.dv_dxb.norm() > 1e-6 * l * l {
        (x.thickness - r.thickness).abs() / l
    } else {
        0.0
    };
    [
        (x.volume - r.volume).abs() / sv,
        (x.dv_dxb - r.dv_dxb).norm() / ss,
        (x.centroid - r.centroid).norm() / l,
        thickness,
        (x.moment_b - r.moment_b).norm() / (ss * l + 1e-3 * l.powi(3)),
    ]
    .into_iter()
    .fold(0.0, f64::max)
}

fn widen(o: &Overlap<f32>) -> Overlap<f64> {
    o.to_world(&Vector3::zeros())
}

fn cast_planes(p: &[Plane<f64>]) -> Vec<Plane<f32>> {
    p.iter()
        .map(|p| Plane {
            normal: p.normal.cast(),
            offset: p.offset as f32,
        })
        .collect()
}

/// Pairs of every ordered pair of the test shapes (tetrahedra to plates, needles and a 1:20
/// size ratio), at random orientations and centre distances from deep to barely touching, and
/// dense-packing dodecahedra: the planes `overlap_pair` keeps, wherever there are at most
/// `ENUM_MAX_PLANES` of them, give the same overlap by enumeration as by the dual hull, to 1e-12
/// of the natural scales in f64 (both are exact up to round-off; the two orders of summation
/// differ, so they cannot be bitwise equal) and 2e-4 in f32 against the f64 hull (f32 round-off
/// amplified by the conditioning of shallow contacts; tests/overlap_oracle.rs allows 1e-4 of the
/// volume between f32 and the exact overlap).
#[test]
fn enumeration_matches_the_dual_hull_on_culled_pairs() {
    let mut shapes: Vec<_> = test_shapes().into_iter().map(|s| s.template).collect();
    let dodecahedron = Generator::Dodecahedron { size: 1.0 }.build().unwrap();
    let k = shapes.len();
    shapes.push(dodecahedron);
    let mut rng = Rng::new(77);
    let mut pair_ws = PairWorkspace::<f64>::boxed();
    let mut ws64 = OverlapWorkspace::<f64>::boxed();
    let mut ws32 = OverlapWorkspace::<f32>::boxed();
    let (mut compared, mut worst64, mut worst32) = (0usize, 0.0f64, 0.0f64);
    let (mut declined64, mut declined32) = (0usize, 0usize);
    let mut by_count = [0usize; ENUM_MAX_PLANES + 1];
    for i in 0..8000 {
        let (ia, ib, fraction) = if i % 2 == 0 {
            (i / 2 % k, i / 2 / k % k, 0.4 + 0.6 * rng.uniform())
        } else {
            (k, k, 0.87 + 0.1 * (rng.uniform() - 0.5))
        };
        let (ta, tb) = (&shapes[ia], &shapes[ib]);
        let dist = fraction * (ta.circumscribed_radius + tb.circumscribed_radius);
        let pa = pose(Vector3::new(0.3, -0.1, 0.2), random_rotation(&mut rng));
        let pb = pose(
            pa.translation.vector + Vector3::from(rng.unit_vector()) * dist,
            random_rotation(&mut rng),
        );
        // A body wholly inside the other is answered before any plane is placed
        // (geometry/contained.rs): the workspace then holds no planes of this pair.
        if polydem::geometry::contained::contained_overlap((ta, 1.0, &pa), (tb, 1.0, &pb)).is_some()
        {
            continue;
        }
        let g = overlap_pair(&mut pair_ws, (ta, 1.0, &pa), (tb, 1.0, &pb)).unwrap();
        let (a, b) = (pair_ws.a.planes(), pair_ws.b.planes());
        let m = a.len() + b.len();
        if !g.intersects || m > ENUM_MAX_PLANES {
            continue;
        }
        let l = ta.circumscribed_radius.min(tb.circumscribed_radius);
        let hull = overlap_volume_by_hull(&mut ws64, a, b, Vector3::zeros()).unwrap();
        let (a32, b32) = (cast_planes(a), cast_planes(b));
        let Some(enumerated) = overlap_volume_by_enumeration(&mut ws64, a, b, Vector3::zeros())
        else {
            declined64 += 1;
            continue;
        };
        let Some(enumerated32) =
            overlap_volume_by_enumeration(&mut ws32, &a32, &b32, Vector3::zeros())
        else {
            declined32 += 1;
            continue;
        };
        let e64 = difference(&enumerated, &hull, l);
        let e32 = difference(&widen(&enumerated32), &hull, l);
        assert!(
            e64 <= 1e-12,
            "pair {i} ({ia}, {ib}), {m} planes: f64 enumeration {enumerated:?} vs hull {hull:?} ({e64:e})"
        );
        assert!(
            e32 <= 2e-4,
            "pair {i} ({ia}, {ib}), {m} planes: f32 enumeration {enumerated32:?} vs hull {hull:?} ({e32:e})"
        );
        worst64 = worst64.max(e64);
        worst32 = worst32.max(e32);
        compared += 1;
        by_count[m] += 1;
    }
    eprintln!(
        "{compared} pairs with at most {ENUM_MAX_PLANES} planes (by plane count {by_count:?}): worst difference {worst64:e} (f64), {worst32:e} (f32); the enumeration declined {declined64} (f64) and {declined32} (f32)"
    );
    assert!(compared > 3000, "only {compared} pairs compared");
    // The hull fallback is for round-off accidents: were it common, the enumeration would not
    // be what the pair kernels spend their time in.
    assert!(
        (declined64 + declined32) * 200 < compared,
        "the enumeration declined {declined64} (f64) and {declined32} (f32) of {compared} pairs"
    );
    assert!(
        by_count[4..].iter().filter(|&&c| c > 20).count() >= 4,
        "plane counts {by_count:?} not varied enough"
    );
}

/// Past 8 planes (`POLYDEM_ENUM_PLANES` up to 16): every contact of the committed settled cells
/// of mineral grains (32 triangles; five faces through each vertex) and catalyst cylinders (26
/// faces), with the planes `overlap_pair` keeps, gives the same overlap by enumeration (as many
/// planes as it can take) as by the dual hull, to 1e-12 of the natural scales in f64 and 2e-4 in
/// f32; where a pair keeps more than 16 planes, or its vertices, copies included, overflow the
/// enumeration's 96, it declines and the hull takes it. It declines for few pairs.
#[test]
fn enumeration_matches_the_dual_hull_past_eight_planes() {
    use polydem::io::packing::Packing;
    let root = repo_root();
    let mineral =
        polydem::shape::ConvexTemplate::from_file(&root.join("meshes/particles/mineral_grain.stl"))
            .unwrap();
    let cylinder =
        polydem::scene::load_scene(&root.join("launch/bench/settled/cylinders_1e5.toml"))
            .unwrap()
            .templates[0]
            .clone();
    let mut pair_ws = PairWorkspace::<f64>::boxed();
    let mut ws64 = OverlapWorkspace::<f64>::boxed();
    let mut ws32 = OverlapWorkspace::<f32>::boxed();
    for (name, t) in [("mineral_grains", &mineral), ("cylinders", &cylinder)] {
        let cell =
            Packing::read(&root.join(format!("launch/bench/packings/{name}.packing"))).unwrap();
        let (c, n, r) = (cell.cell, cell.particles.len(), t.circumscribed_radius);
        let (mut compared, mut past8, mut worst64, mut worst32) = (0usize, 0usize, 0.0f64, 0.0f64);
        let (mut declined, mut beyond) = (0usize, 0usize);
        for i in 0..n {
            for j in i + 1..n {
                let (a, b) = (&cell.particles[i], &cell.particles[j]);
                let mut d = b.position - a.position;
                for k in 0..3 {
                    d[k] -= c[k] * (d[k] / c[k]).round();
                }
                if d.norm() > r * (a.scale + b.scale) {
                    continue;
                }
                let pa = pose(Vector3::zeros(), a.orientation);
                let pb = pose(d, b.orientation);
                let g = overlap_pair(&mut pair_ws, (t, a.scale, &pa), (t, b.scale, &pb)).unwrap();
                if !g.intersects || g.overlap.volume <= 0.0 {
                    continue;
                }
                let (pl_a, pl_b) = (pair_ws.a.planes(), pair_ws.b.planes());
                let m = pl_a.len() + pl_b.len();
                if m > ENUM_PLANES_CAPACITY {
                    beyond += 1;
                    continue;
                }
                let l = r * a.scale.min(b.scale);
                let hull = overlap_volume_by_hull(&mut ws64, pl_a, pl_b, Vector3::zeros()).unwrap();
                let (a32, b32) = (cast_planes(pl_a), cast_planes(pl_b));
                let (Some(e64), Some(e32)) = (
                    overlap_volume_by_enumeration(&mut ws64, pl_a, pl_b, Vector3::zeros()),
                    overlap_volume_by_enumeration(&mut ws32, &a32, &b32, Vector3::zeros()),
                ) else {
                    declined += 1;
                    continue;
                };
                let (d64, d32) = (
                    difference(&e64, &hull, l),
                    difference(&widen(&e32), &hull, l),
                );
                assert!(
                    d64 <= 1e-12,
                    "{name} {i}-{j}, {m} planes: {e64:?} vs {hull:?} ({d64:e})"
                );
                assert!(
                    d32 <= 2e-4,
                    "{name} {i}-{j}, {m} planes: {e32:?} vs {hull:?} ({d32:e})"
                );
                worst64 = worst64.max(d64);
                worst32 = worst32.max(d32);
                compared += 1;
                past8 += usize::from(m > ENUM_MAX_PLANES);
            }
        }
        eprintln!(
            "{name}: {compared} contacts compared ({past8} past {ENUM_MAX_PLANES} planes), worst {worst64:e} (f64), {worst32:e} (f32); declined {declined}, beyond {ENUM_PLANES_CAPACITY} planes {beyond}"
        );
        assert!(past8 > 8000, "{name}: only {past8} contacts past 8 planes");
        assert!(
            declined * 100 < compared,
            "{name}: declined {declined} of {compared}"
        );
    }
}

/// The unit cube [−½, ½]³ as six planes.
fn cube() -> Vec<Plane<f64>> {
    let mut planes = Vec::new();
    for k in 0..3 {
        for s in [1.0, -1.0] {
            let mut n = Vector3::zeros();
            n[k] = s;
            planes.push(Plane {
                normal: n,
                offset: 0.5,
            });
        }
    }
    planes
}

fn plane(n: Vector3<f64>, through: Vector3<f64>) -> Plane<f64> {
    let n = n.normalize();
    Plane {
        normal: n,
        offset: n.dot(&through),
    }
}

/// Closed-form volumes of the unit cube cut by the planes of a second body, each case with
/// vertices where more than three planes meet, or a plane that touches the cube only along an
/// edge or at a vertex (no face: it must add no area, neither to itself nor twice to its
/// neighbours), or a plane coincident with a face (S counts that face half to each body): the
/// enumeration and the hull agree with the exact volume to 1e-14 in f64 and 1e-6 in f32, and
/// with the exact S where it is known.
#[test]
fn degenerate_cuts_of_a_cube_have_their_exact_volumes() {
    let h = 0.5;
    let v = Vector3::new;
    // (name, planes of B, exact volume, exact S when known)
    type Case = (&'static str, Vec<Plane<f64>>, f64, Option<Vector3<f64>>);
    let cases: Vec<Case> = vec![
        (
            "plane along the top edge (x + z <= 1)",
            vec![plane(v(1.0, 0.0, 1.0), v(h, 0.0, h))],
            1.0,
            Some(Vector3::zeros()),
        ),
        (
            "plane through one corner (x + y + z <= 3/2)",
            vec![plane(v(1.0, 1.0, 1.0), v(h, h, h))],
            1.0,
            Some(Vector3::zeros()),
        ),
        (
            "diagonal plane through two edges (x + y <= 0)",
            vec![plane(v(1.0, 1.0, 0.0), Vector3::zeros())],
            0.5,
            Some(v(1.0, 1.0, 0.0).normalize() * 2f64.sqrt()),
        ),
        (
            "two diagonal planes meeting on the cube's axis",
            vec![
                plane(v(1.0, 1.0, 0.0), Vector3::zeros()),
                plane(v(1.0, -1.0, 0.0), Vector3::zeros()),
            ],
            0.25,
            None,
        ),
        (
            "corner cut through three vertices (x + y + z <= 1/2)",
            vec![plane(v(1.0, 1.0, 1.0), v(h, h, -h))],
            1.0 - 1.0 / 6.0,
            None,
        ),
        (
            "hexagonal section (x + y + z <= 0)",
            vec![plane(v(1.0, 1.0, 1.0), Vector3::zeros())],
            0.5,
            Some(v(1.0, 1.0, 1.0).normalize() * (0.75 * 3f64.sqrt())),
        ),
        (
            "coincident top face and a slab",
            vec![
                plane(v(0.0, 0.0, 1.0), v(0.0, 0.0, h)),
                plane(v(0.0, 0.0, -1.0), v(0.0, 0.0, 0.1)),
            ],
            0.4,
            Some(v(0.0, 0.0, 0.5 - 1.0)),
        ),
        (
            "two coincident side faces",
            vec![
                plane(v(1.0, 0.0, 0.0), v(h, 0.0, 0.0)),
                plane(v(0.0, 1.0, 0.0), v(0.0, h, 0.0)),
            ],
            1.0,
            Some(v(0.5, 0.5, 0.0)),
        ),
    ];
    let mut ws64 = OverlapWorkspace::<f64>::boxed();
    let mut ws32 = OverlapWorkspace::<f32>::boxed();
    let a = cube();
    for (name, b, exact, s) in &cases {
        assert!(a.len() + b.len() <= ENUM_MAX_PLANES);
        let enumerated = overlap_volume(&mut ws64, &a, b, v(0.01, 0.02, 0.03)).unwrap();
        let hull = overlap_volume_by_hull(&mut ws64, &a, b, v(0.01, 0.02, 0.03)).unwrap();
        let enumerated32 = overlap_volume(
            &mut ws32,
            &cast_planes(&a),
            &cast_planes(b),
            Vector3::new(0.01, 0.02, 0.03),
        )
        .unwrap();
        for (method, o, tol) in [
            ("enumeration", enumerated, 1e-14),
            ("hull", hull, 1e-14),
            ("f32 enumeration", widen(&enumerated32), 1e-6),
        ] {
            assert!(
                (o.volume - exact).abs() <= tol,
                "{name}: {method} V = {} (exact {exact})",
                o.volume
            );
            if let Some(s) = s {
                assert!(
                    (o.dv_dxb - s).norm() <= 10.0 * tol,
                    "{name}: {method} S = {:?} (exact {s:?})",
                    o.dv_dxb
                );
            }
        }
    }
}

/// The cube's top face against a plane through its centre tilted by θ about y, from 1e-15
/// (coincident within round-off) to 0.1 rad: the exact volume is 1 − tan θ / 8, continuous in θ
/// through the range where the two planes are merged as coincident (dual points within the
/// hull's tolerance), where each could be handed the whole top face if the other's vertices
/// were taken for its own. Enumeration and hull agree with it to 1e-14 (f64) and 1e-6 (f32).
#[test]
fn nearly_coincident_planes_keep_the_volume_continuous() {
    let mut ws64 = OverlapWorkspace::<f64>::boxed();
    let mut ws32 = OverlapWorkspace::<f32>::boxed();
    let a = cube();
    let mut theta: f64 = 1e-15;
    while theta < 0.1 {
        let b = vec![plane(
            Vector3::new(theta.sin(), 0.0, theta.cos()),
            Vector3::new(0.0, 0.0, 0.5),
        )];
        let exact = 1.0 - theta.tan() / 8.0;
        let start = Vector3::new(0.01, 0.02, 0.03);
        let enumerated = overlap_volume(&mut ws64, &a, &b, start).unwrap();
        let hull = overlap_volume_by_hull(&mut ws64, &a, &b, start).unwrap();
        let e32 =
            overlap_volume(&mut ws32, &cast_planes(&a), &cast_planes(&b), start.cast()).unwrap();
        for (method, vol, tol) in [
            ("enumeration", enumerated.volume, 1e-14),
            ("hull", hull.volume, 1e-14),
            ("f32 enumeration", e32.volume as f64, 1e-6),
        ] {
            assert!(
                (vol - exact).abs() <= tol,
                "θ = {theta:e}: {method} V = {vol} (exact {exact})"
            );
        }
        theta *= 1.7;
    }
}

/// The enumeration's limit is the scene's (`Scene::enum_planes`): 16 where a polyhedral
/// template has more than 12 faces (the shipped mineral grain, 32 triangles; the catalyst
/// cylinder, 26 faces), 8 for the dodecahedra and spheres, on both backends (the GPU kernels'
/// `PD_ENUM_MAX_PLANES`); and a CPU run takes it. 5 steps of the
/// committed settled cell of 4000 mineral grains by `polydem run` on the CPU end bitwise where
/// `POLYDEM_ENUM_PLANES=16` ends and elsewhere than `POLYDEM_ENUM_PLANES=8` (the 10 226 of its
/// contacts that keep 9–16 planes change their faces' path, and the results their last bits).
#[test]
fn many_faced_scenes_take_the_enumeration_to_sixteen_planes() {
    use polydem::io::read_checkpoint;
    let root = repo_root();
    if let Ok(v) = std::env::var("POLYDEM_ENUM_PLANES") {
        eprintln!("POLYDEM_ENUM_PLANES={v} is set: the scene defaults are not what it checks");
        return;
    }
    let settled = root.join("launch/bench/settled");
    for (scene, planes) in [
        ("mineral_grains_1e5", 16),
        ("cylinders_1e5", 16),
        ("dodecahedra_1e5", 8),
        ("spheres_1e5", 8),
    ] {
        let s = polydem::scene::load_scene(&settled.join(format!("{scene}.toml"))).unwrap();
        assert_eq!(s.enum_planes(), planes, "{scene}");
        // The GPU's kernels are compiled for the same limit.
        let config = polydem::backend::cuda::KernelConfig::for_scene(&s, polydem::Precision::Mixed);
        let want = format!("-DPD_ENUM_MAX_PLANES={planes}");
        assert!(
            config.defines().contains(&want),
            "{scene}: {want} not in the defines"
        );
    }
    let text = mineral_cell_text();
    let dir = temp_dir("enum-planes-default");
    let scene = dir.join("mineral_cell.toml");
    std::fs::write(&scene, text).unwrap();
    let run = |setting: Option<&str>| {
        let out = dir.join(setting.unwrap_or("default"));
        let mut cmd = std::process::Command::new(polydem_bin());
        cmd.env_remove("POLYDEM_ENUM_PLANES");
        if let Some(n) = setting {
            cmd.env("POLYDEM_ENUM_PLANES", n);
        }
        cmd.args([
            "run",
            scene.to_str().unwrap(),
            "--backend",
            "cpu",
            "--max-steps",
            "5",
        ]);
        let done = cmd.arg("--out").arg(&out).output().unwrap();
        assert!(
            done.status.success(),
            "{setting:?}: {}",
            String::from_utf8_lossy(&done.stderr)
        );
        read_checkpoint(&out.join("checkpoints/latest.ckpt")).unwrap()
    };
    let (default, sixteen, eight) = (run(None), run(Some("16")), run(Some("8")));
    let same = |a: &polydem::io::Checkpoint, b: &polydem::io::Checkpoint| {
        let (p, q) = (&a.particles, &b.particles);
        a.step == b.step
            && p.id == q.id
            && p.position == q.position
            && p.velocity == q.velocity
            && p.orientation == q.orientation
            && p.angular_velocity == q.angular_velocity
            && p.force == q.force
            && p.torque == q.torque
            && a.history == b.history
    };
    assert_eq!(default.step, 5);
    assert!(default.history.len() > 13_000, "{}", default.history.len());
    assert!(
        same(&default, &sixteen),
        "the default is not the 16-plane run"
    );
    assert!(
        !same(&default, &eight),
        "the 8-plane run is the same: the limit did nothing"
    );
    // The two limits differ by round-off only: the same contacts, forces within 1e-11 of the
    // largest (1.6e-13 measured after 5 steps).
    assert_eq!(default.history.len(), eight.history.len());
    let scale = default
        .particles
        .force
        .iter()
        .map(|f| f.norm())
        .fold(0.0, f64::max);
    let gap = default
        .particles
        .force
        .iter()
        .zip(&eight.particles.force)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(
        gap <= 1e-11 * scale,
        "forces differ by {gap:e} of {scale:e}"
    );
}
