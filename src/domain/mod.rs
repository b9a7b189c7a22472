//! Domain decomposition over MPI ranks (docs/design.md §6, seed paper Sec. 2.6).
//!
//! One rank owns the particles whose centroids lie in its box ([`decomposition`]). Particles
//! within the halo width of a neighbour's box (the outer region) are sent there as ghosts each
//! step ([`halo`]); the rest (the inner region) never leave. At neighbour-list rebuilds,
//! particles that left the box migrate with their contact history ([`migration`]) and, when the
//! load is imbalanced, recursive bisection draws new boxes. A pair that spans two ranks is
//! evaluated on both from bitwise-equal inputs with the lower global id as A, and every sum is in
//! partner-id order, so an N-rank run follows the single-rank run bit for bit.
//!
//! All ranks take every collective step together: the rebuild decision, insertion, rebalancing
//! and output are decided from replicated or reduced data, never from one rank's view alone.

pub mod collect;
pub mod comm;
pub mod decomposition;
pub mod exchange;
pub mod halo;
pub mod migration;
pub mod pack;

pub use comm::{Comm, SerialComm};
pub use decomposition::{Aabb, DecompositionError, Subdomains};
pub use exchange::{ExchangeError, Exchanged};

use crate::neighbor::Bounds;
use crate::scene::{BalanceWeight, Decomposition, ParallelSettings, Scene, SceneError};
use halo::{Ghosts, HaloPlan};
use nalgebra::Vector3;
use std::sync::Arc;

/// Seconds and counts of the decomposition's own work, cumulative.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ParallelTimers {
    /// Halo exchange: building and refreshing ghosts.
    pub halo: f64,
    /// Migration at rebuilds.
    pub migrate: f64,
    /// Load checks and recursive bisection.
    pub balance: f64,
    /// Gathering occupancy for insertion.
    pub insert: f64,
    /// Waiting for the slowest rank before the collective rebuild decision: the imbalance.
    pub wait: f64,
    /// A GPU rank's rebuilds: copying to the host what the exchange needs (through the host:
    /// the whole state; on the device: the centroids, the leaving particles with their history
    /// and the ghosts' sources).
    pub device_download: f64,
    /// A GPU rank's rebuilds: uploading the exchanged state after it (through the host: the
    /// particles, ghosts, history and walls; on the device: the arrivals and ghosts, assembled
    /// there with the particles that stay).
    pub device_upload: f64,
    /// Particles that migrated.
    pub migrated: u64,
    /// Times the boxes were redrawn.
    pub rebalances: u64,
    /// Halo rebuilds.
    pub rebuilds: u64,
    /// Of a GPU rank's rebuilds, those made with the state left on the device (the others,
    /// at insertions, removals and after an upload, go through the host).
    pub device_rebuilds: u64,
}

/// A rank's part of a decomposed run.
pub struct Parallel {
    pub comm: Arc<dyn Comm>,
    pub subdomains: Subdomains,
    pub settings: ParallelSettings,
    pub plan: HaloPlan,
    pub ghosts: Ghosts,
    pub timers: ParallelTimers,
    /// Seconds of force evaluation since the last load check (for `weight = "cost"`).
    pub cost: f64,
    rebuilds_since_check: u64,
}

/// The smallest id among `ghosts` held twice, as two ghosts or as a ghost and one of the
/// unique `owned` ids (sorting the ghosts alone: a rank's ghosts are few beside its particles).
fn held_twice(owned: &[u64], ghosts: &[u64]) -> Option<u64> {
    let mut ghosts = ghosts.to_vec();
    ghosts.sort_unstable();
    let among_ghosts = ghosts.windows(2).filter(|w| w[0] == w[1]).map(|w| w[0]);
    let also_owned = owned
        .iter()
        .copied()
        .filter(|id| ghosts.binary_search(id).is_ok());
    among_ghosts.chain(also_owned).min()
}

impl Parallel {
    /// The halo width for `scene`: the pair-list cutoff ([`Scene::cutoff`]).
    pub fn halo_width(scene: &Scene) -> f64 {
        scene.cutoff()
    }

    /// The decomposition of `scene` over `comm`'s ranks before any particle exists: the given
    /// or chosen grid, or for bisection the volume-halving cuts (redrawn at the first rebuild
    /// that finds the load imbalanced).
    ///
    /// A decomposition that cannot be made is an error naming the scene file, the line and the
    /// key to change ([`DecompositionError::scene_key`]).
    pub fn new(comm: Arc<dyn Comm>, scene: &Scene) -> Result<Self, SceneError> {
        Self::decompose(comm, scene).map_err(|e| scene.key_error(e.scene_key(), e.to_string()))
    }

    fn decompose(comm: Arc<dyn Comm>, scene: &Scene) -> Result<Self, DecompositionError> {
        let domain = Bounds {
            min: scene.domain.min,
            max: scene.domain.max,
            periodic: scene.domain.periodic,
        };
        let halo = Self::halo_width(scene);
        let ranks = comm.size();
        let subdomains = if ranks == 1 {
            Subdomains::single(domain, halo)
        } else {
            match scene.parallel.decomposition {
                Decomposition::Grid(Some(g)) => Subdomains::checked_grid(domain, halo, g, ranks)?,
                Decomposition::Grid(None) => {
                    Subdomains::grid(domain, halo, Subdomains::choose_grid(&domain, halo, ranks)?)
                }
                Decomposition::Rcb => Subdomains::bisection(&*comm, domain, halo, &[], &[])?,
            }
        };
        Ok(Parallel {
            comm,
            subdomains,
            settings: scene.parallel,
            plan: HaloPlan::default(),
            ghosts: Ghosts::default(),
            timers: ParallelTimers::default(),
            cost: 0.0,
            rebuilds_since_check: 0,
        })
    }

    /// This rank.
    pub fn rank(&self) -> usize {
        self.comm.rank()
    }

    /// This rank's box.
    pub fn own_box(&self) -> Aabb {
        self.subdomains.boxes[self.rank()]
    }

    /// At a rebuild: whether the boxes should be redrawn, and if so redraws them by recursive
    /// bisection of the owned particles' weights (count, or this rank's measured cost spread
    /// evenly over its particles), given their centroids. Returns whether the boxes changed.
    pub fn rebalance_if_needed(
        &mut self,
        owned: &[Vector3<f64>],
    ) -> Result<bool, DecompositionError> {
        if self.comm.size() == 1 || self.settings.decomposition != Decomposition::Rcb {
            return Ok(false);
        }
        self.rebuilds_since_check += 1;
        if self.rebuilds_since_check < self.settings.balance_interval {
            return Ok(false);
        }
        self.rebuilds_since_check = 0;
        let n = owned.len() as f64;
        let load = match self.settings.weight {
            BalanceWeight::Count => n,
            BalanceWeight::Cost => self.cost,
        };
        let loads = self.comm.sum_f64(&{
            let mut v = vec![0.0; self.comm.size()];
            v[self.rank()] = load;
            v
        });
        let mean = loads.iter().sum::<f64>() / loads.len() as f64;
        let max = loads.iter().cloned().fold(0.0, f64::max);
        self.cost = 0.0;
        if mean <= 0.0 || max <= self.settings.imbalance_threshold * mean {
            return Ok(false);
        }
        let per_particle = match self.settings.weight {
            BalanceWeight::Count => 1.0,
            BalanceWeight::Cost if n > 0.0 => load / n,
            BalanceWeight::Cost => 0.0,
        };
        let weights = vec![per_particle; owned.len()];
        let new = match Subdomains::bisection(
            &*self.comm,
            self.subdomains.domain,
            self.subdomains.halo,
            owned,
            &weights,
        ) {
            Ok(n) => n,
            Err(e) => {
                // Every rank fails alike (same reduced histograms): keep the boxes in use.
                tracing::warn!("rebalancing skipped, the current boxes are kept: {e}");
                return Ok(false);
            }
        };
        let changed = new != self.subdomains;
        if changed {
            tracing::debug!(
                imbalance = max / mean,
                "load imbalance above threshold: boxes redrawn"
            );
            self.subdomains = new;
            self.timers.rebalances += 1;
        }
        Ok(changed)
    }

    /// Ghost ids must be unique and distinct from the owned particles' ids `owned` (unique
    /// themselves: migration moves particles, it never copies them); a repeat means a box
    /// narrower than 2 × halo along a periodic axis, where one particle would be seen twice.
    /// The smallest id held twice is named.
    pub fn check_ghosts(&self, owned: &[u64]) -> Result<(), String> {
        if let Some(twice) = held_twice(owned, &self.ghosts.particles.id) {
            let b = self.own_box();
            return Err(format!(
                "rank {} holds particle {} twice (as owner or ghost): its box {:?} to {:?} is too \
                 thin for the halo width {:e} m across a periodic seam; use fewer ranks along \
                 that axis",
                self.rank(),
                twice,
                b.lo,
                b.hi,
                self.subdomains.halo
            ));
        }
        Ok(())
    }

    /// Positions the pair search bins the ghosts at: the true centroid moved to the image it
    /// was sent for.
    pub fn ghost_bins(&self) -> Vec<Vector3<f64>> {
        self.ghosts
            .particles
            .position
            .iter()
            .zip(&self.ghosts.images)
            .map(|(x, o)| x + self.subdomains.shift(o))
            .collect()
    }

    /// The box the pair search bins in: the own box grown by the halo on the axes it does not
    /// span, the whole (periodic) domain on the axes it spans.
    pub fn search_region(&self) -> Bounds {
        let s = &self.subdomains;
        let r = self.rank();
        let b = self.own_box();
        let mut out = Bounds {
            min: b.lo,
            max: b.hi,
            periodic: [false; 3],
        };
        for k in 0..3 {
            if s.spans(r, k) {
                out.min[k] = s.domain.min[k];
                out.max[k] = s.domain.max[k];
                out.periodic[k] = s.domain.periodic[k];
            } else {
                // Owned particles stray up to half a skin out between rebuilds, ghosts reach a
                // halo beyond the box: bin both inside the grid (edge cells catch the rest).
                out.min[k] -= s.halo;
                out.max[k] += s.halo;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::held_twice;
    use crate::rng::Rng;

    /// The id held twice is the smallest repeat of all ids together (brute force: sort them
    /// all), for unique owned ids and ghosts drawn with repeats and overlaps.
    #[test]
    fn the_smallest_id_held_twice_is_found() {
        let mut rng = Rng::new(5);
        let mut found = 0;
        for case in 0..200 {
            let mut owned: Vec<u64> = (0..300).map(|_| (rng.uniform() * 5000.0) as u64).collect();
            owned.sort_unstable();
            owned.dedup();
            let n_ghosts = 1 + case % 40;
            let ghosts: Vec<u64> = (0..n_ghosts)
                .map(|_| (rng.uniform() * 20000.0) as u64)
                .collect();
            let mut all: Vec<u64> = owned.iter().chain(&ghosts).copied().collect();
            all.sort_unstable();
            let want = all.windows(2).find(|w| w[0] == w[1]).map(|w| w[0]);
            assert_eq!(held_twice(&owned, &ghosts), want, "case {case}");
            found += usize::from(want.is_some());
        }
        assert!(found > 20 && found < 180, "{found} cases with a repeat");
        assert_eq!(held_twice(&[1, 2, 3], &[]), None);
        assert_eq!(held_twice(&[1, 2, 3], &[7, 3, 2]), Some(2));
        assert_eq!(held_twice(&[1], &[9, 8, 9]), Some(9));
    }
}
