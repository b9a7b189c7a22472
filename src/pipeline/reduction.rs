//! Stage 8: the deterministic reduction. Each particle's force and torque are summed from its
//! pairs in partner-id order, then its walls in order; the contact history, the contact counts,
//! the elastic energy and the wall forces are collected in an order that neither the thread
//! count nor the pair list's build step changes; the stability guard's overlap bound is checked
//! on the outcomes in list order.

use super::Simulation;
use super::pairs::PairOutcome;
use super::walls::WallOutcome;
use crate::contact::{ContactHistory, ContactKey, ContactState};
use nalgebra::Vector3;
use rayon::prelude::*;
use std::time::Instant;

impl Simulation {
    /// Stage 8 for the `owned` particles (the ghosts already dropped), from the pair outcomes
    /// of stages 3–7 (in pair-list order) and the wall outcomes of stage 6 (per particle).
    pub(super) fn reduce(
        &mut self,
        owned: usize,
        outcomes: &[PairOutcome],
        wall_outcomes: &[WallOutcome],
    ) {
        let t0 = Instant::now();
        self.reduce_forces(outcomes, wall_outcomes);
        self.reduce_contacts(owned, outcomes, wall_outcomes);
        self.find_too_deep(owned, outcomes, wall_outcomes);
        self.state.timers.reduce += t0.elapsed().as_secs_f64();
    }

    /// Each particle's force and torque: its pairs in the list's per-particle order (by
    /// partner id), then its walls; and its contacts, pairs and walls, which the next
    /// evaluation's dashpot caps split its mass among.
    fn reduce_forces(&mut self, outcomes: &[PairOutcome], wall_outcomes: &[WallOutcome]) {
        let pairs = &self.work.pairs;
        let p = &mut self.state.particles;
        p.force
            .par_iter_mut()
            .zip(p.torque.par_iter_mut())
            .zip(p.contacts.par_iter_mut())
            .enumerate()
            .with_min_len(crate::par::SEARCH)
            .for_each(|(i, ((f, t), c))| {
                let mut force = Vector3::zeros();
                let mut torque = Vector3::zeros();
                let mut contacts = 0u32;
                for r in pairs.of(i) {
                    let o = &outcomes[r.pair as usize];
                    contacts += u32::from(o.state.is_some());
                    let o = &o.forces;
                    if r.is_b {
                        force += o.force_b;
                        torque += o.torque_b;
                    } else {
                        force -= o.force_b;
                        torque += o.torque_a;
                    }
                }
                if let Some(w) = wall_outcomes.get(i) {
                    force += w.force;
                    torque += w.torque;
                    contacts += w.states.len() as u32;
                }
                *f = force;
                *t = torque;
                *c = contacts;
            });
    }

    /// The contact history, the contact counts, the elastic energy and the force on each wall.
    fn reduce_contacts(
        &mut self,
        owned: usize,
        outcomes: &[PairOutcome],
        wall_outcomes: &[WallOutcome],
    ) {
        let pairs = &self.work.pairs;
        // The history's entries in key order as far as the loop below can give it: each owned
        // particle in id order, its pairs as the lower-id member by partner id, then its walls
        // (a wall's key sorts after every particle's). Only pairs whose lower-id member is a
        // ghost come after, and the adaptive sort of `from_entries` merges that short tail
        // instead of sorting every contact each step.
        let mut entries: Vec<(ContactKey, ContactState)> = Vec::with_capacity(outcomes.len());
        // A pair across two ranks is evaluated on both; it counts where its lower-id member
        // (the pair's first) is owned, so that sums over ranks count it once.
        let counted = |k: usize| self.work.pairs.pairs[k][0] < owned as u32;
        // The history in global id order, each particle's pairs by partner id (the order of
        // the force reduction above), then each particle's walls; the elastic energy and the
        // walls' forces as exact sums (crate::exact_sum), which no order, backend, restart or
        // rank count changes.
        // (The ghosts are dropped: the particles are the owned ones, `wall_outcomes` has one
        // per particle or none.)
        let listed = owned.min(pairs.offsets.len().saturating_sub(1));
        let n = self.state.particles.len();
        let order = self.state.particles.id_order(n);
        let at = |j: usize| order.as_ref().map_or(j, |o| o[j]);
        let mut sums = crate::exact_sum::DiagnosticSums::new(self.state.walls.len());
        for j in 0..n {
            let i = at(j);
            // A particle past the listed ones has no pairs, but its walls count.
            if i < listed {
                for r in pairs.of(i) {
                    if !r.is_b && counted(r.pair as usize) {
                        let o = &outcomes[r.pair as usize];
                        sums.elastic.add(o.forces.elastic_energy);
                        entries.extend(o.state);
                    }
                }
            }
            if let Some(w) = wall_outcomes.get(i) {
                entries.extend_from_slice(&w.states);
            }
        }
        // Pairs whose lower-id member is a ghost (a decomposed run).
        entries.extend(
            outcomes
                .iter()
                .enumerate()
                .filter(|&(k, _)| !counted(k))
                .filter_map(|(_, o)| o.state),
        );
        let mut wall_contacts = 0;
        for j in 0..n {
            let Some(w) = wall_outcomes.get(at(j)) else {
                continue;
            };
            sums.elastic.add(w.energy);
            wall_contacts += w.states.len() as u64;
            for (k, f) in &w.per_wall {
                sums.add_wall_force(*k, f);
            }
        }
        self.state.stats.contacts = outcomes
            .iter()
            .enumerate()
            .filter(|(k, o)| o.state.is_some() && counted(*k))
            .count() as u64;
        self.state.stats.wall_contacts = wall_contacts;
        self.state.stats.elastic_energy = sums.elastic.value();
        self.state.wall_forces = sums.wall_force_values();
        self.state.sums = sums;
        self.state.history = ContactHistory::from_entries(entries);
    }

    /// The contact past the stability guard's overlap bound, if any, for
    /// [`Simulation::check_overlaps`].
    fn find_too_deep(
        &mut self,
        owned: usize,
        outcomes: &[PairOutcome],
        wall_outcomes: &[WallOutcome],
    ) {
        // The guard's overlap bound: the first pair past it, else the first particle with a
        // wall contact past it (deterministic, whatever the thread count).
        let limit = self.state.guard.max_overlap;
        self.work.too_deep = None;
        if limit.is_finite() {
            // Id and volume ((4π/3) R³ of the volume-equivalent radius) of an owned particle
            // or a ghost.
            let member = |x: usize| {
                let s = &self.state.scene;
                let p = if x < owned {
                    (&self.state.particles, x)
                } else {
                    let par = self
                        .state
                        .parallel
                        .as_deref()
                        .expect("ghosts only in a decomposed run");
                    (&par.ghosts.particles, x - owned)
                };
                let (p, x) = p;
                let t = &s.templates[s.particle_types[p.kind[x] as usize].template];
                (
                    p.id[x],
                    crate::stability::ball_volume(t.equivalent_radius * p.scale[x]),
                )
            };
            let volume = |i: usize| member(i).1;
            if let Some(k) = outcomes.iter().position(|o| o.penetration > limit) {
                let [a, b] = self.work.pairs.pairs[k].map(|x| x as usize);
                // The owned member is named (a ghost's id is still the partner's).
                let (i, j) = if a < owned { (a, b) } else { (b, a) };
                let size = volume(i).min(volume(j));
                self.work.too_deep = Some((
                    i,
                    format!("particle {}", member(j).0),
                    outcomes[k].penetration * size,
                    size,
                ));
            } else if let Some(i) = wall_outcomes.iter().position(|w| w.penetration.0 > limit) {
                let (depth, k) = wall_outcomes[i].penetration;
                let size = volume(i);
                self.work.too_deep = Some((
                    i,
                    format!("wall \"{}\"", self.state.scene.walls[k].name),
                    depth * size,
                    size,
                ));
            }
        }
    }
}
