//! `[[insertions]] state`: another run's checkpoint as a scene's starting particles (a silo
//! filled once, then discharged through several outlets). The particles whose centre lies in
//! the region come back bit for bit; a count, a shape or a key that does not fit is refused
//! with the key named.

mod common;

use common::{polydem_bin, temp_dir};
use polydem::io::read_checkpoint;
use polydem::pipeline::Simulation;
use polydem::scene::{SceneError, parse_scene};
use std::process::Command;

/// Spheres of `size` in a closed box without gravity; one insertion (TOML lines after `type`).
fn scene(size: f64, end: f64, insertion: &str) -> String {
    format!(
        r#"gravity = [0.0, 0.0, 0.0]
[simulation]
dt = 1.0e-6
end_time = {end:?}
seed = 11
[domain]
min = [-0.01, -0.01, -0.01]
max = [0.01, 0.01, 0.01]
[[materials]]
name = "grain"
youngs_modulus = 1.0e7
poisson_ratio = 0.3
density = 2500.0
[[material_pairs]]
materials = ["grain", "grain"]
restitution = 0.5
friction = 0.5
[[particle_types]]
name = "sphere"
material = "grain"
generator = {{ kind = "sphere", size = {size:?} }}
[[insertions]]
type = "sphere"
{insertion}
[output]
dir = "out"
checkpoint_interval = {end:?}
"#
    )
}

#[test]
fn a_checkpoint_s_particles_in_the_region_come_back_as_they_were() {
    let dir = temp_dir("state-insertion");
    // A run of 40 spheres thrown about for 300 steps: positions, turns and speeds of their own.
    let first = dir.join("first.toml");
    std::fs::write(
        &first,
        scene(
            0.002,
            3.0e-4,
            "region = { kind = \"box\", min = [-0.009, -0.009, -0.009], max = [0.009, 0.009, 0.009] }\n\
             count = 40\nvelocity = [0.3, -0.2, 0.1]\nangular_velocity = [5.0, 0.0, -3.0]",
        ),
    )
    .unwrap();
    let out = Command::new(polydem_bin())
        .args(["run", first.to_str().unwrap(), "--backend", "cpu"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ckpt = dir.join("out/checkpoints/step_0000000300.ckpt");
    let c = read_checkpoint(&ckpt).unwrap();
    let p = &c.particles;
    let west: Vec<usize> = (0..p.len()).filter(|&i| p.position[i].x < 0.0).collect();
    assert!(
        !west.is_empty() && west.len() < p.len(),
        "{} of {} west",
        west.len(),
        p.len()
    );
    // The west half into a new scene.
    let region = format!(
        "region = {{ kind = \"box\", min = [-0.01, -0.01, -0.01], max = [0.0, 0.01, 0.01] }}\nstate = \"{}\"",
        ckpt.display()
    );
    let s = parse_scene(
        &scene(0.002, 1.0e-3, &format!("{region}\ncount = {}", west.len())),
        &dir,
        "second.toml",
    )
    .unwrap();
    let state = Simulation::builder(s).state().unwrap();
    let q = &state.particles;
    assert_eq!(q.len(), west.len());
    for (j, &i) in west.iter().enumerate() {
        assert_eq!(q.position[j], p.position[i]);
        assert_eq!(q.orientation[j], p.orientation[i]);
        assert_eq!(q.velocity[j], p.velocity[i]);
        assert_eq!(q.angular_velocity[j], p.angular_velocity[i]);
        assert_eq!(q.scale[j].to_bits(), p.scale[i].to_bits());
        assert_eq!(q.mass[j].to_bits(), p.mass[i].to_bits());
    }
    // Refused: another count, another shape, a key the checkpoint decides.
    let reject = |text: String, key: &str, words: &str| {
        let e: SceneError = match parse_scene(&text, &dir, "bad.toml") {
            Ok(_) => panic!("accepted, want {key} refused"),
            Err(e) => e,
        };
        let msg = e.to_string();
        assert!(
            e.keys().contains(&key) && msg.contains(words),
            "want {key} / {words:?}: {msg}"
        );
    };
    reject(
        scene(
            0.002,
            1.0e-3,
            &format!("{region}\ncount = {}", west.len() + 1),
        ),
        "insertions[0].count",
        &format!("{} of the 40 particles", west.len()),
    );
    reject(
        scene(0.003, 1.0e-3, &format!("{region}\ncount = {}", west.len())),
        "insertions[0].state",
        "another shape or material",
    );
    // A type whose scales do not hold the state's (1.0): the cutoff, halo and critical step
    // are sized from the type's range. A range that holds it is taken.
    let with_scale = |scale: &str| {
        scene(0.002, 1.0e-3, &format!("{region}\ncount = {}", west.len())).replace(
            "size = 0.002 }\n",
            &format!("size = 0.002 }}\nscale = {scale}\n"),
        )
    };
    assert!(with_scale("0.5").contains("scale = 0.5"));
    reject(
        with_scale("0.5"),
        "insertions[0].state",
        "has scale 1e0, outside particle type \"sphere\"'s scales 5e-1 … 5e-1",
    );
    reject(
        with_scale("{ distribution = \"uniform\", min = 1.01, max = 1.2 }"),
        "insertions[0].state",
        "outside particle type \"sphere\"'s scales 1.01e0 … 1.2e0",
    );
    let s = parse_scene(
        &with_scale("{ distribution = \"uniform\", min = 0.9, max = 1.1 }"),
        &dir,
        "ranged.toml",
    )
    .unwrap();
    assert_eq!(
        Simulation::builder(s).state().unwrap().particles.len(),
        west.len()
    );
    reject(
        scene(
            0.002,
            1.0e-3,
            &format!("{region}\ncount = {}\norientation = \"random\"", west.len()),
        ),
        "insertions[0].orientation",
        "not allowed with state",
    );
    reject(
        scene(0.002, 1.0e-3, &format!("{region}\nrate = 10.0"))
            .replace(&ckpt.display().to_string(), "none.ckpt"),
        "insertions[0].state",
        "none.ckpt",
    );
}
