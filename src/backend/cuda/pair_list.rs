//! The GPU's pair list ([`PairList`]): the int2 pairs and everything indexed by pair, what
//! it holds in device memory, and the staging batches of the lean polyhedral passes
//! ([`staging_batch`]). [`super::pairs::PairStage`] builds it; [`super::pair_contacts`]
//! evaluates it.

use super::error::CudaError;
use super::history::PairOutcomes;
use super::layout::HISTORY_WIDTH;
use cudarc::driver::{CudaSlice, CudaStream};
use std::sync::Arc;

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
    /// `layout::staged_planes_bytes` each), its plane-count bucket, the staged pairs listed bucket by
    /// bucket, and per bucket the count and the fill cursor (`pairs::plane_buckets` values each).
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
    pub(super) fn bytes(&self) -> usize {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::cuda::Precision;
    use crate::backend::cuda::layout::staged_planes_bytes;

    /// A short list is staged whole; a long one in batches that hold at most 256 MiB of staged
    /// planes, in either precision, and the list's bytes count the staging once per batch.
    #[test]
    fn long_lists_are_staged_in_batches_of_256_mib() {
        for precision in [Precision::Mixed, Precision::Double] {
            let staged = staged_planes_bytes(precision, 8);
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
        assert_eq!(staged_planes_bytes(Precision::Mixed, 8), 160);
        assert_eq!(staged_planes_bytes(Precision::Mixed, 16), 288);
        assert_eq!(staging_batch(usize::MAX, 160), 1_677_721);
    }
}
