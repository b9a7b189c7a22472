//! The cases that run for a fixed time rather than one impact: energy conservation in a periodic
//! box, the force curve of a cuboid pushed across a coarse and a fine wall mesh, and the pour's
//! packing fraction.

use super::runner::{CaseRunner, Spec};
use crate::backend::{Device, Engine};
use crate::pipeline::Simulation;
use crate::rng::Rng;
use crate::run_state::RunState;
use crate::scene::parse_scene;
use anyhow::{Context, Result};
use nalgebra::{UnitQuaternion, Vector3};

impl CaseRunner {
    pub(super) fn elastic_energy(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let side = 0.035;
        let types = "[[particle_types]]\nname = \"p\"\nmaterial = \"m\"\n\
                     generator = { kind = \"cuboid\", a = 0.01, b = 0.01, c = 0.01 }\nscale = 1.0\n";
        let mut sim = self.simulation(&Spec {
            e_modulus: 1e7,
            poisson: 0.3,
            density: 2500.0,
            restitution: 1.0,
            friction: 0.0,
            fraction: f,
            domain: (0.0, side),
            periodic: true,
            types,
            wall: None,
        })?;
        let t = sim.state.scene.templates[0].clone();
        let mut rng = Rng::new(7);
        let mut id = 0;
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    let x = Vector3::new(i as f64, j as f64, k as f64) * (side / 3.0)
                        + Vector3::repeat(side / 6.0);
                    sim.state
                        .particles
                        .push(id, 0, 1.0, x, UnitQuaternion::identity(), &t, 2500.0);
                    sim.state.particles.velocity[id as usize] = Vector3::new(
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                    );
                    id += 1;
                }
            }
        }
        sim.refresh()?;
        let e0 = sim.state.total_energy();
        let steps = (0.02 / sim.state.dt).round() as u64;
        let mut e = Engine::new(sim, device)?;
        for _ in 0..steps {
            e.step()?;
        }
        let e1 = e.synced()?.total_energy();
        let error = (e1 - e0).abs() / e0;
        Ok((
            error,
            steps,
            format!("ΔE/E {:.3e} over 20 ms", (e1 - e0) / e0),
        ))
    }

    pub(super) fn mesh_independence(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let lc = 0.025;
        let types = format!(
            "[[particle_types]]\nname = \"cube\"\nmaterial = \"m\"\n\
             generator = {{ kind = \"cuboid\", a = {lc}, b = {lc}, c = {lc} }}\nscale = 1.0\n"
        );
        let mut curves = Vec::new();
        let mut steps_total = 0;
        for mesh in ["mesh_coarse.stl", "mesh_fine.stl"] {
            let mut sim = self.simulation(&Spec {
                e_modulus: 1e6,
                poisson: 0.1,
                density: 1500.0,
                restitution: 0.1,
                friction: 0.8,
                fraction: f,
                domain: (-1.0, 1.0),
                periodic: false,
                types: &types,
                wall: Some(&self.dir.join(mesh)),
            })?;
            let t = sim.state.scene.templates[0].clone();
            let (depth, v, x0) = (0.01 * lc, 0.1, -0.08);
            let dt = sim.state.dt;
            let place = |s: &mut RunState, k: u64| {
                s.particles.velocity[0] = Vector3::new(v, 0.0, 0.0);
                s.particles.angular_velocity[0] = Vector3::zeros();
                s.particles.position[0] =
                    Vector3::new(x0 + v * dt * k as f64, 0.013, 0.5 * lc - depth);
                s.particles.orientation[0] = UnitQuaternion::identity();
            };
            sim.state.particles.push(
                0,
                0,
                1.0,
                Vector3::new(x0, 0.013, 0.5 * lc - depth),
                UnitQuaternion::identity(),
                &t,
                1500.0,
            );
            sim.refresh()?;
            // Over κ = Δx/L_c from 0 to 1: the cube crosses four cells of the fine mesh.
            let steps = (lc / v / dt) as u64;
            let mut e = Engine::new(sim, device)?;
            let mut curve = Vec::with_capacity(steps as usize);
            for k in 0..steps {
                e.edit(|s| place(s, k))?;
                e.step()?;
                let force = e.synced()?.wall_forces[0];
                curve.push((force.z, force.xy().norm()));
            }
            steps_total += steps;
            curves.push(curve);
        }
        let scale_n = curves[0].iter().map(|c| c.0.abs()).fold(0.0, f64::max);
        let scale_t = curves[0].iter().map(|c| c.1).fold(0.0, f64::max);
        let (mut dn, mut dtan) = (0.0f64, 0.0f64);
        for (a, b) in curves[0].iter().zip(&curves[1]) {
            dn = dn.max((a.0 - b.0).abs() / scale_n);
            dtan = dtan.max((a.1 - b.1).abs() / scale_t);
        }
        Ok((
            dn.max(dtan),
            steps_total,
            format!("normal {dn:.2e}, tangential {dtan:.2e} of the force scale"),
        ))
    }

    /// Returns the packing fraction as the "error" (made relative to the finest step by
    /// [`run_accuracy`](super::run_accuracy)).
    pub(super) fn pour_packing(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let path = self.root.join("launch/validation/pour.toml");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        let text = text.replace("dt_fraction = 0.05", &format!("dt_fraction = {f}"));
        // Relative paths of the file (its meshes) resolve against its own folder.
        let base = path.parent().unwrap_or(&self.root);
        let scene = parse_scene(&text, base, "pour.toml")?;
        let end = scene.simulation.end_time;
        let sim = Simulation::builder(scene).build()?;
        let mut e = Engine::new(sim, device)?;
        let mut steps = 0;
        while e.state().time + 0.5 * e.state().dt < end {
            e.step()?;
            steps += 1;
        }
        let p = &e.synced()?.particles;
        Ok((core_packing_fraction(p), steps, String::new()))
    }
}

/// The pour's bulk packing fraction by centre counting in the bed's core (one 4 mm diameter in
/// from the 2 cm box's walls and floor, below the 90th percentile of the centre heights less
/// one diameter), with each dodecahedron's volume.
fn core_packing_fraction(p: &crate::state::Particles) -> f64 {
    let (half, d) = (0.02, 0.004);
    let mut z: Vec<f64> = p.position.iter().map(|x| x.z).collect();
    z.sort_by(f64::total_cmp);
    if z.is_empty() {
        return 0.0;
    }
    let surface = z[(0.9 * z.len() as f64) as usize];
    let (lo, hi) = (
        Vector3::new(-half + d, -half + d, d),
        Vector3::new(half - d, half - d, surface - d),
    );
    let volume: f64 = (0..p.len())
        .filter(|&i| {
            let x = p.position[i];
            (0..3).all(|k| x[k] > lo[k] && x[k] < hi[k])
        })
        .map(|i| p.mass[i] / 2500.0)
        .sum();
    let core = (hi - lo).product();
    if core > 0.0 { volume / core } else { 0.0 }
}
