//! Shared test support: repository paths, the test shape set, random poses, and an independent
//! exact oracle for the intersection of convex polytopes.
#![allow(dead_code)]

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use polydem::rng::Rng;
use polydem::shape::{ConvexTemplate, Generator};
use std::path::PathBuf;

/// The repository root: `POLYDEM_ROOT` when set, else the current directory (tests also run on
/// machines where the source tree is not at its original path).
pub fn repo_root() -> PathBuf {
    std::env::var_os("POLYDEM_ROOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::current_dir().expect("current directory"))
}

/// A template with a scale, as particles carry them.
pub struct Shape {
    pub name: &'static str,
    pub template: ConvexTemplate,
}

/// The shapes of the geometry acceptance tests: the seed's cases plus plates, needles and a
/// 1:20 size ratio.
pub fn test_shapes() -> Vec<Shape> {
    let g = |name: &'static str, generator: Generator| Shape {
        name,
        template: generator.build().unwrap(),
    };
    let file = |name: &'static str, f: &str| Shape {
        name,
        template: ConvexTemplate::from_file(&repo_root().join("meshes/particles").join(f))
            .unwrap_or_else(|e| panic!("{e}"))
            .scaled(1000.0) // mm-sized files → unit-ish sizes keep the tolerances readable
            .unwrap(),
    };
    vec![
        g("tetrahedron", Generator::Tetrahedron { size: 1.0 }),
        g("cube", Generator::Cube { size: 1.0 }),
        g("octahedron", Generator::Octahedron { size: 1.0 }),
        g("dodecahedron", Generator::Dodecahedron { size: 1.0 }),
        g("icosahedron", Generator::Icosahedron { size: 1.0 }),
        file("cylinder_42", "cylinder_42.stl"),
        file("catalyst_cylinder", "catalyst_cylinder.stl"),
        file("mineral_grain", "mineral_grain.stl"),
        g(
            "plate",
            Generator::Cuboid {
                a: 1.0,
                b: 0.8,
                c: 0.04,
            },
        ),
        g(
            "needle",
            Generator::Prism {
                sides: 6,
                diameter: 0.05,
                height: 1.0,
            },
        ),
        g("small_dodecahedron", Generator::Dodecahedron { size: 0.05 }),
    ]
}

/// A uniformly random rotation.
pub fn random_rotation(rng: &mut Rng) -> UnitQuaternion<f64> {
    let [w, x, y, z] = rng.unit_quaternion();
    UnitQuaternion::new_normalize(nalgebra::Quaternion::new(w, x, y, z))
}

/// A pose from a position and a rotation.
pub fn pose(p: Vector3<f64>, q: UnitQuaternion<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(p), q)
}

/// World vertices of a posed template.
pub fn world_vertices(t: &ConvexTemplate, pose: &Isometry3<f64>) -> Vec<Vector3<f64>> {
    t.vertices.iter().map(|v| (pose * v).coords).collect()
}

/// World face planes `(n, h)` of a posed template.
pub fn world_planes(t: &ConvexTemplate, pose: &Isometry3<f64>) -> Vec<(Vector3<f64>, f64)> {
    t.faces
        .iter()
        .map(|f| {
            let n = pose.rotation * f.normal;
            (n, f.offset + n.dot(&pose.translation.vector))
        })
        .collect()
}

/// A template as parry3d-f64's convex polyhedron (the independent reference for GJK verdicts and
/// distances).
pub fn parry_hull(t: &ConvexTemplate) -> parry3d_f64::shape::ConvexPolyhedron {
    let pts: Vec<parry3d_f64::math::Vector> = t
        .vertices
        .iter()
        .map(|v| parry3d_f64::math::Vector::new(v.x, v.y, v.z))
        .collect();
    parry3d_f64::shape::ConvexPolyhedron::from_convex_hull(&pts).unwrap()
}

/// A pose as parry3d-f64's.
pub fn parry_pose(iso: &Isometry3<f64>) -> parry3d_f64::math::Pose {
    let t = iso.translation.vector;
    let q = iso.rotation;
    parry3d_f64::math::Pose::from_parts(
        parry3d_f64::math::Vector::new(t.x, t.y, t.z),
        parry3d_f64::math::Rotation::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

/// Exact oracle, independent of the code under test: the vertices of `∩ {n·x <= h}` by brute
/// force over all plane triples, then parry3d-f64's convex hull of those vertices and the volume
/// and centroid of that hull by signed tetrahedra.
pub struct OracleOverlap {
    pub volume: f64,
    pub centroid: Vector3<f64>,
    /// The intersection's vertices, each once.
    pub vertices: Vec<Vector3<f64>>,
}

pub fn oracle_intersection(planes: &[(Vector3<f64>, f64)], scale: f64) -> OracleOverlap {
    let tol = 1e-11 * scale;
    let mut pts: Vec<Vector3<f64>> = Vec::new();
    let m = planes.len();
    for i in 0..m {
        for j in i + 1..m {
            let cij = planes[i].0.cross(&planes[j].0);
            if cij.norm() < 1e-12 {
                continue;
            }
            for k in j + 1..m {
                let det = cij.dot(&planes[k].0);
                if det.abs() < 1e-12 {
                    continue;
                }
                let (ni, nj, nk) = (planes[i].0, planes[j].0, planes[k].0);
                let x =
                    (nj.cross(&nk) * planes[i].1 + nk.cross(&ni) * planes[j].1 + cij * planes[k].1)
                        / det;
                // Vertices where more than three planes meet come out several times; keep one
                // copy so the hull below sees distinct points.
                if planes.iter().all(|(n, h)| n.dot(&x) <= h + tol)
                    && pts.iter().all(|p| (p - x).norm() > 1e-9 * scale)
                {
                    pts.push(x);
                }
            }
        }
    }
    if pts.len() < 4 {
        return OracleOverlap {
            volume: 0.0,
            centroid: Vector3::zeros(),
            vertices: pts,
        };
    }
    // Shift to the mean for a well-conditioned hull and tetrahedra.
    let mean = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    let glam: Vec<parry3d_f64::math::Vector> = pts
        .iter()
        .map(|p| parry3d_f64::math::Vector::new(p.x - mean.x, p.y - mean.y, p.z - mean.z))
        .collect();
    let (hv, ht) = parry3d_f64::transformation::convex_hull(&glam);
    let mut vol = 0.0;
    let mut cen = Vector3::zeros();
    for t in &ht {
        let a = Vector3::new(
            hv[t[0] as usize].x,
            hv[t[0] as usize].y,
            hv[t[0] as usize].z,
        );
        let b = Vector3::new(
            hv[t[1] as usize].x,
            hv[t[1] as usize].y,
            hv[t[1] as usize].z,
        );
        let c = Vector3::new(
            hv[t[2] as usize].x,
            hv[t[2] as usize].y,
            hv[t[2] as usize].z,
        );
        let v = a.dot(&b.cross(&c)) / 6.0;
        vol += v;
        cen += (a + b + c) * (v / 4.0);
    }
    if vol.abs() <= 0.0 {
        return OracleOverlap {
            volume: 0.0,
            centroid: mean,
            vertices: pts,
        };
    }
    OracleOverlap {
        volume: vol.abs(),
        centroid: cen / vol + mean,
        vertices: pts,
    }
}

/// Point `p` placed with an f64 `Point3` convenience.
pub fn p3(x: f64, y: f64, z: f64) -> Point3<f64> {
    Point3::new(x, y, z)
}

/// The `polydem` binary: `POLYDEM_BIN`, else the one cargo built for this test run, else `polydem`
/// on the PATH (GPU machines run tests from a copied tree with the binary on the PATH).
pub fn polydem_bin() -> PathBuf {
    if let Some(p) = std::env::var_os("POLYDEM_BIN") {
        return PathBuf::from(p);
    }
    let built = PathBuf::from(env!("CARGO_BIN_EXE_polydem"));
    if built.exists() {
        built
    } else {
        PathBuf::from("polydem")
    }
}

/// A fresh temporary directory for one test.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("polydem-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Parameters of [`scene_text`]: one material (E, ν, ρ) and its pair with itself (e, μ),
/// gravity along −z, the time step, and optionally the unit square wall `plane.stl` scaled by
/// `wall_scale` at z = 0 facing +z, moving by `wall_motion` (a TOML inline table, e.g.
/// `{ kind = "translate", velocity = [0.1, 0.0, 0.0] }`; `None` is fixed).
pub struct SceneSpec<'a> {
    pub e_modulus: f64,
    pub poisson: f64,
    pub density: f64,
    pub restitution: f64,
    pub friction: f64,
    pub gravity: f64,
    pub dt: f64,
    pub wall_scale: Option<f64>,
    pub wall_motion: Option<&'a str>,
    /// `[[particle_types]]` blocks (TOML).
    pub types: &'a str,
}

/// The TOML text of a scene described by `spec`.
pub fn scene_text(spec: &SceneSpec) -> String {
    let SceneSpec {
        e_modulus,
        poisson,
        density,
        restitution,
        friction,
        gravity,
        dt,
        wall_scale,
        wall_motion,
        types,
    } = *spec;
    let root = repo_root();
    let wall = match wall_scale {
        Some(s) => format!(
            "[[walls]]\nname = \"floor\"\nmesh = \"{}\"\nmaterial = \"m\"\nscale = {s:e}\n{}",
            root.join("meshes/walls/plane.stl").display(),
            wall_motion.map_or(String::new(), |m| format!("motion = {m}\n"))
        ),
        None => String::new(),
    };
    format!(
        r#"gravity = [0.0, 0.0, {gravity:e}]
[simulation]
dt = {dt:e}
end_time = 1.0
seed = 1
[domain]
min = [-10.0, -10.0, -10.0]
max = [10.0, 10.0, 10.0]
[[materials]]
name = "m"
youngs_modulus = {e_modulus:e}
poisson_ratio = {poisson}
density = {density:e}
[[material_pairs]]
materials = ["m", "m"]
restitution = {restitution}
friction = {friction}
{types}
{wall}
[output]
dir = "{}"
"#,
        std::env::temp_dir().join("polydem-validation").display()
    )
}

/// The backends a validation case runs on: the CPU here, GPU 0 (double or mixed pair geometry)
/// in the `*_on_gpu_*` variants, which are `#[ignore]`d without a GPU.
#[allow(dead_code)]
pub const CPU: polydem::backend::Device = polydem::backend::Device::Cpu;
/// The CPU with the GPU's mixed-precision pair geometry (its twin, `--gpu-precision mixed`).
#[allow(dead_code)]
pub const CPU_MIXED: polydem::backend::Device = polydem::backend::Device::CpuMixed;
#[allow(dead_code)]
pub const GPU_DOUBLE: polydem::backend::Device = polydem::backend::Device::Cuda {
    ordinal: 0,
    precision: polydem::Precision::Double,
};
#[allow(dead_code)]
pub const GPU_MIXED: polydem::backend::Device = polydem::backend::Device::Cuda {
    ordinal: 0,
    precision: polydem::Precision::Mixed,
};

/// `start` on GPU 0 in `precision`, made as every backend is, by [`polydem::backend::Engine::new`];
/// [`polydem::backend::Engine::cuda_mut`] gives the GPU's own methods.
#[allow(dead_code)]
pub fn gpu_engine(
    start: impl Into<polydem::backend::Start>,
    precision: polydem::Precision,
) -> polydem::backend::Engine {
    let device = polydem::backend::Device::Cuda {
        ordinal: 0,
        precision,
    };
    polydem::backend::Engine::new(start, device).expect("GPU backend")
}

/// A new single-rank run of `scene` (its particles placed, its first forces evaluated by the
/// backend that steps it).
#[allow(dead_code)]
pub fn scene_start(scene: polydem::scene::Scene) -> polydem::backend::Start {
    polydem::backend::Start::Scene {
        scene: Box::new(scene),
        comm: std::sync::Arc::new(polydem::domain::SerialComm),
    }
}

/// `sim` (its forces evaluated) on `device`.
#[allow(dead_code)]
pub fn engine(
    sim: polydem::pipeline::Simulation,
    device: polydem::backend::Device,
) -> polydem::backend::Engine {
    polydem::backend::Engine::new(sim, device).expect("backend")
}

/// 60 frictional dodecahedra dropped into an open box and onto each other, with a rate insertion
/// still running at the restart point, so that the checkpoint must carry contacts with
/// tangential history, the insertion state and the random state.
pub fn restart_scene(dir: &std::path::Path) -> std::path::PathBuf {
    let root = repo_root();
    let text = format!(
        r#"gravity = [0.0, 0.0, -9.81]
[simulation]
dt = 2e-5
end_time = 10.0
seed = 11
[domain]
min = [-0.06, -0.06, -0.01]
max = [0.06, 0.06, 0.2]
[[materials]]
name = "grain"
youngs_modulus = 1e6
poisson_ratio = 0.3
density = 2500.0
[[materials]]
name = "steel"
youngs_modulus = 2e11
poisson_ratio = 0.3
density = 7800.0
[[material_pairs]]
materials = ["grain", "grain"]
restitution = 0.5
friction = 0.5
[[material_pairs]]
materials = ["grain", "steel"]
restitution = 0.5
friction = 0.4
[[particle_types]]
name = "d"
material = "grain"
generator = {{ kind = "dodecahedron", size = 0.012 }}
scale = {{ distribution = "uniform", min = 0.8, max = 1.2 }}
[[insertions]]
type = "d"
region = {{ kind = "box", min = [-0.04, -0.04, 0.005], max = [0.04, 0.04, 0.05] }}
count = 40
velocity = [0.0, 0.0, -2.0]
[[insertions]]
type = "d"
region = {{ kind = "box", min = [-0.04, -0.04, 0.06], max = [0.04, 0.04, 0.1] }}
rate = 2000.0
total = 20
[[walls]]
name = "box"
mesh = "{}"
material = "steel"
[output]
dir = "out"
frame_interval = 0.002
formats = ["vtu", "csv"]
checkpoint_interval = 0.004
"#,
        root.join("meshes/walls/box_open_top.stl").display()
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `polydem run ARGS`, asserting that it succeeds.
pub fn polydem_run(args: &[&str]) {
    let out = std::process::Command::new(polydem_bin())
        .arg("run")
        .args(args)
        .output()
        .expect("run polydem");
    assert!(
        out.status.success(),
        "polydem run {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// 240 frictional dodecahedra (or spheres: `kind`) dropped at `speed` (m/s) into the open box
/// and onto each other (those placed above the rim fall in), 40 more fed at a rate from above,
/// walls of another material: the dense pour of the GPU parity and neighbour-mode tests.
pub fn dense_pour_text(kind: &str, seed: u64, speed: f64) -> String {
    let root = repo_root();
    format!(
        r#"gravity = [0.0, 0.0, -9.81]
[simulation]
dt = 2e-5
end_time = 10.0
seed = {seed}
[domain]
min = [-0.06, -0.06, -0.01]
max = [0.06, 0.06, 0.25]
[[materials]]
name = "grain"
youngs_modulus = 1e6
poisson_ratio = 0.3
density = 2500.0
[[materials]]
name = "steel"
youngs_modulus = 2e11
poisson_ratio = 0.3
density = 7800.0
[[material_pairs]]
materials = ["grain", "grain"]
restitution = 0.5
friction = 0.5
[[material_pairs]]
materials = ["grain", "steel"]
restitution = 0.5
friction = 0.4
[[particle_types]]
name = "d"
material = "grain"
generator = {{ kind = "{kind}", size = 0.012 }}
scale = {{ distribution = "uniform", min = 0.8, max = 1.2 }}
[[insertions]]
type = "d"
region = {{ kind = "box", min = [-0.042, -0.042, 0.006], max = [0.042, 0.042, 0.2] }}
count = 240
velocity = [0.0, 0.0, -{speed:?}]
[[insertions]]
type = "d"
region = {{ kind = "box", min = [-0.04, -0.04, 0.205], max = [0.04, 0.04, 0.24] }}
rate = 4000.0
total = 40
[[walls]]
name = "box"
mesh = "{}"
material = "steel"
[output]
dir = "out"
"#,
        root.join("meshes/walls/box_open_top.stl").display()
    )
}

/// Two cubes of a poured pile (12 mm generator cubes at scales 0.920 and 1.021, turned) that
/// touch along a sliver thinner than the dual hull resolves in f64 (docs/contact.md §5): the
/// template, then each body's scale and pose, to the last bit as the run reported them.
#[allow(dead_code)]
pub fn pile_touching_pair() -> (ConvexTemplate, [(f64, Isometry3<f64>); 2]) {
    let pose = |x: [f64; 3], q: [f64; 4]| {
        Isometry3::from_parts(
            nalgebra::Translation3::new(x[0], x[1], x[2]),
            UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3])),
        )
    };
    let cube = Generator::parse("cube", 0.012).unwrap().build().unwrap();
    let a = pose(
        [
            -0.028239433889745848,
            0.02731255681625542,
            0.010259968026271934,
        ],
        [
            -0.23037576541399032,
            0.668525998502521,
            0.23037575758723522,
            0.6685259952703657,
        ],
    );
    let b = pose(
        [
            -0.030143005692809508,
            0.029340879739901495,
            0.00353726389911433,
        ],
        [
            0.2874511062246991,
            0.28745110812115565,
            0.6460432342205854,
            0.6460432349989607,
        ],
    );
    (cube, [(0.9195573907383391, a), (1.0211201337892601, b)])
}

/// `launch/mpi/pour.toml` made long (it would end at step 2000, here at 4 s), logging every 100
/// steps, written into `dir` with its meshes referred to the repository: a run to interrupt.
pub fn long_pour(dir: &std::path::Path) -> PathBuf {
    let root = repo_root();
    let text = std::fs::read_to_string(root.join("launch/mpi/pour.toml"))
        .unwrap()
        .replace("end_time = 0.04", "end_time = 4.0")
        .replace("\"../../meshes/", &format!("\"{}/meshes/", root.display()))
        .replace("log_interval_steps = 500", "log_interval_steps = 100");
    assert!(
        text.contains("end_time = 4.0") && text.contains("log_interval_steps = 100"),
        "the pour's end_time and log lines"
    );
    let scene = dir.join("long_pour.toml");
    std::fs::write(&scene, text).unwrap();
    scene
}

/// The committed settled cell of 4000 mineral grains (32 triangles; periodic, no gravity,
/// `launch/bench/packings/mineral_grains.packing`) as a scene: E 1e7, e 0.5, μ 0.5, the default
/// step, one checkpoint at the end of a run stopped by `--max-steps`.
pub fn mineral_cell_text() -> String {
    let root = repo_root();
    let cell = 1.9347371379318832e-2;
    format!(
        "gravity = [0.0, 0.0, 0.0]\n\
         [simulation]\ndt_fraction = 0.025\nend_time = 1.0\nseed = 9\n\
         [output]\ncheckpoint_interval = 1.0\n\
         [domain]\nmin = [0.0, 0.0, 0.0]\nmax = [{cell}, {cell}, {cell}]\n\
         periodic = [true, true, true]\n\
         [[materials]]\nname = \"grain\"\nyoungs_modulus = 1.0e7\npoisson_ratio = 0.3\n\
         density = 2500.0\n\
         [[material_pairs]]\nmaterials = [\"grain\", \"grain\"]\nrestitution = 0.5\n\
         friction = 0.5\n\
         [[particle_types]]\nname = \"mineral_grain\"\nmaterial = \"grain\"\n\
         mesh = \"{}\"\nscale = 1.0\n\
         [[insertions]]\ntype = \"mineral_grain\"\n\
         region = {{ kind = \"box\", min = [0.0, 0.0, 0.0], max = [{cell}, {cell}, {cell}] }}\n\
         count = 4000\npacking = \"{}\"\n",
        root.join("meshes/particles/mineral_grain.stl").display(),
        root.join("launch/bench/packings/mineral_grains.packing")
            .display(),
    )
}
