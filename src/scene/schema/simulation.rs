//! The run-wide sections as written: `[simulation]` (with its guard and neighbor tables),
//! `[domain]`, `[parallel]` and `[output]`.

use super::Vec3;
use serde::Deserialize;

/// `[parallel]`: how the domain is split over MPI ranks (ignored on one rank).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParallelSection {
    /// `"rcb"` (recursive coordinate bisection, rebalanced) or `"grid"` (fixed Cartesian grid).
    pub decomposition: Option<DecompositionName>,
    /// Ranks per axis for `decomposition = "grid"`; their product must equal the rank count.
    pub grid: Option<[u32; 3]>,
    /// What the bisection balances: `"count"` (particles) or `"cost"` (measured step time).
    pub weight: Option<BalanceWeightName>,
    /// Rebalance when the largest rank load exceeds this multiple of the mean (> 1).
    pub imbalance_threshold: Option<f64>,
    /// Neighbour-list rebuilds between load checks (≥ 1).
    pub balance_interval: Option<u64>,
}
/// Values of `parallel.decomposition`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum DecompositionName {
    Rcb,
    Grid,
}
/// Values of `parallel.weight`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BalanceWeightName {
    Count,
    Cost,
}
/// `[simulation]`: time stepping and the random seed.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSection {
    /// Fixed time step (s); exclusive with `dt_fraction`.
    pub dt: Option<f64>,
    /// Time step as a fraction of the Rayleigh step; exclusive with `dt`.
    pub dt_fraction: Option<f64>,
    /// Simulated end time (s).
    pub end_time: f64,
    /// Seed of every random choice (insertion positions, orientations, scales).
    #[serde(default)]
    pub seed: u64,
    /// `[simulation.neighbor]`.
    #[serde(default)]
    pub neighbor: Option<NeighborSection>,
    /// `[simulation.guard]`.
    #[serde(default)]
    pub guard: Option<GuardSection>,
    /// How a face contact's force is sampled over a step: `"secant"` or `"trajectory"`.
    pub face_window: Option<FaceWindowName>,
}
/// Values of `simulation.face_window`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum FaceWindowName {
    Secant,
    Trajectory,
}
/// `[simulation.guard]`: the stability guard's bounds (`crate::stability`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GuardSection {
    /// Check speeds and overlaps (default true).
    pub enabled: Option<bool>,
    /// Largest overlap volume of a contact, as a fraction of the smaller particle's volume.
    pub max_overlap: Option<f64>,
    /// Largest `|v| + |ω| R` (m/s); default `speed_factor` × the scene's speed scale.
    pub max_speed: Option<f64>,
    /// Multiple of the scene's speed scale that bounds the speed when `max_speed` is not given.
    pub speed_factor: Option<f64>,
}
/// `[simulation.neighbor]`: neighbour-list settings.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NeighborSection {
    /// Verlet skin (m).
    pub skin: Option<f64>,
    /// Who builds the list.
    pub mode: Option<NeighborModeName>,
    /// The skin of lists the host pre-builds (m).
    pub hybrid_skin: Option<f64>,
}
/// Values of `simulation.neighbor.mode`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum NeighborModeName {
    Auto,
    Gpu,
    Cpu,
    Hybrid,
}
/// `[domain]`: the simulated box.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DomainSection {
    /// Lower corner (m).
    pub min: Vec3,
    /// Upper corner (m).
    pub max: Vec3,
    /// Periodic axes `[x, y, z]`.
    #[serde(default)]
    pub periodic: [bool; 3],
    /// What a particle leaving through a closed (non-periodic) face does: `"error"` (the
    /// default) stops the run, `"remove"` removes it and counts it.
    pub on_leaving: Option<LeavingName>,
}
/// Values of `domain.on_leaving`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum LeavingName {
    Error,
    Remove,
}
/// `[output]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    pub dir: Option<String>,
    pub frame_interval: Option<f64>,
    pub formats: Option<Vec<String>>,
    pub fields: Option<Vec<String>>,
    pub checkpoint_interval: Option<f64>,
    pub series_interval: Option<f64>,
    pub log_interval_steps: Option<u64>,
    /// Periodic checkpoints kept (the newest; ≥ 1); default all.
    pub checkpoint_keep: Option<u64>,
}
