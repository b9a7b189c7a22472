//! Stage 2 on the GPU, host side: the [`PairStage`] owns the pair list and everything indexed
//! by pair, and builds it: binning with the reordering of the particle arrays, the int2 pair
//! list and the per-particle references, and the contact history carried over a rebuild
//! (kernels in `cuda/scan.cu` and `cuda/neighbor.cu`). The evaluation of the listed pairs is in
//! [`super::pair_contacts`].

use super::error::{CudaError, HaloError};
use super::exchange::ExchangedHistory;
use super::gpu::Gpu;
use super::history::PairOutcomes;
use super::launch::{cfg, ptr, zeros};
use super::layout::{GridParams, HISTORY_WIDTH, PairSearchParams, staged_planes_bytes};
use super::particles::DeviceParticles;
use super::walls::WallStage;
use crate::geometry::vertex_enumeration::ENUM_MAX_PLANES;
use crate::neighbor::SlotList;
use cudarc::driver::{CudaSlice, CudaStream};
use std::sync::Arc;

/// Plane-count buckets of the lean pair passes: counts 0..=ENUM_MAX_PLANES (`PD_PLANE_BUCKETS`).
pub(super) const PLANE_BUCKETS: usize = ENUM_MAX_PLANES + 1;

/// The pair list and everything indexed by pair.
pub(super) struct PairList {
    pub(super) n: usize,
    /// In a decomposed run, the pairs `0..n_interior` have two owned members and need nothing
    /// from the halo; the rest have a ghost. Otherwise `n`.
    pub(super) n_interior: usize,
    /// Per particle, its pairs as first member (`offset[i]..offset[i + 1]`): the history source
    /// of the next build; `None` for a decomposed run's two-part list.
    pub(super) offset: Option<CudaSlice<u32>>,
    pub(super) pairs: CudaSlice<i32>,
    /// Each pair's cached separating axis, in f32 (a hint: `store_axis` of cuda/contact.cu).
    pub(super) axes: CudaSlice<f32>,
    /// Each pair's contact history ([`HISTORY_WIDTH`] values): read and written in place by
    /// the one thread that settles the pair in a step (`pair_contact_law` reads the record
    /// before it writes it; a pair without contact has it cleared, unread), so one buffer
    /// serves as last step's history and this step's.
    pub(super) spring: CudaSlice<f64>,
    pub(super) forces: CudaSlice<f64>,
    pub(super) energy: CudaSlice<f64>,
    pub(super) contact: CudaSlice<u32>,
    pub(super) ref_offset: CudaSlice<u32>,
    pub(super) refs: CudaSlice<u32>,
    /// The pairs the lean passes leave to the full evaluation (GJK, the dual hull), and their
    /// count.
    pub(super) deferred: CudaSlice<u32>,
    pub(super) deferred_count: CudaSlice<u32>,
    /// Pairs per batch of the lean passes ([`staging_batch`]).
    pub(super) batch: usize,
    /// Between the two lean passes of polyhedral pairs (`pair_planes`, `pair_faces`), for the
    /// pairs of one batch: each staged pair's planes (`StagedPlanes` of cuda/contact.cu,
    /// [`staged_planes_bytes`] each), its plane-count bucket, the staged pairs listed bucket by
    /// bucket, and per bucket the count and the fill cursor ([`PLANE_BUCKETS`] values each).
    pub(super) staged: CudaSlice<u8>,
    pub(super) bucket: CudaSlice<u8>,
    pub(super) order: CudaSlice<u32>,
    pub(super) bucket_count: CudaSlice<u32>,
    pub(super) bucket_fill: CudaSlice<u32>,
}

impl PairList {
    /// The members' slots of the listed pairs.
    pub(super) fn slots(&self, st: &Arc<CudaStream>) -> Result<Vec<[usize; 2]>, CudaError> {
        let pairs = st.clone_dtoh(&self.pairs)?;
        Ok(pairs
            .chunks_exact(2)
            .take(self.n)
            .map(|ab| [ab[0] as usize, ab[1] as usize])
            .collect())
    }

    /// The contact flags of the listed pairs.
    pub(super) fn flags(&self, st: &Arc<CudaStream>) -> Result<Vec<u32>, CudaError> {
        let mut contact = st.clone_dtoh(&self.contact)?;
        contact.truncate(self.n);
        Ok(contact)
    }

    /// The last evaluation's outcomes, copied down.
    pub(super) fn outcomes(&self, st: &Arc<CudaStream>) -> Result<PairOutcomes, CudaError> {
        let (slots, contact) = (self.slots(st)?, self.flags(st)?);
        let mut spring = st.clone_dtoh(&self.spring)?;
        spring.truncate(HISTORY_WIDTH * self.n);
        let mut energy = st.clone_dtoh(&self.energy)?;
        energy.truncate(self.n);
        let mut refs = st.clone_dtoh(&self.refs)?;
        refs.truncate(2 * self.n);
        Ok(PairOutcomes {
            slots,
            contact,
            spring,
            energy,
            ref_offset: st.clone_dtoh(&self.ref_offset)?,
            refs,
        })
    }

    /// Bytes of device memory held by the list and its per-pair buffers.
    fn bytes(&self) -> usize {
        fn b<T>(s: &CudaSlice<T>) -> usize {
            s.len() * std::mem::size_of::<T>()
        }
        self.offset.as_ref().map_or(0, b)
            + b(&self.pairs)
            + b(&self.deferred)
            + b(&self.deferred_count)
            + b(&self.staged)
            + b(&self.bucket)
            + b(&self.order)
            + b(&self.bucket_count)
            + b(&self.bucket_fill)
            + b(&self.axes)
            + b(&self.spring)
            + b(&self.forces)
            + b(&self.energy)
            + b(&self.contact)
            + b(&self.ref_offset)
            + b(&self.refs)
    }
}

/// Device bytes of a list of `np` pairs ([`PairStage::allocate_list`]): per pair, the pair,
/// its two references, the cached separating axis (f32), the spring (one record, updated in place),
/// the forces, energy and contact flag and the deferred index; for polyhedra, per pair of one
/// staging batch of `batch` ([`staging_batch`]), the staged planes (`staged_bytes`), the
/// plane-count bucket and the bucket order.
pub(super) fn list_bytes(np: usize, batch: usize, spheres: bool, staged_bytes: usize) -> usize {
    let per_pair = 2 * 4 + 2 * 4 + 3 * 4 + HISTORY_WIDTH * 8 + 9 * 8 + 8 + 4 + 4;
    let staging = if spheres { 0 } else { staged_bytes + 1 + 4 };
    np * per_pair + batch * staging
}

/// Most bytes of staged planes a list holds by default: the lean passes run over the pairs in
/// batches of as many pairs as that holds ([`staging_batch`]), so that a list of millions of
/// pairs does not hold a staging record for each (160 B a pair in mixed precision, as much as
/// everything else of a pair together).
const STAGING_BYTES: usize = 256 << 20;

/// Pairs per staging batch of the lean passes for a list of `np` pairs of `staged_bytes` a
/// staged record: all of them when they fit [`STAGING_BYTES`] (or `POLYDEM_PAIR_BATCH`), else
/// as many as fit. The batches change no result: each pair is settled by itself.
pub(super) fn staging_batch(np: usize, staged_bytes: usize) -> usize {
    let most = crate::tuning::Tuning::get()
        .pair_batch
        .map_or(STAGING_BYTES / staged_bytes.max(1), |b| b as usize);
    np.min(most.max(1)).max(1)
}

/// The contact history handed to the next list build.
pub(super) enum HistorySource {
    /// For each particle in the numbering before the build's reordering, its pairs as first
    /// member: the partners' ids and the springs (CSR).
    Rows {
        offset: CudaSlice<u32>,
        partner: CudaSlice<u64>,
        spring: CudaSlice<f64>,
    },
    /// A decomposed run's rebuild on the device: the list before it and the entries migrating
    /// particles brought ([`ExchangedHistory`]).
    Exchanged(Box<ExchangedHistory>),
}

/// Stage 2 and the pair list it keeps (the GPU twin of the CPU's `PairList`).
pub(super) struct PairStage {
    /// The current list; `None` until the first build after an upload.
    pub(super) list: Option<PairList>,
    /// The particles' positions at the last build (`kick_drift` checks the half skin against
    /// them).
    pub(super) reference: CudaSlice<f64>,
    /// The history uploaded from the host, for the next build.
    pub(super) pending_history: Option<HistorySource>,
    /// A build is due before the next evaluation.
    pub(super) rebuild: bool,
    /// Pair lists built so far.
    pub(super) builds: u64,
    /// Half the skin of the current list: how far a particle may move from `reference` before
    /// the list is due (`kick_drift`'s check).
    pub(super) half_skin: f64,
    /// Counts the renumberings of the particle slots (every build, every upload): a host
    /// build from positions of an older numbering names slots that no longer hold its
    /// particles.
    pub(super) generation: u64,
}

/// Where a list build takes its order and its pairs from.
pub(super) enum ListSource<'a> {
    /// The device bins, sorts and searches, with this skin and on this grid (cells at least
    /// `2 r_max + skin` wide).
    Device { skin: f64, grid: GridParams },
    /// A list the host built ([`crate::neighbor::build_slot_list`]) from `snapshot`, the
    /// device's positions in the current slot order when the host took them.
    Host {
        list: &'a SlotList,
        snapshot: &'a CudaSlice<f64>,
    },
}

impl PairStage {
    pub(super) fn new(gpu: &Gpu) -> Result<Self, CudaError> {
        Ok(PairStage {
            list: None,
            reference: gpu.stream.alloc_zeros::<f64>(1)?,
            pending_history: None,
            rebuild: true,
            builds: 0,
            half_skin: 0.0,
            generation: 0,
        })
    }

    /// Bytes of device memory held by the list and the reference positions.
    pub(super) fn bytes(&self) -> usize {
        self.reference.len() * 8 + self.list.as_ref().map_or(0, PairList::bytes)
    }

    /// Drops the list (and its history) for a fresh upload; the next evaluation builds one.
    pub(super) fn reset(&mut self, history: HistorySource) {
        self.list = None;
        self.pending_history = Some(history);
        self.rebuild = true;
        self.generation += 1;
    }

    /// Stage 2: bins, reorders the particle arrays (and the walls' springs) by cell, builds the
    /// pair list and the per-particle references, and carries the contact history over; the
    /// order and the pairs come from `source`. `decomposed`: a rank of a decomposed run (pairs
    /// of two owned particles first; device builds only). Returns the reordering: `order[k]`
    /// = the slot before the build now at slot `k`.
    pub(super) fn build(
        &mut self,
        gpu: &Gpu,
        p: &mut DeviceParticles,
        walls: Option<&mut WallStage>,
        decomposed: bool,
        source: ListSource,
    ) -> Result<CudaSlice<u32>, CudaError> {
        let n = p.n;
        // The allocation of the counted list names its bytes itself; an earlier one (the
        // binning, the search's counts) is named here.
        self.build_list(gpu, p, walls, decomposed, source)
            .map_err(|e| e.out_of_memory(|| format!("the pair-list build of {n} particles"), None))
    }

    /// [`PairStage::build`], with the device's out-of-memory while allocating the counted
    /// list's per-pair buffers named with their bytes.
    fn build_list(
        &mut self,
        gpu: &Gpu,
        p: &mut DeviceParticles,
        walls: Option<&mut WallStage>,
        decomposed: bool,
        source: ListSource,
    ) -> Result<CudaSlice<u32>, CudaError> {
        let st = gpu.stream.clone();
        let k = &gpu.k;
        let n = p.n;
        let ni = n as i32;
        // History of the current list (or the one uploaded from the host), in the numbering
        // before this build.
        let history = match (self.pending_history.take(), self.list.take()) {
            (Some(h), _) => h,
            (None, Some(old)) => {
                let Some(old_offset) = old.offset else {
                    return Err(HaloError::MissingHistory.into());
                };
                let mut partner = zeros::<u64>(&st, old.n)?;
                let npi = old.n as i32;
                // SAFETY: `partner` holds a value per pair of the old list.
                unsafe {
                    k.history_partners(&st, cfg(old.n), &npi, &old.pairs, &p.id, &mut partner)?;
                }
                HistorySource::Rows {
                    offset: old_offset,
                    partner,
                    spring: old.spring,
                }
            }
            (None, None) => HistorySource::Rows {
                offset: zeros::<u32>(&st, n + 1)?,
                partner: zeros::<u64>(&st, 1)?,
                spring: zeros::<f64>(&st, HISTORY_WIDTH)?,
            },
        };
        // The order: by cell (global id within a cell), binned here or taken from the host.
        let (order, cell_start, skin) = match &source {
            ListSource::Device { skin, grid } => {
                let (order, cell_start) = sort_by_cell(gpu, p, grid)?;
                (order, Some(cell_start), *skin)
            }
            ListSource::Host { list, .. } => {
                if decomposed || list.order.len() != n {
                    return Err(CudaError::HostListMismatch {
                        list: list.order.len(),
                        device: n,
                        decomposed,
                    });
                }
                (st.clone_htod(&list.order)?, None, list.skin)
            }
        };
        // The host list was built from the snapshot: its positions, in the new order, are the
        // reference the list's validity is measured from (hybrid paper Eq. 2).
        let reference = match &source {
            ListSource::Host { snapshot, .. } => {
                let mut r = zeros::<f64>(&st, 3 * n)?;
                // SAFETY: both buffers hold 3n values, `order` n indices below n.
                unsafe { k.gather_f64(&st, cfg(n), &ni, &3, snapshot, &mut r, &order)? };
                Some(r)
            }
            ListSource::Device { .. } => None,
        };
        // Reorder every particle array (and the wall springs) by `order`; the wall list names
        // particles by index, so it is built again too.
        p.gather_f64s(k, &st, &order)?;
        if let Some(w) = walls {
            w.gather_springs(k, &st, n, &order)?;
            w.list = None;
        }
        p.gather_u32s(k, &st, &order)?;
        p.gather_u64s(k, &st, &order)?;
        // Pairs: count, exclusive prefix sum, fill. A decomposed run lists the pairs of two
        // owned particles first and those with a ghost after them, so the first part can be
        // evaluated while the halo is in flight.
        let (np, n_interior, pairs, offset) = if let ListSource::Host { list, .. } = &source {
            let np = list.pairs.len();
            let flat: &[i32] = list.pairs.as_flattened();
            let pairs = if np > 0 {
                st.clone_htod(flat)?
            } else {
                zeros::<i32>(&st, 2)?
            };
            (np, np, pairs, Some(st.clone_htod(&list.offset)?))
        } else if decomposed {
            let (grid, cell_start) = (device_grid(&source), cell_start.as_ref().expect("binned"));
            let (n1, p1, _) = list_pairs(gpu, p, 1, cell_start, grid, skin)?;
            let (n2, p2, _) = list_pairs(gpu, p, 2, cell_start, grid, skin)?;
            let np = n1 + n2;
            let mut pairs = zeros::<i32>(&st, 2 * np)?;
            if n1 > 0 {
                st.memcpy_dtod(&p1.slice(0..2 * n1), &mut pairs.slice_mut(0..2 * n1))?;
            }
            if n2 > 0 {
                st.memcpy_dtod(&p2.slice(0..2 * n2), &mut pairs.slice_mut(2 * n1..2 * np))?;
            }
            // Pairs of one particle are in two ranges now, so the list is no CSR by particle:
            // this run's history comes up from the host at every rebuild instead.
            (np, n1, pairs, None)
        } else {
            let (grid, cell_start) = (device_grid(&source), cell_start.as_ref().expect("binned"));
            let (np, pairs, offset) = list_pairs(gpu, p, 0, cell_start, grid, skin)?;
            (np, np, pairs, Some(offset))
        };
        let spheres = gpu.config.spheres;
        let staged_bytes = staged_planes_bytes(gpu.config.precision);
        let bytes = list_bytes(np, staging_batch(np, staged_bytes), spheres, staged_bytes);
        let list = Self::allocate_list(
            gpu,
            p,
            (np, n_interior),
            (pairs, offset),
            &history,
            &order,
            spheres,
        )
        .map_err(|e| {
            e.out_of_memory(
                || format!("the pair list of {n} particles ({np} pairs, {bytes} bytes)"),
                Some(bytes),
            )
        })?;
        self.list = Some(list);
        self.reference = match reference {
            Some(r) => r,
            None => st.clone_dtod(&p.position)?,
        };
        self.half_skin = 0.5 * skin;
        self.rebuild = false;
        self.builds += 1;
        self.generation += 1;
        Ok(order)
    }

    /// The per-pair buffers of a list of `np` pairs (`n_interior` of two owned particles),
    /// given its pairs and per-particle offsets: the references per particle sorted by
    /// partner id and the springs of the pairs that survive from `history`
    /// ([`list_bytes`] in all).
    #[allow(clippy::too_many_arguments)]
    fn allocate_list(
        gpu: &Gpu,
        p: &DeviceParticles,
        (np, n_interior): (usize, usize),
        (pairs, offset): (CudaSlice<i32>, Option<CudaSlice<u32>>),
        history: &HistorySource,
        order: &CudaSlice<u32>,
        spheres: bool,
    ) -> Result<PairList, CudaError> {
        let st = gpu.stream.clone();
        let k = &gpu.k;
        let n = p.n;
        let ni = n as i32;
        // References per particle, sorted by partner id.
        let npi = np as i32;
        let mut ref_count = zeros::<u32>(&st, n)?;
        unsafe { k.count_refs(&st, cfg(np), &npi, &pairs, &mut ref_count)? };
        let mut ref_offset = zeros::<u32>(&st, n + 1)?;
        gpu.scan(&ref_count, n, &mut ref_offset)?;
        let mut ref_fill = zeros::<u32>(&st, n)?;
        let mut refs = zeros::<u32>(&st, 2 * np)?;
        unsafe {
            k.fill_refs(
                &st,
                cfg(np),
                &npi,
                &pairs,
                &ref_offset,
                &mut ref_fill,
                &mut refs,
            )?;
            k.sort_refs(&st, cfg(n), &ni, &ref_offset, &mut refs, &pairs, &p.id)?;
        }
        // The springs of pairs that survive, found by (lower-id member, partner id).
        let mut carried = zeros::<f64>(&st, HISTORY_WIDTH * np)?;
        match history {
            HistorySource::Rows {
                offset,
                partner,
                spring,
            } => unsafe {
                // SAFETY: the rows cover the n particles before the build, `order` n indices.
                k.remap_history(
                    &st,
                    cfg(np),
                    &npi,
                    &pairs,
                    &p.id,
                    order,
                    offset,
                    partner,
                    spring,
                    &mut carried,
                )?;
            },
            HistorySource::Exchanged(h) => {
                h.remap(k, &st, np, &pairs, &p.id, order, &mut carried)?
            }
        }
        let staged_bytes = staged_planes_bytes(gpu.config.precision);
        let batch = staging_batch(np, staged_bytes);
        Ok(PairList {
            n: np,
            batch,
            n_interior,
            offset,
            pairs,
            axes: zeros::<f32>(&st, 3 * np)?,
            spring: carried,
            forces: zeros::<f64>(&st, 9 * np)?,
            energy: zeros::<f64>(&st, np)?,
            contact: zeros::<u32>(&st, np)?,
            ref_offset,
            refs,
            deferred: zeros::<u32>(&st, np)?,
            deferred_count: zeros::<u32>(&st, 1)?,
            // The two lean passes of polyhedral pairs stage planes per pair of a batch
            // (spheres: none).
            staged: zeros::<u8>(&st, if spheres { 1 } else { batch * staged_bytes })?,
            bucket: zeros::<u8>(&st, if spheres { 1 } else { batch })?,
            order: zeros::<u32>(&st, if spheres { 1 } else { batch })?,
            bucket_count: zeros::<u32>(&st, PLANE_BUCKETS)?,
            bucket_fill: zeros::<u32>(&st, PLANE_BUCKETS)?,
        })
    }
}

/// The grid of a device build.
fn device_grid(source: &ListSource) -> GridParams {
    match source {
        ListSource::Device { grid, .. } => *grid,
        ListSource::Host { .. } => unreachable!("host lists are not searched on the device"),
    }
}

/// Bins the particles on `grid` and sorts them by cell (global id within a cell, so the
/// order does not depend on the atomics' arrival): the order (`order[k]` = the slot now at
/// slot `k`) and each cell's first slot in it.
fn sort_by_cell(
    gpu: &Gpu,
    p: &DeviceParticles,
    grid: &GridParams,
) -> Result<(CudaSlice<u32>, CudaSlice<u32>), CudaError> {
    let st = gpu.stream.clone();
    let k = &gpu.k;
    let n = p.n;
    let ni = n as i32;
    let cells = grid.cells();
    let mut cell = zeros::<u32>(&st, n)?;
    let mut cell_count = zeros::<u32>(&st, cells)?;
    // SAFETY (all launches below): every buffer holds the element counts the kernels index.
    unsafe {
        k.bin_particles(
            &st,
            cfg(n),
            &ni,
            &p.position,
            grid,
            &mut cell,
            &mut cell_count,
        )?
    };
    let mut cell_start = zeros::<u32>(&st, cells + 1)?;
    gpu.scan(&cell_count, cells, &mut cell_start)?;
    let mut fill = zeros::<u32>(&st, cells)?;
    let mut order = zeros::<u32>(&st, n)?;
    let ci = cells as i32;
    unsafe {
        k.scatter_by_cell(&st, cfg(n), &ni, &cell, &cell_start, &mut fill, &mut order)?;
        k.sort_cells(&st, cfg(cells), &ci, &cell_start, &mut order, &p.id)?;
    }
    Ok((order, cell_start))
}

/// Count, exclusive prefix sum and fill of the pairs of `part` within `skin`, on `grid` (0 all; in a decomposed run 1
/// those of two owned particles, 2 those with a ghost): their number, the int2 list and the
/// per-particle offsets.
fn list_pairs(
    gpu: &Gpu,
    p: &DeviceParticles,
    part: i32,
    cell_start: &CudaSlice<u32>,
    grid: GridParams,
    skin: f64,
) -> Result<(usize, CudaSlice<i32>, CudaSlice<u32>), CudaError> {
    let st = gpu.stream.clone();
    let n = p.n;
    let args = PairSearchParams {
        n: n as i32,
        part,
        position: ptr(&p.position, &st),
        radius: ptr(&p.radius, &st),
        id: ptr(&p.id, &st),
        ghost: ptr(&p.ghost, &st),
        cell_start: ptr(cell_start, &st),
        grid,
        skin,
    };
    let mut counts = zeros::<u32>(&st, n)?;
    // SAFETY: the particle buffers hold n values, cell_start cells + 1, `counts` n.
    unsafe { gpu.k.count_pairs(&st, cfg(n), &args, &mut counts)? };
    let mut offset = zeros::<u32>(&st, n + 1)?;
    let np = gpu.scan(&counts, n, &mut offset)? as usize;
    let mut pairs = zeros::<i32>(&st, 2 * np)?;
    // SAFETY: as above; `pairs` holds the 2 np values the offsets reach.
    unsafe { gpu.k.fill_pairs(&st, cfg(n), &args, &offset, &mut pairs)? };
    Ok((np, pairs, offset))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::cuda::Precision;

    /// A short list is staged whole; a long one in batches that hold at most 256 MiB of staged
    /// planes, in either precision, and the list's bytes count the staging once per batch.
    #[test]
    fn long_lists_are_staged_in_batches_of_256_mib() {
        for precision in [Precision::Mixed, Precision::Double] {
            let staged = staged_planes_bytes(precision);
            assert_eq!(staging_batch(0, staged), 1);
            assert_eq!(staging_batch(5000, staged), 5000);
            let long = 20_000_000;
            let batch = staging_batch(long, staged);
            assert!(batch < long && batch * staged <= STAGING_BYTES);
            assert!((batch + 1) * staged > STAGING_BYTES);
            let whole = list_bytes(long, long, false, staged);
            let batched = list_bytes(long, batch, false, staged);
            assert_eq!(whole - batched, (long - batch) * (staged + 1 + 4));
            assert_eq!(
                list_bytes(long, batch, true, staged),
                list_bytes(long, 1, true, 0)
            );
        }
        // Mixed precision stages 160 bytes a pair: 1.68e6 pairs a batch.
        assert_eq!(staged_planes_bytes(Precision::Mixed), 160);
        assert_eq!(staging_batch(usize::MAX, 160), 1_677_721);
    }
}
