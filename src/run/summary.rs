//! The whole run's observables (sums over ranks in a decomposed run) for the progress line,
//! the series and `summary.json`.
use crate::domain::Comm;
use crate::domain::collect::{GlobalStats, global_stats};
use crate::run_state::RunState;
use serde::Serialize;
use serde_json::json;

/// What `polydem run` reports at its end: `summary.json` in the output folder and on standard
/// output (README, "Commands"). Typed here and serialised only at the edge (the file, the print). The
/// fields are in alphabetical order, the order `summary.json` has always had, so that its
/// bytes do not depend on this type's layout; `neighbor`, `parallel` and `stage_seconds` are
/// reports of their own modules, kept as JSON objects (sorted keys alike).
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    /// `cpu` or `cuda`.
    pub backend: &'static str,
    /// Particle–particle contacts at the end, whole run.
    pub contacts: u64,
    /// The simulation's device buffers at the end (`None` on the CPU); the CUDA context and
    /// the kernels come on top.
    pub device_bytes: Option<usize>,
    /// The time step (s).
    pub dt: f64,
    /// The energies at the end, whole run (J).
    pub energy: SummaryEnergies,
    /// The process's exit status: 0, or `crate::interrupt::exit_status` of the stop signal.
    pub exit_status: i32,
    /// The step the run ended after.
    pub final_step: u64,
    /// Whether a signal stopped the run.
    pub interrupted: bool,
    /// Who built the pair lists (`neighbor::NeighborReport`).
    pub neighbor: serde_json::Value,
    /// Per-rank counts and timers of a decomposed run (`null` on one rank).
    pub parallel: serde_json::Value,
    /// Particles × steps over the wall time of the steps.
    pub particle_steps_per_second: f64,
    /// The same per rayon thread.
    pub particle_steps_per_second_per_thread: f64,
    /// Particles at the end, whole run.
    pub particles: u64,
    /// Particles removed on leaving the domain, cumulative.
    pub particles_removed: u64,
    /// The pair geometry's arithmetic (`double`, `mixed`).
    pub precision: String,
    /// MPI ranks.
    pub ranks: usize,
    /// The scene file as given.
    pub scene: String,
    /// The signal that stopped the run, by name.
    pub signal: Option<&'static str>,
    /// Simulated time at the end (s).
    pub simulated_time: f64,
    /// Seconds per pipeline stage (`pipeline::StageTimers`).
    pub stage_seconds: serde_json::Value,
    /// Steps this invocation made.
    pub steps: u64,
    /// Rayon threads of this rank.
    pub threads: usize,
    /// Particle–wall contacts at the end, whole run.
    pub wall_contacts: u64,
    /// Wall seconds of the steps.
    pub wall_seconds: f64,
    /// `polydem check`'s warnings about the scene, word for word.
    pub warnings: Vec<String>,
}

/// `summary.json`'s `energy` (J), alphabetical like [`RunSummary`].
#[derive(Clone, Copy, Debug, Serialize)]
pub struct SummaryEnergies {
    /// Stored in the contacts.
    pub elastic: f64,
    pub kinetic_rotational: f64,
    pub kinetic_translational: f64,
    /// Gravitational, against the origin.
    pub potential_gravity: f64,
}

/// The whole run's observables: this rank's on one rank, sums over ranks otherwise.
/// The whole run's particles, contacts (with walls) and removed particles, for the progress
/// line: counts only, without [`whole_run`]'s energies, which sum every particle in id order
/// and would cost a sort of the GPU's host copy every hundred steps.
pub(super) fn whole_run_counts(comm: &dyn Comm, sim: &RunState) -> (u64, u64, u64) {
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

pub(super) fn whole_run(comm: &dyn Comm, sim: &RunState) -> GlobalStats {
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

/// Per-rank particle counts, stage seconds and the decomposition's own timers, gathered from
/// every rank (a collective call; `null` on one rank).
pub(super) fn parallel_report(comm: &dyn Comm, sim: &RunState) -> serde_json::Value {
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
