//! Observables of a saved state (`polydem analyze`): what production runs are compared with
//! experiments on (docs/production.md).
//!
//! - [`solids`]: the particles as solids: point coverage and vertical reach, on a grid.
//! - [`fill`]: fill height and bulk solid fraction in a vertical container.
//! - [`porosity`]: porosity of a tube section, overall and by distance from the wall.
//! - [`command`]: the `polydem analyze` subcommands and their checks.
//! - [`drum`]: the averaged flow of a rotating drum, its angle of repose and flowing layer.

pub mod command;
pub mod drum;
pub mod fill;
pub mod porosity;
pub mod solids;

pub use command::{AnalyzeWhat, AnalyzedCylinder, analyze};
pub use drum::{DrumFlow, DrumSamples, DrumSection, FieldCell};
pub use fill::{Disk, FillHeight, HeapProfile, fill_height, heap_profile};
pub use porosity::{RadialPorosity, Tube, radial_porosity};
pub use solids::PackedSolids;

use crate::io::read_checkpoint;
use crate::scene::restart::{SceneFingerprint, check_against_scene};
use crate::scene::{Scene, load_scene};
use crate::state::Particles;
use anyhow::{Context, Result, anyhow};
use std::path::Path;

/// A scene and the particles of one of its checkpoints, refused when the checkpoint was
/// written for another scene (the restart rule: docs/scene.md, Restarts) or when a particle
/// does not fit the scene (a kind it does not have, a mass its type does not give: the checks
/// of a restart, `check_against_scene`), naming the file and the field.
pub fn load_state(scene: &Path, checkpoint: &Path) -> Result<(Scene, Particles)> {
    let s = load_scene(scene).with_context(|| format!("scene {}", scene.display()))?;
    let c = read_checkpoint(checkpoint)?;
    SceneFingerprint::of(&s)
        .check(&c, 0)
        .map_err(|e| anyhow!("{}: {e}", checkpoint.display()))?;
    check_against_scene(&c, &s).map_err(|e| anyhow!("{}: {e}", checkpoint.display()))?;
    Ok((s, c.particles))
}

/// The least-squares line `y = a + b x` through `points` (`[x, y]` each): `[a, b]`, with
/// b = 0 when the x do not vary.
pub(crate) fn fit_line(points: &[[f64; 2]]) -> [f64; 2] {
    let m = points.len().max(1) as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p[0] / m, b + p[1] / m));
    let (sxx, sxy) = points.iter().fold((0.0, 0.0), |(a, b), p| {
        (a + (p[0] - mx) * (p[0] - mx), b + (p[0] - mx) * (p[1] - my))
    });
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    [my - b * mx, b]
}

/// The particle tables of a run's frames (`<output>/particles/`, [`crate::io::write_particle_csv`]),
/// grouped by frame in step order: one table per frame, or one per rank
/// (`step_<step>_r<rank>.csv`) of a decomposed run. Files of other names are ignored.
pub fn frame_tables(dir: &Path) -> Result<Vec<Vec<std::path::PathBuf>>> {
    let mut by_step: std::collections::BTreeMap<u64, Vec<std::path::PathBuf>> = Default::default();
    for entry in
        std::fs::read_dir(dir).with_context(|| format!("{}: cannot list frames", dir.display()))?
    {
        let path = entry
            .with_context(|| format!("{}: cannot list frames", dir.display()))?
            .path();
        let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
            continue;
        };
        let Some(stem) = name
            .strip_prefix("step_")
            .and_then(|n| n.strip_suffix(".csv"))
        else {
            continue;
        };
        let step = stem.split("_r").next().unwrap_or(stem);
        if let Ok(step) = step.parse::<u64>() {
            by_step.entry(step).or_default().push(path);
        }
    }
    if by_step.is_empty() {
        anyhow::bail!(
            "{}: no particle tables (step_<step>.csv; a run writes them with output.formats = [\"csv\"])",
            dir.display()
        );
    }
    Ok(by_step
        .into_values()
        .map(|mut v| {
            v.sort();
            v
        })
        .collect())
}

/// The particles of `scene` placed as solids.
pub fn solids_of(scene: &Scene, particles: &Particles) -> PackedSolids {
    PackedSolids::new(&scene.templates, &scene.particle_types, particles)
}

/// The particles of `scene` whose centre lies inside the vertical cylinder of axis
/// `centre` (x, y) and radius `radius`, placed as solids: one container's contents when a
/// scene holds several.
pub fn solids_in_cylinder(
    scene: &Scene,
    particles: &Particles,
    centre: [f64; 2],
    radius: f64,
) -> PackedSolids {
    PackedSolids::within(&scene.templates, &scene.particle_types, particles, |x| {
        (x.x - centre[0]).powi(2) + (x.y - centre[1]).powi(2) <= radius * radius
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::{ConvexTemplate, Generator};
    use crate::state::ParticleType;
    use nalgebra::{UnitQuaternion, Vector3};

    /// One particle of template `t` at `x`, turned by `q`.
    fn one(t: ConvexTemplate, x: Vector3<f64>, q: UnitQuaternion<f64>) -> PackedSolids {
        let types = [ParticleType {
            name: "p".into(),
            template: 0,
            material: 0,
        }];
        let mut p = Particles::default();
        p.push(0, 0, 1.0, x, q, &t, 1000.0);
        PackedSolids::new(&[t], &types, &p)
    }

    fn cube(edge: f64) -> ConvexTemplate {
        Generator::Cube {
            size: edge * 3f64.sqrt(),
        }
        .build()
        .unwrap()
    }

    fn sphere(radius: f64) -> ConvexTemplate {
        Generator::Sphere { size: 2.0 * radius }.build().unwrap()
    }

    #[test]
    fn a_cube_reaches_its_face_or_its_edge() {
        let a = 0.01;
        let x = Vector3::new(0.0, 0.0, 0.1);
        let flat = one(cube(a), x, UnitQuaternion::identity());
        let top = flat.highest_point().unwrap();
        assert!((flat.top_at(0.001, 0.002).unwrap() - 0.105).abs() < 1e-15);
        assert!((top - 0.105).abs() < 1e-15);
        assert!(flat.top_at(0.0051, 0.0).is_none());
        assert!(flat.contains(&Vector3::new(0.0049, -0.0049, 0.0951)));
        assert!(!flat.contains(&Vector3::new(0.0051, 0.0, 0.1)));
        // Turned 45° about x: an edge on top, a/√2 above the centre, falling off with |y|.
        let q = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_4);
        let edge = one(cube(a), x, q);
        let top = edge.highest_point().unwrap();
        let h = a / 2f64.sqrt();
        assert!((top - (0.1 + h)).abs() < 1e-15);
        for y in [0.0, 0.002, -0.004] {
            let z = edge.top_at(0.003, y).unwrap();
            assert!((z - (0.1 + h - f64::abs(y))).abs() < 1e-15, "y {y}: {z}");
        }
        assert!(edge.top_at(0.0, 1.001 * h).is_none());
        assert!(edge.top_at(0.0051, 0.0).is_none());
    }

    #[test]
    fn fill_height_of_a_cube_and_of_a_sphere_on_the_floor() {
        // A 2 cm cube on the floor over a disk of 5 mm: a flat top at 2 cm everywhere.
        let a = 0.02;
        let s = one(
            cube(a),
            Vector3::new(0.0, 0.0, a / 2.0),
            UnitQuaternion::identity(),
        );
        let disk = Disk {
            centre: [0.0, 0.0],
            radius: 0.005,
            floor: 0.0,
        };
        let f = fill_height(&s, &disk, 1e-4);
        assert!((f.mean_surface - a).abs() < 1e-15 && (f.highest - a).abs() < 1e-15);
        let phi = a * a / (std::f64::consts::PI * 0.005 * 0.005);
        assert!((f.solid_fraction - phi).abs() < 1e-12 * phi);
        // A sphere of radius r resting on the floor over a disk of radius r: the mean of
        // r + √(r² − ρ²) over the disk is 5r/3; the grid of r/200 gets it to 3e-4 (the disk's jagged rim).
        let r = 0.01;
        let s = one(
            sphere(r),
            Vector3::new(0.0, 0.0, r),
            UnitQuaternion::identity(),
        );
        let disk = Disk {
            centre: [0.0, 0.0],
            radius: r,
            floor: 0.0,
        };
        let f = fill_height(&s, &disk, r / 200.0);
        assert!((f.highest - 2.0 * r).abs() < 1e-15);
        let err = (f.mean_surface - 5.0 * r / 3.0).abs() / (5.0 * r / 3.0);
        assert!(
            err < 3e-4,
            "mean surface {} against {}: {err:e}",
            f.mean_surface,
            5.0 * r / 3.0
        );
    }

    #[test]
    fn one_container_of_several_counts_only_its_own_particles() {
        // Two cubes of 2 cm and 4 cm in containers 0.1 m apart: each container's fill height
        // is its own cube's, and the volume counted is that cube's alone.
        let (a, b) = (0.02, 0.04);
        let t = cube(1.0);
        let types = [ParticleType {
            name: "p".into(),
            template: 0,
            material: 0,
        }];
        let mut p = Particles::default();
        let q = UnitQuaternion::identity();
        p.push(0, 0, a, Vector3::new(0.0, 0.0, a / 2.0), q, &t, 1000.0);
        p.push(1, 0, b, Vector3::new(0.1, 0.0, b / 2.0), q, &t, 1000.0);
        let container = |centre: [f64; 2]| {
            PackedSolids::within(std::slice::from_ref(&t), &types, &p, |x| {
                (x.x - centre[0]).powi(2) + (x.y - centre[1]).powi(2) <= 0.04 * 0.04
            })
        };
        for (centre, edge) in [([0.0, 0.0], a), ([0.1, 0.0], b)] {
            let s = container(centre);
            assert_eq!(s.len(), 1);
            assert!((s.volume(0) - edge.powi(3)).abs() < 1e-12 * edge.powi(3));
            let disk = Disk {
                centre,
                radius: 0.005,
                floor: 0.0,
            };
            let f = fill_height(&s, &disk, 1e-4);
            assert!(
                (f.highest - edge).abs() < 1e-12 * edge
                    && (f.mean_surface - edge).abs() < 1e-12 * edge,
                "{centre:?}: {f:?}"
            );
        }
    }

    #[test]
    fn a_sphere_cap_heap_has_the_slope_of_its_tangent_cone() {
        // A ball of radius a centred on the axis at height c: its top at distance ρ is
        // c + √(a² − ρ²), so a ring's mean height is exact, and the least-squares line through
        // the rings' heights is the closed form's, computed here from the same rings.
        let (a, c) = (0.05, 0.01);
        let s = one(
            sphere(a),
            Vector3::new(0.0, 0.0, c),
            UnitQuaternion::identity(),
        );
        let disk = Disk {
            centre: [0.0, 0.0],
            radius: 0.04,
            floor: 0.0,
        };
        let h = heap_profile(&s, &disk, 8, 1e-4, [0.2, 0.8]);
        let exact: Vec<f64> = h.radii.iter().map(|r| c + (a * a - r * r).sqrt()).collect();
        for (got, want) in h.heights.iter().zip(&exact) {
            assert!(
                (got - want).abs() < 1e-12,
                "ring height {got} against {want}"
            );
        }
        let pts: Vec<(f64, f64)> = h
            .radii
            .iter()
            .zip(&exact)
            .filter(|(r, _)| **r >= 0.008 - 1e-12 && **r <= 0.032 + 1e-12)
            .map(|(r, z)| (*r, *z))
            .collect();
        assert_eq!(
            pts.len(),
            4,
            "rings at 2.5 … 37.5 mm: the four from 12.5 to 27.5 mm"
        );
        let m = pts.len() as f64;
        let (mr, mz) = pts
            .iter()
            .fold((0.0, 0.0), |(p, q), (r, z)| (p + r / m, q + z / m));
        let slope = pts.iter().map(|(r, z)| (r - mr) * (z - mz)).sum::<f64>()
            / pts.iter().map(|(r, _)| (r - mr) * (r - mr)).sum::<f64>();
        assert!((h.angle_deg - (-slope).atan().to_degrees()).abs() < 1e-9);
        assert!(
            h.angle_deg > 5.0 && h.angle_deg < 45.0,
            "a cap sloping down: {}",
            h.angle_deg
        );
    }

    #[test]
    fn radial_porosity_of_a_sphere_on_the_axis_matches_the_closed_form() {
        // A sphere of radius a on the axis of a tube of radius 2a, the section z ∈ [−a, a]:
        // solid fraction at distance ρ = r/a from the axis √(1 − ρ²) (ρ < 1), so an annulus
        // [ρ0, ρ1] holds 2/3 [(1 − ρ0²)^{3/2} − (1 − ρ1²)^{3/2}] / (ρ1² − ρ0²), and the whole
        // section (4/3 π a³)/(π 4a² 2a) = 1/6.
        let a = 0.01;
        let s = one(sphere(a), Vector3::zeros(), UnitQuaternion::identity());
        let tube = Tube {
            centre: [0.0, 0.0],
            radius: 2.0 * a,
            z: [-a, a],
        };
        let annuli = 20;
        let p = radial_porosity(&s, &tube, annuli, a / 50.0);
        assert!(
            (p.mean - 5.0 / 6.0).abs() < 1e-3,
            "mean porosity {}",
            p.mean
        );
        let cap = |rho: f64| (1.0 - rho.min(1.0).powi(2)).powf(1.5);
        for (d, phi) in p.wall_distance.iter().zip(&p.porosity) {
            let half = tube.radius / annuli as f64 / 2.0;
            let (r1, r0) = ((2.0 * a - d + half) / a, (2.0 * a - d - half) / a);
            let solid = 2.0 / 3.0 * (cap(r0) - cap(r1)) / (r1 * r1 - r0 * r0);
            assert!(
                ((1.0 - phi) - solid).abs() < 4e-3,
                "{d}: porosity {phi}, expected {}",
                1.0 - solid
            );
        }
        assert_eq!(p.porosity[0], 1.0);
        assert!(p.porosity[annuli - 1] < 0.01);
    }
}
