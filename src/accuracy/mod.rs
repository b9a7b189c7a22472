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
//! | `sphere_sticking` | rigid-body sticking: the sphere rolls off (the soft sphere at 15°–55°, test 6 at 2 rad/s) | max relative error of v_n', v_t', ω' |
//! | `friction_energy` | the soft sphere at 30°, μ 0.1–0.7, e 0.1–1: the rigid-body kinetic energy after the impact | max `|ΔK|/K_in` (the detail: the largest change, never a gain) |
//! | `pour_packing` (full only) | `launch/validation/pour.toml`'s bulk packing fraction at the finest step | relative difference |
//!
//! Results go to `accuracy.csv` and the Pareto plot `accuracy.svg` (error against run time,
//! one series per case and precision, dt_fraction marked) in the output folder.
//!
//! This file holds the options, the sweep and the CSV; `runner` the scene generation every case
//! shares, `impacts` the single-impact cases, `sustained` the cases that run for a fixed time
//! (energy, force curve, pour), and `plot` the SVG.

mod impacts;
mod plot;
mod runner;
mod sustained;

use crate::Precision;
use crate::backend::Device;
use anyhow::{Context, Result, anyhow};
use plot::plot;
use runner::CaseRunner;
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
pub const CASES: [&str; 9] = [
    "cylinder_impact",
    "restitution",
    "elastic_impact",
    "elastic_energy",
    "mesh_independence",
    "sphere_oblique",
    "sphere_sticking",
    "friction_energy",
    "pour_packing",
];

/// The step fractions of the short sweep (`make test`) and of the full one.
pub const SHORT_FRACTIONS: [f64; 3] = [0.1, 0.05, 0.025];
pub const FULL_FRACTIONS: [f64; 5] = [0.2, 0.1, 0.05, 0.025, 0.0125];

/// The devices `bench accuracy` runs on: the CPU, or with a GPU chosen by `backend` both
/// precisions (or the one `precision` names).
pub fn devices(
    backend: crate::backend::BackendChoice,
    precision: Option<Precision>,
) -> Result<Vec<Device>> {
    let serial = crate::domain::SerialComm;
    Ok(
        match crate::backend::select_device(
            backend,
            precision.unwrap_or(Precision::Double),
            &serial,
        )? {
            Device::Cuda { ordinal, .. } => precision
                .map_or(vec![Precision::Double, Precision::Mixed], |p| vec![p])
                .into_iter()
                .map(|precision| Device::Cuda { ordinal, precision })
                .collect(),
            cpu => vec![cpu],
        },
    )
}

fn device_name(d: Device) -> String {
    match d {
        Device::Cpu => "cpu".into(),
        Device::CpuMixed => "cpu mixed".into(),
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
