//! Stage 2 on the GPU: who builds the pair list, per `[simulation.neighbor] mode`
//! (docs/design.md §7; the hybrid CPU–GPU seed, Skorych & Dosta, docs/design.md §10).
//!
//! - `gpu`: the device bins, sorts and searches ([`super::pairs`]).
//! - `cpu`: the seed's sequential mode (its Fig. 1A): at a rebuild the host takes the device's
//!   positions, builds the list on rayon threads ([`build_slot_list`]) and uploads it; the GPU
//!   waits.
//! - `hybrid`: the seed's parallel mode (its Fig. 1B). When some particle has moved
//!   `max((S − s)/2, S/4)` from the current list's reference (`kick_drift`'s `snapshot`
//!   flag; `s` the skin, `S` the hybrid skin), the host takes a snapshot of the positions and
//!   builds the next list with the skin `S` on a thread of its own while the GPU keeps
//!   stepping (B4, B5). When the current list expires, the GPU waits for the host list if it
//!   is not ready (B8), then checks on the device that no particle has moved more than `S/2`
//!   from the snapshot (seed Eq. 2, B10: every pair that can touch is then in the list) and
//!   takes it; if one has, the device builds the list itself (with `S`), so a missed contact
//!   can never happen. The enlarged skin gives the snapshot's list the same remaining reach
//!   when it is taken as a fresh device list: the host has a whole list lifetime to build it
//!   (`S = 2s`), where the seed's `S = s` halves the GPU's stretch per list (its Eq. 6).
//! - `auto`: rounds of trials, each a few list lifetimes long, by wall-clock seconds per
//!   step with the builds included. A round measures `gpu` while a probe times one host
//!   build in the background (the seed's τ_CPU; probes are rationed to about 1 % of the
//!   run's time, the first after a second); `hybrid` is tried only when the host builds
//!   a list in less than 0.8 of the GPU's stretch per list (else its lists come too late) and
//!   the device's build is at least 2 % of that stretch (else there is nothing to gain), `cpu`
//!   only when the host builds faster than the device, and `gpu` once more after them, so
//!   that a scene whose cost drifts favours neither. A trial more than 10 % slower than `gpu`
//!   ends early. The fastest runs until the next round, 64 lifetimes later, each gap twice the
//!   last (up to 4096): the seed's q changes during a run. Auto's `hybrid` never waits: a
//!   late host list is dropped and the device builds.
//!
//! Every list holds every pair that can touch while it is used, and nothing else about a
//! list reaches the trajectory (neighbor::slot_list), so every mode steps bit for bit like
//! `gpu`. A decomposed run rebuilds through the host's exchange, whose device build follows
//! the migration; there every mode builds on the device (docs/design.md §7).

mod auto;

use super::error::CudaError;
use super::gpu::Gpu;
use super::launch::{cfg, zeros};
use super::layout::GridParams;
use super::pairs::ListSource;
use super::particles::DeviceParticles;
use crate::neighbor::{Bounds, Builder, NeighborReport, Reach, SlotList, Switch, build_slot_list};
use crate::scene::{NeighborMode, Scene};
use auto::Auto;
use cudarc::driver::CudaSlice;
use std::thread::JoinHandle;
use std::time::Instant;

/// The device's slots as a host build needs them (the seed's B4): positions, bounding radii and
/// global ids.
struct HostSlots {
    x: Vec<f64>,
    r: Vec<f64>,
    id: Vec<u64>,
    n: usize,
}

impl HostSlots {
    /// Copies `positions` (the particles' or a snapshot of them) with `p`'s radii and ids.
    fn copy(gpu: &Gpu, p: &DeviceParticles, positions: &CudaSlice<f64>) -> Result<Self, CudaError> {
        let st = &gpu.stream;
        Ok(HostSlots {
            x: st.clone_dtoh(positions)?,
            r: st.clone_dtoh(&p.radius)?,
            id: st.clone_dtoh(&p.id)?,
            n: p.n,
        })
    }

    /// The slot list of `reach`, built here (rayon).
    fn build(&self, bounds: &Bounds, reach: Reach) -> SlotList {
        let n = self.n;
        build_slot_list(&self.x[..3 * n], &self.r[..n], &self.id[..n], bounds, reach)
    }

    /// The slot list of `reach`, built on a thread of its own named `name`.
    fn spawn(
        self,
        name: &str,
        bounds: Bounds,
        reach: Reach,
    ) -> Result<JoinHandle<SlotList>, CudaError> {
        std::thread::Builder::new()
            .name(name.into())
            .spawn(move || self.build(&bounds, reach))
            .map_err(CudaError::PrebuildThread)
    }
}

/// A host build in flight: the thread, and the snapshot it builds from.
struct Prebuild {
    /// The pair stage's generation when the snapshot was taken: a build or an upload since
    /// renumbered the slots the host list names.
    generation: u64,
    /// The positions it builds from, on the device (the validity check's reference).
    snapshot: CudaSlice<f64>,
    thread: JoinHandle<SlotList>,
}

/// A list interval: from the start of one build to the start of the next.
struct Interval {
    builder: Builder,
    start: Instant,
    step: u64,
    /// Seconds of its build, as the GPU saw it.
    build: f64,
}

/// Stage 2's builder choice and its bookkeeping (see the module docs).
pub(super) struct ListBuilder {
    /// The builder of the next list.
    builder: Builder,
    /// The reaches of lists with the scene's skin and its hybrid skin (their cutoffs the
    /// scene's, as the device grids').
    reach: Reach,
    hybrid_reach: Reach,
    bounds: Bounds,
    /// The device grids for lists of the skin and the hybrid skin.
    grid: GridParams,
    hybrid_grid: GridParams,
    pending: Option<Prebuild>,
    auto: Option<Auto>,
    interval: Option<Interval>,
    /// The consistency check's reach is zero: every host list is stale (a test's way to force
    /// the device fallback).
    force_stale: bool,
    flag: Option<CudaSlice<u32>>,
    report: NeighborReport,
    /// Sums for the report's means: host builds timed, device builds, GPU stretches.
    tau_cpu: (f64, u64),
    tau_dev: (f64, u64),
    tau_gpu: (f64, u64),
}

impl ListBuilder {
    pub(super) fn new(scene: &Scene, grid: GridParams, decomposed: bool, particles: usize) -> Self {
        let n = &scene.simulation.neighbor;
        let bounds = Bounds {
            min: scene.domain.min,
            max: scene.domain.max,
            periodic: scene.domain.periodic,
        };
        let hybrid_cutoff = scene.cutoff_with_skin(n.hybrid_skin);
        let builder = match (decomposed, n.mode) {
            (true, _) | (_, NeighborMode::Gpu | NeighborMode::Auto) => Builder::Gpu,
            (false, NeighborMode::Cpu) => Builder::Cpu,
            (false, NeighborMode::Hybrid) => Builder::Hybrid,
        };
        ListBuilder {
            builder,
            reach: Reach {
                skin: n.skin,
                cutoff: scene.cutoff(),
            },
            hybrid_reach: Reach {
                skin: n.hybrid_skin,
                cutoff: hybrid_cutoff,
            },
            bounds,
            grid,
            hybrid_grid: GridParams::new(&bounds, hybrid_cutoff, 4 * particles.max(1)),
            pending: None,
            auto: (n.mode == NeighborMode::Auto && !decomposed).then(Auto::new),
            interval: None,
            force_stale: false,
            flag: None,
            report: NeighborReport {
                mode: n.mode.name().into(),
                builder: builder.name().into(),
                ..NeighborReport::default()
            },
            tau_cpu: (0.0, 0),
            tau_dev: (0.0, 0),
            tau_gpu: (0.0, 0),
        }
    }

    /// Makes every host list fail the consistency check, so that each is replaced by a
    /// device build (tests of the fallback).
    pub(super) fn force_stale(&mut self, on: bool) {
        self.force_stale = on;
    }

    /// How far a particle may move from the current list's reference before the next host
    /// build's snapshot is due (`kick_drift`'s `snapshot` flag); infinite when none is wanted.
    pub(super) fn snapshot_distance(&self) -> f64 {
        if self.builder == Builder::Hybrid && self.pending.is_none() {
            (0.5 * (self.hybrid_reach.skin - self.reach.skin)).max(0.25 * self.hybrid_reach.skin)
        } else {
            f64::INFINITY
        }
    }

    /// The seed's B4–B5: copies the positions (with the radii and ids) of the current slots,
    /// keeps the positions on the device as the check's reference, and starts the host build
    /// of the next list on a thread of its own. `generation`: the pair stage's.
    pub(super) fn start_prebuild(
        &mut self,
        gpu: &Gpu,
        p: &DeviceParticles,
        generation: u64,
    ) -> Result<(), CudaError> {
        if self.pending.is_some() || self.builder != Builder::Hybrid {
            return Ok(());
        }
        let snapshot = gpu.stream.clone_dtod(&p.position)?;
        let slots = HostSlots::copy(gpu, p, &snapshot)?;
        let thread = slots.spawn("polydem-prebuild", self.bounds, self.hybrid_reach)?;
        self.pending = Some(Prebuild {
            generation,
            snapshot,
            thread,
        });
        Ok(())
    }

    /// The start of a build at `step`: closes the list interval that ends here (its GPU
    /// stretch, and `auto`'s measurement, which may change the builder).
    pub(super) fn begin_build(&mut self, step: u64) {
        let now = Instant::now();
        if let Some(iv) = self.interval.take() {
            let total = now.duration_since(iv.start).as_secs_f64();
            self.tau_gpu.0 += (total - iv.build).max(0.0);
            self.tau_gpu.1 += 1;
            let steps = step.saturating_sub(iv.step);
            self.auto_interval(iv.builder, total, steps, step);
        }
        self.interval = Some(Interval {
            builder: self.builder,
            start: now,
            step,
            build: 0.0,
        });
    }

    /// The end of the build begun by [`ListBuilder::begin_build`].
    pub(super) fn end_build(&mut self) {
        if let Some(iv) = &mut self.interval {
            iv.build = iv.start.elapsed().as_secs_f64();
        }
    }

    /// Where the next list comes from, by the current builder: the device (`Device`), or a
    /// host list with the snapshot it was built from. `p`: the particles now; `generation`:
    /// the pair stage's.
    pub(super) fn source(
        &mut self,
        gpu: &Gpu,
        p: &DeviceParticles,
        generation: u64,
    ) -> Result<Option<(SlotList, CudaSlice<f64>)>, CudaError> {
        let pending = self.pending.take();
        if p.n == 0 {
            return Ok(None);
        }
        match self.builder {
            Builder::Gpu => Ok(None),
            Builder::Cpu => {
                let snapshot = gpu.stream.clone_dtod(&p.position)?;
                let t0 = Instant::now();
                let list = HostSlots::copy(gpu, p, &snapshot)?.build(&self.bounds, self.reach);
                self.report.host_wait_s += t0.elapsed().as_secs_f64();
                self.tau_cpu.0 += list.seconds;
                self.tau_cpu.1 += 1;
                Ok(Some((list, snapshot)))
            }
            Builder::Hybrid => {
                let Some(pre) = pending else {
                    return Ok(None);
                };
                if pre.generation != generation {
                    return Ok(None);
                }
                if !pre.thread.is_finished() && self.auto.is_some() {
                    // `auto` never waits: the device builds and the late list is dropped
                    // (its thread finishes on its own).
                    self.report.late_host_lists += 1;
                    return Ok(None);
                }
                let t0 = Instant::now();
                let list = pre.thread.join().map_err(|_| CudaError::PrebuildPanicked)?;
                self.report.host_wait_s += t0.elapsed().as_secs_f64();
                self.tau_cpu.0 += list.seconds;
                self.tau_cpu.1 += 1;
                if list.order.len() != p.n || !self.consistent(gpu, p, &pre.snapshot)? {
                    self.report.stale_host_lists += 1;
                    return Ok(None);
                }
                Ok(Some((list, pre.snapshot)))
            }
        }
    }

    /// The seed's B10 on the device: no particle moved more than half the hybrid skin from
    /// `snapshot` (Eq. 2), so the list built from it holds every pair that can touch now.
    fn consistent(
        &mut self,
        gpu: &Gpu,
        p: &DeviceParticles,
        snapshot: &CudaSlice<f64>,
    ) -> Result<bool, CudaError> {
        let st = &gpu.stream;
        let flag = match &mut self.flag {
            Some(f) => f,
            None => self.flag.insert(zeros::<u32>(st, 1)?),
        };
        st.memset_zeros(flag)?;
        let half = if self.force_stale {
            0.0
        } else {
            0.5 * self.hybrid_reach.skin
        };
        let n = p.n as i32;
        // SAFETY: both position buffers hold 3n values, `flag` one.
        unsafe {
            gpu.k.moved_beyond(
                st,
                cfg(p.n),
                &n,
                &p.position,
                snapshot,
                &gpu.grid,
                &half,
                flag,
            )?
        };
        let mut out = [0u32];
        st.memcpy_dtoh(flag, &mut out)?;
        Ok(out[0] == 0)
    }

    /// The device build's skin and grid for the current builder (`hybrid` lists keep the
    /// hybrid skin, so that the next snapshot comes at the same point).
    pub(super) fn device_source(&self) -> ListSource<'static> {
        if self.builder == Builder::Hybrid {
            ListSource::Device {
                skin: self.hybrid_reach.skin,
                grid: self.hybrid_grid,
            }
        } else {
            ListSource::Device {
                skin: self.reach.skin,
                grid: self.grid,
            }
        }
    }

    /// Counts a finished build and its GPU seconds.
    pub(super) fn count_build(&mut self, host: bool, seconds: f64) {
        if host {
            self.report.host_builds += 1;
        } else {
            self.report.device_builds += 1;
            self.tau_dev.0 += seconds;
            self.tau_dev.1 += 1;
        }
    }

    /// `auto`: after a device build, the round's probe of the host's build time (see
    /// [`Auto`]), from the positions the device just built from.
    pub(super) fn after_build(&mut self, gpu: &Gpu, p: &DeviceParticles) -> Result<(), CudaError> {
        let Some(auto) = self.auto.as_mut() else {
            return Ok(());
        };
        if self.builder != Builder::Gpu || p.n == 0 || !auto.probe_due() {
            return Ok(());
        }
        let slots = HostSlots::copy(gpu, p, &p.position)?;
        auto.start_probe(slots.spawn("polydem-probe", self.bounds, self.hybrid_reach)?);
        Ok(())
    }

    /// `auto`: a list interval of `builder` took `seconds` over `steps`; picks the builder of
    /// the list that the build at `step` makes ([`Auto::interval`]).
    fn auto_interval(&mut self, builder: Builder, seconds: f64, steps: u64, step: u64) {
        let mean = |(s, k): (f64, u64)| (k > 0).then(|| s / k as f64);
        let tau_dev = mean(self.tau_dev);
        let Some(auto) = self.auto.as_mut() else {
            return;
        };
        if let Some(seconds) = auto.finished_probe() {
            self.tau_cpu.0 += seconds;
            self.tau_cpu.1 += 1;
        }
        let switch = auto.interval(self.builder, builder, seconds, steps, step, tau_dev);
        self.report.measured_s_per_step = auto.measured();
        if let Some((next, reason)) = switch {
            tracing::info!(
                "neighbor mode auto: {} → {} at step {step} ({reason})",
                self.builder.name(),
                next.name()
            );
            self.report.switches.push(Switch {
                step,
                from: self.builder,
                to: next,
                reason,
            });
            if next != Builder::Hybrid {
                self.pending = None;
            }
            self.builder = next;
        }
    }

    /// The report so far.
    pub(super) fn report(&self) -> NeighborReport {
        let mut r = self.report.clone();
        r.builder = self.builder.name().into();
        let mean = |(s, k): (f64, u64)| (k > 0).then(|| s / k as f64);
        r.tau_cpu_s = mean(self.tau_cpu);
        r.tau_build_gpu_s = mean(self.tau_dev);
        r.tau_gpu_s = mean(self.tau_gpu);
        r.q = match (r.tau_cpu_s, r.tau_gpu_s) {
            (Some(c), Some(g)) if g > 0.0 => Some(c / g),
            _ => None,
        };
        r
    }
}
