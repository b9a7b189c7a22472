//! Stage 2 on the GPU, host side: the exclusive scans, binning with the reordering of the
//! particle arrays, the int2 pair list and the per-particle references, and the contact
//! history carried over a rebuild (kernels in `cuda/scan.cu` and `cuda/neighbor.cu`).

use super::layout::{HISTORY_WIDTH, staged_planes_bytes};
use super::simulation::{
    CudaError, CudaSimulation, DevicePairs, HistorySource, PLANE_BUCKETS, ParticleView, cfg, ptr,
    zeros,
};
use cudarc::driver::{CudaSlice, LaunchConfig, PushKernelArg};

/// Elements per block of `scan.cu` (its PD_SCAN_BLOCK).
const SCAN_BLOCK: usize = 1024;

impl CudaSimulation {
    /// Exclusive prefix sum of `input[..len]` into `out[..len + 1]` (out[len] = total), with
    /// `scan.cu`; returns the total.
    pub(super) fn scan(
        &self,
        input: &CudaSlice<u32>,
        len: usize,
        out: &mut CudaSlice<u32>,
    ) -> Result<u32, CudaError> {
        // Scan len + 1 elements, the last read as 0 (scan_blocks zero-fills past n only for the
        // padding of the last block, so a copy with a trailing zero is scanned).
        let m = len + 1;
        let mut padded = self.stream.alloc_zeros::<u32>(m)?;
        if len > 0 {
            self.stream
                .memcpy_dtod(&input.slice(0..len), &mut padded.slice_mut(0..len))?;
        }
        self.scan_inplace(&padded, m, out)?;
        let mut total = [0u32; 1];
        self.stream
            .memcpy_dtoh(&out.slice(len..len + 1), &mut total)?;
        Ok(total[0])
    }

    /// Exclusive scan of `input[..m]` into `out[..m]`.
    pub(super) fn scan_inplace(
        &self,
        input: &CudaSlice<u32>,
        m: usize,
        out: &mut CudaSlice<u32>,
    ) -> Result<(), CudaError> {
        let blocks = m.div_ceil(SCAN_BLOCK).max(1);
        let mut sums = self.stream.alloc_zeros::<u32>(blocks)?;
        let lc = LaunchConfig {
            grid_dim: (blocks as u32, 1, 1),
            block_dim: (SCAN_BLOCK as u32, 1, 1),
            shared_mem_bytes: 0,
        };
        let mi = m as i32;
        let f = self.k.get("scan_blocks");
        // SAFETY: argument types and counts match the kernel; buffers hold m (out, input) and
        // `blocks` (sums) elements.
        unsafe {
            self.stream
                .launch_builder(f)
                .arg(&mi)
                .arg(input)
                .arg(&mut *out)
                .arg(&mut sums)
                .launch(lc)?;
        }
        if blocks > 1 {
            let mut scanned = self.stream.alloc_zeros::<u32>(blocks)?;
            self.scan_inplace(&sums, blocks, &mut scanned)?;
            let f = self.k.get("scan_add");
            // SAFETY: as above.
            unsafe {
                self.stream
                    .launch_builder(f)
                    .arg(&mi)
                    .arg(&mut *out)
                    .arg(&scanned)
                    .launch(lc)?;
            }
        }
        Ok(())
    }

    pub(super) fn particle_view(&self) -> ParticleView {
        let st = &self.stream;
        let p = &self.p;
        ParticleView {
            ptrs: [
                ptr(&p.position, st),
                ptr(&p.velocity, st),
                ptr(&p.angular_velocity, st),
                ptr(&p.orientation, st),
                ptr(&p.mass, st),
                ptr(&p.inertia, st),
                ptr(&p.scale, st),
                ptr(&p.radius, st),
                ptr(&p.cn, st),
                ptr(&p.ct, st),
                ptr(&p.tmpl, st),
                ptr(&p.material, st),
            ],
        }
    }

    /// Stage 2: bins, reorders the particle arrays by cell, builds the pair list and the
    /// per-particle references, and carries the contact history over.
    pub(super) fn build_pairs(&mut self) -> Result<(), CudaError> {
        let st = self.stream.clone();
        let n = self.n;
        let ni = n as i32;
        // History of the current list (or the one uploaded from the host), in the numbering
        // before this build.
        let history = match (self.pending_history.take(), self.pairs.take()) {
            (Some(h), _) => h,
            (None, Some(old)) => {
                let Some(old_offset) = old.offset else {
                    return Err(CudaError::Halo(
                        "a decomposed run's pair list was rebuilt without the host's history"
                            .into(),
                    ));
                };
                let mut partner = zeros::<u64>(&st, old.n)?;
                let npi = old.n as i32;
                // SAFETY: argument types match `history_partners`.
                unsafe {
                    st.launch_builder(self.k.get("history_partners"))
                        .arg(&npi)
                        .arg(&old.pairs)
                        .arg(&self.p.id)
                        .arg(&mut partner)
                        .launch(cfg(old.n))?;
                }
                HistorySource {
                    offset: old_offset,
                    partner,
                    // The latest springs: `forces` swapped them into `spring_in`.
                    spring: old.spring_in,
                }
            }
            (None, None) => HistorySource {
                offset: zeros::<u32>(&st, n + 1)?,
                partner: zeros::<u64>(&st, 1)?,
                spring: zeros::<f64>(&st, HISTORY_WIDTH)?,
            },
        };
        // Bin and sort by cell (global id within a cell).
        let cells = self.grid.cells();
        let mut cell = zeros::<u32>(&st, n)?;
        let mut cell_count = zeros::<u32>(&st, cells)?;
        let g = self.grid;
        // SAFETY (all launches below): argument lists match the kernels' signatures in cuda/,
        // and every buffer holds the element counts the kernels index.
        unsafe {
            st.launch_builder(self.k.get("bin_particles"))
                .arg(&ni)
                .arg(&self.p.position)
                .arg(&g)
                .arg(&mut cell)
                .arg(&mut cell_count)
                .launch(cfg(n))?;
        }
        let mut cell_start = zeros::<u32>(&st, cells + 1)?;
        self.scan(&cell_count, cells, &mut cell_start)?;
        let mut fill = zeros::<u32>(&st, cells)?;
        let mut order = zeros::<u32>(&st, n)?;
        let ci = cells as i32;
        unsafe {
            st.launch_builder(self.k.get("scatter_by_cell"))
                .arg(&ni)
                .arg(&cell)
                .arg(&cell_start)
                .arg(&mut fill)
                .arg(&mut order)
                .launch(cfg(n))?;
            st.launch_builder(self.k.get("sort_cells"))
                .arg(&ci)
                .arg(&cell_start)
                .arg(&mut order)
                .arg(&self.p.id)
                .launch(cfg(cells))?;
        }
        // Reorder every particle array (and the wall springs) by `order`; the wall list names
        // particles by index, so it is built again too.
        self.gather_all(&order)?;
        if let Some(w) = &mut self.walls {
            w.list = None;
        }
        // Pairs: count, exclusive prefix sum, fill. A decomposed run lists the pairs of two
        // owned particles first and those with a ghost after them, so the first part can be
        // evaluated while the halo is in flight.
        let (np, n_interior, pairs, offset) = if self.host.parallel.is_some() {
            let (n1, p1, _) = self.list_pairs(1, &cell_start)?;
            let (n2, p2, _) = self.list_pairs(2, &cell_start)?;
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
            let (np, pairs, offset) = self.list_pairs(0, &cell_start)?;
            (np, np, pairs, Some(offset))
        };
        // References per particle, sorted by partner id.
        let npi = np as i32;
        let mut ref_count = zeros::<u32>(&st, n)?;
        unsafe {
            st.launch_builder(self.k.get("count_refs"))
                .arg(&npi)
                .arg(&pairs)
                .arg(&mut ref_count)
                .launch(cfg(np))?;
        }
        let mut ref_offset = zeros::<u32>(&st, n + 1)?;
        self.scan(&ref_count, n, &mut ref_offset)?;
        let mut ref_fill = zeros::<u32>(&st, n)?;
        let mut refs = zeros::<u32>(&st, 2 * np)?;
        unsafe {
            st.launch_builder(self.k.get("fill_refs"))
                .arg(&npi)
                .arg(&pairs)
                .arg(&ref_offset)
                .arg(&mut ref_fill)
                .arg(&mut refs)
                .launch(cfg(np))?;
            st.launch_builder(self.k.get("sort_refs"))
                .arg(&ni)
                .arg(&ref_offset)
                .arg(&mut refs)
                .arg(&pairs)
                .arg(&self.p.id)
                .launch(cfg(n))?;
        }
        // The springs of pairs that survive, found by (lower-id member, partner id).
        let mut spring_in = zeros::<f64>(&st, HISTORY_WIDTH * np)?;
        unsafe {
            st.launch_builder(self.k.get("remap_history"))
                .arg(&npi)
                .arg(&pairs)
                .arg(&self.p.id)
                .arg(&order)
                .arg(&history.offset)
                .arg(&history.partner)
                .arg(&history.spring)
                .arg(&mut spring_in)
                .launch(cfg(np))?;
        }
        let spheres = self.config.spheres;
        let staged_bytes = staged_planes_bytes(self.config.precision);
        self.pairs = Some(DevicePairs {
            n: np,
            n_interior,
            offset,
            pairs,
            axes: zeros::<f64>(&st, 3 * np)?,
            spring_in,
            spring_out: zeros::<f64>(&st, HISTORY_WIDTH * np)?,
            forces: zeros::<f64>(&st, 9 * np)?,
            energy: zeros::<f64>(&st, np)?,
            contact: zeros::<u32>(&st, np)?,
            ref_offset,
            refs,
            deferred: zeros::<u32>(&st, np)?,
            deferred_count: zeros::<u32>(&st, 1)?,
            // The two lean passes of polyhedral pairs stage planes per pair (spheres: none).
            staged: zeros::<u8>(&st, if spheres { 1 } else { np * staged_bytes })?,
            bucket: zeros::<u8>(&st, if spheres { 1 } else { np })?,
            order: zeros::<u32>(&st, if spheres { 1 } else { np })?,
            bucket_count: zeros::<u32>(&st, PLANE_BUCKETS)?,
            bucket_fill: zeros::<u32>(&st, PLANE_BUCKETS)?,
        });
        self.reference = st.clone_dtod(&self.p.position)?;
        self.rebuild = false;
        self.list_builds += 1;
        if self.host.parallel.is_some() {
            self.setup_halo(&order)?;
        }
        Ok(())
    }

    /// Count, exclusive prefix sum and fill of the pairs of `part` (0 all; in a decomposed run
    /// 1 those of two owned particles, 2 those with a ghost): their number, the int2 list and
    /// the per-particle offsets.
    fn list_pairs(
        &self,
        part: i32,
        cell_start: &CudaSlice<u32>,
    ) -> Result<(usize, CudaSlice<i32>, CudaSlice<u32>), CudaError> {
        let st = self.stream.clone();
        let n = self.n;
        let ni = n as i32;
        let g = self.grid;
        let skin = self.skin;
        let mut counts = zeros::<u32>(&st, n)?;
        // SAFETY: argument lists match `count_pairs` and `fill_pairs` of cuda/neighbor.cu; the
        // buffers hold n (particles), cells + 1 (cell_start) and the listed pairs' values.
        unsafe {
            st.launch_builder(self.k.get("count_pairs"))
                .arg(&ni)
                .arg(&self.p.position)
                .arg(&self.p.radius)
                .arg(&self.p.id)
                .arg(&self.p.ghost)
                .arg(&part)
                .arg(cell_start)
                .arg(&g)
                .arg(&skin)
                .arg(&mut counts)
                .launch(cfg(n))?;
        }
        let mut offset = zeros::<u32>(&st, n + 1)?;
        let np = self.scan(&counts, n, &mut offset)? as usize;
        let mut pairs = zeros::<i32>(&st, 2 * np)?;
        unsafe {
            st.launch_builder(self.k.get("fill_pairs"))
                .arg(&ni)
                .arg(&self.p.position)
                .arg(&self.p.radius)
                .arg(&self.p.id)
                .arg(&self.p.ghost)
                .arg(&part)
                .arg(cell_start)
                .arg(&g)
                .arg(&skin)
                .arg(&offset)
                .arg(&mut pairs)
                .launch(cfg(n))?;
        }
        Ok((np, pairs, offset))
    }

    pub(super) fn gather_all(&mut self, order: &CudaSlice<u32>) -> Result<(), CudaError> {
        let st = self.stream.clone();
        let n = self.n;
        let ni = n as i32;
        let g64 = self.k.get("gather_f64").clone();
        let gather = |src: &mut CudaSlice<f64>, width: usize| -> Result<(), CudaError> {
            let mut dst = zeros::<f64>(&st, width * n)?;
            let w = width as i32;
            // SAFETY: `gather_f64(n, width, src, dst, order)`; both buffers hold width·n values.
            unsafe {
                st.launch_builder(&g64)
                    .arg(&ni)
                    .arg(&w)
                    .arg(&*src)
                    .arg(&mut dst)
                    .arg(order)
                    .launch(cfg(n))?;
            }
            *src = dst;
            Ok(())
        };
        let p = &mut self.p;
        for (buf, w) in [
            (&mut p.scale, 1),
            (&mut p.radius, 1),
            (&mut p.cn, 1),
            (&mut p.ct, 1),
            (&mut p.mass, 1),
            (&mut p.position, 3),
            (&mut p.velocity, 3),
            (&mut p.angular_velocity, 3),
            (&mut p.orientation, 4),
            (&mut p.force, 3),
            (&mut p.torque, 3),
            (&mut p.inertia, 3),
        ] {
            gather(buf, w)?;
        }
        if let Some(w) = &mut self.walls {
            let width = HISTORY_WIDTH * w.n;
            gather(&mut w.spring_in, width)?;
        }
        let g32 = self.k.get("gather_u32").clone();
        for buf in [&mut p.tmpl, &mut p.material, &mut p.kind, &mut p.ghost] {
            let mut dst = zeros::<u32>(&st, n)?;
            // SAFETY: `gather_u32(n, src, dst, order)`.
            unsafe {
                st.launch_builder(&g32)
                    .arg(&ni)
                    .arg(&*buf)
                    .arg(&mut dst)
                    .arg(order)
                    .launch(cfg(n))?;
            }
            *buf = dst;
        }
        let mut id = zeros::<u64>(&st, n)?;
        // SAFETY: `gather_u64(n, src, dst, order)`.
        unsafe {
            st.launch_builder(self.k.get("gather_u64"))
                .arg(&ni)
                .arg(&p.id)
                .arg(&mut id)
                .arg(order)
                .launch(cfg(n))?;
        }
        p.id = id;
        Ok(())
    }
}
