//! Copying the device state back into the host [`Simulation`] for output, checkpoints and
//! host-side insertion: particles in the device's order, the contact history rebuilt from the
//! pair slots and per-particle wall slots, and the step statistics.

use super::CudaSimulation;
use super::error::CudaError;
use super::history::gather_contacts;
use super::layout::CONTACT_LIVE;
use crate::pipeline::Simulation;

impl CudaSimulation {
    /// Copies the device state into [`CudaSimulation::host`] (particles in the device's
    /// current order, forces, contact history, statistics and wall forces), when it is stale.
    pub fn sync_host(&mut self) -> Result<&Simulation, CudaError> {
        if self.host_current {
            return Ok(&self.host);
        }
        let st = &self.gpu.stream;
        let n = self.particles.n;
        let p = &mut self.host.particles;
        // The host's fields of the table, into `p`.
        let arrays = self.particles.download(st)?;
        arrays.copy_into(p, n);
        // History and statistics from the last evaluation.
        // A rank of a decomposed run holds ghosts too: they are left out of the host copy, and
        // a pair counts in the statistics where its lower-id member (the first) is owned.
        let ghost: Vec<bool> = if self.host.parallel.is_some() {
            let mut g = st.clone_dtoh(&self.particles.ghost)?;
            g.truncate(n);
            g.iter().map(|&g| g != 0).collect()
        } else {
            vec![false; n]
        };
        let pairs = match &self.pairs.list {
            Some(list) => Some(list.outcomes(st)?),
            None => None,
        };
        let walls = match &self.walls {
            Some(w) => Some(w.outcomes(st)?),
            None => None,
        };
        let gathered = gather_contacts(&p.id, &ghost, pairs.as_ref(), walls.as_ref());
        if ghost.iter().any(|&g| g) {
            let keep: Vec<usize> = (0..n).filter(|&i| !ghost[i]).collect();
            *p = p.select(&keep);
        }
        // Until the first evaluation after an upload (a restart, an insertion) the device has
        // no contact outputs: the history and statistics are still the uploaded host ones.
        if self.pairs.list.is_some() {
            self.host.history = gathered.history;
            self.host.stats.contacts = gathered.contacts;
            self.host.stats.wall_contacts = gathered.wall_contacts;
            self.host.stats.elastic_energy = gathered.sums.elastic.value();
            self.host.wall_forces = gathered.sums.wall_force_values();
            self.host.sums = gathered.sums;
        }
        self.host_current = true;
        Ok(&self.host)
    }
}

impl CudaSimulation {
    /// Applies `f` to the host copy of the current state and uploads the result; the next step
    /// rebuilds the pair list. When `f` changed only the motion (positions, orientations,
    /// velocities, forces), only those arrays go back up, into the device's order; otherwise
    /// everything does, with the contact history. When `f` changed the domain (a rescaled
    /// periodic box), the grid and the list builder follow it.
    pub fn edit_host(&mut self, f: impl FnOnce(&mut Simulation)) -> Result<(), CudaError> {
        self.sync_host()?;
        let before = (
            self.host.particles.id.clone(),
            self.host.particles.kind.clone(),
            self.host.particles.scale.clone(),
            self.host.particles.mass.clone(),
            self.host.particles.inertia.clone(),
            self.host.history.clone(),
        );
        let domain = self.host.scene.domain;
        f(&mut self.host);
        if self.host.scene.domain != domain {
            self.domain_changed();
        }
        let p = &self.host.particles;
        let motion_only = before.0 == p.id
            && before.1 == p.kind
            && before.2 == p.scale
            && before.3 == p.mass
            && before.4 == p.inertia
            && before.5 == self.host.history;
        // A decomposed run's device arrays interleave ghosts with the owned particles: it
        // always uploads whole (and rebuilds, with fresh ghosts, at the next step).
        if !motion_only || self.particles.n == 0 || self.host.parallel.is_some() {
            return self.upload_from_host();
        }
        self.particles.upload_motion(&self.gpu.stream, p)?;
        self.pairs.rebuild = true;
        Ok(())
    }

    /// The candidate pair list as global-id pairs (lower id first), sorted (see
    /// [`Simulation::candidate_pair_ids`]).
    pub fn candidate_pair_ids(&mut self) -> Result<Vec<(u64, u64)>, CudaError> {
        let Some(pairs) = &self.pairs.list else {
            return Ok(Vec::new());
        };
        let st = &self.gpu.stream;
        let slots = pairs.slots(st)?;
        let id = st.clone_dtoh(&self.particles.id)?;
        let mut v: Vec<(u64, u64)> = slots
            .iter()
            .map(|&[a, b]| {
                let (x, y) = (id[a], id[b]);
                (x.min(y), x.max(y))
            })
            .collect();
        v.sort_unstable();
        Ok(v)
    }

    /// Particle–particle and particle–wall contacts of the last force evaluation, from the
    /// contact flags alone (the rest of the state stays on the device).
    pub fn contact_counts(&mut self) -> Result<(u64, u64), CudaError> {
        if self.host_current || self.host.parallel.is_some() {
            // A decomposed run's flags include the ghosts: count from the synced copy.
            self.sync_host()?;
            return Ok((self.host.stats.contacts, self.host.stats.wall_contacts));
        }
        let st = &self.gpu.stream;
        let live = |flags: &[u32], n: usize| {
            flags.iter().take(n).filter(|&&c| c == CONTACT_LIVE).count() as u64
        };
        let pairs = match &self.pairs.list {
            Some(p) => live(&p.flags(st)?, p.n),
            None => 0,
        };
        let walls = match &self.walls {
            Some(w) => live(&w.flags(st)?, self.particles.n * w.n),
            None => 0,
        };
        Ok((pairs, walls))
    }
}
