//! The communicator the domain decomposition talks through (docs/design.md §6): [`SerialComm`] for
//! one rank, [`MpiComm`] over rsmpi when built with the `mpi` feature.
//!
//! Every message is a byte buffer packed by [`super::pack`] (floats as their raw bits), so the
//! trait has no generic methods and both implementations move exactly the same bytes. Sums are
//! formed by gathering every rank's contribution and adding them in rank order: the result is
//! bitwise the same on every rank and in every run, which an MPI reduction does not promise.

/// Point-to-point and collective operations on byte buffers among the ranks of one run.
pub trait Comm: Send + Sync {
    /// This rank, `0..size()`.
    fn rank(&self) -> usize;
    /// Number of ranks.
    fn size(&self) -> usize;
    /// Waits until every rank has called it.
    fn barrier(&self);
    /// Every rank's `local`, in rank order, on every rank.
    fn all_gather(&self, local: &[u8]) -> Vec<Vec<u8>>;
    /// Sends `sends[r]` to rank `r` (an empty buffer for none) and returns what each rank sent
    /// here, in rank order.
    fn all_to_all(&self, sends: &[Vec<u8>]) -> Vec<Vec<u8>>;
    /// Sends `sends[k].1` to rank `sends[k].0` and receives one buffer from each rank of `from`
    /// (in that order). Both sides must name each other: used for the halo exchange with a
    /// rank's neighbours, where the neighbour relation is symmetric.
    fn neighbor_exchange(&self, sends: &[(usize, Vec<u8>)], from: &[usize]) -> Vec<Vec<u8>>;
    /// Rank `root`'s `data` on every rank.
    fn broadcast(&self, data: &mut Vec<u8>, root: usize);
    /// Ends every rank of the run with exit status `code` (a rank that failed alone must not
    /// leave the others waiting in a collective).
    fn abort(&self, code: i32) -> !;

    /// Element-wise sums over ranks, added in rank order (bitwise reproducible).
    fn sum_f64(&self, x: &[f64]) -> Vec<f64> {
        let parts = self.all_gather(&super::pack::f64s(x));
        let mut out = vec![0.0; x.len()];
        for p in parts {
            for (o, v) in out.iter_mut().zip(super::pack::read_f64s(&p)) {
                *o += v;
            }
        }
        out
    }

    /// Element-wise sums over ranks of counters.
    fn sum_u64(&self, x: &[u64]) -> Vec<u64> {
        let parts = self.all_gather(&super::pack::u64s(x));
        let mut out = vec![0u64; x.len()];
        for p in parts {
            for (o, v) in out.iter_mut().zip(super::pack::read_u64s(&p)) {
                *o += v;
            }
        }
        out
    }

    /// Whether `b` holds on some rank.
    fn any(&self, b: bool) -> bool {
        self.sum_u64(&[u64::from(b)])[0] > 0
    }
}

/// The communicator of a single-rank run: collectives return the local data.
#[derive(Clone, Copy, Debug, Default)]
pub struct SerialComm;

impl Comm for SerialComm {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn barrier(&self) {}
    fn all_gather(&self, local: &[u8]) -> Vec<Vec<u8>> {
        vec![local.to_vec()]
    }
    fn all_to_all(&self, sends: &[Vec<u8>]) -> Vec<Vec<u8>> {
        vec![sends.first().cloned().unwrap_or_default()]
    }
    fn neighbor_exchange(&self, _sends: &[(usize, Vec<u8>)], from: &[usize]) -> Vec<Vec<u8>> {
        // A single rank has no neighbours (its own periodic images never go through here).
        vec![Vec::new(); from.len()]
    }
    fn broadcast(&self, _data: &mut Vec<u8>, _root: usize) {}
    fn abort(&self, code: i32) -> ! {
        std::process::exit(code)
    }
}

#[cfg(feature = "mpi")]
pub use mpi_comm::MpiComm;

#[cfg(feature = "mpi")]
mod mpi_comm {
    use super::Comm;
    use mpi::Count;
    use mpi::datatype::PartitionMut;
    use mpi::topology::SimpleCommunicator;
    use mpi::traits::*;

    /// Tag of halo messages.
    const HALO_TAG: i32 = 17;

    /// MPI_COMM_WORLD through rsmpi. Only the thread that created it calls MPI (rayon workers
    /// never do), so `MPI_THREAD_FUNNELED` suffices.
    pub struct MpiComm {
        world: SimpleCommunicator,
        // Finalizes MPI when dropped; kept last so the communicator goes first.
        _universe: mpi::environment::Universe,
    }

    // SAFETY: rsmpi's handles are plain MPI handles; polydem calls MPI only from the main
    // thread (Funneled), the bounds only let the communicator sit inside `Arc<dyn Comm>`.
    unsafe impl Send for MpiComm {}
    unsafe impl Sync for MpiComm {}

    impl MpiComm {
        /// Initializes MPI; `None` if it was initialized before.
        pub fn init() -> Option<Self> {
            let (universe, _) =
                mpi::initialize_with_threading(mpi::environment::Threading::Funneled)?;
            Some(MpiComm {
                world: universe.world(),
                _universe: universe,
            })
        }

        fn counts_displs(counts: &[u64]) -> (Vec<Count>, Vec<Count>, usize) {
            let c: Vec<Count> = counts.iter().map(|&n| n as Count).collect();
            let mut d = Vec::with_capacity(c.len());
            let mut total = 0usize;
            for &n in &c {
                d.push(total as Count);
                total += n as usize;
            }
            (c, d, total)
        }

        /// Bytes one rank passes to or takes from one other rank in one round of a collective:
        /// MPI counts and displacements are 32-bit, so a round moves at most 2³¹ − 1 bytes in
        /// all (a checkpoint of 1e7 particles gathered on rank 0 is several rounds).
        fn round_limit(ranks: usize) -> u64 {
            // POLYDEM_MPI_ROUND_BYTES lowers it, so that tests can drive small runs through
            // many rounds.
            let set = crate::tuning::Tuning::get().mpi_round_bytes;
            let most = (i32::MAX as u64 / ranks.max(1) as u64).clamp(1, 1 << 30);
            set.map_or(most, |b| b.min(most))
        }

        /// Rounds needed for `largest` bytes (at least one, so empty collectives still meet).
        fn rounds(largest: u64, limit: u64) -> u64 {
            largest.div_ceil(limit).max(1)
        }

        /// (start, length) of round `round` of a buffer of `len` bytes.
        fn part(len: u64, round: u64, limit: u64) -> (u64, u64) {
            let from = (round * limit).min(len);
            (from, (len - from).min(limit))
        }

        /// `data` in a heap buffer of capacity ≥ 1: the address of an empty Rust slice is 0x1,
        /// which Open MPI takes for `MPI_IN_PLACE` and then rejects the call.
        fn heap(data: &[u8]) -> Vec<u8> {
            let mut v = Vec::with_capacity(data.len().max(1));
            v.extend_from_slice(data);
            v
        }

        fn split(buf: Vec<u8>, counts: &[Count]) -> Vec<Vec<u8>> {
            let mut out = Vec::with_capacity(counts.len());
            let mut at = 0usize;
            for &n in counts {
                out.push(buf[at..at + n as usize].to_vec());
                at += n as usize;
            }
            out
        }
    }

    impl Comm for MpiComm {
        fn rank(&self) -> usize {
            self.world.rank() as usize
        }
        fn size(&self) -> usize {
            self.world.size() as usize
        }
        fn barrier(&self) {
            self.world.barrier();
        }
        fn all_gather(&self, local: &[u8]) -> Vec<Vec<u8>> {
            let n = self.size();
            let mut counts = vec![0u64; n];
            self.world
                .all_gather_into(&(local.len() as u64), &mut counts[..]);
            let limit = Self::round_limit(n);
            let rounds = Self::rounds(counts.iter().copied().max().unwrap_or(0), limit);
            let mut out: Vec<Vec<u8>> = counts
                .iter()
                .map(|&c| Vec::with_capacity(c as usize))
                .collect();
            for round in 0..rounds {
                let part = |len: u64| Self::part(len, round, limit);
                let c: Vec<u64> = counts.iter().map(|&l| part(l).1).collect();
                let (c, d, total) = Self::counts_displs(&c);
                let (from, len) = part(local.len() as u64);
                let mine = Self::heap(&local[from as usize..(from + len) as usize]);
                let mut buf = vec![0u8; total.max(1)];
                {
                    let mut recv = PartitionMut::new(&mut buf[..], &c[..], &d[..]);
                    self.world.all_gather_varcount_into(&mine[..], &mut recv);
                }
                for (o, piece) in out.iter_mut().zip(Self::split(buf, &c)) {
                    o.extend_from_slice(&piece);
                }
            }
            out
        }
        fn all_to_all(&self, sends: &[Vec<u8>]) -> Vec<Vec<u8>> {
            let n = self.size();
            assert_eq!(sends.len(), n, "all_to_all needs one buffer per rank");
            let send_counts: Vec<u64> = sends.iter().map(|s| s.len() as u64).collect();
            let mut recv_counts = vec![0u64; n];
            self.world
                .all_to_all_into(&send_counts[..], &mut recv_counts[..]);
            let limit = Self::round_limit(n);
            // Rounds agree on every rank: the largest buffer any rank sends anywhere.
            let mut largest = vec![0u64; n];
            self.world.all_gather_into(
                &send_counts.iter().copied().max().unwrap_or(0),
                &mut largest[..],
            );
            let rounds = Self::rounds(largest.into_iter().max().unwrap_or(0), limit);
            let mut out: Vec<Vec<u8>> = recv_counts
                .iter()
                .map(|&c| Vec::with_capacity(c as usize))
                .collect();
            for round in 0..rounds {
                let part = |len: u64| Self::part(len, round, limit);
                let sc: Vec<u64> = send_counts.iter().map(|&l| part(l).1).collect();
                let rc: Vec<u64> = recv_counts.iter().map(|&l| part(l).1).collect();
                let (sc, sd, _) = Self::counts_displs(&sc);
                let (rc, rd, total) = Self::counts_displs(&rc);
                let mut flat = Vec::with_capacity(sd.last().map_or(0, |&x| x as usize) + 1);
                for s in sends {
                    let (from, len) = part(s.len() as u64);
                    flat.extend_from_slice(&s[from as usize..(from + len) as usize]);
                }
                let flat = Self::heap(&flat);
                let mut buf = vec![0u8; total.max(1)];
                {
                    let send = mpi::datatype::Partition::new(&flat[..], &sc[..], &sd[..]);
                    let mut recv = PartitionMut::new(&mut buf[..], &rc[..], &rd[..]);
                    self.world.all_to_all_varcount_into(&send, &mut recv);
                }
                for (o, piece) in out.iter_mut().zip(Self::split(buf, &rc)) {
                    o.extend_from_slice(&piece);
                }
            }
            out
        }
        fn neighbor_exchange(&self, sends: &[(usize, Vec<u8>)], from: &[usize]) -> Vec<Vec<u8>> {
            let mut out = Vec::with_capacity(from.len());
            let bufs: Vec<Vec<u8>> = sends.iter().map(|(_, b)| Self::heap(b)).collect();
            mpi::request::scope(|scope| {
                let requests: Vec<_> = sends
                    .iter()
                    .zip(&bufs)
                    .map(|((r, _), buf)| {
                        self.world
                            .process_at_rank(*r as i32)
                            .immediate_send_with_tag(scope, &buf[..], HALO_TAG)
                    })
                    .collect();
                for &r in from {
                    let (msg, _) = self
                        .world
                        .process_at_rank(r as i32)
                        .receive_vec_with_tag::<u8>(HALO_TAG);
                    out.push(msg);
                }
                for q in requests {
                    q.wait();
                }
            });
            out
        }
        fn broadcast(&self, data: &mut Vec<u8>, root: usize) {
            let root_process = self.world.process_at_rank(root as i32);
            let mut len = data.len() as u64;
            root_process.broadcast_into(&mut len);
            data.resize(len as usize, 0);
            if len > 0 {
                root_process.broadcast_into(&mut data[..]);
            }
        }
        fn abort(&self, code: i32) -> ! {
            self.world.abort(code)
        }
    }
}

/// Whether this process was started by an MPI launcher (mpirun, mpiexec, srun with PMI/PMIx):
/// only then is MPI initialized, so a plain `polydem run` never waits on a process manager.
/// `POLYDEM_MPI=0` or `1` overrides the guess.
pub fn launched_under_mpi() -> bool {
    if let Some(set) = crate::tuning::Tuning::get().mpi {
        return set;
    }
    [
        "OMPI_COMM_WORLD_SIZE",
        "PMI_SIZE",
        "PMI_RANK",
        "PMIX_RANK",
        "MPI_LOCALNRANKS",
        "MV2_COMM_WORLD_SIZE",
    ]
    .iter()
    .any(|k| std::env::var_os(k).is_some())
}

/// The rank's index among the ranks on its node, as the launcher reports it (`None` when it
/// does not): the GPU a rank drives is this modulo the visible GPUs (docs/design.md §6).
pub fn node_local_rank() -> Option<usize> {
    [
        "OMPI_COMM_WORLD_LOCAL_RANK",
        "MPI_LOCALRANKID",
        "SLURM_LOCALID",
        "MV2_COMM_WORLD_LOCAL_RANK",
        "PMI_LOCAL_RANK",
    ]
    .iter()
    .find_map(|k| std::env::var(k).ok()?.parse().ok())
}
