//! Every kernel of `cuda/` compiles under NVRTC 13.0 for sm_90 (the H100/H200 architecture),
//! in each configuration that changes their code (see `configs`): this needs NVRTC but no GPU (`make test` puts
//! PyPI's `nvidia-cuda-nvrtc` on the library path). The kernels also `static_assert` the sizes
//! of the structs they share with Rust, so a layout drift fails here.

use polydem::Precision;
use polydem::backend::cuda::KernelConfig;
use polydem::backend::cuda::kernels::{KERNEL_FILES, compile_in};
use polydem::backend::cuda::probe::PROBE_FILE;

/// The scene configurations whose kernels are checked. Only `cuda/contact.cu` (tens of seconds
/// to minutes under NVRTC) and `cuda/probe.cu` are costly; the others take about a second.
/// What the kernels switch on (`#if` in `cuda/`), and where each value is covered:
///
/// - `contact.cu`: `PD_DOUBLE_GEOMETRY`, `PD_SPHERES`, `PD_WALLS`, `PD_PERIODIC`, and the hull
///   index type of `quickhull.cuh` (a byte for templates of fewer than 60 faces, else 16 bits).
///   Polyhedra: double with walls (the CPU-bitwise path), mixed with walls (the default GPU
///   path), double, periodic, without walls, with the 16-bit hull index and 3 templates, and
///   mixed with the enumeration taking up to 16 planes (`PD_ENUM_MAX_PLANES`, the wider
///   staging and vertex workspace of `POLYDEM_ENUM_PLANES`).
///   Spheres: double with walls, mixed, periodic, without walls. `PD_ROLLING_FRICTION`: on
///   for mixed polyhedra with walls and for spheres with walls, off elsewhere.
/// - `integrate.cu`: `PD_GHOSTS`, `PD_WALLS`; `neighbor.cu`: `PD_GHOSTS`: both values of each.
/// - `probe.cu`: only the template sizes, so the hull index type ([`probe_configs`]).
/// - `scan.cu`, `halo.cu`: nothing of the scene.
///
/// `PD_MATERIALS` only sizes a table and no kernel reads `PD_FRICTION`; both vary anyway. The
/// files are compiled on all cores (`jobs`), so on 2 cores the check takes about 4 minutes.
fn configs() -> Vec<KernelConfig> {
    let base = KernelConfig {
        precision: Precision::Double,
        walls: true,
        friction: true,
        rolling_friction: false,
        periodic: false,
        spheres: false,
        templates: 1,
        max_vertices: 20,
        max_faces: 12,
        materials: 2,
        ghosts: false,
        face_trajectory: false,
        enum_planes: 8,
    };
    vec![
        base.clone(),
        // A rank of a decomposed run (ghost flags in the pair search), mixed precision, face
        // contacts along their trajectory, rolling friction.
        KernelConfig {
            precision: Precision::Mixed,
            ghosts: true,
            face_trajectory: true,
            rolling_friction: true,
            ..base.clone()
        },
        // Periodic, no walls, several large templates: 128 faces need the 16-bit hull index.
        KernelConfig {
            walls: false,
            friction: false,
            periodic: true,
            templates: 3,
            max_vertices: 256,
            max_faces: 128,
            materials: 1,
            ghosts: true,
            ..base.clone()
        },
        // The sphere fast path, with (and rolling friction) and without walls.
        KernelConfig {
            spheres: true,
            rolling_friction: true,
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
            ..base.clone()
        },
        // Many-faced grains with the enumeration up to 16 planes, mixed precision.
        KernelConfig {
            precision: Precision::Mixed,
            periodic: true,
            max_vertices: 18,
            max_faces: 32,
            enum_planes: 16,
            ..base
        },
    ]
}

/// `cuda/probe.cu` reads no scene flag, only the template sizes, and its code differs between
/// sizes only in the hull index type. It is compiled once, with the 16-bit index: its kernels
/// evaluate the geometry in both precisions, so this also covers mixed precision with the 16-bit
/// index, which `contact.cu` is checked in only with double; the byte index is `contact.cu`'s
/// in both precisions.
fn probe_configs() -> Vec<KernelConfig> {
    vec![configs().remove(2)]
}

/// Each kernel file with each configuration that can change its code: every configuration for
/// the files that read scene flags, the probe's one, and one for the files that read none.
fn jobs() -> Vec<(&'static str, KernelConfig)> {
    let all = configs();
    // Measured under NVRTC 13.0 (2 cores, other work running): contact.cu for polyhedra with the
    // byte hull index 140-210 s, probe.cu 190 s, contact.cu with the 16-bit index 64 s, for
    // spheres 3-13 s, the rest 0.2-4 s each. Longest first, so that the threads end together.
    let wide = all.len() - 1; // the 16-plane enumeration, as costly as the other polyhedra
    let mut jobs = vec![
        ("contact.cu", all[1].clone()),
        ("contact.cu", all[0].clone()),
        ("contact.cu", all[wide].clone()),
    ];
    jobs.extend(probe_configs().into_iter().map(|c| (PROBE_FILE, c)));
    jobs.extend(all[2..wide].iter().map(|c| ("contact.cu", c.clone())));
    for file in KERNEL_FILES {
        match *file {
            "contact.cu" => {}
            "scan.cu" | "halo.cu" => jobs.push((*file, all[0].clone())),
            _ => jobs.extend(all.iter().map(|c| (*file, c.clone()))),
        }
    }
    jobs
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
    // A new kernel file must be placed in `jobs` (with the configurations that change its code).
    for file in KERNEL_FILES {
        assert!(
            matches!(
                *file,
                "contact.cu" | "scan.cu" | "halo.cu" | "integrate.cu" | "neighbor.cu"
            ),
            "{file}: say in jobs() which configurations change its code"
        );
    }
    // NVRTC compiles independent programs on several threads at once; a compile of contact.cu
    // is single-threaded, so the threads divide the wall time by up to the core count.
    let jobs = jobs();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(jobs.len());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some((file, config)) = jobs.get(k) else {
                        break;
                    };
                    let t = std::time::Instant::now();
                    // Without the PTX cache: this is the check that NVRTC accepts every kernel.
                    match compile_in(file, config, 90, None) {
                        Ok(_) => println!(
                            "{file} {:?} spheres={} walls={} periodic={} faces={}: {:.2} s",
                            config.precision,
                            config.spheres,
                            config.walls,
                            config.periodic,
                            config.max_faces,
                            t.elapsed().as_secs_f64()
                        ),
                        Err(e) => failures.lock().unwrap().push(format!("{config:?}\n{e}")),
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
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
