//! Stage 2 on the GPU, host side: the [`PairStage`] owns the pair list and everything indexed
//! by pair, and builds it: binning with the reordering of the particle arrays, the int2 pair
//! list and the per-particle references, and the contact history carried over a rebuild
//! (kernels in `cuda/scan.cu` and `cuda/neighbor.cu`). The evaluation of the listed pairs is in
//! [`super::pair_contacts`].

use super::error::{CudaError, HaloError};
use super::exchange::ExchangedHistory;
use super::gpu::Gpu;
use super::launch::{cfg, ptr, zeros};
use super::layout::{GridParams, HISTORY_WIDTH, PairSearchParams, staged_planes_bytes};
use super::pair_list::{PairList, list_bytes, staging_batch};
use super::particles::DeviceParticles;
use super::walls::WallStage;
use crate::neighbor::SlotList;
use cudarc::driver::CudaSlice;

/// Plane-count buckets of the lean pair passes for the enumeration's limit `enum_planes`: counts
/// 0..=enum_planes (`PD_PLANE_BUCKETS`).
pub(super) fn plane_buckets(enum_planes: usize) -> usize {
    enum_planes + 1
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

/// The pairs of one build ([`PairStage::listed_pairs`]): how many, how many of them are of two
/// owned particles (listed first), the pairs as `int2`, and their CSR offsets by particle
/// (`None` where a decomposed run's two ranges make none).
struct ListedPairs {
    np: usize,
    n_interior: usize,
    pairs: CudaSlice<i32>,
    offset: Option<CudaSlice<u32>>,
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
        let history = self.history_before_build(gpu, p)?;
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
        let ListedPairs {
            np,
            n_interior,
            pairs,
            offset,
        } = Self::listed_pairs(gpu, p, &source, cell_start.as_ref(), skin, decomposed)?;
        let spheres = gpu.config.spheres;
        let staged_bytes = staged_planes_bytes(gpu.config.precision, gpu.config.enum_planes);
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

    /// The history of the current list (or the one uploaded from the host) in the numbering
    /// before a build: its rows by particle with each pair's partner id, or none yet.
    fn history_before_build(
        &mut self,
        gpu: &Gpu,
        p: &DeviceParticles,
    ) -> Result<HistorySource, CudaError> {
        let (st, k, n) = (&gpu.stream, &gpu.k, p.n);
        Ok(match (self.pending_history.take(), self.list.take()) {
            (Some(h), _) => h,
            (None, Some(old)) => {
                let Some(old_offset) = old.offset else {
                    return Err(HaloError::MissingHistory.into());
                };
                let mut partner = zeros::<u64>(st, old.n)?;
                let npi = old.n as i32;
                // SAFETY: `partner` holds a value per pair of the old list.
                unsafe {
                    k.history_partners(st, cfg(old.n), &npi, &old.pairs, &p.id, &mut partner)?;
                }
                HistorySource::Rows {
                    offset: old_offset,
                    partner,
                    spring: old.spring,
                }
            }
            (None, None) => HistorySource::Rows {
                offset: zeros::<u32>(st, n + 1)?,
                partner: zeros::<u64>(st, 1)?,
                spring: zeros::<f64>(st, HISTORY_WIDTH)?,
            },
        })
    }

    /// The pairs of a build, from the host's list or counted, prefix-summed and filled on the
    /// device (`cell_start` the binned cells, `None` for a host list). A decomposed run lists
    /// the pairs of two owned particles first and those with a ghost after them, so the first
    /// part can be evaluated while the halo is in flight.
    fn listed_pairs(
        gpu: &Gpu,
        p: &DeviceParticles,
        source: &ListSource,
        cell_start: Option<&CudaSlice<u32>>,
        skin: f64,
        decomposed: bool,
    ) -> Result<ListedPairs, CudaError> {
        let st = &gpu.stream;
        if let ListSource::Host { list, .. } = source {
            let np = list.pairs.len();
            let flat: &[i32] = list.pairs.as_flattened();
            let pairs = if np > 0 {
                st.clone_htod(flat)?
            } else {
                zeros::<i32>(st, 2)?
            };
            return Ok(ListedPairs {
                np,
                n_interior: np,
                pairs,
                offset: Some(st.clone_htod(&list.offset)?),
            });
        }
        let (grid, cell_start) = (device_grid(source), cell_start.expect("binned"));
        if decomposed {
            let (n1, p1, _) = list_pairs(gpu, p, 1, cell_start, grid, skin)?;
            let (n2, p2, _) = list_pairs(gpu, p, 2, cell_start, grid, skin)?;
            let np = n1 + n2;
            let mut pairs = zeros::<i32>(st, 2 * np)?;
            if n1 > 0 {
                st.memcpy_dtod(&p1.slice(0..2 * n1), &mut pairs.slice_mut(0..2 * n1))?;
            }
            if n2 > 0 {
                st.memcpy_dtod(&p2.slice(0..2 * n2), &mut pairs.slice_mut(2 * n1..2 * np))?;
            }
            // Pairs of one particle are in two ranges now, so the list is no CSR by particle:
            // this run's history comes up from the host at every rebuild instead.
            Ok(ListedPairs {
                np,
                n_interior: n1,
                pairs,
                offset: None,
            })
        } else {
            let (np, pairs, offset) = list_pairs(gpu, p, 0, cell_start, grid, skin)?;
            Ok(ListedPairs {
                np,
                n_interior: np,
                pairs,
                offset: Some(offset),
            })
        }
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
        let staged_bytes = staged_planes_bytes(gpu.config.precision, gpu.config.enum_planes);
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
            bucket_count: zeros::<u32>(&st, plane_buckets(gpu.config.enum_planes))?,
            bucket_fill: zeros::<u32>(&st, plane_buckets(gpu.config.enum_planes))?,
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
