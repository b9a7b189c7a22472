//! The stability guard (`polydem::stability`, docs/contact.md §7) against closed-form timings,
//! and a body wholly inside another.
//!
//! - Two spheres of negligible stiffness (E = 1 Pa) approach head-on: their centres move as in
//!   free flight, so the step at which the lens's volume first passes the guard's overlap
//!   bound (a tenth of a sphere) is known in closed form; the run stops at exactly that step,
//!   naming both.
//! - A sphere falls from rest under gravity with `max_speed` set: after step n's first half
//!   kick its speed is `g Δt (n − 1/2)`, so the stop step is known in closed form too.
//! - `polydem run` of that scene stops with the error, leaves the last scheduled checkpoint as
//!   it was, and writes the state at the stop beside it.
//! - The default speed bound is 10 × the scene's speed scale, which adds up free fall across
//!   the domain, insertion, wall motion and the placed particles.
//! - A cube wholly inside a larger one (where `S = dV/dx_B` is round-off) is pushed out along
//!   the line of centres with `c V`.

mod common;

use common::*;
use nalgebra::{UnitQuaternion, Vector3};
use polydem::backend::Device;
use polydem::pipeline::Simulation;
use polydem::scene::parse_scene;
use std::path::Path;
use std::process::Command;

/// A scene of one particle type `types` (elastic, frictionless) with the guard table `guard`.
fn guard_scene(types: &str, e_modulus: f64, gravity: f64, dt: f64, guard: &str) -> String {
    let text = scene_text(&SceneSpec {
        e_modulus,
        poisson: 0.3,
        density: 2500.0,
        restitution: 1.0,
        friction: 0.0,
        gravity,
        dt,
        wall_scale: None,
        wall_motion: None,
        types,
    });
    format!("{text}\n[simulation.guard]\n{guard}\n")
}

fn sphere_scene(e_modulus: f64, gravity: f64, dt: f64, guard: &str) -> String {
    let types = "[[particle_types]]\nname = \"ball\"\nmaterial = \"m\"\n\
                 generator = { kind = \"sphere\", size = 0.02 }\n";
    guard_scene(types, e_modulus, gravity, dt, guard)
}

fn place(sim: &mut Simulation, at: &[(Vector3<f64>, Vector3<f64>)]) {
    let t = sim.state.scene.templates[0].clone();
    for (k, (x, v)) in at.iter().enumerate() {
        sim.state
            .particles
            .push(k as u64, 0, 1.0, *x, UnitQuaternion::identity(), &t, 2500.0);
        sim.state.particles.velocity[k] = *v;
    }
    sim.refresh().unwrap();
}

/// Steps until an error; returns (steps done, the error's text).
fn run_to_error(device: Device, sim: Simulation, limit: u64) -> (u64, String) {
    let mut e = engine(sim, device);
    for k in 1..=limit {
        if let Err(err) = e.step() {
            return (k, err.to_string());
        }
    }
    panic!("no stop within {limit} steps");
}

fn deep_overlap(device: Device) {
    let (r, v, dt) = (0.01, 1.0, 1e-4);
    let text = sphere_scene(1.0, 0.0, dt, "max_overlap = 0.1");
    let scene = parse_scene(&text, &repo_root(), "guard.toml").unwrap();
    let mut sim = Simulation::builder(scene).build().unwrap();
    // Centres 2R + gap apart, closing at 2v: after n steps the lens is δ = 2 v Δt n − gap thick
    // (forces of 1 Pa change the velocities by 1e-9 of v over the run, far from a tie), with
    // the volume π (4R + d)(2R − d)²/12, d = 2R − δ.
    let gap = 1.3e-4;
    place(
        &mut sim,
        &[
            (Vector3::new(-(r + gap / 2.0), 0.0, 0.0), Vector3::x() * v),
            (Vector3::new(r + gap / 2.0, 0.0, 0.0), -Vector3::x() * v),
        ],
    );
    let limit = 0.1 * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
    let lens = |delta: f64| {
        let d = 2.0 * r - delta;
        std::f64::consts::PI * (4.0 * r + d) * (2.0 * r - d).powi(2) / 12.0
    };
    let expected = (1..)
        .find(|&n| lens(2.0 * v * dt * n as f64 - gap) > limit)
        .unwrap();
    let (step, msg) = run_to_error(device, sim, 1000);
    println!("deep overlap: stop at step {step} (closed form {expected}): {msg}");
    assert_eq!(step, expected, "{msg}");
    assert!(
        msg.contains(&format!("step {expected}:"))
            && msg.contains("particle 0 is blowing up")
            && msg.contains("particle 1")
            && msg.contains("max_overlap"),
        "{msg}"
    );
    if device != CPU {
        // The device names no partner; the host's f64 evaluation of the same state does,
        // with the lens of that step.
        let x = lens(2.0 * v * dt * expected as f64 - gap) / (limit / 0.1);
        assert!(
            msg.contains(&format!(
                "its deepest contact with a particle of this rank overlaps particle 1 by {x:.3e}"
            )) && !msg.contains("--gpu-precision double to tell"),
            "{msg}"
        );
    }
}

/// The host's f64 overlap of one particle with every other, which the GPU guard's report
/// names: cubes of edge a face to face, overlapping by δ, share a slab of a² δ, δ/a of a
/// cube's volume.
#[test]
fn the_deepest_overlap_of_a_particle_is_found_without_a_list() {
    let a = 0.01;
    let types = format!(
        "[[particle_types]]\nname = \"cube\"\nmaterial = \"m\"\n\
         generator = {{ kind = \"cube\", size = {:?} }}\n",
        a * 3f64.sqrt()
    );
    let text = scene_text(&SceneSpec {
        e_modulus: 1e6,
        poisson: 0.3,
        density: 2500.0,
        restitution: 0.5,
        friction: 0.0,
        gravity: 0.0,
        dt: 1e-5,
        wall_scale: None,
        wall_motion: None,
        types: &types,
    });
    let scene = parse_scene(&text, &repo_root(), "guard.toml").unwrap();
    let mut sim = Simulation::builder(scene).build().unwrap();
    let (d1, d2) = (1e-3, 5e-4);
    place(
        &mut sim,
        &[
            (Vector3::zeros(), Vector3::zeros()),
            (Vector3::new(a - d1, 0.0, 0.0), Vector3::zeros()),
            (Vector3::new(-(a - d2), 0.0, 0.0), Vector3::zeros()),
            (Vector3::new(0.0, 0.0, 3.0 * a), Vector3::zeros()),
        ],
    );
    let found: Vec<_> = (0..4)
        .map(|i| sim.state.deepest_particle_overlap(i))
        .collect();
    println!("{found:?}");
    let near = |f: Option<(u64, f64)>, id: u64, x: f64| {
        f.is_some_and(|(j, y)| j == id && (y - x).abs() <= 1e-9 * x)
    };
    assert!(near(found[0], 1, d1 / a), "{found:?}");
    assert!(near(found[1], 0, d1 / a), "{found:?}");
    assert!(near(found[2], 0, d2 / a), "{found:?}");
    assert_eq!(found[3], None);
}

/// A scene of one particle type, a cube of edge `a`, with the guard table `guard`.
fn cube_scene(a: f64, e_modulus: f64, gravity: f64, dt: f64, guard: &str) -> Simulation {
    let types = format!(
        "[[particle_types]]\nname = \"cube\"\nmaterial = \"m\"\n\
         generator = {{ kind = \"cube\", size = {:?} }}\n",
        a * 3f64.sqrt()
    );
    let text = guard_scene(&types, e_modulus, gravity, dt, guard);
    let scene = parse_scene(&text, &repo_root(), "guard.toml").unwrap();
    Simulation::builder(scene).build().unwrap()
}

/// Two cubes of edge a closing face to face at 2v through a gap, with negligible stiffness
/// (E = 1 Pa): after n steps their faces overlap by δ = 2 v Δt n − gap, a slab of a² δ, δ/a of
/// a cube's volume (the guard measures a particle by the ball of its volume, here a³). With
/// the bound 0.1 the run stops at the first n with δ > a/10, naming the other cube; the face
/// contact's exponent k = 1 does not change the measure.
fn deep_face_overlap(device: Device) {
    let (a, v, dt, gap) = (0.01, 1.0, 1e-4, 1.3e-4);
    let mut sim = cube_scene(a, 1.0, 0.0, dt, "max_overlap = 0.1");
    let half = (a + gap) / 2.0;
    place(
        &mut sim,
        &[
            (Vector3::new(-half, 0.0, 0.0), Vector3::x() * v),
            (Vector3::new(half, 0.0, 0.0), -Vector3::x() * v),
        ],
    );
    let depth = |n: u64| 2.0 * v * dt * n as f64 - gap;
    let expected = (1..).find(|&n| depth(n) > 0.1 * a).unwrap();
    let (step, msg) = run_to_error(device, sim, 1000);
    println!("cubes face to face: stop at step {step} (closed form {expected}): {msg}");
    assert_eq!(step, expected, "{msg}");
    assert!(
        msg.contains(&format!("step {expected}: particle 0 is blowing up"))
            && msg.contains("particle 1")
            && msg.contains("max_overlap"),
        "{msg}"
    );
    if device == CPU {
        // The overlap's own volume, as the error gives it: a² δ to 1e-9.
        let x = depth(expected) / a;
        assert!(msg.contains(&format!("{x:.3}")), "{msg}");
    }
}

/// A cube spinning at ω about a face normal (its inertia is isotropic, so ω stays) while it
/// falls from rest: after step n's first half kick its fastest point moves at
/// `g Δt (n − 1/2) + ω R`, R = a√3/2 its circumscribed radius, so the speed bound stops it at
/// the first n past the bound, with ω counted by the polyhedron's own corner.
fn spinning_speed_bound(device: Device) {
    let (a, g, dt, vmax, w) = (0.01, 9.81, 1e-3, 1.0, 50.0);
    let mut sim = cube_scene(a, 1e7, -g, dt, "max_speed = 1.0");
    place(&mut sim, &[(Vector3::new(0.0, 0.0, 5.0), Vector3::zeros())]);
    sim.state.particles.angular_velocity[0] = Vector3::z() * w;
    let corner = w * a * 3f64.sqrt() / 2.0;
    let expected = (1u64..)
        .find(|&n| g * dt * (n as f64 - 0.5) + corner > vmax)
        .unwrap();
    let (step, msg) = run_to_error(device, sim, 1000);
    println!("spinning cube: stop at step {step} (closed form {expected}): {msg}");
    assert_eq!(step, expected, "{msg}");
    // Without the spin it would fall 44 steps longer: the corner's speed counts.
    assert!(expected + 40 < (vmax / (g * dt) + 0.5).ceil() as u64);
    assert!(
        msg.contains(&format!("step {expected}: particle 0 is blowing up"))
            && msg.contains("above the bound 1.0000e0 m/s"),
        "{msg}"
    );
}

#[test]
fn a_deep_face_overlap_of_cubes_stops_the_run_at_the_step_it_happens() {
    deep_face_overlap(CPU);
}

#[test]
fn a_spinning_cube_past_the_speed_bound_stops_the_run_at_its_step() {
    spinning_speed_bound(CPU);
}

fn speed_bound(device: Device) {
    let (g, dt, vmax) = (9.81, 1e-3, 1.0);
    let text = sphere_scene(1e7, -g, dt, "max_speed = 1.0");
    let scene = parse_scene(&text, &repo_root(), "guard.toml").unwrap();
    let mut sim = Simulation::builder(scene).build().unwrap();
    place(&mut sim, &[(Vector3::new(0.0, 0.0, 5.0), Vector3::zeros())]);
    // |v| after step n's first half kick: g Δt (n − 1/2).
    let expected = (vmax / (g * dt) + 0.5).ceil() as u64;
    let (step, msg) = run_to_error(device, sim, 1000);
    println!("speed bound: stop at step {step} (closed form {expected}): {msg}");
    assert_eq!(step, expected, "{msg}");
    assert!(
        msg.contains("particle 0 is blowing up")
            && msg.contains("above the bound 1.0000e0 m/s")
            && msg.contains("its contacts: none"),
        "{msg}"
    );
}

#[test]
fn a_deep_overlap_stops_the_run_at_the_step_it_happens() {
    deep_overlap(CPU);
}

#[test]
fn a_speed_past_the_bound_stops_the_run_at_the_step_it_happens() {
    speed_bound(CPU);
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn the_guard_stops_gpu_runs_at_the_same_steps() {
    for device in [GPU_DOUBLE, GPU_MIXED] {
        deep_overlap(device);
        speed_bound(device);
        deep_face_overlap(device);
        spinning_speed_bound(device);
    }
}

#[test]
fn the_default_speed_bound_is_ten_times_the_scene_speed_scale() {
    // Domain ±10 m: free fall across its diagonal √(2 g √1200); a turning wall adds ω r_max.
    let text = sphere_scene(1e7, -9.81, 1e-4, "enabled = true");
    let scene = parse_scene(&text, &repo_root(), "guard.toml").unwrap();
    let mut sim = Simulation::builder(scene).build().unwrap();
    let fall = (2.0 * 9.81 * 1200f64.sqrt()).sqrt();
    assert!((sim.state.guard.speed_scale - fall).abs() <= 1e-12 * fall);
    assert!((sim.state.guard.max_speed - 10.0 * fall).abs() <= 1e-12 * fall);
    // A placed particle's speed counts, the spin with its circumscribed radius.
    place(&mut sim, &[(Vector3::zeros(), Vector3::new(3.0, 0.0, 4.0))]);
    sim.state.particles.angular_velocity[0] = Vector3::new(0.0, 0.0, 100.0);
    sim.refresh().unwrap();
    let expected = fall + 5.0 + 100.0 * 0.01;
    assert!(
        (sim.state.guard.speed_scale - expected).abs() <= 1e-12 * expected,
        "{} vs {expected}",
        sim.state.guard.speed_scale
    );
    // With the guard off nothing is bounded.
    let text = sphere_scene(1e7, -9.81, 1e-4, "enabled = false");
    let sim = Simulation::builder(parse_scene(&text, &repo_root(), "guard.toml").unwrap())
        .build()
        .unwrap();
    assert!(sim.state.guard.max_speed.is_infinite() && sim.state.guard.max_overlap.is_infinite());
    // Bad values are refused with the key.
    let text = sphere_scene(1e7, -9.81, 1e-4, "max_overlap = -1.0");
    let err = parse_scene(&text, &repo_root(), "guard.toml").unwrap_err();
    assert_eq!(err.keys(), vec!["simulation.guard.max_overlap"]);
}

fn write_scene(dir: &Path) -> std::path::PathBuf {
    // The falling sphere of `speed_bound` at half its step, with checkpoints every 100 steps.
    let text = sphere_scene(1e7, -9.81, 5e-4, "max_speed = 1.0")
        .replace(
            &format!(
                "dir = \"{}\"",
                std::env::temp_dir().join("polydem-validation").display()
            ),
            "dir = \"out\"\ncheckpoint_interval = 0.05",
        )
        .replace("end_time = 1.0", "end_time = 1.0\n")
        + "[[insertions]]\ntype = \"ball\"\nregion = { kind = \"box\", min = [-0.05, -0.05, 4.9], max = [0.05, 0.05, 5.1] }\ncount = 1\n";
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_stopped_run_keeps_its_checkpoint_and_writes_the_stopped_state() {
    let dir = std::env::temp_dir().join(format!("polydem-guard-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let scene = write_scene(&dir);
    let out = Command::new(polydem_bin())
        .arg("run")
        .arg(&scene)
        .args(["--backend", "cpu"])
        .output()
        .expect("run polydem");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the run must fail: {stderr}");
    // Stop at step 205 (g Δt (n − 1/2) > 1 m/s), after the checkpoints of steps 100 and 200.
    assert!(
        stderr.contains("step 205: particle 0 is blowing up")
            && stderr.contains("unstable-step-205.ckpt"),
        "{stderr}"
    );
    let ck = dir.join("out/checkpoints");
    let latest = polydem::io::read_checkpoint(&ck.join("latest.ckpt")).unwrap();
    assert_eq!(latest.step, 200);
    let stopped = polydem::io::read_checkpoint(&ck.join("unstable-step-205.ckpt")).unwrap();
    assert_eq!(stopped.step, 205);
    assert!(stopped.particles.velocity[0].norm() > 1.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_body_wholly_inside_another_is_pushed_out_along_the_line_of_centres() {
    use nalgebra::Isometry3;
    use polydem::contact::history::ContactState;
    use polydem::contact::{ContactKinematics, ContactParameters, contact_forces};
    use polydem::geometry::pair::{PairWorkspace, overlap_pair};
    use polydem::shape::ConvexTemplate;
    let cube = |edge: f64| {
        let h = edge / 2.0;
        let corners: Vec<nalgebra::Point3<f64>> = (0..8)
            .map(|k| {
                let s = |b: i32| if k >> b & 1 == 1 { h } else { -h };
                nalgebra::Point3::new(s(0), s(1), s(2))
            })
            .collect();
        ConvexTemplate::from_points("cube", &corners).unwrap()
    };
    let (big, small) = (cube(0.04), cube(0.01));
    let mut ws = PairWorkspace::<f64>::default();
    for (offset, direction) in [
        (
            Vector3::new(0.003, -0.002, 0.001),
            Vector3::new(0.003, -0.002, 0.001).normalize(),
        ),
        (Vector3::zeros(), Vector3::z()),
    ] {
        let (xa, xb) = (
            Vector3::new(0.1, 0.2, 0.3),
            Vector3::new(0.1, 0.2, 0.3) + offset,
        );
        let q = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.1);
        let pa = Isometry3::from_parts(xa.into(), q);
        let pb = Isometry3::from_parts(xb.into(), UnitQuaternion::identity());
        let g = overlap_pair(&mut ws, (&big, 1.0, &pa), (&small, 1.0, &pb)).unwrap();
        let o = g.overlap;
        // The whole small cube: V = 1e-6 m³ and S is round-off.
        assert!((o.volume - 1e-6).abs() <= 1e-15, "{}", o.volume);
        assert!(o.dv_dxb.norm() <= 1e-12, "{:?}", o.dv_dxb);
        let c = 1e6 / big.equivalent_radius + 1e6 / small.equivalent_radius;
        let params = ContactParameters {
            normal_stiffness: c,
            tangential_stiffness: 0.0,
            restitution: 1.0,
            friction: 0.0,
            rolling_friction: 0.0,
            damping: 0.0,
            rocking: true,
            face_window: Default::default(),
        };
        let kin = ContactKinematics {
            x_a: xa,
            x_b: xb,
            v_a: Vector3::zeros(),
            v_b: Vector3::zeros(),
            w_a: Vector3::zeros(),
            w_b: Vector3::zeros(),
            effective_mass: 1.0,
            inverse_mass_a: 1.0,
            inverse_mass_b: 1.0,
            q_a: q,
            q_b: UnitQuaternion::identity(),
            inverse_inertia_a: Vector3::repeat(1.0),
            inverse_inertia_b: Vector3::repeat(1.0),
            sphere_radius_a: 0.0,
            sphere_radius_b: 0.0,
            split_a: 1.0,
            split_b: 1.0,
            dashpot_mass: 1.0,
        };
        let f = contact_forces(&params, &o, &kin, &mut ContactState::default(), 1e-5);
        // c V^{1/3} · V^{2/3} = c V, on B away from A.
        let expected = direction * c * o.volume;
        assert!(
            (f.force_b - expected).norm() <= 1e-9 * expected.norm(),
            "{:?} vs {expected:?}",
            f.force_b
        );
    }
}

/// The packing of [`elastic_packing`]: 64 particles of `shape` on a simple cubic lattice of
/// `spacing` in a periodic box, randomly oriented, e = 1, μ = 0.
fn packing_scene(shape: &str, spacing: f64) -> polydem::scene::Scene {
    let side = 4.0 * spacing;
    let generator = generator(shape);
    // `POLYDEM_PACKING_DT_FRACTION` runs the packings at another step than the default.
    let dt_fraction = std::env::var("POLYDEM_PACKING_DT_FRACTION")
        .map(|f| format!("dt_fraction = {f}"))
        .unwrap_or_default();
    let text = format!(
        r#"gravity = [0.0, 0.0, 0.0]
[simulation]
end_time = 1000.0
seed = 3
{dt_fraction}
[domain]
min = [0.0, 0.0, 0.0]
max = [{side}, {side}, {side}]
periodic = [true, true, true]
[[materials]]
name = "m"
youngs_modulus = 1e7
poisson_ratio = 0.3
density = 2500.0
[[material_pairs]]
materials = ["m", "m"]
restitution = 1.0
friction = 0.0
[[particle_types]]
name = "p"
material = "m"
generator = {generator}
[[insertions]]
type = "p"
region = {{ kind = "box", min = [0.0, 0.0, 0.0], max = [{side}, {side}, {side}] }}
count = 64
lattice = [{spacing}, {spacing}, {spacing}]
orientation = "random"
[output]
dir = "{}"
"#,
        std::env::temp_dir().join("polydem-validation").display()
    );
    parse_scene(&text, &repo_root(), "packing.toml").unwrap()
}

/// A dense elastic packing of `shape` (circumscribed diameter 1 cm): 64 particles on a simple
/// cubic lattice in a periodic box, randomly oriented and overlapping, with random velocities
/// of up to 0.5 m/s per axis, e = 1, μ = 0, at the default step. Returns the largest relative
/// energy change over `steps` steps (sampled 20 times); every step passes the stability guard.
fn elastic_packing(device: Device, shape: &str, steps: u64) -> f64 {
    // Lattice spacings that give 30–120 contacts among the 64 particles, with an elastic
    // energy of the order of the kinetic one (spheres: 1 % overlaps).
    let spacing = match shape {
        "tetrahedron" => 0.007,
        "cube" => 0.0085,
        "octahedron" => 0.008,
        "sphere" => 0.0099,
        "cuboid" => 0.0088,
        "prism" => 0.0098,
        "random_hull" => 0.0075,
        _ => 0.009,
    };
    let scene = packing_scene(shape, spacing);
    let mut sim = Simulation::builder(scene).build().unwrap();
    let mut rng = polydem::rng::Rng::new(11);
    for v in sim.state.particles.velocity.iter_mut() {
        *v = Vector3::new(
            rng.uniform() - 0.5,
            rng.uniform() - 0.5,
            rng.uniform() - 0.5,
        );
    }
    sim.refresh().unwrap();
    let e0 = sim.state.total_energy();
    let contacts0 = sim.state.stats.contacts;
    let mut e = engine(sim, device);
    let mut worst = 0.0f64;
    let every = (steps / 20).max(1);
    let clock = std::time::Instant::now();
    for k in 1..=steps {
        e.step()
            .unwrap_or_else(|err| panic!("{shape}, step {k}: {err}"));
        if k % every == 0 {
            let s = e.synced().unwrap();
            worst = worst.max((s.total_energy() - e0).abs() / e0);
        }
    }
    println!(
        "{device:?} {shape}: {contacts0} contacts at the start, {steps} steps in {:.1} s, \
         largest |ΔE|/E {worst:.3e}",
        clock.elapsed().as_secs_f64()
    );
    worst
}

/// Every built-in shape: the regular solids and spheres (`GENERATOR_NAMES`), and one of each
/// parametrised generator (a flat cuboid, a 24-gon catalyst cylinder, a mineral-like random
/// hull).
fn shapes() -> Vec<&'static str> {
    let mut all = polydem::shape::GENERATOR_NAMES.to_vec();
    all.extend(["cuboid", "prism", "random_hull"]);
    all
}

/// The generator of a shape of [`shapes`], about 1 cm across.
fn generator(shape: &str) -> String {
    match shape {
        "cuboid" => "{ kind = \"cuboid\", a = 0.01, b = 0.006, c = 0.004 }".into(),
        "prism" => "{ kind = \"prism\", sides = 24, diameter = 0.008, height = 0.008 }".into(),
        "random_hull" => "{ kind = \"random_hull\", points = 18, size = 0.01, seed = 5, \
                          aspect = [1.0, 0.8, 0.6] }"
            .into(),
        regular => {
            assert!(
                polydem::shape::GENERATOR_NAMES.contains(&regular),
                "{regular}"
            );
            format!("{{ kind = \"{regular}\", size = 0.01 }}")
        }
    }
}

/// The shapes of the long packing runs: `POLYDEM_PACKING_SHAPES` (comma-separated; every
/// built-in shape by default), so that one machine can run them side by side.
fn long_shapes() -> Vec<&'static str> {
    let only = std::env::var("POLYDEM_PACKING_SHAPES").unwrap_or_default();
    let all = shapes();
    let chosen: Vec<&str> = all
        .iter()
        .copied()
        .filter(|s| only.is_empty() || only.split(',').any(|o| o.trim() == *s))
        .collect();
    assert!(
        !chosen.is_empty(),
        "POLYDEM_PACKING_SHAPES={only}: none of {all:?}"
    );
    chosen
}

/// Steps of the long packing runs: `POLYDEM_PACKING_STEPS`, default 1e6.
fn long_steps() -> u64 {
    std::env::var("POLYDEM_PACKING_STEPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000)
}

/// The dense elastic packings of every built-in shape stay finite and within the guard's
/// bounds, and keep their energy to 1 % over 1500 steps (measured at the default step: 3.2e-7 …
/// 3.3e-6 for the polyhedra, 5.1e-4 for spheres).
#[test]
fn dense_elastic_packings_of_every_shape_keep_their_energy() {
    for shape in shapes() {
        let worst = elastic_packing(CPU, shape, 1500);
        assert!(worst <= 0.01, "{shape}: energy changed by {worst:e}");
    }
}

/// The same packings for 1e6 steps each (`POLYDEM_PACKING_STEPS`): about 3 minutes per shape on
/// one CPU core. Measured at the default step: tetrahedra 2.2e-7, cubes 1.3e-7, octahedra
/// 4.0e-7, dodecahedra 9.9e-7, icosahedra 2.2e-6, spheres 3.6e-4. (At twice the step the
/// spheres drift to 0.54: docs/contact.md §8.)
#[test]
#[ignore = "long: 1e6 steps of each shape"]
fn dense_elastic_packings_run_a_million_steps() {
    for shape in long_shapes() {
        let worst = elastic_packing(CPU, shape, long_steps());
        assert!(worst <= 0.01, "{shape}: energy changed by {worst:e}");
    }
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn dense_elastic_packings_run_on_the_gpu() {
    // `POLYDEM_PACKING_PRECISION=double|mixed` runs one of them.
    let only = std::env::var("POLYDEM_PACKING_PRECISION").unwrap_or_default();
    let devices: Vec<Device> = [("double", GPU_DOUBLE), ("mixed", GPU_MIXED)]
        .into_iter()
        .filter(|(name, _)| only.is_empty() || only == *name)
        .map(|(_, d)| d)
        .collect();
    assert!(
        !devices.is_empty(),
        "POLYDEM_PACKING_PRECISION={only}: double or mixed"
    );
    for shape in long_shapes() {
        for &device in &devices {
            let worst = elastic_packing(device, shape, long_steps());
            assert!(
                worst <= 0.01,
                "{shape} {device:?}: energy changed by {worst:e}"
            );
        }
    }
}
