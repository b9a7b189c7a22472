//! `polydem bench`: a scene stepped without output, timed.
use super::summary::{parallel_report, whole_run};
use crate::Precision;
use crate::backend::{BackendChoice, Engine, Start, select_device};
use crate::domain::{Comm, SerialComm};
use crate::scene::load_scene;
use anyhow::Result;
use serde_json::json;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

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
    /// Overrides the scene's `simulation.neighbor.mode`.
    pub neighbor_mode: Option<crate::scene::NeighborMode>,
}

/// `polydem bench`: steps a scene without output and reports particle-steps per second, the
/// per-stage seconds, contacts and candidate pairs per particle and (on the GPU) the bytes of
/// device memory per particle (docs/design.md §9).
pub fn bench(opts: &BenchOptions) -> Result<serde_json::Value> {
    bench_on(opts, Arc::new(SerialComm))
}

/// `polydem bench` on the ranks of `comm`: the same report for the whole run (particle-steps
/// per second of all ranks together, stage seconds of rank 0) plus each rank's particles,
/// stage seconds and the decomposition's exchange and waiting times.
pub fn bench_on(opts: &BenchOptions, comm: Arc<dyn Comm>) -> Result<serde_json::Value> {
    let mut scene = load_scene(&opts.scene)?;
    if let Some(mode) = opts.neighbor_mode {
        scene.simulation.neighbor.mode = mode;
    }
    let ranks = comm.size();
    let device = select_device(opts.backend, opts.precision, &*comm)?;
    let t_setup = Instant::now();
    let mut engine = Engine::new(
        Start::Scene {
            scene: Box::new(scene),
            comm: comm.clone(),
        },
        device,
    )?;
    let setup = t_setup.elapsed().as_secs_f64();
    for _ in 0..opts.warmup {
        engine.step()?;
    }
    let timers_before = engine.state().timers;
    if let Some(par) = engine.state_mut().parallel.as_deref_mut() {
        // The per-rank decomposition timers of the report cover the timed steps only.
        par.timers = Default::default();
    }
    let n = comm.sum_u64(&[engine.state().particles.len() as u64])[0] as usize;
    comm.barrier();
    let start = Instant::now();
    for _ in 0..opts.steps {
        engine.step()?;
    }
    comm.barrier();
    let wall = start.elapsed().as_secs_f64();
    let t = engine.state().timers;
    let stages = json!({
        "integrate": t.integrate - timers_before.integrate,
        "exchange": t.exchange - timers_before.exchange,
        "neighbor": t.neighbor - timers_before.neighbor,
        "pairs": t.pairs - timers_before.pairs,
        "walls": t.walls - timers_before.walls,
        "reduce": t.reduce - timers_before.reduce,
    });
    let neighbor = engine.neighbor_report();
    let (wall_items, wall_particles) = engine.wall_candidates()?;
    let wall_sums = comm.sum_u64(&[wall_items, wall_particles]);
    let (backend_name, described, bytes, pairs) = (
        engine.backend_name(),
        engine.describe(),
        engine.device_bytes(),
        engine.candidate_pairs(),
    );
    let sim = engine.synced()?;
    let per_particle = |x: usize| x as f64 / n.max(1) as f64;
    let g = whole_run(&*comm, sim);
    let parallel = parallel_report(&*comm, sim);
    Ok(json!({
        "scene": opts.scene.display().to_string(),
        "backend": backend_name,
        "ranks": ranks,
        "parallel": parallel,
        "precision": device.precision_name(),
        "device": described,
        "particles": n,
        "steps": opts.steps,
        "wall_seconds": wall,
        "setup_seconds": setup,
        "particle_steps_per_second": (n as f64 * opts.steps as f64) / wall.max(1e-12),
        "stage_seconds": stages,
        "contacts_per_particle": 2.0 * g.stats.contacts as f64 / n.max(1) as f64,
        "wall_contacts": g.stats.wall_contacts,
        // Facets per particle the wall stage evaluates, over all particles and over those
        // near a wall (Backend::wall_candidates says which reach each backend uses).
        "wall_facets_per_particle": wall_sums[0] as f64 / n.max(1) as f64,
        "wall_facets_per_wall_particle": wall_sums[0] as f64 / wall_sums[1].max(1) as f64,
        "particles_near_walls": wall_sums[1],
        "candidate_pairs_per_particle": pairs.map(per_particle),
        "neighbor": neighbor,
        "device_bytes_per_particle": bytes.map(per_particle),
    }))
}
