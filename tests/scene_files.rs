//! Scene files: parsing, validation errors that name their key, wall meshes and motion,
//! insertion (placement, rate, determinism, checkpoint round trip), time-step report.

use nalgebra::{UnitQuaternion, Vector3};
use polydem::scene::{
    DEFAULT_DT_FRACTION, Inserter, InsertionMode, OrientationMode, Region, Scene, SceneError,
    TimeStep, WallMotion, WallPlacement, check_report, critical_time_step, load_scene,
    load_wall_mesh, parse_scene, rayleigh_step,
};
use polydem::shape::MeshFile;
use polydem::state::Particles;
use std::f64::consts::{PI, TAU};
use std::path::PathBuf;

/// The repository root: `POLYDEM_ROOT` when set, else the current directory.
fn repo_root() -> PathBuf {
    std::env::var_os("POLYDEM_ROOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::current_dir().expect("current directory"))
}

/// A valid scene with every section; paths relative to the repository root.
const BASE: &str = r#"
gravity = [0.0, 0.0, -9.81]

[simulation]
dt = 1.0e-5
end_time = 0.5
seed = 11

[domain]
min = [-0.5, -0.5, -0.1]
max = [0.5, 0.5, 0.5]

[[materials]]
name = "glass"
youngs_modulus = 5.0e7
poisson_ratio = 0.25
density = 2500.0

[[materials]]
name = "steel"
youngs_modulus = 2.0e11
poisson_ratio = 0.3
density = 7800.0

[[material_pairs]]
materials = ["glass", "glass"]
restitution = 0.5
friction = 0.4

[[material_pairs]]
materials = ["glass", "steel"]
restitution = 0.6
friction = 0.3

[[particle_types]]
name = "grain"
material = "glass"
generator = { kind = "cube", size = 1.0 }
scale = 0.01

[[insertions]]
type = "grain"
region = { kind = "box", min = [-0.1, -0.1, 0.1], max = [0.1, 0.1, 0.3] }
count = 50

[[walls]]
name = "floor"
mesh = "meshes/walls/plane.stl"
material = "steel"

[[walls]]
name = "paddle"
mesh = "meshes/walls/plane.stl"
material = "steel"
scale = 0.1
translate = [0.0, 0.0, 0.4]
motion = { kind = "rotate", axis = [0.0, 0.0, 1.0], rpm = 30.0 }

[output]
formats = ["vtu"]
fields = ["id", "velocity"]
"#;

fn parse(text: &str) -> Result<Scene, SceneError> {
    parse_scene(text, &repo_root(), "test.toml")
}

/// The error of `text`, which must be invalid; its message must name `key`.
fn error_naming(text: &str, key: &str) -> String {
    match parse(text) {
        Ok(_) => panic!("scene should be rejected for {key}"),
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.contains("test.toml"),
                "error does not name the file: {msg}"
            );
            assert!(
                e.keys().contains(&key),
                "error does not name key {key}: keys {:?}, message:\n{msg}",
                e.keys()
            );
            msg
        }
    }
}

fn replace(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "BASE lacks {from:?}");
    BASE.replacen(from, to, 1)
}

#[test]
fn base_and_example_scenes_load() {
    let s = parse(BASE).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.walls.len(), 2);
    assert_eq!(s.walls[0].triangles.len(), 2);
    assert_eq!(s.pairs.get(1, 0).restitution, 0.6);
    assert_eq!(s.output.series_interval, 100.0 * 1e-5);
    assert!((s.simulation.neighbor.skin - 0.1 * 0.01).abs() < 1e-15);
    // The hybrid skin defaults to twice the skin, the mode to auto.
    assert_eq!(
        s.simulation.neighbor.hybrid_skin,
        2.0 * s.simulation.neighbor.skin
    );
    assert_eq!(
        s.simulation.neighbor.mode,
        polydem::scene::NeighborMode::Auto
    );

    let dir = repo_root().join("launch/examples");
    let pour = load_scene(&dir.join("pour_box.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(pour.simulation.dt, TimeStep::FractionOfCritical(0.025));
    assert_eq!(pour.walls[0].triangles.len(), 10);
    assert!(pour.output.formats.vtu && pour.output.formats.csv);
    assert!(pour.output.dir.ends_with("out/pour_box"));
    assert!(matches!(
        pour.insertions[0].mode,
        InsertionMode::Rate {
            total: Some(800),
            ..
        }
    ));
    let report = check_report(&pour);
    assert_eq!(report["particles_to_insert"], 800);
    assert_eq!(report["walls"][0]["facets"], 10);
    assert_eq!(report["templates"][0]["faces"], 12);
    // dt_fraction = 0.025 of the critical step, the face contact time, which is shorter than
    // the Rayleigh step for this grain.
    let ts = &report["time_step"];
    let (dt, contact) = (
        ts["dt"].as_f64().unwrap(),
        ts["contact_time"].as_f64().unwrap(),
    );
    assert!(contact < ts["rayleigh"].as_f64().unwrap());
    assert!((dt / contact - 0.025).abs() < 1e-12);

    for name in ["hopper.toml", "shaker.toml"] {
        let s = load_scene(&dir.join(name)).unwrap_or_else(|e| panic!("{e}"));
        assert!(!s.insertions.is_empty() && !s.walls.is_empty(), "{name}");
    }
}

/// Every example, quickstart, validation and MPI scene starts: its count insertions fit (a
/// scene can parse and still fail there: "only 277 of 300 particles fit"), and the first forces
/// are evaluated. The benchmark packings are lattices, whose fit the parser checks.
#[test]
fn launch_scenes_start() {
    let root = repo_root().join("launch");
    let mut started = 0;
    for sub in ["examples", "quickstart", "validation", "mpi"] {
        let mut files: Vec<_> = std::fs::read_dir(root.join(sub))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        files.sort();
        for f in files {
            let scene = load_scene(&f).unwrap_or_else(|e| panic!("{e}"));
            let to_place: u64 = scene
                .insertions
                .iter()
                .map(|i| match i.mode {
                    InsertionMode::Count(n) => n,
                    _ => 0,
                })
                .sum();
            let sim = polydem::pipeline::Simulation::builder(scene)
                .build()
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            assert_eq!(
                sim.state.particles.len() as u64,
                to_place,
                "{}",
                f.display()
            );
            started += 1;
        }
    }
    assert!(started >= 7, "{started} scenes");
}

#[test]
fn unknown_keys_are_errors_naming_the_full_key() {
    let msg = error_naming(&format!("colour = 1\n{BASE}"), "colour");
    assert!(
        msg.contains("allowed keys") && msg.contains("simulation"),
        "{msg}"
    );
    error_naming(
        &replace("seed = 11", "seed = 11\ndtt = 3"),
        "simulation.dtt",
    );
    error_naming(
        &replace("density = 2500.0", "density = 2500.0\nhue = 2"),
        "materials[0].hue",
    );
    let text = replace("rpm = 30.0 }", "rpm = 30.0, rpmm = 2 }");
    let msg = error_naming(&text, "walls[1].motion.rpmm");
    let line = text.lines().position(|l| l.contains("rpmm")).unwrap() + 1;
    assert!(
        msg.contains(&format!("test.toml:{line}: walls[1].motion.rpmm")),
        "line {line}: {msg}"
    );
    error_naming(
        &replace(
            "region = { kind = \"box\",",
            "region = { kind = \"box\", radius = 1.0,",
        ),
        "insertions[0].region.radius",
    );
    error_naming(
        &format!("{BASE}gravity = [0, 0, -9.81]\n"),
        "output.gravity",
    );
    error_naming(
        &replace(
            "scale = 0.01",
            "scale = { distribution = \"uniform\", min = 0.01, max = 0.02, mode = 1 }",
        ),
        "particle_types[0].scale.mode",
    );
    error_naming(
        &replace(
            "count = 50",
            "count = 50\norientation = { axis = [1, 0, 0], angle = 3, spin = 1 }",
        ),
        "insertions[0].orientation.spin",
    );
    // Wrong types and missing keys name the key too.
    error_naming(
        &replace("end_time = 0.5", "end_time = \"soon\""),
        "simulation.end_time",
    );
    error_naming(&replace("end_time = 0.5\n", ""), "simulation.end_time");
    // A value outside a key's names lists the names.
    let msg = error_naming(
        &replace("seed = 11", "seed = 11\nface_window = \"exact\""),
        "simulation.face_window",
    );
    assert!(msg.contains("allowed: `secant`, `trajectory`"), "{msg}");
}

/// `simulation.face_window` (docs/contact.md §1): the trajectory by default, the secant when
/// named, and part of what a restart must match.
#[test]
fn the_face_window_is_read_and_fingerprinted() {
    use polydem::contact::FaceWindow;
    let trajectory = parse(BASE).unwrap();
    assert_eq!(trajectory.simulation.face_window, FaceWindow::Trajectory);
    let named = parse(&replace(
        "seed = 11",
        "seed = 11\nface_window = \"trajectory\"",
    ))
    .unwrap();
    assert_eq!(named.simulation, trajectory.simulation);
    let secant = parse(&replace("seed = 11", "seed = 11\nface_window = \"secant\"")).unwrap();
    assert_eq!(secant.simulation.face_window, FaceWindow::Secant);
    let (a, b) = (
        polydem::scene::restart::SceneFingerprint::of(&secant),
        polydem::scene::restart::SceneFingerprint::of(&trajectory),
    );
    assert_ne!(
        a.hash(),
        b.hash(),
        "a restart must not change the face window"
    );
}

#[test]
fn material_values_are_checked() {
    let msg = error_naming(
        &replace("youngs_modulus = 5.0e7", "youngs_modulus = -5.0e7"),
        "materials[0].youngs_modulus",
    );
    assert!(msg.contains("positive"), "{msg}");
    for nu in ["0.5", "-1.0", "0.7"] {
        let msg = error_naming(
            &replace("poisson_ratio = 0.25", &format!("poisson_ratio = {nu}")),
            "materials[0].poisson_ratio",
        );
        assert!(msg.contains("(-1, 0.5)"), "{msg}");
    }
    error_naming(
        &replace("density = 7800.0", "density = 0"),
        "materials[1].density",
    );
    for e in ["0.0", "1.2", "-0.1"] {
        let msg = error_naming(
            &replace("restitution = 0.6", &format!("restitution = {e}")),
            "material_pairs[1].restitution",
        );
        assert!(msg.contains("(0, 1]"), "{msg}");
    }
    assert!(parse(&replace("restitution = 0.6", "restitution = 1.0")).is_ok());
    error_naming(
        &replace("friction = 0.3", "friction = -0.3"),
        "material_pairs[1].friction",
    );
}

#[test]
fn missing_pairs_and_unknown_names_are_errors() {
    // Without glass–steel, particles cannot meet the steel walls.
    let text = replace(
        "materials = [\"glass\", \"steel\"]",
        "materials = [\"steel\", \"steel\"]",
    );
    let msg = error_naming(&text, "material_pairs");
    assert!(
        msg.contains("[\"glass\", \"steel\"]") && msg.contains("walls"),
        "{msg}"
    );
    let msg = error_naming(
        &replace("material = \"glass\"", "material = \"glas\""),
        "particle_types[0].material",
    );
    assert!(
        msg.contains("\"glass\", \"steel\""),
        "lists the defined names: {msg}"
    );
    error_naming(
        &replace("type = \"grain\"", "type = \"sand\""),
        "insertions[0].type",
    );
    error_naming(
        &replace(
            "material = \"steel\"\n\n[[walls]]",
            "material = \"iron\"\n\n[[walls]]",
        ),
        "walls[0].material",
    );
    error_naming(
        &replace(
            "materials = [\"glass\", \"glass\"]",
            "materials = [\"glass\", \"gold\"]",
        ),
        "material_pairs[0].materials",
    );
}

#[test]
fn missing_files_and_bad_motions_are_errors() {
    let msg = error_naming(
        &replace("meshes/walls/plane.stl", "meshes/walls/nope.stl"),
        "walls[0].mesh",
    );
    assert!(msg.contains("nope.stl"), "{msg}");
    let msg = error_naming(
        &replace(
            "generator = { kind = \"cube\", size = 1.0 }",
            "mesh = \"meshes/particles/missing.stl\"",
        ),
        "particle_types[0].mesh",
    );
    assert!(msg.contains("missing.stl"), "{msg}");
    // A wall STL cut short: the error gives the sizes (it used to say only "failed to fill
    // whole buffer").
    let dir = std::env::temp_dir().join(format!("polydem_scene_stl_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cut = dir.join("plane_cut.stl");
    let plane = std::fs::read(repo_root().join("meshes/walls/plane.stl")).unwrap();
    assert_eq!(plane.len(), 184); // 2 triangles
    std::fs::write(&cut, &plane[..150]).unwrap();
    let msg = error_naming(
        &replace("meshes/walls/plane.stl", &cut.display().to_string()),
        "walls[0].mesh",
    );
    assert!(
        msg.contains("plane_cut.stl")
            && msg.contains("the header gives 2 triangles, which take 84 + 50 × 2 = 184 bytes, but the file has 150 bytes"),
        "{msg}"
    );
    // Shapes a template cannot hold are refused before they are built, naming the limit.
    let msg = error_naming(
        &replace(
            "generator = { kind = \"cube\", size = 1.0 }",
            "generator = { kind = \"prism\", sides = 10000, diameter = 1.0, height = 1.0 }",
        ),
        "particle_types[0].generator",
    );
    assert!(
        msg.contains("prism10000: sides = 10000") && msg.contains("sides must be 3 to 126"),
        "{msg}"
    );
    error_naming(&replace("rpm = 30.0 }", "}"), "walls[1].motion.rpm");
    error_naming(
        &replace("axis = [0.0, 0.0, 1.0], rpm", "axis = [0.0, 0.0, 0.0], rpm"),
        "walls[1].motion.axis",
    );
    let msg = error_naming(
        &replace("kind = \"rotate\"", "kind = \"spin\""),
        "walls[1].motion.kind",
    );
    assert!(
        msg.contains("rotate") && msg.contains("sinusoidal"),
        "{msg}"
    );
    let msg = error_naming(
        &replace("kind = \"rotate\"", "kind = \"translate\""),
        "walls[1].motion.rpm",
    );
    assert!(msg.contains("not allowed"), "{msg}");
    let sin = "motion = { kind = \"sinusoidal\", direction = [0, 0, 1], amplitude = -0.01, frequency = 5 }";
    error_naming(
        &replace(
            "motion = { kind = \"rotate\", axis = [0.0, 0.0, 1.0], rpm = 30.0 }",
            sin,
        ),
        "walls[1].motion.amplitude",
    );
    let sin = "motion = { kind = \"sinusoidal\", direction = [0, 0, 1], amplitude = 0.01, frequency = 0 }";
    error_naming(
        &replace(
            "motion = { kind = \"rotate\", axis = [0.0, 0.0, 1.0], rpm = 30.0 }",
            sin,
        ),
        "walls[1].motion.frequency",
    );
    error_naming(&replace("scale = 0.1", "scale = -0.1"), "walls[1].scale");
}

#[test]
fn simulation_domain_insertion_and_output_values_are_checked() {
    error_naming(
        &replace("dt = 1.0e-5", "dt = 1.0e-5\ndt_fraction = 0.1"),
        "simulation.dt_fraction",
    );
    error_naming(
        &replace("dt = 1.0e-5", "dt_fraction = 1.5"),
        "simulation.dt_fraction",
    );
    error_naming(
        &replace("max = [0.5, 0.5, 0.5]", "max = [0.5, -0.6, 0.5]"),
        "domain.max",
    );
    error_naming(
        &replace("max = [0.1, 0.1, 0.3]", "max = [0.1, 0.1, 0.9]"),
        "insertions[0].region",
    );
    error_naming(
        &replace("count = 50", "count = 50\nrate = 10.0"),
        "insertions[0].count",
    );
    error_naming(
        &replace("count = 50", "count = 50\ntotal = 3"),
        "insertions[0].total",
    );
    let msg = error_naming(
        &replace("formats = [\"vtu\"]", "formats = []"),
        "output.formats",
    );
    assert!(msg.contains("vtu, csv"), "{msg}");
    error_naming(
        &replace("formats = [\"vtu\"]", "formats = [\"vtk\"]"),
        "output.formats[0]",
    );
    let msg = error_naming(
        &replace(
            "fields = [\"id\", \"velocity\"]",
            "fields = [\"id\", \"speed\"]",
        ),
        "output.fields[1]",
    );
    assert!(
        msg.contains("angular_velocity") && msg.contains("rank"),
        "lists allowed fields: {msg}"
    );
    error_naming(
        &replace(
            "formats = [\"vtu\"]",
            "formats = [\"vtu\"]\nframe_interval = -1",
        ),
        "output.frame_interval",
    );
    // Several problems are reported together.
    let text =
        replace("density = 7800.0", "density = -1").replace("friction = 0.3", "friction = -1");
    let e = parse(&text).unwrap_err();
    assert!(
        e.keys().contains(&"materials[1].density")
            && e.keys().contains(&"material_pairs[1].friction")
    );
}

#[test]
fn toml_syntax_error_names_file_and_line() {
    let text = replace("seed = 11", "seed = = 11");
    match parse(&text) {
        Err(SceneError::Syntax { file, line, .. }) => {
            assert_eq!(file, "test.toml");
            assert_eq!(line, 7);
        }
        other => panic!("expected a syntax error, got {other:?}"),
    }
    let msg = parse(&text).unwrap_err().to_string();
    assert!(msg.starts_with("test.toml:7:"), "{msg}");
}

/// Asserts no two bounding spheres overlap and every particle is inside `region`.
fn assert_separated(scene: &Scene, p: &Particles) {
    let r: Vec<f64> = (0..p.len())
        .map(|i| {
            scene.templates[scene.particle_types[p.kind[i] as usize].template].circumscribed_radius
                * p.scale[i]
        })
        .collect();
    for i in 0..p.len() {
        for j in i + 1..p.len() {
            let d = (p.position[i] - p.position[j]).norm();
            assert!(
                d >= r[i] + r[j],
                "particles {i} and {j} overlap: {d} < {}",
                r[i] + r[j]
            );
        }
    }
}

#[test]
fn count_insertion_places_separated_deterministic_particles() {
    let scene = parse(BASE).unwrap();
    let run = |scene: &Scene| {
        let mut p = Particles::default();
        let mut next_id = 100;
        let mut ins = Inserter::new(scene);
        let rep = ins.insert(0.0, &mut p, scene, &mut next_id).unwrap();
        assert_eq!(rep.inserted, 50);
        assert_eq!(next_id, 150);
        // A count insertion runs once.
        assert_eq!(
            ins.insert(0.1, &mut p, scene, &mut next_id)
                .unwrap()
                .inserted,
            0
        );
        p
    };
    let a = run(&scene);
    assert_eq!(a.len(), 50);
    assert_separated(&scene, &a);
    let (lo, hi) = scene.insertions[0].region.aabb();
    let r = scene.max_bounding_radius();
    for x in &a.position {
        assert!(
            (0..3).all(|k| x[k] - r >= lo[k] && x[k] + r <= hi[k]),
            "outside region: {x}"
        );
    }
    assert!(
        a.mass
            .iter()
            .all(|m| (m - 2500.0 * 1e-6 * (1.0 / 3f64.sqrt()).powi(3)).abs() < 1e-12)
    );
    let b = run(&scene);
    assert_eq!(a, b, "same seed, same particles");
    let other = parse(&replace("seed = 11", "seed = 12")).unwrap();
    assert_ne!(a.position, run(&other).position);
    // Velocity and fixed orientation are applied.
    let text = replace(
        "count = 50",
        "count = 5\nvelocity = [0, 0, -1]\norientation = \"identity\"",
    );
    let s = parse(&text).unwrap();
    assert_eq!(
        s.insertions[0].orientation,
        OrientationMode::Fixed(UnitQuaternion::identity())
    );
    let mut p = Particles::default();
    Inserter::new(&s).insert(0.0, &mut p, &s, &mut 0).unwrap();
    assert!(
        p.velocity
            .iter()
            .all(|v| *v == Vector3::new(0.0, 0.0, -1.0))
    );
    assert!(
        p.orientation
            .iter()
            .all(|q| *q == UnitQuaternion::identity())
    );
}

#[test]
fn count_insertion_that_does_not_fit_says_how_many_fit() {
    let text = replace("count = 50", "count = 100000\nmax_attempts = 50");
    let s = parse(&text).unwrap();
    let mut p = Particles::default();
    let err = Inserter::new(&s)
        .insert(0.0, &mut p, &s, &mut 0)
        .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("insertions[0].count") && msg.contains(&format!("only {} of 100000", p.len())),
        "{msg}"
    );
}

#[test]
fn particles_are_not_placed_across_walls() {
    // The region straddles the floor plane (z = 0): no bounding sphere may cross it.
    let text = replace("min = [-0.1, -0.1, 0.1]", "min = [-0.1, -0.1, -0.05]");
    let s = parse(&text).unwrap();
    let mut p = Particles::default();
    Inserter::new(&s).insert(0.0, &mut p, &s, &mut 0).unwrap();
    let r = s.max_bounding_radius();
    assert!(
        p.position.iter().all(|x| x.z.abs() >= r),
        "a particle crosses the floor"
    );
    assert!(p.position.iter().any(|x| x.z < 0.0), "both sides used");
}

/// New particles keep clear of particles outside their region whose bounding spheres reach
/// into it (the searches look at the particles near the region only, and must not miss
/// these): a shell of cubes with centres half a radius outside every face of the region,
/// spaced one radius apart, leaves the 50 new cubes a smaller box, and none touches the shell.
#[test]
fn insertion_avoids_particles_reaching_in_from_outside_the_region() {
    let scene = parse(BASE).unwrap();
    let template = &scene.templates[scene.particle_types[0].template];
    let r = template.circumscribed_radius * 0.01;
    let (lo, hi) = scene.insertions[0].region.aabb();
    let mut p = Particles::default();
    let mut id = 0;
    let steps = |a: f64, b: f64| {
        let n = ((b - a) / r).ceil() as usize;
        (0..=n).map(move |k| a + (b - a) * k as f64 / n as f64)
    };
    for axis in 0..3 {
        for side in [lo[axis] - 0.5 * r, hi[axis] + 0.5 * r] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for a in steps(lo[u], hi[u]) {
                for b in steps(lo[v], hi[v]) {
                    let mut x = Vector3::zeros();
                    (x[axis], x[u], x[v]) = (side, a, b);
                    p.push(id, 0, 0.01, x, UnitQuaternion::identity(), template, 2500.0);
                    id += 1;
                }
            }
        }
    }
    let shell = p.len();
    let rep = Inserter::new(&scene)
        .insert(0.0, &mut p, &scene, &mut id)
        .unwrap();
    assert_eq!(rep.inserted, 50);
    for i in shell..p.len() {
        for j in 0..shell {
            let d = (p.position[i] - p.position[j]).norm();
            assert!(
                d >= 2.0 * r,
                "new cube {i} overlaps shell cube {j}: {d} < {}",
                2.0 * r
            );
        }
    }
}

fn rate_scene() -> Scene {
    let text = replace(
        "count = 50",
        "rate = 200.0\nstart = 0.1\nend = 0.4\ntotal = 50",
    );
    parse(&text).unwrap()
}

#[test]
fn rate_insertion_feeds_the_expected_count() {
    let s = rate_scene();
    let mut p = Particles::default();
    let mut ins = Inserter::new(&s);
    let mut id = 0;
    let dt = 1e-3;
    for step in 0..=500 {
        let t = step as f64 * dt;
        ins.insert(t, &mut p, &s, &mut id).unwrap();
        let expected = (((t.min(0.4) - 0.1) * 200.0).floor().max(0.0) as usize).min(50);
        assert_eq!(p.len(), expected, "at t = {t}");
    }
    assert_eq!(p.len(), 50);
    assert_separated(&s, &p);
    assert_eq!(ins.inserted(), &[50]);
    // Without a total the end time limits it: 0.3 s × 200/s.
    let s2 = parse(&replace(
        "count = 50",
        "rate = 200.0\nstart = 0.1\nend = 0.4",
    ))
    .unwrap();
    assert_eq!(s2.insertions[0].planned_count(0.5), 60);
    assert_eq!(check_report(&s2)["particles_to_insert"], 60);
}

/// A rate insertion with an `interval` places what fell due in batches at the steps that
/// cross the interval's multiples: 200 per second from 0.1 s, 50 in all, every 0.05 s gives
/// five batches of ten (at 0.15 … 0.35 s) and nothing between them. `interval` is for rate
/// insertions only and must be positive.
#[test]
fn a_batched_rate_insertion_feeds_at_its_interval() {
    let s = parse(&replace(
        "count = 50",
        "rate = 200.0\nstart = 0.1\nend = 0.4\ntotal = 50\ninterval = 0.05",
    ))
    .unwrap();
    let (mut p, mut ins, mut id) = (Particles::default(), Inserter::new(&s), 0);
    let dt = s.time_step();
    let mut batches = Vec::new();
    for k in 0..=50_000u64 {
        let t = k as f64 * dt;
        let before = p.len();
        let crossing = (t / 0.05).floor() != ((t - dt) / 0.05).floor();
        assert!(
            crossing || !ins.pending(t, &s),
            "pending between batches at {t} s"
        );
        ins.insert(t, &mut p, &s, &mut id).unwrap();
        if p.len() != before {
            assert_ne!(
                (t / 0.05).floor(),
                ((t - dt) / 0.05).floor(),
                "placed between batches at {t} s"
            );
            batches.push((t, p.len() - before));
        }
    }
    assert_eq!(batches.len(), 5, "{batches:?}");
    for (j, (t, n)) in batches.iter().enumerate() {
        assert!(
            (t - 0.05 * (j + 3) as f64).abs() <= dt && *n == 10,
            "{batches:?}"
        );
    }
    assert_separated(&s, &p);
    error_naming(
        &replace("count = 50", "count = 50\ninterval = 0.1"),
        "insertions[0].interval",
    );
    error_naming(
        &replace("count = 50", "rate = 10.0\ninterval = 0.0"),
        "insertions[0].interval",
    );
}

#[test]
fn inserter_state_round_trip_gives_identical_insertions() {
    let s = rate_scene();
    let mut p = Particles::default();
    let mut ins = Inserter::new(&s);
    let mut id = 0;
    for step in 0..200 {
        ins.insert(step as f64 * 1e-3, &mut p, &s, &mut id).unwrap();
    }
    let state = ins.state();
    let json = serde_json::to_string(&state).unwrap();
    let restored_state = serde_json::from_str(&json).unwrap();
    assert_eq!(state, restored_state);
    let mut restored = Inserter::try_restore(&s, &restored_state).unwrap();
    let (mut p2, mut id2) = (p.clone(), id);
    for step in 200..500 {
        let t = step as f64 * 1e-3;
        ins.insert(t, &mut p, &s, &mut id).unwrap();
        restored.insert(t, &mut p2, &s, &mut id2).unwrap();
    }
    assert_eq!(p, p2);
    assert_eq!(ins.state(), restored.state());
    assert!(!p.is_empty() && id == id2);
}

#[test]
fn wall_motion_matches_closed_forms() {
    let axis = Vector3::new(1.0, 2.0, 2.0).normalize();
    let origin = Vector3::new(0.3, -0.2, 0.1);
    let rot = WallMotion::Rotate {
        axis: nalgebra::Unit::new_normalize(axis),
        origin,
        rpm: 45.0,
    };
    let w = TAU * 45.0 / 60.0;
    let p0 = Vector3::new(1.0, 0.5, -0.25);
    for t in [0.0, 0.1, 0.37, 2.0] {
        let pt = rot.transform(t).transform_point(&p0.into()).coords;
        let expect = origin
            + UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), w * t)
                * (p0 - origin);
        assert!((pt - expect).norm() < 1e-12);
        let v = rot.velocity_at(t, &pt);
        assert!((v - (axis * w).cross(&(pt - origin))).norm() < 1e-12);
        // Finite difference of the pose agrees with the velocity.
        let h = 1e-6;
        let fd = (rot.transform(t + h).transform_point(&p0.into()).coords
            - rot.transform(t - h).transform_point(&p0.into()).coords)
            / (2.0 * h);
        assert!((fd - v).norm() < 1e-6);
        // Points on the axis stay put.
        assert!(
            (rot.transform(t)
                .transform_point(&(origin + axis).into())
                .coords
                - origin
                - axis)
                .norm()
                < 1e-12
        );
    }
    let dir = Vector3::new(0.0, 0.6, 0.8);
    let (a, f) = (0.002, 15.0);
    let sin = WallMotion::Sinusoidal {
        direction: nalgebra::Unit::new_normalize(dir),
        amplitude: a,
        frequency: f,
    };
    for t in [0.0, 0.013, 0.05, 1.234] {
        let x = sin.transform(t).translation.vector;
        assert!((x - dir * (a * (TAU * f * t).sin())).norm() < 1e-15);
        assert!(
            (sin.velocity_at(t, &p0) - dir * (TAU * f * a * (TAU * f * t).cos())).norm() < 1e-12
        );
        assert_eq!(sin.transform(t).rotation, UnitQuaternion::identity());
    }
    let tr = WallMotion::Translate {
        velocity: Vector3::new(0.1, 0.0, -0.2),
    };
    assert!((tr.transform(2.0).translation.vector - Vector3::new(0.2, 0.0, -0.4)).norm() < 1e-15);
    assert_eq!(WallMotion::Fixed.velocity_at(1.0, &p0), Vector3::zeros());
    // The scene's rotating paddle resolves to ω = 2π·30/60 about z.
    let s = parse(BASE).unwrap();
    assert!((s.walls[1].motion.angular_velocity() - Vector3::new(0.0, 0.0, PI)).norm() < 1e-15);
}

#[test]
fn wall_mesh_scale_rotate_translate_and_flip() {
    let path = repo_root().join("meshes/walls/plane.stl");
    let plain = load_wall_mesh(&path, &WallPlacement::default())
        .unwrap()
        .triangles;
    let normal = |t: &[Vector3<f64>; 3]| (t[1] - t[0]).cross(&(t[2] - t[0])).normalize();
    assert!(
        plain
            .iter()
            .all(|t| (normal(t) - Vector3::z()).norm() < 1e-12)
    );
    let placement = WallPlacement {
        scale: 2.0,
        rotation: UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 90f64.to_radians()),
        translation: Vector3::new(0.0, 0.0, 1.0),
        flip_normals: true,
    };
    let placed = load_wall_mesh(&path, &placement).unwrap().triangles;
    for (a, b) in plain.iter().zip(&placed) {
        // Flip swaps the last two vertices; the first maps as translate + R (2 p).
        let p = a[0] * 2.0;
        assert!((b[0] - Vector3::new(p.x, -p.z, p.y + 1.0)).norm() < 1e-6);
        // +z turned to −y by the rotation, then flipped to +y.
        assert!((normal(b) - Vector3::y()).norm() < 1e-9);
    }
    // Via the scene: rotate = { axis, angle } in degrees.
    let text = replace(
        "scale = 0.1\n",
        "scale = 0.1\nrotate = { axis = [1, 0, 0], angle = 90 }\n",
    );
    let s = parse(&text).unwrap();
    let t = &s.walls[1].triangles[0];
    assert!((normal(t) + Vector3::y()).norm() < 1e-9);
    assert!(
        t.iter()
            .all(|p| (p.z - 0.4).abs() <= 0.05 + 1e-9 && p.y.abs() < 1e-9)
    );
}

#[test]
fn committed_wall_meshes_face_the_particles() {
    let dir = repo_root().join("meshes/walls");
    let load = |f: &str| {
        load_wall_mesh(&dir.join(f), &WallPlacement::default())
            .unwrap()
            .triangles
    };
    let normal = |t: &[Vector3<f64>; 3]| (t[1] - t[0]).cross(&(t[2] - t[0])).normalize();
    let centroid = |t: &[Vector3<f64>; 3]| (t[0] + t[1] + t[2]) / 3.0;
    for (file, height) in [("box_open_top.stl", 0.1), ("box_open_top_tall.stl", 0.2)] {
        let box_tris = load(file);
        assert_eq!(box_tris.len(), 10);
        let inside = Vector3::new(0.0, 0.0, 0.5 * height);
        assert!(
            box_tris
                .iter()
                .all(|t| normal(t).dot(&(inside - centroid(t))) > 0.0)
        );
        let top = box_tris.iter().flatten().map(|x| x.z).fold(0.0, f64::max);
        assert!((top - height).abs() < 1e-6, "{file}: top at {top}");
    }
    let hopper = load("hopper.stl");
    assert_eq!(hopper.len(), 4 * HOPPER_SEGMENTS);
    for t in &hopper {
        let c = centroid(t);
        let n = normal(t);
        assert!(
            n.dot(&Vector3::new(-c.x, -c.y, 0.0)) > 0.0,
            "hopper normals face the axis"
        );
        assert!(n.z >= -1e-6, "and never downwards");
    }
    assert_eq!(load("plane.stl").len(), 2);
}

#[test]
fn rayleigh_step_matches_the_formula() {
    let s = parse(&replace("dt = 1.0e-5", "dt_fraction = 0.25")).unwrap();
    let ts = critical_time_step(&s);
    // Cube of circumscribed diameter 1 scaled by 0.01: edge 0.01/√3, R = (3V/4π)^(1/3).
    let edge = 0.01 / 3f64.sqrt();
    let r = (3.0 * edge.powi(3) / (4.0 * PI)).cbrt();
    let g: f64 = 5.0e7 / (2.0 * 1.25);
    let expect = PI * r * (2500.0 / g).sqrt() / (0.1631 * 0.25 + 0.8766);
    assert!((ts.rayleigh - expect).abs() < 1e-12 * expect);
    assert!((rayleigh_step(&s.materials[0], r) - expect).abs() < 1e-12 * expect);
    assert_eq!(ts.per_material.len(), 1, "only particle materials count");
    // Face-to-face contact time of two such cubes at the impact speed max(1, √(2 g H)):
    // T = τ (m_eff v^{2/3} / (c A^{4/3}))^{3/4}, τ = 2 X_max Γ(7/4)Γ(1/2)/Γ(5/4) with
    // X_max = (2/3)^{3/4} for F ∝ δ^{1/3} (closed form of the undamped impact).
    let tau = 2.0 * (2.0f64 / 3.0).powf(0.75) * 0.919_062_526_848_883_5 * PI.sqrt()
        / 0.906_402_477_055_477;
    let m = 2500.0 * edge.powi(3);
    let c = 2.0 * 5.0e7 / r;
    let v = polydem::scene::impact_speed(&s);
    let t_face =
        tau * (0.5 * m * v.powf(2.0 / 3.0) / (c * (edge * edge).powf(4.0 / 3.0))).powf(0.75);
    let contact = ts.contact_time.expect("contact time");
    assert!(
        (contact - t_face).abs() < 1e-6 * t_face,
        "{contact} vs {t_face}"
    );
    assert!((ts.dt - 0.25 * expect.min(t_face)).abs() < 1e-6 * ts.dt);
    assert!((s.time_step() - ts.dt).abs() < 1e-20);
}

/// A small soft grain meeting a large stiff one: their face contact (m* = m_a m_b/(m_a + m_b),
/// c = E_a/R_a + E_b/R_b, the smaller face) is shorter than either type's with itself, and it
/// sets the critical step and the check's warning.
#[test]
fn the_contact_time_of_two_types_sets_the_step_when_it_is_the_shortest() {
    let text = replace(
        "[[insertions]]",
        "[[particle_types]]\nname = \"bolt\"\nmaterial = \"steel\"\n\
         generator = { kind = \"cube\", size = 1.0 }\nscale = 0.02\n\n\
         [[material_pairs]]\nmaterials = [\"steel\", \"steel\"]\nrestitution = 0.5\n\
         friction = 0.3\n\n[[insertions]]",
    )
    .replace("dt = 1.0e-5", "dt_fraction = 0.025");
    let s = parse(&text).unwrap();
    let v = polydem::scene::impact_speed(&s);
    let times = polydem::scene::face_contact_times(&s, v);
    let names: Vec<&str> = times.iter().map(|t| t.0.as_str()).collect();
    assert_eq!(names, ["grain", "bolt", "grain + bolt"]);
    // The closed form of rayleigh_step_matches_the_formula for the pair.
    let tau = 2.0 * (2.0f64 / 3.0).powf(0.75) * 0.919_062_526_848_883_5 * PI.sqrt()
        / 0.906_402_477_055_477;
    let edge = 0.01 / 3f64.sqrt();
    let r = (3.0 * edge.powi(3) / (4.0 * PI)).cbrt();
    let (m_a, m_b) = (2500.0 * edge.powi(3), 7800.0 * (2.0 * edge).powi(3));
    let m = m_a * m_b / (m_a + m_b);
    let c = 5.0e7 / r + 2.0e11 / (2.0 * r);
    let t_pair = tau * (m * v.powf(2.0 / 3.0) / (c * (edge * edge).powf(4.0 / 3.0))).powf(0.75);
    assert!(
        (times[2].1 - t_pair).abs() < 1e-6 * t_pair,
        "{} vs {t_pair}",
        times[2].1
    );
    assert!(
        times[2].1 < times[0].1 && times[2].1 < times[1].1,
        "{times:?}"
    );
    let ts = critical_time_step(&s);
    assert_eq!(ts.contact_time, Some(times[2].1));
    assert!((ts.dt - 0.025 * t_pair.min(ts.rayleigh)).abs() < 1e-6 * ts.dt);
}

#[test]
fn scale_distributions_and_cylinder_regions() {
    let text = replace("scale = 0.01", "scale = { distribution = \"normal\", mean = 0.01, std = 0.002, min = 0.008, max = 0.012 }")
        .replace("region = { kind = \"box\", min = [-0.1, -0.1, 0.1], max = [0.1, 0.1, 0.3] }", "region = { kind = \"cylinder\", base = [0, 0, 0.1], axis = [0, 0, 1], radius = 0.1, height = 0.2 }");
    let s = parse(&text).unwrap();
    assert!(matches!(s.insertions[0].region, Region::Cylinder { .. }));
    let mut p = Particles::default();
    Inserter::new(&s).insert(0.0, &mut p, &s, &mut 0).unwrap();
    assert_eq!(p.len(), 50);
    assert!(p.scale.iter().all(|x| (0.008..=0.012).contains(x)));
    assert!(p.scale.iter().any(|x| *x != p.scale[0]));
    assert_separated(&s, &p);
    for (x, sc) in p.position.iter().zip(&p.scale) {
        let r = s.templates[0].circumscribed_radius * sc;
        assert!(x.xy().norm() + r <= 0.1 + 1e-12 && x.z - r >= 0.1 && x.z + r <= 0.3 + 1e-12);
    }
    error_naming(
        &replace(
            "scale = 0.01",
            "scale = { distribution = \"uniform\", min = 0.02, max = 0.01 }",
        ),
        "particle_types[0].scale.max",
    );
    error_naming(
        &replace("scale = 0.01", "scale = { distribution = \"gamma\" }"),
        "particle_types[0].scale.distribution",
    );
}

// ---- wall meshes (meshes/walls): written by `regenerate_wall_meshes` -------------------------

/// Segments around the hopper's circumference.
const HOPPER_SEGMENTS: usize = 64;

/// Appends the quad `p, p+u, p+u+v, p+v` as two triangles wound so that `u × v` is their normal.
fn quad(m: &mut MeshFile, p: [f64; 3], u: [f64; 3], v: [f64; 3]) {
    let p = Vector3::from(p);
    let (u, v) = (Vector3::from(u), Vector3::from(v));
    tri(m, [p, p + u, p + u + v]);
    tri(m, [p, p + u + v, p + v]);
}

fn tri(m: &mut MeshFile, t: [Vector3<f64>; 3]) {
    let base = m.vertices.len() as u32;
    m.vertices
        .extend(t.iter().map(|x| nalgebra::Point3::from(*x)));
    m.triangles.push([base, base + 1, base + 2]);
}

/// Open-top box, 0.1 m cube: x, y ∈ [−0.05, 0.05], z ∈ [0, 0.1], normals inwards.
fn box_open_top() -> MeshFile {
    open_box(0.1)
}

/// Open-top box of base 0.1 m × 0.1 m and height `height`: x, y ∈ [−0.05, 0.05],
/// z ∈ [0, height], normals inwards.
fn open_box(height: f64) -> MeshFile {
    let (h, l) = (0.05, 0.1);
    let mut m = MeshFile::default();
    quad(&mut m, [-h, -h, 0.0], [l, 0.0, 0.0], [0.0, l, 0.0]); // floor, +z
    quad(&mut m, [-h, -h, 0.0], [0.0, l, 0.0], [0.0, 0.0, height]); // x = −h, +x
    quad(&mut m, [h, -h, 0.0], [0.0, 0.0, height], [0.0, l, 0.0]); // x = +h, −x
    quad(&mut m, [-h, -h, 0.0], [0.0, 0.0, height], [l, 0.0, 0.0]); // y = −h, +y
    quad(&mut m, [-h, h, 0.0], [l, 0.0, 0.0], [0.0, 0.0, height]); // y = +h, −y
    m
}

/// Conical hopper with a cylindrical bin: outlet radius 10 mm at z = 0, cone at 30° from the
/// vertical up to radius 50 mm, then a cylinder to z = 0.15 m; normals face the axis.
fn hopper() -> MeshFile {
    let (r0, r1, top) = (0.01, 0.05, 0.15);
    let zc = (r1 - r0) / 30f64.to_radians().tan();
    let rings = [(r0, 0.0), (r1, zc), (r1, top)];
    let mut m = MeshFile::default();
    let at = |r: f64, z: f64, k: usize| {
        let a = TAU * k as f64 / HOPPER_SEGMENTS as f64;
        Vector3::new(r * a.cos(), r * a.sin(), z)
    };
    for w in rings.windows(2) {
        let ((ra, za), (rb, zb)) = (w[0], w[1]);
        for k in 0..HOPPER_SEGMENTS {
            let (a, b) = (at(ra, za, k), at(ra, za, k + 1));
            let (c, d) = (at(rb, zb, k + 1), at(rb, zb, k));
            // (d − a) × (c − a): up-the-wall × around = towards the axis.
            tri(&mut m, [a, d, c]);
            tri(&mut m, [a, c, b]);
        }
    }
    m
}

/// Square of side 1 m in z = 0 centred at the origin, normal +z.
fn plane() -> MeshFile {
    let mut m = MeshFile::default();
    quad(&mut m, [-0.5, -0.5, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
    m
}

#[test]
#[ignore = "writes meshes/walls/*.stl; run by hand to regenerate them"]
fn regenerate_wall_meshes() {
    let dir = repo_root().join("meshes/walls");
    std::fs::create_dir_all(&dir).unwrap();
    box_open_top()
        .write_stl(&dir.join("box_open_top.stl"))
        .unwrap();
    open_box(0.2)
        .write_stl(&dir.join("box_open_top_tall.stl"))
        .unwrap();
    hopper().write_stl(&dir.join("hopper.stl")).unwrap();
    plane().write_stl(&dir.join("plane.stl")).unwrap();
}

/// `polydem check` warns only past the contact law's safe step: the example scenes at
/// `dt_fraction = 0.05` of a face contact time get no warning (0.05 × t could round one ulp
/// above t/20 and did), the same scene at 0.06 gets one naming the restitution band.
#[test]
fn check_warns_only_past_the_safe_face_step() {
    let root = repo_root();
    for name in [
        "launch/quickstart/quickstart.toml",
        "launch/examples/pour_box.toml",
    ] {
        let path = root.join(name);
        let report = polydem::run::check(&path).unwrap();
        let fraction = report["contact_time"]["dt_fraction_of_shortest"]
            .as_f64()
            .unwrap();
        assert!(
            report.get("warnings").is_none(),
            "{name}: dt fraction {fraction}: {report}"
        );
        let text = std::fs::read_to_string(&path)
            .unwrap()
            .replace("dt_fraction = 0.05", "dt_fraction = 0.06");
        let dir = std::env::temp_dir().join("polydem-check-test");
        std::fs::create_dir_all(&dir).unwrap();
        let copy = dir.join(path.file_name().unwrap());
        // Relative paths in the scene resolve from its folder: keep the copy beside the original.
        let copy = if text.contains("../") {
            path.with_file_name(format!(
                "check-test-{}",
                path.file_name().unwrap().to_string_lossy()
            ))
        } else {
            copy
        };
        std::fs::write(&copy, &text).unwrap();
        let report = polydem::run::check(&copy);
        let _ = std::fs::remove_file(&copy);
        let report = report.unwrap();
        let fraction_06 = report["contact_time"]["dt_fraction_of_shortest"]
            .as_f64()
            .unwrap();
        if fraction_06 > 0.05 {
            let warnings = report["warnings"].to_string();
            assert!(warnings.contains("restitution"), "{name}: {report}");
        }
        println!("{name}: dt fraction {fraction} at 0.05, {fraction_06} at 0.06");
    }
}

/// `hybrid_skin` below the skin is refused, naming both; a valid pair and the mode are read.
#[test]
fn the_hybrid_skin_is_at_least_the_skin() {
    let text = replace(
        "seed = 11\n",
        "seed = 11\n[simulation.neighbor]\nskin = 0.002\nhybrid_skin = 0.001\n",
    );
    let msg = error_naming(&text, "simulation.neighbor.hybrid_skin");
    assert!(msg.contains("at least simulation.neighbor.skin"), "{msg}");
    let text = replace(
        "seed = 11\n",
        "seed = 11\n[simulation.neighbor]\nskin = 0.002\nhybrid_skin = 0.005\nmode = \"hybrid\"\n",
    );
    let s = parse(&text).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.simulation.neighbor.hybrid_skin, 0.005);
    assert_eq!(
        s.simulation.neighbor.mode,
        polydem::scene::NeighborMode::Hybrid
    );
}

/// Every shipped scene runs at a step it trusts: `polydem check` (and `polydem run`) gives no
/// time-step warning for the scenes of `launch/` users run — the examples, the quickstart, the
/// production cases and their twins, the benchmarks (lattices, settled and packing scenes), the
/// validation and neighbour scenes. A scene past 0.05 of its face-to-face contact time fails
/// here with `check`'s own message (the shaker once ran at 4.2 times that time). Not listed:
/// `launch/mpi/`, the decomposition tests' fixtures, which compare rank counts bit for bit at
/// a coarse fixed step (0.12–1.0 of their contact times) and warn when run. The examples, the
/// quickstart and the benchmarks also take at most the default `dt_fraction` (0.025): at 0.05 an
/// elastic face impact gains up to 2.8e-3 of its energy with the secant face window
/// (docs/accuracy.md). So does production case 1 (`dodecahedra_cylinder*.toml`), whose pours
/// were rerun at the default; cases 2–5 still run at 0.05 with the secant, as their results
/// were made, until their observables are rerun at the default (docs/production.md), and the
/// packing scenes of `launch/bench/packings/` at the step that made the committed packings.
#[test]
fn no_shipped_scene_warns_about_its_time_step() {
    let root = repo_root().join("launch");
    let mut checked = 0;
    let mut warned = Vec::new();
    let mut coarse = Vec::new();
    for sub in [
        "examples",
        "quickstart",
        "production",
        "production/twins",
        "bench",
        "bench/settled",
        "bench/packings",
        "validation",
        "neighbor",
    ] {
        let mut files: Vec<_> = std::fs::read_dir(root.join(sub))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        files.sort();
        for f in files {
            // The step depends on the materials, shapes and domain only: a scene is checked
            // without what other runs or scripts make (the state another production run
            // leaves, `state = "out/…"`; walls meshed by `make_meshes.py`).
            let mut text = String::new();
            let mut in_walls = false;
            for l in std::fs::read_to_string(&f).unwrap().lines() {
                let t = l.trim_start();
                if t.starts_with('[') {
                    in_walls = t.starts_with("[[walls]]") || t.starts_with("[walls");
                }
                if !in_walls && !t.starts_with("state = \"out/") {
                    text.push_str(l);
                    text.push('\n');
                }
            }
            let name = f.file_name().unwrap().to_string_lossy().to_string();
            let scene =
                parse_scene(&text, f.parent().unwrap(), &name).unwrap_or_else(|e| panic!("{e}"));
            for w in polydem::run::time_step_warnings(&scene) {
                warned.push(format!("{}: {w}", f.display()));
            }
            // What users run as it ships takes the default fraction of the critical step or a
            // finer one (the largest at which `polydem bench accuracy` holds, docs/accuracy.md),
            // or an explicit step that `check` accepts.
            let rerun = sub == "production" && name.starts_with("dodecahedra_cylinder");
            if (rerun || ["examples", "quickstart", "bench", "bench/settled"].contains(&sub))
                && let TimeStep::FractionOfCritical(k) = scene.simulation.dt
                && k > DEFAULT_DT_FRACTION
            {
                coarse.push(format!("{}: dt_fraction {k}", f.display()));
            }
            checked += 1;
        }
    }
    assert!(checked >= 50, "only {checked} scenes found");
    assert!(warned.is_empty(), "{}", warned.join("\n"));
    assert!(
        coarse.is_empty(),
        "above the default dt_fraction {DEFAULT_DT_FRACTION}:\n{}",
        coarse.join("\n")
    );
}
