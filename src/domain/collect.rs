//! Whole-run views of a decomposed run, for output: observables summed over ranks, and the
//! checkpoint gathered on rank 0 in the single-rank layout (particles by global id, history by
//! key), so a checkpoint does not depend on the rank count that wrote it and restarts on any.

use super::comm::Comm;
use super::migration::{pack_particles, unpack_particles};
use crate::contact::ContactHistory;
use crate::exact_sum::{DiagnosticSums, ExactSum};
use crate::state::{Particles, StepStats};
use nalgebra::Vector3;

/// One rank's part of a run as the whole-run views read it: implemented by the simulation, so
/// that the decomposition needs none of its stages.
pub trait RankState {
    /// This rank's owned particles.
    fn owned_particles(&self) -> &Particles;
    /// Their contacts' history.
    fn contact_history(&self) -> &ContactHistory;
    /// Observables of the last force evaluation.
    fn step_stats(&self) -> &StepStats;
    /// Kinetic (translational, rotational) and gravitational potential energy of this rank's
    /// particles, as exact sums.
    fn energy_sums(&self) -> [ExactSum; 3];
    /// This rank's elastic energy and its particles' shares of the walls' forces, as exact
    /// sums.
    fn diagnostic_sums(&self) -> &DiagnosticSums;
}

/// Observables of the whole run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GlobalStats {
    pub particles: u64,
    pub stats: StepStats,
    /// Kinetic (translational, rotational) and gravitational potential energy.
    pub energies: (f64, f64, f64),
    pub wall_forces: Vec<Vector3<f64>>,
}

/// Sums this rank's observables with every other rank's (a collective call).
pub fn global_stats(comm: &dyn Comm, sim: &impl RankState) -> GlobalStats {
    // Exact sums merged across ranks (crate::exact_sum): the values are the bits one rank
    // gives, whatever the decomposition.
    let (d, energies) = (sim.diagnostic_sums(), sim.energy_sums());
    let mut sums: Vec<&ExactSum> = energies.iter().collect();
    sums.push(&d.elastic);
    for w in &d.wall_forces {
        sums.extend(w.iter());
    }
    let words: Vec<u64> = sums.iter().flat_map(|s| s.words()).collect();
    let specials: Vec<f64> = sums.iter().map(|s| s.special()).collect();
    let (words, specials) = (comm.sum_u64(&words), comm.sum_f64(&specials));
    let f: Vec<f64> = words
        .chunks_exact(ExactSum::WORDS)
        .zip(&specials)
        .map(|(w, &x)| ExactSum::from_sums(w, x).value())
        .collect();
    let s = sim.step_stats();
    let u = comm.sum_u64(&[
        sim.owned_particles().len() as u64,
        s.contacts,
        s.wall_contacts,
        s.removed,
    ]);
    GlobalStats {
        particles: u[0],
        stats: StepStats {
            contacts: u[1],
            wall_contacts: u[2],
            elastic_energy: f[3],
            removed: u[3],
        },
        energies: (f[0], f[1], f[2]),
        wall_forces: f[4..]
            .chunks_exact(3)
            .map(|c| Vector3::new(c[0], c[1], c[2]))
            .collect(),
    }
}

/// Every rank's particles and history on `root`, particles sorted by global id (a collective
/// call; `None` on the other ranks).
pub fn gather_state(
    comm: &dyn Comm,
    sim: &impl RankState,
    root: usize,
) -> Option<(Particles, ContactHistory)> {
    let (particles, history) = (sim.owned_particles(), sim.contact_history());
    let all: Vec<usize> = (0..particles.len()).collect();
    let mut sends = vec![Vec::new(); comm.size()];
    sends[root] = pack_particles(particles, &all, history);
    let received = comm.all_to_all(&sends);
    if comm.rank() != root {
        return None;
    }
    let mut p = Particles::default();
    let mut entries = Vec::new();
    for buf in &received {
        entries.extend(unpack_particles(buf, &mut p));
    }
    Some((sorted_by_id(&p), ContactHistory::from_entries(entries)))
}

/// The particles reordered by global id.
pub fn sorted_by_id(p: &Particles) -> Particles {
    let mut order: Vec<usize> = (0..p.len()).collect();
    order.sort_unstable_by_key(|&i| p.id[i]);
    p.select(&order)
}
