//! A decomposed run's rebuild on the device (docs/design.md §6): migration and the choice of
//! ghosts without the rank's state going through the host.
//!
//! The host round trip (the whole state down, the CPU backend's exchange, everything up again)
//! costs about 100 ms a rebuild for 1.25e5 spheres a rank against 3.5 ms of stepping per list
//! (docs/performance.md). Here only what the decisions and the neighbours need crosses the bus
//! (the copies down of steps 1–3 are in [`super::rebuild_records`]):
//!
//! 1. down: every slot's ghost flag, global id and centroid (36 bytes a particle), from which
//!    the host balances, picks the particles that leave ([`crate::domain::migration::leaving`])
//!    and, after they arrive, plans the halo ([`HaloPlan::new`]) exactly as the CPU backend;
//! 2. down: the leaving particles' records, and their contact history packed on the device
//!    (`count_live_refs`, `pack_live_refs` and their wall rows of cuda/halo.cu), sent to their
//!    new owners as [`pack_particles`] buffers;
//! 3. down: the records of the particles the neighbours need as ghosts (the outer region),
//!    exchanged as [`build_ghosts`] does;
//! 4. up: the arrivals and the ghosts, appended on the device to the particles that stay,
//!    gathered there ([`DeviceParticles::assemble`]).
//!
//! The contact history never comes down whole: the next list build looks each new pair up in
//! the list before the rebuild (through each particle's slot before it) and then among the
//! entries the arrivals brought (`remap_history_exchanged` of cuda/neighbor.cu), and the walls'
//! springs are gathered from the old slots (`gather_live_wall_springs`). Both keep live contacts
//! only, the union the host round trip holds, so the trajectory is bitwise the same.
//! `POLYDEM_GPU_EXCHANGE` chooses the path (`device` or `host`; see [`ON_DEVICE_BY_DEFAULT`]).
//!
//! Insertion, removal through an open face, and the first rebuild after an upload (no list
//! yet) still take the round trip: they are rare, and need the host's state anyway.

use super::CudaSimulation;
use super::error::CudaError;
use super::history::history_rows;
use super::launch::{cfg, zeros};
use super::layout::HISTORY_WIDTH;
use super::pair_list::PairList;
use super::pairs::HistorySource;
use super::particles::{DeviceParticles, at_least_one};
use super::upload::host_arrays;
use crate::contact::{ContactHistory, ContactKey, ContactState};
use crate::domain::ExchangeError;
use crate::domain::halo::{HaloPlan, build_ghosts};
use crate::domain::migration::{leaving, pack_particles, unpack_particles};
use crate::pipeline::SimulationError;
use crate::state::Particles;
use cudarc::driver::{CudaSlice, CudaStream};
use nalgebra::Vector3;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

/// Whether rebuilds stay on the device when `POLYDEM_GPU_EXCHANGE` is unset: on. Measured on
/// one H100 with 2 ranks of `launch/neighbor/spheres_dense.toml`, the device path runs 3.26
/// times the host round trip (6.42e7 against 1.97e7 particle-steps/s; exchange 1.12 s against
/// 7.22 s), and every GPU test of the path passes (`tests/mpi_decomposition.rs`,
/// `gpu_rebuilds_on_the_device_are_the_host_round_trip` holds the two paths bitwise equal).
/// `POLYDEM_GPU_EXCHANGE=host` keeps the round trip.
const ON_DEVICE_BY_DEFAULT: bool = true;

/// No slot on this rank before the rebuild (`cuda/common.cuh: PD_NO_SLOT`).
const NO_SLOT: u32 = u32::MAX;

/// The contact history for the first list build after a rebuild on the device: of the list
/// before it, what the look-up reads (the pairs, each slot's references, the contact flags and
/// the springs; the rest of that list is freed at the rebuild, as the round trip frees it
/// all), the particles' global ids then, each new upload index's slot before it, and the
/// entries migrating particles brought, sorted by key.
pub(super) struct ExchangedHistory {
    old_pairs: CudaSlice<i32>,
    old_ref_offset: CudaSlice<u32>,
    old_refs: CudaSlice<u32>,
    old_contact: CudaSlice<u32>,
    old_spring: CudaSlice<f64>,
    old_id: CudaSlice<u64>,
    /// Per particle of the new upload order: its slot before the rebuild, or [`NO_SLOT`].
    old_slot: CudaSlice<u32>,
    n_recv: usize,
    recv_a: CudaSlice<u64>,
    recv_b: CudaSlice<u64>,
    recv_spring: CudaSlice<f64>,
}

impl ExchangedHistory {
    /// The springs of the `np` new pairs `pairs` (slots after the build's reordering `order`;
    /// `id` the particles' global ids in it) into `spring`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn remap(
        &self,
        k: &super::launch::Kernels,
        st: &Arc<CudaStream>,
        np: usize,
        pairs: &CudaSlice<i32>,
        id: &CudaSlice<u64>,
        order: &CudaSlice<u32>,
        spring: &mut CudaSlice<f64>,
    ) -> Result<(), CudaError> {
        let (npi, nr) = (np as i32, self.n_recv as i32);
        // SAFETY: `old_slot` covers the upload order `order` indexes, and its slots the old
        // list's particles; the received arrays hold n_recv entries, `spring` np records.
        unsafe {
            k.remap_history_exchanged(
                st,
                cfg(np),
                &npi,
                pairs,
                id,
                order,
                &self.old_slot,
                &self.old_ref_offset,
                &self.old_refs,
                &self.old_pairs,
                &self.old_id,
                &self.old_contact,
                &self.old_spring,
                &nr,
                &self.recv_a,
                &self.recv_b,
                &self.recv_spring,
                spring,
            )?;
        }
        Ok(())
    }
}

/// The owned slots (`ghost[i] == 0`) that are not among `leaving`, in slot order: the
/// particles that stay on the rank, new indices `0..` of its arrays.
fn staying(ghost: &[u32], leaving: &[u32]) -> Vec<u32> {
    let mut gone = vec![false; ghost.len()];
    for &s in leaving {
        gone[s as usize] = true;
    }
    (0..ghost.len() as u32)
        .filter(|&s| ghost[s as usize] == 0 && !gone[s as usize])
        .collect()
}

/// Where each particle of a rank's arrays after a rebuild on the device was before it: the
/// particles that stay (new indices `0..kept`), then the arrivals and the ghosts (`tail`).
#[derive(Debug, PartialEq)]
struct RebuildLayout {
    /// Per new index, its slot before, or [`NO_SLOT`]: a particle that stays, its own; an
    /// arrival or a ghost, the slot where it was a ghost or that it left from.
    old_slot: Vec<u32>,
    /// Per new index, the old slot whose live wall contacts it keeps, or [`NO_SLOT`]: a
    /// particle that stays, its own; a ghost that was owned here (it left), its own too, as
    /// the host's history would keep them; an arrival none (it brings its own).
    wall_source: Vec<u32>,
}

impl RebuildLayout {
    /// The layout for old slots of flags `ghost` and global ids `id`, the slots `kept` that
    /// stay and `leaving` that left, and after the kept ones the particles of ids `tail`, of
    /// which the first `arrivals` arrived (the rest are ghosts).
    fn new(
        ghost: &[u32],
        id: &[u64],
        kept: &[u32],
        leaving: &[u32],
        tail: &[u64],
        arrivals: usize,
    ) -> Self {
        // Only ghosts and leavers can come back as arrivals or ghosts: a few among many.
        let mut was: HashMap<u64, u32> = HashMap::new();
        for s in (0..ghost.len() as u32).filter(|&s| ghost[s as usize] != 0) {
            was.insert(id[s as usize], s);
        }
        for &s in leaving {
            was.insert(id[s as usize], s);
        }
        let before: Vec<u32> = tail
            .iter()
            .map(|g| was.get(g).copied().unwrap_or(NO_SLOT))
            .collect();
        let old_slot = kept.iter().chain(&before).copied().collect();
        let wall_source = kept
            .iter()
            .copied()
            .chain(before.iter().enumerate().map(|(t, &s)| {
                let left_from_here = s != NO_SLOT && ghost[s as usize] == 0;
                if t >= arrivals && left_from_here {
                    s
                } else {
                    NO_SLOT
                }
            }))
            .collect();
        RebuildLayout {
            old_slot,
            wall_source,
        }
    }
}

/// What the migration of a rebuild on the device leaves: whether the subdomains were redrawn,
/// the old slots that left (rank by rank), the particles that arrived and the contact history
/// entries they brought, and the seconds spent copying the leavers down.
struct Migration {
    redrawn: bool,
    leaving_slots: Vec<u32>,
    arrivals: Particles,
    brought: Vec<(ContactKey, ContactState)>,
    download: f64,
}

impl CudaSimulation {
    /// Whether this rebuild of a decomposed run can stay on the device: it is asked for
    /// (`POLYDEM_GPU_EXCHANGE`), no insertion is due on any rank (`pending` is the same on
    /// all), no particle left through an open face, and the device holds a list to carry the
    /// history from. A collective: every rank calls it at every rebuild and all get the same
    /// answer, even if the setting reached some ranks and not others.
    pub(super) fn rebuild_stays_on_device(&self, pending: bool, outside: bool) -> bool {
        let par = self.state.part();
        let asked = crate::tuning::Tuning::get()
            .gpu_exchange_on_device
            .unwrap_or(ON_DEVICE_BY_DEFAULT);
        let local = !asked || outside || self.pairs.list.is_none();
        !(pending || par.comm.any(local))
    }

    /// The rebuild of a decomposed run on the device (see the module docs): balance,
    /// migration and the ghosts chosen afresh, the particle arrays assembled anew on the
    /// device, and the next list build set to carry the history over.
    pub(super) fn rebuild_on_device(&mut self) -> Result<(), CudaError> {
        let t_down = Instant::now();
        let (ghost, id, position) = self.agree_device(self.centroids())?;
        let mut download = t_down.elapsed().as_secs_f64();
        let migration = self.migrate_from_device(&ghost, &position)?;
        download += migration.download;
        let kept = staying(&ghost, &migration.leaving_slots);
        download += self.choose_ghosts(&kept, &id, &position, &migration.arrivals)?;

        // Up: the arrivals and the ghosts after the particles that stay.
        let t_up = Instant::now();
        let Migration {
            redrawn,
            leaving_slots,
            arrivals,
            brought,
            ..
        } = migration;
        let n_arrivals = arrivals.len();
        let mut tail = arrivals;
        let par = self.state.part();
        tail.extend_from(&par.ghosts.particles);
        let particles = self.assemble_after_rebuild(&kept, &tail, n_arrivals)?;
        let n_new = particles.n;
        let layout = RebuildLayout::new(&ghost, &id, &kept, &leaving_slots, &tail.id, n_arrivals);
        let received = ContactHistory::from_entries(brought);
        let arrival_ids = &tail.id[..n_arrivals];
        let wall_spring =
            self.carried_wall_springs(&layout, n_new, kept.len(), arrival_ids, &received)?;
        let history = self.exchange_history(&received, particles, layout.old_slot)?;
        if redrawn {
            // The walls this rank keeps follow its new box.
            self.state.restrict_walls();
            self.upload_walls()?;
        }
        let st = self.gpu.stream.clone();
        if let (Some(w), Some(spring)) = (&mut self.walls, wall_spring) {
            w.install(&st, n_new, spring)?;
        }
        self.pairs
            .reset(HistorySource::Exchanged(Box::new(history)));
        self.halo.reset();
        self.host_current = false;
        let par = self.state.part_mut();
        par.timers.device_download += download;
        par.timers.device_upload += t_up.elapsed().as_secs_f64();
        Ok(())
    }

    /// Steps 1–2 of a rebuild on the device, for the old slots' ghost flags and centroids:
    /// the balance, the owned particles that leave and their records and history sent to
    /// their new owners, and what arrived.
    fn migrate_from_device(
        &mut self,
        ghost: &[u32],
        position: &[Vector3<f64>],
    ) -> Result<Migration, CudaError> {
        let owned: Vec<u32> = (0..ghost.len() as u32)
            .filter(|&i| ghost[i as usize] == 0)
            .collect();
        let owned_x: Vec<Vector3<f64>> = owned.iter().map(|&s| position[s as usize]).collect();
        let par = self.state.part_mut();
        let t0 = Instant::now();
        let redrawn = par
            .rebalance_if_needed(&owned_x)
            .map_err(|e| SimulationError::from(ExchangeError::from(e)))?;
        par.timers.balance += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let (me, ranks) = (par.rank(), par.comm.size());
        let leaving = leaving(&par.subdomains, me, ranks, &owned_x);
        // Their slots, rank by rank in `leaving`'s order, which the sends below follow.
        let leaving_slots: Vec<u32> = leaving.iter().flatten().map(|&i| owned[i]).collect();
        let moved = leaving_slots.len();
        let t_pack = Instant::now();
        let (batch, entries) = self.agree_device(self.leavers_state(&leaving_slots))?;
        let pack = t_pack.elapsed().as_secs_f64();
        let history = ContactHistory::from_entries(entries);
        let mut at = 0;
        let sends: Vec<Vec<u8>> = leaving
            .iter()
            .map(|which| {
                let range: Vec<usize> = (at..at + which.len()).collect();
                at += which.len();
                if which.is_empty() {
                    Vec::new()
                } else {
                    pack_particles(&batch, &range, &history)
                }
            })
            .collect();
        let par = self.state.part_mut();
        let received = par.comm.all_to_all(&sends);
        let mut arrivals = Particles::default();
        let mut brought = Vec::new();
        for buf in &received {
            brought.extend(unpack_particles(buf, &mut arrivals));
        }
        par.timers.migrated += moved as u64;
        par.timers.migrate += t0.elapsed().as_secs_f64() - pack;
        Ok(Migration {
            redrawn,
            leaving_slots,
            arrivals,
            brought,
            download: pack,
        })
    }

    /// Step 3: the halo planned for the particles that stay (old slots `kept`, in order) and
    /// the `arrivals`, and the ghosts exchanged with the neighbours, checked against the owned
    /// ids (`id`, `position`: the old slots'). Returns the seconds spent copying down.
    fn choose_ghosts(
        &mut self,
        kept: &[u32],
        id: &[u64],
        position: &[Vector3<f64>],
        arrivals: &Particles,
    ) -> Result<f64, CudaError> {
        let step = self.state.step;
        let ghosts_error =
            |message: String| SimulationError::from(ExchangeError::Ghosts { step, message });
        let t0 = Instant::now();
        let new_x: Vec<Vector3<f64>> = kept
            .iter()
            .map(|&s| position[s as usize])
            .chain(arrivals.position.iter().copied())
            .collect();
        let par = self.state.part_mut();
        par.plan = HaloPlan::new(&par.subdomains, par.rank(), &new_x);
        let (compact, sent) = par.plan.compact();
        let n_kept = kept.len();
        let sent_kept: Vec<u32> = sent
            .iter()
            .filter(|&&m| (m as usize) < n_kept)
            .map(|&m| kept[m as usize])
            .collect();
        let t_src = Instant::now();
        let mut source = self.agree_device(self.download_particles(&sent_kept))?;
        let sources = t_src.elapsed().as_secs_f64();
        let arrived: Vec<usize> = sent
            .iter()
            .filter(|&&m| (m as usize) >= n_kept)
            .map(|&m| m as usize - n_kept)
            .collect();
        source.extend_from(&arrivals.select(&arrived));
        let (scene, parallel) = (&self.state.scene, &mut self.state.parallel);
        let par = parallel.as_deref_mut().expect("a decomposed run");
        par.ghosts = build_ghosts(&*par.comm, &compact, &source, scene);
        par.timers.rebuilds += 1;
        par.timers.device_rebuilds += 1;
        let owned_ids: Vec<u64> = kept
            .iter()
            .map(|&s| id[s as usize])
            .chain(arrivals.id.iter().copied())
            .collect();
        par.check_ghosts(&owned_ids).map_err(ghosts_error)?;
        par.timers.halo += t0.elapsed().as_secs_f64() - sources;
        Ok(sources)
    }

    /// Step 4: the particle arrays anew, the old slots `kept` gathered on the device, then
    /// `tail` (its first `n_arrivals` the arrivals, the rest the ghosts) uploaded after them.
    fn assemble_after_rebuild(
        &self,
        kept: &[u32],
        tail: &Particles,
        n_arrivals: usize,
    ) -> Result<DeviceParticles, CudaError> {
        let st = &self.gpu.stream;
        let n_kept = kept.len();
        let kept_slots = st.clone_htod(&at_least_one(kept.to_vec()))?;
        let n_tail = tail.len();
        DeviceParticles::assemble(
            &self.gpu.k,
            st,
            &self.particles,
            (&kept_slots, n_kept),
            host_arrays(&self.state.scene, tail, n_arrivals),
            n_tail,
        )
        .map_err(|e| {
            let n = n_kept + n_tail;
            e.out_of_memory(
                || format!("the particle arrays of {n} particles"),
                Some(n * DeviceParticles::BYTES_PER_PARTICLE),
            )
        })
    }

    /// The walls' springs for the `n_new` particles after a rebuild, `None` without walls: a
    /// particle that stays keeps its live ones, an arrival takes those it brought
    /// (`received`, for the ids `arrival_ids` after the `n_kept` that stay), a ghost that was
    /// owned here keeps its own (the host's history would; a ghost's walls are its owner's to
    /// evaluate).
    fn carried_wall_springs(
        &self,
        layout: &RebuildLayout,
        n_new: usize,
        n_kept: usize,
        arrival_ids: &[u64],
        received: &ContactHistory,
    ) -> Result<Option<CudaSlice<f64>>, CudaError> {
        let w = match &self.walls {
            Some(w) if w.n > 0 => w,
            _ => return Ok(None),
        };
        let (st, k) = (&self.gpu.stream, &self.gpu.k);
        let n_arrivals = arrival_ids.len();
        let mut spring = zeros::<f64>(st, HISTORY_WIDTH * w.n * n_new)?;
        let source_slot = st.clone_htod(&at_least_one(layout.wall_source.clone()))?;
        let (nn, nw) = (n_new as i32, w.n as i32);
        // SAFETY: `source_slot` holds n_new slots of the old arrays (or NO_SLOT), the old
        // flags and springs a row per old slot and wall, `spring` n_new · walls.
        unsafe {
            k.gather_live_wall_springs(
                st,
                cfg(n_new * w.n),
                &nn,
                &nw,
                &source_slot,
                &w.contact,
                &w.spring_in,
                &mut spring,
            )?;
        }
        let rows = history_rows(arrival_ids, received, w.n).wall_spring;
        let (from, len) = (
            HISTORY_WIDTH * w.n * n_kept,
            HISTORY_WIDTH * w.n * n_arrivals,
        );
        if n_arrivals > 0 {
            st.memcpy_htod(&rows[..len], &mut spring.slice_mut(from..from + len))?;
        }
        Ok(Some(spring))
    }

    /// The history the next list build carries over ([`ExchangedHistory`]): what it needs of
    /// the list before the rebuild, the old particles' ids (the arrays `particles` replace),
    /// each new index's slot before (`old_slot`), and the pair entries the arrivals brought
    /// (`received`), sorted by key.
    fn exchange_history(
        &mut self,
        received: &ContactHistory,
        particles: DeviceParticles,
        old_slot: Vec<u32>,
    ) -> Result<ExchangedHistory, CudaError> {
        let st = self.gpu.stream.clone();
        let recv: Vec<&(ContactKey, ContactState)> = received
            .entries()
            .iter()
            .filter(|(key, _)| key.wall_index().is_none())
            .collect();
        let recv_a: Vec<u64> = recv.iter().map(|(key, _)| key.a).collect();
        let recv_b: Vec<u64> = recv.iter().map(|(key, _)| key.b).collect();
        let recv_spring: Vec<f64> = recv
            .iter()
            .flat_map(|(_, s)| super::layout::history_record(s))
            .collect();
        let PairList {
            pairs: old_pairs,
            ref_offset: old_ref_offset,
            refs: old_refs,
            contact: old_contact,
            spring: old_spring,
            ..
        } = self
            .pairs
            .list
            .take()
            .ok_or(super::error::HaloError::MissingHistory)?;
        let old = std::mem::replace(&mut self.particles, particles);
        Ok(ExchangedHistory {
            old_pairs,
            old_ref_offset,
            old_refs,
            old_contact,
            old_spring,
            old_id: old.id,
            old_slot: st.clone_htod(&at_least_one(old_slot))?,
            n_recv: recv.len(),
            recv_a: st.clone_htod(&at_least_one(recv_a))?,
            recv_b: st.clone_htod(&at_least_one(recv_b))?,
            recv_spring: st.clone_htod(&at_least_one(recv_spring))?,
        })
    }

    /// `local`, the outcome of this rank's device copies between two collectives of a
    /// rebuild, agreed with every rank before the next one: a rank whose copy failed returns
    /// its error and the others stop with it ([`SimulationError::Stopped`]), rather than wait
    /// in a collective that rank will not join.
    fn agree_device<T>(&self, local: Result<T, CudaError>) -> Result<T, CudaError> {
        match (self.state.stopped_by(local.is_err()), local) {
            (Some(stopped), Ok(_)) => Err(stopped.into()),
            (_, local) => local,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// On random ranks (slots of owned particles and ghosts shuffled, some owned ones leaving;
    /// arrivals and ghosts after the rebuild drawn among the old ghosts, the leavers and new
    /// ids): the particles that stay are the owned ones that did not leave, in slot order; a
    /// new particle's old slot holds its id, and is missing exactly when it was not on the
    /// rank; the wall springs come from its own slot for those that stay and for ghosts that
    /// left from here, from nowhere for the others.
    #[test]
    fn each_particle_after_a_rebuild_is_traced_to_its_slot_before() {
        let mut rng = Rng::new(41);
        for case in 0..50 {
            let n = 50 + case * 7;
            let ghost: Vec<u32> = (0..n).map(|_| u32::from(rng.uniform() < 0.3)).collect();
            let id: Vec<u64> = (0..n as u64).map(|i| 1000 + 3 * i + case as u64).collect();
            let owned: Vec<u32> = (0..n as u32).filter(|&s| ghost[s as usize] == 0).collect();
            let leaving: Vec<u32> = owned
                .iter()
                .copied()
                .filter(|_| rng.uniform() < 0.2)
                .collect();
            let kept = staying(&ghost, &leaving);
            let want: Vec<u32> = owned
                .iter()
                .copied()
                .filter(|s| !leaving.contains(s))
                .collect();
            assert_eq!(kept, want);
            // Arrivals: old ghosts or new ids; ghosts: old ghosts, leavers or new ids.
            let old_ghosts: Vec<u64> = (0..n).filter(|&s| ghost[s] != 0).map(|s| id[s]).collect();
            let mut fresh = 10_000_000 + case as u64 * 1000;
            let mut pick = |from: &[u64], rng: &mut Rng| -> u64 {
                if from.is_empty() || rng.uniform() < 0.4 {
                    fresh += 1;
                    fresh
                } else {
                    from[(rng.uniform() * from.len() as f64) as usize % from.len()]
                }
            };
            let left: Vec<u64> = leaving.iter().map(|&s| id[s as usize]).collect();
            let mut tail: Vec<u64> = (0..8).map(|_| pick(&old_ghosts, &mut rng)).collect();
            let arrivals = tail.len();
            let back: Vec<u64> = old_ghosts.iter().chain(&left).copied().collect();
            tail.extend((0..15).map(|_| pick(&back, &mut rng)));
            tail.sort_unstable();
            tail.dedup();
            let arrivals = arrivals.min(tail.len());
            let l = RebuildLayout::new(&ghost, &id, &kept, &leaving, &tail, arrivals);
            assert_eq!(l.old_slot.len(), kept.len() + tail.len());
            assert_eq!(l.wall_source.len(), l.old_slot.len());
            let new_ids: Vec<u64> = kept
                .iter()
                .map(|&s| id[s as usize])
                .chain(tail.iter().copied())
                .collect();
            for (j, (&s, &g)) in l.old_slot.iter().zip(&new_ids).enumerate() {
                let here_before = (0..n).find(|&t| id[t] == g);
                match here_before {
                    Some(t) => assert_eq!(s, t as u32, "new index {j}, id {g}"),
                    None => assert_eq!(s, NO_SLOT, "new index {j}, id {g}"),
                }
                let wall = l.wall_source[j];
                if j < kept.len() {
                    assert_eq!(wall, s);
                } else if j < kept.len() + arrivals {
                    assert_eq!(wall, NO_SLOT);
                } else if s != NO_SLOT && ghost[s as usize] == 0 {
                    assert!(leaving.contains(&s));
                    assert_eq!(wall, s);
                } else {
                    assert_eq!(wall, NO_SLOT);
                }
            }
        }
    }
}
