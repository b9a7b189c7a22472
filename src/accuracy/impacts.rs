//! The single-impact cases, each checked against rigid-body impact theory: the faceted
//! cylinder, the cube impacts (restitution and the elastic energy gain), the oblique sphere.

use super::runner::{CaseRunner, Spec};
use crate::backend::{Device, Engine};
use anyhow::Result;
use nalgebra::{UnitQuaternion, Vector3};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};

impl CaseRunner {
    pub(super) fn cylinder_impact(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let mesh = self.root.join("meshes/particles/cylinder_42.stl");
        let types = format!(
            "[[particle_types]]\nname = \"cyl\"\nmaterial = \"m\"\nmesh = \"{}\"\nscale = 1.0\n",
            mesh.display()
        );
        let (mut worst, mut steps, mut detail) = (0.0f64, 0, String::new());
        for theta_deg in [30.0f64, 45.0] {
            let mut sim = self.simulation(&Spec {
                e_modulus: 1.15e9,
                poisson: 0.35,
                density: 1245.0,
                restitution: 0.85,
                friction: 0.0,
                fraction: f,
                domain: (-0.5, 0.5),
                periodic: false,
                types: &types,
                wall: Some(&self.dir.join("plane.stl")),
            })?;
            let t = sim.scene.templates[0].clone();
            let tilt = UnitQuaternion::from_axis_angle(
                &Vector3::y_axis(),
                FRAC_PI_2 - theta_deg.to_radians(),
            );
            let q = tilt * t.file_to_body.rotation.inverse();
            let low = t
                .vertices
                .iter()
                .map(|v| q * v.coords)
                .min_by(|a, b| a.z.total_cmp(&b.z))
                .unwrap_or_default();
            let v0 = 1.0;
            let dt = sim.dt;
            sim.particles.push(
                0,
                0,
                1.0,
                Vector3::new(0.0, 0.0, -low.z + 0.37 * v0 * dt),
                q,
                &t,
                1245.0,
            );
            sim.particles.velocity[0] = Vector3::new(0.0, 0.0, -v0);
            sim.refresh()?;
            let m = sim.particles.mass[0];
            let i_perp = {
                let r = q.to_rotation_matrix();
                let i = nalgebra::Matrix3::from_diagonal(&sim.particles.inertia[0]);
                (r * i * r.transpose())[(1, 1)]
            };
            let mut e = Engine::new(sim, device)?;
            steps += Self::impact(&mut e, 1_000_000)?;
            let s = e.synced()?;
            let (k2, r, e_n) = (i_perp / m, low.x, 0.85);
            let v_ref = (e_n * k2 - r * r) / (k2 + r * r);
            let w_ref = -(1.0 + e_n) * r / (k2 + r * r);
            let dv = (s.particles.velocity[0].z / v0 - v_ref).abs();
            let dw = (s.particles.angular_velocity[0].y / v0 - w_ref).abs() * k2.sqrt();
            worst = worst.max(dv).max(dw);
            detail.push_str(&format!("{theta_deg}°: Δv' {dv:.2e}, Δω'k {dw:.2e}; "));
        }
        Ok((worst, steps, detail))
    }

    pub(super) fn restitution(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        self.impacts(device, f, 0.5)
    }

    pub(super) fn elastic_impact(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        self.impacts(device, f, 1.0)
    }

    /// Cube impacts at 1 m/s with restitution `e_set`, 16 phases of first touch each: the worst
    /// `|e_out − e|/e` for e < 1, the worst energy gain `e_out² − 1` for e = 1.
    fn impacts(&self, device: Device, f: f64, e_set: f64) -> Result<(f64, u64, String)> {
        let types = "[[particle_types]]\nname = \"p\"\nmaterial = \"m\"\n\
                     generator = { kind = \"cuboid\", a = 0.01, b = 0.01, c = 0.01 }\nscale = 1.0\n";
        let vertex = UnitQuaternion::rotation_between(&Vector3::new(1.0, 1.0, 1.0), &-Vector3::z())
            .unwrap_or_else(UnitQuaternion::identity);
        let edge = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), FRAC_PI_4);
        let face = UnitQuaternion::identity();
        let (mut worst, mut steps, mut detail) = (0.0f64, 0, String::new());
        let mut worst_loss = 0.0f64;
        for (name, q, reach, wall) in [
            ("vertex", vertex, 0.005 * 3f64.sqrt(), true),
            ("edge", edge, 0.005 * 2f64.sqrt(), true),
            ("face", face, 0.005, true),
            ("face on face", face, 0.005, false),
        ] {
            let mut case_worst = 0.0f64;
            for k in 0..16 {
                let mut sim = self.simulation(&Spec {
                    e_modulus: 1e7,
                    poisson: 0.3,
                    density: 2500.0,
                    restitution: e_set,
                    friction: 0.0,
                    fraction: f,
                    domain: (-0.5, 0.5),
                    periodic: false,
                    types,
                    wall: wall.then(|| self.dir.join("plane.stl")).as_deref(),
                })?;
                let t = sim.scene.templates[0].clone();
                let gap = 1e-6 + sim.dt * k as f64 / 16.0;
                sim.particles.push(
                    1,
                    0,
                    1.0,
                    Vector3::new(0.0, 0.0, reach + gap),
                    q,
                    &t,
                    2500.0,
                );
                sim.particles.velocity[0] = Vector3::new(0.0, 0.0, -1.0);
                if !wall {
                    sim.particles
                        .push(2, 0, 1.0, Vector3::new(0.0, 0.0, -0.005), face, &t, 2500.0);
                }
                sim.refresh()?;
                let mut e = Engine::new(sim, device)?;
                steps += Self::impact(&mut e, 1_000_000)?;
                let p = &e.synced()?.particles;
                let v = |id: u64| {
                    p.id.iter()
                        .position(|&i| i == id)
                        .map_or(f64::NAN, |i| p.velocity[i].z)
                };
                let rebound = if wall { v(1) } else { v(1) - v(2) };
                let error = if e_set < 1.0 {
                    (rebound - e_set).abs() / e_set
                } else {
                    // The energy an elastic impact gains (its loss is the restitution error
                    // of the exit, which `restitution` measures).
                    worst_loss = worst_loss.max(1.0 - rebound * rebound);
                    (rebound * rebound - 1.0).max(0.0)
                };
                case_worst = case_worst.max(error);
            }
            worst = worst.max(case_worst);
            detail.push_str(&format!("{name} {case_worst:.2e}; "));
        }
        if e_set >= 1.0 {
            detail.push_str(&format!("largest energy loss {worst_loss:.2e}"));
        }
        Ok((worst, steps, detail))
    }

    pub(super) fn sphere_oblique(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let (mut worst, mut steps, mut detail) = (0.0f64, 0, String::new());
        // (name, E, ν, ρ, R, v_n, v_t, ω about y, μ)
        let cases = [
            ("test 6", 7.0e10, 0.33, 2700.0, 0.1, 0.2, 0.0, -8.0, 0.4),
            (
                "soft 70°",
                1e7,
                0.3,
                2500.0,
                0.01,
                0.3420201433256687,
                0.9396926207859084,
                0.0,
                0.3,
            ),
        ];
        let e_set = 0.5;
        for (name, em, nu, rho, r, vn, vt, omega, mu) in cases {
            let types = format!(
                "[[particle_types]]\nname = \"ball\"\nmaterial = \"m\"\n\
                 generator = {{ kind = \"sphere\", size = {:e} }}\n",
                2.0 * r
            );
            let mut sim = self.simulation(&Spec {
                e_modulus: em,
                poisson: nu,
                density: rho,
                restitution: e_set,
                friction: mu,
                fraction: f,
                domain: (-1.0, 1.0),
                periodic: false,
                types: &types,
                wall: Some(&self.dir.join("plane.stl")),
            })?;
            let t = sim.scene.templates[0].clone();
            let dt = sim.dt;
            sim.particles.push(
                0,
                0,
                1.0,
                Vector3::new(0.0, 0.0, r + 0.37 * vn * dt),
                UnitQuaternion::identity(),
                &t,
                rho,
            );
            sim.particles.velocity[0] = Vector3::new(vt, 0.0, -vn);
            sim.particles.angular_velocity[0] = Vector3::new(0.0, omega, 0.0);
            sim.refresh()?;
            let mut e = Engine::new(sim, device)?;
            steps += Self::impact(&mut e, 1_000_000)?;
            let p = &e.synced()?.particles;
            let impulse = mu * (1.0 + e_set) * vn;
            let (vt_ref, w_ref) = (vt - impulse, omega + 2.5 * impulse / r);
            let errs = [
                (p.velocity[0].z - e_set * vn).abs() / (e_set * vn),
                (p.velocity[0].x - vt_ref).abs() / vt_ref.abs(),
                (p.angular_velocity[0].y - w_ref).abs() / w_ref.abs(),
            ];
            let w = errs.iter().copied().fold(0.0, f64::max);
            worst = worst.max(w);
            detail.push_str(&format!("{name} {w:.2e}; "));
        }
        Ok((worst, steps, detail))
    }
}
