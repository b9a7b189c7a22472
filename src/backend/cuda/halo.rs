//! A decomposed run's rank on the GPU (docs/design.md §6): the GPU twin of [`crate::domain::halo`].
//!
//! The rank's owned particles and its ghosts share the device arrays (a `ghost` flag per slot,
//! carried through the list build's reordering); pairs of two ghosts are not listed, ghosts are
//! not integrated. Each step the motion of the outer-region particles the neighbours need is
//! packed on the device (`cuda/halo.cu: pack_motion`), copied to a pinned host buffer, sent
//! with MPI, and the received motion goes up through a second pinned buffer into the ghost
//! slots (`unpack_motion`): only the halo crosses the bus. The pair list holds the pairs of two
//! owned particles first; they are evaluated while the halo is in flight (the host waits for
//! the packed copy alone and does the MPI exchange meanwhile), the pairs with a ghost after it.
//! At neighbour-list rebuilds (decided by all ranks together) the state makes a round trip
//! through the host, where migration, load balancing and the choice of ghosts run as on the CPU
//! backend ([`Simulation`]'s exchange); or, with `POLYDEM_GPU_EXCHANGE=device`, these run on the
//! host from the centroids alone while the state stays on the device ([`super::exchange`]).
//! Either way the ghosts follow the owned particles in the device arrays.
//!
//! [`Simulation`]: crate::pipeline::Simulation

use super::error::{CudaError, HaloError};
use super::gpu::Gpu;
use super::launch::{cfg, zeros};
use super::particles::DeviceParticles;
use crate::domain::Parallel;
use cudarc::driver::{CudaEvent, CudaSlice, PinnedHostSlice};
use std::time::Instant;

/// Doubles of one motion record (`cuda/halo.cu: PD_MOTION_DOUBLES`): the motion and the
/// contact count.
const MOTION: usize = 14;

/// A decomposed run's halo on the device: the buffers of the current plan (from one rebuild
/// to the next), and whether this step's refresh is still due.
#[derive(Default)]
pub(super) struct HaloStage {
    /// `None` outside a decomposed run, and from an upload to the next list build.
    buffers: Option<HaloBuffers>,
    /// The ghosts await this step's halo refresh (set by the exchange, done by the forces).
    pub(super) due: bool,
}

/// The halo's device-side index lists and staging buffers, valid from one rebuild to the next.
struct HaloBuffers {
    /// Device slots of the owned particles sent: neighbour by neighbour in the plan's order,
    /// then this rank's own periodic images.
    send_slots: CudaSlice<u32>,
    /// Records sent to each neighbour (plan order), then the self-image count.
    send_counts: Vec<usize>,
    /// Device slots of the ghosts, in the order their records arrive.
    ghost_slots: CudaSlice<u32>,
    n_ghosts: usize,
    send_device: CudaSlice<f64>,
    recv_device: CudaSlice<f64>,
    send_host: PinnedHostSlice<f64>,
    recv_host: PinnedHostSlice<f64>,
    /// Recorded after the packed copy to `send_host`, and after the upload from `recv_host`:
    /// cudarc's event tracking is off (`CudaSimulation::new`), so it records no events of its
    /// own on pinned buffers, and the host waits on these before touching them.
    sent: Option<CudaEvent>,
    received: Option<CudaEvent>,
}

impl HaloStage {
    /// Drops the buffers of the last plan (an upload: the next list build sets up new ones).
    pub(super) fn reset(&mut self) {
        self.buffers = None;
    }

    /// After a list build of a decomposed run: the device slots of the plan's particles and of
    /// the ghosts, from the build's reordering (`order[k]` = upload index now at slot `k`),
    /// and staging buffers sized for them.
    pub(super) fn setup(
        &mut self,
        gpu: &Gpu,
        n: usize,
        par: &Parallel,
        order: &CudaSlice<u32>,
    ) -> Result<(), CudaError> {
        let st = gpu.stream.clone();
        let order = st.clone_dtoh(order)?;
        let mut slot = vec![0u32; n];
        for (k, &o) in order.iter().take(n).enumerate() {
            slot[o as usize] = k as u32;
        }
        let owned = n - par.ghosts.particles.len();
        let plan = &par.plan;
        let mut sends: Vec<u32> = Vec::with_capacity(plan.sent() + plan.self_images.len());
        let mut send_counts = Vec::with_capacity(plan.sends.len() + 1);
        for list in plan.sends.iter().chain(std::iter::once(&plan.self_images)) {
            sends.extend(list.iter().map(|(i, _)| slot[*i as usize]));
            send_counts.push(list.len());
        }
        let n_ghosts = n - owned;
        let ghosts: Vec<u32> = (owned..n).map(|g| slot[g]).collect();
        let pad = |mut v: Vec<u32>| {
            if v.is_empty() {
                v.push(0);
            }
            v
        };
        let ctx = st.context().clone();
        let n_send = sends.len();
        // SAFETY: pinned buffers of plain f64, written by the copies below before being read.
        let (send_host, recv_host) = unsafe {
            (
                ctx.alloc_pinned::<f64>((MOTION * n_send).max(1))?,
                ctx.alloc_pinned::<f64>((MOTION * n_ghosts).max(1))?,
            )
        };
        self.buffers = Some(HaloBuffers {
            send_slots: st.clone_htod(&pad(sends))?,
            send_counts,
            ghost_slots: st.clone_htod(&pad(ghosts))?,
            n_ghosts,
            send_device: zeros::<f64>(&st, MOTION * n_send)?,
            recv_device: zeros::<f64>(&st, MOTION * n_ghosts)?,
            send_host,
            recv_host,
            sent: None,
            received: None,
        });
        Ok(())
    }

    /// Stage 1 between rebuilds, first half: the motion of this rank's outer-region particles
    /// packed on the device and its copy to the pinned buffer queued (the stream goes on with
    /// the pairs of owned particles meanwhile).
    pub(super) fn start(&mut self, gpu: &Gpu, p: &DeviceParticles) -> Result<(), CudaError> {
        let Some(h) = self.buffers.as_mut() else {
            return Ok(());
        };
        let n_send: usize = h.send_counts.iter().sum();
        if n_send == 0 {
            return Ok(());
        }
        let st = &gpu.stream;
        let nsi = n_send as i32;
        // SAFETY: the slots are below n and `send_device` holds 14 doubles per slot.
        unsafe {
            gpu.k.pack_motion(
                st,
                cfg(n_send),
                &nsi,
                &h.send_slots,
                &p.position,
                &p.velocity,
                &p.orientation,
                &p.angular_velocity,
                &p.contacts,
                &mut h.send_device,
            )?;
        }
        // Asynchronous into pinned memory: the host waits for this copy alone.
        st.memcpy_dtoh(&h.send_device, &mut h.send_host)?;
        h.sent = Some(st.record_event(None)?);
        Ok(())
    }

    /// Second half: waits for the packed motion, exchanges it with the neighbours by MPI, and
    /// queues the upload of what arrived and its unpacking into the ghost slots (after the
    /// work already queued on the stream).
    pub(super) fn finish(
        &mut self,
        gpu: &Gpu,
        p: &mut DeviceParticles,
        par: &mut Parallel,
    ) -> Result<(), CudaError> {
        let Some(h) = self.buffers.as_mut() else {
            return Ok(());
        };
        let t0 = Instant::now();
        let st = &gpu.stream;
        let n_send: usize = h.send_counts.iter().sum();
        // Waits for the copy alone, not for the pair kernel queued after it.
        if let Some(e) = h.sent.take() {
            e.synchronize()?;
        }
        let staged = h.send_host.as_slice()?;
        let mut at = 0;
        let mut sends = Vec::with_capacity(par.plan.neighbours.len());
        for (&r, &c) in par.plan.neighbours.iter().zip(&h.send_counts) {
            sends.push((r, f64_bytes(&staged[MOTION * at..MOTION * (at + c)])));
            at += c;
        }
        let own_images = f64_bytes(&staged[MOTION * at..MOTION * n_send]);
        let received = par.comm.neighbor_exchange(&sends, &par.plan.neighbours);
        // The last step's upload from this buffer is done (the step ends synchronised; the
        // event makes it explicit).
        if let Some(e) = h.received.take() {
            e.synchronize()?;
        }
        let incoming = h.recv_host.as_mut_slice()?;
        let mut k = 0; // doubles written
        for buf in received.iter().chain(std::iter::once(&own_images)) {
            let m = buf.len() / 8;
            if k + m <= incoming.len() {
                bytes_into_f64(buf, &mut incoming[k..k + m]);
            }
            k += m;
        }
        if k != MOTION * h.n_ghosts {
            return Err(HaloError::MotionCount {
                rank: par.rank(),
                values: k,
                ghosts: h.n_ghosts,
            }
            .into());
        }
        if h.n_ghosts > 0 {
            st.memcpy_htod(&h.recv_host, &mut h.recv_device)?;
            h.received = Some(st.record_event(None)?);
            let ngi = h.n_ghosts as i32;
            // SAFETY: the ghost slots are below n and `recv_device` holds 14 doubles per ghost.
            unsafe {
                gpu.k.unpack_motion(
                    st,
                    cfg(h.n_ghosts),
                    &ngi,
                    &h.ghost_slots,
                    &h.recv_device,
                    &mut p.position,
                    &mut p.velocity,
                    &mut p.orientation,
                    &mut p.angular_velocity,
                    &mut p.contacts,
                )?;
            }
        }
        par.timers.halo += t0.elapsed().as_secs_f64();
        Ok(())
    }
}

/// The doubles' bytes as MPI sends them: little-endian IEEE-754 bits, as
/// [`crate::domain::pack::f64s`] writes them (a plain copy on little-endian machines).
fn f64_bytes(x: &[f64]) -> Vec<u8> {
    if cfg!(target_endian = "little") {
        // SAFETY: any f64 is 8 initialised bytes; the view lives only for the copy.
        unsafe { std::slice::from_raw_parts(x.as_ptr().cast::<u8>(), 8 * x.len()) }.to_vec()
    } else {
        crate::domain::pack::f64s(x)
    }
}

/// Fills `out` from the little-endian bytes of `f64_bytes` (`bytes.len() == 8 · out.len()`).
fn bytes_into_f64(bytes: &[u8], out: &mut [f64]) {
    if cfg!(target_endian = "little") {
        // SAFETY: `out` is 8 · len writable bytes, every bit pattern is a valid f64.
        unsafe { std::slice::from_raw_parts_mut(out.as_mut_ptr().cast::<u8>(), 8 * out.len()) }
            .copy_from_slice(bytes);
    } else {
        for (o, v) in out.iter_mut().zip(crate::domain::pack::read_f64s(bytes)) {
            *o = v;
        }
    }
}
