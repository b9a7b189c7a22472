//! Placement of one particle: drawing its scale and orientation from the insertion stream,
//! and finding a free position, either a given lattice point or random tries tested against an
//! [`Occupancy`] grid of the particles already present and the walls.

use super::super::Scene;
use super::super::walls::WallTriangles;
use super::{Inserter, Insertion, OrientationMode};
use crate::state::Particles;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::collections::HashMap;

impl Inserter {
    /// Draws one particle's scale and orientation (in this order, from the insertion stream);
    /// `None` for a type the scene does not define (validation prevents it).
    fn draw(&mut self, ins: &Insertion, scene: &Scene) -> Option<(f64, UnitQuaternion<f64>)> {
        let dist = scene.scale_distributions.get(ins.particle_type)?;
        let scale = dist.sample(&mut self.rng);
        let orientation = match &ins.orientation {
            OrientationMode::Random => {
                let q = self.rng.unit_quaternion();
                UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
            }
            OrientationMode::Fixed(q) => *q,
        };
        Some((scale, orientation))
    }

    /// Appends a particle of the insertion's type at `c` with the insertion's velocities.
    pub(super) fn push(
        ins: &Insertion,
        particles: &mut Particles,
        scene: &Scene,
        (scale, orientation): (f64, UnitQuaternion<f64>),
        c: Vector3<f64>,
        next_id: &mut u64,
    ) {
        let kind = ins.particle_type;
        let ptype = &scene.particle_types[kind];
        let density = scene
            .materials
            .get(ptype.material)
            .map_or(0.0, |m| m.density);
        particles.push(
            *next_id,
            kind as u32,
            scale,
            c,
            orientation,
            &scene.templates[ptype.template],
            density,
        );
        let i = particles.len() - 1;
        particles.velocity[i] = ins.velocity;
        particles.angular_velocity[i] = ins.angular_velocity;
        *next_id += 1;
    }

    /// Draws one particle and places it at `c` without any test (lattice insertion).
    pub(super) fn place_at(
        &mut self,
        ins: &Insertion,
        particles: &mut Particles,
        scene: &Scene,
        c: Vector3<f64>,
        next_id: &mut u64,
    ) {
        if let Some(body) = self.draw(ins, scene) {
            Self::push(ins, particles, scene, body, c, next_id);
        }
    }

    /// Draws one particle and tries to place it; false if no position was free.
    pub(super) fn place_one(
        &mut self,
        ins: &Insertion,
        particles: &mut Particles,
        scene: &Scene,
        occupied: &mut Occupancy,
        walls: &WallTriangles,
        next_id: &mut u64,
    ) -> bool {
        let Some(template) = scene
            .particle_types
            .get(ins.particle_type)
            .and_then(|p| scene.templates.get(p.template))
        else {
            return false;
        };
        let Some(body) = self.draw(ins, scene) else {
            return false;
        };
        let r = template.circumscribed_radius * body.0;
        for _ in 0..ins.max_attempts {
            let Some(c) = ins.region.sample_centre(&mut self.rng, r) else {
                return false;
            };
            if occupied.is_free(&c, r) && walls.is_free(&c, r) {
                Self::push(ins, particles, scene, body, c, next_id);
                occupied.add(c, r);
                return true;
            }
        }
        false
    }
}

pub(super) fn type_name(scene: &Scene, kind: usize) -> &str {
    scene
        .particle_types
        .get(kind)
        .map_or("?", |p| p.name.as_str())
}

/// Bounding radius of a particle of type `kind` at `scale`; the scene's largest when the type is
/// unknown (conservative).
fn bounding_radius(scene: &Scene, kind: usize, scale: f64) -> f64 {
    scene
        .particle_types
        .get(kind)
        .and_then(|p| scene.templates.get(p.template))
        .map_or(scene.max_bounding_radius(), |t| {
            t.circumscribed_radius * scale
        })
}

/// Bounding spheres of present particles in a uniform hash grid of cell size ≥ 2 r_max, so a
/// query looks at no more than 2 cells per axis (times periodic images).
pub(super) struct Occupancy {
    cell: f64,
    r_max: f64,
    cells: HashMap<[i64; 3], Vec<(Vector3<f64>, f64)>>,
    /// Shifts of the periodic axes (zero for the others): the domain's extent.
    period: Vector3<f64>,
    periodic: [bool; 3],
    domain_min: Vector3<f64>,
    domain_max: Vector3<f64>,
}

impl Occupancy {
    /// The bounding spheres of `particles`, or of those whose centre lies in one of the boxes
    /// `near` (the regions grown by the reach of a new particle's search). The cell size comes
    /// from all of them either way, so the searches' answers do not depend on `near`.
    pub(super) fn new(
        scene: &Scene,
        particles: &Particles,
        near: Option<&[(Vector3<f64>, Vector3<f64>)]>,
    ) -> Self {
        let mut r_max = scene.max_bounding_radius();
        let radii: Vec<f64> = (0..particles.len())
            .map(|i| {
                let kind = particles.kind.get(i).copied().unwrap_or(u32::MAX) as usize;
                let s = particles.scale.get(i).copied().unwrap_or(1.0);
                bounding_radius(scene, kind, s)
            })
            .collect();
        for &r in &radii {
            r_max = r_max.max(r);
        }
        let cell = (2.0 * r_max).max(f64::MIN_POSITIVE);
        let d = &scene.domain;
        let mut occ = Occupancy {
            cell,
            r_max,
            cells: HashMap::new(),
            period: d.max - d.min,
            periodic: d.periodic,
            domain_min: d.min,
            domain_max: d.max,
        };
        let inside = |p: &Vector3<f64>| {
            near.is_none_or(|boxes| {
                boxes
                    .iter()
                    .any(|(lo, hi)| (0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a]))
            })
        };
        for (p, r) in particles.position.iter().zip(radii) {
            if inside(p) {
                occ.add(*p, r);
            }
        }
        occ
    }

    fn key(&self, p: &Vector3<f64>) -> [i64; 3] {
        // `as` saturates (NaN → 0): a particle far outside still gets a cell, never a panic.
        p.map(|x| (x / self.cell).floor() as i64).into()
    }

    fn add(&mut self, p: Vector3<f64>, r: f64) {
        let k = self.key(&p);
        self.cells.entry(k).or_default().push((p, r));
    }

    /// No present sphere within `r` of `c`, including periodic images.
    fn is_free(&self, c: &Vector3<f64>, r: f64) -> bool {
        let reach = r + self.r_max;
        // Images of c across each periodic axis whose boundary is within reach.
        let mut images = vec![*c];
        for a in 0..3 {
            if !self.periodic[a] {
                continue;
            }
            let mut shifted = Vec::new();
            for img in &images {
                if img[a] - self.domain_min[a] < reach {
                    let mut s = *img;
                    s[a] += self.period[a];
                    shifted.push(s);
                }
                if self.domain_max[a] - img[a] < reach {
                    let mut s = *img;
                    s[a] -= self.period[a];
                    shifted.push(s);
                }
            }
            images.extend(shifted);
        }
        images.iter().all(|q| self.is_free_at(q, r, reach))
    }

    fn is_free_at(&self, q: &Vector3<f64>, r: f64, reach: f64) -> bool {
        let lo = self.key(&q.add_scalar(-reach));
        let hi = self.key(&q.add_scalar(reach));
        for i in lo[0]..=hi[0] {
            for j in lo[1]..=hi[1] {
                for k in lo[2]..=hi[2] {
                    let Some(list) = self.cells.get(&[i, j, k]) else {
                        continue;
                    };
                    for (p, rp) in list {
                        let d = r + rp;
                        if (p - q).norm_squared() < d * d {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }
}
