//! Lattices and packings in cylinder regions (docs/scene.md, `[[insertions]]`): a silo or a
//! tube filled at the start without random tries. The sites kept are those inside the
//! cylinder, bottom up; a tiled packing keeps the particles whose bounding sphere lies inside,
//! each at its image's distance from the others.

mod common;

use common::temp_dir;
use polydem::io::Packing;
use polydem::pipeline::Simulation;
use polydem::scene::{SceneError, parse_scene};

/// A closed box without gravity holding 1 mm spheres, with one insertion (TOML lines after
/// `type`).
fn scene(insertion: &str) -> String {
    format!(
        r#"gravity = [0.0, 0.0, 0.0]
[simulation]
dt_fraction = 0.05
end_time = 1.0
[domain]
min = [-0.02, -0.02, -0.001]
max = [0.02, 0.02, 0.03]
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
generator = {{ kind = "sphere", size = 0.001 }}
[[insertions]]
type = "sphere"
{insertion}
"#
    )
}

#[test]
fn a_lattice_fills_a_cylinder_bottom_up_with_the_sites_inside() {
    // Radius 5.5 spacings: the 11 × 11 sites of the square around it whose centre lies inside
    // the circle, counted here directly; 4 levels along the axis.
    let (s, r) = (0.0012, 0.0066);
    let inside = (0..11)
        .flat_map(|i| (0..11).map(move |j| (i, j)))
        .filter(|&(i, j)| {
            let x = -r + s * (i as f64 + 0.5);
            let y = -r + s * (j as f64 + 0.5);
            (x * x + y * y).sqrt() <= r
        })
        .count();
    assert_eq!(
        inside, 97,
        "the circle of 5.5 spacings holds 97 sites of the square grid"
    );
    let region = format!(
        "region = {{ kind = \"cylinder\", base = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0], radius = {r}, height = {} }}\nlattice = [{s}, {s}, {s}]",
        4.0 * s
    );
    let dir = temp_dir("cylinder-lattice");
    let full = parse_scene(
        &scene(&format!("{region}\ncount = {}", 4 * inside)),
        &dir,
        "c.toml",
    )
    .unwrap();
    let sim = Simulation::builder(full).build().unwrap();
    let p = &sim.state.particles;
    assert_eq!(p.len(), 4 * inside);
    for (k, x) in p.position.iter().enumerate() {
        assert!(
            x.xy().norm() <= r * (1.0 + 1e-12),
            "a site outside the cylinder"
        );
        let level = ((x.z / s) - 0.5).round();
        assert!(
            (x.z - s * (level + 0.5)).abs() < 1e-12,
            "a site off the lattice"
        );
        assert_eq!(
            level as usize,
            k / inside,
            "bottom up, one level after the other"
        );
    }
    // Two levels and a half: the lowest sites first.
    let part = parse_scene(
        &scene(&format!("{region}\ncount = {}", 2 * inside + 10)),
        &dir,
        "c.toml",
    )
    .unwrap();
    let sim = Simulation::builder(part).build().unwrap();
    let top = sim
        .state
        .particles
        .position
        .iter()
        .map(|x| x.z)
        .fold(0.0, f64::max);
    assert!(
        (top - 2.5 * s).abs() < 1e-12,
        "the partial level is the third: {top}"
    );
    // One more than the sites is refused, with the count named.
    let e: SceneError = parse_scene(
        &scene(&format!("{region}\ncount = {}", 4 * inside + 1)),
        &dir,
        "c.toml",
    )
    .unwrap_err();
    assert!(
        e.keys().contains(&"insertions[0].count")
            && e.to_string()
                .contains(&format!("{} points in the cylinder", 4 * inside)),
        "{e}"
    );
}

/// A packing file of spheres of 1 mm on a simple cubic cell of 1.1 mm holding one sphere, with
/// a second sphere offset half a cell: the tiling's distances are known.
fn two_sphere_packing(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("two.packing");
    std::fs::write(
        &path,
        "# polydem packing 1\ncell 0.0022 0.0022 0.0022\nparticles 2\n\
         0.00055 0.00055 0.00055 1 0 0 0 1\n0.00165 0.00165 0.00165 1 0 0 0 1\n",
    )
    .unwrap();
    assert_eq!(Packing::read(&path).unwrap().particles.len(), 2);
    path
}

#[test]
fn a_packing_tiled_in_a_cylinder_keeps_the_spheres_inside_at_their_distances() {
    let dir = temp_dir("cylinder-packing");
    let packing = two_sphere_packing(&dir);
    let (r, h): (f64, f64) = (0.0075, 0.0088);
    let region = format!(
        "region = {{ kind = \"cylinder\", base = [0.001, -0.002, 0.0], axis = [0.0, 0.0, 1.0], radius = {r}, height = {h} }}\npacking = \"{}\"",
        packing.display()
    );
    // As many as fit: refused above, and the message gives the number.
    let e = parse_scene(&scene(&format!("{region}\ncount = 100000")), &dir, "p.toml").unwrap_err();
    let msg = e.to_string();
    let kept: usize = msg
        .split("has ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{msg}"));
    // Roughly the cell's density (2 per 0.0022³) over the cylinder shrunk by a radius; the
    // lattice's ragged ends and rim make up the rest (checked exactly below).
    let volume = std::f64::consts::PI * (r - 0.0005).powi(2) * (h - 0.001);
    let expected = 2.0 * volume / 0.0022f64.powi(3);
    assert!(
        (kept as f64 - expected).abs() < 0.25 * expected,
        "{kept} kept, {expected:.0} expected from the volume"
    );
    let s = parse_scene(&scene(&format!("{region}\ncount = {kept}")), &dir, "p.toml").unwrap();
    let sim = Simulation::builder(s).build().unwrap();
    let p = &sim.state.particles;
    assert_eq!(p.len(), kept);
    let mut closest = f64::INFINITY;
    for (i, x) in p.position.iter().enumerate() {
        let d = x - nalgebra::Vector3::new(0.001, -0.002, 0.0);
        assert!(
            d.xy().norm() <= r - 0.0005 + 1e-12,
            "a sphere pokes out of the side"
        );
        assert!(
            d.z >= 0.0005 - 1e-12 && d.z <= h - 0.0005 + 1e-12,
            "a sphere pokes out of an end"
        );
        for y in &p.position[i + 1..] {
            closest = closest.min((x - y).norm());
        }
    }
    // The nearest images are half a cell diagonal apart: √3 × 1.1 mm.
    assert!(
        (closest - 0.0011 * 3f64.sqrt()).abs() < 1e-12,
        "closest pair {closest}"
    );
    // None missing: the tiling is a body-centred lattice, connected through its eight
    // neighbours at (±1.1, ±1.1, ±1.1) mm (a set any quarter turn about z keeps), so every
    // neighbour of a kept sphere that would lie inside is kept too.
    let fits = |d: nalgebra::Vector3<f64>| {
        d.xy().norm() <= r - 0.0005 - 1e-12 && d.z >= 0.0005 + 1e-12 && d.z <= h - 0.0005 - 1e-12
    };
    let base = nalgebra::Vector3::new(0.001, -0.002, 0.0);
    for x in &p.position {
        for k in 0..8 {
            let o = nalgebra::Vector3::new(
                if k & 1 == 0 { 0.0011 } else { -0.0011 },
                if k & 2 == 0 { 0.0011 } else { -0.0011 },
                if k & 4 == 0 { 0.0011 } else { -0.0011 },
            );
            if fits(x + o - base) {
                assert!(
                    p.position.iter().any(|y| (y - (x + o)).norm() < 1e-12),
                    "the neighbour at {:?} of a kept sphere is missing",
                    x + o
                );
            }
        }
    }
}
