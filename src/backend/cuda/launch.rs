//! The kernels of the step, by name in one table: the [`Kernel`] enum, their loading from the
//! compiled modules ([`Kernels::load`]), and one typed launch function per kernel, whose
//! parameters follow the kernel's signature in `cuda/` in order. Kernels of many parameters
//! take one `#[repr(C)]` struct of [`super::layout`] instead (`kick_drift`, `reduce_and_kick`,
//! `count_pairs`/`fill_pairs`, the pair kernels' `PairArgs`, the three wall kernels).

use super::error::CudaError;
use super::kernels::{KERNEL_FILES, KernelConfig, compile};
use super::layout::{
    GridParams, KickDriftParams, PairArgs, PairSearchParams, ReduceKickParams,
    WallCandidatesParams, WallContactsParams, WallOverlapsParams,
};
use cudarc::driver::{
    CudaContext, CudaFunction, CudaModule, CudaSlice, CudaStream, DeviceRepr, DriverError,
    LaunchConfig, PushKernelArg, ValidAsZeroBits,
};
use std::sync::Arc;

/// Threads per block of the per-particle and per-pair kernels.
pub(super) const BLOCK: u32 = 256;

/// Threads per block of the sphere pair kernel. Its 94 registers per thread allow two blocks of
/// 256 per multiprocessor (16 warps) but five of 128 (20 warps), and the kernel waits on memory,
/// so the smaller blocks are faster (measured in docs/performance.md, dense spheres). The
/// polyhedral passes keep [`BLOCK`]: their per-thread workspace lives in local memory.
pub(super) const SPHERE_PAIR_BLOCK: u32 = 128;

/// Launch configuration for `n` threads in blocks of [`BLOCK`] (see [`cfg_with`]).
pub(super) fn cfg(n: usize) -> LaunchConfig {
    cfg_with(n, BLOCK)
}

/// Launch configuration for `n` threads in blocks of `preferred`. Small launches get smaller
/// blocks, so that they still spread over the GPU's multiprocessors (a 2000-particle scene in
/// blocks of 128 would occupy 16 of a GPU's 132 multiprocessors); `POLYDEM_CUDA_BLOCK` fixes the block size
/// of every kernel instead (for tuning).
pub(super) fn cfg_with(n: usize, preferred: u32) -> LaunchConfig {
    let fixed = crate::tuning::Tuning::get().cuda_block;
    // Enough blocks for two per multiprocessor of the largest current GPUs (132 SMs).
    let block = fixed.unwrap_or(if n >= 264 * preferred as usize {
        preferred
    } else if n >= 264 * 64 {
        64
    } else {
        32
    });
    LaunchConfig {
        grid_dim: ((n as u32).div_ceil(block).max(1), 1, 1),
        block_dim: (block, 1, 1),
        shared_mem_bytes: 0,
    }
}

/// The device address of `s`, as the kernels' structs hold it.
pub(super) fn ptr<T>(s: &CudaSlice<T>, stream: &CudaStream) -> u64 {
    use cudarc::driver::DevicePtr;
    let (p, _sync) = s.device_ptr(stream);
    p
}

/// `n` zeroed values (at least one, so that every buffer has an address).
pub(super) fn zeros<T: DeviceRepr + ValidAsZeroBits>(
    st: &Arc<CudaStream>,
    n: usize,
) -> Result<CudaSlice<T>, CudaError> {
    Ok(st.alloc_zeros::<T>(n.max(1))?)
}

/// The table of kernels: per file, each kernel's [`Kernel`] variant and its typed launch
/// function (the kernel's name), with the parameters of its signature in order.
macro_rules! kernel_table {
    ($($file:literal {
        $($variant:ident $name:ident($($arg:ident: $ty:ty),* $(,)?);)*
    })*) => {
        /// A kernel of the step (`cuda/`), named once here.
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        pub(super) enum Kernel {
            $($($variant,)*)*
        }

        impl Kernel {
            /// Every kernel, in the order of the table (file by file).
            pub(super) const ALL: &'static [Kernel] = &[$($(Kernel::$variant,)*)*];

            /// The kernel's name in its `.cu` file.
            pub(super) fn name(self) -> &'static str {
                match self {
                    $($(Kernel::$variant => stringify!($name),)*)*
                }
            }

            /// The kernel file that defines it.
            pub(super) fn file(self) -> &'static str {
                match self {
                    $($(Kernel::$variant => $file,)*)*
                }
            }
        }

        impl Kernels {
            $($(
                #[doc = concat!("Launches `", stringify!($name), "` of cuda/", $file, " on `st`.")]
                ///
                /// # Safety
                /// The buffers (and the device pointers in the argument structs) must hold
                /// every element the kernel indexes for this launch configuration, and stay
                /// alive and unwritten by other streams until it completes.
                #[allow(clippy::too_many_arguments)]
                pub(super) unsafe fn $name(
                    &self,
                    st: &CudaStream,
                    cfg: LaunchConfig,
                    $($arg: $ty),*
                ) -> Result<(), DriverError> {
                    // SAFETY: the parameters are the kernel's, in its order and of its types
                    // (device pointers for pointers); the caller vouches for the sizes.
                    unsafe {
                        st.launch_builder(self.get(Kernel::$variant))
                            $(.arg($arg))*
                            .launch(cfg)?;
                    }
                    Ok(())
                }
            )*)*
        }
    };
}

kernel_table! {
    "scan.cu" {
        ScanBlocks scan_blocks(
            n: &i32,
            input: &CudaSlice<u32>,
            out: &mut CudaSlice<u32>,
            block_sums: &mut CudaSlice<u32>,
        );
        ScanAdd scan_add(n: &i32, out: &mut CudaSlice<u32>, scanned_block_sums: &CudaSlice<u32>);
    }
    "integrate.cu" {
        KickDrift kick_drift(args: &KickDriftParams);
        ReduceAndKick reduce_and_kick(args: &ReduceKickParams);
    }
    "neighbor.cu" {
        BinParticles bin_particles(
            n: &i32,
            position: &CudaSlice<f64>,
            grid: &GridParams,
            cell: &mut CudaSlice<u32>,
            cell_count: &mut CudaSlice<u32>,
        );
        ScatterByCell scatter_by_cell(
            n: &i32,
            cell: &CudaSlice<u32>,
            cell_start: &CudaSlice<u32>,
            cell_fill: &mut CudaSlice<u32>,
            order: &mut CudaSlice<u32>,
        );
        SortCells sort_cells(
            n_cells: &i32,
            cell_start: &CudaSlice<u32>,
            order: &mut CudaSlice<u32>,
            id: &CudaSlice<u64>,
        );
        GatherF64 gather_f64(
            n: &i32,
            width: &i32,
            src: &CudaSlice<f64>,
            dst: &mut CudaSlice<f64>,
            order: &CudaSlice<u32>,
        );
        GatherU64 gather_u64(
            n: &i32,
            src: &CudaSlice<u64>,
            dst: &mut CudaSlice<u64>,
            order: &CudaSlice<u32>,
        );
        GatherU32 gather_u32(
            n: &i32,
            width: &i32,
            src: &CudaSlice<u32>,
            dst: &mut CudaSlice<u32>,
            order: &CudaSlice<u32>,
        );
        CountPairs count_pairs(args: &PairSearchParams, counts: &mut CudaSlice<u32>);
        FillPairs fill_pairs(
            args: &PairSearchParams,
            pair_offset: &CudaSlice<u32>,
            pairs: &mut CudaSlice<i32>,
        );
        CountRefs count_refs(n_pairs: &i32, pairs: &CudaSlice<i32>, ref_count: &mut CudaSlice<u32>);
        FillRefs fill_refs(
            n_pairs: &i32,
            pairs: &CudaSlice<i32>,
            ref_offset: &CudaSlice<u32>,
            ref_fill: &mut CudaSlice<u32>,
            refs: &mut CudaSlice<u32>,
        );
        SortRefs sort_refs(
            n: &i32,
            ref_offset: &CudaSlice<u32>,
            refs: &mut CudaSlice<u32>,
            pairs: &CudaSlice<i32>,
            id: &CudaSlice<u64>,
        );
        HistoryPartners history_partners(
            n_pairs: &i32,
            pairs: &CudaSlice<i32>,
            id: &CudaSlice<u64>,
            partner: &mut CudaSlice<u64>,
        );
        RemapHistory remap_history(
            n_pairs: &i32,
            pairs: &CudaSlice<i32>,
            id: &CudaSlice<u64>,
            order: &CudaSlice<u32>,
            old_offset: &CudaSlice<u32>,
            old_partner: &CudaSlice<u64>,
            old_spring: &CudaSlice<f64>,
            spring: &mut CudaSlice<f64>,
        );
        RemapHistoryExchanged remap_history_exchanged(
            n_pairs: &i32,
            pairs: &CudaSlice<i32>,
            id: &CudaSlice<u64>,
            order: &CudaSlice<u32>,
            old_slot: &CudaSlice<u32>,
            old_ref_offset: &CudaSlice<u32>,
            old_refs: &CudaSlice<u32>,
            old_pairs: &CudaSlice<i32>,
            old_id: &CudaSlice<u64>,
            old_contact: &CudaSlice<u32>,
            old_spring: &CudaSlice<f64>,
            n_recv: &i32,
            recv_a: &CudaSlice<u64>,
            recv_b: &CudaSlice<u64>,
            recv_spring: &CudaSlice<f64>,
            spring: &mut CudaSlice<f64>,
        );
        MovedBeyond moved_beyond(
            n: &i32,
            position: &CudaSlice<f64>,
            reference: &CudaSlice<f64>,
            grid: &GridParams,
            half_skin: &f64,
            flag: &mut CudaSlice<u32>,
        );
    }
    "contact.cu" {
        PairContacts pair_contacts(first: &i32, last: &i32, args: &PairArgs);
        PairPlanes pair_planes(
            first: &i32,
            last: &i32,
            args: &PairArgs,
            deferred: &mut CudaSlice<u32>,
            deferred_count: &mut CudaSlice<u32>,
            staged: &mut CudaSlice<u8>,
            bucket: &mut CudaSlice<u8>,
            bucket_count: &mut CudaSlice<u32>,
        );
        BucketPairs bucket_pairs(
            first: &i32,
            last: &i32,
            bucket: &CudaSlice<u8>,
            bucket_count: &CudaSlice<u32>,
            bucket_fill: &mut CudaSlice<u32>,
            order: &mut CudaSlice<u32>,
        );
        PairFaces pair_faces(
            first: &i32,
            args: &PairArgs,
            order: &CudaSlice<u32>,
            bucket_count: &CudaSlice<u32>,
            staged: &CudaSlice<u8>,
            deferred: &mut CudaSlice<u32>,
            deferred_count: &mut CudaSlice<u32>,
        );
        PairContactsDeferred pair_contacts_deferred(
            args: &PairArgs,
            deferred: &CudaSlice<u32>,
            deferred_count: &CudaSlice<u32>,
        );
        WallCandidates wall_candidates(args: &WallCandidatesParams);
        WallFacetOverlaps wall_facet_overlaps(args: &WallOverlapsParams);
        WallContacts wall_contacts(args: &WallContactsParams);
    }
    "halo.cu" {
        PackMotion pack_motion(
            count: &i32,
            slots: &CudaSlice<u32>,
            position: &CudaSlice<f64>,
            velocity: &CudaSlice<f64>,
            orientation: &CudaSlice<f64>,
            angular_velocity: &CudaSlice<f64>,
            contacts: &CudaSlice<u32>,
            out: &mut CudaSlice<f64>,
        );
        UnpackMotion unpack_motion(
            count: &i32,
            slots: &CudaSlice<u32>,
            input: &CudaSlice<f64>,
            position: &mut CudaSlice<f64>,
            velocity: &mut CudaSlice<f64>,
            orientation: &mut CudaSlice<f64>,
            angular_velocity: &mut CudaSlice<f64>,
            contacts: &mut CudaSlice<u32>,
        );
        CountLiveRefs count_live_refs(
            count: &i32,
            slots: &CudaSlice<u32>,
            ref_offset: &CudaSlice<u32>,
            refs: &CudaSlice<u32>,
            contact: &CudaSlice<u32>,
            out: &mut CudaSlice<u32>,
        );
        PackLiveRefs pack_live_refs(
            count: &i32,
            slots: &CudaSlice<u32>,
            ref_offset: &CudaSlice<u32>,
            refs: &CudaSlice<u32>,
            pairs: &CudaSlice<i32>,
            id: &CudaSlice<u64>,
            contact: &CudaSlice<u32>,
            spring: &CudaSlice<f64>,
            row_offset: &CudaSlice<u32>,
            out_a: &mut CudaSlice<u64>,
            out_b: &mut CudaSlice<u64>,
            out_spring: &mut CudaSlice<f64>,
        );
        GatherLiveWallSprings gather_live_wall_springs(
            n: &i32,
            walls: &i32,
            source: &CudaSlice<u32>,
            contact: &CudaSlice<u32>,
            src: &CudaSlice<f64>,
            dst: &mut CudaSlice<f64>,
        );
    }
}

/// The compiled kernel files and their functions.
pub(super) struct Kernels {
    _modules: Vec<Arc<CudaModule>>,
    /// `contact.cu`'s module, whose constant and global tables the host fills (templates) and
    /// reads (phase clocks).
    pub(super) contact: Arc<CudaModule>,
    /// By [`Kernel`] (as index); `None` for a kernel not loaded (the wall kernels without walls).
    f: Vec<Option<CudaFunction>>,
}

impl Kernels {
    /// Compiles every kernel file of the step for `sm_<arch>` with `config` and loads its
    /// kernels (the wall kernels only for a scene with walls).
    pub(super) fn load(
        ctx: &Arc<CudaContext>,
        config: &KernelConfig,
        arch: u32,
    ) -> Result<Self, CudaError> {
        let mut modules = Vec::new();
        let mut f = vec![None; Kernel::ALL.len()];
        let mut contact = None;
        for &file in KERNEL_FILES {
            let ptx = compile(file, config, arch)?;
            let module = ctx.load_module(ptx)?;
            for &k in Kernel::ALL.iter().filter(|k| k.file() == file) {
                if k.name().starts_with("wall_") && !config.walls {
                    continue;
                }
                f[k as usize] = Some(module.load_function(k.name())?);
            }
            if file == "contact.cu" {
                contact = Some(module.clone());
            }
            modules.push(module);
        }
        Ok(Kernels {
            _modules: modules,
            contact: contact.expect("contact.cu is among KERNEL_FILES"),
            f,
        })
    }

    /// The function of kernel `k`.
    fn get(&self, k: Kernel) -> &CudaFunction {
        self.f[k as usize]
            .as_ref()
            .unwrap_or_else(|| panic!("kernel {} is not loaded for this scene", k.name()))
    }
}
