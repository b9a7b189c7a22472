//! What every stage of the GPU step shares: the context, the streams, the kernels, the scene's
//! kernel configuration and constants (grid, skin, material table), the geometry error word,
//! and the exclusive scan that the list builds use (`cuda/scan.cu`).

use super::error::CudaError;
use super::kernels::KernelConfig;
use super::launch::Kernels;
use super::layout::{GridParams, PairMaterial};
use cudarc::driver::sys::CUevent_flags;
use cudarc::driver::{CudaContext, CudaEvent, CudaSlice, CudaStream, LaunchConfig};
use std::sync::Arc;

/// Elements per block of `scan.cu` (its PD_SCAN_BLOCK).
const SCAN_BLOCK: usize = 1024;

/// The stream on which the walls' facet overlaps run alongside the pair kernels of the main
/// stream, with the two events that order it: after the main stream's poses, before its wall
/// sums (`CudaSimulation::forces`).
pub(super) struct WallStream {
    pub(super) stream: Arc<CudaStream>,
    /// Recorded on the main stream once the walls' states and the list are queued.
    pub(super) poses_ready: CudaEvent,
    /// Recorded on the wall stream after the facet overlaps.
    pub(super) overlaps_done: CudaEvent,
}

/// The device, its streams and kernels, and the scene's constants every stage reads.
pub(super) struct Gpu {
    pub(super) _ctx: Arc<CudaContext>,
    /// The main stream: every kernel but the walls' facet overlaps.
    pub(super) stream: Arc<CudaStream>,
    pub(super) wall_stream: WallStream,
    pub(super) k: Kernels,
    pub(super) config: KernelConfig,
    /// The domain box and the neighbour grid.
    pub(super) grid: GridParams,
    /// The neighbour list's skin.
    pub(super) skin: f64,
    /// Contact parameters per pair of materials (`n_materials²`).
    pub(super) materials: CudaSlice<PairMaterial>,
    /// The geometry error word of the pair and wall kernels (`report_error` of
    /// cuda/contact.cu: a 64-bit key in the first two values) and the stability guard's deep
    /// contact (the third).
    pub(super) error: CudaSlice<u32>,
    /// The stage boundaries of a step's force evaluation, timed on the device.
    pub(super) clock: StageClock,
}

/// The device's time per stage of the force evaluation without a host wait per stage: events
/// recorded on the main stream at the stage boundaries (before the pairs, after them, after
/// the walls, after the reduction), read once the step's error word has been copied back,
/// which waits for all of them. A wait per stage cost the step a round trip each (the host
/// waits, then the device waits for the next launch), which a small scene pays at every step.
pub(super) struct StageClock {
    marks: [CudaEvent; 4],
}

impl StageClock {
    pub(super) fn new(ctx: &Arc<CudaContext>) -> Result<Self, CudaError> {
        let timed = || ctx.new_event(Some(CUevent_flags::CU_EVENT_DEFAULT));
        Ok(StageClock {
            marks: [timed()?, timed()?, timed()?, timed()?],
        })
    }

    /// Records boundary `k` (0 ..= 3) after the work queued so far on `stream`.
    pub(super) fn mark(&self, k: usize, stream: &CudaStream) -> Result<(), CudaError> {
        self.marks[k].record(stream)?;
        Ok(())
    }

    /// Seconds between consecutive boundaries: pairs, walls, reduction (waits for the last).
    pub(super) fn spans(&self) -> Result<[f64; 3], CudaError> {
        let span = |a: usize| -> Result<f64, CudaError> {
            Ok(f64::from(self.marks[a].elapsed_ms(&self.marks[a + 1])?) * 1e-3)
        };
        Ok([span(0)?, span(1)?, span(2)?])
    }
}

impl Gpu {
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
        // SAFETY: buffers hold m (out, input) and `blocks` (sums) elements.
        unsafe {
            self.k
                .scan_blocks(&self.stream, lc, &mi, input, out, &mut sums)?;
        }
        if blocks > 1 {
            let mut scanned = self.stream.alloc_zeros::<u32>(blocks)?;
            self.scan_inplace(&sums, blocks, &mut scanned)?;
            // SAFETY: as above.
            unsafe { self.k.scan_add(&self.stream, lc, &mi, out, &scanned)? };
        }
        Ok(())
    }

    /// Prints the pair kernels' per-phase clock totals so far (a profiling build,
    /// `POLYDEM_PHASE_CLOCKS`): thread-cycles summed over all pairs, from `clock64()` at the
    /// phase boundaries of `cuda/pair.cuh` and `cuda/contact.cu`.
    pub(super) fn report_phase_clocks(&self) -> Result<(), CudaError> {
        const PHASES: [&str; 16] = [
            "broad phase and cached axis",
            "planes placed",
            "planes reaching the other ball",
            "faces set aside",
            "Chebyshev centre",
            "proof of intersection",
            "planes moved to the centre",
            "overlap (faces and their sums)",
            "contact law",
            "body inside the other (contained check)",
            "",
            "pairs evaluated (count)",
            "pairs needing GJK (count)",
            "  of which the faces (enumeration, or dual hull)",
            "  of which volume, centroid, S and moment",
            "",
        ];
        let view = self.k.contact.get_global("pd_clk", &self.stream)?;
        // SAFETY: `pd_clk` is `unsigned long long[16]` in cuda/overlap.cuh (PD_PHASE_CLOCKS).
        let typed = unsafe { view.transmute::<u64>(PHASES.len()) }.ok_or(CudaError::Symbol {
            name: "pd_clk",
            expected: PHASES.len(),
        })?;
        let clocks = self.stream.clone_dtoh(&typed)?;
        let lines: Vec<String> = PHASES
            .iter()
            .zip(&clocks)
            .filter(|(name, _)| !name.is_empty())
            .map(|(name, c)| format!("{name}: {c}"))
            .collect();
        eprintln!("pair phase clocks: {}", lines.join("; "));
        Ok(())
    }
}
