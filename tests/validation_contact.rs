//! Validation cases 3–5 on the CPU: energy conservation of elastic frictionless collisions and
//! its dt² convergence, restitution for vertex, edge and face impacts, and a polyhedron at rest
//! on a plane. Each test states its tolerance. The same tests run on the GPU (double and mixed
//! pair geometry) in the `*_on_gpu_*` variants, with the same tolerances.

mod common;

use common::*;
use nalgebra::{UnitQuaternion, Vector3};
use polydem::backend::{Device, Engine};
use polydem::contact::FaceWindow;
use polydem::geometry::pair::Precision;
use polydem::pipeline::Simulation;
use polydem::scene::parse_scene;
use std::f64::consts::FRAC_PI_4;

const E: f64 = 1e7;
const RHO: f64 = 2500.0;

/// A simulation with one material (e, μ), gravity g (along −z), time step dt, the unit plane
/// (scaled ×0.5) as floor when `floor`, and one particle type `generator`.
fn simulation(e: f64, mu: f64, g: f64, dt: f64, floor: bool, generator: &str) -> Simulation {
    let types = format!(
        "[[particle_types]]\nname = \"p\"\nmaterial = \"m\"\ngenerator = {generator}\nscale = 1.0\n"
    );
    let text = scene_text(&SceneSpec {
        e_modulus: E,
        poisson: 0.3,
        density: RHO,
        restitution: e,
        friction: mu,
        gravity: -g,
        dt,
        wall_scale: floor.then_some(0.5),
        wall_motion: None,
        types: &types,
    });
    let scene = parse_scene(&text, &repo_root(), "validation.toml").unwrap();
    Simulation::builder(scene).build().unwrap()
}

fn add(
    sim: &mut Simulation,
    id: u64,
    x: Vector3<f64>,
    q: UnitQuaternion<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
) {
    let t = sim.state.scene.templates[0].clone();
    let i = sim.state.particles.len();
    sim.state.particles.push(id, 0, 1.0, x, q, &t, RHO);
    sim.state.particles.velocity[i] = v;
    sim.state.particles.angular_velocity[i] = w;
}

fn in_contact(e: &mut Engine) -> bool {
    let (pairs, walls) = e.contact_counts().unwrap();
    pairs + walls > 0
}

/// Steps `e` until a contact has begun and ended; returns the steps in contact.
fn impact(e: &mut Engine) -> u64 {
    let (mut touched, mut contact_steps) = (false, 0);
    for _ in 0..2_000_000 {
        e.step().unwrap();
        if in_contact(e) {
            touched = true;
            contact_steps += 1;
        } else if touched {
            break;
        }
    }
    assert!(touched, "no collision");
    contact_steps
}

/// Runs until a contact has begun and ended on `device`; returns (steps in contact, relative
/// energy change).
fn collide(mut sim: Simulation, device: Device) -> (u64, f64) {
    sim.refresh().unwrap();
    let e0 = sim.state.total_energy();
    let mut e = engine(sim, device);
    let contact_steps = impact(&mut e);
    (
        contact_steps,
        (e.synced().unwrap().total_energy() - e0).abs() / e0,
    )
}

/// Two spinning dodecahedra (circumscribed diameter 2 cm) collide off-centre, and one spins
/// onto the floor; e = 1, μ = 0. At dt = t_c/50 the relative energy error after the collision
/// must be below 1e-4, and halving dt must reduce it at least fourfold (second order, observed
/// over dt = t_c/50 … t_c/200).
#[test]
fn elastic_collisions_conserve_energy_to_second_order() {
    elastic_collisions(CPU);
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn elastic_collisions_on_gpu_double() {
    elastic_collisions(GPU_DOUBLE);
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn elastic_collisions_on_gpu_mixed() {
    elastic_collisions(GPU_MIXED);
}

/// The same in the CPU twin of mixed precision: the f32 pair geometry's floor, on CI.
#[test]
fn elastic_collisions_in_the_cpu_twin_of_mixed_precision() {
    elastic_collisions(CPU_MIXED);
}

fn elastic_collisions(device: Device) {
    let dodeca = "{ kind = \"dodecahedron\", size = 0.02 }";
    let q1 = UnitQuaternion::from_euler_angles(0.3, 1.1, -0.4);
    let q2 = UnitQuaternion::from_euler_angles(-0.9, 0.2, 2.0);
    let pair = |dt: f64| {
        let mut s = simulation(1.0, 0.0, 0.0, dt, false, dodeca);
        add(
            &mut s,
            1,
            Vector3::new(-0.0105, 0.002, 0.0),
            q1,
            Vector3::new(0.3, 0.0, 0.0),
            Vector3::new(5.0, -20.0, 30.0),
        );
        add(
            &mut s,
            2,
            Vector3::new(0.0105, -0.002, 0.001),
            q2,
            Vector3::new(-0.3, 0.0, 0.0),
            Vector3::new(-40.0, 10.0, 3.0),
        );
        s
    };
    let wall = |dt: f64| {
        let mut s = simulation(1.0, 0.0, 0.0, dt, true, dodeca);
        add(
            &mut s,
            1,
            Vector3::new(0.0, 0.0, 0.0102),
            q1,
            Vector3::new(0.1, 0.0, -0.4),
            Vector3::new(20.0, 35.0, -10.0),
        );
        s
    };
    for (name, build) in [
        ("particle-particle", &pair as &dyn Fn(f64) -> Simulation),
        ("particle-wall", &wall),
    ] {
        // Contact duration from a fine run (on the CPU: it only sets the time steps).
        let fine_dt = 2e-7;
        let (steps, _) = collide(build(fine_dt), CPU);
        let tc = steps as f64 * fine_dt;
        let errors: Vec<f64> = [50.0, 100.0, 200.0]
            .iter()
            .map(|n| collide(build(tc / n), device).1)
            .collect();
        let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        println!(
            "{device:?} {name}: t_c = {tc:.3e} s; relative energy error at t_c/50, /100, /200: {errors:?}; observed orders {orders:.2?}"
        );
        assert!(
            errors[0] < 1e-4,
            "{name}: energy error {:e} at dt = t_c/50",
            errors[0]
        );
        // Velocity Verlet with the symmetric rotation splitting is second order; over a whole
        // collision the error often converges faster still, so the check is that it is at
        // least second order. In mixed mode the pair geometry's f32 rounding (relative 1e-7 on
        // V and S per step, docs/validation.md §8) leaves an energy floor of about 1e-7: a
        // halving whose errors are both below it says nothing about the order.
        let floor = if device.pair_precision() == Precision::Mixed {
            1e-7
        } else {
            0.0
        };
        for (o, w) in orders.iter().zip(errors.windows(2)) {
            if w[0] < floor && w[1] < floor {
                continue;
            }
            assert!(
                *o > 1.8,
                "{name}: convergence order {o:.2} (errors {errors:?})"
            );
        }
    }
}

/// A 1 cm cube hits the floor (particle–wall), or a resting cube's top face (particle–particle),
/// at 1 m/s, frictionless, without gravity, with a vertex, an edge or a face first. For
/// e = 0.1, 0.3, 0.5, 0.7, 0.9, 0.95 and 1 (on the GPU 0.1, 0.5, 0.95 and 1), at each of 16
/// phases of first touch within a step, and at Δt = t_c/40, /80, /160, /400 and /800 of each
/// impact (from a step of 0.025 of the contact time, the default, to 1/20 of it),
/// the rebound speed over the impact speed must be the prescribed restitution within 2 %
/// (docs/contact.md §2), each phase on its own, not their mean; and no elastic impact may gain
/// more than 1e-3 of its energy.
#[test]
fn restitution_is_prescribed_at_every_phase_and_step() {
    restitution(CPU, &RESTITUTIONS, &DIVISIONS, 16);
}

/// The GPU runs a subset of the sweep: e = 0.1, 0.5 and 1 at the default step and half of it,
/// 4 phases (each impact some 100 launch-bound steps, 0.3 ms each on an H100; the full sweep is
/// about an hour there). In double precision every impact is asserted bitwise equal to the
/// CPU's, so the CPU's full sweep stands for the GPU's.
#[test]
#[ignore = "needs a CUDA GPU"]
fn restitution_on_gpu_double() {
    restitution(GPU_DOUBLE, &[0.1, 0.5, 1.0], &DIVISIONS[..2], 4);
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn restitution_on_gpu_mixed() {
    restitution(GPU_MIXED, &[0.1, 0.5, 1.0], &DIVISIONS[..2], 4);
}

/// The GPU's subset of the sweep in the CPU twin of mixed precision (on CI): face impacts
/// resolved in f32, the thin slabs of a face first touching a face in f64.
#[test]
fn restitution_in_the_cpu_twin_of_mixed_precision() {
    restitution(CPU_MIXED, &[0.1, 0.5, 0.95, 1.0], &DIVISIONS, 16);
}

/// `simulation.face_window = "trajectory"` (docs/contact.md §1): face-first impacts of the
/// sweep above, at `dt_fraction` 0.05 (t_c/20) as well as at the default and finer, hold the
/// same bounds: e within 2 % at every phase, and no elastic impact gains more than 1e-3 (the
/// secant window gains 2.8e-3 at t_c/20).
#[test]
fn face_impacts_sampled_along_their_trajectory_hold_at_twice_the_default_step() {
    restitution_of(
        CPU,
        FaceWindow::Trajectory,
        &["face"],
        &[0.1, 0.5, 0.9, 1.0],
        &[20.0, 40.0, 80.0, 160.0],
        16,
    );
}

/// The face impacts along their trajectory on the GPU (`PD_FACE_TRAJECTORY`): e = 0.5 and 1
/// at t_c/20 and t_c/40, 4 phases, each impact bitwise the CPU's in double precision.
#[test]
#[ignore = "needs a CUDA GPU"]
fn face_impacts_along_their_trajectory_on_gpu_double() {
    restitution_of(
        GPU_DOUBLE,
        FaceWindow::Trajectory,
        &["face"],
        &[0.5, 1.0],
        &[20.0, 40.0],
        4,
    );
}

/// The e of the restitution sweeps: 0.1 … 0.95, and 1.
const RESTITUTIONS: [f64; 7] = [0.1, 0.3, 0.5, 0.7, 0.9, 0.95, 1.0];

/// The steps of the restitution sweeps, as fractions of each impact's contact time: the default
/// t_c/40 down to 1/20 of it.
const DIVISIONS: [f64; 5] = [40.0, 80.0, 160.0, 400.0, 800.0];

fn restitution(device: Device, restitutions: &[f64], divisions_swept: &[f64], phases: usize) {
    restitution_of(
        device,
        FaceWindow::Secant,
        &["vertex", "edge", "face"],
        restitutions,
        divisions_swept,
        phases,
    );
}

/// The sweep of [`restitution`] for the first-touching features `kinds` (of "vertex", "edge",
/// "face") with the face contacts' force sampled by `window`.
fn restitution_of(
    device: Device,
    window: FaceWindow,
    kinds: &[&str],
    restitutions: &[f64],
    divisions_swept: &[f64],
    phases: usize,
) {
    let cube = "{ kind = \"cuboid\", a = 0.01, b = 0.01, c = 0.01 }";
    // Orientations that put a vertex, an edge or a face straight below the centre.
    let vertex =
        UnitQuaternion::rotation_between(&Vector3::new(1.0, 1.0, 1.0), &-Vector3::z()).unwrap();
    let edge = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), FRAC_PI_4);
    let face = UnitQuaternion::identity();
    let mut failures = Vec::new();
    let mut worst = 0.0f64;
    // `POLYDEM_RESTITUTION_ONLY="pair face"` (say) runs the impacts whose "wall|pair kind"
    // contains it: a long GPU run split across calls.
    let only = std::env::var("POLYDEM_RESTITUTION_ONLY").unwrap_or_default();
    for wall in [true, false] {
        for (name, q, reach) in [
            ("vertex", vertex, 0.005 * 3f64.sqrt()),
            ("edge", edge, 0.005 * 2f64.sqrt()),
            ("face", face, 0.005),
        ] {
            let case = format!("{} {name}", if wall { "wall" } else { "pair" });
            if !case.contains(only.as_str()) || !kinds.contains(&name) {
                continue;
            }
            for &e in restitutions {
                // Particle–wall: the floor at z = 0. Particle–particle: a free cube (face up)
                // centred at z = −0.005, so that its top face is the floor's plane.
                let build_at = |dt: f64, gap: f64| {
                    let mut s = simulation(e, 0.0, 0.0, dt, wall, cube);
                    s.state.scene.simulation.face_window = window;
                    add(
                        &mut s,
                        1,
                        Vector3::new(0.0, 0.0, reach + gap),
                        q,
                        Vector3::new(0.0, 0.0, -1.0),
                        Vector3::zeros(),
                    );
                    if !wall {
                        add(
                            &mut s,
                            2,
                            Vector3::new(0.0, 0.0, -0.005),
                            UnitQuaternion::identity(),
                            Vector3::zeros(),
                            Vector3::zeros(),
                        );
                    }
                    s.refresh().unwrap();
                    s
                };
                let run = |s: Simulation, device: Device| {
                    let mut s = engine(s, device);
                    let steps = impact(&mut s);
                    // By id: a GPU backend sorts its particles.
                    let p = &s.synced().unwrap().particles;
                    let v = |id: u64| p.velocity[p.id.iter().position(|&i| i == id).unwrap()].z;
                    let rebound = if wall { v(1) } else { v(1) - v(2) };
                    (steps, rebound)
                };
                // The contact time from a fine run, on the CPU (it only sets the time step).
                let fine = 5e-8;
                let (steps, _) = run(build_at(fine, 1e-6), CPU);
                let tc = steps as f64 * fine;
                for &divisions in divisions_swept {
                    let dt = tc / divisions;
                    let outs: Vec<f64> = (0..phases)
                        .map(|k| {
                            let at = || build_at(dt, 1e-6 + dt * k as f64 / phases as f64);
                            let rebound = run(at(), device).1;
                            if device == GPU_DOUBLE {
                                let cpu = run(at(), CPU).1;
                                assert!(
                                    rebound == cpu,
                                    "{case}, e {e}, t_c/{divisions}, phase {k}: GPU double \
                                     {rebound:e}, CPU {cpu:e}"
                                );
                            }
                            rebound
                        })
                        .collect();
                    let (lo, hi) = outs
                        .iter()
                        .fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
                    let error = ((lo - e) / e).abs().max(((hi - e) / e).abs());
                    worst = worst.max(error);
                    println!(
                        "{device:?} {window:?} {} {name}, e_in {e}, dt = t_c/{divisions}: e_out {lo:.4} … {hi:.4} (worst {:.2e}; energy {:+.2e} … {:+.2e} of e²; t_c {tc:.3e} s)",
                        if wall { "wall" } else { "pair" },
                        error,
                        lo * lo / (e * e) - 1.0,
                        hi * hi / (e * e) - 1.0,
                    );
                    // Elastic impacts: no single one may gain more than 1e-3 of its energy, in
                    // either precision (mixed precision evaluates the thin slab of a face
                    // impact's first steps in f64, docs/performance.md).
                    let gain = hi * hi - 1.0;
                    if e == 1.0 && gain > 1e-3 {
                        failures.push(format!(
                            "{} {name}, e = 1, t_c/{divisions}: energy gain {gain:.2e}",
                            if wall { "wall" } else { "pair" }
                        ));
                    }
                    if error > 0.02 {
                        failures.push(format!(
                            "{} {name}, e_in {e}, t_c/{divisions}: e_out {lo:.4} … {hi:.4}",
                            if wall { "wall" } else { "pair" }
                        ));
                    }
                }
            }
        }
    }
    println!("{device:?}: worst relative restitution error over every case {worst:.2e}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A polyhedron resting on a face on the floor (a 2 cm cube, a 2 cm dodecahedron), started at
/// the equilibrium overlap with a push of 1 mm/s into the floor, friction 0.5, e = 0.5: after
/// 1e5 steps its kinetic energy is below 1e-12 m g L, the wall carries its weight within 1e-6,
/// and no sideways force or motion has appeared. (A sideways push is not used: with E = 0.1 MPa
/// the tangential spring's period is about a second, longer than the 0.2 s simulated.)
///
/// Resting face contacts are the stiff extreme of the volume law: with V = A δ the force
/// `c A^{4/3} δ^{1/3}` has stiffness `F/(3δ)`, unbounded as δ → 0, and the equilibrium overlap
/// `δ = (m g / (c A))³ / A` is only 6e-16 m for a 2 cm cube with E = 10 MPa. The test uses a very
/// soft material (E = 0.1 MPa, δ ≈ 0.6 nm) so that the equilibrium is resolved in f64 and
/// Δt = 2 µs is below the explicit limit 2 √(3 δ / g); stiffer materials need a smaller Δt for
/// resting faces (`polydem check` reports it).
#[test]
fn a_polyhedron_comes_to_rest_on_a_plane() {
    rest(CPU);
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn rest_on_gpu_double() {
    rest(GPU_DOUBLE);
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn rest_on_gpu_mixed() {
    rest(GPU_MIXED);
}

fn rest(device: Device) {
    let g = 9.81;
    let dt = 2e-6;
    let e_soft = 1e5;
    for (name, generator) in [
        (
            "cube",
            "{ kind = \"cuboid\", a = 0.02, b = 0.02, c = 0.02 }",
        ),
        ("dodecahedron", "{ kind = \"dodecahedron\", size = 0.028 }"),
    ] {
        let types = format!(
            "[[particle_types]]\nname = \"p\"\nmaterial = \"m\"\ngenerator = {generator}\nscale = 1.0\n"
        );
        let text = scene_text(&SceneSpec {
            e_modulus: e_soft,
            poisson: 0.3,
            density: RHO,
            restitution: 0.5,
            friction: 0.5,
            gravity: -g,
            dt,
            wall_scale: Some(0.5),
            wall_motion: None,
            types: &types,
        });
        let mut s = Simulation::builder(parse_scene(&text, &repo_root(), "rest.toml").unwrap())
            .build()
            .unwrap();
        let t = s.state.scene.templates[0].clone();
        // Face 0 down: rotate its normal onto −z.
        let q = UnitQuaternion::rotation_between(&t.faces[0].normal, &-Vector3::z())
            .unwrap_or_else(UnitQuaternion::identity);
        let low = t.faces[0].offset; // distance from the centroid to that face
        let area = {
            let f = &t.faces[0];
            let v: Vec<_> = f
                .vertices
                .iter()
                .map(|&k| t.vertices[k as usize].coords)
                .collect();
            (1..v.len() - 1)
                .map(|k| (v[k] - v[0]).cross(&(v[k + 1] - v[0])).norm() / 2.0)
                .sum::<f64>()
        };
        let m = RHO * t.volume;
        let c = e_soft / t.equivalent_radius;
        let delta = (m * g / (c * area)).powi(3) / area;
        add(
            &mut s,
            1,
            Vector3::new(0.0, 0.0, low - delta),
            q,
            Vector3::new(0.0, 0.0, -1e-3),
            Vector3::zeros(),
        );
        s.refresh().unwrap();
        let mut e = engine(s, device);
        for _ in 0..100_000 {
            e.step().unwrap();
        }
        let s = e.synced().unwrap();
        let l = 2.0 * t.circumscribed_radius;
        let ke = s.particles.kinetic_energy(0);
        let f = s.wall_forces[0];
        println!(
            "{device:?} {name}: δ_eq = {delta:.3e} m; after 1e5 steps KE/(m g L) = {:.3e}, wall force/(m g) = {:?}",
            ke / (m * g * l),
            (f / (m * g)).as_slice()
        );
        assert!(
            ke < 1e-12 * m * g * l,
            "{name}: kinetic energy {:e} m g L",
            ke / (m * g * l)
        );
        // The force on the wall points down (into it) and balances the weight.
        assert!(
            (f.z / (m * g) + 1.0).abs() < 1e-6,
            "{name}: wall force {f:?} vs m g {}",
            m * g
        );
        assert!(
            f.xy().norm() < 1e-6 * m * g,
            "{name}: lateral wall force {f:?}"
        );
    }
}

/// A periodic box of 27 aligned 1 cm cubes (a 3 × 3 × 3 lattice in a 3.5 cm box, just above
/// the least periodic extent `4 r_max`), e = 1, μ = 0, no gravity, random velocities of about
/// 0.5 m/s: the relative change of the total energy over 40 ms (a dense box: 15–20 contacts
/// live at any time, most of them face on face) at Δt = t_c/20, t_c/40 and t_c/80 of a face
/// impact at 1 m/s.
/// The face contact time at 1 m/s between two 1 cm cubes of the material above: m* = m/2,
/// c = 2E/R (R the volume-equivalent radius), A = 1e-4 m².
fn cube_face_contact_time() -> f64 {
    let m = RHO * 1e-6;
    let r = (3.0 * 1e-6 / (4.0 * std::f64::consts::PI)).cbrt();
    polydem::contact::restitution::face_contact_time(0.5 * m, 2.0 * E / r, 1e-4, 1.0)
}

fn aligned_cubes_energy(device: Device, divisions_swept: &[f64]) -> Vec<f64> {
    aligned_cubes_energy_seeded(device, divisions_swept, 7, FaceWindow::default())
}

/// [`aligned_cubes_energy`] with the cubes' random velocities drawn from `velocity_seed`, and
/// the face contacts sampled by `window`.
fn aligned_cubes_energy_seeded(
    device: Device,
    divisions_swept: &[f64],
    velocity_seed: u64,
    window: FaceWindow,
) -> Vec<f64> {
    let side = 0.035;
    let window = window.name();
    let text = format!(
        r#"gravity = [0.0, 0.0, 0.0]
[simulation]
face_window = "{window}"
dt = 1e-6
end_time = 1.0
seed = 1
[domain]
min = [0.0, 0.0, 0.0]
max = [{side}, {side}, {side}]
periodic = [true, true, true]
[[materials]]
name = "m"
youngs_modulus = {E:e}
poisson_ratio = 0.3
density = {RHO:e}
[[material_pairs]]
materials = ["m", "m"]
restitution = 1.0
friction = 0.0
[[particle_types]]
name = "p"
material = "m"
generator = {{ kind = "cuboid", a = 0.01, b = 0.01, c = 0.01 }}
scale = 1.0
[output]
dir = "{}"
"#,
        std::env::temp_dir().join("polydem-validation").display()
    );
    let tc = cube_face_contact_time();
    let mut errors = Vec::new();
    for &divisions in divisions_swept {
        let dt = tc / divisions;
        let scene = parse_scene(
            &text.replace("dt = 1e-6", &format!("dt = {dt:e}")),
            &repo_root(),
            "aligned.toml",
        )
        .unwrap();
        let mut sim = Simulation::builder(scene).build().unwrap();
        let mut rng = polydem::rng::Rng::new(velocity_seed);
        let mut id = 0;
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    let x = Vector3::new(i as f64, j as f64, k as f64) * (side / 3.0)
                        + Vector3::repeat(side / 6.0);
                    let v = Vector3::new(
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                    );
                    add(
                        &mut sim,
                        id,
                        x,
                        UnitQuaternion::identity(),
                        v,
                        Vector3::zeros(),
                    );
                    id += 1;
                }
            }
        }
        sim.refresh().unwrap();
        let e0 = sim.state.total_energy();
        let steps = (0.04 / dt).round() as u64;
        let mut e = engine(sim, device);
        for _ in 0..steps {
            e.step().unwrap();
        }
        let s = e.synced().unwrap();
        errors.push((s.total_energy() - e0) / e0);
        println!(
            "{device:?} aligned cubes (velocities {velocity_seed}), dt = t_c/{divisions}: {} steps, {} contacts at the end, relative energy change {:.3e}",
            steps,
            s.stats.contacts,
            errors.last().unwrap()
        );
    }
    errors
}

/// The energy change must lie within the second-order envelope `|ΔE/E| ≤ K (20 Δt/t_c)²` at
/// every step, t_c/20 … t_c/160, with `K` = 2.5e-3, twice the largest error at t_c/20 over the
/// 8-draw ensemble below (one draw is chaotic: a change of step changes which contacts occur,
/// so its own error need not fall at every halving; docs/validation.md §3). Before the face
/// depth of docs/contact.md §1 took offset faces for faces, this draw left the envelope at
/// t_c/20 (5.1e-3) and t_c/80 (4.6e-4).
#[test]
fn aligned_cubes_in_a_periodic_box_conserve_energy_to_second_order() {
    aligned_cubes(CPU);
}

/// The GPU runs the box at t_c/20 and t_c/40 (184 000 launch-bound steps) and must end with
/// bitwise the CPU's energies there; the CPU's four steps stand for the GPU's.
#[test]
#[ignore = "needs a CUDA GPU"]
fn aligned_cubes_on_gpu_double() {
    let steps = [20.0, 40.0];
    let (gpu, cpu) = (
        aligned_cubes_energy(GPU_DOUBLE, &steps),
        aligned_cubes_energy(CPU, &steps),
    );
    assert!(gpu == cpu, "GPU double {gpu:?}, CPU {cpu:?}");
}

/// Faces on faces throughout, in the CPU twin of mixed precision: the same second order.
#[test]
fn aligned_cubes_in_the_cpu_twin_of_mixed_precision() {
    aligned_cubes(CPU_MIXED);
}

fn aligned_cubes(device: Device) {
    let errors = aligned_cubes_energy(device, &[20.0, 40.0, 80.0, 160.0]);
    let orders: Vec<f64> = errors
        .windows(2)
        .map(|w| (w[0].abs() / w[1].abs()).log2())
        .collect();
    println!("{device:?} aligned cubes: orders {orders:.2?}");
    for (k, e) in errors.iter().enumerate() {
        let envelope = 2.5e-3 / 4f64.powi(k as i32);
        assert!(
            e.abs() <= envelope,
            "t_c/{}: energy change {e:e} outside the second-order envelope {envelope:e} \
             (errors {errors:?})",
            20 << k
        );
    }
}

/// The aligned cubes' box over 8 draws of the random velocities at Δt = t_c/10, /20, /40 and
/// /80 (`dt_fraction` 0.1 … 0.0125). One draw is chaotic: a change of step changes which
/// contacts occur, and its energy error need not fall monotonically (one draw gave 1.94e-3,
/// 1.51e-4, 4.65e-4, 5.35e-5). The error is a sum of per-impact errors whose sign depends on
/// the phase of first touch, each within the face impact's envelope (docs/accuracy.md); over
/// the draws, the mean and the largest |ΔE/E| must fall at every halving of the step, for
/// both face windows. With the secant the mean falls at second order from t_c/20 to t_c/40
/// (observed 2.40) and at order 1.5 or more below (observed 1.79). What holds it there: faces
/// whose first touch is an edge (a slightly tilted face, k = 2 at its first step), which the
/// law windows from their second step without the entry's share; one such contact in draw 7
/// at t_c/80 gains 2.5e-5 of the box's energy in two steps, half that draw's error
/// (docs/validation.md §3). Along the trajectory (the default) the mean is below the
/// secant's at every step (observed 3.9e-4, 5.5e-5, 2.5e-5, 9.4e-6 against 7.1e-4, 2.5e-4,
/// 4.7e-5, 1.4e-5), falls at order 2 or more from t_c/10 to t_c/20 (2.84) and at order 1 or
/// more below (1.12, 1.43), where draw 7, the edge-first contact's, holds the largest error
/// at every step (3.5e-5 at t_c/80).
#[test]
#[ignore = "full validation: make validate"]
fn aligned_cubes_converge_over_an_ensemble_of_boxes() {
    let steps = [10.0, 20.0, 40.0, 80.0];
    let seeds: Vec<u64> = (1..=8).collect();
    // |ΔE/E| of every draw at every step, for one face window.
    let ensemble = |window: FaceWindow| -> (Vec<f64>, Vec<f64>) {
        let runs: Vec<Vec<f64>> = std::thread::scope(|scope| {
            let halves: Vec<_> = seeds
                .chunks(4)
                .map(|chunk| {
                    scope.spawn(move || {
                        chunk
                            .iter()
                            .map(|&seed| aligned_cubes_energy_seeded(CPU, &steps, seed, window))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            halves.into_iter().flat_map(|h| h.join().unwrap()).collect()
        });
        let (mut means, mut maxima) = (Vec::new(), Vec::new());
        for (k, divisions) in steps.iter().enumerate() {
            let errors: Vec<f64> = runs.iter().map(|r| r[k].abs()).collect();
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            let max = errors.iter().copied().fold(0.0, f64::max);
            println!(
                "{window:?}, t_c/{divisions}: mean |ΔE/E| {mean:.3e}, largest {max:.3e} over {} draws",
                errors.len()
            );
            means.push(mean);
            maxima.push(max);
        }
        let order =
            |v: &[f64]| -> Vec<f64> { v.windows(2).map(|w| (w[0] / w[1]).log2()).collect() };
        println!(
            "{window:?} orders: mean {:.2?}, largest {:.2?}",
            order(&means),
            order(&maxima)
        );
        for w in means.windows(2).chain(maxima.windows(2)) {
            assert!(
                w[1] < w[0],
                "{window:?} not monotone: means {means:?}, largest {maxima:?}"
            );
        }
        (means, maxima)
    };
    let (secant, _) = ensemble(FaceWindow::Secant);
    for (k, w) in secant.windows(2).enumerate().skip(1) {
        let order = (w[0] / w[1]).log2();
        let least = if k == 1 { 2.0 } else { 1.5 };
        assert!(
            order >= least,
            "secant: mean order {order:.2} from t_c/{} (means {secant:?})",
            steps[k]
        );
    }
    // Along the trajectory (the default) every step's mean is below the secant's, and it
    // falls at order 2 or more from t_c/10 to t_c/20; below, at order 1 or more, it has reached
    // the floor that bounds the secant there too (the edge-first faces).
    let (trajectory, _) = ensemble(FaceWindow::Trajectory);
    for (k, (t, s)) in trajectory.iter().zip(&secant).enumerate() {
        assert!(t < s, "t_c/{}: trajectory {t:e} ≥ secant {s:e}", steps[k]);
    }
    for (k, w) in trajectory.windows(2).enumerate() {
        let order = (w[0] / w[1]).log2();
        let least = if k == 0 { 2.0 } else { 1.0 };
        assert!(
            order >= least,
            "trajectory: mean order {order:.2} from t_c/{} (means {trajectory:?})",
            steps[k]
        );
    }
}

/// Two 1 cm cubes meeting face to face with the upper one's centre off the lower one's by
/// (2, 1) mm and (4, 2) mm (face overlaps of 8 × 9 and 6 × 8 mm), e = 1, μ = 0, at 1 m/s, over
/// 16 phases of first touch: the overlap is a box whose `S` leans by the penetration over the
/// width, and its depth must be the distance to separation, not the extent along that normal
/// (docs/contact.md §1), for the kick window to open. The energy change of every impact stays
/// below 1e-3 at t_c/20 (`dt_fraction` 0.05) and 2.5e-4 at t_c/40 with the secant window
/// (observed 7.6e-4 and 1.4e-4), and below 2.5e-4 at both along the trajectory (2.2e-4,
/// 1.1e-4); with the extent as depth they changed by up to about 6e-3 and 4e-3.
#[test]
fn faces_meeting_off_centre_keep_their_energy() {
    let cube = "{ kind = \"cuboid\", a = 0.01, b = 0.01, c = 0.01 }";
    let tc = cube_face_contact_time();
    let mut failures = Vec::new();
    for (window, bounds) in [
        (FaceWindow::Secant, [1e-3, 2.5e-4]),
        (FaceWindow::Trajectory, [2.5e-4, 2.5e-4]),
    ] {
        for offset in [0.002, 0.004] {
            let build_at = |dt: f64, gap: f64| {
                let mut s = simulation(1.0, 0.0, 0.0, dt, false, cube);
                s.state.scene.simulation.face_window = window;
                let above = Vector3::new(offset, 0.5 * offset, 0.005 + gap);
                let down = Vector3::new(0.0, 0.0, -1.0);
                let q = UnitQuaternion::identity();
                add(&mut s, 1, above, q, down, Vector3::zeros());
                let below = Vector3::new(0.0, 0.0, -0.005);
                add(&mut s, 2, below, q, Vector3::zeros(), Vector3::zeros());
                s.refresh().unwrap();
                s
            };
            for (divisions, bound) in [20.0, 40.0].into_iter().zip(bounds) {
                let dt = tc / divisions;
                let changes: Vec<f64> = (0..16)
                    .map(|k| {
                        let s = build_at(dt, 1e-6 + dt * k as f64 / 16.0);
                        let e0 = s.state.total_energy();
                        let mut e = engine(s, CPU);
                        impact(&mut e);
                        e.synced().unwrap().total_energy() / e0 - 1.0
                    })
                    .collect();
                let worst = changes.iter().fold(0.0f64, |w, c| w.max(c.abs()));
                println!(
                    "{window:?}, {} mm off, t_c/{divisions}: largest energy change {worst:.2e}",
                    offset * 1e3
                );
                if worst > bound {
                    failures.push(format!(
                        "{window:?}, {} mm off, t_c/{divisions}: {worst:.2e} > {bound:.1e}",
                        offset * 1e3
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
