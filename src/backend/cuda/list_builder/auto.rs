//! `auto`: the neighbour-list builder chosen by measurement while the run goes (the module
//! docs of [`super`] give the rounds, trials and probes).

use crate::neighbor::{Builder, SlotList};
use std::thread::JoinHandle;
use std::time::Instant;

/// `auto`'s state (see the module docs).
pub(super) struct Auto {
    /// Seconds per step measured per builder (its trials of the latest round).
    per_step: [Option<f64>; 3],
    /// This round's measured seconds and steps per builder.
    round: [(f64, u64); 3],
    /// This round's `gpu` intervals: seconds and count (the seed's stretch per list).
    gpu_intervals: (f64, u64),
    /// The trial under way.
    trial: Option<Trial>,
    /// The builders still to try in this round.
    queue: Vec<Builder>,
    /// The round's probe of the host's build time is due (after the next device build).
    want_probe: bool,
    /// The probe in flight: a host build from the positions of a device build, run while the
    /// GPU steps and then dropped; and its measured seconds once it has finished.
    probe: Option<JoinHandle<SlotList>>,
    probe_seconds: Option<f64>,
    /// When the last probe started, and when the builder was made: probes are rationed to
    /// about 1 % of the run's time ([`PROBE_EVERY`], [`FIRST_PROBE_S`]).
    last_probe: Option<Instant>,
    created: Instant,
    /// Intervals until the next round, and the gap after it (doubling).
    until_round: u64,
    gap: u64,
}

/// A trial: its builder, the intervals still to skip (the switch's transition) and to
/// measure, and the seconds and steps measured so far.
struct Trial {
    builder: Builder,
    skip: u32,
    left: u32,
    seconds: f64,
    steps: u64,
}

/// Intervals a trial skips after a switch, and measures.
const TRIAL_SKIP: u32 = 1;
const TRIAL_MEASURE: u32 = 3;
/// A trial of another builder ends early when it is this much slower per step than `gpu`.
const TRIAL_LOSS: f64 = 1.10;
/// Hybrid is tried only when the host builds a list in this fraction of the GPU's stretch
/// per list (else the list would be late and dropped), and when the device's build is at
/// least this fraction of that stretch (else there is nothing to gain).
const HOST_FITS: f64 = 0.8;
const BUILD_WORTH: f64 = 0.02;
/// The first probe waits for this much run time (s): a shorter run has nothing to gain.
const FIRST_PROBE_S: f64 = 1.0;
/// A probe starts at least this many times the last probe's build time after it.
const PROBE_EVERY: f64 = 100.0;
/// Intervals between the first two rounds of trials; each gap doubles, up to the last.
const FIRST_GAP: u64 = 64;
const LAST_GAP: u64 = 4096;

impl Auto {
    pub(super) fn new() -> Self {
        Auto {
            per_step: [None; 3],
            round: [(0.0, 0); 3],
            gpu_intervals: (0.0, 0),
            trial: None,
            queue: vec![Builder::Gpu],
            want_probe: true,
            probe: None,
            probe_seconds: None,
            last_probe: None,
            created: Instant::now(),
            until_round: 0,
            gap: FIRST_GAP,
        }
    }

    /// A new round: `gpu` first, a fresh probe of the host.
    fn start_round(&mut self) {
        self.queue = vec![Builder::Gpu];
        self.per_step = [None; 3];
        self.round = [(0.0, 0); 3];
        self.gpu_intervals = (0.0, 0);
        self.want_probe = true;
    }

    /// Whether a probe may start now: not before [`FIRST_PROBE_S`] of run time, and then
    /// [`PROBE_EVERY`] times the last probe's build time after it, so that probing (a host
    /// build on every core, beside the thread that drives the GPU) costs about 1 % at most.
    fn probe_allowed(&self) -> bool {
        match (self.last_probe, self.probe_seconds) {
            (None, _) => self.created.elapsed().as_secs_f64() >= FIRST_PROBE_S,
            (Some(t), Some(c)) => t.elapsed().as_secs_f64() >= PROBE_EVERY * c,
            (Some(_), None) => false,
        }
    }

    /// Whether the round's probe of the host's build time may start now: wanted, none in
    /// flight, and [`Auto::probe_allowed`].
    pub(super) fn probe_due(&self) -> bool {
        self.want_probe && self.probe.is_none() && self.probe_allowed()
    }

    /// The probe started: a host build from the positions of a device build, run while the
    /// GPU steps and then dropped.
    pub(super) fn start_probe(&mut self, thread: JoinHandle<SlotList>) {
        self.want_probe = false;
        self.last_probe = Some(Instant::now());
        self.probe = Some(thread);
    }

    /// The probe's build seconds, once its thread is done (then kept as the latest probe's).
    pub(super) fn finished_probe(&mut self) -> Option<f64> {
        if self.probe.as_ref().is_some_and(|t| t.is_finished())
            && let Some(t) = self.probe.take()
            && let Ok(list) = t.join()
        {
            self.probe_seconds = Some(list.seconds);
            return Some(list.seconds);
        }
        None
    }

    /// Seconds per step measured per builder in the latest round.
    pub(super) fn measured(&self) -> Vec<(Builder, f64)> {
        Builder::ALL
            .into_iter()
            .filter_map(|b| self.per_step[b.index()].map(|t| (b, t)))
            .collect()
    }

    /// A list interval of `builder` took `seconds` over `steps`, with `current` building now
    /// and device builds of `tau_dev` s on average: the trials and rounds of the module docs.
    /// Returns the builder of the list that the build at `step` makes, and why, when it
    /// changes.
    pub(super) fn interval(
        &mut self,
        current: Builder,
        builder: Builder,
        seconds: f64,
        steps: u64,
        step: u64,
        tau_dev: Option<f64>,
    ) -> Option<(Builder, String)> {
        let mean = |(s, k): (f64, u64)| (k > 0).then(|| s / k as f64);
        let mut note = None;
        if let Some(t) = self.trial.as_mut() {
            if builder == t.builder && steps > 0 {
                if t.skip > 0 {
                    t.skip -= 1;
                } else {
                    t.seconds += seconds;
                    t.steps += steps;
                    t.left -= 1;
                    if builder == Builder::Gpu {
                        self.gpu_intervals.0 += seconds;
                        self.gpu_intervals.1 += 1;
                    } else if let Some(g) = self.per_step[Builder::Gpu.index()]
                        && t.seconds / t.steps as f64 > TRIAL_LOSS * g
                    {
                        // Clearly slower: no need to measure it further.
                        t.left = 0;
                    }
                }
            }
            if t.left == 0 {
                let r = &mut self.round[t.builder.index()];
                r.0 += t.seconds;
                r.1 += t.steps;
                self.per_step[t.builder.index()] = Some(r.0 / r.1.max(1) as f64);
                let first_gpu = t.builder == Builder::Gpu && self.round[0].1 == t.steps;
                self.trial = None;
                if first_gpu {
                    // What else is worth a trial, from the probe and the device's builds.
                    let stretch = mean(self.gpu_intervals).unwrap_or(0.0);
                    let (fits, worth, faster) = match (self.probe_seconds, tau_dev) {
                        (Some(c), Some(d)) => {
                            (c < HOST_FITS * stretch, d >= BUILD_WORTH * stretch, c < d)
                        }
                        _ => (false, false, false),
                    };
                    if fits && worth {
                        self.queue.push(Builder::Hybrid);
                    }
                    if faster {
                        self.queue.push(Builder::Cpu);
                    }
                    if !self.queue.is_empty() {
                        self.queue.push(Builder::Gpu);
                    }
                    let fmt = |x: Option<f64>| x.map_or("unknown".into(), |x| format!("{x:.2e} s"));
                    note = Some(format!(
                        "host build {}, device build {}, GPU stretch per list {stretch:.2e} s",
                        fmt(self.probe_seconds),
                        fmt(tau_dev)
                    ));
                }
            }
        } else if self.until_round > 0 {
            self.until_round -= 1;
            if self.until_round == 0 {
                self.start_round();
            }
        }
        let mut next = current;
        let mut reason = None;
        if self.trial.is_none() && self.until_round == 0 {
            if !self.queue.is_empty() {
                let b = self.queue.remove(0);
                self.trial = Some(Trial {
                    builder: b,
                    skip: if b == current { 0 } else { TRIAL_SKIP },
                    left: TRIAL_MEASURE,
                    seconds: 0.0,
                    steps: 0,
                });
                next = b;
                reason = Some(format!("trial of {}", b.name()));
            } else {
                // The round is over: the fastest measured, until the next round.
                let measured = self.measured();
                if let Some(&(b, _)) = measured.iter().min_by(|x, y| x.1.total_cmp(&y.1)) {
                    next = b;
                    let parts: Vec<String> = measured
                        .iter()
                        .map(|(b, t)| format!("{} {t:.3e} s/step", b.name()))
                        .collect();
                    reason = Some(format!("fastest measured: {}", parts.join(", ")));
                    tracing::info!(
                        "neighbor mode auto: picks {} at step {step} ({}{})",
                        b.name(),
                        parts.join(", "),
                        note.as_deref().map_or(String::new(), |n| format!("; {n}"))
                    );
                }
                self.until_round = self.gap;
                self.gap = (2 * self.gap).min(LAST_GAP);
            }
        }
        if let Some(n) = &note
            && next != current
        {
            tracing::info!("neighbor mode auto: {n}");
        }
        (next != current).then(|| (next, reason.unwrap_or_default()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::cuda::layout::GridParams;
    use crate::backend::cuda::list_builder::ListBuilder;
    use crate::neighbor::Bounds;
    use crate::scene::test_sphere_scene;

    /// A scene of spheres with `mode` (the builder needs its skins and box only).
    fn builder(mode: &str) -> ListBuilder {
        let scene = test_sphere_scene(&format!("mode = \"{mode}\""));
        let bounds = Bounds {
            min: scene.domain.min,
            max: scene.domain.max,
            periodic: scene.domain.periodic,
        };
        let grid = GridParams::new(&bounds, scene.cutoff(), 4000);
        ListBuilder::new(&scene, grid, false, 1000)
    }

    /// Feeds `auto` list intervals of 100 steps, each builder taking its seconds per step from
    /// `cost`, with a device build of `device` s and a probe that measured `host` s; returns
    /// the builder after `intervals` intervals and the builders used, in order.
    fn drive(
        b: &mut ListBuilder,
        cost: impl Fn(Builder) -> f64,
        device: f64,
        host: f64,
        intervals: u64,
    ) -> Vec<Builder> {
        let mut used = Vec::new();
        for k in 0..intervals {
            let now = b.builder;
            used.push(now);
            if now != Builder::Cpu {
                b.count_build(false, device);
            }
            if let Some(a) = b.auto.as_mut() {
                a.probe_seconds = Some(host);
                a.want_probe = false;
            }
            b.auto_interval(now, 100.0 * cost(now), 100, 100 * (k + 1));
        }
        used
    }

    /// Hybrid 10 % faster, a host that builds in a fifth of the GPU's stretch and a device
    /// build worth 5 % of it: auto tries gpu, hybrid, gpu, then runs hybrid, and logs it.
    #[test]
    fn auto_picks_hybrid_when_it_measures_faster() {
        let mut b = builder("auto");
        let cost = |x: Builder| if x == Builder::Hybrid { 0.9e-3 } else { 1.0e-3 };
        let used = drive(&mut b, cost, 5e-3, 0.02, 40);
        assert_eq!(b.builder, Builder::Hybrid, "used {used:?}");
        let r = b.report();
        assert!(r.switches.len() >= 3, "{:?}", r.switches);
        assert_eq!(r.switches.last().unwrap().to, Builder::Hybrid);
        assert!(
            r.switches
                .last()
                .unwrap()
                .reason
                .starts_with("fastest measured")
        );
        let hybrid = r
            .measured_s_per_step
            .iter()
            .find(|m| m.0 == Builder::Hybrid);
        assert!((hybrid.unwrap().1 - 0.9e-3).abs() < 1e-12);
        // It keeps hybrid until the next round, 64 intervals after the pick (interval 12),
        // which tries gpu, hybrid and gpu again and picks hybrid again.
        let rest = drive(&mut b, cost, 5e-3, 0.02, 60);
        assert!(rest[..30].iter().all(|&x| x == Builder::Hybrid), "{rest:?}");
        assert!(rest[30..].contains(&Builder::Gpu), "{rest:?}");
        assert_eq!(b.builder, Builder::Hybrid);
    }

    /// A host build ten times the GPU's stretch per list (the spheres on the H200): hybrid is
    /// never tried, auto stays on gpu.
    #[test]
    fn auto_does_not_try_hybrid_when_the_host_cannot_keep_up() {
        let mut b = builder("auto");
        let used = drive(&mut b, |_| 1.0e-3, 5e-3, 1.0, 200);
        assert!(used.iter().all(|&x| x == Builder::Gpu), "{used:?}");
        assert!(b.report().switches.is_empty());
    }

    /// A hybrid 50 % slower than gpu: its trial ends after one measured interval (after the
    /// skipped one), and auto returns to gpu.
    #[test]
    fn a_losing_trial_ends_early() {
        let mut b = builder("auto");
        let cost = |x: Builder| if x == Builder::Hybrid { 1.5e-3 } else { 1.0e-3 };
        let used = drive(&mut b, cost, 5e-3, 0.02, 30);
        let hybrid = used.iter().filter(|&&x| x == Builder::Hybrid).count();
        assert_eq!(hybrid, 2, "{used:?}");
        assert_eq!(b.builder, Builder::Gpu);
    }

    /// Fixed modes never switch; a decomposed run builds on the device whatever the mode.
    #[test]
    fn fixed_modes_keep_their_builder() {
        for (mode, want) in [
            ("gpu", Builder::Gpu),
            ("cpu", Builder::Cpu),
            ("hybrid", Builder::Hybrid),
        ] {
            let mut b = builder(mode);
            drive(&mut b, |_| 1e-3, 5e-3, 0.02, 50);
            assert_eq!(b.builder, want);
        }
        let mut b = builder("hybrid");
        b.builder = Builder::Gpu;
        assert_eq!(b.snapshot_distance(), f64::INFINITY);
        let h = builder("hybrid");
        // Snapshot at max((S − s)/2, S/4) with S = 2s: s/2.
        assert!((h.snapshot_distance() - 0.5 * h.reach.skin).abs() < 1e-15);
    }
}
