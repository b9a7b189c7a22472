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
            let t = sim.state.scene.templates[0].clone();
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
            let dt = sim.state.dt;
            sim.state.particles.push(
                0,
                0,
                1.0,
                Vector3::new(0.0, 0.0, -low.z + 0.37 * v0 * dt),
                q,
                &t,
                1245.0,
            );
            sim.state.particles.velocity[0] = Vector3::new(0.0, 0.0, -v0);
            sim.refresh()?;
            let m = sim.state.particles.mass[0];
            let i_perp = {
                let r = q.to_rotation_matrix();
                let i = nalgebra::Matrix3::from_diagonal(&sim.state.particles.inertia[0]);
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
                let t = sim.state.scene.templates[0].clone();
                let gap = 1e-6 + sim.state.dt * k as f64 / 16.0;
                sim.state.particles.push(
                    1,
                    0,
                    1.0,
                    Vector3::new(0.0, 0.0, reach + gap),
                    q,
                    &t,
                    2500.0,
                );
                sim.state.particles.velocity[0] = Vector3::new(0.0, 0.0, -1.0);
                if !wall {
                    sim.state.particles.push(
                        2,
                        0,
                        1.0,
                        Vector3::new(0.0, 0.0, -0.005),
                        face,
                        &t,
                        2500.0,
                    );
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
        let theta = 70f64.to_radians();
        let cases = [
            ("test 6", SphereImpact::aluminium(0.0, -8.0, 0.4, 0.5)),
            (
                "soft 70°",
                SphereImpact::soft(theta.cos(), theta.sin(), 0.3, 0.5),
            ),
        ];
        self.sphere_cases(device, f, &cases)
    }

    /// Sticking oblique impacts (below the sliding angle the contact point stops slipping and
    /// the sphere rolls off at `v_t' = v_t − (2/7) u`, u its slip): the soft sphere at v_n 0.5
    /// m/s from 15° to 55° (sliding from 57.6°) and Chung & Ooi test 6 at 2 rad/s (sliding from
    /// 4.2 rad/s).
    pub(super) fn sphere_sticking(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let soft = |deg: f64| SphereImpact::soft(0.5, 0.5 * deg.to_radians().tan(), 0.3, 0.5);
        let cases = [
            ("soft 15°", soft(15.0)),
            ("soft 30°", soft(30.0)),
            ("soft 45°", soft(45.0)),
            ("soft 55°", soft(55.0)),
            (
                "test 6 at 2 rad/s",
                SphereImpact::aluminium(0.0, -2.0, 0.4, 0.5),
            ),
        ];
        self.sphere_cases(device, f, &cases)
    }

    /// Friction's energy: the soft sphere at 30° for μ 0.1, 0.3, 0.7 and e 0.1, 0.5, 1 (sticking
    /// and sliding), its kinetic energy after the impact against the rigid-body one; the detail
    /// names the largest change against the energy it came in with, which friction must keep
    /// below zero.
    pub(super) fn friction_energy(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let (mut worst, mut steps, mut gain) = (0.0f64, 0, f64::NEG_INFINITY);
        let theta = 30f64.to_radians();
        for mu in [0.1, 0.3, 0.7] {
            for e in [0.1, 0.5, 1.0] {
                let c = SphereImpact::soft(0.5, 0.5 * theta.tan(), mu, e);
                let (out, n) = self.sphere_impact(device, f, &c)?;
                steps += n;
                let reference = c.reference();
                let (before, after, want) = (
                    c.kinetic(c.vn, c.vt, c.omega),
                    out.kinetic,
                    reference.kinetic,
                );
                worst = worst.max((after - want).abs() / before);
                gain = gain.max(after / before - 1.0);
            }
        }
        Ok((
            worst,
            steps,
            format!("largest change of kinetic energy {gain:+.3e}"),
        ))
    }

    fn sphere_cases(
        &self,
        device: Device,
        f: f64,
        cases: &[(&str, SphereImpact)],
    ) -> Result<(f64, u64, String)> {
        let (mut worst, mut steps, mut detail) = (0.0f64, 0, String::new());
        for (name, c) in cases {
            let (out, n) = self.sphere_impact(device, f, c)?;
            steps += n;
            let r = c.reference();
            let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-12);
            let errs = [
                rel(out.vn, r.vn),
                rel(out.vt, r.vt),
                rel(out.omega, r.omega),
            ];
            let w = errs.iter().copied().fold(0.0, f64::max);
            worst = worst.max(w);
            detail.push_str(&format!("{name} {w:.2e}; "));
        }
        Ok((worst, steps, detail))
    }

    /// One sphere impact on the wall: the rebound's normal and tangential speeds, spin about
    /// y and kinetic energy, and the steps it took.
    fn sphere_impact(&self, device: Device, f: f64, c: &SphereImpact) -> Result<(SphereOut, u64)> {
        let types = format!(
            "[[particle_types]]\nname = \"ball\"\nmaterial = \"m\"\n\
             generator = {{ kind = \"sphere\", size = {:e} }}\n",
            2.0 * c.radius
        );
        let mut sim = self.simulation(&Spec {
            e_modulus: c.e_modulus,
            poisson: c.poisson,
            density: c.density,
            restitution: c.restitution,
            friction: c.friction,
            fraction: f,
            domain: (-1.0, 1.0),
            periodic: false,
            types: &types,
            wall: Some(&self.dir.join("plane.stl")),
        })?;
        let t = sim.state.scene.templates[0].clone();
        let dt = sim.state.dt;
        sim.state.particles.push(
            0,
            0,
            1.0,
            Vector3::new(0.0, 0.0, c.radius + 0.37 * c.vn * dt),
            UnitQuaternion::identity(),
            &t,
            c.density,
        );
        sim.state.particles.velocity[0] = Vector3::new(c.vt, 0.0, -c.vn);
        sim.state.particles.angular_velocity[0] = Vector3::new(0.0, c.omega, 0.0);
        sim.refresh()?;
        let mut e = Engine::new(sim, device)?;
        let steps = Self::impact(&mut e, 1_000_000)?;
        let p = &e.synced()?.particles;
        let (vn, vt, omega) = (p.velocity[0].z, p.velocity[0].x, p.angular_velocity[0].y);
        Ok((
            SphereOut {
                vn,
                vt,
                omega,
                kinetic: c.kinetic(vn, vt, omega),
            },
            steps,
        ))
    }
}

/// An oblique impact of a solid sphere on the wall below it: approach speed `vn`, tangential
/// velocity `vt` along x, spin `omega` about y (its contact point slips at `vt − ω R`).
struct SphereImpact {
    e_modulus: f64,
    poisson: f64,
    density: f64,
    radius: f64,
    vn: f64,
    vt: f64,
    omega: f64,
    friction: f64,
    restitution: f64,
}

/// What an impact leaves (rebound speed `vn` positive up).
struct SphereOut {
    vn: f64,
    vt: f64,
    omega: f64,
    kinetic: f64,
}

impl SphereImpact {
    /// The soft sphere: E 10 MPa, ν 0.3, 2500 kg/m³, R 10 mm.
    fn soft(vn: f64, vt: f64, friction: f64, restitution: f64) -> Self {
        SphereImpact {
            e_modulus: 1e7,
            poisson: 0.3,
            density: 2500.0,
            radius: 0.01,
            vn,
            vt,
            omega: 0.0,
            friction,
            restitution,
        }
    }

    /// Chung & Ooi's Al-alloy sphere (R 0.1 m) at v_n 0.2 m/s.
    fn aluminium(vt: f64, omega: f64, friction: f64, restitution: f64) -> Self {
        SphereImpact {
            e_modulus: 7.0e10,
            poisson: 0.33,
            density: 2700.0,
            radius: 0.1,
            vn: 0.2,
            vt,
            omega,
            friction,
            restitution,
        }
    }

    /// The sphere's kinetic energy at these velocities (I = 2/5 m R²).
    fn kinetic(&self, vn: f64, vt: f64, omega: f64) -> f64 {
        let m = self.density * 4.0 / 3.0 * std::f64::consts::PI * self.radius.powi(3);
        0.5 * m * (vn * vn + vt * vt) + 0.2 * m * (self.radius * omega).powi(2)
    }

    /// Rigid-body theory with Coulomb friction: the normal impulse `(1 + e) m v_n`; the slip
    /// `u = v_t − ω R` stopped by `(2/7) m u` when that is at most `μ` times it (the sphere
    /// rolls off), else `μ (1 + e) m v_n` against the slip throughout.
    fn reference(&self) -> SphereOut {
        let u = self.vt - self.omega * self.radius;
        let sliding = self.friction * (1.0 + self.restitution) * self.vn;
        let stop = 2.0 / 7.0 * u;
        let dv = if stop.abs() <= sliding {
            stop
        } else {
            sliding.copysign(u)
        };
        let (vn, vt, omega) = (
            self.restitution * self.vn,
            self.vt - dv,
            self.omega + 2.5 * dv / self.radius,
        );
        SphereOut {
            vn,
            vt,
            omega,
            kinetic: self.kinetic(vn, vt, omega),
        }
    }
}
