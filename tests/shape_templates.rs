//! Integration tests of `polydem::shape`: closed-form mass properties of the built-in solids,
//! agreement with parry3d-f64, face merging, the principal frame, mesh import and its errors, and
//! the committed meshes under meshes/particles/.

use nalgebra::{Matrix3, Point3, Vector3};
use polydem::rng::Rng;
use polydem::shape::{
    ConvexTemplate, Generator, MAX_INPUT_POINTS, MAX_PRISM_SIDES, MAX_RANDOM_HULL_POINTS,
    MassProperties, MeshFile, ShapeError, load_mesh, prism_mass_properties,
};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

const PHI: f64 = 1.618_033_988_749_895;

/// Repository root: `$POLYDEM_ROOT` if set, else the current directory (cargo runs integration
/// tests in the package root), else the manifest directory this test was built from.
fn repo_root() -> PathBuf {
    if let Some(root) = std::env::var_os("POLYDEM_ROOT") {
        return PathBuf::from(root);
    }
    let cwd = std::env::current_dir().unwrap_or_default();
    if cwd.join("meshes").is_dir() || cwd.join("Cargo.toml").is_file() {
        return cwd;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh temporary directory for one test.
fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("polydem_shape_{tag}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(f64::MIN_POSITIVE)
}

fn size_of(t: &ConvexTemplate) -> f64 {
    2.0 * t.circumscribed_radius
}

/// Structural invariants every template must satisfy; `tol` is relative to the size.
fn check_invariants(t: &ConvexTemplate, tol: f64) {
    let size = size_of(t);
    let (v, e, f) = (
        t.vertices.len() as i64,
        t.edges.len() as i64,
        t.faces.len() as i64,
    );
    assert_eq!(v - e + f, 2, "{}: Euler V-E+F = {v}-{e}+{f}", t.name);
    let mut edge_uses = std::collections::HashMap::new();
    for face in &t.faces {
        assert!(
            (face.normal.norm() - 1.0).abs() < 1e-14,
            "{}: normal not unit",
            t.name
        );
        assert!(
            face.offset > 0.0,
            "{}: face plane does not have the centroid inside",
            t.name
        );
        for p in &t.vertices {
            let d = face.normal.dot(&p.coords) - face.offset;
            assert!(
                d <= tol * size,
                "{}: vertex outside a face plane by {d:e}",
                t.name
            );
        }
        let n = face.vertices.len();
        assert!(n >= 3);
        for k in 0..n {
            let a = t.vertices[face.vertices[k] as usize];
            let b = t.vertices[face.vertices[(k + 1) % n] as usize];
            let c = t.vertices[face.vertices[(k + 2) % n] as usize];
            // On the plane, and turning left: strictly convex (no collinear middle vertex) for
            // exact input; within the merge tolerance, not reflex.
            assert!(
                (face.normal.dot(&a.coords) - face.offset).abs() <= tol * size,
                "{}",
                t.name
            );
            let turn = (b - a).cross(&(c - b)).dot(&face.normal);
            assert!(
                turn > if tol <= 1e-9 { 1e-9 } else { -tol } * size * size,
                "{}: loop not strictly convex CCW ({turn:e})",
                t.name
            );
            let (i, j) = (face.vertices[k], face.vertices[(k + 1) % n]);
            *edge_uses.entry([i.min(j), i.max(j)]).or_insert(0) += 1;
        }
    }
    assert_eq!(edge_uses.len(), t.edges.len(), "{}", t.name);
    for e in &t.edges {
        assert_eq!(edge_uses.get(e), Some(&2), "{}: edge {e:?}", t.name);
    }
    // Principal frame: centroid at the origin, inertia diagonal and equal to principal_inertia.
    let m = MassProperties::from_triangles(&t.vertices, &t.triangles()).unwrap();
    assert!(rel(m.volume, t.volume) < 1e-12, "{}", t.name);
    assert!(
        m.centroid.coords.norm() <= 1e-12 * size,
        "{}: centroid {:?}",
        t.name,
        m.centroid
    );
    let imax = t.principal_inertia.max();
    for i in 0..3 {
        for j in 0..3 {
            let want = if i == j { t.principal_inertia[i] } else { 0.0 };
            assert!(
                (m.inertia[(i, j)] - want).abs() <= tol.max(1e-9) * imax,
                "{}: I[{i}{j}]",
                t.name
            );
        }
    }
    assert!(
        t.principal_inertia[0] <= t.principal_inertia[1]
            && t.principal_inertia[1] <= t.principal_inertia[2]
    );
    let r = t
        .vertices
        .iter()
        .map(|p| p.coords.norm())
        .fold(0.0, f64::max);
    assert_eq!(r, t.circumscribed_radius);
    assert!(
        rel(
            t.equivalent_radius,
            (3.0 * t.volume / (4.0 * std::f64::consts::PI)).cbrt()
        ) < 1e-15
    );
    assert!(t.max_face_vertices() >= 3);
}

/// Every input point maps (by `file_to_body`) inside the template, and every template vertex is
/// the image of some input point.
fn check_file_to_body(t: &ConvexTemplate, points: &[Point3<f64>], tol: f64) {
    let size = size_of(t);
    let mapped: Vec<Point3<f64>> = points.iter().map(|p| t.file_to_body * p).collect();
    for q in &mapped {
        for f in &t.faces {
            assert!(
                f.normal.dot(&q.coords) <= f.offset + tol * size,
                "{}",
                t.name
            );
        }
    }
    for v in &t.vertices {
        let d = mapped
            .iter()
            .map(|q| (q - v).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(
            d <= tol * size,
            "{}: vertex not an input point ({d:e})",
            t.name
        );
    }
}

#[test]
fn regular_solids_match_closed_forms() {
    let s5 = 5f64.sqrt();
    for size in [2.0, 0.01, 37.5] {
        let r = size / 2.0;
        // (generator, edge a, V(a), I(a) per unit density, F, V, E)
        let cases: Vec<(&str, f64, f64, f64, usize, usize, usize)> = {
            let a_tet = 2.0 * 2f64.sqrt() * r / 3f64.sqrt();
            let a_cub = 2.0 * r / 3f64.sqrt();
            let a_oct = 2f64.sqrt() * r;
            let a_dod = 2.0 / PHI * r / 3f64.sqrt();
            let a_ico = 2.0 * r / (1.0 + PHI * PHI).sqrt();
            let v_tet = a_tet.powi(3) / (6.0 * 2f64.sqrt());
            let v_cub = a_cub.powi(3);
            let v_oct = 2f64.sqrt() / 3.0 * a_oct.powi(3);
            let v_dod = (15.0 + 7.0 * s5) / 4.0 * a_dod.powi(3);
            let v_ico = 5.0 * (3.0 + s5) / 12.0 * a_ico.powi(3);
            vec![
                (
                    "tetrahedron",
                    a_tet,
                    v_tet,
                    v_tet * a_tet * a_tet / 20.0,
                    4,
                    4,
                    6,
                ),
                ("cube", a_cub, v_cub, v_cub * a_cub * a_cub / 6.0, 6, 8, 12),
                (
                    "octahedron",
                    a_oct,
                    v_oct,
                    v_oct * a_oct * a_oct / 10.0,
                    8,
                    6,
                    12,
                ),
                (
                    "dodecahedron",
                    a_dod,
                    v_dod,
                    v_dod * a_dod * a_dod * (95.0 + 39.0 * s5) / 300.0,
                    12,
                    20,
                    30,
                ),
                (
                    "icosahedron",
                    a_ico,
                    v_ico,
                    v_ico * a_ico * a_ico * PHI * PHI / 10.0,
                    20,
                    12,
                    30,
                ),
            ]
        };
        for (name, a, vol, inertia, nf, nv, ne) in cases {
            let g = Generator::parse(name, size).unwrap();
            let t = g.build().unwrap();
            assert_eq!(
                (t.faces.len(), t.vertices.len(), t.edges.len()),
                (nf, nv, ne),
                "{name}"
            );
            assert!(
                rel(t.volume, vol) < 1e-12,
                "{name}: V {} vs {vol}",
                t.volume
            );
            for k in 0..3 {
                assert!(
                    rel(t.principal_inertia[k], inertia) < 1e-12,
                    "{name}: I {} vs {inertia}",
                    t.principal_inertia[k]
                );
            }
            assert!(rel(t.circumscribed_radius, r) < 1e-14, "{name}");
            // Edge length: every edge of a regular solid is `a`.
            for e in &t.edges {
                let l = (t.vertices[e[0] as usize] - t.vertices[e[1] as usize]).norm();
                assert!(rel(l, a) < 1e-12, "{name}: edge {l} vs {a}");
            }
            // Isotropic inertia: the template keeps the orientation it was given.
            assert!(t.file_to_body.rotation.angle() == 0.0, "{name}: rotated");
            check_invariants(&t, 1e-12);
            check_file_to_body(&t, &g.points().unwrap(), 1e-12);
        }
    }
}

#[test]
fn cuboids_and_principal_axes() {
    let t = Generator::Cuboid {
        a: 3.0,
        b: 2.0,
        c: 1.0,
    }
    .build()
    .unwrap();
    assert_eq!((t.faces.len(), t.vertices.len(), t.edges.len()), (6, 8, 12));
    assert!(rel(t.volume, 6.0) < 1e-12);
    let want = Vector3::new(6.0 * 5.0 / 12.0, 6.0 * 10.0 / 12.0, 6.0 * 13.0 / 12.0);
    for k in 0..3 {
        assert!(rel(t.principal_inertia[k], want[k]) < 1e-12);
    }
    // Already principal and ascending: the frame is the input frame.
    assert!(t.file_to_body.rotation.angle() < 1e-12);
    check_invariants(&t, 1e-12);

    // Largest edge along z: the smallest moment is about z, so body x is ±input z.
    let g = Generator::Cuboid {
        a: 1.0,
        b: 2.0,
        c: 3.0,
    };
    let t = g.build().unwrap();
    let bx = t.file_to_body.rotation.inverse() * Vector3::x();
    assert!((bx.z.abs() - 1.0).abs() < 1e-12, "body x = {bx:?}");
    assert!(rel(t.principal_inertia[0], 6.0 * 5.0 / 12.0) < 1e-12);
    check_invariants(&t, 1e-12);
    check_file_to_body(&t, &g.points().unwrap(), 1e-12);

    // Off-centre, rotated input: the body frame undoes both.
    let rot = nalgebra::UnitQuaternion::from_euler_angles(0.3, -1.1, 2.0);
    let shift = Vector3::new(10.0, -4.0, 7.5);
    let pts: Vec<Point3<f64>> = Generator::Cuboid {
        a: 3.0,
        b: 2.0,
        c: 1.0,
    }
    .points()
    .unwrap()
    .iter()
    .map(|p| rot * p + shift)
    .collect();
    let t2 = ConvexTemplate::from_points("moved", &pts).unwrap();
    for k in 0..3 {
        assert!(rel(t2.principal_inertia[k], want[k]) < 1e-12);
    }
    check_invariants(&t2, 1e-12);
    check_file_to_body(&t2, &pts, 1e-12);
}

#[test]
fn prisms_match_closed_forms() {
    for sides in [3usize, 4, 5, 6, 7, 8, 12, 20, 24, 60] {
        for (d, h) in [(1.0, 0.3), (1.0, 2.5), (8e-3, 5.3e-3)] {
            let g = Generator::Prism {
                sides,
                diameter: d,
                height: h,
            };
            let t = g.build().unwrap();
            assert_eq!(t.faces.len(), sides + 2, "prism{sides}");
            assert_eq!(t.vertices.len(), 2 * sides);
            assert_eq!(t.edges.len(), 3 * sides);
            assert_eq!(t.max_face_vertices(), sides.max(4));
            let (v, perp, axis) = prism_mass_properties(sides, d, h);
            assert!(
                rel(t.volume, v) < 1e-12,
                "prism{sides}: {} vs {v}",
                t.volume
            );
            let mut want = [perp, perp, axis];
            want.sort_by(f64::total_cmp);
            for (k, w) in want.iter().enumerate() {
                assert!(rel(t.principal_inertia[k], *w) < 1e-12, "prism{sides} I{k}");
            }
            check_invariants(&t, 1e-12);
            check_file_to_body(&t, &g.points().unwrap(), 1e-12);
        }
    }
}

#[test]
fn seed_cylinder_matches_paper_table_1() {
    // Seed paper Sec. 3.1, Table 1: D = 8 mm, L = 5.3 mm, 42 vertices / 80 triangles,
    // V = 2.62e-7 m³, ρ = 1245 kg/m³, Ixx = Iyy = 2.047e-9, Izz = 2.567e-9 kg m².
    let mesh = MeshFile::prism_with_cap_centres(20, 8e-3, 5.3e-3).unwrap();
    assert_eq!((mesh.vertices.len(), mesh.triangles.len()), (42, 80));
    assert!(mesh.is_closed());
    let t = ConvexTemplate::from_points("cylinder", &mesh.vertices).unwrap();
    assert_eq!(
        (t.faces.len(), t.vertices.len(), t.edges.len()),
        (22, 40, 60)
    );
    let mv = mesh.mass_properties().unwrap();
    assert!(rel(mv.volume, t.volume) < 1e-12);
    assert!(rel(t.volume, 2.62e-7) < 2e-3, "V = {}", t.volume);
    let rho = 1245.0;
    assert!(
        rel(rho * t.principal_inertia[0], 2.047e-9) < 5e-4,
        "Ixx = {}",
        rho * t.principal_inertia[0]
    );
    assert!(rel(rho * t.principal_inertia[1], 2.047e-9) < 5e-4);
    assert!(
        rel(rho * t.principal_inertia[2], 2.567e-9) < 5e-4,
        "Izz = {}",
        rho * t.principal_inertia[2]
    );
    // Cap centres are not vertices, but they lie on the (mapped) cap faces.
    check_invariants(&t, 1e-12);
    check_file_to_body(&t, &mesh.vertices, 1e-12);
}

#[test]
fn random_hulls_match_parry() {
    use parry3d_f64::math::Vector as PV;
    for (points, seed) in [(4usize, 1u64), (8, 2), (18, 3), (50, 4), (60, 5), (66, 6)] {
        let g = Generator::RandomHull {
            points,
            size: 3.0,
            seed,
            aspect: [1.0, 0.7, 0.45],
        };
        let pts = g.points().unwrap();
        let t = g.build().unwrap();
        assert_eq!(t.vertices.len(), points, "all points are extreme");
        assert_eq!(t.faces.len(), 2 * points - 4);
        check_invariants(&t, 1e-12);
        check_file_to_body(&t, &pts, 1e-12);

        let ppts: Vec<PV> = pts.iter().map(|p| PV::new(p.x, p.y, p.z)).collect();
        let (hv, hi) = parry3d_f64::transformation::convex_hull(&ppts);
        let mp =
            parry3d_f64::mass_properties::MassProperties::from_convex_polyhedron(1.0, &hv, &hi);
        assert!(
            rel(t.volume, mp.mass()) < 1e-10,
            "V {} vs parry {}",
            t.volume,
            mp.mass()
        );
        let com = t.file_to_body.inverse() * Point3::origin();
        assert!(
            (com - Point3::new(mp.local_com.x, mp.local_com.y, mp.local_com.z)).norm()
                < 1e-10 * 3.0
        );
        let pi = mp.principal_inertia();
        let mut theirs = [pi.x, pi.y, pi.z];
        theirs.sort_by(f64::total_cmp);
        for (k, th) in theirs.iter().enumerate() {
            assert!(
                rel(t.principal_inertia[k], *th) < 1e-10,
                "I{k} {} vs {th}",
                t.principal_inertia[k]
            );
        }
        // Full tensor in the input frame: R diag(I) Rᵀ against parry's.
        let r = t
            .file_to_body
            .rotation
            .inverse()
            .to_rotation_matrix()
            .into_inner();
        let ours = r * t.inertia_tensor() * r.transpose();
        let m = mp.reconstruct_inertia_matrix();
        let cols = [m.x_axis, m.y_axis, m.z_axis];
        let theirs = Matrix3::from_fn(|i, j| cols[j][i]);
        assert!((ours - theirs).norm() < 1e-10 * theirs.norm());
    }
}

#[test]
fn mineral_grain_has_18_vertices_32_faces() {
    let t = mineral_grain().build().unwrap();
    assert_eq!(
        (t.vertices.len(), t.faces.len(), t.edges.len()),
        (18, 32, 48)
    );
    assert!(t.faces.iter().all(|f| f.vertices.len() == 3));
    check_invariants(&t, 1e-12);
}

fn mineral_grain() -> Generator {
    Generator::RandomHull {
        points: 18,
        size: 2e-3,
        seed: 2024,
        aspect: [1.0, 0.8, 0.6],
    }
}

#[test]
fn points_on_faces_and_edges_are_dropped() {
    // Cube corners plus face centres, edge midpoints and random points on the faces.
    let mut pts: Vec<Point3<f64>> = Generator::Cuboid {
        a: 2.0,
        b: 2.0,
        c: 2.0,
    }
    .points()
    .unwrap();
    let mut rng = Rng::new(7);
    for k in 0..3 {
        for s in [-1.0, 1.0] {
            let mut c = [0.0; 3];
            c[k] = s;
            pts.push(Point3::new(c[0], c[1], c[2]));
            for _ in 0..20 {
                let mut p = [
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                ];
                p[k] = s;
                pts.push(Point3::new(p[0], p[1], p[2]));
            }
            for s2 in [-1.0, 1.0] {
                let mut m = [0.0; 3];
                m[k] = s;
                m[(k + 1) % 3] = s2;
                pts.push(Point3::new(m[0], m[1], m[2]));
            }
        }
    }
    // Interior points too.
    for _ in 0..30 {
        pts.push(Point3::new(
            rng.range(-0.9, 0.9),
            rng.range(-0.9, 0.9),
            rng.range(-0.9, 0.9),
        ));
    }
    let t = ConvexTemplate::from_points("busy_cube", &pts).unwrap();
    assert_eq!((t.faces.len(), t.vertices.len(), t.edges.len()), (6, 8, 12));
    assert!(rel(t.volume, 8.0) < 1e-12);
    assert!(t.faces.iter().all(|f| f.vertices.len() == 4));
    check_invariants(&t, 1e-12);
    check_file_to_body(&t, &pts, 1e-12);
}

#[test]
fn scaled_template() {
    let t = Generator::Prism {
        sides: 7,
        diameter: 1.0,
        height: 0.4,
    }
    .build()
    .unwrap();
    let s = 2.5;
    let u = t.scaled(s).unwrap();
    assert!(rel(u.volume, t.volume * s.powi(3)) < 1e-14);
    for k in 0..3 {
        assert!(rel(u.principal_inertia[k], t.principal_inertia[k] * s.powi(5)) < 1e-14);
    }
    assert!(rel(u.circumscribed_radius, 2.5 * t.circumscribed_radius) < 1e-15);
    assert!(rel(u.equivalent_radius, 2.5 * t.equivalent_radius) < 1e-15);
    check_invariants(&u, 1e-12);
    let pts: Vec<Point3<f64>> = Generator::Prism {
        sides: 7,
        diameter: 1.0,
        height: 0.4,
    }
    .points()
    .unwrap()
    .iter()
    .map(|p| p * s)
    .collect();
    check_file_to_body(&u, &pts, 1e-12);
    // Invalid factors are errors that name the template and the value.
    for bad in [-1.0, 0.0, f64::NAN, f64::INFINITY] {
        let e = t.scaled(bad).unwrap_err().to_string();
        assert!(e.contains("prism7") && e.contains("scale factor"), "{e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Import
// ---------------------------------------------------------------------------------------------

/// Captures what `tracing` writes while `f` runs.
fn capture_logs<T>(f: impl FnOnce() -> T) -> (T, String) {
    #[derive(Clone)]
    struct Sink(Arc<Mutex<Vec<u8>>>);
    impl std::io::Write for Sink {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let buf = Arc::new(Mutex::new(Vec::new()));
    let sink = Sink(buf.clone());
    let subscriber = tracing_subscriber::fmt()
        .with_ansi(false)
        .with_max_level(tracing::Level::WARN)
        .with_writer(move || sink.clone())
        .finish();
    let out = tracing::subscriber::with_default(subscriber, f);
    let text = String::from_utf8_lossy(&buf.lock().unwrap()).into_owned();
    (out, text)
}

/// The unit cube [0,1]³ with its top face dented: the top is four triangles meeting at
/// (0.5, 0.5, 1 − depth). Volume 1 − depth/3; its hull is the cube. Side faces are quads and one
/// face uses negative indices and v/vt/vn references, to exercise the parser.
fn dented_cube_obj(depth: f64) -> String {
    let mut s = String::from("# dented cube\no dent\n");
    for (x, y, z) in [
        (0, 0, 0),
        (1, 0, 0),
        (1, 1, 0),
        (0, 1, 0),
        (0, 0, 1),
        (1, 0, 1),
        (1, 1, 1),
        (0, 1, 1),
    ] {
        s += &format!("v {x} {y} {z}\n");
    }
    s += &format!("v 0.5 0.5 {} 1.0\n", 1.0 - depth);
    s += "vt 0 0\nvn 0 0 1\n";
    s += "f 1 4 3 2\nf 1/1 2/1 6/1 5/1\nf 2//1 3//1 7//1 6//1\nf 3/1/1 4/1/1 8/1/1 7/1/1\nf 4 1 5 8\n";
    s += "f 5 6 -1\nf 6 7 9\nf 7 8 9\nf 8 5 9\n";
    s
}

#[test]
fn non_convex_obj_warns_and_uses_hull() {
    let dir = temp_dir("dent");
    let path = dir.join("dented_cube.obj");
    std::fs::write(&path, dented_cube_obj(0.3)).unwrap();
    let mesh = load_mesh(&path).unwrap();
    assert_eq!((mesh.vertices.len(), mesh.triangles.len()), (9, 14));
    assert!(mesh.is_closed());
    let (result, logs) = capture_logs(|| ConvexTemplate::from_file_with_report(&path));
    let (t, report) = result.unwrap();
    assert_eq!(t.name, "dented_cube");
    assert_eq!((t.faces.len(), t.vertices.len()), (6, 8));
    assert!(rel(t.volume, 1.0) < 1e-12);
    assert!(rel(report.mesh_volume.unwrap(), 0.9) < 1e-12);
    assert!(rel(report.added_volume, 0.1) < 1e-12);
    assert!(logs.contains("WARN"), "{logs}");
    assert!(logs.contains("dented_cube.obj"), "{logs}");
    assert!(logs.contains("1.000000e-1"), "{logs}");
    assert!(logs.contains("11.1111%"), "{logs}");

    // A convex mesh does not warn.
    let cube = Generator::Cube { size: 3f64.sqrt() }.build().unwrap();
    let stl = dir.join("cube.STL");
    cube.write_stl(&stl).unwrap();
    let (result, logs) = capture_logs(|| ConvexTemplate::from_file_with_report(&stl));
    let (t, report) = result.unwrap();
    assert!(logs.is_empty(), "{logs}");
    assert_eq!(report.added_volume, 0.0);
    assert_eq!((t.faces.len(), t.vertices.len()), (6, 8));
}

/// Writes `mesh` as ASCII STL with the same f32 values the binary writer stores.
fn write_ascii_stl(mesh: &MeshFile, path: &Path) {
    let mut s = String::from("solid test\n");
    for t in &mesh.triangles {
        s += "  facet normal 0 0 0\n    outer loop\n";
        for &i in t {
            let p = mesh.vertices[i as usize];
            s += &format!(
                "      vertex {:e} {:e} {:e}\n",
                p.x as f32, p.y as f32, p.z as f32
            );
        }
        s += "    endloop\n  endfacet\n";
    }
    s += "endsolid test\n";
    std::fs::write(path, s).unwrap();
}

#[test]
fn binary_and_ascii_stl_load_identically() {
    let dir = temp_dir("stl");
    let t = Generator::Dodecahedron { size: 0.01 }.build().unwrap();
    let bin = dir.join("d.stl");
    let asc = dir.join("d_ascii.stl");
    t.write_stl(&bin).unwrap();
    write_ascii_stl(&t.mesh(), &asc);
    let a = load_mesh(&bin).unwrap();
    let b = load_mesh(&asc).unwrap();
    assert_eq!(a, b);
    assert_eq!((a.vertices.len(), a.triangles.len()), (20, 36));
    let ta = ConvexTemplate::from_file(&bin).unwrap();
    let tb = ConvexTemplate::from_file(&asc).unwrap();
    assert_eq!(ta.vertices, tb.vertices);
    assert_eq!(ta.faces, tb.faces);
    assert_eq!(
        (ta.faces.len(), ta.vertices.len(), ta.edges.len()),
        (12, 20, 30)
    );
    // f32 storage: volume within f32 precision, symmetry kept (frame not rotated).
    assert!(rel(ta.volume, t.volume) < 1e-6);
    assert!(
        ta.file_to_body.rotation.angle() < 1e-6,
        "{}",
        ta.file_to_body.rotation.angle()
    );
    check_invariants(&ta, 1e-6);

    // A binary STL whose header starts with "solid " still reads as binary.
    let mut bytes = std::fs::read(&bin).unwrap();
    bytes[..6].copy_from_slice(b"solid ");
    let odd = dir.join("odd_header.stl");
    std::fs::write(&odd, bytes).unwrap();
    assert_eq!(load_mesh(&odd).unwrap(), a);
}

#[test]
fn stl_problems_are_named_with_sizes_and_lines() {
    let dir = temp_dir("stl_errors");
    let cube = particles_dir().join("cube.stl"); // 12 triangles: 84 + 600 = 684 bytes
    let bytes = std::fs::read(&cube).unwrap();
    assert_eq!(bytes.len(), 684);
    let load = |name: &str, data: &[u8]| {
        let path = dir.join(name);
        std::fs::write(&path, data).unwrap();
        err_text(load_mesh(&path).unwrap_err())
    };

    let e = load("empty.stl", b"");
    assert!(
        e.contains("empty.stl: cannot read mesh file: invalid STL: the file is empty (0 bytes)"),
        "{e}"
    );
    let e = load("header.stl", &bytes[..80]);
    assert!(
        e.contains("80 bytes: too short for a binary STL, which has at least 84"),
        "{e}"
    );
    // A count of 0 is a well-formed, empty binary STL.
    let mut empty = bytes[..84].to_vec();
    empty[80..84].copy_from_slice(&0u32.to_le_bytes());
    let e = load("no_triangles.stl", &empty);
    assert!(e.contains("no vertices"), "{e}");

    // Truncated (or a count larger than the data).
    let e = load("truncated.stl", &bytes[..654]);
    assert!(
        e.contains(
            "the header gives 12 triangles, which take 84 + 50 × 12 = 684 bytes, but the file \
             has 654 bytes, 30 bytes fewer"
        ) && e.contains("hold 11 whole triangles and 20 bytes more"),
        "{e}"
    );
    // A count smaller than the data: read partially before, now refused.
    let mut short_count = bytes.clone();
    short_count[80..84].copy_from_slice(&11u32.to_le_bytes());
    let e = load("short_count.stl", &short_count);
    assert!(
        e.contains("the header gives 11 triangles, which take 84 + 50 × 11 = 634 bytes, but the file has 684 bytes, 50 bytes more")
            && e.contains("hold 12 whole triangles and 0 bytes more"),
        "{e}"
    );
    // The same with a header beginning with "solid": still a binary size mismatch.
    short_count[..6].copy_from_slice(b"solid ");
    let e = load("solid_header.stl", &short_count);
    assert!(
        e.contains("634 bytes, but the file has 684") && e.contains("contains NUL bytes"),
        "{e}"
    );
    // Random bytes.
    let mut rng = Rng::new(8);
    let noise: Vec<u8> = (0..1000).map(|_| (rng.uniform() * 256.0) as u8).collect();
    let e = load("noise.stl", &noise);
    assert!(
        e.contains("binary STL size mismatch") && e.contains("but the file has 1000 bytes"),
        "{e}"
    );

    // ASCII: coordinates that f32 cannot hold are named with their line.
    let tet = |x: &str| {
        format!(
            "solid t\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex {x} 0 0\n\
             vertex 0 {x} 0\nendloop\nendfacet\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\n\
             vertex 0 {x} 0\nvertex 0 0 {x}\nendloop\nendfacet\nendsolid t\n"
        )
    };
    let e = load("tiny.stl", tet("1e-50").as_bytes());
    assert!(
        e.contains("tiny.stl: cannot read mesh file: invalid STL: line 5: coordinate 1e-50 underflows to 0 in f32"),
        "{e}"
    );
    let e = load("huge.stl", tet("1e50").as_bytes());
    assert!(e.contains("line 5: coordinate 1e50 overflows f32"), "{e}");
    let ok = dir.join("ok.stl");
    std::fs::write(&ok, tet("1e-30")).unwrap();
    assert_eq!(load_mesh(&ok).unwrap().vertices.len(), 4);
    let text = tet("1");
    // Cut after the last vertex: "endloop\nendfacet\nendsolid t\n" (28 bytes) missing.
    let e = load("cut.stl", &text.as_bytes()[..text.len() - 28]);
    assert!(
        e.contains("ends at line 13 inside a facet (truncated?)"),
        "{e}"
    );
    let e = load(
        "two.stl",
        text.replace("vertex 0 0 0\nvertex 1", "vertex 1")
            .as_bytes(),
    );
    assert!(
        e.contains("line 7: a facet has 2 vertices, an STL facet needs 3"),
        "{e}"
    );
    let e = load(
        "word.stl",
        text.replace("vertex 1 0 0", "vertex 1 x 0").as_bytes(),
    );
    assert!(e.contains("line 5: \"x\" is not a number"), "{e}");
}

#[test]
fn obj_parser_features() {
    let dir = temp_dir("obj");
    let path = dir.join("TET.OBJ");
    std::fs::write(
        &path,
        "# tetra with colours and comments\nmtllib x.mtl\nv 1 1 1 0.5 0.5 0.5\nv 1 -1 -1\nv -1 1 -1 # c\n\
         v -1 -1 1\ng part\nusemtl m\ns off\nf -4 -3 -2\nf 1 4 2\nf 1 3 4\nf 2 4 3\n",
    )
    .unwrap();
    let mesh = load_mesh(&path).unwrap();
    assert_eq!((mesh.vertices.len(), mesh.triangles.len()), (4, 4));
    assert_eq!(mesh.triangles[0], [0, 1, 2]);
    assert!(mesh.is_closed());
    let t = ConvexTemplate::from_file(&path).unwrap();
    assert_eq!(t.name, "TET");
    assert!(rel(t.volume, 8.0 / 3.0) < 1e-12);
}

fn err_text(e: ShapeError) -> String {
    e.to_string()
}

#[test]
fn errors_name_their_source() {
    let p = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
    let tet = vec![
        p(0.0, 0.0, 0.0),
        p(1.0, 0.0, 0.0),
        p(0.0, 1.0, 0.0),
        p(0.0, 0.0, 1.0),
    ];

    let mut nan = tet.clone();
    nan[2].y = f64::NAN;
    let e = err_text(ConvexTemplate::from_points("grain", &nan).unwrap_err());
    assert!(
        e.contains("grain") && e.contains("point 2") && e.contains("non-finite"),
        "{e}"
    );
    let mut inf = tet.clone();
    inf[3].z = f64::INFINITY;
    let e = err_text(ConvexTemplate::from_points("grain", &inf).unwrap_err());
    assert!(e.contains("point 3"), "{e}");

    let e = err_text(ConvexTemplate::from_points("three", &tet[..3]).unwrap_err());
    assert!(
        e.contains("three") && e.contains("at least 4 points, got 3"),
        "{e}"
    );
    let e = err_text(ConvexTemplate::from_points("none", &[]).unwrap_err());
    assert!(e.contains("got 0"), "{e}");

    let flat: Vec<_> = (0..10)
        .map(|k| p(k as f64 % 3.0, (k * k) as f64 % 5.0, 2.0))
        .collect();
    let e = err_text(ConvexTemplate::from_points("flat", &flat).unwrap_err());
    assert!(e.contains("flat") && e.contains("coplanar"), "{e}");
    let line: Vec<_> = (0..6).map(|k| p(k as f64, 2.0 * k as f64, -1.0)).collect();
    let e = err_text(ConvexTemplate::from_points("line", &line).unwrap_err());
    assert!(e.contains("collinear"), "{e}");
    let same = vec![p(1.0, 2.0, 3.0); 5];
    let e = err_text(ConvexTemplate::from_points("same", &same).unwrap_err());
    assert!(e.contains("coincide"), "{e}");

    let big = Generator::RandomHull {
        points: 100,
        size: 1.0,
        seed: 5,
        aspect: [1.0, 1.0, 1.0],
    };
    let e = err_text(big.build().unwrap_err());
    assert!(
        e.contains("random_hull100_seed5")
            && e.contains("points = 100")
            && e.contains("2n − 4 faces")
            && e.contains("4 to 66"),
        "{e}"
    );
    // The same 100 points as a vertex list: refused by the merged-face count.
    let e = err_text(ConvexTemplate::from_points("big", &big_points(100)).unwrap_err());
    assert!(
        e.contains("big: convex hull has 196 faces")
            && e.contains("limit 128")
            && e.contains("simplify"),
        "{e}"
    );

    let e = err_text(Generator::parse("ellipsoid", 1.0).unwrap_err());
    assert!(
        e.contains("ellipsoid") && e.contains("dodecahedron, icosahedron, sphere"),
        "{e}"
    );
    let e = err_text(Generator::parse("sphere", 0.0).unwrap_err());
    assert!(e.contains("sphere") && e.contains("positive"), "{e}");
    let e = err_text(Generator::parse("cube", -1.0).unwrap_err());
    assert!(e.contains("positive"), "{e}");
    let e = err_text(
        Generator::Prism {
            sides: 2,
            diameter: 1.0,
            height: 1.0,
        }
        .build()
        .unwrap_err(),
    );
    assert!(e.contains("at least 3 sides"), "{e}");

    let dir = temp_dir("errors");
    let missing = dir.join("missing.stl");
    let e = err_text(ConvexTemplate::from_file(&missing).unwrap_err());
    assert!(e.contains("missing.stl"), "{e}");

    let garbage = dir.join("garbage.stl");
    std::fs::write(&garbage, b"this is not an STL file at all\n").unwrap();
    let e = err_text(ConvexTemplate::from_file(&garbage).unwrap_err());
    assert!(e.contains("garbage.stl"), "{e}");
    let empty = dir.join("empty.obj");
    std::fs::write(&empty, b"").unwrap();
    let e = err_text(ConvexTemplate::from_file(&empty).unwrap_err());
    assert!(e.contains("empty.obj") && e.contains("no vertices"), "{e}");
    let empty_stl = dir.join("empty.stl");
    std::fs::write(&empty_stl, b"").unwrap();
    let e = err_text(ConvexTemplate::from_file(&empty_stl).unwrap_err());
    assert!(e.contains("empty.stl"), "{e}");

    let ply = dir.join("shape.ply");
    std::fs::write(&ply, b"ply\n").unwrap();
    let e = err_text(ConvexTemplate::from_file(&ply).unwrap_err());
    assert!(e.contains("shape.ply") && e.contains(".stl, .obj"), "{e}");

    let bad = dir.join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 one 0\nv 0 0 1\n").unwrap();
    let e = err_text(ConvexTemplate::from_file(&bad).unwrap_err());
    assert!(
        e.contains("bad.obj") && e.contains("line 3") && e.contains("one"),
        "{e}"
    );
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 5\n").unwrap();
    let e = err_text(ConvexTemplate::from_file(&bad).unwrap_err());
    assert!(e.contains("line 5") && e.contains("out of range"), "{e}");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nbogus 1 2\n").unwrap();
    let e = err_text(ConvexTemplate::from_file(&bad).unwrap_err());
    assert!(e.contains("line 5") && e.contains("bogus"), "{e}");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv nan 0 0\n").unwrap();
    let e = err_text(ConvexTemplate::from_file(&bad).unwrap_err());
    assert!(e.contains("bad.obj") && e.contains("point 4"), "{e}");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 2 0\n").unwrap();
    let e = err_text(ConvexTemplate::from_file(&bad).unwrap_err());
    assert!(e.contains("bad.obj") && e.contains("coplanar"), "{e}");
}

#[test]
fn never_panics_on_odd_point_sets() {
    let mut rng = Rng::new(99);
    let specials = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        1e-300,
        1e300,
        f64::MAX,
        f64::MIN_POSITIVE,
        1e-9,
        3.0,
    ];
    for trial in 0..400 {
        let n = (rng.uniform() * 12.0) as usize;
        let pts: Vec<Point3<f64>> = (0..n)
            .map(|_| {
                let mut c = [0.0; 3];
                for x in &mut c {
                    *x = if rng.uniform() < 0.3 {
                        specials[(rng.uniform() * specials.len() as f64) as usize]
                    } else {
                        (rng.uniform() * 4.0).floor() * 0.5
                            + if rng.uniform() < 0.2 { 1e-8 } else { 0.0 }
                    };
                }
                Point3::new(c[0], c[1], c[2])
            })
            .collect();
        match ConvexTemplate::from_points(&format!("trial{trial}"), &pts) {
            Ok(t) => check_invariants(&t, 1e-6),
            Err(e) => assert!(e.to_string().starts_with(&format!("trial{trial}: ")), "{e}"),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Committed meshes
// ---------------------------------------------------------------------------------------------

fn particles_dir() -> PathBuf {
    repo_root().join("meshes").join("particles")
}

#[test]
fn committed_particle_meshes_load() {
    let dir = particles_dir();
    // (file, raw vertices, raw triangles, template vertices, faces, edges)
    let cases = [
        ("dodecahedron.stl", 20, 36, 20, 12, 30),
        ("cube.stl", 8, 12, 8, 6, 12),
        ("cylinder_42.stl", 42, 80, 40, 22, 60),
        ("catalyst_cylinder.stl", 48, 92, 48, 26, 72),
        ("mineral_grain.stl", 18, 32, 18, 32, 48),
    ];
    for (file, rv, rt, v, f, e) in cases {
        let path = dir.join(file);
        let mesh = load_mesh(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (mesh.vertices.len(), mesh.triangles.len()),
            (rv, rt),
            "{file}"
        );
        assert!(mesh.is_closed(), "{file}");
        let (result, logs) = capture_logs(|| ConvexTemplate::from_file_with_report(&path));
        let (t, report) = result.unwrap();
        assert!(logs.is_empty(), "{file}: {logs}");
        assert_eq!(
            (t.vertices.len(), t.faces.len(), t.edges.len()),
            (v, f, e),
            "{file}"
        );
        assert!(rel(report.mesh_volume.unwrap(), t.volume) < 1e-6, "{file}");
        check_invariants(&t, 1e-6);
    }
    let t = ConvexTemplate::from_file(&dir.join("dodecahedron.stl")).unwrap();
    assert!(rel(t.circumscribed_radius, 0.5) < 1e-6);
    let t = ConvexTemplate::from_file(&dir.join("cube.stl")).unwrap();
    assert!(rel(t.volume, 1.0) < 1e-12);
    let t = ConvexTemplate::from_file(&dir.join("cylinder_42.stl")).unwrap();
    assert!(rel(t.volume, prism_mass_properties(20, 8e-3, 5.3e-3).0) < 1e-6);
    let t = ConvexTemplate::from_file(&dir.join("catalyst_cylinder.stl")).unwrap();
    assert!(rel(t.volume, prism_mass_properties(24, 5.5e-3, 5.5e-3).0) < 1e-6);
    let t = ConvexTemplate::from_file(&dir.join("mineral_grain.stl")).unwrap();
    assert!(rel(t.volume, mineral_grain().build().unwrap().volume) < 1e-6);
}

/// Regenerates meshes/particles/*.stl: `cargo test --release --test shape_templates -- --ignored`.
#[test]
#[ignore]
fn regenerate_particle_meshes() {
    let dir = particles_dir();
    std::fs::create_dir_all(&dir).unwrap();
    // Unit shapes: dodecahedron of circumscribed diameter 1, cube of edge 1.
    Generator::Dodecahedron { size: 1.0 }
        .build()
        .unwrap()
        .write_stl(&dir.join("dodecahedron.stl"))
        .unwrap();
    Generator::Cube { size: 3f64.sqrt() }
        .build()
        .unwrap()
        .write_stl(&dir.join("cube.stl"))
        .unwrap();
    // Seed paper Sec. 3.1 cylinder, metres, axis z, with cap-centre fans.
    MeshFile::prism_with_cap_centres(20, 8e-3, 5.3e-3)
        .unwrap()
        .write_stl(&dir.join("cylinder_42.stl"))
        .unwrap();
    // Seed paper Sec. 4.3 catalyst, metres, written in the generator's frame (axis z).
    let g = Generator::Prism {
        sides: 24,
        diameter: 5.5e-3,
        height: 5.5e-3,
    };
    let t = g.build().unwrap();
    let back = t.file_to_body.inverse();
    let mesh = MeshFile {
        vertices: t.vertices.iter().map(|v| back * v).collect(),
        triangles: t.triangles(),
    };
    mesh.write_stl(&dir.join("catalyst_cylinder.stl")).unwrap();
    // Seed paper Sec. 4.2 mineral grain, metres, principal frame.
    mineral_grain()
        .build()
        .unwrap()
        .write_stl(&dir.join("mineral_grain.stl"))
        .unwrap();
}

#[test]
fn dense_coplanar_inputs_merge() {
    // A cube surface sampled on a 21 × 21 grid per face (2402 points, most on faces and edges),
    // exact and with 1e-9 relative noise (below the merge tolerance).
    for noise in [0.0, 1e-9] {
        let mut rng = Rng::new(11);
        let mut pts = Vec::new();
        for k in 0..3 {
            for s in [-0.5, 0.5] {
                for i in 0..=20 {
                    for j in 0..=20 {
                        let mut p = [0.0; 3];
                        p[k] = s;
                        p[(k + 1) % 3] = -0.5 + i as f64 / 20.0;
                        p[(k + 2) % 3] = -0.5 + j as f64 / 20.0;
                        let jitter = |x: f64, r: &mut Rng| x + noise * r.range(-1.0, 1.0);
                        pts.push(Point3::new(
                            jitter(p[0], &mut rng),
                            jitter(p[1], &mut rng),
                            jitter(p[2], &mut rng),
                        ));
                    }
                }
            }
        }
        let t = ConvexTemplate::from_points("grid_cube", &pts).unwrap();
        assert_eq!(
            (t.faces.len(), t.vertices.len(), t.edges.len()),
            (6, 8, 12),
            "noise {noise}"
        );
        assert!(rel(t.volume, 1.0) < 1e-8);
        check_invariants(&t, if noise == 0.0 { 1e-12 } else { 1e-6 });
        check_file_to_body(&t, &pts, if noise == 0.0 { 1e-12 } else { 1e-6 });
    }
    // A 64-gon prism with 10 points along every side line and a grid on the caps.
    let mut pts = Vec::new();
    for k in 0..64 {
        let a = std::f64::consts::TAU * k as f64 / 64.0;
        for z in 0..10 {
            pts.push(Point3::new(a.cos(), a.sin(), -0.3 + 0.6 * z as f64 / 9.0));
        }
    }
    for i in -5..=5 {
        for j in -5..=5 {
            for z in [-0.3, 0.3] {
                pts.push(Point3::new(i as f64 * 0.1, j as f64 * 0.1, z));
            }
        }
    }
    let t = ConvexTemplate::from_points("dense_prism", &pts).unwrap();
    assert_eq!(
        (t.faces.len(), t.vertices.len(), t.edges.len()),
        (66, 128, 192)
    );
    let (v, perp, axis) = prism_mass_properties(64, 2.0, 0.6);
    assert!(rel(t.volume, v) < 1e-12);
    assert!(rel(t.principal_inertia[0], perp) < 1e-12 && rel(t.principal_inertia[2], axis) < 1e-12);
    check_invariants(&t, 1e-12);
}

#[test]
fn large_point_clouds_are_fast_and_rejected_cleanly() {
    // 100 000 points (MAX_INPUT_POINTS), the icosahedron's and the rest inside it: the hull is
    // the icosahedron.
    let ico = Generator::Icosahedron { size: 2.0 }.points().unwrap();
    let mut rng = Rng::new(3);
    let mut pts = ico.clone();
    for _ in ico.len()..MAX_INPUT_POINTS {
        // Random convex combination of vertices: inside.
        let w: Vec<f64> = (0..12).map(|_| rng.uniform()).collect();
        let s: f64 = w.iter().sum();
        let p = ico
            .iter()
            .zip(&w)
            .fold(Vector3::zeros(), |acc, (v, wi)| acc + v.coords * (wi / s));
        pts.push(Point3::from(p));
    }
    let start = std::time::Instant::now();
    let t = ConvexTemplate::from_points("cloud", &pts).unwrap();
    assert_eq!((t.faces.len(), t.vertices.len()), (20, 12));
    assert!(start.elapsed().as_secs_f64() < 5.0, "{:?}", start.elapsed());
    // 5000 points on a sphere: too many faces and vertices, said so.
    let start = std::time::Instant::now();
    let e = ConvexTemplate::from_points("sphere5000", &big_points(5000))
        .unwrap_err()
        .to_string();
    // (Fewer than the 9996 triangles: on so dense a sphere a few neighbouring triangles are
    // coplanar within the merge tolerance and merge.)
    assert!(
        e.contains("faces after merging") && e.contains("limit 128"),
        "{e}"
    );
    assert!(start.elapsed().as_secs_f64() < 5.0, "{:?}", start.elapsed());
}

/// `n` seeded random points on the unit sphere, all extreme: a hull of 2n − 4 triangles.
fn big_points(n: usize) -> Vec<Point3<f64>> {
    let mut rng = Rng::new(5);
    (0..n)
        .map(|_| {
            let u = rng.unit_vector();
            Point3::new(u[0], u[1], u[2])
        })
        .collect()
}

#[test]
fn oversized_hulls_are_refused_within_seconds() {
    // Each of these used to run for minutes (10⁵ points on a sphere: the O(faces × vertices)
    // plane offsets of a 2·10⁵-face hull; 10⁴ prism sides; 10⁷ random points) before being
    // refused by the face count.
    let start = std::time::Instant::now();
    let e = err_text(ConvexTemplate::from_points("ball", &big_points(100_000)).unwrap_err());
    assert!(
        e.starts_with("ball: convex hull has ") && e.contains("more than the limit 128"),
        "{e}"
    );
    let faces: usize = e["ball: convex hull has ".len()..]
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(faces > 150_000, "{e}");
    assert!(
        start.elapsed().as_secs_f64() < 10.0,
        "{:?}",
        start.elapsed()
    );

    let start = std::time::Instant::now();
    let prism = Generator::Prism {
        sides: 10_000,
        diameter: 1.0,
        height: 1.0,
    };
    let e = err_text(prism.build().unwrap_err());
    assert_eq!(
        e,
        "prism10000: sides = 10000: a prism has sides + 2 faces and a template at most 128 \
         (MAX_TEMPLATE_FACES), so sides must be 3 to 126"
    );
    assert!(
        Generator::Prism {
            sides: MAX_PRISM_SIDES,
            diameter: 1.0,
            height: 1.0,
        }
        .build()
        .is_ok_and(|t| t.faces.len() == 128)
    );
    let e = err_text(
        Generator::RandomHull {
            points: 10_000_000,
            size: 1.0,
            seed: 1,
            aspect: [1.0; 3],
        }
        .build()
        .unwrap_err(),
    );
    assert!(
        e.starts_with("random_hull10000000_seed1: points = 10000000") && e.contains("4 to 66"),
        "{e}"
    );
    assert_eq!(MAX_RANDOM_HULL_POINTS, 66);

    // Beyond MAX_INPUT_POINTS nothing is built: refused in the time it takes to count.
    let too_many = vec![Point3::new(1.0, 2.0, 3.0); MAX_INPUT_POINTS + 1];
    let e = err_text(ConvexTemplate::from_points("scan", &too_many).unwrap_err());
    assert_eq!(
        e,
        format!(
            "scan: {} points, more than the limit {MAX_INPUT_POINTS} (MAX_INPUT_POINTS) a \
             particle template is built from; a template has at most 128 faces and 256 \
             vertices, so decimate the mesh first",
            MAX_INPUT_POINTS + 1
        )
    );
    assert!(start.elapsed().as_secs_f64() < 2.0, "{:?}", start.elapsed());
}

#[test]
fn generators_deserialize_from_toml() {
    let g: Generator =
        toml::from_str("kind = \"prism\"\nsides = 20\ndiameter = 8e-3\nheight = 5.3e-3\n").unwrap();
    assert_eq!(
        g,
        Generator::Prism {
            sides: 20,
            diameter: 8e-3,
            height: 5.3e-3
        }
    );
    assert_eq!(g.name(), "prism20");
    let g: Generator = toml::from_str(
        "kind = \"random_hull\"\npoints = 18\nsize = 2e-3\nseed = 2024\naspect = [1.0, 0.8, 0.6]\n",
    )
    .unwrap();
    assert_eq!(g, mineral_grain());
    assert!(toml::from_str::<Generator>("kind = \"cube\"\nsize = 1.0\nedge = 2.0\n").is_err());
}

/// The sphere generator: an exact sphere's mass properties and radii, drawn as the 80-face
/// geodesic polyhedron with every vertex on the sphere; scaling keeps it a sphere.
#[test]
fn sphere_template_has_exact_mass_properties() {
    let t = Generator::Sphere { size: 2.0 }.build().unwrap();
    assert!(t.sphere);
    let pi = std::f64::consts::PI;
    assert!((t.volume - 4.0 / 3.0 * pi).abs() <= 1e-15 * t.volume);
    for k in 0..3 {
        assert!((t.principal_inertia[k] - 0.4 * t.volume).abs() <= 1e-15 * t.volume);
    }
    assert_eq!((t.circumscribed_radius, t.equivalent_radius), (1.0, 1.0));
    assert_eq!((t.vertices.len(), t.faces.len()), (42, 80));
    for v in &t.vertices {
        assert!((v.coords.norm() - 1.0).abs() <= 1e-15, "{v}");
    }
    let s = t.scaled(0.01).unwrap();
    assert!(s.sphere);
    assert!((s.volume - 4.0 / 3.0 * pi * 1e-6).abs() <= 1e-15 * s.volume);
    assert!(
        (s.principal_inertia[0] - 0.4 * s.volume * 1e-4).abs() <= 1e-15 * s.principal_inertia[0]
    );
    assert_eq!(s.circumscribed_radius, 0.01);
}
