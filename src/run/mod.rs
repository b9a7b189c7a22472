//! `polydem run`, `polydem check` and `polydem bench`: the driver around the
//! [`Engine`]'s step — output frames, time series, checkpoints and restarts, progress,
//! signals, and the closing `summary.json` (stage 10 of docs/design.md §1).
//!
//! [`run_on`] is four parts, each a function here: `start_or_restore` (the engine on its
//! device, fresh or from a checkpoint), `Outputs::open` (the output folder's writers and
//! schedules), `step_loop` (steps, scheduled output, progress, signals) and `finish` (the
//! closing output and the summary).

mod bench;
mod check;
mod checkpoints;
mod output;
mod pack;
mod summary;

pub use bench::{BenchOptions, bench, bench_on};
pub use check::{ENERGY_FACE_FRACTION, SAFE_FACE_FRACTION, check, time_step_warnings};
pub use output::{OUTPUT_ENTRIES, prepare_output_dir};
pub use pack::{PackOptions, pack};

use crate::Precision;
use crate::backend::{BackendChoice, Device, Engine, Start, select_device};
use crate::domain::{Comm, SerialComm};
use crate::io::{remove_temporary_files, write_atomic};
use crate::pipeline::{RestoredState, Simulation};
use crate::run_state::RunState;
use crate::scene::{Inserter, InserterState, load_scene};
use anyhow::{Context, Result};
use checkpoints::{KeptCheckpoints, SceneId, read_restart, save_checkpoint, stopped_unstable};
use output::{Outputs, Schedule};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
pub use summary::{RunSummary, SummaryEnergies};
use summary::{parallel_report, whole_run, whole_run_counts};

/// Options of `polydem run`.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub scene: PathBuf,
    pub backend: BackendChoice,
    pub out: Option<PathBuf>,
    pub restart: Option<PathBuf>,
    /// Stop after this many steps (for tests and benchmarks); `None`: run to the end time.
    pub max_steps: Option<u64>,
    /// Arithmetic of the pair geometry on the GPU (the CPU backend is always f64).
    pub precision: Precision,
    /// Clear a previous run's output from the output folder ([`prepare_output_dir`]).
    pub overwrite: bool,
    /// Overrides the scene's `simulation.neighbor.mode` (the trajectory is the same in
    /// every mode; only who builds the pair lists changes).
    pub neighbor_mode: Option<crate::scene::NeighborMode>,
}

/// `polydem run` on one rank: returns the summary it also writes to `summary.json`.
pub fn run(opts: &RunOptions) -> Result<RunSummary> {
    run_on(opts, Arc::new(SerialComm))
}

/// `polydem run` on the ranks of `comm` (one rank: [`run`]). Rank 0 returns the summary and
/// writes `summary.json`; the other ranks return the same summary without writing it.
pub fn run_on(opts: &RunOptions, comm: Arc<dyn Comm>) -> Result<RunSummary> {
    // The start-up checks every rank makes alike (the scene, its decomposition over the ranks)
    // and rank 0's output folder end in an agreement, so that a failure ends MPI in order on
    // every rank instead of aborting it (docs/parallel.md, "Failures at start-up").
    let mut scene = agreed(&*comm, load_scene(&opts.scene).map_err(anyhow::Error::from))?;
    if comm.size() > 1 {
        agreed(
            &*comm,
            crate::domain::Parallel::new(comm.clone(), &scene)
                .map(drop)
                .map_err(anyhow::Error::from),
        )?;
    }
    if let Some(out) = &opts.out {
        scene.output.dir = out.clone();
    }
    if let Some(mode) = opts.neighbor_mode {
        scene.simulation.neighbor.mode = mode;
    }
    let device = select_device(opts.backend, opts.precision, &*comm)?;
    let warnings = time_step_warnings(&scene);
    if comm.rank() == 0 {
        for msg in &warnings {
            tracing::warn!("{msg}");
        }
    }
    if comm.rank() == 0 {
        log_neighbor_mode(&scene, device, comm.size());
    }
    let id = SceneId::of(&scene, &opts.scene)?;
    let dir = scene.output.dir.clone();
    let prepared = if comm.rank() == 0 {
        prepare_output_dir(&dir, opts.overwrite, opts.restart.is_some()).and_then(|()| {
            // Leftovers of writes killed in an earlier run: never read, they would pile up.
            let removed = remove_temporary_files(&dir)?;
            if !removed.is_empty() {
                tracing::info!(
                    "removed {} temporary file(s) left by a killed run in {}",
                    removed.len(),
                    dir.display()
                );
            }
            Ok(())
        })
    } else {
        Ok(())
    };
    // In place of a barrier: every rank learns whether rank 0 could prepare the folder.
    agreed(&*comm, prepared)?;
    let (mut engine, resumed) = start_or_restore(opts, scene, &comm, device, &id)?;
    let mut out = Outputs::open(engine.state(), &dir, comm.clone(), resumed)?;
    if !resumed {
        out.frame(engine.synced()?)?;
        out.series(engine.synced()?)?;
    }
    let ended = step_loop(opts, &mut engine, &mut out, &id)?;
    finish(opts, &mut engine, &mut out, &id, ended, warnings)
}

/// A failure every rank of a decomposed run knows of at the same point: MPI can be ended in
/// order on all of them (`polydem`'s main then finalizes and exits 1) instead of aborted,
/// which Open MPI follows by killing every rank through its `odls_base_sigkill_timeout` path
/// (docs/parallel.md, "Interrupting a run"). `error` is the message to print, held
/// by the lowest rank that failed only, so that it is printed once.
#[derive(Debug, thiserror::Error)]
#[error("{}", error.as_deref().unwrap_or("another rank could not start the run"))]
pub struct EveryRankStops {
    pub error: Option<String>,
}

/// `result` after every rank of `comm` has said whether its own failed (a collective: every
/// rank calls it at the same point): a failure on any rank is an [`EveryRankStops`] on all,
/// its message carried by the lowest failing rank. One rank: `result` as it is.
fn agreed<T>(comm: &dyn Comm, result: Result<T>) -> Result<T> {
    if comm.size() == 1 {
        return result;
    }
    let failed = comm.all_gather(&[u8::from(result.is_err())]);
    let Some(first) = failed.iter().position(|f| f.first() == Some(&1)) else {
        return result;
    };
    Err(EveryRankStops {
        error: match result {
            Err(e) if first == comm.rank() => Some(format!("{e:#}")),
            _ => None,
        },
    }
    .into())
}

/// The engine of a run on `device`: a new one from `scene`, or with `--restart` the
/// checkpoint's state (read on rank 0, sent to every particle's owner by the first exchange).
/// Returns it and whether it resumed a run.
fn start_or_restore(
    opts: &RunOptions,
    scene: crate::scene::Scene,
    comm: &Arc<dyn Comm>,
    device: Device,
    id: &SceneId,
) -> Result<(Engine, bool)> {
    let Some(path) = &opts.restart else {
        let start = Start::Scene {
            scene: Box::new(scene),
            comm: comm.clone(),
        };
        return Ok((Engine::new(start, device)?, false));
    };
    let (header, local) = read_restart(&**comm, path, &scene, id)?;
    let state: InserterState = serde_json::from_slice(&header.inserter)
        .with_context(|| format!("{}: insertion state", path.display()))?;
    let inserter =
        Inserter::try_restore(&scene, &state).with_context(|| path.display().to_string())?;
    let (particles, history) = local.map(|c| (c.particles, c.history)).unwrap_or_default();
    let mut sim = Simulation::builder(scene)
        .comm(comm.clone())
        .restore(RestoredState {
            particles,
            history,
            inserter,
            time: header.time,
            step: header.step,
            next_id: header.next_id,
        })
        .build()?;
    // The removal count is the whole run's; rank 0 carries it.
    sim.state.stats.removed = if comm.rank() == 0 { header.removed } else { 0 };
    tracing::info!(
        "restarted from {} at step {} (t = {} s) on {} rank(s)",
        path.display(),
        sim.state.step,
        sim.state.time,
        comm.size()
    );
    Ok((Engine::new(sim, device)?, true))
}

/// How the step loop ended.
struct LoopEnd {
    /// The step the loop started from.
    first_step: u64,
    /// Wall-clock seconds of the loop.
    wall: f64,
    /// Particle-steps done on this rank.
    particle_steps: u64,
    /// The signal that stopped the run (number, name), if one did.
    stopped_by: Option<(i32, &'static str)>,
    /// Whether `--max-steps` stopped the run before its end time.
    max_steps_reached: bool,
}

/// The frames, series rows and checkpoints a run writes on schedule, and the checkpoints kept.
struct Scheduled {
    frame_at: Schedule,
    series_at: Schedule,
    checkpoint_at: Schedule,
    kept: KeptCheckpoints,
}

impl Scheduled {
    fn new(sim: &RunState, dir: &std::path::Path) -> Self {
        let o = &sim.scene.output;
        Scheduled {
            frame_at: Schedule::new(o.frame_interval, sim.time, sim.dt),
            series_at: Schedule::new(Some(o.series_interval), sim.time, sim.dt),
            checkpoint_at: Schedule::new(o.checkpoint_interval, sim.time, sim.dt),
            kept: KeptCheckpoints::new(&sim.scene, dir, sim.step),
        }
    }

    /// Writes what is due after the step just taken.
    fn write_due(&mut self, engine: &mut Engine, out: &mut Outputs, id: &SceneId) -> Result<()> {
        let (t, dt) = (engine.state().time, engine.state().dt);
        if self.frame_at.due(t, dt) {
            out.frame(engine.synced()?)?;
        }
        if self.series_at.due(t, dt) {
            out.series(engine.synced()?)?;
        }
        if self.checkpoint_at.due(t, dt) {
            let comm = out.comm.clone();
            let path = save_checkpoint(&*comm, engine.synced()?, &out.dir, id)?;
            self.kept.push(comm.rank(), path)?;
        }
        Ok(())
    }
}

/// A run's progress: a bar on a terminal, else a log line every `log_interval_steps` (rank 0).
struct Progress {
    bar: Option<indicatif::ProgressBar>,
    start: Instant,
    total_steps: u64,
    log_every: u64,
}

impl Progress {
    fn new(sim: &RunState, rank: usize) -> Self {
        let s = &sim.scene;
        let total_steps = ((s.simulation.end_time - sim.time) / sim.dt)
            .ceil()
            .max(0.0) as u64;
        let bar = (rank == 0 && std::io::stderr().is_terminal()).then(|| {
            let b = indicatif::ProgressBar::new(total_steps);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "{bar:40} {pos}/{len} steps  {per_sec}  ETA {eta}  {msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            b
        });
        Progress {
            bar,
            start: Instant::now(),
            total_steps,
            log_every: s.output.log_interval_steps.max(1),
        }
    }

    /// Shows `done` steps since the loop began. Whole-run counts are summed at deterministic
    /// steps only, where every rank joins the sums.
    fn show(&self, comm: &dyn Comm, sim: &RunState, done: u64) {
        let (n_all, contacts_all, removed_all) =
            if done.is_multiple_of(100) || done.is_multiple_of(self.log_every) {
                whole_run_counts(comm, sim)
            } else {
                (0, 0, 0)
            };
        let t = sim.time;
        if let Some(b) = &self.bar {
            b.set_position(done);
            if done.is_multiple_of(100) {
                b.set_message(format!(
                    "t = {t:.4} s, {n_all} particles, {contacts_all} contacts"
                ));
            }
        } else if done.is_multiple_of(self.log_every) && comm.rank() == 0 {
            let elapsed = self.start.elapsed().as_secs_f64();
            let rate = done as f64 / elapsed.max(1e-9);
            let eta = (self.total_steps.saturating_sub(done)) as f64 / rate.max(1e-9);
            // Removed particles (domain.on_leaving = "remove") are named only when there are
            // any, so that a closed scene's log reads as before.
            let removed = if removed_all > 0 {
                format!("  {removed_all} removed (left the domain)")
            } else {
                String::new()
            };
            tracing::info!(
                "step {} t = {:.5} s  {:.0} steps/s  {} particles  {} contacts{removed}  ETA {:.0} s",
                sim.step,
                t,
                rate,
                n_all,
                contacts_all,
                eta
            );
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// The stop signal the ranks agree on after a step, if any. A signal reaches the ranks of a
/// decomposed run at different moments: they agree on it after every step (one small sum), so
/// that all stop after the same step, within the second mpirun leaves between its SIGTERM and
/// SIGKILL (crate::interrupt).
fn agreed_signal(
    comm: &dyn Comm,
    signals: &crate::interrupt::StopSignals,
) -> Option<(i32, &'static str)> {
    let received = signals.received();
    let counts = if comm.size() > 1 {
        comm.sum_u64(&received)
    } else {
        received.to_vec()
    };
    crate::interrupt::stop_signal(&counts)
}

/// Steps to the end time (or `--max-steps`), writing the scheduled frames, series rows and
/// checkpoints, showing progress, and stopping with a checkpoint on SIGINT or SIGTERM. A
/// stability stop leaves the state at the stop beside the checkpoints ([`stopped_unstable`]).
fn step_loop(
    opts: &RunOptions,
    engine: &mut Engine,
    out: &mut Outputs,
    id: &SceneId,
) -> Result<LoopEnd> {
    let comm = out.comm.clone();
    let rank = comm.rank();
    let dir = out.dir.clone();
    let mut scheduled = Scheduled::new(engine.state(), &dir);
    let end_time = engine.state().scene.simulation.end_time;
    let signals = crate::interrupt::StopSignals::install().map_err(anyhow::Error::msg)?;
    let progress = Progress::new(engine.state(), rank);
    let (step0, mut particle_steps) = (engine.state().step, 0u64);
    let mut stopped_by: Option<(i32, &str)> = None;
    let mut max_steps_reached = false;
    while engine.state().time + 0.5 * engine.state().dt < end_time {
        if opts
            .max_steps
            .is_some_and(|m| engine.state().step - step0 >= m)
        {
            max_steps_reached = true;
            break;
        }
        if let Err(e) = engine.step() {
            return Err(stopped_unstable(e, &*comm, engine, &dir, id));
        }
        particle_steps += engine.particle_count() as u64;
        if crate::tuning::Tuning::get().panic_at == Some((rank, engine.state().step)) {
            panic!(
                "POLYDEM_PANIC_AT: rank {rank} panics after step {} as asked",
                engine.state().step
            );
        }
        scheduled.write_due(engine, out, id)?;
        progress.show(&*comm, engine.state(), engine.state().step - step0);
        if let Some(signal) = agreed_signal(&*comm, &signals) {
            let path = save_checkpoint(&*comm, engine.synced()?, &dir, id)?;
            if rank == 0 {
                tracing::warn!(
                    "interrupted by {} after step {}: checkpoint written to {}; resume with \
                     --restart {}",
                    signal.1,
                    engine.state().step,
                    path.display(),
                    path.display()
                );
            }
            stopped_by = Some(signal);
            break;
        }
    }
    progress.finish();
    Ok(LoopEnd {
        first_step: step0,
        wall: progress.start.elapsed().as_secs_f64(),
        particle_steps,
        stopped_by,
        max_steps_reached,
    })
}

/// The closing frame, series row and checkpoint of a run that reached its end (the checkpoint
/// alone after `--max-steps`; nothing of one stopped by a signal, whose checkpoint is written),
/// and `summary.json` (rank 0).
fn finish(
    opts: &RunOptions,
    engine: &mut Engine,
    out: &mut Outputs,
    id: &SceneId,
    ended: LoopEnd,
    warnings: Vec<String>,
) -> Result<RunSummary> {
    let comm = out.comm.clone();
    let (rank, ranks) = (comm.rank(), comm.size());
    let dir = out.dir.clone();
    let (backend_name, device) = (engine.backend_name(), engine.device());
    let device_bytes = engine.device_bytes();
    let neighbor = engine.neighbor_report();
    if rank == 0 {
        log_neighbor_report(&neighbor);
    }
    let sim = engine.synced()?;
    if ended.stopped_by.is_none() {
        // A `--max-steps` stop, like a signal's, writes no frame or series row off the
        // schedule: restarted, the run then gives the uninterrupted run's series byte for byte
        // (the closing row once stayed in the series as an extra line).
        if !ended.max_steps_reached {
            out.frame(sim)?;
            out.series(sim)?;
        }
        if sim.scene.output.checkpoint_interval.is_some() {
            save_checkpoint(&*comm, sim, &dir, id)?;
        }
    }
    let g = whole_run(&*comm, sim);
    if rank == 0 && g.stats.removed > 0 {
        tracing::info!(
            "{} particles left the domain and were removed (domain.on_leaving = \"remove\"); \
             summary.json: particles_removed",
            g.stats.removed
        );
    }
    let (kt, kr, pg) = g.energies;
    let particle_steps = comm.sum_u64(&[ended.particle_steps])[0];
    let wall = ended.wall;
    let threads = rayon::current_num_threads();
    let parallel = parallel_report(&*comm, sim);
    let stopped_by = ended.stopped_by;
    let rate = particle_steps as f64 / wall.max(1e-12);
    let summary = RunSummary {
        scene: opts.scene.display().to_string(),
        backend: backend_name,
        precision: device.precision_name(),
        ranks,
        parallel,
        threads,
        steps: sim.step - ended.first_step,
        final_step: sim.step,
        simulated_time: sim.time,
        dt: sim.dt,
        wall_seconds: wall,
        particle_steps_per_second: rate,
        particle_steps_per_second_per_thread: rate / threads as f64,
        particles: g.particles,
        particles_removed: g.stats.removed,
        contacts: g.stats.contacts,
        wall_contacts: g.stats.wall_contacts,
        energy: SummaryEnergies {
            kinetic_translational: kt,
            kinetic_rotational: kr,
            potential_gravity: pg,
            elastic: g.stats.elastic_energy,
        },
        stage_seconds: serde_json::to_value(sim.timers)?,
        neighbor: serde_json::to_value(&neighbor)?,
        device_bytes,
        interrupted: stopped_by.is_some(),
        signal: stopped_by.map(|s| s.1),
        exit_status: stopped_by.map_or(0, |s| crate::interrupt::exit_status(s.0)),
        warnings,
    };
    if rank == 0 {
        write_atomic(
            &dir.join("summary.json"),
            serde_json::to_string_pretty(&summary)?.as_bytes(),
        )
        .with_context(|| format!("{}: cannot write summary.json", dir.display()))?;
    }
    Ok(summary)
}

/// The log's account of who built the pair lists (`summary.json`'s `neighbor`).
fn log_neighbor_report(r: &crate::neighbor::NeighborReport) {
    let secs = |x: Option<f64>| x.map_or("-".into(), |x| format!("{x:.3e} s"));
    tracing::info!(
        "neighbor lists (mode {}, last builder {}): {} device builds, {} host builds, {} stale \
         and {} late host lists, GPU waited {:.3} s for the host; τ_CPU {}, τ_GPU {}, q {}",
        r.mode,
        r.builder,
        r.device_builds,
        r.host_builds,
        r.stale_host_lists,
        r.late_host_lists,
        r.host_wait_s,
        secs(r.tau_cpu_s),
        secs(r.tau_gpu_s),
        r.q.map_or("-".into(), |q| format!("{q:.3}"))
    );
}

/// Says at the start who builds the pair lists: the mode, or why it does not apply here.
fn log_neighbor_mode(scene: &crate::scene::Scene, device: Device, ranks: usize) {
    use crate::scene::NeighborMode;
    let mode = scene.simulation.neighbor.mode;
    let what = match (device, mode) {
        (Device::Cpu | Device::CpuMixed, _) => format!(
            "the CPU backend builds its pair lists itself (simulation.neighbor.mode = \"{}\" \
             chooses the builder of a GPU run)",
            mode.name()
        ),
        (Device::Cuda { .. }, NeighborMode::Gpu) => "the GPU builds the pair lists".into(),
        (Device::Cuda { .. }, _) if ranks > 1 => format!(
            "a decomposed run builds every pair list on the GPU after the host's exchange \
             (simulation.neighbor.mode = \"{}\" applies to one rank; docs/design.md §7)",
            mode.name()
        ),
        (Device::Cuda { .. }, NeighborMode::Cpu) => {
            "the host builds the pair lists and uploads them (neighbor mode cpu)".into()
        }
        (Device::Cuda { .. }, NeighborMode::Hybrid) => format!(
            "the host pre-builds the next pair list while the GPU steps (neighbor mode hybrid, \
             hybrid skin {:.3e} m)",
            scene.simulation.neighbor.hybrid_skin
        ),
        (Device::Cuda { .. }, NeighborMode::Auto) => {
            "neighbor mode auto: measures gpu and hybrid list building and runs the faster".into()
        }
    };
    tracing::info!("{what}");
}
