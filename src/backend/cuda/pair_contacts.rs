//! Stages 3–7 for the pairs of the list, host side (kernels in `cuda/contact.cu`): the
//! arguments every pair kernel reads, spheres in one pass, polyhedra in two lean passes with
//! the deferred pairs evaluated in full after them.

use super::error::CudaError;
use super::gpu::Gpu;
use super::launch::{SPHERE_PAIR_BLOCK, cfg, cfg_with, ptr};
use super::layout::{PairArgs, PairOutputs, ParticleView};
use super::pairs::PairStage;

impl PairStage {
    /// The arguments of the pair kernels for this step (the list must be built).
    pub(super) fn args(
        &self,
        gpu: &Gpu,
        view: &ParticleView,
        n_materials: i32,
        dt: f64,
        max_overlap: f64,
    ) -> PairArgs {
        let st = &gpu.stream;
        let pairs = self.list.as_ref().expect("built");
        PairArgs {
            pairs: ptr(&pairs.pairs, st),
            grid: gpu.grid,
            axes: ptr(&pairs.axes, st),
            p: *view,
            materials: ptr(&gpu.materials, st),
            n_materials,
            // One buffer, read and written in place (`PairList::spring`).
            spring_in: ptr(&pairs.spring, st),
            spring_out: ptr(&pairs.spring, st),
            out: PairOutputs {
                forces: ptr(&pairs.forces, st),
                energy: ptr(&pairs.energy, st),
                contact: ptr(&pairs.contact, st),
            },
            dt,
            max_overlap,
            error: ptr(&gpu.error, st),
        }
    }

    /// Zeroes the count of deferred pairs before this step's passes.
    pub(super) fn clear_deferred(&mut self, gpu: &Gpu) -> Result<(), CudaError> {
        let pairs = self.list.as_mut().expect("built");
        gpu.stream.memset_zeros(&mut pairs.deferred_count)?;
        Ok(())
    }

    /// Stages 3–7 for the pairs `first..last` of the list. Spheres in one pass; polyhedra in
    /// two lean passes (`pair_planes`, then the faces and the contact law in `pair_faces`, with
    /// the staged pairs listed by plane count in between by `bucket_pairs`), the pairs that need
    /// GJK or the dual hull queued for [`Self::launch_deferred`].
    pub(super) fn launch(
        &mut self,
        gpu: &Gpu,
        first: usize,
        last: usize,
        args: &PairArgs,
    ) -> Result<(), CudaError> {
        if last <= first {
            return Ok(());
        }
        let (st, k) = (&gpu.stream, &gpu.k);
        let pairs = self.list.as_mut().expect("built");
        let (fi, li) = (first as i32, last as i32);
        if gpu.config.spheres {
            // SAFETY: `args` points into buffers alive for the whole call.
            unsafe {
                k.pair_contacts(
                    st,
                    cfg_with(last - first, SPHERE_PAIR_BLOCK),
                    &fi,
                    &li,
                    args,
                )?;
            }
            return Ok(());
        }
        // The lean passes batch by batch: the staging buffers hold one batch of pairs.
        let batch = pairs.batch.max(1);
        let mut start = first;
        while start < last {
            let end = (start + batch).min(last);
            let (si, ei) = (start as i32, end as i32);
            st.memset_zeros(&mut pairs.bucket_count)?;
            st.memset_zeros(&mut pairs.bucket_fill)?;
            let lc = cfg(end - start);
            // SAFETY: `deferred` holds one slot per pair of the list; `bucket`, `order` one per
            // pair of a batch and `staged` one StagedPlanes record per pair of a batch (sizes
            // checked by static_assert), indexed from `start`; the bucket counts and fill
            // cursors plane_buckets values.
            unsafe {
                k.pair_planes(
                    st,
                    lc,
                    &si,
                    &ei,
                    args,
                    &mut pairs.deferred,
                    &mut pairs.deferred_count,
                    &mut pairs.staged,
                    &mut pairs.bucket,
                    &mut pairs.bucket_count,
                )?;
                k.bucket_pairs(
                    st,
                    lc,
                    &si,
                    &ei,
                    &pairs.bucket,
                    &pairs.bucket_count,
                    &mut pairs.bucket_fill,
                    &mut pairs.order,
                )?;
                k.pair_faces(
                    st,
                    lc,
                    &si,
                    args,
                    &pairs.order,
                    &pairs.bucket_count,
                    &pairs.staged,
                    &mut pairs.deferred,
                    &mut pairs.deferred_count,
                )?;
            }
            start = end;
        }
        Ok(())
    }

    /// The pairs queued by the pair pass, evaluated in full (GJK included). The count stays on
    /// the device: the kernel loops over it, so the grid only needs to be large enough to keep
    /// the GPU busy when many pairs are deferred. `spheres_only`: nothing is deferred.
    pub(super) fn launch_deferred(
        &self,
        gpu: &Gpu,
        args: &PairArgs,
        spheres_only: bool,
    ) -> Result<(), CudaError> {
        let pairs = self.list.as_ref().expect("built");
        if pairs.n == 0 || spheres_only {
            return Ok(());
        }
        // A sixteenth of the pairs per sweep: a dense packing defers a few per cent.
        let threads = pairs.n.div_ceil(16).max(1);
        // SAFETY: the list and its count were written by the lean passes this step.
        unsafe {
            gpu.k.pair_contacts_deferred(
                &gpu.stream,
                cfg(threads),
                args,
                &pairs.deferred,
                &pairs.deferred_count,
            )?;
        }
        Ok(())
    }
}
