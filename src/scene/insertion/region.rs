//! Insertion regions: the shapes particles are inserted into, how a centre is drawn uniformly
//! inside one, and the validation of an `insertions[i].region` table.

use super::super::Scene;
use super::super::schema;
use crate::rng::Rng;
use nalgebra::Vector3;
use std::f64::consts::TAU;

/// Where particles are inserted. Whole bounding spheres are kept inside the region.
#[derive(Clone, Debug, PartialEq)]
pub enum Region {
    /// Axis-aligned box (m).
    Box {
        min: Vector3<f64>,
        max: Vector3<f64>,
    },
    /// Cylinder from `base` along the unit `axis` for `height`, of `radius` (m).
    Cylinder {
        base: Vector3<f64>,
        axis: Vector3<f64>,
        radius: f64,
        height: f64,
    },
}

impl Region {
    /// Axis-aligned bounding box `(min, max)`.
    pub fn aabb(&self) -> (Vector3<f64>, Vector3<f64>) {
        match self {
            Region::Box { min, max } => (*min, *max),
            Region::Cylinder {
                base,
                axis,
                radius,
                height,
            } => {
                // A disk of radius R normal to unit a extends R·√(1 − a_i²) along axis i.
                let ext = axis.map(|a| radius * (1.0 - a * a).max(0.0).sqrt());
                let top = base + axis * *height;
                (base.inf(&top) - ext, base.sup(&top) + ext)
            }
        }
    }

    /// Whether the point `x` lies inside (boundary included).
    pub fn contains(&self, x: &Vector3<f64>) -> bool {
        match self {
            Region::Box { min, max } => (0..3).all(|a| x[a] >= min[a] && x[a] <= max[a]),
            Region::Cylinder {
                base,
                axis,
                radius,
                height,
            } => {
                let d = x - base;
                let h = d.dot(axis);
                h >= 0.0 && h <= *height && (d - axis * h).norm() <= *radius
            }
        }
    }

    /// Volume (m³).
    pub fn volume(&self) -> f64 {
        match self {
            Region::Box { min, max } => (max - min).product(),
            Region::Cylinder { radius, height, .. } => 0.5 * TAU * radius * radius * height,
        }
    }

    /// Whether a sphere of radius `r` fits inside at all.
    pub fn fits(&self, r: f64) -> bool {
        match self {
            Region::Box { min, max } => (max - min).min() > 2.0 * r,
            Region::Cylinder { radius, height, .. } => *radius > r && *height > 2.0 * r,
        }
    }

    /// A uniformly random centre such that a sphere of radius `r` lies inside; `None` when it
    /// cannot fit. Draws exactly three uniforms when it fits.
    pub fn sample_centre(&self, rng: &mut Rng, r: f64) -> Option<Vector3<f64>> {
        if !self.fits(r) {
            return None;
        }
        match self {
            Region::Box { min, max } => {
                let x = rng.range(min.x + r, max.x - r);
                let y = rng.range(min.y + r, max.y - r);
                let z = rng.range(min.z + r, max.z - r);
                Some(Vector3::new(x, y, z))
            }
            Region::Cylinder {
                base,
                axis,
                radius,
                height,
            } => {
                let (u, v) = perpendicular_basis(axis);
                let rho = (radius - r) * rng.uniform().sqrt();
                let phi = TAU * rng.uniform();
                let h = rng.range(r, height - r);
                Some(base + axis * h + u * (rho * phi.cos()) + v * (rho * phi.sin()))
            }
        }
    }
}

/// The frame of a cylinder region for lattices and packings: `(u, v, axis)` right-handed,
/// `u = axis × e` with `e` the coordinate axis least aligned with the axis, `v = axis × u`.
/// Lattice spacings and packing cells are given in this frame (the first two components across
/// the axis, the third along it).
pub fn cylinder_frame(axis: &Vector3<f64>) -> nalgebra::Rotation3<f64> {
    let (u, v) = perpendicular_basis(axis);
    nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[u, v, *axis]))
}

/// The sites of a lattice of `spacing` (in the [`cylinder_frame`]) filling the square prism
/// around a cylinder, `(c + 0.5) spacing` from its corner `(−radius, −radius, 0)`, those within
/// `radius` of the axis; in lattice order (first frame axis fastest, the axis slowest: bottom
/// up).
pub fn cylinder_sites(
    base: &Vector3<f64>,
    axis: &Vector3<f64>,
    radius: f64,
    height: f64,
    spacing: &Vector3<f64>,
) -> Vec<Vector3<f64>> {
    let f = cylinder_frame(axis);
    let n = |len: f64, s: f64| (len / s + 1e-9).floor().max(0.0) as u64;
    let (nu, nv, nh) = (
        n(2.0 * radius, spacing.x),
        n(2.0 * radius, spacing.y),
        n(height, spacing.z),
    );
    let mut out = Vec::new();
    for k in 0..nh {
        for j in 0..nv {
            for i in 0..nu {
                let l = Vector3::new(
                    -radius + spacing.x * (i as f64 + 0.5),
                    -radius + spacing.y * (j as f64 + 0.5),
                    spacing.z * (k as f64 + 0.5),
                );
                if l.xy().norm() <= radius {
                    out.push(base + f * l);
                }
            }
        }
    }
    out
}

/// Two unit vectors completing the unit `a` to a right-handed orthonormal basis.
fn perpendicular_basis(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    // Cross with the coordinate axis least aligned with a: never near-parallel.
    let i = a.iamin();
    let mut e = Vector3::zeros();
    e[i] = 1.0;
    let u = a.cross(&e).normalize();
    (u, a.cross(&u))
}
/// Validation of `insertions[i].region`.
impl super::super::validate::Validator<'_> {
    pub(in crate::scene) fn region(
        &mut self,
        p: &str,
        r: &schema::RegionSection,
        scene: &Scene,
        kind: usize,
    ) -> Region {
        let present = [
            ("min", r.min.is_some()),
            ("max", r.max.is_some()),
            ("base", r.base.is_some()),
            ("axis", r.axis.is_some()),
            ("radius", r.radius.is_some()),
            ("height", r.height.is_some()),
        ];
        let key = |f: &str| format!("{p}.{f}");
        let region = match r.kind {
            schema::RegionKind::Box => {
                self.only(p, "box", &present, &["min", "max"]);
                let min = self.required(&key("min"), "box", r.min, [0.0; 3]);
                let max = self.required(&key("max"), "box", r.max, [1.0; 3]);
                let (min, max) = (self.vector(&key("min"), min), self.vector(&key("max"), max));
                if (0..3).any(|a| max[a] <= min[a]) {
                    self.err(&key("max"), "must exceed min on every axis");
                }
                Region::Box { min, max }
            }
            schema::RegionKind::Cylinder => {
                let k = "cylinder";
                self.only(p, k, &present, &["base", "axis", "radius", "height"]);
                let base = self.required(&key("base"), k, r.base, [0.0; 3]);
                let axis = self.required(&key("axis"), k, r.axis, [0.0, 0.0, 1.0]);
                let radius = self.required(&key("radius"), k, r.radius, 1.0);
                let height = self.required(&key("height"), k, r.height, 1.0);
                Region::Cylinder {
                    base: self.vector(&key("base"), base),
                    axis: self.direction(&key("axis"), axis).into_inner(),
                    radius: self.positive(&key("radius"), radius),
                    height: self.positive(&key("height"), height),
                }
            }
        };
        let (lo, hi) = region.aabb();
        let d = &scene.domain;
        if (0..3).any(|a| lo[a] < d.min[a] || hi[a] > d.max[a]) {
            self.err(
                p,
                format!(
                    "region (bounding box {:?} to {:?}) is not inside the domain {:?} to {:?}",
                    lo.as_slice(),
                    hi.as_slice(),
                    d.min.as_slice(),
                    d.max.as_slice()
                ),
            );
        }
        let fits = scene.particle_types.get(kind).and_then(|t| {
            let tpl = scene.templates.get(t.template)?;
            Some((
                tpl.circumscribed_radius * scene.scale_distributions.get(kind)?.max_scale(),
                t,
            ))
        });
        if let Some((r, t)) = fits.filter(|(r, _)| !region.fits(*r)) {
            self.err(
                p,
                format!(
                    "too small for particles of type \"{}\" (bounding diameter up to {:.4e} m)",
                    t.name,
                    2.0 * r
                ),
            );
        }
        region
    }
}
