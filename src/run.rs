//! `polydem run` and `polydem check`: the driver around [`Simulation::step`] — output frames,
//! time series, checkpoints and restarts, progress, Ctrl-C, and the closing `summary.json`
//! (stage 10 of DESIGN.md §1).

use crate::backend;
use crate::backend::Engine;
use crate::backend::cuda::{CudaSimulation, Precision};
use crate::domain::collect::{GlobalStats, gather_state, global_stats};
use crate::domain::{Comm, SerialComm};
use crate::io::checkpoint::fnv1a64;
use crate::io::{
    Checkpoint, FrameView, FrameWriter, SeriesRow, SeriesWriter, WallView, read_checkpoint,
    remove_temporary_files, write_atomic, write_checkpoint, write_particle_csv,
};
use crate::pipeline::{Simulation, SimulationError};
use crate::scene::restart::{SECTIONS_RECORD, SceneFingerprint, check_against_scene};
use crate::scene::{
    Inserter, InserterState, Scene, check_report, face_contact_times, impact_speed, load_scene,
};
use anyhow::{Context, Result, anyhow, bail};
use nalgebra::Vector3;
use serde_json::json;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// Which backend a run asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    /// CUDA when a usable GPU is present, else the CPU.
    Auto,
    /// The CPU (rayon).
    Cpu,
    /// CUDA.
    Cuda,
}

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
}

/// What `polydem run` writes into its output folder: `--overwrite` removes these (and
/// temporary files of interrupted writes), and nothing else.
pub const OUTPUT_ENTRIES: [&str; 7] = [
    "summary.json",
    "series.csv",
    "frames.pvd",
    "walls.pvd",
    "frames",
    "checkpoints",
    "particles",
];

/// Whether `name` is one of the run's outputs ([`OUTPUT_ENTRIES`]) or a temporary file of an
/// interrupted atomic write (`NAME.tmp-PID`).
fn is_run_output(name: &str) -> bool {
    OUTPUT_ENTRIES.contains(&name)
        || name
            .rsplit_once(".tmp-")
            .is_some_and(|(_, pid)| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// Makes `dir` ready for a run's output (rank 0, before the run).
///
/// - A path blocked by a file is refused, naming the file (not only the folder it blocks).
/// - A new run into a folder that already holds output is refused unless `overwrite`: its
///   series, summary and collections would be overwritten and a previous run's later
///   checkpoints and frames left mixed with the new ones. With `overwrite` the previous run's
///   outputs are removed ([`OUTPUT_ENTRIES`]); other files are kept and named in the log.
/// - A restart (`restart`) continues in the folder as it is.
pub fn prepare_output_dir(dir: &Path, overwrite: bool, restart: bool) -> Result<()> {
    // The nearest part of the path that exists must be a folder.
    for ancestor in dir.ancestors() {
        match std::fs::metadata(ancestor) {
            Ok(m) if m.is_dir() => break,
            Ok(_) if ancestor == dir => {
                bail!(
                    "{}: the output folder's path is a file, not a folder; give another --out \
                     (or output.dir)",
                    dir.display()
                )
            }
            Ok(_) => bail!(
                "{}: is a file, not a folder, so the output folder {} cannot be created in it; \
                 give another --out (or output.dir)",
                ancestor.display(),
                dir.display()
            ),
            // Not there yet, or below a file (which a shorter ancestor then names).
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory
                ) =>
            {
                continue;
            }
            Err(e) => {
                return Err(e).with_context(|| format!("{}: cannot inspect", ancestor.display()));
            }
        }
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the output directory", dir.display()))?;
    if restart {
        return Ok(());
    }
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list the output directory", dir.display()))?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    if names.is_empty() {
        return Ok(());
    }
    let (ours, others): (Vec<String>, Vec<String>) =
        names.into_iter().partition(|n| is_run_output(n));
    if !overwrite {
        if ours.is_empty() {
            // Only files the run does not write (notes, a scene copy): nothing is overwritten.
            return Ok(());
        }
        let shown: Vec<&str> = ours.iter().take(6).map(String::as_str).collect();
        bail!(
            "{}: the output folder holds a previous run's output ({}{}); give --overwrite to \
             remove it, --restart CHECKPOINT to continue that run, or another --out",
            dir.display(),
            shown.join(", "),
            if ours.len() > shown.len() {
                ", …"
            } else {
                ""
            }
        );
    }
    for name in &ours {
        let path = dir.join(name);
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        removed.with_context(|| format!("{}: cannot remove (--overwrite)", path.display()))?;
    }
    tracing::info!(
        "--overwrite: removed the previous output in {} ({})",
        dir.display(),
        ours.join(", ")
    );
    if !others.is_empty() {
        tracing::warn!(
            "{}: kept {} entries that polydem does not write: {}",
            dir.display(),
            others.len(),
            others.join(", ")
        );
    }
    Ok(())
}

/// What identifies a scene for restarts: its parsed sections ([`SceneFingerprint`]), and the
/// hash of the file's bytes that older checkpoints store.
struct SceneId {
    fingerprint: SceneFingerprint,
    legacy: u64,
}

impl SceneId {
    fn of(scene: &Scene, path: &Path) -> Result<Self> {
        let bytes =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        Ok(SceneId {
            fingerprint: SceneFingerprint::of(scene),
            legacy: fnv1a64(&bytes),
        })
    }
}

/// Picks the backend (DESIGN.md §5): `cuda` needs a usable GPU and NVRTC, `auto` takes the GPU
/// when there is one and says in the log why it does not.
pub fn choose_backend(choice: BackendChoice) -> Result<&'static str> {
    let info = backend::cuda_info();
    match choice {
        BackendChoice::Cpu => Ok("cpu"),
        BackendChoice::Cuda => match (&info.unavailable, info.gpus.first()) {
            (None, Some(g)) => {
                tracing::info!("running on GPU 0: {}", g.name);
                Ok("cuda")
            }
            (Some(why), _) => bail!("--backend cuda: {why}; use --backend cpu"),
            _ => bail!("--backend cuda: no GPU found; use --backend cpu"),
        },
        BackendChoice::Auto => match (&info.unavailable, info.gpus.first()) {
            (None, Some(g)) => {
                tracing::info!("running on GPU 0: {}", g.name);
                Ok("cuda")
            }
            (Some(why), _) => {
                tracing::info!("running on the CPU: {why}");
                Ok("cpu")
            }
            _ => {
                tracing::info!("running on the CPU");
                Ok("cpu")
            }
        },
    }
}

/// Events that happen every so many seconds of simulated time.
struct Schedule {
    interval: Option<f64>,
    next: f64,
}

impl Schedule {
    /// The schedule at time `now` (steps of `dt`): where [`Schedule::due`] would have left it
    /// had the run stepped from 0 to `now`. The next event is found by the same accumulation
    /// `due` does, not as `floor(now / i) · i`, whose round-off differs: a restart on an event
    /// then repeats it, or skips one, where the uninterrupted run did not.
    fn new(interval: Option<f64>, now: f64, dt: f64) -> Self {
        let next = match interval {
            Some(i) if i > 0.0 => {
                let mut next = i;
                while next <= now + 0.5 * dt {
                    next += i;
                }
                next
            }
            _ => f64::INFINITY,
        };
        Schedule { interval, next }
    }

    /// True once per interval, at the first step at or past each multiple (half a step early
    /// counts, so round-off in the accumulated time never skips a frame).
    fn due(&mut self, t: f64, dt: f64) -> bool {
        match self.interval {
            Some(i) if i > 0.0 && t + 0.5 * dt >= self.next => {
                while self.next <= t + 0.5 * dt {
                    self.next += i;
                }
                true
            }
            _ => false,
        }
    }
}

/// Output of a run in progress. Every rank writes its own frame piece; rank 0 writes the
/// collections, walls, series, checkpoints and summary from whole-run values.
struct Outputs {
    dir: PathBuf,
    frames: Option<FrameWriter>,
    series: Option<SeriesWriter>,
    type_template: Vec<usize>,
    comm: Arc<dyn Comm>,
    /// Step of the last series row (on every rank: the row's sums are collective).
    series_step: Option<u64>,
}

impl Outputs {
    fn frame(&mut self, sim: &Simulation) -> Result<()> {
        let s = &sim.scene;
        let rank = self.comm.rank();
        let ranks = self.comm.size();
        let wall_forces = if ranks > 1 {
            global_stats(&*self.comm, sim).wall_forces
        } else {
            sim.wall_forces.clone()
        };
        let view = FrameView {
            particles: &sim.particles,
            templates: &s.templates,
            type_template: &self.type_template,
            rank: rank as u32,
            fields: &s.output.fields,
        };
        if let Some(fw) = self.frames.as_mut() {
            let placed: Vec<Vec<[Vector3<f64>; 3]>> = s
                .walls
                .iter()
                .map(|w| {
                    let pose = w.motion.transform(sim.time);
                    w.triangles
                        .iter()
                        .map(|t| t.map(|v| (pose * nalgebra::Point3::from(v)).coords))
                        .collect()
                })
                .collect();
            let walls: Vec<WallView> = s
                .walls
                .iter()
                .zip(&placed)
                .zip(&wall_forces)
                .map(|((w, tris), f)| WallView {
                    name: &w.name,
                    triangles: tris,
                    force: *f,
                })
                .collect();
            fw.write_frame(sim.step, sim.time, std::slice::from_ref(&view), &walls)?;
        }
        if s.output.formats.csv {
            let particles_dir = self.dir.join("particles");
            std::fs::create_dir_all(&particles_dir)
                .with_context(|| format!("{}: cannot create", particles_dir.display()))?;
            let name = if ranks > 1 {
                format!("step_{:010}_r{rank:04}.csv", sim.step)
            } else {
                format!("step_{:010}.csv", sim.step)
            };
            write_particle_csv(&particles_dir.join(name), sim.time, &view)?;
        }
        // The .pvtu names every rank's piece: all are on disk before the frame is complete.
        self.comm.barrier();
        Ok(())
    }

    /// Appends the series row of the current step, once: the closing row of a run that
    /// ends on a series event is that event's row.
    fn series(&mut self, sim: &Simulation) -> Result<()> {
        if self.series_step == Some(sim.step) {
            return Ok(());
        }
        self.series_step = Some(sim.step);
        let g = whole_run(&*self.comm, sim);
        let (kt, kr, pg) = g.energies;
        if let Some(series) = self.series.as_mut() {
            series.append(&SeriesRow {
                step: sim.step,
                time: sim.time,
                kinetic_translational: kt,
                kinetic_rotational: kr,
                potential_gravity: pg,
                elastic: g.stats.elastic_energy,
                contacts: g.stats.contacts,
                wall_contacts: g.stats.wall_contacts,
                wall_forces: g.wall_forces,
            })?;
        }
        Ok(())
    }
}

/// The whole run's observables: this rank's on one rank, sums over ranks otherwise.
/// The whole run's particles, contacts (with walls) and removed particles, for the progress
/// line: counts only, without [`whole_run`]'s energies, which sum every particle in id order
/// and would cost a sort of the GPU's host copy every hundred steps.
fn whole_run_counts(comm: &dyn Comm, sim: &Simulation) -> (u64, u64, u64) {
    let s = &sim.stats;
    let local = [
        sim.particles.len() as u64,
        s.contacts + s.wall_contacts,
        s.removed,
    ];
    if comm.size() > 1 {
        let u = comm.sum_u64(&local);
        (u[0], u[1], u[2])
    } else {
        (local[0], local[1], local[2])
    }
}

fn whole_run(comm: &dyn Comm, sim: &Simulation) -> GlobalStats {
    if comm.size() > 1 {
        return global_stats(comm, sim);
    }
    GlobalStats {
        particles: sim.particles.len() as u64,
        stats: sim.stats,
        energies: sim.energies(),
        wall_forces: sim.wall_forces.clone(),
    }
}

/// The checkpoint of the current state, particles by global id whatever the backend's order;
/// in a decomposed run the whole run's state gathered on rank 0 (`None` on the other ranks).
fn checkpoint_of(comm: &dyn Comm, sim: &Simulation, id: &SceneId) -> Result<Option<Checkpoint>> {
    let inserter = serde_json::to_vec(&sim.inserter.state())?;
    let (particles, history, removed) = if comm.size() > 1 {
        let removed = comm.sum_u64(&[sim.stats.removed])[0];
        match gather_state(comm, sim, 0) {
            Some((p, h)) => (p, h, removed),
            None => return Ok(None),
        }
    } else {
        // By global id, as gathered from many ranks: the GPU keeps its own (cell) order.
        (
            crate::domain::collect::sorted_by_id(&sim.particles),
            sim.history.clone(),
            sim.stats.removed,
        )
    };
    Ok(Some(Checkpoint {
        step: sim.step,
        time: sim.time,
        particles,
        history,
        rng_state: sim.inserter.state().rng,
        inserter,
        next_id: sim.next_id,
        scene_hash: id.fingerprint.hash(),
        extra: vec![
            ("removed".into(), removed.to_le_bytes().to_vec()),
            (SECTIONS_RECORD.into(), id.fingerprint.record()),
        ],
    }))
}

/// A run stopped by the stability guard (`crate::stability`), a non-finite value or a particle
/// leaving the domain through a closed face (`domain.on_leaving`): the last
/// scheduled checkpoint is left as it is, and the state at the stop is written beside it as
/// `checkpoints/unstable-step-<step>.ckpt` for a post-mortem (or a restart with a smaller step),
/// on one rank and when every value is finite. Other errors pass through unchanged.
fn stopped_unstable(
    e: anyhow::Error,
    comm: &dyn Comm,
    engine: &mut Engine,
    dir: &Path,
    id: &SceneId,
) -> anyhow::Error {
    let unstable = matches!(
        e.downcast_ref::<SimulationError>(),
        Some(
            SimulationError::Unstable { .. }
                | SimulationError::NonFinite { .. }
                | SimulationError::LeftDomain { .. }
        )
    );
    if !unstable {
        return e;
    }
    if comm.size() > 1 {
        return e.context("no checkpoint of the stopped state: the run is decomposed");
    }
    let sim = match engine.synced() {
        Ok(sim) => sim,
        Err(sync) => return e.context(format!("the stopped state could not be read: {sync}")),
    };
    let p = &sim.particles;
    let finite = (0..p.len()).all(|i| {
        p.position[i].iter().all(|x| x.is_finite())
            && p.velocity[i].iter().all(|x| x.is_finite())
            && p.angular_velocity[i].iter().all(|x| x.is_finite())
            && p.orientation[i].coords.iter().all(|x| x.is_finite())
    });
    if !finite {
        return e.context("no checkpoint of the stopped state: it holds non-finite values");
    }
    let path = dir
        .join("checkpoints")
        .join(format!("unstable-step-{}.ckpt", sim.step));
    let written = checkpoint_of(comm, sim, id).and_then(|c| match c {
        Some(c) => {
            std::fs::create_dir_all(dir.join("checkpoints"))?;
            write_checkpoint(&path, &c).map_err(anyhow::Error::from)
        }
        None => Ok(()),
    });
    match written {
        Ok(()) => e.context(format!(
            "the state at the stop is in {} (the last scheduled checkpoint is unchanged)",
            path.display()
        )),
        Err(w) => e.context(format!("the state at the stop could not be written: {w}")),
    }
}

/// Writes the checkpoint (a collective call in a decomposed run; rank 0 writes) and returns
/// its path.
fn save_checkpoint(comm: &dyn Comm, sim: &Simulation, dir: &Path, id: &SceneId) -> Result<PathBuf> {
    let ckdir = dir.join("checkpoints");
    let path = checkpoint_path(dir, sim.step);
    if let Some(checkpoint) = checkpoint_of(comm, sim, id)? {
        std::fs::create_dir_all(&ckdir)
            .with_context(|| format!("{}: cannot create", ckdir.display()))?;
        write_checkpoint(&path, &checkpoint)?;
        // The newest is also `latest.ckpt`, so that a restart needs no step number.
        write_checkpoint(&ckdir.join("latest.ckpt"), &checkpoint)?;
    }
    comm.barrier();
    Ok(path)
}

/// The periodic checkpoints (those of the `checkpoint_interval` schedule) on disk, oldest first,
/// pruned to the newest `output.checkpoint_keep`. `latest.ckpt`, the checkpoint of an
/// interrupt or of the end of a run off the schedule, and `unstable-step-*.ckpt` are never
/// among them, so never deleted.
struct KeptCheckpoints {
    keep: Option<u64>,
    periodic: std::collections::VecDeque<PathBuf>,
}

impl KeptCheckpoints {
    /// The periodic checkpoints already on disk in `dir` at step `step` (a restart): the steps
    /// the schedule fires at, found by replaying it with the run's own time accumulation.
    fn new(scene: &Scene, dir: &Path, step: u64) -> Self {
        let keep = scene.output.checkpoint_keep;
        let mut periodic = std::collections::VecDeque::new();
        if keep.is_some() && step > 0 {
            let dt = scene.time_step();
            let mut at = Schedule::new(scene.output.checkpoint_interval, 0.0, dt);
            let mut t = 0.0;
            for k in 1..=step {
                t += dt;
                if at.due(t, dt) {
                    let path = checkpoint_path(dir, k);
                    if path.is_file() {
                        periodic.push_back(path);
                    }
                }
            }
        }
        KeptCheckpoints { keep, periodic }
    }

    /// Records the periodic checkpoint just written at `path` and, on rank 0, deletes the
    /// oldest beyond the number kept.
    fn push(&mut self, rank: usize, path: PathBuf) -> Result<()> {
        let Some(keep) = self.keep else {
            return Ok(());
        };
        if self.periodic.back() != Some(&path) {
            self.periodic.push_back(path);
        }
        while self.periodic.len() as u64 > keep {
            if let Some(old) = self.periodic.pop_front()
                && rank == 0
            {
                std::fs::remove_file(&old)
                    .or_else(|e| match e.kind() {
                        std::io::ErrorKind::NotFound => Ok(()),
                        _ => Err(e),
                    })
                    .with_context(|| format!("{}: cannot delete", old.display()))?;
            }
        }
        Ok(())
    }
}

/// The file of the checkpoint at `step`.
fn checkpoint_path(dir: &Path, step: u64) -> PathBuf {
    dir.join("checkpoints")
        .join(format!("step_{step:010}.ckpt"))
}

/// What every rank needs of a checkpoint to restart: all but the particles and history, which
/// stay on rank 0 until the first exchange sends them to their owners.
struct RestartHeader {
    step: u64,
    time: f64,
    next_id: u64,
    inserter: Vec<u8>,
    removed: u64,
}

/// Reads a checkpoint on rank 0 and shares its header with every rank; rank 0 also gets the
/// particles and history. An unreadable checkpoint stops every rank with rank 0's message.
fn read_restart(
    comm: &dyn Comm,
    path: &Path,
    scene: &Scene,
    id: &SceneId,
) -> Result<(RestartHeader, Option<Checkpoint>)> {
    use crate::domain::pack::{Reader, Writer};
    let mut w = Writer::default();
    let mut local = None;
    if comm.rank() == 0 {
        // The scene first: a state checked against the wrong scene would report the wrong
        // field.
        let checked = read_checkpoint(path)
            .map_err(anyhow::Error::from)
            .and_then(|c| {
                id.fingerprint
                    .check(&c, id.legacy)
                    .and_then(|_| check_against_scene(&c, scene))
                    .map_err(|e| anyhow!("checkpoint {}: {e}", path.display()))?;
                Ok(c)
            });
        match checked {
            Ok(c) => {
                let removed = c
                    .extra
                    .iter()
                    .find(|(k, _)| k == "removed")
                    .and_then(|(_, b)| b.as_slice().try_into().ok().map(u64::from_le_bytes))
                    .unwrap_or(0);
                w.u64(0);
                w.u64(c.step);
                w.f64(c.time);
                w.u64(c.next_id);
                w.u64(removed);
                w.bytes(&c.inserter);
                local = Some(c);
            }
            Err(e) => {
                w.u64(1);
                w.bytes(format!("{e:#}").as_bytes());
            }
        }
    }
    let mut buf = w.buf;
    comm.broadcast(&mut buf, 0);
    let mut r = Reader::new(&buf);
    if r.u64() != 0 {
        bail!("{}", String::from_utf8_lossy(r.bytes()));
    }
    let header = RestartHeader {
        step: r.u64(),
        time: r.f64(),
        next_id: r.u64(),
        removed: r.u64(),
        inserter: r.bytes().to_vec(),
    };
    Ok((header, local))
}

/// `polydem run` on one rank: returns the summary it also writes to `summary.json`.
pub fn run(opts: &RunOptions) -> Result<serde_json::Value> {
    run_on(opts, Arc::new(SerialComm))
}

/// The backend of a decomposed run and, on the GPU, the device of this rank: its node-local
/// rank modulo the GPUs it sees (DESIGN.md §6).
fn choose_parallel_backend(
    choice: BackendChoice,
    comm: &dyn Comm,
) -> Result<(&'static str, usize)> {
    let local = choose_backend(choice)?;
    // Every rank must step on the same backend (their collectives differ): with `auto`, one
    // rank without a usable GPU puts all on the CPU (an explicit `cuda` has already failed on
    // that rank, which ends the run on all).
    let cpu_somewhere = comm.any(local == "cpu");
    let name = if cpu_somewhere { "cpu" } else { local };
    if cpu_somewhere && local == "cuda" {
        tracing::warn!("another rank has no usable GPU: all ranks run on the CPU");
    }
    if name == "cpu" {
        return Ok(("cpu", 0));
    }
    let gpus = backend::cuda_info().gpus.len().max(1);
    let local = crate::domain::comm::node_local_rank().unwrap_or(comm.rank());
    let ordinal = local % gpus;
    tracing::info!(
        "{} ranks on the GPU: rank {} on GPU {ordinal} of {gpus}",
        comm.size(),
        comm.rank()
    );
    Ok(("cuda", ordinal))
}

/// `polydem run` on the ranks of `comm` (one rank: [`run`]). Rank 0 returns the summary and
/// writes `summary.json`; the other ranks return the same summary without writing it.
pub fn run_on(opts: &RunOptions, comm: Arc<dyn Comm>) -> Result<serde_json::Value> {
    let mut scene = load_scene(&opts.scene).map_err(|e| anyhow!("{e}"))?;
    if let Some(out) = &opts.out {
        scene.output.dir = out.clone();
    }
    let ranks = comm.size();
    let rank = comm.rank();
    let (backend_name, ordinal) = if ranks > 1 {
        choose_parallel_backend(opts.backend, &*comm)?
    } else {
        (choose_backend(opts.backend)?, 0)
    };
    let warnings = time_step_warnings(&scene);
    if rank == 0 {
        for msg in &warnings {
            tracing::warn!("{msg}");
        }
    }
    let hash = SceneId::of(&scene, &opts.scene)?;
    let dir = scene.output.dir.clone();
    if rank == 0 {
        prepare_output_dir(&dir, opts.overwrite, opts.restart.is_some())?;
        // Leftovers of writes killed in an earlier run: never read, they would pile up.
        let removed = remove_temporary_files(&dir)?;
        if !removed.is_empty() {
            tracing::info!(
                "removed {} temporary file(s) left by a killed run in {}",
                removed.len(),
                dir.display()
            );
        }
    }
    comm.barrier();
    let type_template: Vec<usize> = scene.particle_types.iter().map(|t| t.template).collect();
    let wall_names: Vec<String> = scene.walls.iter().map(|w| w.name.clone()).collect();
    let series_path = dir.join("series.csv");

    let (sim, resumed) = match &opts.restart {
        Some(path) => {
            let (header, local) = read_restart(&*comm, path, &scene, &hash)?;
            let state: InserterState = serde_json::from_slice(&header.inserter)
                .with_context(|| format!("{}: insertion state", path.display()))?;
            let inserter = Inserter::try_restore(&scene, &state)
                .map_err(|e| anyhow!("{}: {e}", path.display()))?;
            let (particles, history) = local.map(|c| (c.particles, c.history)).unwrap_or_default();
            let mut sim = Simulation::restore_parallel(
                scene,
                comm.clone(),
                particles,
                history,
                inserter,
                header.time,
                header.step,
                header.next_id,
            )?;
            // The removal count is the whole run's; rank 0 carries it.
            sim.stats.removed = if rank == 0 { header.removed } else { 0 };
            tracing::info!(
                "restarted from {} at step {} (t = {} s) on {ranks} rank(s)",
                path.display(),
                sim.step,
                sim.time
            );
            (sim, true)
        }
        None => {
            let sim = if backend_name == "cuda" {
                Simulation::new_parallel_unevaluated(scene, comm.clone())?
            } else {
                Simulation::new_parallel(scene, comm.clone())?
            };
            (sim, false)
        }
    };
    let mut engine = if backend_name == "cuda" {
        let mut c =
            CudaSimulation::new(sim, ordinal, opts.precision).map_err(|e| anyhow!("{e}"))?;
        if !resumed {
            c.evaluate_first_forces().map_err(|e| anyhow!("{e}"))?;
        }
        tracing::info!(
            "kernels compiled for {} ({:?} pair geometry)",
            c.device,
            c.precision
        );
        Engine::Cuda(Box::new(c))
    } else {
        Engine::Cpu(Box::new(sim))
    };
    let sim = engine.host();
    let s = &sim.scene;
    let (nr, r) = (ranks as u32, rank as u32);
    let frames = if s.output.formats.vtu && s.output.frame_interval.is_some() {
        Some(if resumed {
            FrameWriter::resume_rank(&dir, nr, r, sim.time)?
        } else {
            FrameWriter::new_rank(&dir, nr, r)?
        })
    } else {
        None
    };
    let series = match (rank, resumed) {
        (0, true) => Some(SeriesWriter::resume(&series_path, &wall_names, sim.step)?),
        (0, false) => Some(SeriesWriter::new(&series_path, &wall_names)?),
        _ => None,
    };
    let mut out = Outputs {
        dir: dir.clone(),
        frames,
        series,
        type_template,
        comm: comm.clone(),
        // A resumed series ends at the checkpoint's step at most: its row there, if any, is
        // kept, never written twice.
        series_step: resumed.then_some(sim.step),
    };
    let mut frame_at = Schedule::new(s.output.frame_interval, sim.time, sim.dt);
    let mut series_at = Schedule::new(Some(s.output.series_interval), sim.time, sim.dt);
    let mut checkpoint_at = Schedule::new(s.output.checkpoint_interval, sim.time, sim.dt);
    let mut kept = KeptCheckpoints::new(s, &dir, sim.step);
    let end_time = s.simulation.end_time;
    let log_every = s.output.log_interval_steps.max(1);
    if !resumed {
        out.frame(engine.synced()?)?;
        out.series(engine.synced()?)?;
    }

    let signals = crate::interrupt::StopSignals::install().map_err(|e| anyhow!("{e}"))?;
    let sim = engine.host();
    let total_steps = ((end_time - sim.time) / sim.dt).ceil().max(0.0) as u64;
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
    let start = Instant::now();
    let (step0, mut particle_steps) = (engine.host().step, 0u64);
    let mut stopped_by: Option<(i32, &str)> = None;
    while engine.host().time + 0.5 * engine.host().dt < end_time {
        if opts
            .max_steps
            .is_some_and(|m| engine.host().step - step0 >= m)
        {
            break;
        }
        if let Err(e) = engine.step() {
            return Err(stopped_unstable(e, &*comm, &mut engine, &dir, &hash));
        }
        particle_steps += engine.host().particles.len() as u64;
        let (t, dt) = (engine.host().time, engine.host().dt);
        if frame_at.due(t, dt) {
            out.frame(engine.synced()?)?;
        }
        if series_at.due(t, dt) {
            out.series(engine.synced()?)?;
        }
        if checkpoint_at.due(t, dt) {
            let path = save_checkpoint(&*comm, engine.synced()?, &dir, &hash)?;
            kept.push(rank, path)?;
        }
        let sim = engine.host();
        let done = sim.step - step0;
        // Whole-run counts at deterministic steps only: every rank joins the sums.
        let (n_all, contacts_all, removed_all) = if done % 100 == 0 || done % log_every == 0 {
            whole_run_counts(&*comm, sim)
        } else {
            (0, 0, 0)
        };
        if let Some(b) = &bar {
            b.set_position(done);
            if done % 100 == 0 {
                b.set_message(format!(
                    "t = {t:.4} s, {n_all} particles, {contacts_all} contacts"
                ));
            }
        } else if done % log_every == 0 && rank == 0 {
            let elapsed = start.elapsed().as_secs_f64();
            let rate = done as f64 / elapsed.max(1e-9);
            let eta = (total_steps.saturating_sub(done)) as f64 / rate.max(1e-9);
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
        // A signal reaches the ranks of a decomposed run at different moments: they agree on
        // it after every step (one small sum), so that all stop after the same step, within
        // the second mpirun leaves between its SIGTERM and SIGKILL (crate::interrupt).
        let received = signals.received();
        let counts = if ranks > 1 {
            let c = comm.sum_u64(&received);
            [c[0], c[1]]
        } else {
            received
        };
        if let Some(signal) = crate::interrupt::stop_signal(counts) {
            let path = save_checkpoint(&*comm, engine.synced()?, &dir, &hash)?;
            if rank == 0 {
                tracing::warn!(
                    "interrupted by {} after step {}: checkpoint written to {}; resume with \
                     --restart {}",
                    signal.1,
                    engine.host().step,
                    path.display(),
                    path.display()
                );
            }
            stopped_by = Some(signal);
            break;
        }
    }
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let wall = start.elapsed().as_secs_f64();
    let sim = engine.synced()?;
    if stopped_by.is_none() {
        out.frame(sim)?;
        out.series(sim)?;
        if sim.scene.output.checkpoint_interval.is_some() {
            save_checkpoint(&*comm, sim, &dir, &hash)?;
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
    let particle_steps = comm.sum_u64(&[particle_steps])[0];
    let threads = rayon::current_num_threads();
    let parallel = parallel_report(&*comm, sim);
    let summary = json!({
        "scene": opts.scene.display().to_string(),
        "backend": backend_name,
        "ranks": ranks,
        "parallel": parallel,
        "threads": threads,
        "steps": sim.step - step0,
        "final_step": sim.step,
        "simulated_time": sim.time,
        "dt": sim.dt,
        "wall_seconds": wall,
        "particle_steps_per_second": particle_steps as f64 / wall.max(1e-12),
        "particle_steps_per_second_per_thread": particle_steps as f64 / wall.max(1e-12) / threads as f64,
        "particles": g.particles,
        "particles_removed": g.stats.removed,
        "contacts": g.stats.contacts,
        "wall_contacts": g.stats.wall_contacts,
        "energy": {"kinetic_translational": kt, "kinetic_rotational": kr, "potential_gravity": pg, "elastic": g.stats.elastic_energy},
        "stage_seconds": sim.timers,
        "interrupted": stopped_by.is_some(),
        "signal": stopped_by.map(|s| s.1),
        "exit_status": stopped_by.map_or(0, |s| crate::interrupt::exit_status(s.0)),
        "warnings": warnings,
    });
    if rank == 0 {
        write_atomic(
            &dir.join("summary.json"),
            serde_json::to_string_pretty(&summary)?.as_bytes(),
        )
        .with_context(|| format!("{}: cannot write summary.json", dir.display()))?;
    }
    Ok(summary)
}

/// Per-rank particle counts, stage seconds and the decomposition's own timers, gathered from
/// every rank (a collective call; `null` on one rank).
fn parallel_report(comm: &dyn Comm, sim: &Simulation) -> serde_json::Value {
    let Some(par) = sim.parallel.as_deref() else {
        return serde_json::Value::Null;
    };
    let local = json!({
        "rank": comm.rank(),
        "particles": sim.particles.len(),
        "ghosts": par.ghosts.particles.len(),
        "box": {"lo": par.own_box().lo.as_slice(), "hi": par.own_box().hi.as_slice()},
        "stage_seconds": sim.timers,
        "decomposition_seconds": par.timers,
    });
    let parts: Vec<serde_json::Value> = comm
        .all_gather(local.to_string().as_bytes())
        .iter()
        .map(|b| serde_json::from_slice(b).unwrap_or(serde_json::Value::Null))
        .collect();
    json!({ "per_rank": parts })
}

/// `polydem check`: validates the scene and reports the time-step estimates and counts.
///
/// Besides the Rayleigh step, it reports the face-to-face contact time of each particle type at
/// an impact speed of 1 m/s and at the free-fall speed over the domain's height, and the chosen
/// dt as a fraction of the shortest. A dt above [`SAFE_FACE_FRACTION`] of it is flagged: face
/// impacts then leave the 2 % restitution band of the contact law (docs/contact.md); up to
/// [`ENERGY_FACE_FRACTION`] of it an elastic face impact also keeps its energy to 1e-3
/// (docs/validation.md §4).
pub fn check(scene_path: &Path) -> Result<serde_json::Value> {
    let scene: Scene = load_scene(scene_path).map_err(|e| anyhow!("{e}"))?;
    let mut report = check_report(&scene);
    let v_fall = impact_speed(&scene);
    let times = face_contact_times(&scene, v_fall);
    let shortest = times.iter().map(|t| t.1).fold(f64::INFINITY, f64::min);
    let dt = scene.time_step();
    report["contact_time"] = json!({
        "face_to_face_at_impact_speed": v_fall,
        "per_type": times.iter().map(|(n, t)| json!({"type": n, "seconds": t})).collect::<Vec<_>>(),
        "dt_fraction_of_shortest": dt / shortest,
        "recommended_dt_max": SAFE_FACE_FRACTION * shortest,
        "energy_conserving_dt_max": ENERGY_FACE_FRACTION * shortest,
    });
    let warnings = time_step_warnings(&scene);
    for msg in &warnings {
        tracing::warn!("{msg}");
    }
    if !warnings.is_empty() {
        report["warnings"] = json!(warnings);
    }
    Ok(report)
}

/// The time-step warnings of a scene: a step above [`SAFE_FACE_FRACTION`] of the shortest
/// face-to-face contact time. `polydem check` reports them and `polydem run` logs them at the
/// start and lists them in `summary.json`, so that a run at an unstable step is never silent.
pub fn time_step_warnings(scene: &Scene) -> Vec<String> {
    let v_fall = impact_speed(scene);
    let shortest = face_contact_times(scene, v_fall)
        .iter()
        .map(|t| t.1)
        .fold(f64::INFINITY, f64::min);
    let dt = scene.time_step();
    let mut out = Vec::new();
    // The relative margin keeps dt_fraction = 0.05 itself, whose product with the contact time
    // can round one ulp above 0.05 × that time, from being flagged.
    if dt > SAFE_FACE_FRACTION * shortest * (1.0 + 1e-12) {
        out.push(format!(
            "dt = {dt:e} s exceeds {SAFE_FACE_FRACTION} of the face-to-face contact time {shortest:e} s at {v_fall:.2} m/s ({:.3} × it): face impacts leave the 2 % restitution band",
            dt / shortest
        ));
    }
    out
}

/// The largest step, as a fraction of the face-to-face contact time, at which every face impact
/// keeps the restitution of the contact law within 2 % at every phase of first touch
/// (docs/contact.md §1: 1.9 % at this step in the dimensionless face impact, unstable for
/// e = 0.1 at twice it).
pub const SAFE_FACE_FRACTION: f64 = 0.05;

/// The largest step, as a fraction of the face-to-face contact time, at which no elastic face
/// impact gains more than 1e-3 of its energy (8e-4 measured, docs/validation.md §4).
pub const ENERGY_FACE_FRACTION: f64 = 0.025;

/// Options of `polydem bench`.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub scene: PathBuf,
    pub backend: BackendChoice,
    pub precision: Precision,
    /// Steps run before timing (list build, kernel warm-up).
    pub warmup: u64,
    /// Steps timed.
    pub steps: u64,
}

/// `polydem bench`: steps a scene without output and reports particle-steps per second, the
/// per-stage seconds, contacts and candidate pairs per particle and (on the GPU) the bytes of
/// device memory per particle (DESIGN.md §9).
pub fn bench(opts: &BenchOptions) -> Result<serde_json::Value> {
    bench_on(opts, Arc::new(SerialComm))
}

/// `polydem bench` on the ranks of `comm`: the same report for the whole run (particle-steps
/// per second of all ranks together, stage seconds of rank 0) plus each rank's particles,
/// stage seconds and the decomposition's exchange and waiting times.
pub fn bench_on(opts: &BenchOptions, comm: Arc<dyn Comm>) -> Result<serde_json::Value> {
    let scene = load_scene(&opts.scene).map_err(|e| anyhow!("{e}"))?;
    let ranks = comm.size();
    let (backend_name, ordinal) = if ranks > 1 {
        choose_parallel_backend(opts.backend, &*comm)?
    } else {
        (choose_backend(opts.backend)?, 0)
    };
    let t_setup = Instant::now();
    let mut engine = if backend_name == "cuda" {
        let host = Simulation::new_parallel_unevaluated(scene, comm.clone())?;
        let mut c =
            CudaSimulation::new(host, ordinal, opts.precision).map_err(|e| anyhow!("{e}"))?;
        c.evaluate_first_forces().map_err(|e| anyhow!("{e}"))?;
        Engine::Cuda(Box::new(c))
    } else {
        Engine::Cpu(Box::new(Simulation::new_parallel(scene, comm.clone())?))
    };
    let setup = t_setup.elapsed().as_secs_f64();
    for _ in 0..opts.warmup {
        engine.step()?;
    }
    let timers_before = engine.host().timers;
    let host = match &mut engine {
        Engine::Cpu(sim) => &mut **sim,
        Engine::Cuda(c) => &mut c.host,
    };
    if let Some(par) = host.parallel.as_deref_mut() {
        // The per-rank decomposition timers of the report cover the timed steps only.
        par.timers = Default::default();
    }
    let n = comm.sum_u64(&[engine.host().particles.len() as u64])[0] as usize;
    comm.barrier();
    let start = Instant::now();
    for _ in 0..opts.steps {
        engine.step()?;
    }
    comm.barrier();
    let wall = start.elapsed().as_secs_f64();
    let t = engine.host().timers;
    let stages = json!({
        "integrate": t.integrate - timers_before.integrate,
        "exchange": t.exchange - timers_before.exchange,
        "neighbor": t.neighbor - timers_before.neighbor,
        "pairs": t.pairs - timers_before.pairs,
        "walls": t.walls - timers_before.walls,
        "reduce": t.reduce - timers_before.reduce,
    });
    let (device, bytes, pairs) = match &engine {
        Engine::Cuda(c) => (
            c.device.clone(),
            Some(c.device_bytes()),
            Some(c.candidate_pairs()),
        ),
        Engine::Cpu(_) => (
            format!("CPU, {} threads", rayon::current_num_threads()),
            None,
            None,
        ),
    };
    let sim = engine.synced()?;
    let per_particle = |x: usize| x as f64 / n.max(1) as f64;
    let g = whole_run(&*comm, sim);
    let parallel = parallel_report(&*comm, sim);
    Ok(json!({
        "scene": opts.scene.display().to_string(),
        "backend": backend_name,
        "ranks": ranks,
        "parallel": parallel,
        "precision": if backend_name == "cuda" { format!("{:?}", opts.precision).to_lowercase() } else { "double".into() },
        "device": device,
        "particles": n,
        "steps": opts.steps,
        "wall_seconds": wall,
        "setup_seconds": setup,
        "particle_steps_per_second": (n as f64 * opts.steps as f64) / wall.max(1e-12),
        "stage_seconds": stages,
        "contacts_per_particle": 2.0 * g.stats.contacts as f64 / n.max(1) as f64,
        "wall_contacts": g.stats.wall_contacts,
        "candidate_pairs_per_particle": pairs.map(per_particle),
        "device_bytes_per_particle": bytes.map(per_particle),
    }))
}
