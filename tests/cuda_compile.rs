//! Every kernel of `cuda/` compiles under NVRTC 13.0 for sm_90 (the H100/H200 architecture),
//! in each configuration a scene can ask for: this needs NVRTC but no GPU (`make test` puts
//! PyPI's `nvidia-cuda-nvrtc` on the library path). The kernels also `static_assert` the sizes
//! of the structs they share with Rust, so a layout drift fails here.

use polydem::backend::cuda::kernels::{KERNEL_FILES, compile_in};
use polydem::backend::cuda::probe::PROBE_FILE;
use polydem::backend::cuda::{KernelConfig, Precision};

fn configs() -> Vec<KernelConfig> {
    let base = KernelConfig {
        precision: Precision::Double,
        walls: true,
        friction: true,
        periodic: false,
        spheres: false,
        templates: 1,
        max_vertices: 20,
        max_faces: 12,
        materials: 2,
        ghosts: false,
    };
    vec![
        base.clone(),
        // A rank of a decomposed run (ghost flags in the pair search).
        KernelConfig {
            precision: Precision::Mixed,
            ghosts: true,
            ..base.clone()
        },
        KernelConfig {
            walls: false,
            friction: false,
            periodic: true,
            templates: 3,
            max_vertices: 42,
            max_faces: 22,
            materials: 1,
            ghosts: true,
            ..base.clone()
        },
        KernelConfig {
            precision: Precision::Mixed,
            templates: 2,
            max_vertices: 256,
            max_faces: 128,
            ..base.clone()
        },
        // The sphere fast path, with and without walls.
        KernelConfig {
            spheres: true,
            max_vertices: 42,
            max_faces: 80,
            ..base.clone()
        },
        KernelConfig {
            spheres: true,
            walls: false,
            periodic: true,
            precision: Precision::Mixed,
            max_vertices: 42,
            max_faces: 80,
            ..base
        },
    ]
}

#[test]
fn every_kernel_compiles_with_nvrtc_for_sm_90() {
    // SAFETY: only tries to open the shared library.
    let present = unsafe { cudarc::nvrtc::sys::is_culib_present() };
    assert!(
        present,
        "libnvrtc not found: run `make test` (it installs nvidia-cuda-nvrtc==13.0.88 into .venv and \
         puts .venv/lib/python3*/site-packages/nvidia/cu13/lib on LD_LIBRARY_PATH), or add a CUDA \
         13.0 lib64 folder to LD_LIBRARY_PATH"
    );
    let mut failures = Vec::new();
    for config in configs() {
        for file in KERNEL_FILES.iter().chain([&PROBE_FILE]) {
            let t = std::time::Instant::now();
            // Without the PTX cache: this is the check that NVRTC accepts every kernel.
            match compile_in(file, &config, 90, None) {
                Ok(_) => println!(
                    "{file} {:?}: {:.2} s",
                    config.precision,
                    t.elapsed().as_secs_f64()
                ),
                Err(e) => failures.push(format!("{config:?}\n{e}")),
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// The PTX cache: a first compile stores the PTX under a key of source, options and NVRTC
/// version; a second one with the same key returns what is stored (shown by planting a marker
/// in the stored file); another configuration is another key; a stored file that is no PTX is
/// compiled afresh and replaced.
#[test]
fn compiled_ptx_is_cached_by_source_and_options() {
    // SAFETY: only tries to open the shared library.
    if !unsafe { cudarc::nvrtc::sys::is_culib_present() } {
        panic!("libnvrtc not found: run `make test`");
    }
    let dir = std::env::temp_dir().join(format!("polydem-ptx-cache-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = configs().remove(0);
    let first = compile_in("scan.cu", &config, 90, Some(&dir))
        .unwrap()
        .to_src();
    let files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    assert_eq!(std::fs::read_to_string(&files[0]).unwrap(), first);
    let marked = format!("{first}\n// marker\n");
    std::fs::write(&files[0], &marked).unwrap();
    let second = compile_in("scan.cu", &config, 90, Some(&dir))
        .unwrap()
        .to_src();
    assert_eq!(second, marked, "the second compile reads the cache");
    let other = KernelConfig {
        precision: Precision::Mixed,
        ..config.clone()
    };
    compile_in("scan.cu", &other, 90, Some(&dir)).unwrap();
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        2,
        "one file per key"
    );
    std::fs::write(&files[0], "not ptx").unwrap();
    let again = compile_in("scan.cu", &config, 90, Some(&dir))
        .unwrap()
        .to_src();
    assert_eq!(again, first, "a damaged entry is compiled afresh");
    assert_eq!(std::fs::read_to_string(&files[0]).unwrap(), first);
    let _ = std::fs::remove_dir_all(&dir);
}
