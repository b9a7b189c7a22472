//! `polydem run` and `polydem check`: the driver around [`Simulation::step`] — output frames,
//! time series, checkpoints and restarts, progress, Ctrl-C, and the closing `summary.json`
//! (stage 10 of DESIGN.md §1).

use crate::backend;
use crate::backend::Engine;
use crate::backend::cuda::{CudaSimulation, Precision};
use crate::io::checkpoint::fnv1a64;
use crate::io::{
    Checkpoint, FrameView, FrameWriter, SeriesRow, SeriesWriter, WallView, read_checkpoint,
    write_atomic, write_checkpoint, write_particle_csv,
};
use crate::pipeline::Simulation;
use crate::scene::{
    Inserter, InserterState, Scene, check_report, face_contact_times, impact_speed, load_scene,
};
use anyhow::{Context, Result, anyhow, bail};
use nalgebra::Vector3;
use serde_json::json;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
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
}

/// Hash identifying a scene for restarts: the scene file's bytes.
fn scene_hash(path: &Path) -> Result<u64> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(fnv1a64(&bytes))
}

/// Picks the backend (DESIGN.md §5): `cuda` needs a usable GPU and NVRTC, `auto` takes the GPU
/// when there is one and says in the log why it does not.
fn choose_backend(choice: BackendChoice) -> Result<&'static str> {
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
    fn new(interval: Option<f64>, now: f64) -> Self {
        let next = match interval {
            Some(i) if i > 0.0 => (now / i).floor() * i + i,
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

/// Output of a run in progress.
struct Outputs {
    dir: PathBuf,
    frames: Option<FrameWriter>,
    series: SeriesWriter,
    type_template: Vec<usize>,
}

impl Outputs {
    fn frame(&mut self, sim: &Simulation) -> Result<()> {
        let s = &sim.scene;
        let view = FrameView {
            particles: &sim.particles,
            templates: &s.templates,
            type_template: &self.type_template,
            rank: 0,
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
                .zip(&sim.wall_forces)
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
            let path = particles_dir.join(format!("step_{:010}.csv", sim.step));
            write_particle_csv(&path, sim.time, &view)?;
        }
        Ok(())
    }

    fn series(&mut self, sim: &Simulation) -> Result<()> {
        let (kt, kr, pg) = sim.energies();
        self.series.append(&SeriesRow {
            step: sim.step,
            time: sim.time,
            kinetic_translational: kt,
            kinetic_rotational: kr,
            potential_gravity: pg,
            elastic: sim.stats.elastic_energy,
            contacts: sim.stats.contacts,
            wall_contacts: sim.stats.wall_contacts,
            wall_forces: sim.wall_forces.clone(),
        })?;
        Ok(())
    }
}

/// The checkpoint of the current state.
fn checkpoint_of(sim: &Simulation, hash: u64) -> Result<Checkpoint> {
    let inserter = serde_json::to_vec(&sim.inserter.state())?;
    Ok(Checkpoint {
        step: sim.step,
        time: sim.time,
        particles: sim.particles.clone(),
        history: sim.history.clone(),
        rng_state: sim.inserter.state().rng,
        inserter,
        next_id: sim.next_id,
        scene_hash: hash,
        extra: vec![("removed".into(), sim.stats.removed.to_le_bytes().to_vec())],
    })
}

fn save_checkpoint(sim: &Simulation, dir: &Path, hash: u64) -> Result<PathBuf> {
    let ckdir = dir.join("checkpoints");
    std::fs::create_dir_all(&ckdir)
        .with_context(|| format!("{}: cannot create", ckdir.display()))?;
    let path = ckdir.join(format!("step_{:010}.ckpt", sim.step));
    let checkpoint = checkpoint_of(sim, hash)?;
    write_checkpoint(&path, &checkpoint)?;
    // The newest is also `latest.ckpt`, so that a restart needs no step number.
    write_checkpoint(&ckdir.join("latest.ckpt"), &checkpoint)?;
    Ok(path)
}

/// `polydem run`: returns the summary it also writes to `summary.json`.
pub fn run(opts: &RunOptions) -> Result<serde_json::Value> {
    let mut scene = load_scene(&opts.scene).map_err(|e| anyhow!("{e}"))?;
    if let Some(out) = &opts.out {
        scene.output.dir = out.clone();
    }
    let backend_name = choose_backend(opts.backend)?;
    let hash = scene_hash(&opts.scene)?;
    let dir = scene.output.dir.clone();
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("{}: cannot create the output directory", dir.display()))?;
    let type_template: Vec<usize> = scene.particle_types.iter().map(|t| t.template).collect();
    let wall_names: Vec<String> = scene.walls.iter().map(|w| w.name.clone()).collect();
    let series_path = dir.join("series.csv");

    let (sim, resumed) = match &opts.restart {
        Some(path) => {
            let c = read_checkpoint(path)?;
            c.check_scene(hash, path)?;
            let state: InserterState = serde_json::from_slice(&c.inserter)
                .with_context(|| format!("{}: insertion state", path.display()))?;
            let inserter = Inserter::try_restore(&scene, &state)
                .map_err(|e| anyhow!("{}: {e}", path.display()))?;
            let mut sim = Simulation::restore(
                scene,
                c.particles,
                c.history,
                inserter,
                c.time,
                c.step,
                c.next_id,
            )?;
            if let Some((_, b)) = c.extra.iter().find(|(k, _)| k == "removed") {
                sim.stats.removed = b.as_slice().try_into().map(u64::from_le_bytes).unwrap_or(0);
            }
            tracing::info!(
                "restarted from {} at step {} (t = {} s)",
                path.display(),
                sim.step,
                sim.time
            );
            (sim, true)
        }
        None => {
            let sim = if backend_name == "cuda" {
                Simulation::new_unevaluated(scene)?
            } else {
                Simulation::new(scene)?
            };
            (sim, false)
        }
    };
    let mut engine = if backend_name == "cuda" {
        let mut c = CudaSimulation::new(sim, 0, opts.precision).map_err(|e| anyhow!("{e}"))?;
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
    let frames = if s.output.formats.vtu && s.output.frame_interval.is_some() {
        Some(if resumed {
            FrameWriter::resume(&dir, 1, sim.time)?
        } else {
            FrameWriter::new(&dir, 1)?
        })
    } else {
        None
    };
    let series = if resumed {
        SeriesWriter::resume(&series_path, &wall_names, sim.time)?
    } else {
        SeriesWriter::new(&series_path, &wall_names)?
    };
    let mut out = Outputs {
        dir: dir.clone(),
        frames,
        series,
        type_template,
    };
    let mut frame_at = Schedule::new(s.output.frame_interval, sim.time);
    let mut series_at = Schedule::new(Some(s.output.series_interval), sim.time);
    let mut checkpoint_at = Schedule::new(s.output.checkpoint_interval, sim.time);
    let end_time = s.simulation.end_time;
    let log_every = s.output.log_interval_steps.max(1);
    if !resumed {
        out.frame(engine.synced()?)?;
        out.series(engine.synced()?)?;
    }

    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        // A second handler registration (several runs in one process, as in tests) is refused;
        // the first one's flag then never fires for this run, which only loses Ctrl-C handling.
        let _ = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst));
    }
    let sim = engine.host();
    let total_steps = ((end_time - sim.time) / sim.dt).ceil().max(0.0) as u64;
    let bar = std::io::stderr().is_terminal().then(|| {
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
    let mut stopped_by_user = false;
    while engine.host().time + 0.5 * engine.host().dt < end_time {
        if opts
            .max_steps
            .is_some_and(|m| engine.host().step - step0 >= m)
        {
            break;
        }
        engine.step()?;
        particle_steps += engine.host().particles.len() as u64;
        let (t, dt) = (engine.host().time, engine.host().dt);
        if frame_at.due(t, dt) {
            out.frame(engine.synced()?)?;
        }
        if series_at.due(t, dt) {
            out.series(engine.synced()?)?;
        }
        if checkpoint_at.due(t, dt) {
            save_checkpoint(engine.synced()?, &dir, hash)?;
        }
        let sim = engine.host();
        let done = sim.step - step0;
        if let Some(b) = &bar {
            b.set_position(done);
            if done % 100 == 0 {
                b.set_message(format!(
                    "t = {t:.4} s, {} particles, {} contacts",
                    sim.particles.len(),
                    sim.stats.contacts + sim.stats.wall_contacts
                ));
            }
        } else if done % log_every == 0 {
            let elapsed = start.elapsed().as_secs_f64();
            let rate = done as f64 / elapsed.max(1e-9);
            let eta = (total_steps.saturating_sub(done)) as f64 / rate.max(1e-9);
            tracing::info!(
                "step {} t = {:.5} s  {:.0} steps/s  {} particles  {} contacts  ETA {:.0} s",
                sim.step,
                t,
                rate,
                sim.particles.len(),
                sim.stats.contacts + sim.stats.wall_contacts,
                eta
            );
        }
        if interrupted.load(Ordering::SeqCst) {
            let path = save_checkpoint(engine.synced()?, &dir, hash)?;
            tracing::warn!(
                "interrupted: checkpoint written to {}; resume with --restart {}",
                path.display(),
                path.display()
            );
            stopped_by_user = true;
            break;
        }
    }
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let wall = start.elapsed().as_secs_f64();
    let sim = engine.synced()?;
    if !stopped_by_user {
        out.frame(sim)?;
        out.series(sim)?;
        if sim.scene.output.checkpoint_interval.is_some() {
            save_checkpoint(sim, &dir, hash)?;
        }
    }
    let (kt, kr, pg) = sim.energies();
    let threads = rayon::current_num_threads();
    let summary = json!({
        "scene": opts.scene.display().to_string(),
        "backend": backend_name,
        "threads": threads,
        "steps": sim.step - step0,
        "final_step": sim.step,
        "simulated_time": sim.time,
        "dt": sim.dt,
        "wall_seconds": wall,
        "particle_steps_per_second": particle_steps as f64 / wall.max(1e-12),
        "particle_steps_per_second_per_thread": particle_steps as f64 / wall.max(1e-12) / threads as f64,
        "particles": sim.particles.len(),
        "particles_removed": sim.stats.removed,
        "contacts": sim.stats.contacts,
        "wall_contacts": sim.stats.wall_contacts,
        "energy": {"kinetic_translational": kt, "kinetic_rotational": kr, "potential_gravity": pg, "elastic": sim.stats.elastic_energy},
        "stage_seconds": sim.timers,
        "interrupted": stopped_by_user,
    });
    write_atomic(
        &dir.join("summary.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )
    .with_context(|| format!("{}: cannot write summary.json", dir.display()))?;
    Ok(summary)
}

/// `polydem check`: validates the scene and reports the time-step estimates and counts.
///
/// Besides the Rayleigh step, it reports the face-to-face contact time of each particle type at
/// an impact speed of 1 m/s and at the free-fall speed over the domain's height, and the chosen
/// dt as a fraction of the shortest; a dt above 1/20 of it is flagged, since flat impacts then
/// gain energy in their first step.
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
        "recommended_dt_max": shortest / 20.0,
    });
    if dt > shortest / 20.0 {
        let msg = format!(
            "dt = {dt:e} s exceeds 1/20 of the face-to-face contact time {shortest:e} s at {v_fall:.2} m/s"
        );
        tracing::warn!("{msg}");
        report["warnings"] = json!([msg]);
    }
    Ok(report)
}

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
    let scene = load_scene(&opts.scene).map_err(|e| anyhow!("{e}"))?;
    let backend_name = choose_backend(opts.backend)?;
    let t_setup = Instant::now();
    let mut engine = if backend_name == "cuda" {
        let c = CudaSimulation::from_scene(scene, 0, opts.precision).map_err(|e| anyhow!("{e}"))?;
        Engine::Cuda(Box::new(c))
    } else {
        Engine::Cpu(Box::new(Simulation::new(scene)?))
    };
    let setup = t_setup.elapsed().as_secs_f64();
    for _ in 0..opts.warmup {
        engine.step()?;
    }
    let timers_before = engine.host().timers;
    let n = engine.host().particles.len();
    let start = Instant::now();
    for _ in 0..opts.steps {
        engine.step()?;
    }
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
    Ok(json!({
        "scene": opts.scene.display().to_string(),
        "backend": backend_name,
        "precision": if backend_name == "cuda" { format!("{:?}", opts.precision).to_lowercase() } else { "double".into() },
        "device": device,
        "particles": n,
        "steps": opts.steps,
        "wall_seconds": wall,
        "setup_seconds": setup,
        "particle_steps_per_second": (n as f64 * opts.steps as f64) / wall.max(1e-12),
        "stage_seconds": stages,
        "contacts_per_particle": 2.0 * sim.stats.contacts as f64 / n.max(1) as f64,
        "wall_contacts": sim.stats.wall_contacts,
        "candidate_pairs_per_particle": pairs.map(per_particle),
        "device_bytes_per_particle": bytes.map(per_particle),
    }))
}
