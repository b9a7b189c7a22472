//! Rolling friction (`[[material_pairs]] rolling_friction`, docs/contact.md §5) against the
//! rigid-body closed form of a sphere rolling without slip on a plane under a rolling couple
//! `M = μ_r R F_n`: with `I = (2/5) m R²` the centre decelerates at
//! `a = g (μ_r cos θ − sin θ) / (1 + I/(m R²)) = (5/7) g (μ_r cos θ − sin θ)` down a slope of
//! angle θ (θ = 0 on the level), so a sphere rolling at `v₀` stops after `v₀²/(2a)` where `a >
//! 0` (tan θ < μ_r) and accelerates at `−a` from rest where tan θ > μ_r. Also: the key's
//! refusals and the restart fingerprint of scenes that do not set it. The CUDA backend's couple
//! is the CPU's bit for bit (`tests/cuda_geometry_host.rs` on the host, `tests/gpu_pipeline.rs`
//! on a GPU).

mod common;

use common::*;
use nalgebra::{UnitQuaternion, Vector3};
use polydem::pipeline::Simulation;
use polydem::scene::parse_scene;

const RADIUS: f64 = 0.005;
const DENSITY: f64 = 2500.0;
const G: f64 = 9.81;

/// The scene of a sphere of radius [`RADIUS`] (E = 10 MPa, e = 0.5, μ = 0.5) on the floor
/// plane at the default step, with `rolling_friction = rolling` (as written in TOML).
fn ball_scene(rolling: &str) -> String {
    let types = format!(
        "[[particle_types]]\nname = \"ball\"\nmaterial = \"m\"\n\
         generator = {{ kind = \"sphere\", size = {:e} }}\n",
        2.0 * RADIUS
    );
    scene_text(&SceneSpec {
        e_modulus: 1e7,
        poisson: 0.3,
        density: DENSITY,
        restitution: 0.5,
        friction: 0.5,
        gravity: -G,
        dt: 1.0,
        wall_scale: Some(1.0),
        wall_motion: None,
        types: &types,
    })
    .replace("dt = 1e0\n", "")
    .replace(
        "friction = 0.5\n",
        &format!("friction = 0.5\nrolling_friction = {rolling}\n"),
    )
}

/// [`ball_scene`] with rolling friction `mu_r`, gravity tilted by `slope` about y (down the
/// slope is +x), the sphere at rest on the floor after 0.05 s of settling.
fn resting_sphere(mu_r: f64, slope: f64) -> Simulation {
    let text = ball_scene(&format!("{mu_r:e}")).replacen(
        &format!("gravity = [0.0, 0.0, {:e}]", -G),
        &format!(
            "gravity = [{:e}, 0.0, {:e}]",
            G * slope.sin(),
            -G * slope.cos()
        ),
        1,
    );
    assert!(text.contains("rolling_friction") && text.contains("gravity = ["));
    let scene = parse_scene(&text, &repo_root(), "rolling.toml").unwrap();
    let mut sim = Simulation::builder(scene).build().unwrap();
    let t = sim.state.scene.templates[0].clone();
    let centre = Vector3::new(0.0, 0.0, RADIUS);
    sim.state
        .particles
        .push(0, 0, 1.0, centre, UnitQuaternion::identity(), &t, DENSITY);
    sim.refresh().unwrap();
    // Settle on the floor for 0.05 s (on a slope steeper than μ_r it rolls meanwhile), then
    // start from rest.
    let settle = (0.05 / sim.state.dt).ceil() as usize;
    for _ in 0..settle {
        sim.step().unwrap();
    }
    sim.state.particles.velocity[0] = Vector3::zeros();
    sim.state.particles.angular_velocity[0] = Vector3::zeros();
    sim
}

/// Sets the sphere rolling without slip at `v0` along +x.
fn roll(sim: &mut Simulation, v0: f64) {
    sim.state.particles.velocity[0] = Vector3::new(v0, 0.0, 0.0);
    sim.state.particles.angular_velocity[0] = Vector3::new(0.0, v0 / RADIUS, 0.0);
}

/// On the level and on a slope gentler than μ_r, a sphere rolling at 0.2 m/s stops where the
/// closed form says, to 0.2 % of the distance, and stays.
#[test]
fn a_rolling_sphere_stops_where_the_rolling_couple_says() {
    let mu_r = 0.1;
    for slope in [0.0, (0.05f64).atan()] {
        let mut sim = resting_sphere(mu_r, slope);
        let v0 = 0.2;
        roll(&mut sim, v0);
        let x0 = sim.state.particles.position[0].x;
        let a = 5.0 / 7.0 * G * (mu_r * slope.cos() - slope.sin());
        let distance = v0 * v0 / (2.0 * a);
        let stop_time = v0 / a;
        // Past the closed form's stop by a fifth of its time: the sphere must be at rest.
        let steps = (1.2 * stop_time / sim.state.dt).ceil() as usize;
        let mut x_max = x0;
        for _ in 0..steps {
            sim.step().unwrap();
            x_max = x_max.max(sim.state.particles.position[0].x);
        }
        let p = &sim.state.particles;
        let travelled = p.position[0].x - x0;
        println!(
            "slope {:.4} rad: travelled {travelled:.6} m (closed form {distance:.6}), furthest \
             {:.6} m, now {:.2e} m/s",
            slope,
            x_max - x0,
            p.velocity[0].norm()
        );
        assert!(
            (travelled - distance).abs() <= 2e-3 * distance,
            "slope {slope}: travelled {travelled} m, closed form {distance} m"
        );
        assert!(
            x_max - p.position[0].x <= 1e-3 * distance,
            "slope {slope}: rolled back by {} m",
            x_max - p.position[0].x
        );
        assert!(
            p.velocity[0].norm() <= 1e-3 * v0,
            "slope {slope}: still moving at {} m/s",
            p.velocity[0].norm()
        );
    }
}

/// On a slope steeper than μ_r a sphere released at rest rolls down at the closed form's
/// acceleration, `(5/7) g (sin θ − μ_r cos θ)`, to 0.2 % after 0.1 s, and without rolling
/// friction at `(5/7) g sin θ`.
#[test]
fn on_a_slope_steeper_than_mu_r_a_sphere_rolls_at_the_closed_form() {
    let slope = (0.2f64).atan();
    for mu_r in [0.0, 0.1] {
        let mut sim = resting_sphere(mu_r, slope);
        let time = 0.1;
        let steps = (time / sim.state.dt).round() as usize;
        let elapsed = steps as f64 * sim.state.dt;
        for _ in 0..steps {
            sim.step().unwrap();
        }
        let p = &sim.state.particles;
        let expected = 5.0 / 7.0 * G * (slope.sin() - mu_r * slope.cos()) * elapsed;
        let v = p.velocity[0].x;
        // Rolling without slip: the contact point at rest.
        let slip = v - p.angular_velocity[0].y * RADIUS;
        println!("μ_r {mu_r}: v = {v:.6} m/s (closed form {expected:.6}), slip {slip:.2e}");
        assert!(
            (v - expected).abs() <= 2e-3 * expected,
            "μ_r {mu_r}: {v} m/s after {elapsed} s, closed form {expected}"
        );
        assert!(slip.abs() <= 0.01 * v, "μ_r {mu_r}: slips at {slip} m/s");
    }
}

/// A negative or non-finite coefficient is refused with its key; a valid one reaches the pair
/// table and compiles the CUDA kernels' couple in (`PD_ROLLING_FRICTION`).
#[test]
fn rolling_friction_is_checked() {
    let text = ball_scene;
    for bad in ["-0.1", "nan", "inf"] {
        let e = parse_scene(&text(bad), &repo_root(), "rolling.toml").unwrap_err();
        let msg = format!("{e:#}");
        assert!(
            msg.contains("material_pairs[0].rolling_friction") && msg.contains("≥ 0"),
            "{bad}: {msg}"
        );
    }
    let scene = parse_scene(&text("0.1"), &repo_root(), "rolling.toml").unwrap();
    assert_eq!(scene.pairs.get(0, 0).rolling_friction, 0.1);
    assert!(scene.pairs.any_rolling_friction());
    let zero = parse_scene(&text("0.0"), &repo_root(), "rolling.toml").unwrap();
    assert!(!zero.pairs.any_rolling_friction());
    // The CUDA kernels compile the couple in for the first scene only.
    use polydem::backend::cuda::KernelConfig;
    for (scene, flag) in [(&scene, "1"), (&zero, "0")] {
        for precision in [polydem::Precision::Double, polydem::Precision::Mixed] {
            let defines = KernelConfig::for_scene(scene, precision).defines();
            let want = format!("-DPD_ROLLING_FRICTION={flag}");
            assert!(defines.contains(&want), "{want} not in {defines:?}");
        }
    }
}

/// A scene that does not set the key prints its pair table as before the key existed, so the
/// restart fingerprint of its checkpoints (which prints the table) is unchanged; one that sets
/// it prints it.
#[test]
fn the_pair_table_prints_as_before_unless_rolling_friction_is_set() {
    let p = polydem::state::PairParameters {
        restitution: 0.5,
        friction: 0.8,
        rolling_friction: 0.0,
    };
    assert_eq!(
        format!("{p:?}"),
        "PairParameters { restitution: 0.5, friction: 0.8 }"
    );
    let q = polydem::state::PairParameters {
        rolling_friction: 0.05,
        ..p
    };
    assert_eq!(
        format!("{q:?}"),
        "PairParameters { restitution: 0.5, friction: 0.8, rolling_friction: 0.05 }"
    );
}
