//! Rounded edges and corners (`polydem::shape::rounded`, `[[particle_types]] rounding`): the
//! planes against the ball-swept solid `T ⊕ B_ρ` they stand for (tangent to it, and its volume by
//! Steiner's formula as a lower bound), the volumes against the brute-force half-space oracle of
//! tests/common, and the refusals.

mod common;

use common::*;
use nalgebra::Vector3;
use polydem::shape::{ConvexTemplate, Generator, MAX_ROUNDING, rounded, tangent_planes};

/// Volume of `T ⊕ B_ρ` by Steiner's formula for a convex polytope:
/// `V + S ρ + ρ² Σ_e L_e α_e / 2 + 4π ρ³ / 3`, α_e the angle between the normals of the faces at
/// edge e (π minus the dihedral angle), L_e its length.
fn steiner_volume(t: &ConvexTemplate, rho: f64) -> f64 {
    let area: f64 = t
        .faces
        .iter()
        .map(|f| {
            let p: Vec<Vector3<f64>> = f
                .vertices
                .iter()
                .map(|&v| t.vertices[v as usize].coords)
                .collect();
            (1..p.len() - 1)
                .map(|k| (p[k] - p[0]).cross(&(p[k + 1] - p[0])).dot(&f.normal) / 2.0)
                .sum::<f64>()
        })
        .sum();
    let mut edges = 0.0;
    for &[a, b] in &t.edges {
        let at = |v: u32| t.faces.iter().filter(move |f| f.vertices.contains(&v));
        let normals: Vec<Vector3<f64>> = at(a)
            .filter(|f| f.vertices.contains(&b))
            .map(|f| f.normal)
            .collect();
        assert_eq!(normals.len(), 2, "{}: edge {a}-{b}", t.name);
        let length = (t.vertices[a as usize] - t.vertices[b as usize]).norm();
        edges += length * normals[0].dot(&normals[1]).clamp(-1.0, 1.0).acos() / 2.0;
    }
    t.volume + area * rho + edges * rho * rho + 4.0 / 3.0 * std::f64::consts::PI * rho.powi(3)
}

fn shapes() -> Vec<ConvexTemplate> {
    let mut out: Vec<ConvexTemplate> = [
        Generator::Tetrahedron { size: 1.0 },
        Generator::Cube { size: 1.0 },
        Generator::Octahedron { size: 1.0 },
        Generator::Dodecahedron { size: 1.0 },
        Generator::Icosahedron { size: 1.0 },
    ]
    .iter()
    .map(|g| g.build().unwrap())
    .collect();
    out.push(
        ConvexTemplate::from_file(&repo_root().join("meshes/particles/mineral_grain.stl"))
            .unwrap()
            .scaled(1000.0)
            .unwrap(),
    );
    out
}

/// Every plane touches `T ⊕ B_ρ` (its offset is the support of T along its normal plus ρ, so
/// the normal lies in its feature's normal cone), the polytope holds `T ⊕ B_ρ` (its volume, by the
/// oracle, at least Steiner's) and cuts most of what the faces alone leave beyond it, and the
/// rounded template has one face per face, edge and corner (the regular solids) at the sharp
/// template's volume, with
/// its circumscribed radius falling as the rounding grows. Measured: the cut planes leave
/// 15–26 % of the faces-only excess over the swept solid.
#[test]
fn rounded_grains_circumscribe_the_ball_swept_solid_at_the_same_volume() {
    for t in shapes() {
        let r = t.circumscribed_radius;
        let (f, e, v) = (t.faces.len(), t.edges.len(), t.vertices.len());
        let mut last_radius = r;
        for fraction in [0.02, 0.1, 0.3, MAX_ROUNDING] {
            let rho = fraction * r;
            let planes = tangent_planes(&t, rho);
            assert_eq!(planes.len(), f + e + v, "{}", t.name);
            for (n, o) in &planes {
                let support = t
                    .vertices
                    .iter()
                    .map(|x| n.dot(&x.coords))
                    .fold(f64::MIN, f64::max);
                assert!(
                    (support + rho - o).abs() <= 1e-12 * r,
                    "{} at {fraction}: a plane {:.3e} off the swept solid",
                    t.name,
                    support + rho - o
                );
            }
            let oracle = oracle_intersection(&planes, 2.0 * r);
            let polytope = oracle.volume;
            let faces_only = oracle_intersection(&planes[..f], 2.0 * r).volume;
            let swept = steiner_volume(&t, rho);
            let kept = (polytope - swept) / (faces_only - swept);
            println!(
                "{} rounded {fraction}: V {polytope:.6} against the swept {swept:.6} \
                 (faces alone {faces_only:.6}): {:.1} % of the excess left",
                t.name,
                100.0 * kept
            );
            assert!(
                polytope >= swept * (1.0 - 1e-12),
                "{}: {polytope} < {swept}",
                t.name
            );
            assert!(kept < 0.35, "{} at {fraction}: {kept:.3}", t.name);

            // A cut between faces that meet almost flat (the grain's triangles) is a strip
            // thinner than the hull's coplanarity tolerance and merges into its neighbour.
            let g = rounded(&t, fraction).unwrap();
            if t.name == "mineral_grain" {
                assert!(g.faces.len() <= f + e + v && g.faces.len() > f + v);
            } else {
                assert_eq!(g.faces.len(), f + e + v, "{} at {fraction}", t.name);
            }
            assert!(
                (g.volume - t.volume).abs() <= 1e-12 * t.volume,
                "{} at {fraction}: volume {} against {}",
                t.name,
                g.volume,
                t.volume
            );
            // The same polytope, scaled: its volume ratio fixes the scale, and the oracle's
            // polytope scaled by it has the template's circumscribed radius.
            let s = (t.volume / polytope).cbrt();
            let far = g
                .vertices
                .iter()
                .map(|x| x.coords.norm())
                .fold(0.0, f64::max);
            let corner_radius = oracle
                .vertices
                .iter()
                .map(|x| (x - oracle.centroid).norm())
                .fold(0.0, f64::max)
                * s;
            // (The grain's merged strips move its hull by round-off of the merge, ~1e-8.)
            let tol = if t.name == "mineral_grain" {
                1e-7
            } else {
                1e-12
            };
            assert!(
                (far - corner_radius).abs() <= tol * r,
                "{} at {fraction}: circumscribed {far} against the oracle's {corner_radius}",
                t.name
            );
            assert!(g.circumscribed_radius < last_radius, "{}", t.name);
            assert!(g.circumscribed_radius > g.equivalent_radius, "{}", t.name);
            last_radius = g.circumscribed_radius;
        }
    }
}

fn refusal(t: &ConvexTemplate, fraction: f64) -> String {
    rounded(t, fraction).unwrap_err().to_string()
}

/// What cannot be rounded says why: a fraction outside (0, 0.5], a sphere, and a template whose
/// faces, edges and corners are more planes than a template may have (the 24-gon catalyst:
/// 26 + 72 + 48 = 146).
#[test]
fn rounding_refuses_what_it_cannot_build() {
    let dodecahedron = Generator::Dodecahedron { size: 1.0 }.build().unwrap();
    for bad in [0.0, -0.1, f64::NAN, 0.51, f64::INFINITY] {
        let e = refusal(&dodecahedron, bad);
        assert!(e.contains("must be in (0, 0.5]"), "{bad}: {e}");
    }
    let sphere = Generator::Sphere { size: 1.0 }.build().unwrap();
    assert!(refusal(&sphere, 0.1).contains("a sphere has no edges"));
    let catalyst =
        ConvexTemplate::from_file(&repo_root().join("meshes/particles/catalyst_cylinder.stl"))
            .unwrap();
    let e = refusal(&catalyst, 0.1);
    assert!(
        e.contains("26 faces, 72 edges and 48 corners make 146 faces")
            && e.contains("MAX_TEMPLATE_FACES"),
        "{e}"
    );
}

/// In a scene, `rounding` gives its type a template of its own (a sharp type of the same mesh
/// keeps the sharp one), and a bad value is named by its key.
#[test]
fn the_rounding_key_makes_its_own_template() {
    let text = |rounding: &str| {
        format!(
            r#"
[simulation]
end_time = 0.1
[domain]
min = [-0.1, -0.1, -0.1]
max = [0.1, 0.1, 0.1]
[[materials]]
name = "g"
youngs_modulus = 1e6
poisson_ratio = 0.3
density = 1000.0
[[material_pairs]]
materials = ["g", "g"]
restitution = 0.5
friction = 0.5
[[particle_types]]
name = "sharp"
material = "g"
mesh = "meshes/particles/dodecahedron.stl"
scale = 0.01
[[particle_types]]
name = "round"
material = "g"
mesh = "meshes/particles/dodecahedron.stl"
scale = 0.01
rounding = {rounding}
"#
        )
    };
    let scene = polydem::scene::parse_scene(&text("0.1"), &repo_root(), "rounding.toml").unwrap();
    let faces: Vec<usize> = scene
        .particle_types
        .iter()
        .map(|p| scene.templates[p.template].faces.len())
        .collect();
    assert_eq!(faces, [12, 62]);
    let e = polydem::scene::parse_scene(&text("0.8"), &repo_root(), "rounding.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("particle_types[1].rounding") && e.contains("must be in (0, 0.5]"),
        "{e}"
    );
}
