//! The kernels of `cuda/`, embedded in the binary and compiled at run time by NVRTC with
//! `#define`s derived from the scene (docs/design.md §1, §5): a scene pays only for the stages it
//! uses, and the struct sizes shared with Rust are checked by `static_assert` in the kernels.

use super::layout;
use crate::scene::Scene;
use cudarc::nvrtc::{CompileOptions, Ptx};

/// Every file of `cuda/`, by name. `#include "x.cuh"` lines are resolved against this list
/// (each header once), so the binary carries its kernels and runs from any directory.
pub const SOURCES: &[(&str, &str)] = &[
    ("common.cuh", include_str!("../../../cuda/common.cuh")),
    ("layout.cuh", include_str!("../../../cuda/layout.cuh")),
    ("state.cuh", include_str!("../../../cuda/state.cuh")),
    ("polytope.cuh", include_str!("../../../cuda/polytope.cuh")),
    ("gjk.cuh", include_str!("../../../cuda/gjk.cuh")),
    ("interior.cuh", include_str!("../../../cuda/interior.cuh")),
    ("quickhull.cuh", include_str!("../../../cuda/quickhull.cuh")),
    (
        "vertex_enumeration.cuh",
        include_str!("../../../cuda/vertex_enumeration.cuh"),
    ),
    ("overlap.cuh", include_str!("../../../cuda/overlap.cuh")),
    ("pair.cuh", include_str!("../../../cuda/pair.cuh")),
    ("prism.cuh", include_str!("../../../cuda/prism.cuh")),
    ("sphere.cuh", include_str!("../../../cuda/sphere.cuh")),
    (
        "contact_law.cuh",
        include_str!("../../../cuda/contact_law.cuh"),
    ),
    ("scan.cu", include_str!("../../../cuda/scan.cu")),
    ("integrate.cu", include_str!("../../../cuda/integrate.cu")),
    ("neighbor.cu", include_str!("../../../cuda/neighbor.cu")),
    (
        "wall_contacts.cuh",
        include_str!("../../../cuda/wall_contacts.cuh"),
    ),
    ("contact.cu", include_str!("../../../cuda/contact.cu")),
    ("halo.cu", include_str!("../../../cuda/halo.cu")),
    ("probe.cu", include_str!("../../../cuda/probe.cu")),
];

/// The kernel files (translation units) of the step, in stage order.
pub const KERNEL_FILES: &[&str] = &[
    "scan.cu",
    "integrate.cu",
    "neighbor.cu",
    "contact.cu",
    "halo.cu",
];

pub use crate::geometry::pair::Precision;

/// What a scene needs from the kernels; turned into `#define`s.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelConfig {
    pub precision: Precision,
    /// Walls present (stage 6 compiled in).
    pub walls: bool,
    /// Some material pair has friction (tangential history compiled in).
    pub friction: bool,
    /// Some material pair has rolling friction (the rolling couple compiled in).
    pub rolling_friction: bool,
    /// Some axis is periodic (minimum-image displacements in the pair kernels).
    pub periodic: bool,
    /// Every particle is a sphere: stages 4–5 and the wall overlaps are the sphere formulas
    /// (`cuda/sphere.cuh`, always in f64), and no polyhedral workspace is compiled.
    pub spheres: bool,
    /// Number of templates, and the largest vertex and face counts among them: the sizes of the
    /// constant-memory template tables and of the per-thread geometry workspace.
    pub templates: usize,
    pub max_vertices: usize,
    pub max_faces: usize,
    /// Number of materials (contact-parameter tables).
    pub materials: usize,
    /// A rank of a decomposed run: some particles are ghosts, and pairs of two ghosts are left
    /// out of the pair list.
    pub ghosts: bool,
    /// `simulation.face_window = "trajectory"`: face contacts take the impulse of their own
    /// normal motion (`contact::trajectory`); the secant's kernels carry none of its code.
    pub face_trajectory: bool,
    /// The most planes whose faces come from the vertex enumeration (`PD_ENUM_MAX_PLANES`,
    /// the scene's [`crate::scene::Scene::enum_planes`]): the lean passes stage and take
    /// the pairs of at most that many planes.
    pub enum_planes: usize,
}

impl KernelConfig {
    /// The configuration a scene needs.
    pub fn for_scene(scene: &Scene, precision: Precision) -> Self {
        KernelConfig {
            precision,
            walls: !scene.walls.is_empty(),
            friction: scene.pairs.any_friction(),
            rolling_friction: scene.pairs.any_rolling_friction(),
            periodic: scene.domain.periodic.iter().any(|&p| p),
            spheres: scene.spheres_only(),
            templates: scene.templates.len().max(1),
            max_vertices: scene
                .templates
                .iter()
                .map(|t| t.vertices.len())
                .max()
                .unwrap_or(1),
            max_faces: scene
                .templates
                .iter()
                .map(|t| t.faces.len())
                .max()
                .unwrap_or(1),
            materials: scene.materials.len().max(1),
            ghosts: false,
            face_trajectory: scene.simulation.face_window == crate::contact::FaceWindow::Trajectory,
            enum_planes: scene.enum_planes(),
        }
    }

    /// The `-D` options.
    pub fn defines(&self) -> Vec<String> {
        let flag = |b: bool| u8::from(b);
        let mut d = vec![
            format!(
                "-DPD_DOUBLE_GEOMETRY={}",
                flag(self.precision == Precision::Double)
            ),
            format!("-DPD_WALLS={}", flag(self.walls)),
            format!("-DPD_FRICTION={}", flag(self.friction)),
            format!("-DPD_ROLLING_FRICTION={}", flag(self.rolling_friction)),
            format!("-DPD_PERIODIC={}", flag(self.periodic)),
            format!("-DPD_SPHERES={}", flag(self.spheres)),
            format!("-DPD_TEMPLATES={}", self.templates),
            format!("-DPD_MAX_TEMPLATE_VERTICES={}", self.max_vertices),
            format!("-DPD_MAX_TEMPLATE_FACES={}", self.max_faces),
            format!("-DPD_MATERIALS={}", self.materials),
            format!("-DPD_GHOSTS={}", flag(self.ghosts)),
            format!("-DPD_FACE_TRAJECTORY={}", flag(self.face_trajectory)),
            format!("-DPD_ENUM_MAX_PLANES={}", self.enum_planes),
        ];
        // Most grid cells merged per particle and wall when the wall list is built (default
        // 27; a box spanning more walks the facet grid in id order instead):
        // POLYDEM_WALL_MERGE_CELLS sets it (0–64), so that tests can drive every particle down
        // the walk.
        let tuning = crate::tuning::Tuning::get();
        if let Some(n) = tuning.wall_merge_cells {
            d.push(format!("-DPD_WALL_MERGE_CELLS={n}"));
        }
        // Register cap of the lean pair kernels: DEFAULT_PAIR_MAX_REGISTERS (for spheres
        // DEFAULT_SPHERE_PAIR_MAX_REGISTERS) unless POLYDEM_PAIR_MAX_REGISTERS gives another
        // (24–255), or 0 for none (a tuning knob).
        let cap = tuning.pair_max_registers.unwrap_or(if self.spheres {
            DEFAULT_SPHERE_PAIR_MAX_REGISTERS
        } else {
            DEFAULT_PAIR_MAX_REGISTERS
        });
        if cap > 0 {
            d.push(format!("-DPD_PAIR_MAX_REGISTERS={cap}"));
        }
        if phase_clocks() {
            d.push("-DPD_PHASE_CLOCKS=1".into());
        }
        // Mixed precision's Chebyshev LP in f32 (POLYDEM_MIXED_LP=f32; on trial).
        if tuning.mixed_lp_f32 && self.precision == Precision::Mixed {
            d.push("-DPD_MIXED_LP_F32=1".into());
        }
        d.extend(layout::layout_defines());
        d.push(format!(
            "-DPD_SIZEOF_STAGED_PLANES={}",
            layout::staged_planes_bytes(self.precision, self.enum_planes)
        ));
        d
    }
}

/// Why a kernel file did not compile.
#[derive(Debug, thiserror::Error)]
pub enum CompileError {
    /// An `#include` names a file that is not among [`SOURCES`].
    #[error("cuda/{name} is not among the embedded kernel sources")]
    MissingSource { name: String },
    /// A kernel file of the `POLYDEM_CUDA_SOURCES` folder could not be read.
    #[error("POLYDEM_CUDA_SOURCES: cannot read {path}: {error}")]
    Unreadable { path: String, error: String },
    /// NVRTC rejected the source: its log.
    #[error("NVRTC could not compile cuda/{kernel_file} (options {options:?}):\n{log}")]
    Nvrtc {
        kernel_file: String,
        options: Vec<String>,
        log: String,
    },
    /// NVRTC failed otherwise (the library, the program's creation).
    #[error("NVRTC could not compile cuda/{kernel_file}: {error:?}")]
    Failed {
        kernel_file: String,
        /// Part of the message, not chained as a source (it would print twice).
        error: cudarc::nvrtc::CompileError,
    },
}

/// Register cap of the lean polyhedral pair kernels (`pair_planes` and `pair_faces`; the
/// deferred pass has none), 0 for none: uncapped, the two passes fit two blocks of 256 per SM
/// and ran fastest in the sweep of docs/performance.md (§ dense dodecahedra). A cap changes
/// only the register allocation, never the arithmetic (no FMA contraction, IEEE division and
/// square root), so results are the same bits with any cap.
pub const DEFAULT_PAIR_MAX_REGISTERS: u32 = 0;

/// Register cap of the sphere pair kernel (`pair_contacts`): at most 96 registers let five
/// blocks of 128 threads (`SPHERE_PAIR_BLOCK`) share an SM (20 warps; the kernel waits on
/// memory and needs them), where its 100 uncapped registers allow four (the cap costs it one
/// 8-byte spill).
pub const DEFAULT_SPHERE_PAIR_MAX_REGISTERS: u32 = 96;

/// Whether the pair kernels are built to time their phases (`POLYDEM_PHASE_CLOCKS` set, a
/// profiling build: `clock64()` sums per phase, printed after every pair stage).
pub fn phase_clocks() -> bool {
    crate::tuning::Tuning::get().phase_clocks
}

/// Kernel file `name`: from `dir` (the folder `POLYDEM_CUDA_SOURCES` names) where it holds
/// the file, a kernel variant measured without a rebuild; else the copy built in from `cuda/`.
fn source(
    name: &str,
    dir: Option<&std::path::Path>,
) -> Result<std::borrow::Cow<'static, str>, CompileError> {
    if let Some(path) = dir.map(|d| d.join(name)).filter(|p| p.is_file()) {
        return std::fs::read_to_string(&path)
            .map(std::borrow::Cow::Owned)
            .map_err(|e| CompileError::Unreadable {
                path: path.display().to_string(),
                error: e.to_string(),
            });
    }
    SOURCES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, t)| std::borrow::Cow::Borrowed(*t))
        .ok_or_else(|| CompileError::MissingSource {
            name: name.to_string(),
        })
}

/// `file` with its `#include "…"` lines replaced by the named sources (each once, as
/// `#pragma once` would), so NVRTC needs no file system; the sources are those built in, or
/// those of the `POLYDEM_CUDA_SOURCES` folder where it has them.
pub fn expand(file: &str) -> Result<String, CompileError> {
    expand_from(file, crate::tuning::Tuning::get().cuda_sources.as_deref())
}

/// [`expand`] with the files of `dir` (where it holds them) in place of the built-in ones.
pub fn expand_from(file: &str, dir: Option<&std::path::Path>) -> Result<String, CompileError> {
    fn visit(
        name: &str,
        dir: Option<&std::path::Path>,
        seen: &mut Vec<String>,
        out: &mut String,
    ) -> Result<(), CompileError> {
        if seen.iter().any(|s| s == name) {
            return Ok(());
        }
        seen.push(name.to_string());
        let text = source(name, dir)?;
        for line in text.lines() {
            let t = line.trim_start();
            if let Some(rest) = t.strip_prefix("#include \"") {
                let inc = rest.split('"').next().unwrap_or_default();
                visit(inc, dir, seen, out)?;
            } else if t.starts_with("#pragma once") {
                continue;
            } else {
                out.push_str(line);
                out.push('\n');
            }
        }
        Ok(())
    }
    let mut out = String::new();
    visit(file, dir, &mut Vec::new(), &mut out)?;
    Ok(out)
}

/// Compiles kernel file `file` for `sm_<arch>` (e.g. 90) with the scene's defines. Floating-point
/// contraction is off (`--fmad=false`) so that double results follow the CPU's rounding.
///
/// The PTX is cached ([`ptx_cache_dir`]) under a hash of the expanded source, the options and
/// the NVRTC version, so a run (and every rank of a decomposed run) after the first skips the
/// seconds NVRTC takes; a cache that cannot be read or written is only skipped.
pub fn compile(file: &str, config: &KernelConfig, arch: u32) -> Result<Ptx, CompileError> {
    compile_in(file, config, arch, ptx_cache_dir().as_deref())
}

/// [`compile`] with the PTX cache in `cache` (`None`: always NVRTC).
pub fn compile_in(
    file: &str,
    config: &KernelConfig,
    arch: u32,
    cache: Option<&std::path::Path>,
) -> Result<Ptx, CompileError> {
    let source = expand(file)?;
    let mut options = config.defines();
    options.push(format!("--gpu-architecture=sm_{arch}"));
    options.push("--std=c++17".into());
    let cached = cache.map(|dir| {
        let mut key = source.clone().into_bytes();
        for o in &options {
            key.extend_from_slice(o.as_bytes());
            key.push(0);
        }
        key.extend_from_slice(nvrtc_version().as_bytes());
        let name = file.trim_end_matches(".cu");
        dir.join(format!(
            "{name}-{:016x}.ptx",
            crate::io::checkpoint::fnv1a64(&key)
        ))
    });
    if let Some(path) = &cached
        && let Ok(text) = std::fs::read_to_string(path)
        && text.contains(".entry")
    {
        return Ok(Ptx::from_src(text));
    }
    let ptx = nvrtc_compile(file, source, options)?;
    if let Some(path) = &cached {
        let stored = path
            .parent()
            .map(std::fs::create_dir_all)
            .transpose()
            .is_ok()
            && crate::io::write_atomic(path, ptx.to_src().as_bytes()).is_ok();
        if !stored {
            tracing::debug!("PTX cache {}: not writable, skipped", path.display());
        }
    }
    Ok(ptx)
}

/// Where compiled PTX is kept: `POLYDEM_PTX_CACHE` (`0` or empty: no cache), else
/// `$XDG_CACHE_HOME/polydem/ptx`, else `~/.cache/polydem/ptx`.
pub fn ptx_cache_dir() -> Option<std::path::PathBuf> {
    use std::path::PathBuf;
    match &crate::tuning::Tuning::get().ptx_cache {
        Some(set) => set.clone(),
        None => std::env::var_os("XDG_CACHE_HOME")
            .map(PathBuf::from)
            .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
            .map(|c| c.join("polydem").join("ptx")),
    }
}

/// NVRTC's version, part of the cache key (PTX of a newer NVRTC is refused by an older driver).
fn nvrtc_version() -> String {
    let (mut major, mut minor) = (0, 0);
    // SAFETY: the first call only tries to open the library; nvrtcVersion, called only when it
    // is present, writes two ints.
    unsafe {
        if cudarc::nvrtc::sys::is_culib_present() {
            cudarc::nvrtc::sys::nvrtcVersion(&mut major, &mut minor);
        }
    }
    format!("nvrtc {major}.{minor}")
}

fn nvrtc_compile(file: &str, source: String, options: Vec<String>) -> Result<Ptx, CompileError> {
    let opts = CompileOptions {
        fmad: Some(false),
        options,
        name: Some(file.to_string()),
        ..Default::default()
    };
    cudarc::nvrtc::compile_ptx_with_opts(source, opts).map_err(|e| match e {
        cudarc::nvrtc::CompileError::CompileError { log, options, .. } => CompileError::Nvrtc {
            kernel_file: file.to_string(),
            options,
            log: log.to_string_lossy().into_owned(),
        },
        error => CompileError::Failed {
            kernel_file: file.to_string(),
            error,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file of the override folder replaces the built-in one wherever it is included, the
    /// others stay the built-in ones, and an unreadable override is an error that names it.
    #[test]
    fn the_sources_folder_replaces_only_the_files_it_holds() {
        let dir = std::env::temp_dir().join(format!("polydem-kernels-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("pair.cuh"), "// a variant of pair.cuh\n").unwrap();
        let built_in = expand_from("contact.cu", None).unwrap();
        let variant = expand_from("contact.cu", Some(&dir)).unwrap();
        assert!(built_in.contains("contained_overlap(const BodyRef& A"));
        assert!(!variant.contains("contained_overlap(const BodyRef& A"));
        assert_eq!(variant.matches("// a variant of pair.cuh").count(), 1);
        assert!(variant.contains("__global__"));
        assert_eq!(
            expand_from("scan.cu", Some(&dir)).unwrap(),
            expand_from("scan.cu", None).unwrap()
        );
        std::fs::create_dir_all(dir.join("gjk.cuh")).unwrap();
        assert!(
            expand_from("contact.cu", Some(&dir)).is_ok(),
            "a folder is not a file"
        );
        std::fs::write(dir.join("scan.cu"), [0xff, 0xfe, 0x00]).unwrap();
        let error = expand_from("scan.cu", Some(&dir)).unwrap_err().to_string();
        assert!(
            error.contains("POLYDEM_CUDA_SOURCES") && error.contains("scan.cu"),
            "{error}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
