//! The `polydem` command line.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use polydem::backend::BackendChoice;
use polydem::domain::{Comm, SerialComm};
use polydem::probe::{Precision, probe_overlap, probe_wall};
use polydem::run::RunOptions;
use std::path::PathBuf;
use std::sync::Arc;

#[derive(Parser)]
#[command(
    name = "polydem",
    version,
    about = "DEM for convex polyhedral particles"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Contact-geometry queries on given shapes and poses (JSON in, one JSON line per query out).
    Probe {
        #[command(subcommand)]
        query: ProbeQuery,
    },
    /// Runs a scene: frames, series, checkpoints, and summary.json in the output directory.
    Run {
        /// Scene file (TOML, see docs/scene.md).
        scene: PathBuf,
        #[arg(long, value_enum, default_value = "auto")]
        backend: BackendChoice,
        /// Output directory (overrides the scene's output.dir).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Continue from a checkpoint of the same scene.
        #[arg(long)]
        restart: Option<PathBuf>,
        /// Stop after this many steps.
        #[arg(long)]
        max_steps: Option<u64>,
        /// Pair-geometry arithmetic on the GPU: all f64, or f32 in the contact-centred pair
        /// frame with f64 state (the CPU is always f64).
        #[arg(long, value_enum, default_value = "double")]
        gpu_precision: polydem::backend::cuda::Precision,
        /// Remove a previous run's output from the output folder first (a new run into a
        /// folder holding one is refused otherwise; `--restart` continues in it).
        #[arg(long)]
        overwrite: bool,
        /// Who builds the pair lists on the GPU, overriding the scene's
        /// simulation.neighbor.mode (docs/scene.md).
        #[arg(long, value_enum)]
        neighbor_mode: Option<polydem::scene::NeighborMode>,
    },
    /// Validates a scene and prints the critical time step, the chosen dt and counts.
    Check { scene: PathBuf },
    /// Steps a scene without output and prints particle-steps per second, per-stage seconds,
    /// contacts per particle and device bytes per particle, as JSON. `polydem bench accuracy`
    /// runs the reference cases of docs/accuracy.md instead: error against run time at several
    /// dt_fraction values (both precisions on a GPU), written as accuracy.csv and accuracy.svg.
    Bench {
        /// The scene file, or `accuracy`.
        scene: PathBuf,
        #[arg(long, value_enum, default_value = "auto")]
        backend: BackendChoice,
        /// Pair-geometry arithmetic on the GPU: `mixed` unless given; `bench accuracy` runs
        /// both precisions unless one is given.
        #[arg(long, value_enum)]
        gpu_precision: Option<polydem::backend::cuda::Precision>,
        /// Who builds the pair lists on the GPU, overriding the scene's
        /// simulation.neighbor.mode.
        #[arg(long, value_enum)]
        neighbor_mode: Option<polydem::scene::NeighborMode>,
        /// Steps before timing.
        #[arg(long, default_value_t = 20)]
        warmup: u64,
        /// Steps timed.
        #[arg(long, default_value_t = 200)]
        steps: u64,
        /// Print JSON only (the default output is JSON as well; kept for scripts).
        #[arg(long)]
        json: bool,
        /// `bench accuracy`: also the pour, over five step fractions (the short sweep runs
        /// three).
        #[arg(long)]
        full: bool,
        /// `bench accuracy`: the step fractions to run, comma-separated.
        #[arg(long, value_delimiter = ',')]
        fractions: Option<Vec<f64>>,
        /// `bench accuracy`: output folder.
        #[arg(long, default_value = "accuracy")]
        out: PathBuf,
        /// `bench accuracy`: only these cases, comma-separated (default: all; the pour with
        /// --full).
        #[arg(long, value_delimiter = ',')]
        cases: Option<Vec<String>>,
    },
    /// Compresses a scene's loosely inserted particles in a fully periodic box to a target
    /// number of contacts per particle and writes the packing, which `[[insertions]] packing`
    /// tiles (docs/scene.md). Prints a JSON report.
    Pack {
        /// Scene file: periodic on every axis, no gravity, no walls.
        scene: PathBuf,
        /// Target contacts per particle (2 × contacts / particles, after settling).
        #[arg(long)]
        contacts: f64,
        /// The packing file to write.
        #[arg(long)]
        out: PathBuf,
        #[arg(long, value_enum, default_value = "auto")]
        backend: BackendChoice,
        /// Pair-geometry arithmetic on the GPU.
        #[arg(long, value_enum, default_value = "double")]
        gpu_precision: polydem::backend::cuda::Precision,
    },
    /// Observables of a checkpoint of a scene (docs/production.md), as JSON.
    Analyze {
        #[command(subcommand)]
        what: AnalyzeWhat,
    },
    /// Lists GPUs, the CUDA driver and NVRTC versions, as JSON.
    Info,
    /// Shape templates: mass properties and face counts.
    Shape {
        #[command(subcommand)]
        action: ShapeAction,
    },
}

/// The state an analysis reads and the vertical cylinder it looks in.
#[derive(clap::Args)]
struct AnalyzedCylinder {
    scene: PathBuf,
    checkpoint: PathBuf,
    /// The cylinder's axis, x and y (m). Only the particles whose centre lies inside the
    /// cylinder count, so a scene of several containers side by side is analysed one at a time.
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 0.0])]
    centre: Vec<f64>,
    /// The cylinder's inner radius (m).
    #[arg(long)]
    radius: f64,
}

#[derive(Subcommand)]
enum AnalyzeWhat {
    /// Fill height in a vertical cylindrical container: the highest particle point, the mean
    /// height of the packing's top surface over the cross-section, and the bulk solid fraction.
    FillHeight {
        #[command(flatten)]
        at: AnalyzedCylinder,
        /// Floor height (m).
        #[arg(long, default_value_t = 0.0)]
        floor: f64,
        /// Spacing of the vertical lines sampled (m; default radius / 200).
        #[arg(long)]
        spacing: Option<f64>,
    },
    /// Porosity of a section of a vertical tube: overall, and in annuli from the wall to the
    /// axis.
    Porosity {
        #[command(flatten)]
        at: AnalyzedCylinder,
        /// Lower and upper ends of the section (m).
        #[arg(long, value_delimiter = ',', required = true)]
        z: Vec<f64>,
        /// Annuli from the wall to the axis.
        #[arg(long, default_value_t = 50)]
        annuli: usize,
        /// Spacing of the sampled points (m; default radius / 100).
        #[arg(long)]
        spacing: Option<f64>,
    },
    /// The top surface of a fill in a vertical cylinder by distance from the axis, and the
    /// angle of the cone fitted to it: a heap's angle of repose (negative for a crater).
    Heap {
        #[command(flatten)]
        at: AnalyzedCylinder,
        /// Floor height (m).
        #[arg(long, default_value_t = 0.0)]
        floor: f64,
        /// Rings of equal width from the axis to the wall.
        #[arg(long, default_value_t = 20)]
        rings: usize,
        /// Fitted range of distances from the axis, as fractions of the radius.
        #[arg(long, value_delimiter = ',', default_values_t = [0.2, 0.8])]
        fit: Vec<f64>,
        /// Spacing of the points sampled on each ring (m; default radius / 200).
        #[arg(long)]
        spacing: Option<f64>,
    },
    /// The flow of a quasi-2D drum turning about the y axis, averaged over frames: velocity
    /// field, dynamic angle of repose and flowing layer depth (docs/production.md §2).
    Drum {
        /// The run's frame folder (`<output.dir>/particles`, written with formats = ["csv"]).
        frames: PathBuf,
        /// The drum's inner radius (m).
        #[arg(long)]
        radius: f64,
        /// The drum's axis, x and z (m).
        #[arg(long, value_delimiter = ',', default_values_t = [0.0, 0.0])]
        centre: Vec<f64>,
        /// The slice of y holding this drum's particles, YMIN,YMAX (m; default: every particle).
        #[arg(long, value_delimiter = ',')]
        y: Option<Vec<f64>>,
        /// Frames before this time (s) are skipped: the start-up.
        #[arg(long, default_value_t = 0.0)]
        from: f64,
        /// Cell size of the averaging grid (m; default radius / 30).
        #[arg(long)]
        cell: Option<f64>,
        /// Writes the averaged field here as CSV: x,z,occupancy,vx,vz,samples per cell.
        #[arg(long)]
        field: Option<PathBuf>,
    },
}

#[derive(Subcommand)]
enum ProbeQuery {
    /// Overlap of polyhedron pairs: volume, S = dV/dx_B, area, normal, centroid.
    Overlap {
        file: PathBuf,
        #[arg(long, value_enum, default_value = "f64")]
        precision: Precision,
    },
    /// A polyhedron against triangle facets: clipped section area, centroid, penetrating volume.
    Wall {
        file: PathBuf,
        #[arg(long, value_enum, default_value = "f64")]
        precision: Precision,
    },
}

#[derive(Subcommand)]
enum ShapeAction {
    /// Prints a template's properties as JSON: from a mesh file, or a generator name and size.
    Info {
        /// STL or OBJ file, or a generator name (tetrahedron, cube, octahedron, dodecahedron,
        /// icosahedron).
        shape: String,
        /// Circumscribed diameter for a generator.
        #[arg(long, default_value_t = 1.0)]
        size: f64,
    },
}

/// The communicator of this process: MPI's world when started by an MPI launcher (and built
/// with the `mpi` feature), else a single rank.
fn communicator() -> Arc<dyn Comm> {
    #[cfg(feature = "mpi")]
    if polydem::domain::comm::launched_under_mpi()
        && let Some(c) = polydem::domain::comm::MpiComm::init()
    {
        return Arc::new(c);
    }
    Arc::new(SerialComm)
}

fn main() {
    let cli = Cli::parse();
    let comm = match cli.command {
        Command::Run { .. } | Command::Bench { .. } => communicator(),
        _ => Arc::new(SerialComm),
    };
    // Ranks other than 0 log warnings and errors only, unless RUST_LOG says otherwise.
    let default = if comm.rank() == 0 { "info" } else { "warn" };
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default)),
        )
        .init();
    polydem::tuning::Tuning::get().log();
    if comm.size() > 1 {
        // A panic on one rank must end the run on all: unwinding would finalize MPI here while
        // the others wait in a collective.
        // A weak handle: the hook outlives main, and must not keep MPI from being finalized.
        let hook_comm = Arc::downgrade(&comm);
        let default_hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            default_hook(info);
            if let Some(c) = hook_comm.upgrade() {
                eprintln!(
                    "error (rank {} of {}): panic; ending every rank",
                    c.rank(),
                    c.size()
                );
                c.abort(101);
            }
        }));
    }
    match run(cli, comm.clone()) {
        Err(e) => {
            if comm.size() > 1 {
                eprintln!("error (rank {} of {}): {e:#}", comm.rank(), comm.size());
                // A stop every rank agreed on (the stability guard's, a particle leaving the
                // domain) ends MPI in order, each rank having said its part; any other error
                // is this rank's alone, and ends the others where they wait.
                let agreed = e
                    .downcast_ref::<polydem::pipeline::SimulationError>()
                    .is_some_and(polydem::pipeline::SimulationError::stops_every_rank);
                if !agreed {
                    comm.abort(1);
                }
                drop(comm);
                std::process::exit(1);
            }
            eprintln!("error: {e:#}");
            std::process::exit(1);
        }
        Ok(0) => {}
        Ok(status) => {
            // A run stopped by a signal: MPI is finalized first (the communicator's last
            // handle), then the shell's 128 + signal tells scripts it did not finish.
            drop(comm);
            std::process::exit(status);
        }
    }
}

/// Runs the command; returns the process's exit status (non-zero only for a run stopped by a
/// signal, `polydem::interrupt`).
fn run(cli: Cli, comm: Arc<dyn Comm>) -> Result<i32> {
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    match cli.command {
        Command::Probe {
            query: ProbeQuery::Overlap { file, precision },
        } => probe_overlap(&file, precision, &mut out).map(|()| 0),
        Command::Probe {
            query: ProbeQuery::Wall { file, precision },
        } => probe_wall(&file, precision, &mut out).map(|()| 0),
        Command::Run {
            scene,
            backend,
            out: dir,
            restart,
            max_steps,
            gpu_precision,
            overwrite,
            neighbor_mode,
        } => {
            let rank = comm.rank();
            let summary = polydem::run::run_on(
                &RunOptions {
                    scene,
                    backend,
                    out: dir,
                    restart,
                    max_steps,
                    precision: gpu_precision,
                    overwrite,
                    neighbor_mode,
                },
                comm,
            )?;
            if rank == 0 {
                use std::io::Write;
                writeln!(out, "{}", serde_json::to_string_pretty(&summary)?)?;
            }
            Ok(summary["exit_status"].as_i64().unwrap_or(0) as i32)
        }
        Command::Bench {
            scene,
            backend,
            gpu_precision,
            neighbor_mode,
            warmup,
            steps,
            json: _,
            full,
            fractions,
            out: out_dir,
            cases,
        } => {
            if scene.as_os_str() == "accuracy" && !scene.exists() {
                use polydem::accuracy::{AccuracyOptions, FULL_FRACTIONS, SHORT_FRACTIONS};
                use polydem::backend::Device;
                use polydem::backend::cuda::Precision;
                let serial = SerialComm;
                let devices =
                    match polydem::backend::select_device(backend, Precision::Double, &serial)? {
                        Device::Cuda { ordinal, .. } => gpu_precision
                            .map_or(vec![Precision::Double, Precision::Mixed], |p| vec![p])
                            .into_iter()
                            .map(|precision| Device::Cuda { ordinal, precision })
                            .collect(),
                        Device::Cpu => vec![Device::Cpu],
                    };
                let fractions = fractions.unwrap_or_else(|| {
                    if full {
                        FULL_FRACTIONS.to_vec()
                    } else {
                        SHORT_FRACTIONS.to_vec()
                    }
                });
                if let Some(bad) = fractions.iter().find(|f| !(**f > 0.0 && **f <= 1.0)) {
                    anyhow::bail!("--fractions: each must be in (0, 1], got {bad}");
                }
                let rows = polydem::accuracy::run_accuracy(&AccuracyOptions {
                    devices,
                    fractions,
                    full,
                    cases: cases.unwrap_or_default(),
                    out: out_dir.clone(),
                })?;
                use std::io::Write;
                writeln!(
                    out,
                    "{}",
                    serde_json::to_string_pretty(&serde_json::json!({
                        "csv": out_dir.join("accuracy.csv"),
                        "plot": out_dir.join("accuracy.svg"),
                        "rows": rows,
                    }))?
                )?;
                return Ok(0);
            }
            let rank = comm.rank();
            let report = polydem::run::bench_on(
                &polydem::run::BenchOptions {
                    scene,
                    backend,
                    precision: gpu_precision.unwrap_or(polydem::backend::cuda::Precision::Mixed),
                    warmup,
                    steps,
                    neighbor_mode,
                },
                comm,
            )?;
            if rank == 0 {
                use std::io::Write;
                writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
            }
            Ok(0)
        }
        Command::Analyze { what } => {
            use polydem::analysis;
            use std::io::Write;
            let positive = |name: &str, v: f64| {
                if v.is_finite() && v > 0.0 {
                    Ok(v)
                } else {
                    Err(anyhow::anyhow!(
                        "--{name} {v}: must be a positive length (m)"
                    ))
                }
            };
            // The state, placed as solids, and the cylinder's axis and radius.
            let open = |at: &AnalyzedCylinder| -> Result<(analysis::PackedSolids, [f64; 2], f64)> {
                if at.centre.len() != 2 {
                    anyhow::bail!("--centre {:?}: two numbers, x,y (m)", at.centre);
                }
                let radius = positive("radius", at.radius)?;
                let (s, p) = analysis::load_state(&at.scene, &at.checkpoint)?;
                let centre = [at.centre[0], at.centre[1]];
                Ok((
                    analysis::solids_in_cylinder(&s, &p, centre, radius),
                    centre,
                    radius,
                ))
            };
            let report = match what {
                AnalyzeWhat::FillHeight { at, floor, spacing } => {
                    let r = positive("radius", at.radius)?;
                    let spacing = positive("spacing", spacing.unwrap_or(r / 200.0))?;
                    let (solids, centre, radius) = open(&at)?;
                    let disk = analysis::Disk {
                        centre,
                        radius,
                        floor,
                    };
                    serde_json::to_value(analysis::fill_height(&solids, &disk, spacing))?
                }
                AnalyzeWhat::Porosity {
                    at,
                    z,
                    annuli,
                    spacing,
                } => {
                    let r = positive("radius", at.radius)?;
                    let spacing = positive("spacing", spacing.unwrap_or(r / 100.0))?;
                    if z.len() != 2
                        || z[1].partial_cmp(&z[0]) != Some(std::cmp::Ordering::Greater)
                        || annuli == 0
                    {
                        anyhow::bail!(
                            "--z {z:?}: two heights ZMIN,ZMAX (m), the upper above the lower; \
                             --annuli {annuli}: at least 1"
                        );
                    }
                    let (solids, centre, radius) = open(&at)?;
                    let tube = analysis::Tube {
                        centre,
                        radius,
                        z: [z[0], z[1]],
                    };
                    serde_json::to_value(analysis::radial_porosity(
                        &solids, &tube, annuli, spacing,
                    ))?
                }
                AnalyzeWhat::Heap {
                    at,
                    floor,
                    rings,
                    fit,
                    spacing,
                } => {
                    let r = positive("radius", at.radius)?;
                    let spacing = positive("spacing", spacing.unwrap_or(r / 200.0))?;
                    let fit = match fit.as_slice() {
                        [a, b] if (0.0..1.0).contains(a) && b > a && *b <= 1.0 => [*a, *b],
                        v => anyhow::bail!(
                            "--fit {v:?}: two fractions of the radius A,B with 0 ≤ A < B ≤ 1"
                        ),
                    };
                    if rings < 2 {
                        anyhow::bail!("--rings {rings}: at least 2");
                    }
                    let (solids, centre, radius) = open(&at)?;
                    let disk = analysis::Disk {
                        centre,
                        radius,
                        floor,
                    };
                    serde_json::to_value(analysis::heap_profile(
                        &solids, &disk, rings, spacing, fit,
                    ))?
                }
                AnalyzeWhat::Drum {
                    frames,
                    radius,
                    centre,
                    y,
                    from,
                    cell,
                    field,
                } => {
                    let radius = positive("radius", radius)?;
                    let cell = positive("cell", cell.unwrap_or(radius / 30.0))?;
                    if centre.len() != 2 {
                        anyhow::bail!("--centre {centre:?}: two numbers, x,z (m)");
                    }
                    let y = match y.as_deref() {
                        None => [f64::NEG_INFINITY, f64::INFINITY],
                        Some([a, b]) if b > a => [*a, *b],
                        Some(v) => anyhow::bail!(
                            "--y {v:?}: two numbers YMIN,YMAX (m), the second above the first"
                        ),
                    };
                    let section = analysis::DrumSection {
                        centre: [centre[0], centre[1]],
                        radius,
                        y,
                    };
                    let mut samples = analysis::DrumSamples::new(section, cell);
                    let mut times = Vec::new();
                    for tables in analysis::frame_tables(&frames)? {
                        let mut rows = Vec::new();
                        for t in &tables {
                            rows.extend(polydem::io::read_particle_csv(t)?);
                        }
                        let Some(time) = rows.first().map(|r| r.time) else {
                            continue;
                        };
                        if time < from {
                            continue;
                        }
                        times.push(time);
                        samples.add_frame(rows.iter().map(|r| (&r.position, &r.velocity)));
                    }
                    if times.is_empty() {
                        anyhow::bail!("{}: no frame at or after --from {from} s", frames.display());
                    }
                    let flow = samples.flow();
                    if let Some(path) = &field {
                        let mut csv = String::from("x,z,occupancy,vx,vz,samples\n");
                        for c in &flow.cells {
                            csv.push_str(&format!(
                                "{},{},{},{},{},{}\n",
                                c.x, c.z, c.occupancy, c.vx, c.vz, c.samples
                            ));
                        }
                        polydem::io::write_atomic(path, csv.as_bytes()).with_context(|| {
                            format!("{}: cannot write the field", path.display())
                        })?;
                    }
                    let mut v = serde_json::to_value(&flow)?;
                    if let Some(o) = v.as_object_mut() {
                        o.remove("cells");
                        o.insert("radius".into(), radius.into());
                        o.insert("first_time".into(), times[0].into());
                        o.insert("last_time".into(), times[times.len() - 1].into());
                    }
                    v
                }
            };
            writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
            Ok(0)
        }
        Command::Check { scene } => {
            use std::io::Write;
            writeln!(
                out,
                "{}",
                serde_json::to_string_pretty(&polydem::run::check(&scene)?)?
            )?;
            Ok(0)
        }
        Command::Pack {
            scene,
            contacts,
            out: file,
            backend,
            gpu_precision,
        } => {
            use std::io::Write;
            let report = polydem::run::pack(&polydem::run::PackOptions {
                scene,
                contacts,
                out: file,
                backend,
                precision: gpu_precision,
            })?;
            writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
            Ok(0)
        }
        Command::Info => {
            use std::io::Write;
            let info = polydem::backend::cuda_info();
            writeln!(out, "{}", serde_json::to_string_pretty(&info)?)?;
            Ok(0)
        }
        Command::Shape {
            action: ShapeAction::Info { shape, size },
        } => polydem::probe::shape_info(&shape, size, &mut out).map(|()| 0),
    }
}
