//! The `polydem` command line.

use anyhow::Result;
use clap::{Parser, Subcommand};
use polydem::backend::BackendChoice;
use polydem::domain::{Comm, SerialComm};
use polydem::probe::{Arithmetic, probe_overlap, probe_wall};
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
        #[arg(long, allow_negative_numbers = true)]
        max_steps: Option<u64>,
        /// Pair-geometry arithmetic on the GPU: all f64, or f32 in the contact-centred pair
        /// frame with f64 state. With `--backend cpu`, `mixed` evaluates the polyhedral pairs
        /// as the GPU's mixed precision does (to reproduce a GPU run without a GPU).
        #[arg(long, value_enum, default_value = "double")]
        gpu_precision: polydem::Precision,
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
        /// both precisions unless one is given. With `--backend cpu`: f64 unless `mixed` is
        /// given (the GPU's mixed precision on the CPU).
        #[arg(long, value_enum)]
        gpu_precision: Option<polydem::Precision>,
        /// Who builds the pair lists on the GPU, overriding the scene's
        /// simulation.neighbor.mode.
        #[arg(long, value_enum)]
        neighbor_mode: Option<polydem::scene::NeighborMode>,
        /// Steps before timing.
        #[arg(long, default_value_t = 20, allow_negative_numbers = true)]
        warmup: u64,
        /// Steps timed.
        #[arg(long, default_value_t = 200, allow_negative_numbers = true)]
        steps: u64,
        /// Print JSON only (the default output is JSON as well; kept for scripts).
        #[arg(long)]
        json: bool,
        /// `bench accuracy`: also the pour, over five step fractions (the short sweep runs
        /// three).
        #[arg(long)]
        full: bool,
        /// `bench accuracy`: the step fractions to run, comma-separated, each in (0, 1].
        #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_parser = step_fraction)]
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
        /// Target contacts per particle (2 × contacts / particles, after settling), in (0, 30].
        #[arg(long, allow_negative_numbers = true, value_parser = contacts_per_particle)]
        contacts: f64,
        /// The packing file to write.
        #[arg(long)]
        out: PathBuf,
        #[arg(long, value_enum, default_value = "auto")]
        backend: BackendChoice,
        /// Pair-geometry arithmetic on the GPU.
        #[arg(long, value_enum, default_value = "double")]
        gpu_precision: polydem::Precision,
    },
    /// Observables of a checkpoint of a scene (docs/production.md), as JSON.
    Analyze {
        #[command(subcommand)]
        what: polydem::analysis::AnalyzeWhat,
    },
    /// Lists GPUs, the CUDA driver and NVRTC versions, as JSON.
    Info,
    /// Shape templates: mass properties and face counts.
    Shape {
        #[command(subcommand)]
        action: ShapeAction,
    },
}

#[derive(Subcommand)]
enum ProbeQuery {
    /// Overlap of polyhedron pairs: volume, S = dV/dx_B, area, normal, centroid.
    Overlap {
        file: PathBuf,
        #[arg(long, value_enum, default_value = "f64")]
        precision: Arithmetic,
    },
    /// A polyhedron against triangle facets: clipped section area, centroid, penetrating volume.
    Wall {
        file: PathBuf,
        #[arg(long, value_enum, default_value = "f64")]
        precision: Arithmetic,
    },
}

#[derive(Subcommand)]
enum ShapeAction {
    /// Prints a template's properties as JSON: from a mesh file, or a generator name and size.
    Info {
        /// STL or OBJ file, or a generator name (tetrahedron, cube, octahedron, dodecahedron,
        /// icosahedron).
        shape: String,
        /// Circumscribed diameter for a generator (m), in (0, 1e6].
        #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = shape_size)]
        size: f64,
    },
}

/// A real number in `[lo, hi]` (`lo` excluded when `open`), or the error clap prints after
/// the option's name: what was given and what is allowed.
fn bounded_real(text: &str, lo: f64, open: bool, hi: f64, what: &str) -> Result<f64, String> {
    let x: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("not a number; {what}"))?;
    let above = if open { x > lo } else { x >= lo };
    if x.is_finite() && above && x <= hi {
        Ok(x)
    } else {
        Err(format!("out of range; {what}"))
    }
}

/// `shape info --size`: a circumscribed diameter.
fn shape_size(text: &str) -> Result<f64, String> {
    bounded_real(text, 0.0, true, 1e6, "the size is a length in (0, 1e6] m")
}

/// `pack --contacts`: a target number of contacts per particle.
fn contacts_per_particle(text: &str) -> Result<f64, String> {
    bounded_real(
        text,
        0.0,
        true,
        30.0,
        "the target is contacts per particle in (0, 30]",
    )
}

/// `bench accuracy --fractions`: a step as a fraction of the critical step.
fn step_fraction(text: &str) -> Result<f64, String> {
    bounded_real(
        text,
        0.0,
        true,
        1.0,
        "each is a fraction of the critical step in (0, 1]",
    )
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

/// Prints one rank's error line to stderr in a single write: `eprintln!` writes the pieces of
/// its format one by one, and the ranks' pieces then interleave in mpirun's forwarded stream
/// (a pipe keeps writes of up to `PIPE_BUF` bytes whole).
fn rank_error(comm: &dyn Comm, message: &str) {
    use std::io::Write;
    let line = format!(
        "error (rank {} of {}): {message}\n",
        comm.rank(),
        comm.size()
    );
    let _ = std::io::stderr().lock().write_all(line.as_bytes());
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
                rank_error(c.as_ref(), "panic; ending every rank");
                c.abort(101);
            }
        }));
    }
    match run(cli, comm.clone()) {
        Err(e) => {
            if comm.size() > 1 {
                // A start-up failure the ranks agreed on: printed once, by the lowest failing
                // rank, and MPI ended in order.
                if let Some(stop) = e.downcast_ref::<polydem::run::EveryRankStops>() {
                    if let Some(error) = &stop.error {
                        rank_error(comm.as_ref(), error);
                    }
                    drop(comm);
                    std::process::exit(1);
                }
                rank_error(comm.as_ref(), &format!("{e:#}"));
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
    use std::io::Write;
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
                writeln!(out, "{}", serde_json::to_string_pretty(&summary)?)?;
            }
            Ok(summary.exit_status)
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
            if scene.as_os_str() == "accuracy" && !scene.is_file() {
                let accuracy = AccuracyCommand {
                    backend,
                    gpu_precision,
                    full,
                    fractions,
                    cases,
                    out: out_dir,
                };
                return bench_accuracy(accuracy, &mut out).map(|()| 0);
            }
            let rank = comm.rank();
            let report = polydem::run::bench_on(
                &polydem::run::BenchOptions {
                    scene,
                    backend,
                    // Mixed on a GPU unless given; the CPU only when asked.
                    precision: gpu_precision.unwrap_or(match backend {
                        polydem::backend::BackendChoice::Cpu => polydem::Precision::Double,
                        _ => polydem::Precision::Mixed,
                    }),
                    warmup,
                    steps,
                    neighbor_mode,
                },
                comm,
            )?;
            if rank == 0 {
                writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
            }
            Ok(0)
        }
        Command::Analyze { what } => {
            let report = polydem::analysis::analyze(what)?;
            writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
            Ok(0)
        }
        Command::Check { scene } => {
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
            let info = polydem::backend::cuda_info();
            writeln!(out, "{}", serde_json::to_string_pretty(&info)?)?;
            Ok(0)
        }
        Command::Shape {
            action: ShapeAction::Info { shape, size },
        } => polydem::probe::shape_info(&shape, size, &mut out).map(|()| 0),
    }
}

/// The arguments of `polydem bench accuracy`.
struct AccuracyCommand {
    backend: polydem::backend::BackendChoice,
    gpu_precision: Option<polydem::Precision>,
    full: bool,
    fractions: Option<Vec<f64>>,
    cases: Option<Vec<String>>,
    out: PathBuf,
}

/// `polydem bench accuracy`: restitution and energy against run time over step fractions
/// (docs/accuracy.md); prints where the table and plot went and the rows.
fn bench_accuracy(a: AccuracyCommand, out: &mut impl std::io::Write) -> Result<()> {
    use polydem::accuracy::{AccuracyOptions, FULL_FRACTIONS, SHORT_FRACTIONS};
    let devices = polydem::accuracy::devices(a.backend, a.gpu_precision)?;
    let fractions = a.fractions.unwrap_or_else(|| {
        if a.full {
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
        full: a.full,
        cases: a.cases.unwrap_or_default(),
        out: a.out.clone(),
    })?;
    let report = serde_json::json!({
        "csv": a.out.join("accuracy.csv"),
        "plot": a.out.join("accuracy.svg"),
        "rows": rows,
    });
    writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
    Ok(())
}
