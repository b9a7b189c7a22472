//! Queries on a resolved [`Scene`] (radii, cutoff, key lines, name lookups) and the critical
//! time step derived from them: Rayleigh steps and face contact times.

use super::*;

impl Scene {
    /// Whether every particle is a sphere: the scene then takes the sphere fast path (docs/design.md
    /// §1), and validation guarantees it has no polyhedra.
    pub fn spheres_only(&self) -> bool {
        !self.templates.is_empty() && self.templates.iter().all(|t| t.sphere)
    }

    /// The most planes of a pair's overlap whose faces come from the vertex enumeration rather
    /// than the dual hull, on every backend: 16 when a polyhedral template has more than 12
    /// faces, else 8; `POLYDEM_ENUM_PLANES` overrides
    /// ([`crate::geometry::vertex_enumeration::enum_planes_for`] says why).
    pub fn enum_planes(&self) -> usize {
        let max_faces = self
            .templates
            .iter()
            .filter(|t| !t.sphere)
            .map(|t| t.faces.len())
            .max()
            .unwrap_or(0);
        crate::geometry::vertex_enumeration::enum_planes_for(max_faces)
    }

    /// The time step (s): the fixed one, or the fraction of the Rayleigh step.
    pub fn time_step(&self) -> f64 {
        match self.simulation.dt {
            TimeStep::Fixed(dt) => dt,
            TimeStep::FractionOfCritical(_) => critical_time_step(self).dt,
        }
    }

    /// Largest bounding (circumscribed) radius any particle type can have at its largest scale.
    pub fn max_bounding_radius(&self) -> f64 {
        self.particle_types
            .iter()
            .zip(&self.scale_distributions)
            .filter_map(|(p, d)| {
                self.templates
                    .get(p.template)
                    .map(|t| t.circumscribed_radius * d.max_scale())
            })
            .fold(0.0, f64::max)
    }

    /// The neighbour cutoff: the farthest two particles' centroids can be and still be listed
    /// as a candidate pair, `2 r_max + skin` (the largest bounding diameter plus the skin). It
    /// sizes the binning cells, the facet grids of the walls and the decomposition's halo.
    pub fn cutoff(&self) -> f64 {
        self.cutoff_with_skin(self.simulation.neighbor.skin)
    }

    /// The least length of a periodic axis, twice the reach of a contact: `2 × 2 r_max`
    /// (`r_max` the largest circumscribed radius). Below it a particle can touch two images of
    /// another (or its own), and the minimum-image pair list holds only one of them.
    pub fn least_periodic_extent(&self) -> f64 {
        4.0 * self.max_bounding_radius()
    }

    /// How far outside an insertion region a particle can still stop a new one placed in it:
    /// two bounding radii (a new particle's bounding sphere lies inside its region), widened
    /// by a relative 1e-9 and 1e-12 m so that rounding never leaves a touching one out.
    pub fn insertion_reach(&self) -> f64 {
        2.0 * self.max_bounding_radius() * (1.0 + 1e-9) + 1e-12
    }

    /// The cutoff of a list built with `skin` in place of the scene's (a hybrid list's
    /// enlarged skin): `2 r_max + skin`.
    pub fn cutoff_with_skin(&self, skin: f64) -> f64 {
        2.0 * self.max_bounding_radius() + skin
    }

    /// Smallest volume-equivalent radius any particle type can have at its smallest scale
    /// (infinite without particle types).
    pub fn min_equivalent_radius(&self) -> f64 {
        self.particle_types
            .iter()
            .zip(&self.scale_distributions)
            .filter_map(|(p, d)| {
                self.templates
                    .get(p.template)
                    .map(|t| t.equivalent_radius * d.min_scale())
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// 1-based line of `key` in the scene file, or of its nearest ancestor that is there.
    pub fn line_of(&self, key: &str) -> Option<usize> {
        let mut p = key;
        loop {
            if let Some((_, line)) = self.key_lines.iter().find(|(k, _)| k == p) {
                return Some(*line);
            }
            let cut = p.rfind(['.', '['])?;
            p = &p[..cut];
        }
    }

    /// An error about `key` found after validation (say by the domain decomposition, which
    /// needs the rank count), in the same `file:line: key: message` form as validation's.
    pub fn key_error(&self, key: &str, message: impl Into<String>) -> SceneError {
        SceneError::Invalid {
            file: self.file.display().to_string(),
            errors: vec![KeyError {
                key: key.to_string(),
                line: self.line_of(key),
                message: message.into(),
            }],
        }
    }

    /// Index of the particle type called `name`.
    pub fn particle_type_index(&self, name: &str) -> Option<usize> {
        self.particle_types.iter().position(|p| p.name == name)
    }

    /// Index of the material called `name`.
    pub fn material_index(&self, name: &str) -> Option<usize> {
        self.materials.iter().position(|m| m.name == name)
    }
}

/// Face-to-face contact time of every pair of particle types at the impact speed `v`
/// (validation.md §6; see [`crate::contact::restitution::face_contact_time`]): each type with
/// itself (named by the type), then each pair of different types (named `a + b`), each at its
/// smallest scale, meeting with the larger of their largest faces' areas capped by the smaller
/// one's. A pair takes `m* = m_a m_b/(m_a + m_b)` and `c = E_a/R_a + E_b/R_b`, so a small soft
/// grain meeting a stiff one can have a shorter contact than either type with itself. For
/// spheres, the head-on sphere–sphere time with `r* = r_a r_b/(r_a + r_b)`
/// ([`crate::contact::restitution::sphere_contact_time`]).
pub fn face_contact_times(scene: &Scene, v: f64) -> Vec<(String, f64)> {
    // Per type: (name, mass, E/R, largest face area, radius, sphere).
    let per_type: Vec<(String, f64, f64, f64, f64, bool)> = scene
        .particle_types
        .iter()
        .zip(&scene.scale_distributions)
        .map(|(ty, dist)| {
            let t = &scene.templates[ty.template];
            let m = &scene.materials[ty.material];
            let s = dist.min_scale();
            let area = t
                .faces
                .iter()
                .map(|f| {
                    let v: Vec<_> = f
                        .vertices
                        .iter()
                        .map(|&k| t.vertices[k as usize].coords)
                        .collect();
                    (1..v.len().saturating_sub(1))
                        .map(|k| (v[k] - v[0]).cross(&(v[k + 1] - v[0])).norm() / 2.0)
                        .sum::<f64>()
                })
                .fold(0.0, f64::max)
                * s
                * s;
            let mass = m.density * t.volume * s.powi(3);
            let stiffness = m.youngs_modulus / (t.equivalent_radius * s);
            let radius = t.circumscribed_radius * s;
            (ty.name.clone(), mass, stiffness, area, radius, t.sphere)
        })
        .collect();
    let mut out = Vec::new();
    for gap in 0..per_type.len() {
        for i in 0..per_type.len() - gap {
            let (a, b) = (&per_type[i], &per_type[i + gap]);
            // A type with itself as m/2 and r/2 exactly (the harmonic means round otherwise).
            let (mass, r_eff) = if gap == 0 {
                (0.5 * a.1, 0.5 * a.4)
            } else {
                (a.1 * b.1 / (a.1 + b.1), a.4 * b.4 / (a.4 + b.4))
            };
            let c = a.2 + b.2;
            let time = if a.5 && b.5 {
                crate::contact::restitution::sphere_contact_time(mass, c, r_eff, v)
            } else {
                crate::contact::restitution::face_contact_time(mass, c, a.3.min(b.3), v)
            };
            let name = if gap == 0 {
                a.0.clone()
            } else {
                format!("{} + {}", a.0, b.0)
            };
            out.push((name, time));
        }
    }
    out
}

/// The impact speed the contact-time estimate assumes: free fall over the domain's height, at
/// least 1 m/s.
pub fn impact_speed(scene: &Scene) -> f64 {
    let height = scene.domain.max.z - scene.domain.min.z;
    (2.0 * scene.gravity.norm() * height).sqrt().max(1.0)
}

/// The Rayleigh step of one material.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RayleighStep {
    /// Material name.
    pub material: String,
    /// Smallest volume-equivalent radius of any particle type of this material at its smallest
    /// scale (m).
    pub radius: f64,
    /// `Δt_R = π R √(ρ/G) / (0.1631 ν + 0.8766)` with `G = E / (2 (1 + ν))` (s).
    pub step: f64,
}

/// Time-step stability figures of a scene.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TimeStepReport {
    /// Smallest Rayleigh step over the particle materials (s) (infinite without particle types).
    pub rayleigh: f64,
    /// Rayleigh step per material that some particle type uses.
    pub per_material: Vec<RayleighStep>,
    /// Contact-time estimate (Hertz or linear spring); not computed here yet.
    pub contact_time: Option<f64>,
    /// The chosen time step (s).
    pub dt: f64,
    /// `dt / rayleigh`.
    pub fraction_of_rayleigh: f64,
}

/// Rayleigh step of a material with radius `r`.
pub fn rayleigh_step(m: &Material, r: f64) -> f64 {
    let g = m.youngs_modulus / (2.0 * (1.0 + m.poisson_ratio));
    std::f64::consts::PI * r * (m.density / g).sqrt() / (0.1631 * m.poisson_ratio + 0.8766)
}

/// The Rayleigh step per particle material and the chosen time step.
pub fn critical_time_step(scene: &Scene) -> TimeStepReport {
    let mut per_material = Vec::new();
    for (mi, m) in scene.materials.iter().enumerate() {
        let radius = scene
            .particle_types
            .iter()
            .zip(&scene.scale_distributions)
            .filter(|(p, _)| p.material == mi)
            .filter_map(|(p, d)| {
                scene
                    .templates
                    .get(p.template)
                    .map(|t| t.equivalent_radius * d.min_scale())
            })
            .fold(f64::INFINITY, f64::min);
        if radius.is_finite() {
            per_material.push(RayleighStep {
                material: m.name.clone(),
                radius,
                step: rayleigh_step(m, radius),
            });
        }
    }
    let rayleigh = per_material
        .iter()
        .map(|r| r.step)
        .fold(f64::INFINITY, f64::min);
    // The volume law's face-to-face contact is far stiffer at first touch than the Rayleigh
    // estimate assumes (it is derived for Hertzian spheres), so the critical step is the
    // smaller of the two.
    let contact = face_contact_times(scene, impact_speed(scene))
        .iter()
        .map(|t| t.1)
        .fold(f64::INFINITY, f64::min);
    let dt = match scene.simulation.dt {
        TimeStep::Fixed(dt) => dt,
        TimeStep::FractionOfCritical(f) => f * rayleigh.min(contact),
    };
    TimeStepReport {
        rayleigh,
        per_material,
        contact_time: contact.is_finite().then_some(contact),
        dt,
        fraction_of_rayleigh: dt / rayleigh,
    }
}
