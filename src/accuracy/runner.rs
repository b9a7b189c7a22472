//! What every case shares: the scratch folder with its generated wall meshes, the scene text
//! built from a [`Spec`], the dispatch by case name, and stepping through one impact.

use crate::backend::{Device, Engine};
use crate::pipeline::Simulation;
use crate::scene::parse_scene;
use crate::shape::MeshFile;
use anyhow::{Context, Result, anyhow};
use nalgebra::Point3;
use std::path::{Path, PathBuf};

/// Scratch folder, the repository's meshes, the generated walls.
pub(super) struct CaseRunner {
    pub(super) dir: PathBuf,
    pub(super) root: PathBuf,
}

/// The repository root (its `meshes/`): `POLYDEM_ROOT`, else the working folder, else the
/// source tree this binary was built from.
fn repo_root() -> PathBuf {
    if let Some(r) = &crate::tuning::Tuning::get().root {
        return r.clone();
    }
    let here = PathBuf::from(".");
    if here.join("meshes/particles/cylinder_42.stl").is_file() {
        return here;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A flat square wall `[−h, h]²` at z = 0 facing +z, cut into n × n cells of two triangles
/// (alternating diagonals, interior nodes shifted by a third of a cell along x).
fn write_plane(path: &Path, h: f64, n: usize) -> Result<()> {
    let c = 2.0 * h / n as f64;
    let coord = |i: usize| -h + i as f64 * c;
    let mut vertices = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let shift = if i > 0 && i < n { c / 3.0 } else { 0.0 };
            vertices.push(Point3::new(coord(i) + shift, coord(j), 0.0));
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut triangles = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let (a, b, cc, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                triangles.extend([[a, b, cc], [a, cc, d]]);
            } else {
                triangles.extend([[a, b, d], [b, cc, d]]);
            }
        }
    }
    MeshFile {
        vertices,
        triangles,
    }
    .write_stl(path)
    .with_context(|| format!("{}: cannot write", path.display()))
}

/// Material and set-up of one scene.
pub(super) struct Spec<'a> {
    pub(super) e_modulus: f64,
    pub(super) poisson: f64,
    pub(super) density: f64,
    pub(super) restitution: f64,
    pub(super) friction: f64,
    pub(super) fraction: f64,
    /// Domain `[lo, hi]³`, periodic on every axis when set.
    pub(super) domain: (f64, f64),
    pub(super) periodic: bool,
    pub(super) types: &'a str,
    /// A wall mesh at z = 0, if any.
    pub(super) wall: Option<&'a Path>,
}

impl CaseRunner {
    pub(super) fn new(out: &Path) -> Result<Self> {
        let dir = out.join("cases");
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        // Absolute: the cases' scenes name their meshes from here, and are read relative to
        // the repository root, not the working folder (a relative `--out`, the default, named
        // meshes that did not exist outside the repository).
        let dir = std::path::absolute(&dir)
            .with_context(|| format!("{}: cannot resolve", dir.display()))?;
        write_plane(&dir.join("plane.stl"), 1.0, 1)?;
        write_plane(&dir.join("mesh_coarse.stl"), 0.2, 8)?; // λ = 0.5 for the 2.5 cm cuboid
        write_plane(&dir.join("mesh_fine.stl"), 0.2, 64)?; // λ = 4
        Ok(CaseRunner {
            dir,
            root: repo_root(),
        })
    }

    pub(super) fn simulation(&self, spec: &Spec) -> Result<Simulation> {
        let wall = spec.wall.map_or(String::new(), |w| {
            format!(
                "[[walls]]\nname = \"wall\"\nmesh = \"{}\"\nmaterial = \"m\"\n",
                w.display()
            )
        });
        let (lo, hi) = spec.domain;
        let text = format!(
            r#"gravity = [0.0, 0.0, 0.0]
[simulation]
dt_fraction = {}
end_time = 1.0
seed = 1
[domain]
min = [{lo:e}, {lo:e}, {lo:e}]
max = [{hi:e}, {hi:e}, {hi:e}]
periodic = [{p}, {p}, {p}]
[[materials]]
name = "m"
youngs_modulus = {:e}
poisson_ratio = {}
density = {:e}
[[material_pairs]]
materials = ["m", "m"]
restitution = {}
friction = {}
{}
{wall}
[output]
dir = "{}"
"#,
            spec.fraction,
            spec.e_modulus,
            spec.poisson,
            spec.density,
            spec.restitution,
            spec.friction,
            spec.types,
            self.dir.join("out").display(),
            p = spec.periodic,
        );
        let scene = parse_scene(&text, &self.root, "accuracy.toml")?;
        Ok(Simulation::builder(scene).build()?)
    }

    pub(super) fn run(&self, case: &str, device: Device, f: f64) -> Result<(f64, u64, String)> {
        match case {
            "cylinder_impact" => self.cylinder_impact(device, f),
            "restitution" => self.restitution(device, f),
            "elastic_impact" => self.elastic_impact(device, f),
            "elastic_energy" => self.elastic_energy(device, f),
            "mesh_independence" => self.mesh_independence(device, f),
            "sphere_oblique" => self.sphere_oblique(device, f),
            "sphere_sticking" => self.sphere_sticking(device, f),
            "friction_energy" => self.friction_energy(device, f),
            "pour_packing" => self.pour_packing(device, f),
            _ => Err(anyhow!("unknown accuracy case {case}")),
        }
    }

    /// Steps until a contact has begun and ended (at most `limit` steps); returns the steps.
    pub(super) fn impact(e: &mut Engine, limit: u64) -> Result<u64> {
        let (mut touched, mut steps) = (false, 0);
        while steps < limit {
            e.step()?;
            steps += 1;
            let (pairs, walls) = e.contact_counts()?;
            if pairs + walls > 0 {
                touched = true;
            } else if touched {
                return Ok(steps);
            }
        }
        Err(anyhow!("no complete impact within {limit} steps"))
    }
}
