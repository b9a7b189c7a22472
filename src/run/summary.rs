//! The whole run's observables (sums over ranks in a decomposed run) for the progress line,
//! the series and `summary.json`.
use crate::domain::Comm;
use crate::domain::collect::{GlobalStats, global_stats};
use crate::pipeline::Simulation;
use serde_json::json;

/// The whole run's observables: this rank's on one rank, sums over ranks otherwise.
/// The whole run's particles, contacts (with walls) and removed particles, for the progress
/// line: counts only, without [`whole_run`]'s energies, which sum every particle in id order
/// and would cost a sort of the GPU's host copy every hundred steps.
pub(super) fn whole_run_counts(comm: &dyn Comm, sim: &Simulation) -> (u64, u64, u64) {
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

pub(super) fn whole_run(comm: &dyn Comm, sim: &Simulation) -> GlobalStats {
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
pub(super) fn parallel_report(comm: &dyn Comm, sim: &Simulation) -> serde_json::Value {
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
