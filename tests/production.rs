//! The production scenes of `launch/production/` (docs/production.md): their wall meshes as
//! `make_meshes.py` states them, and each case's small twin (`launch/production/twins/`), run
//! to its end on the CPU, giving its observable with the right sign and order of magnitude.

mod common;

use common::*;
use nalgebra::Vector3;
use polydem::analysis::{self, Disk};
use polydem::pipeline::Simulation;
use polydem::scene::{WallPlacement, load_scene, load_wall_mesh};
use std::f64::consts::PI;

/// The twin `scene` (under `launch/production/twins/`) run to its end on the CPU.
fn run_twin(scene: &str) -> Simulation {
    let scene = load_scene(&repo_root().join("launch/production/twins").join(scene)).unwrap();
    let end = scene.simulation.end_time;
    let mut sim = Simulation::builder(scene).build().unwrap();
    while sim.time < end {
        sim.step().unwrap();
    }
    sim
}

fn triangles(file: &str) -> Vec<[Vector3<f64>; 3]> {
    let path = repo_root().join("launch/production/meshes").join(file);
    load_wall_mesh(&path, &WallPlacement::default())
        .unwrap()
        .triangles
}

fn normal(t: &[Vector3<f64>; 3]) -> Vector3<f64> {
    (t[1] - t[0]).cross(&(t[2] - t[0])).normalize()
}

fn centroid(t: &[Vector3<f64>; 3]) -> Vector3<f64> {
    (t[0] + t[1] + t[2]) / 3.0
}

/// Every triangle of a vertical tube of radius `r` from z = 0 to `height` with a floor: the
/// side faces the axis, the floor faces up, and every vertex lies on the circle or the axis.
fn check_tube(file: &str, r: f64, height: f64, segments: usize, rings: usize) {
    let tris = triangles(file);
    assert_eq!(
        tris.len(),
        segments + 2 * segments * rings,
        "{file}: triangles"
    );
    for t in &tris {
        let (c, n) = (centroid(t), normal(t));
        if c.z.abs() < 1e-9 {
            assert!(n.z > 0.999_999, "{file}: the floor faces up");
        } else {
            assert!(n.z.abs() < 1e-6, "{file}: the side is vertical");
            assert!(
                n.dot(&Vector3::new(-c.x, -c.y, 0.0)) > 0.0,
                "{file}: the side faces the axis"
            );
        }
        for v in t {
            let rho = v.xy().norm();
            assert!(
                rho < 1e-9 || (rho - r).abs() < 1e-6 * r,
                "{file}: a vertex at radius {rho}"
            );
            assert!(
                v.z > -1e-9 && v.z < height + 1e-6,
                "{file}: a vertex at z = {}",
                v.z
            );
        }
    }
    let top = tris.iter().flatten().map(|v| v.z).fold(0.0, f64::max);
    assert!((top - height).abs() < 1e-6, "{file}: top at {top}");
}

#[test]
fn production_meshes_are_what_make_meshes_py_states() {
    check_tube("dodecahedra_cylinder.stl", 0.05, 0.20, 96, 4);
    check_tube("fixed_bed_tube.stl", 0.0125, 1.80, 64, 90);
    check_tube("fixed_bed_tube_twin.stl", 0.0125, 0.10, 24, 5);
    // The drum: a ring of radius 0.15 m about the y axis, 11 mm deep, facing the axis, and two
    // end plates facing each other.
    let drum = triangles("drum.stl");
    assert_eq!(drum.len(), 4 * 192);
    for t in &drum {
        let (c, n) = (centroid(t), normal(t));
        if (c.y.abs() - 0.0055).abs() < 1e-9 {
            assert!(
                (n.y + c.y.signum()).abs() < 1e-6,
                "the end plates face each other"
            );
        } else {
            assert!(
                n.y.abs() < 1e-6 && n.dot(&Vector3::new(-c.x, 0.0, -c.z)) > 0.0,
                "the rim faces the axis"
            );
        }
    }
}

/// Case 1's twin: 16 of the seed's dodecahedra (30.8 mm) dropped into its 10 cm cylinder come
/// to rest as a bed whose top surface is where their volume at a random packing's solid
/// fraction puts it.
#[test]
fn dodecahedra_settle_in_the_cylinder_to_a_random_packing() {
    let sim = run_twin("dodecahedra_cylinder.toml");
    let p = &sim.particles;
    assert_eq!(p.len(), 16);
    // Come to rest: the fastest grain moves at less than 5 % of the speed of a fall through
    // its own size (0.78 m/s).
    let fastest = p.velocity.iter().map(|v| v.norm()).fold(0.0, f64::max);
    let scale = (2.0 * 9.81 * 0.0308f64).sqrt();
    assert!(
        fastest < 0.05 * scale,
        "fastest grain at {fastest} m/s: not settled"
    );
    // Every grain inside the cylinder, above the floor.
    for x in &p.position {
        assert!(
            x.xy().norm() < 0.05 && x.z > 0.0,
            "a grain at {x:?} is outside the cylinder"
        );
    }
    let solids = analysis::solids_of(&sim.scene, p);
    let disk = Disk {
        centre: [0.0, 0.0],
        radius: 0.05,
        floor: 0.0,
    };
    let fill = analysis::fill_height(&solids, &disk, 0.0005);
    // 16 dodecahedra of 1.017e-5 m³ at a solid fraction φ fill H = 16 V / (φ π R²): 5.2 cm
    // at the loosest random packing of dodecahedra (0.40 with walls this close), 3.2 cm at the
    // densest (0.65); a grain's height lying flat is 2.45 cm.
    let volume = 16.0 * 0.348_145 * 0.0308f64.powi(3);
    let h = |phi: f64| volume / (phi * PI * 0.05 * 0.05);
    println!("twin fill: {fill:?}");
    assert!(
        fill.mean_surface > h(0.65) && fill.mean_surface < h(0.40),
        "mean surface {} m",
        fill.mean_surface
    );
    // The top layer is partial: its highest grain stands at most two grains above the mean.
    assert!(fill.highest > fill.mean_surface && fill.highest < fill.mean_surface + 2.0 * 0.0308);
}

/// Case 3's twin: 30 catalyst pellets (5.5 mm × 5.5 mm prisms) rained into the 25 mm tube form
/// a bed whose porosity is a random packing's, and which is looser at the wall than inside
/// it (the wall effect of a narrow tube, D/d = 4.5).
#[test]
fn catalyst_pellets_pack_looser_at_the_tube_wall() {
    let sim = run_twin("fixed_bed.toml");
    let p = &sim.particles;
    assert_eq!(p.len(), 30);
    for x in &p.position {
        assert!(
            x.xy().norm() < 0.0125 && x.z > 0.0,
            "a pellet at {x:?} is outside the tube"
        );
    }
    let solids = analysis::solids_of(&sim.scene, p);
    let fill = analysis::fill_height(
        &solids,
        &Disk {
            centre: [0.0, 0.0],
            radius: 0.0125,
            floor: 0.0,
        },
        0.0002,
    );
    // Below the uneven top: from the floor to one pellet under the mean surface.
    let tube = analysis::Tube {
        centre: [0.0, 0.0],
        radius: 0.0125,
        z: [0.0005, fill.mean_surface - 0.0055],
    };
    assert!(
        tube.z[1] > tube.z[0] + 0.004,
        "bed only {} m high",
        fill.mean_surface
    );
    let profile = analysis::radial_porosity(&solids, &tube, 25, 0.00025);
    println!("twin bed: {fill:?}\n{profile:?}");
    // Random packings of cylinders of aspect 1 in tubes of D/d 4–5: 0.35–0.5 (the correlations
    // of docs/production.md §3); a bed this shallow is looser still near the floor.
    assert!(
        profile.mean > 0.3 && profile.mean < 0.65,
        "bed porosity {}",
        profile.mean
    );
    assert!(
        profile.porosity[0] > profile.mean + 0.1,
        "porosity within 0.5 mm of the wall {} against {} in all",
        profile.porosity[0],
        profile.mean
    );
}
