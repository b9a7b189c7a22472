//! What built a run's pair lists (`[simulation.neighbor] mode`, docs/design.md §7): the
//! builders, `auto`'s switches, and the seed's τ_CPU, τ_GPU and q (hybrid paper Eq. 5), for
//! the log and `summary.json`.

use serde::Serialize;

/// Who builds a list.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Builder {
    /// The device (`gpu` mode).
    Gpu,
    /// The host, while the GPU waits (`cpu` mode).
    Cpu,
    /// The host from a snapshot, while the GPU steps (`hybrid` mode).
    Hybrid,
}

impl Builder {
    /// Every builder.
    pub const ALL: [Builder; 3] = [Builder::Gpu, Builder::Cpu, Builder::Hybrid];

    /// The builder's index in [`Builder::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The builder's name, as the mode of the same name.
    pub fn name(self) -> &'static str {
        match self {
            Builder::Gpu => "gpu",
            Builder::Cpu => "cpu",
            Builder::Hybrid => "hybrid",
        }
    }
}

/// A switch of `auto` from one builder to another.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Switch {
    /// The step at which the new builder builds its first list.
    pub step: u64,
    pub from: Builder,
    pub to: Builder,
    /// Why: a trial, or the measured seconds per step that decided it.
    pub reason: String,
}

/// What the list builder did over a run: `summary.json`'s `neighbor`, and the log's.
#[derive(Clone, Debug, Default, Serialize)]
pub struct NeighborReport {
    /// The scene's `mode`.
    pub mode: String,
    /// The builder in use at the end (`auto`: its last pick).
    pub builder: String,
    /// Lists built by the device (a `hybrid` fallback included).
    pub device_builds: u64,
    /// Lists built by the host and taken (`cpu` and `hybrid`).
    pub host_builds: u64,
    /// Host lists that failed the consistency check (seed Eq. 2) and were replaced by a
    /// device build.
    pub stale_host_lists: u64,
    /// Host lists `auto` did not wait for: not ready when the current list expired.
    pub late_host_lists: u64,
    /// Seconds the GPU waited for the host (`cpu`: every build; `hybrid`: late lists).
    pub host_wait_s: f64,
    /// Mean seconds of a host build (the seed's τ_CPU), of those timed.
    pub tau_cpu_s: Option<f64>,
    /// Mean seconds of a device build.
    pub tau_build_gpu_s: Option<f64>,
    /// Mean seconds the GPU steps on one list, its build excluded (the seed's τ_GPU).
    pub tau_gpu_s: Option<f64>,
    /// τ_CPU / τ_GPU (seed Eq. 5).
    pub q: Option<f64>,
    /// `auto`: the measured seconds per step of each builder tried (its last trial).
    pub measured_s_per_step: Vec<(Builder, f64)>,
    /// `auto`: its switches, in order.
    pub switches: Vec<Switch>,
}
