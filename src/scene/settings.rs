//! The resolved settings of each run-wide section (parallel, simulation, guard, neighbor list,
//! domain, output) and the per-pair contact table, as the [`super::Scene`] holds them.

use super::*;

/// How subdomains are laid out over the ranks (`[parallel] decomposition`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decomposition {
    /// Recursive coordinate bisection, recomputed when the load is imbalanced.
    Rcb,
    /// A fixed Cartesian grid: ranks per axis, or `None` to choose from the domain's shape.
    Grid(Option<[u32; 3]>),
}

/// What recursive bisection balances (`[parallel] weight`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BalanceWeight {
    /// Owned particles per rank.
    Count,
    /// Measured seconds of force evaluation per rank, spread over its particles.
    Cost,
}

/// `[parallel]`, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParallelSettings {
    pub decomposition: Decomposition,
    pub weight: BalanceWeight,
    /// Rebalance when max load / mean load exceeds this.
    pub imbalance_threshold: f64,
    /// Neighbour-list rebuilds between load checks.
    pub balance_interval: u64,
}

impl Default for ParallelSettings {
    fn default() -> Self {
        ParallelSettings {
            decomposition: Decomposition::Rcb,
            weight: BalanceWeight::Count,
            imbalance_threshold: 1.2,
            balance_interval: 1,
        }
    }
}

/// `[simulation]`, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulationSettings {
    /// Time step rule.
    pub dt: TimeStep,
    /// Simulated end time (s).
    pub end_time: f64,
    /// Seed of all random choices.
    pub seed: u64,
    /// Neighbour-list settings.
    pub neighbor: NeighborSettings,
    /// Stability guard settings.
    pub guard: GuardSettings,
    /// How a face contact's elastic force is sampled over a step (`face_window`).
    pub face_window: crate::contact::FaceWindow,
}

/// `[simulation.guard]`, resolved (`crate::stability`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuardSettings {
    /// Whether speeds and overlaps are checked (finiteness always is).
    pub enabled: bool,
    /// Largest overlap volume of a contact, as a fraction of the smaller particle's volume.
    pub max_overlap: f64,
    /// Largest `|v| + |ω| R` (m/s), when given.
    pub max_speed: Option<f64>,
    /// Multiple of the scene's speed scale that bounds the speed otherwise.
    pub speed_factor: f64,
}

impl GuardSettings {
    /// Default largest overlap: a tenth of the smaller particle's volume.
    pub const MAX_OVERLAP: f64 = 0.1;
    /// Default speed bound: ten times the scene's speed scale.
    pub const SPEED_FACTOR: f64 = 10.0;
}

impl Default for GuardSettings {
    fn default() -> Self {
        GuardSettings {
            enabled: true,
            max_overlap: Self::MAX_OVERLAP,
            max_speed: None,
            speed_factor: Self::SPEED_FACTOR,
        }
    }
}

/// `simulation.dt_fraction` when neither `dt` nor `dt_fraction` is given: the largest fraction
/// of the critical step at which every reference case of `polydem bench accuracy` is within
/// 1 % of its reference and no elastic face impact gains more than 1e-3 of its energy
/// (docs/accuracy.md).
pub const DEFAULT_DT_FRACTION: f64 = 0.025;

/// How the time step is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TimeStep {
    /// This step (s).
    Fixed(f64),
    /// This fraction of the Rayleigh step ([`critical_time_step`]).
    FractionOfCritical(f64),
}

/// `[simulation.neighbor]`, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeighborSettings {
    /// Verlet skin, an absolute length (m); default 0.1 × the largest circumscribed diameter.
    pub skin: f64,
    /// Who builds the neighbour list (docs/design.md §7).
    pub mode: NeighborMode,
    /// The skin of the lists `hybrid` (and `auto` when it runs hybrid) builds, on the host
    /// from a snapshot and on the device when the host's list is stale (m); at least `skin`,
    /// default 2 × `skin` (docs/design.md §7).
    pub hybrid_skin: f64,
}

/// `simulation.neighbor.mode` (and `--neighbor-mode`, which overrides it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum NeighborMode {
    /// Measure the others while running and use the fastest (GPU backend).
    Auto,
    /// Lists built on the GPU.
    Gpu,
    /// Lists built on the host from the device's positions and uploaded (the hybrid seed's
    /// sequential mode).
    Cpu,
    /// The host pre-builds the next list from a snapshot while the GPU steps (the hybrid
    /// seed's parallel mode).
    Hybrid,
}

impl NeighborMode {
    /// The mode's name in scene files, logs and summaries.
    pub fn name(self) -> &'static str {
        match self {
            NeighborMode::Auto => "auto",
            NeighborMode::Gpu => "gpu",
            NeighborMode::Cpu => "cpu",
            NeighborMode::Hybrid => "hybrid",
        }
    }
}

/// `[domain]`, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Domain {
    /// Lower corner (m).
    pub min: Vector3<f64>,
    /// Upper corner (m).
    pub max: Vector3<f64>,
    /// Periodic along x, y, z.
    pub periodic: [bool; 3],
    /// What a particle that leaves through a closed face does (`domain.on_leaving`).
    pub on_leaving: LeavingDomain,
}

/// What a particle whose centroid leaves the domain through a closed (non-periodic) face does
/// (`domain.on_leaving`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LeavingDomain {
    /// The run stops with [`crate::pipeline::SimulationError::LeftDomain`] before the particle
    /// is removed: a particle lost through a wall or a closed face is a fault of the scene.
    #[default]
    Error,
    /// The particle is removed (an outflow): counted in `summary.json` and the log.
    Remove,
}

/// Which output formats are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputFormats {
    /// VTU/PVTU/PVD frames.
    pub vtu: bool,
    /// Per-particle CSV frames.
    pub csv: bool,
}

/// `[output]`, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputSettings {
    /// Output directory (resolved against the scene file's directory).
    pub dir: PathBuf,
    /// Seconds between frames; `None`: no frames.
    pub frame_interval: Option<f64>,
    /// Frame formats.
    pub formats: OutputFormats,
    /// Per-particle fields (a subset of [`OUTPUT_FIELDS`], in the order given).
    pub fields: Vec<String>,
    /// Seconds between checkpoints; `None`: none.
    pub checkpoint_interval: Option<f64>,
    /// Seconds between rows of the energy/contacts/wall-force CSV series; default the frame
    /// interval, else 100 time steps.
    pub series_interval: f64,
    /// Steps between progress log lines.
    pub log_interval_steps: u64,
    /// Periodic checkpoints kept, the newest (`latest.ckpt` and the checkpoints of a stop are
    /// always kept); `None`: all.
    pub checkpoint_keep: Option<u64>,
}

/// Contact parameters for every pair of materials, symmetric.
#[derive(Clone, Debug, PartialEq)]
pub struct PairTable {
    n: usize,
    entries: Vec<Option<PairParameters>>,
}

impl PairTable {
    /// An empty table for `n` materials.
    pub fn new(n: usize) -> Self {
        PairTable {
            n,
            entries: vec![None; n * n],
        }
    }

    /// Number of materials.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are no materials.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Sets the parameters of `(m1, m2)` and `(m2, m1)`; out-of-range indices are ignored.
    pub fn set(&mut self, m1: usize, m2: usize, p: PairParameters) {
        if m1 < self.n && m2 < self.n {
            self.entries[m1 * self.n + m2] = Some(p);
            self.entries[m2 * self.n + m1] = Some(p);
        }
    }

    /// Whether some given pair has rolling friction (μ_r > 0): the CUDA kernels compile the
    /// rolling couple in (`PD_ROLLING_FRICTION`).
    pub fn any_rolling_friction(&self) -> bool {
        self.entries
            .iter()
            .flatten()
            .any(|p| p.rolling_friction > 0.0)
    }

    /// Whether some given pair has friction (μ > 0): the tangential history is needed.
    pub fn any_friction(&self) -> bool {
        self.entries.iter().flatten().any(|p| p.friction > 0.0)
    }

    /// The parameters of `(m1, m2)` if given.
    pub fn try_get(&self, m1: usize, m2: usize) -> Option<PairParameters> {
        if m1 < self.n && m2 < self.n {
            self.entries[m1 * self.n + m2]
        } else {
            None
        }
    }

    /// The parameters of `(m1, m2)` (symmetric). Validation guarantees every pair that can
    /// meet is present; for a pair that cannot meet (say two wall materials) this returns
    /// [`PairTable::ABSENT`], which no contact of a validated scene uses.
    pub fn get(&self, m1: usize, m2: usize) -> PairParameters {
        self.try_get(m1, m2).unwrap_or(Self::ABSENT)
    }

    /// Returned by [`PairTable::get`] for pairs not given: elastic and frictionless.
    pub const ABSENT: PairParameters = PairParameters {
        restitution: 1.0,
        friction: 0.0,
        rolling_friction: 0.0,
    };
}
