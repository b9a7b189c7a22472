//! Copying the device state back into the host [`RunState`] for output, checkpoints and
//! host-side insertion: particles in the device's order, the contact history rebuilt from the
//! pair slots and per-particle wall slots, and the step statistics.

use super::CudaSimulation;
use super::error::CudaError;
use super::history::gather_contacts;
use super::layout::CONTACT_LIVE;
use crate::run_state::RunState;

impl CudaSimulation {
    /// Copies the device state into [`CudaSimulation::state`] (particles in the device's
    /// current order, forces, contact history, statistics and wall forces), when it is stale.
    pub fn sync_host(&mut self) -> Result<&RunState, CudaError> {
        if self.host_current {
            return Ok(&self.state);
        }
        let st = &self.gpu.stream;
        let n = self.particles.n;
        let p = &mut self.state.particles;
        // The host's fields of the table, into `p`.
        let arrays = self.particles.download(st)?;
        arrays.copy_into(p, n);
        // History and statistics from the last evaluation.
        // A rank of a decomposed run holds ghosts too: they are left out of the host copy, and
        // a pair counts in the statistics where its lower-id member (the first) is owned.
        let ghost: Vec<bool> = if self.state.parallel.is_some() {
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
            self.state.history = gathered.history;
            self.state.stats.contacts = gathered.contacts;
            self.state.stats.wall_contacts = gathered.wall_contacts;
            self.state.stats.elastic_energy = gathered.sums.elastic.value();
            self.state.wall_forces = gathered.sums.wall_force_values();
            self.state.sums = gathered.sums;
        }
        self.host_current = true;
        Ok(&self.state)
    }
}

impl CudaSimulation {
    /// Applies `f` to the host copy of the current state and uploads the result; the next step
    /// rebuilds the pair list. When `f` changed only the motion (positions, orientations,
    /// velocities, forces), only those arrays go back up, into the device's order; otherwise
    /// everything does, with the contact history. When `f` changed the domain (a rescaled
    /// periodic box), the grid and the list builder follow it.
    pub fn edit_host(&mut self, f: impl FnOnce(&mut RunState)) -> Result<(), CudaError> {
        self.sync_host()?;
        let before = (
            self.state.particles.id.clone(),
            self.state.particles.kind.clone(),
            self.state.particles.scale.clone(),
            self.state.particles.mass.clone(),
            self.state.particles.inertia.clone(),
            self.state.history.clone(),
        );
        let domain = self.state.scene.domain;
        f(&mut self.state);
        if self.state.scene.domain != domain {
            self.domain_changed();
        }
        let p = &self.state.particles;
        let motion_only = before.0 == p.id
            && before.1 == p.kind
            && before.2 == p.scale
            && before.3 == p.mass
            && before.4 == p.inertia
            && before.5 == self.state.history;
        // A decomposed run's device arrays interleave ghosts with the owned particles: it
        // always uploads whole (and rebuilds, with fresh ghosts, at the next step).
        if !motion_only || self.particles.n == 0 || self.state.parallel.is_some() {
            return self.upload_from_host();
        }
        self.particles.upload_motion(&self.gpu.stream, p)?;
        self.pairs.rebuild = true;
        Ok(())
    }

    /// Evaluates the forces again on the device at the current state without advancing the
    /// contact history, as [`crate::pipeline::Simulation::refresh`] does on the CPU: the
    /// forces of an edited state (a rescaled periodic box) before the next step's kick.
    pub fn refresh(&mut self) -> Result<(), CudaError> {
        self.sync_host()?;
        let saved = self.state.history.clone();
        self.state.reset_guard();
        if self.state.parallel.is_some() {
            // The decomposed part of stage 1 alone, as the CPU's refresh runs it (no
            // insertion): the ghosts of the edited state chosen afresh, as at a rebuild.
            self.state.exchange_decomposed(true)?;
            self.upload_from_host()?;
        }
        self.pairs.rebuild = true;
        self.forces(0.0, false)?;
        self.host_current = false;
        self.sync_host()?;
        self.state.history = saved;
        self.state.reset_guard();
        self.upload_from_host()
    }

    /// The candidate pair list as global-id pairs (lower id first), sorted (see
    /// [`crate::pipeline::Simulation::candidate_pair_ids`]).
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
        if self.host_current || self.state.parallel.is_some() {
            // A decomposed run's flags include the ghosts: count from the synced copy.
            self.sync_host()?;
            return Ok((self.state.stats.contacts, self.state.stats.wall_contacts));
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
