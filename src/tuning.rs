//! Process-wide tuning and test knobs read from `POLYDEM_*` environment variables.
//!
//! Every such variable is read here, once per process ([`Tuning::get`]), and `polydem run`
//! logs the ones set at start ([`Tuning::log`]), so that a run's log says which knobs shaped it.
//! None of them changes results but one: they choose launch shapes, caches, profiling builds
//! and the MPI start-up, or drive rare code paths in tests. `POLYDEM_MIXED_LP` changes
//! mixed-precision results within mixed precision's tolerance (an arithmetic on trial, on the
//! GPU and its CPU twin alike). A value outside what a knob allows is reported and the default
//! kept.

use std::path::PathBuf;
use std::sync::OnceLock;

/// The knobs, as read from the environment.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tuning {
    /// `POLYDEM_CUDA_BLOCK`: one block size for every kernel (32–1024, a multiple of 32)
    /// instead of the per-launch choice.
    pub cuda_block: Option<u32>,
    /// `POLYDEM_WALL_MERGE_CELLS`: most grid cells merged per particle and wall when the wall
    /// list is built (0–64; default 27), so that tests can drive every particle down the walk
    /// of the facet grid.
    pub wall_merge_cells: Option<u32>,
    /// `POLYDEM_PAIR_MAX_REGISTERS`: register cap of the lean pair kernels (24–255, or 0 for
    /// none) instead of the defaults of `backend::cuda::kernels`.
    pub pair_max_registers: Option<u32>,
    /// `POLYDEM_PHASE_CLOCKS` set: the pair kernels are built to time their phases.
    pub phase_clocks: bool,
    /// `POLYDEM_PTX_CACHE`: the PTX cache folder; `Some(None)` when set to `0` or empty (no
    /// cache), `None` when unset (the default folder).
    pub ptx_cache: Option<Option<PathBuf>>,
    /// `POLYDEM_MPI_ROUND_BYTES`: a lower bound on the bytes one collective round moves, so
    /// that tests can drive small runs through many rounds.
    pub mpi_round_bytes: Option<u64>,
    /// `POLYDEM_MPI`: `0` or `1` overrides the guess whether an MPI launcher started the
    /// process.
    pub mpi: Option<bool>,
    /// `POLYDEM_PAIR_BATCH`: pairs per batch of the GPU's lean polyhedral pair passes (a
    /// positive count) instead of as many as 256 MiB of staged planes hold; tests drive small
    /// lists through many batches with it.
    pub pair_batch: Option<u64>,
    /// `POLYDEM_GPU_EXCHANGE`: `device` keeps a decomposed GPU run's rebuilds on the device,
    /// `host` makes them the round trip of the whole rank state through the host; `None` when
    /// unset (the backend's default). Both give bitwise the same run.
    pub gpu_exchange_on_device: Option<bool>,
    /// `POLYDEM_MIXED_LP`: `f32` solves mixed precision's Chebyshev LP in f32 instead of f64
    /// (the thin pairs an f32 LP cannot resolve still go to f64 by their radius); on trial:
    /// docs/performance.md has what it was measured against. `f64` or unset: the default.
    pub mixed_lp_f32: bool,
    /// `POLYDEM_CUDA_SOURCES`: a folder whose kernel files (named as in `cuda/`) NVRTC compiles
    /// instead of the copies built into the binary, so that a kernel variant can be measured
    /// without a rebuild; a file missing there is taken from the binary. Kernel work only: the
    /// host code and the layout it shares with the kernels are the binary's.
    pub cuda_sources: Option<PathBuf>,
    /// `POLYDEM_ENUM_PLANES`: the most planes whose overlap faces come from the vertex
    /// enumeration rather than the dual hull (8–16), on the CPU and the GPU alike, in place of
    /// the scene's (`Scene::enum_planes`: 16 for templates of more than 12 faces, else 8). Results change in the last bits where a
    /// pair of 9 or more planes takes the enumeration.
    pub enum_planes: Option<u32>,
    /// `POLYDEM_ROOT`: the repository root (its `meshes/`) for `polydem bench accuracy`.
    pub root: Option<PathBuf>,
    /// `POLYDEM_PANIC_AT=RANK:STEP`: that rank of `polydem run` panics after that step, so that
    /// tests can check that a panic on one rank ends the whole job (`tests/mpi_signals.rs`).
    pub panic_at: Option<(usize, u64)>,
    /// What was set but not allowed, one line each (the default is kept).
    pub rejected: Vec<String>,
}

impl Tuning {
    /// The knobs of this process, read on first use.
    pub fn get() -> &'static Tuning {
        static TUNING: OnceLock<Tuning> = OnceLock::new();
        TUNING.get_or_init(|| Tuning::from_vars(|k| std::env::var_os(k)))
    }

    /// The knobs from `var` (the environment, or a table in tests).
    pub fn from_vars(var: impl Fn(&str) -> Option<std::ffi::OsString>) -> Tuning {
        let mut t = Tuning::default();
        let text = |k: &str| var(k).map(|v| v.to_string_lossy().into_owned());
        let mut number = |k: &str, allowed: &str, ok: &dyn Fn(u64) -> bool| -> Option<u64> {
            let v = text(k)?;
            match v.trim().parse::<u64>().ok().filter(|&n| ok(n)) {
                Some(n) => Some(n),
                None => {
                    t.rejected
                        .push(format!("{k}={v:?} is not {allowed}; the default is used"));
                    None
                }
            }
        };
        let cuda_block = number("POLYDEM_CUDA_BLOCK", "a multiple of 32 in 32-1024", &|b| {
            (32..=1024).contains(&b) && b % 32 == 0
        });
        let wall_merge_cells = number("POLYDEM_WALL_MERGE_CELLS", "0-64", &|n| n <= 64);
        let pair_max_registers = number("POLYDEM_PAIR_MAX_REGISTERS", "0 or 24-255", &|n| {
            n == 0 || (24..=255).contains(&n)
        });
        let mpi_round_bytes = number("POLYDEM_MPI_ROUND_BYTES", "a positive count", &|b| b > 0);
        let enum_planes = number("POLYDEM_ENUM_PLANES", "8-16", &|n| (8..=16).contains(&n));
        let pair_batch = number("POLYDEM_PAIR_BATCH", "a count in 1-2147483647", &|b| {
            (1..=i32::MAX as u64).contains(&b)
        });
        t.cuda_block = cuda_block.map(|b| b as u32);
        t.wall_merge_cells = wall_merge_cells.map(|n| n as u32);
        t.pair_max_registers = pair_max_registers.map(|n| n as u32);
        t.mpi_round_bytes = mpi_round_bytes;
        t.pair_batch = pair_batch;
        t.enum_planes = enum_planes.map(|n| n as u32);
        t.phase_clocks = var("POLYDEM_PHASE_CLOCKS").is_some();
        t.ptx_cache = var("POLYDEM_PTX_CACHE")
            .map(|v| (!(v.is_empty() || v == "0")).then(|| PathBuf::from(v)));
        t.mpi = match text("POLYDEM_MPI").as_deref() {
            None => None,
            Some("0") => Some(false),
            Some("1") => Some(true),
            Some(v) => {
                t.rejected.push(format!(
                    "POLYDEM_MPI={v:?} is not 0 or 1; the launcher is guessed from the environment"
                ));
                None
            }
        };
        t.gpu_exchange_on_device = match text("POLYDEM_GPU_EXCHANGE").as_deref() {
            None => None,
            Some("device") => Some(true),
            Some("host") => Some(false),
            Some(v) => {
                t.rejected.push(format!(
                    "POLYDEM_GPU_EXCHANGE={v:?} is not host or device; the default is used"
                ));
                None
            }
        };
        t.mixed_lp_f32 = match text("POLYDEM_MIXED_LP").as_deref() {
            None | Some("f64") => false,
            Some("f32") => true,
            Some(v) => {
                t.rejected.push(format!(
                    "POLYDEM_MIXED_LP={v:?} is not f32 or f64; the default (f64) is used"
                ));
                false
            }
        };
        t.root = var("POLYDEM_ROOT").map(PathBuf::from);
        t.cuda_sources = var("POLYDEM_CUDA_SOURCES")
            .filter(|v| !v.is_empty())
            .map(PathBuf::from);
        t.panic_at = text("POLYDEM_PANIC_AT").and_then(|v| {
            let parsed = v
                .split_once(':')
                .and_then(|(r, s)| Some((r.trim().parse().ok()?, s.trim().parse().ok()?)));
            if parsed.is_none() {
                t.rejected.push(format!(
                    "POLYDEM_PANIC_AT={v:?} is not RANK:STEP (two whole numbers); no panic is made"
                ));
            }
            parsed
        });
        t
    }

    /// The knobs that are set, as `NAME=value` (empty when none is).
    pub fn set(&self) -> Vec<String> {
        let mut v = Vec::new();
        let mut put = |k: &str, x: Option<String>| {
            if let Some(x) = x {
                v.push(format!("{k}={x}"));
            }
        };
        put("POLYDEM_CUDA_BLOCK", self.cuda_block.map(|x| x.to_string()));
        put(
            "POLYDEM_WALL_MERGE_CELLS",
            self.wall_merge_cells.map(|x| x.to_string()),
        );
        put(
            "POLYDEM_PAIR_MAX_REGISTERS",
            self.pair_max_registers.map(|x| x.to_string()),
        );
        put("POLYDEM_PHASE_CLOCKS", self.phase_clocks.then(String::new));
        put(
            "POLYDEM_PTX_CACHE",
            self.ptx_cache.as_ref().map(|c| {
                c.as_ref()
                    .map_or_else(|| "0".into(), |p| p.display().to_string())
            }),
        );
        put(
            "POLYDEM_MPI_ROUND_BYTES",
            self.mpi_round_bytes.map(|x| x.to_string()),
        );
        put("POLYDEM_MPI", self.mpi.map(|x| u8::from(x).to_string()));
        put("POLYDEM_PAIR_BATCH", self.pair_batch.map(|x| x.to_string()));
        put(
            "POLYDEM_GPU_EXCHANGE",
            self.gpu_exchange_on_device
                .map(|d| if d { "device" } else { "host" }.to_string()),
        );
        put("POLYDEM_MIXED_LP", self.mixed_lp_f32.then(|| "f32".into()));
        put(
            "POLYDEM_ROOT",
            self.root.as_ref().map(|p| p.display().to_string()),
        );
        put(
            "POLYDEM_ENUM_PLANES",
            self.enum_planes.map(|x| x.to_string()),
        );
        put(
            "POLYDEM_CUDA_SOURCES",
            self.cuda_sources.as_ref().map(|p| p.display().to_string()),
        );
        put(
            "POLYDEM_PANIC_AT",
            self.panic_at.map(|(r, s)| format!("{r}:{s}")),
        );
        v
    }

    /// Logs the knobs that are set and those refused.
    pub fn log(&self) {
        let set = self.set();
        if !set.is_empty() {
            tracing::info!("tuning from the environment: {}", set.join(", "));
        }
        for r in &self.rejected {
            tracing::warn!("{r}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from(pairs: &[(&str, &str)]) -> Tuning {
        let pairs: Vec<(String, String)> = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        Tuning::from_vars(|k| pairs.iter().find(|(n, _)| n == k).map(|(_, v)| v.into()))
    }

    #[test]
    fn unset_knobs_keep_the_defaults() {
        assert_eq!(from(&[]), Tuning::default());
        assert!(from(&[]).set().is_empty());
    }

    #[test]
    fn knobs_are_parsed_and_bad_values_refused_by_name() {
        let t = from(&[
            ("POLYDEM_CUDA_BLOCK", "96"),
            ("POLYDEM_WALL_MERGE_CELLS", "0"),
            ("POLYDEM_PAIR_MAX_REGISTERS", "20"),
            ("POLYDEM_PTX_CACHE", "0"),
            ("POLYDEM_MPI", "1"),
            ("POLYDEM_MPI_ROUND_BYTES", "777"),
            ("POLYDEM_GPU_EXCHANGE", "host"),
            ("POLYDEM_PAIR_BATCH", "64"),
            ("POLYDEM_MIXED_LP", "f32"),
            ("POLYDEM_PANIC_AT", "1:300"),
            ("POLYDEM_CUDA_SOURCES", "/tmp/kernels"),
            ("POLYDEM_ENUM_PLANES", "12"),
        ]);
        assert_eq!(t.enum_planes, Some(12));
        assert!(t.set().contains(&"POLYDEM_ENUM_PLANES=12".to_string()));
        assert_eq!(t.cuda_sources, Some(PathBuf::from("/tmp/kernels")));
        assert!(
            t.set()
                .contains(&"POLYDEM_CUDA_SOURCES=/tmp/kernels".to_string())
        );
        assert_eq!(t.panic_at, Some((1, 300)));
        assert!(t.set().contains(&"POLYDEM_PANIC_AT=1:300".to_string()));
        assert_eq!(t.cuda_block, Some(96));
        assert!(t.mixed_lp_f32);
        assert!(t.set().contains(&"POLYDEM_MIXED_LP=f32".to_string()));
        assert_eq!(t.wall_merge_cells, Some(0));
        assert_eq!(t.pair_max_registers, None);
        assert_eq!(t.ptx_cache, Some(None));
        assert_eq!(t.mpi, Some(true));
        assert_eq!(t.mpi_round_bytes, Some(777));
        assert_eq!(t.gpu_exchange_on_device, Some(false));
        assert_eq!(t.pair_batch, Some(64));
        assert_eq!(t.rejected.len(), 1, "{:?}", t.rejected);
        assert!(t.rejected[0].starts_with("POLYDEM_PAIR_MAX_REGISTERS=\"20\""));
        let bad = from(&[
            ("POLYDEM_CUDA_BLOCK", "100"),
            ("POLYDEM_MPI", "yes"),
            ("POLYDEM_GPU_EXCHANGE", "gpu"),
            ("POLYDEM_MIXED_LP", "half"),
            ("POLYDEM_PANIC_AT", "1"),
            ("POLYDEM_ENUM_PLANES", "17"),
        ]);
        assert_eq!(bad.panic_at, None);
        assert_eq!(bad.enum_planes, None);
        assert_eq!(bad.cuda_block, None);
        assert_eq!(bad.mpi, None);
        assert_eq!(bad.gpu_exchange_on_device, None);
        assert!(!bad.mixed_lp_f32);
        assert_eq!(bad.rejected.len(), 6);
        assert!(
            bad.rejected
                .iter()
                .any(|r| r.starts_with("POLYDEM_ENUM_PLANES=\"17\" is not 8-16")),
            "{:?}",
            bad.rejected
        );
        assert!(t.set().contains(&"POLYDEM_CUDA_BLOCK=96".to_string()));
    }
}
