//! `polydem bench accuracy`: run time against error on a fixed set of reference cases, each at
//! several `dt_fraction` values and, on the GPU, in both precisions (docs/accuracy.md).
//!
//! Every case builds its scene from `dt_fraction` (the step is that fraction of the scene's
//! critical step, docs/scene.md), runs it and compares one observable with an independent
//! reference; its error is a dimensionless relative number, so that the cases share one axis:
//!
//! | case | reference | error |
//! |---|---|---|
//! | `cylinder_impact` | rigid-body single-point impact of the seed's faceted cylinder at 30° and 45° (docs/validation.md §1) | max of `|Δv'|/v₀` and `|Δω'| k/v₀` (k the radius of gyration) |
//! | `restitution` | the set e = 0.5, 1 cm cubes vertex-, edge- and face-first on a wall and face on face, 16 touch phases each | max `|e_out − e|/e` |
//! | `elastic_impact` | the same 64 impacts with e = 1 | no energy gained | the worst gain `e_out² − 1` (the default step needs it within 1e-3) |
//! | `elastic_energy` | energy conservation, e = 1: 27 aligned cubes in a periodic box (docs/validation.md §3) | `|ΔE|/E` over the run |
//! | `mesh_independence` | the cuboid pushed across a flat wall meshed at λ = 0.5 and 4 (docs/validation.md §2): the same force curve | max force difference over the force scale |
//! | `sphere_oblique` | rigid-body gross sliding (Chung & Ooi test 6 and the soft sphere at 70°) | max relative error of v_n', v_t', ω' |
//! | `pour_packing` (full only) | `launch/validation/pour.toml`'s bulk packing fraction at the finest step | relative difference |
//!
//! Results go to `accuracy.csv` and the Pareto plot `accuracy.svg` (error against run time,
//! one series per case and precision, dt_fraction marked) in the output folder.

use crate::backend::cuda::Precision;
use crate::backend::{Device, Engine};
use crate::pipeline::Simulation;
use crate::rng::Rng;
use crate::scene::parse_scene;
use crate::shape::MeshFile;
use anyhow::{Context, Result, anyhow};
use nalgebra::{Point3, UnitQuaternion, Vector3};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One case at one step and precision.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AccuracyRow {
    pub case: &'static str,
    /// `cpu`, `gpu double` or `gpu mixed`.
    pub backend: String,
    pub dt_fraction: f64,
    /// Relative error against the case's reference (module docs).
    pub error: f64,
    /// Steps run and wall-clock seconds spent, set-up included.
    pub steps: u64,
    pub seconds: f64,
    /// What the error is made of.
    pub detail: String,
}

/// What to run.
#[derive(Clone, Debug)]
pub struct AccuracyOptions {
    /// Backends (precisions) to run every case on.
    pub devices: Vec<Device>,
    /// Step fractions.
    pub fractions: Vec<f64>,
    /// Also the pour (minutes per step fraction on a GPU, an hour on a CPU core).
    pub full: bool,
    /// Only these cases (names of [`CASES`]); empty: all (the pour only when `full`).
    pub cases: Vec<String>,
    /// Where the CSV, the plot and the cases' scratch files go.
    pub out: PathBuf,
}

/// The cases in order.
pub const CASES: [&str; 7] = [
    "cylinder_impact",
    "restitution",
    "elastic_impact",
    "elastic_energy",
    "mesh_independence",
    "sphere_oblique",
    "pour_packing",
];

/// The step fractions of the short sweep (`make test`) and of the full one.
pub const SHORT_FRACTIONS: [f64; 3] = [0.1, 0.05, 0.025];
pub const FULL_FRACTIONS: [f64; 5] = [0.2, 0.1, 0.05, 0.025, 0.0125];

fn device_name(d: Device) -> String {
    match d {
        Device::Cpu => "cpu".into(),
        Device::Cuda { precision, .. } => match precision {
            Precision::Double => "gpu double".into(),
            Precision::Mixed => "gpu mixed".into(),
        },
    }
}

/// Runs the cases; writes `accuracy.csv` and `accuracy.svg` into `opts.out`.
pub fn run_accuracy(opts: &AccuracyOptions) -> Result<Vec<AccuracyRow>> {
    if let Some(bad) = opts.cases.iter().find(|c| !CASES.contains(&c.as_str())) {
        return Err(anyhow!(
            "--cases: unknown case {bad:?}; the cases are {}",
            CASES.join(", ")
        ));
    }
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("{}: cannot create", opts.out.display()))?;
    let ctx = CaseRunner::new(&opts.out)?;
    let mut rows = Vec::new();
    for &device in &opts.devices {
        for case in CASES {
            let chosen = if opts.cases.is_empty() {
                case != "pour_packing" || opts.full
            } else {
                opts.cases.iter().any(|c| c == case)
            };
            if !chosen {
                continue;
            }
            let mut case_rows = Vec::new();
            for &f in &opts.fractions {
                let t0 = Instant::now();
                let (error, steps, detail) = ctx.run(case, device, f)?;
                let row = AccuracyRow {
                    case,
                    backend: device_name(device),
                    dt_fraction: f,
                    error,
                    steps,
                    seconds: t0.elapsed().as_secs_f64(),
                    detail,
                };
                tracing::info!(
                    "{} {} dt_fraction {}: error {:.3e} ({} steps, {:.2} s) {}",
                    row.case,
                    row.backend,
                    f,
                    row.error,
                    row.steps,
                    row.seconds,
                    row.detail
                );
                case_rows.push(row);
            }
            if case == "pour_packing" {
                // Self-convergence: the finest step is the reference.
                let finest = case_rows
                    .iter()
                    .min_by(|a, b| a.dt_fraction.total_cmp(&b.dt_fraction))
                    .map(|r| r.error)
                    .unwrap_or(f64::NAN);
                for r in &mut case_rows {
                    let phi = r.error;
                    r.detail = format!("packing fraction {phi:.4} (finest step {finest:.4})");
                    r.error = (phi - finest).abs() / finest;
                }
            }
            rows.extend(case_rows);
            // Written after every case, so that a sweep cut short keeps what it measured.
            write_csv(&opts.out.join("accuracy.csv"), &rows)?;
        }
    }
    write_csv(&opts.out.join("accuracy.csv"), &rows)?;
    plot(&opts.out.join("accuracy.svg"), &rows)?;
    Ok(rows)
}

fn write_csv(path: &Path, rows: &[AccuracyRow]) -> Result<()> {
    let mut s = String::from("case,backend,dt_fraction,error,steps,seconds,detail\n");
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{:e},{},{:.4},\"{}\"\n",
            r.case,
            r.backend,
            r.dt_fraction,
            r.error,
            r.steps,
            r.seconds,
            r.detail.replace('"', "'")
        ));
    }
    crate::io::write_atomic(path, s.as_bytes())
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// Error against run time on log axes, one series per case and backend, points labelled by
/// dt_fraction; the 1 % line dashed.
fn plot(path: &Path, rows: &[AccuracyRow]) -> Result<()> {
    use plotters::prelude::*;
    let floor = 1e-7;
    let (mut t_lo, mut t_hi) = (f64::MAX, f64::MIN);
    let (mut e_lo, mut e_hi) = (f64::MAX, f64::MIN);
    for r in rows {
        t_lo = t_lo.min(r.seconds);
        t_hi = t_hi.max(r.seconds);
        e_lo = e_lo.min(r.error.max(floor));
        e_hi = e_hi.max(r.error.max(floor));
    }
    if rows.is_empty() {
        return Ok(());
    }
    let root = SVGBackend::new(path, (960, 640)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<std::io::Error>| anyhow!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "polydem bench accuracy: error against run time",
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(
            (t_lo * 0.7..t_hi * 1.4).log_scale(),
            (e_lo * 0.5..e_hi.max(0.02) * 2.0).log_scale(),
        )
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("run time of the case (s)")
        .y_desc("relative error")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(LineSeries::new(
            [(t_lo * 0.7, 0.01), (t_hi * 1.4, 0.01)],
            BLACK.mix(0.4).stroke_width(1),
        ))
        .map_err(err)?
        .label("1 %");
    let mut series: Vec<(String, Vec<&AccuracyRow>)> = Vec::new();
    for r in rows {
        let key = format!("{} ({})", r.case, r.backend);
        match series.iter_mut().find(|(k, _)| *k == key) {
            Some((_, v)) => v.push(r),
            None => series.push((key, vec![r])),
        }
    }
    for (k, (key, pts)) in series.iter().enumerate() {
        let colour = Palette99::pick(k).to_rgba();
        let points: Vec<(f64, f64)> = pts
            .iter()
            .map(|r| (r.seconds, r.error.max(floor)))
            .collect();
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
            .map_err(err)?
            .label(key.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
        chart
            .draw_series(pts.iter().map(|r| {
                EmptyElement::at((r.seconds, r.error.max(floor)))
                    + Circle::new((0, 0), 3, colour.filled())
                    + Text::new(
                        format!("{}", r.dt_fraction),
                        (5, -12),
                        ("sans-serif", 11).into_font(),
                    )
            }))
            .map_err(err)?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// Scratch folder, the repository's meshes, the generated walls.
struct CaseRunner {
    dir: PathBuf,
    root: PathBuf,
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
struct Spec<'a> {
    e_modulus: f64,
    poisson: f64,
    density: f64,
    restitution: f64,
    friction: f64,
    fraction: f64,
    /// Domain `[lo, hi]³`, periodic on every axis when set.
    domain: (f64, f64),
    periodic: bool,
    types: &'a str,
    /// A wall mesh at z = 0, if any.
    wall: Option<&'a Path>,
}

impl CaseRunner {
    fn new(out: &Path) -> Result<Self> {
        let dir = out.join("cases");
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        write_plane(&dir.join("plane.stl"), 1.0, 1)?;
        write_plane(&dir.join("mesh_coarse.stl"), 0.2, 8)?; // λ = 0.5 for the 2.5 cm cuboid
        write_plane(&dir.join("mesh_fine.stl"), 0.2, 64)?; // λ = 4
        Ok(CaseRunner {
            dir,
            root: repo_root(),
        })
    }

    fn simulation(&self, spec: &Spec) -> Result<Simulation> {
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

    fn run(&self, case: &str, device: Device, f: f64) -> Result<(f64, u64, String)> {
        match case {
            "cylinder_impact" => self.cylinder_impact(device, f),
            "restitution" => self.restitution(device, f),
            "elastic_impact" => self.elastic_impact(device, f),
            "elastic_energy" => self.elastic_energy(device, f),
            "mesh_independence" => self.mesh_independence(device, f),
            "sphere_oblique" => self.sphere_oblique(device, f),
            "pour_packing" => self.pour_packing(device, f),
            _ => Err(anyhow!("unknown accuracy case {case}")),
        }
    }

    /// Steps until a contact has begun and ended (at most `limit` steps); returns the steps.
    fn impact(e: &mut Engine, limit: u64) -> Result<u64> {
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

    fn cylinder_impact(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
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

    fn restitution(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        self.impacts(device, f, 0.5)
    }

    fn elastic_impact(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
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

    fn elastic_energy(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let side = 0.033;
        let types = "[[particle_types]]\nname = \"p\"\nmaterial = \"m\"\n\
                     generator = { kind = \"cuboid\", a = 0.01, b = 0.01, c = 0.01 }\nscale = 1.0\n";
        let mut sim = self.simulation(&Spec {
            e_modulus: 1e7,
            poisson: 0.3,
            density: 2500.0,
            restitution: 1.0,
            friction: 0.0,
            fraction: f,
            domain: (0.0, side),
            periodic: true,
            types,
            wall: None,
        })?;
        let t = sim.scene.templates[0].clone();
        let mut rng = Rng::new(7);
        let mut id = 0;
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    let x = Vector3::new(i as f64, j as f64, k as f64) * (side / 3.0)
                        + Vector3::repeat(side / 6.0);
                    sim.particles
                        .push(id, 0, 1.0, x, UnitQuaternion::identity(), &t, 2500.0);
                    sim.particles.velocity[id as usize] = Vector3::new(
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                    );
                    id += 1;
                }
            }
        }
        sim.refresh()?;
        let e0 = sim.total_energy();
        let steps = (0.02 / sim.dt).round() as u64;
        let mut e = Engine::new(sim, device)?;
        for _ in 0..steps {
            e.step()?;
        }
        let e1 = e.synced()?.total_energy();
        let error = (e1 - e0).abs() / e0;
        Ok((
            error,
            steps,
            format!("ΔE/E {:.3e} over 20 ms", (e1 - e0) / e0),
        ))
    }

    fn mesh_independence(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let lc = 0.025;
        let types = format!(
            "[[particle_types]]\nname = \"cube\"\nmaterial = \"m\"\n\
             generator = {{ kind = \"cuboid\", a = {lc}, b = {lc}, c = {lc} }}\nscale = 1.0\n"
        );
        let mut curves = Vec::new();
        let mut steps_total = 0;
        for mesh in ["mesh_coarse.stl", "mesh_fine.stl"] {
            let mut sim = self.simulation(&Spec {
                e_modulus: 1e6,
                poisson: 0.1,
                density: 1500.0,
                restitution: 0.1,
                friction: 0.8,
                fraction: f,
                domain: (-1.0, 1.0),
                periodic: false,
                types: &types,
                wall: Some(&self.dir.join(mesh)),
            })?;
            let t = sim.scene.templates[0].clone();
            let (depth, v, x0) = (0.01 * lc, 0.1, -0.08);
            let dt = sim.dt;
            let place = |sim: &mut Simulation, k: u64| {
                sim.particles.velocity[0] = Vector3::new(v, 0.0, 0.0);
                sim.particles.angular_velocity[0] = Vector3::zeros();
                sim.particles.position[0] =
                    Vector3::new(x0 + v * dt * k as f64, 0.013, 0.5 * lc - depth);
                sim.particles.orientation[0] = UnitQuaternion::identity();
            };
            sim.particles.push(
                0,
                0,
                1.0,
                Vector3::new(x0, 0.013, 0.5 * lc - depth),
                UnitQuaternion::identity(),
                &t,
                1500.0,
            );
            sim.refresh()?;
            // Over κ = Δx/L_c from 0 to 1: the cube crosses four cells of the fine mesh.
            let steps = (lc / v / dt) as u64;
            let mut e = Engine::new(sim, device)?;
            let mut curve = Vec::with_capacity(steps as usize);
            for k in 0..steps {
                e.edit(|s| place(s, k))?;
                e.step()?;
                let force = e.synced()?.wall_forces[0];
                curve.push((force.z, force.xy().norm()));
            }
            steps_total += steps;
            curves.push(curve);
        }
        let scale_n = curves[0].iter().map(|c| c.0.abs()).fold(0.0, f64::max);
        let scale_t = curves[0].iter().map(|c| c.1).fold(0.0, f64::max);
        let (mut dn, mut dtan) = (0.0f64, 0.0f64);
        for (a, b) in curves[0].iter().zip(&curves[1]) {
            dn = dn.max((a.0 - b.0).abs() / scale_n);
            dtan = dtan.max((a.1 - b.1).abs() / scale_t);
        }
        Ok((
            dn.max(dtan),
            steps_total,
            format!("normal {dn:.2e}, tangential {dtan:.2e} of the force scale"),
        ))
    }

    fn sphere_oblique(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
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

    /// Returns the packing fraction as the "error" (made relative to the finest step by
    /// [`run_accuracy`]).
    fn pour_packing(&self, device: Device, f: f64) -> Result<(f64, u64, String)> {
        let path = self.root.join("launch/validation/pour.toml");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        let text = text.replace("dt_fraction = 0.05", &format!("dt_fraction = {f}"));
        // Relative paths of the file (its meshes) resolve against its own folder.
        let base = path.parent().unwrap_or(&self.root);
        let scene = parse_scene(&text, base, "pour.toml")?;
        let end = scene.simulation.end_time;
        let sim = Simulation::builder(scene).build()?;
        let mut e = Engine::new(sim, device)?;
        let mut steps = 0;
        while e.host().time + 0.5 * e.host().dt < end {
            e.step()?;
            steps += 1;
        }
        let p = &e.synced()?.particles;
        Ok((core_packing_fraction(p), steps, String::new()))
    }
}

/// The pour's bulk packing fraction by centre counting in the bed's core (one 4 mm diameter in
/// from the 2 cm box's walls and floor, below the 90th percentile of the centre heights less
/// one diameter), with each dodecahedron's volume.
fn core_packing_fraction(p: &crate::state::Particles) -> f64 {
    let (half, d) = (0.02, 0.004);
    let mut z: Vec<f64> = p.position.iter().map(|x| x.z).collect();
    z.sort_by(f64::total_cmp);
    if z.is_empty() {
        return 0.0;
    }
    let surface = z[(0.9 * z.len() as f64) as usize];
    let (lo, hi) = (
        Vector3::new(-half + d, -half + d, d),
        Vector3::new(half - d, half - d, surface - d),
    );
    let volume: f64 = (0..p.len())
        .filter(|&i| {
            let x = p.position[i];
            (0..3).all(|k| x[k] > lo[k] && x[k] < hi[k])
        })
        .map(|i| p.mass[i] / 2500.0)
        .sum();
    let core = (hi - lo).product();
    if core > 0.0 { volume / core } else { 0.0 }
}
