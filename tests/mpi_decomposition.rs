//! Domain decomposition over real MPI ranks (docs/design.md §6): the built `polydem` binary under
//! `mpirun --oversubscribe -n 2..4`, held to the single-rank run of the same scene.
//!
//! The reference is exact: a checkpoint holds every particle field (sorted by global id), the
//! contact history and the insertion state, gathered on rank 0 in the single-rank layout, so
//! "the same physics" is checked as byte-identical checkpoint files. That the runs really were
//! decomposed (particles migrated, ghosts were exchanged, boxes were redrawn) is checked from
//! each rank's report in `summary.json`.
//!
//! Needs Open MPI's `mpirun` (scripts/setup.sh installs openmpi-bin); each rank runs one rayon
//! thread.

mod common;

use common::{long_pour, polydem_bin, repo_root, temp_dir};
use polydem::io::read_checkpoint;
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::{Arc, Mutex, OnceLock};

/// `polydem run SCENE --backend BACKEND --out OUT` on `ranks` ranks (1: without mpirun), as
/// root too, with warnings only in the log.
fn command(ranks: usize, scene: &str, out: &Path, backend: &str) -> Command {
    let bin = polydem_bin();
    let mut cmd = if ranks == 1 {
        Command::new(&bin)
    } else {
        let mut c = Command::new("mpirun");
        c.args(["--oversubscribe", "-n", &ranks.to_string()])
            .arg(&bin);
        c
    };
    cmd.arg("run")
        .arg(repo_root().join(scene))
        .args(["--backend", backend, "--out"])
        .arg(out)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("RUST_LOG", "warn");
    cmd
}

/// Runs `cmd`, with a clear message when it cannot start.
fn output(mut cmd: Command) -> Output {
    cmd.output().unwrap_or_else(|e| {
        panic!(
            "cannot start {:?} ({e}); the MPI tests need Open MPI's mpirun: run `make test`, \
             which installs openmpi-bin",
            cmd.get_program()
        )
    })
}

/// `polydem run SCENE` on the CPU on `ranks` ranks into `out`, one rayon thread a rank, with
/// extra arguments.
fn run(ranks: usize, scene: &str, out: &Path, extra: &[&str]) -> Output {
    let mut cmd = command(ranks, scene, out, "cpu");
    cmd.args(extra).env("RAYON_NUM_THREADS", "1");
    output(cmd)
}

/// As [`run`], and asserts that it succeeded; returns rank 0's summary.
fn run_ok(ranks: usize, scene: &str, out: &Path, extra: &[&str]) -> Value {
    let o = run(ranks, scene, out, extra);
    assert!(
        o.status.success(),
        "{ranks} rank(s) of {scene} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("summary JSON on stdout")
}

/// Output folders of single-rank runs by scene, each made once.
type References = Mutex<HashMap<&'static str, Arc<OnceLock<PathBuf>>>>;

/// The single-rank run of `scene`, made once for all tests.
fn reference(scene: &'static str) -> PathBuf {
    static RUNS: OnceLock<References> = OnceLock::new();
    let cell = RUNS
        .get_or_init(Default::default)
        .lock()
        .unwrap()
        .entry(scene)
        .or_default()
        .clone();
    cell.get_or_init(|| {
        let dir = temp_dir(&format!("mpi-ref-{}", scene.replace('/', "_")));
        run_ok(1, scene, &dir, &[]);
        dir
    })
    .clone()
}

/// The checkpoint `name` of `a` and of `b` are byte for byte the same.
fn same_checkpoint(a: &Path, b: &Path, name: &str, what: &str) {
    let (pa, pb) = (
        a.join("checkpoints").join(name),
        b.join("checkpoints").join(name),
    );
    let (x, y) = (std::fs::read(&pa).unwrap(), std::fs::read(&pb).unwrap());
    if x != y {
        let (ca, cb) = (read_checkpoint(&pa).unwrap(), read_checkpoint(&pb).unwrap());
        let at: std::collections::HashMap<u64, usize> = cb
            .particles
            .id
            .iter()
            .enumerate()
            .map(|(i, &g)| (g, i))
            .collect();
        let worst = (0..ca.particles.len())
            .filter_map(|i| {
                let j = *at.get(&ca.particles.id[i])?;
                Some((ca.particles.position[i] - cb.particles.position[j]).norm())
            })
            .fold(0.0, f64::max);
        panic!(
            "{what}: {name} differs from the single-rank run ({} vs {} particles, {} vs {} \
             contacts, largest position difference {worst:e} m)",
            ca.particles.len(),
            cb.particles.len(),
            ca.history.len(),
            cb.history.len()
        );
    }
}

/// Every particle exactly once: `expected` particles with distinct global ids.
fn no_particle_lost_or_duplicated(dir: &Path, expected: usize) {
    let c = read_checkpoint(&dir.join("checkpoints/latest.ckpt")).unwrap();
    let mut ids = c.particles.id.clone();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(c.particles.len(), expected, "particles in the checkpoint");
    assert_eq!(ids.len(), expected, "distinct global ids");
}

/// Sums of a per-rank decomposition counter.
fn per_rank_sum(summary: &Value, key: &str) -> u64 {
    summary["parallel"]["per_rank"]
        .as_array()
        .expect("per-rank report")
        .iter()
        .map(|r| r["decomposition_seconds"][key].as_u64().unwrap())
        .sum()
}

/// A dense pour into a walled box (count and rate insertion, friction, recursive bisection
/// rebalanced as the bed forms) on 2, 3 and 4 ranks: the checkpoints at steps 1000 and 2000
/// are byte-identical to the single-rank run's, and so are `series.csv` and the summary's
/// energies (exact sums merged across ranks, `crate::exact_sum`: the series once differed in
/// the last bit, 0.0025558616366241245 against 0.002555861636624125).
#[test]
fn pour_on_2_3_4_ranks_is_bitwise_the_single_rank_run() {
    let one = reference("launch/mpi/pour.toml");
    no_particle_lost_or_duplicated(&one, 280);
    for ranks in [2, 3, 4] {
        let dir = temp_dir(&format!("mpi-pour-{ranks}"));
        let s = run_ok(ranks, "launch/mpi/pour.toml", &dir, &[]);
        assert_eq!(s["ranks"], ranks);
        assert_eq!(s["particles"], 280);
        for step in ["step_0000001000.ckpt", "step_0000002000.ckpt"] {
            same_checkpoint(&one, &dir, step, &format!("{ranks} ranks"));
        }
        assert!(
            std::fs::read(one.join("series.csv")).unwrap()
                == std::fs::read(dir.join("series.csv")).unwrap(),
            "{ranks} ranks: series.csv differs from the single-rank run's"
        );
        let one_summary: Value =
            serde_json::from_slice(&std::fs::read(one.join("summary.json")).unwrap()).unwrap();
        assert_eq!(s["energy"], one_summary["energy"], "{ranks} ranks");
        no_particle_lost_or_duplicated(&dir, 280);
        // It was a decomposed run: particles crossed boxes, ghosts were held, boxes redrawn.
        let migrated = per_rank_sum(&s, "migrated");
        let rebalances = per_rank_sum(&s, "rebalances");
        let ghosts: u64 = s["parallel"]["per_rank"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["ghosts"].as_u64().unwrap())
            .sum();
        println!("{ranks} ranks: {migrated} migrations, {rebalances} rebalances, {ghosts} ghosts");
        assert!(migrated > 50, "{ranks} ranks: only {migrated} migrations");
        assert!(
            rebalances > 0,
            "{ranks} ranks: the boxes were never redrawn"
        );
        assert!(ghosts > 10, "{ranks} ranks: {ghosts} ghosts at the end");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// The collectives split what they move into rounds of at most 2³¹ − 1 bytes (MPI's counts are
/// 32-bit: a checkpoint of 1e7 particles gathered on rank 0 needs several). With rounds of 777
/// bytes (`POLYDEM_MPI_ROUND_BYTES`) every gather, migration and insertion of the pour takes
/// many rounds, and the run is still bitwise the single-rank one.
#[test]
fn collectives_in_small_rounds_give_the_same_run() {
    let one = reference("launch/mpi/pour.toml");
    let dir = temp_dir("mpi-rounds-3");
    let mut cmd = command(3, "launch/mpi/pour.toml", &dir, "cpu");
    cmd.env("POLYDEM_MPI_ROUND_BYTES", "777")
        .env("RAYON_NUM_THREADS", "1");
    let o = output(cmd);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for step in ["step_0000001000.ckpt", "step_0000002000.ckpt"] {
        same_checkpoint(&one, &dir, step, "3 ranks, 777-byte rounds");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A checkpoint written by 4 ranks at step 1000, restarted on 2 ranks, ends at step 2000
/// byte-identical to the single-rank run (and the 4-rank checkpoint itself is the single-rank
/// one, so it also restarts on 1 rank).
#[test]
fn checkpoint_of_4_ranks_restarts_on_2() {
    let one = reference("launch/mpi/pour.toml");
    let four = temp_dir("mpi-ckpt-4");
    run_ok(4, "launch/mpi/pour.toml", &four, &["--max-steps", "1000"]);
    same_checkpoint(&one, &four, "step_0000001000.ckpt", "4 ranks, first half");
    let two = temp_dir("mpi-ckpt-2");
    let ck = four.join("checkpoints/step_0000001000.ckpt");
    let s = run_ok(
        2,
        "launch/mpi/pour.toml",
        &two,
        &["--restart", ck.to_str().unwrap()],
    );
    assert_eq!(s["final_step"], 2000);
    same_checkpoint(&one, &two, "step_0000002000.ckpt", "restart on 2 ranks");
    no_particle_lost_or_duplicated(&two, 280);
    let _ = std::fs::remove_dir_all(&four);
    let _ = std::fs::remove_dir_all(&two);
}

/// Colliding streams in a fully periodic box on a fixed 2 × 1 × 2 grid: pairs across periodic
/// seams and subdomain edges and corners, bitwise as on one rank.
#[test]
fn periodic_box_on_a_4_rank_grid_is_bitwise_the_single_rank_run() {
    let one = reference("launch/mpi/periodic.toml");
    let dir = temp_dir("mpi-periodic-4");
    let s = run_ok(4, "launch/mpi/periodic.toml", &dir, &[]);
    for step in ["step_0000001000.ckpt", "step_0000002000.ckpt"] {
        same_checkpoint(&one, &dir, step, "periodic, 4 ranks");
    }
    no_particle_lost_or_duplicated(&dir, 180);
    assert!(per_rank_sum(&s, "migrated") > 50);
    // A fixed grid is never redrawn.
    assert_eq!(per_rank_sum(&s, "rebalances"), 0);
    // Contacts happened, across the seams among them (the streams wrap around).
    let series = std::fs::read_to_string(dir.join("series.csv")).unwrap();
    let peak = series
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(6)?.parse::<u64>().ok())
        .max()
        .unwrap();
    assert!(peak > 20, "at most {peak} contacts");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A compressed periodic lattice of cubes sheared at e = 0.05 on a fixed 2 × 1 × 2 grid: the
/// dashpot caps split each cube's mass among its 26 contacts, so a pair across two ranks needs
/// the ghost's whole contact count, refreshed with its motion every step. Bitwise as on one
/// rank (keeping the ghosts' counts from the last rebuild instead diverged).
#[test]
fn sheared_lattice_on_a_4_rank_grid_is_bitwise_the_single_rank_run() {
    let one = reference("launch/mpi/lattice.toml");
    let dir = temp_dir("mpi-lattice-4");
    run_ok(4, "launch/mpi/lattice.toml", &dir, &[]);
    for step in ["step_0000001638.ckpt", "step_0000003275.ckpt"] {
        same_checkpoint(&one, &dir, step, "lattice, 4 ranks");
    }
    no_particle_lost_or_duplicated(&dir, 256);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The same lattice in the CPU twin of mixed precision (`--gpu-precision mixed`: f32 face
/// contacts, the thin ones in f64): a pair across two ranks is evaluated alike on both, so 4
/// ranks are bitwise one rank in mixed precision too; and its thin slabs all go to f64.
#[test]
fn sheared_lattice_in_mixed_precision_on_4_ranks_is_bitwise_one_rank() {
    let scene = "launch/mpi/lattice.toml";
    let mixed = ["--gpu-precision", "mixed"];
    let one = temp_dir("mpi-lattice-mixed-1");
    let s = run_ok(1, scene, &one, &mixed);
    assert_eq!(s["precision"], "mixed");
    let four = temp_dir("mpi-lattice-mixed-4");
    run_ok(4, scene, &four, &mixed);
    for step in ["step_0000001638.ckpt", "step_0000003275.ckpt"] {
        same_checkpoint(&one, &four, step, "lattice in mixed precision, 4 ranks");
    }
    // Every contact of this lattice is a face slab 1e-6 m thick, below the f32 resolution
    // that mixed precision asks of a pair (docs/performance.md): each goes to f64, and with the
    // friction of docs/contact.md §4 no cube tilts onto an edge, so the run is the f64 run bit
    // for bit. (With the earlier friction the cubes turned and met on edges, in f32.)
    let last = |d: &Path| std::fs::read(d.join("checkpoints/step_0000003275.ckpt")).unwrap();
    assert!(
        last(&one) == last(&reference(scene)),
        "the mixed-precision run is not the f64 run: a contact went the f32 way"
    );
    let _ = std::fs::remove_dir_all(&one);
    let _ = std::fs::remove_dir_all(&four);
}

/// Grains leaving through the open bottom of a domain periodic along x, fed from above: on 3
/// ranks the same particles are removed and inserted, bitwise as on one rank.
#[test]
fn outflow_on_3_ranks_removes_and_inserts_as_one_rank() {
    let one = reference("launch/mpi/outflow.toml");
    let dir = temp_dir("mpi-outflow-3");
    let s = run_ok(3, "launch/mpi/outflow.toml", &dir, &[]);
    for step in ["step_0000001000.ckpt", "step_0000002000.ckpt"] {
        same_checkpoint(&one, &dir, step, "outflow, 3 ranks");
    }
    assert_eq!(s["particles_removed"], 150, "removed in all");
    assert_eq!(s["particles"], 100);
    no_particle_lost_or_duplicated(&dir, 100);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Each rank writes its own piece of every frame and rank 0 a `.pvtu` naming all of them; the
/// pieces hold every particle once, with the writing rank in the `rank` field.
#[test]
fn frames_have_one_piece_per_rank() {
    let cells_in = |path: &Path| -> usize {
        std::fs::read_to_string(path)
            .unwrap()
            .split("NumberOfCells=\"")
            .nth(1)
            .and_then(|t| t.split('"').next())
            .unwrap()
            .parse()
            .unwrap()
    };
    let one = reference("launch/mpi/pour.toml");
    let expected = cells_in(&one.join("frames/step_0000000500_r0000.vtu"));
    let dir = temp_dir("mpi-frames-3");
    run_ok(3, "launch/mpi/pour.toml", &dir, &["--max-steps", "500"]);
    let frames = dir.join("frames");
    let pvtu = std::fs::read_to_string(frames.join("step_0000000500.pvtu")).unwrap();
    let mut cells = 0;
    let mut ids = Vec::new();
    for r in 0..3 {
        let piece = format!("step_0000000500_r{r:04}.vtu");
        assert!(pvtu.contains(&piece), "{piece} not in the .pvtu");
        let n = cells_in(&frames.join(&piece));
        cells += n;
        ids.push(n);
    }
    assert_eq!(cells, expected, "cells over the pieces: {ids:?}");
    assert!(
        ids.iter().all(|&n| n > 0),
        "a rank wrote no particle: {ids:?}"
    );
    // An independent reader (meshio, tests/oracles/read_vtu.py) reads every frame of the
    // collection through its .pvtu: three pieces, as many cells as the single-rank frame, and
    // each piece's `rank` field is the rank that wrote it.
    let frames3 = oracle("collection", &dir.join("frames.pvd"));
    let frames1 = oracle("collection", &one.join("frames.pvd"));
    let (d3, d1) = (
        frames3["datasets"].as_array().unwrap(),
        frames1["datasets"].as_array().unwrap(),
    );
    assert_eq!(d3.len(), 2, "frames at steps 0 and 500");
    for (a, b) in d3.iter().zip(d1) {
        assert_eq!(a["pieces"].as_array().unwrap().len(), 3);
        assert_eq!(a["cells"], b["cells"], "cells of {} read back", a["file"]);
    }
    for r in 0..3u64 {
        let piece = oracle("mesh", &frames.join(format!("step_0000000500_r{r:04}.vtu")));
        let ranks = piece["cell_data"]["rank"].as_array().unwrap();
        assert!(
            !ranks.is_empty() && ranks.iter().all(|v| v.as_u64() == Some(r)),
            "rank field of piece {r}: {ranks:?}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `POLYDEM_PYTHON`, else `<root>/.venv/bin/python` (`make test` creates it) runs the meshio
/// oracle in `mode` on `file` and returns its JSON.
fn oracle(mode: &str, file: &Path) -> Value {
    let python = std::env::var_os("POLYDEM_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join(".venv/bin/python"));
    let script = repo_root().join("tests/oracles/read_vtu.py");
    let out = Command::new(&python)
        .arg(&script)
        .arg(mode)
        .arg(file)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run {} ({e}): run `make test`, which sets up .venv with meshio",
                python.display()
            )
        });
    assert!(
        out.status.success(),
        "read_vtu.py {mode} {}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("oracle JSON")
}

/// What cannot run is refused on every rank with a message that says why, once: a grid whose
/// product is not the rank count, and the GPU backend where there is no GPU.
#[test]
fn bad_parallel_requests_are_refused_clearly() {
    let dir = temp_dir("mpi-refused");
    let o = run(2, "launch/mpi/periodic.toml", &dir, &[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("[parallel] grid = [2, 1, 2]") && err.contains("2 ranks"),
        "{err}"
    );
    // The ranks agree on a start-up failure: printed once, MPI ended in order, not aborted.
    assert_eq!(err.matches("has 4 subdomains").count(), 1, "{err}");
    assert!(!err.contains("MPI_ABORT"), "{err}");
    if polydem::backend::cuda_info().unavailable.is_none() {
        return; // a GPU machine runs the GPU ranks instead (gpu_ranks_* below)
    }
    let o = output(command(2, "launch/mpi/pour.toml", &dir, "cuda"));
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--backend cuda:"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `polydem run` on the GPU: `ranks` ranks (all on GPU 0 of a one-GPU machine) in `precision`.
fn run_gpu(ranks: usize, scene: &str, out: &Path, precision: &str, extra: &[&str]) -> Value {
    let mut cmd = command(ranks, scene, out, "cuda");
    cmd.args(["--gpu-precision", precision]).args(extra);
    let o = output(cmd);
    assert!(
        o.status.success(),
        "{ranks} GPU rank(s) of {scene} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("summary JSON")
}

/// GPU ranks: a rebuild that stays on the device (migration and the ghosts' choice from the
/// centroids alone, the history carried over on the device) gives bitwise the run of the round
/// trip of the whole state through the host (`POLYDEM_GPU_EXCHANGE=device` against `host`), on
/// the pour (walls, insertions, which still take the round trip, and recursive bisection
/// rebalanced) on 2 and 3 ranks, in double and mixed precision (on 3 ranks with the lean pair
/// passes in batches of 97 pairs as well). Both make the same rebuilds and migrations; only
/// the first makes any on the device.
#[test]
#[ignore = "needs a CUDA GPU"]
fn gpu_rebuilds_on_the_device_are_the_host_round_trip() {
    for (ranks, precision) in [(2, "double"), (3, "double"), (2, "mixed")] {
        let host = temp_dir(&format!("mpi-gpu-exchange-host-{ranks}-{precision}"));
        let mut cmd = command(ranks, "launch/mpi/pour.toml", &host, "cuda");
        cmd.args(["--gpu-precision", precision])
            .env("POLYDEM_GPU_EXCHANGE", "host");
        let o = output(cmd);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let by_host: Value = serde_json::from_slice(&o.stdout).expect("summary JSON");
        let dir = temp_dir(&format!("mpi-gpu-exchange-device-{ranks}-{precision}"));
        let mut cmd = command(ranks, "launch/mpi/pour.toml", &dir, "cuda");
        cmd.args(["--gpu-precision", precision])
            .env("POLYDEM_GPU_EXCHANGE", "device");
        if ranks == 3 {
            // The lean pair passes in small batches too: the pairs with a ghost start mid-list.
            cmd.env("POLYDEM_PAIR_BATCH", "97");
        }
        let o = output(cmd);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let on_device: Value = serde_json::from_slice(&o.stdout).expect("summary JSON");
        for step in ["step_0000001000.ckpt", "step_0000002000.ckpt"] {
            same_checkpoint(
                &host,
                &dir,
                step,
                &format!("{ranks} GPU ranks, {precision}, rebuilds on the device"),
            );
        }
        for key in ["rebuilds", "migrated", "rebalances"] {
            assert_eq!(
                per_rank_sum(&by_host, key),
                per_rank_sum(&on_device, key),
                "{key}"
            );
        }
        let device = per_rank_sum(&on_device, "device_rebuilds");
        let rebuilds = per_rank_sum(&on_device, "rebuilds");
        println!("{ranks} GPU ranks, {precision}: {device} of {rebuilds} rebuilds on the device");
        assert_eq!(per_rank_sum(&by_host, "device_rebuilds"), 0);
        assert!(device > 0 && device < rebuilds, "{device} of {rebuilds}");
        no_particle_lost_or_duplicated(&dir, 280);
        let _ = std::fs::remove_dir_all(&host);
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// GPU ranks: the pour on 2 and 3 ranks sharing one GPU ends bitwise equal to one GPU, in
/// double (and then to the CPU's single-rank run, which double on the GPU follows bit for bit)
/// and in mixed precision, with the halo exchanged through the device and pinned buffers.
#[test]
#[ignore = "needs a CUDA GPU"]
fn gpu_ranks_match_one_gpu() {
    let cpu = reference("launch/mpi/pour.toml");
    for precision in ["double", "mixed"] {
        let one = temp_dir(&format!("mpi-gpu1-{precision}"));
        run_gpu(1, "launch/mpi/pour.toml", &one, precision, &[]);
        if precision == "double" {
            same_checkpoint(&cpu, &one, "step_0000002000.ckpt", "one GPU, double");
        }
        for ranks in [2, 3] {
            let dir = temp_dir(&format!("mpi-gpu{ranks}-{precision}"));
            let s = run_gpu(ranks, "launch/mpi/pour.toml", &dir, precision, &[]);
            assert_eq!(s["backend"], "cuda");
            for step in ["step_0000001000.ckpt", "step_0000002000.ckpt"] {
                same_checkpoint(&one, &dir, step, &format!("{ranks} GPU ranks, {precision}"));
            }
            no_particle_lost_or_duplicated(&dir, 280);
            let migrated = per_rank_sum(&s, "migrated");
            println!("{ranks} GPU ranks, {precision}: {migrated} migrations");
            assert!(migrated > 50);
            let _ = std::fs::remove_dir_all(&dir);
        }
        let _ = std::fs::remove_dir_all(&one);
    }
}

/// The sheared lattice restarted from its single-rank checkpoint at step 1638 ends bitwise as
/// the uninterrupted run: the contact counts the caps read are not in the checkpoint but
/// recovered from its contact history (reading them as zero instead diverged).
#[test]
fn sheared_lattice_restarts_bitwise() {
    let one = reference("launch/mpi/lattice.toml");
    let dir = temp_dir("mpi-lattice-restart");
    let ckpt = one.join("checkpoints/step_0000001638.ckpt");
    run_ok(
        1,
        "launch/mpi/lattice.toml",
        &dir,
        &["--restart", ckpt.to_str().unwrap()],
    );
    same_checkpoint(&one, &dir, "step_0000003275.ckpt", "lattice, restarted");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The sheared lattice on 4 GPU ranks (double): bitwise the CPU's single-rank run, the ghosts'
/// contact counts travelling in the device's halo records.
#[test]
#[ignore = "needs a CUDA GPU"]
fn gpu_ranks_sheared_lattice_is_the_cpus() {
    let cpu = reference("launch/mpi/lattice.toml");
    let four = temp_dir("mpi-gpu-lattice-4");
    run_gpu(4, "launch/mpi/lattice.toml", &four, "double", &[]);
    for step in ["step_0000001638.ckpt", "step_0000003275.ckpt"] {
        same_checkpoint(&cpu, &four, step, "lattice, 4 GPU ranks");
    }
    no_particle_lost_or_duplicated(&four, 256);
    let _ = std::fs::remove_dir_all(&four);
}

/// GPU ranks in a periodic box on a 2 × 1 × 2 grid, and a 4-rank GPU checkpoint restarted on
/// 2 GPU ranks, bitwise as one GPU (double).
#[test]
#[ignore = "needs a CUDA GPU"]
fn gpu_ranks_periodic_grid_and_restart() {
    let one = temp_dir("mpi-gpu-periodic-1");
    run_gpu(1, "launch/mpi/periodic.toml", &one, "double", &[]);
    let four = temp_dir("mpi-gpu-periodic-4");
    run_gpu(4, "launch/mpi/periodic.toml", &four, "double", &[]);
    for step in ["step_0000001000.ckpt", "step_0000002000.ckpt"] {
        same_checkpoint(&one, &four, step, "periodic, 4 GPU ranks");
    }
    let pour1 = temp_dir("mpi-gpu-restart-1");
    run_gpu(1, "launch/mpi/pour.toml", &pour1, "double", &[]);
    let four = temp_dir("mpi-gpu-restart-4");
    run_gpu(
        4,
        "launch/mpi/pour.toml",
        &four,
        "double",
        &["--max-steps", "1000"],
    );
    let two = temp_dir("mpi-gpu-restart-2");
    let ck = four.join("checkpoints/step_0000001000.ckpt");
    run_gpu(
        2,
        "launch/mpi/pour.toml",
        &two,
        "double",
        &["--restart", ck.to_str().unwrap()],
    );
    same_checkpoint(
        &pour1,
        &two,
        "step_0000002000.ckpt",
        "GPU restart 4 → 2 ranks",
    );
}

/// The pour of `launch/mpi/pour.toml` written to `dir` with checkpoints every 500 steps and
/// either a speed bound of 1.9 m/s, which particle 165 passes at step 1018 (with the friction
/// of docs/contact.md §4; with the earlier friction particle 26 was spun up past 2.2 m/s at step
/// 929), or no walls, so that particle 194 falls out through the closed bottom at step
/// 1020. Returns the scene's path.
fn stopping_pour(dir: &Path, stop: &str) -> PathBuf {
    let mut text = std::fs::read_to_string(repo_root().join("launch/mpi/pour.toml"))
        .unwrap()
        .replace(
            "\"../../meshes",
            &format!("\"{}/meshes", repo_root().display()),
        )
        .replace("checkpoint_interval = 0.02", "checkpoint_interval = 0.01");
    match stop {
        "speed" => {
            text = text.replace(
                "seed = 5\n",
                "seed = 5\n\n[simulation.guard]\nmax_speed = 1.9\n",
            )
        }
        "leaving" => {
            let (a, b) = (
                text.find("[[walls]]").unwrap(),
                text.find("[parallel]").unwrap(),
            );
            text.replace_range(a..b, "");
        }
        _ => unreachable!(),
    }
    let path = dir.join(format!("{stop}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// A stop on one rank of a decomposed run, by the stability guard or by a particle leaving
/// through a closed face, stops every rank after the same step as the single-rank run: the
/// ranks agree on it and write the state at the stop together, byte-identical to the
/// single-rank run's, beside the untouched scheduled checkpoint; the run exits non-zero with
/// the cause named, with the single-rank run's speed scale. (Before, the failing rank alone
/// ended the others: no stopped state.) On the GPU in double, whose trajectory is the CPU's bit
/// for bit: there the reported speed once took the circumscribed radius of another particle
/// (the cached radii follow the last list build's order, not the synced state's) and the
/// decomposed GPU start left insertion out of the speed scale.
fn stops_every_rank(backend: &str) {
    let dir = temp_dir(&format!("mpi-stop-{backend}"));
    for (stop, step, cause) in [
        (
            "speed",
            1018,
            "particle 165 is blowing up: it moves at 1.9027e0 m/s",
        ),
        (
            "leaving",
            1020,
            "1 particle(s) left the domain through a closed face: particle 194",
        ),
    ] {
        let scene = stopping_pour(&dir, stop);
        let name = format!("unstable-step-{step}.ckpt");
        let one = dir.join(format!("{stop}-1"));
        let o = output(command(1, scene.to_str().unwrap(), &one, "cpu"));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains(cause),
            "1 rank, {stop}: {err}"
        );
        // The guard's bounds come from the whole run's particles on every rank count: the
        // speed scale the error names is the single-rank one.
        let scale = err
            .find("the scene's speed scale is")
            .map(|k| err[k..].split(')').next().unwrap_or_default().to_string());
        for ranks in [2, 3] {
            let out = dir.join(format!("{stop}-{backend}-{ranks}"));
            let mut cmd = command(ranks, scene.to_str().unwrap(), &out, backend);
            cmd.env("RAYON_NUM_THREADS", "1");
            if backend == "cuda" {
                cmd.args(["--gpu-precision", "double"]);
            }
            let o = output(cmd);
            let err = String::from_utf8_lossy(&o.stderr);
            let what = format!("{ranks} {backend} ranks, {stop}");
            assert!(!o.status.success(), "{what}: the run must fail: {err}");
            assert!(
                err.contains(&format!("step {step}: {cause}"))
                    && err.contains(&format!("the state at the stop is in {}", out.display()))
                    && err.contains("the run stops at this step with rank(s)")
                    && !err.contains("MPI_ABORT"),
                "{what}: {err}"
            );
            if let Some(scale) = &scale {
                assert!(
                    err.contains(scale.as_str()),
                    "{what}: not \"{scale}\": {err}"
                );
            }
            same_checkpoint(&one, &out, &name, &what);
            let latest = read_checkpoint(&out.join("checkpoints/latest.ckpt")).unwrap();
            // Both stops come after the scheduled checkpoint at step 1000.
            assert_eq!(latest.step, 1000, "{what}");
            let stopped = read_checkpoint(&out.join("checkpoints").join(&name)).unwrap();
            assert_eq!(
                (stopped.step, stopped.particles.len()),
                (step, 280),
                "{what}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_stop_on_one_rank_stops_every_rank_with_the_state_written() {
    stops_every_rank("cpu");
}

#[test]
#[ignore = "needs a CUDA GPU"]
fn a_stop_on_one_gpu_rank_stops_every_rank_with_the_state_written() {
    stops_every_rank("cuda");
}

/// Interrupting a 2-rank run, as a terminal's Ctrl-C does (SIGINT to the whole process group:
/// mpirun and its ranks) and as `kill -INT` on mpirun does (mpirun then sends every rank
/// SIGTERM, and SIGKILL a second later): every rank stops after the same step, the checkpoint
/// of that step and the summary (`interrupted`, the signal) are written, and the run exits
/// non-zero. The first checkpoint restarts on 2 ranks and ends byte-identical to the
/// uninterrupted single-rank run of as many steps.
#[cfg(unix)]
#[test]
fn interrupting_mpirun_stops_every_rank_at_the_same_step() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let dir = temp_dir("mpi-interrupt");
    let scene = long_pour(&dir);
    let scene = scene.to_str().unwrap().to_string();
    let mut first = None;
    for target in ["process group", "mpirun"] {
        let out = dir.join(target.replace(' ', "_"));
        let mut child = Command::new("setsid")
            .args(["mpirun", "--oversubscribe", "-n", "2"])
            .arg(polydem_bin())
            .args(["run", &scene, "--backend", "cpu", "--out"])
            .arg(&out)
            .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
            .env("RAYON_NUM_THREADS", "1")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start setsid mpirun (util-linux, Open MPI)");
        let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
        let mut log = String::new();
        for line in lines.by_ref() {
            let line = line.unwrap();
            log.push_str(&line);
            log.push('\n');
            if line.contains("step 300 ") {
                break;
            }
        }
        // setsid made mpirun the leader of its own group: -pid names the group.
        let pid = child.id().to_string();
        let whom = if target == "mpirun" {
            pid
        } else {
            format!("-{pid}")
        };
        let kill = Command::new("kill").args(["-INT", "--", &whom]).status();
        assert!(kill.unwrap().success());
        for line in lines {
            log.push_str(&line.unwrap());
            log.push('\n');
        }
        let status = child.wait().unwrap();
        assert!(!status.success(), "{target}: exited with success:\n{log}");
        let summary: Value = serde_json::from_slice(
            &std::fs::read(out.join("summary.json"))
                .unwrap_or_else(|e| panic!("{target}: no summary.json ({e}):\n{log}")),
        )
        .unwrap();
        assert_eq!(summary["interrupted"], true, "{target}");
        assert!(
            ["SIGINT", "SIGTERM"].contains(&summary["signal"].as_str().unwrap_or("")),
            "{target}: {}",
            summary["signal"]
        );
        let k = summary["final_step"].as_u64().unwrap();
        assert!(k >= 300, "{target}: stopped at step {k}");
        // One message, from rank 0, for the step every rank stopped after.
        assert_eq!(
            log.matches(&format!("after step {k}:")).count(),
            1,
            "{target}:\n{log}"
        );
        let name = format!("step_{k:010}.ckpt");
        let c = read_checkpoint(&out.join("checkpoints").join(&name)).unwrap();
        assert_eq!(c.step, k, "{target}");
        println!(
            "{target}: every rank stopped after step {k} ({})",
            summary["signal"]
        );
        first.get_or_insert((out, k));
    }
    // The first interrupted run's checkpoint, restarted on 2 ranks for 100 steps, against one
    // rank run straight through.
    let (stopped, k) = first.unwrap();
    let ck = stopped.join(format!("checkpoints/step_{k:010}.ckpt"));
    let (resumed, straight) = (dir.join("resumed"), dir.join("straight"));
    let until = (k + 100).to_string();
    let s = run_ok(
        2,
        &scene,
        &resumed,
        &["--restart", ck.to_str().unwrap(), "--max-steps", "100"],
    );
    assert_eq!(s["final_step"], k + 100);
    run_ok(1, &scene, &straight, &["--max-steps", &until]);
    same_checkpoint(
        &straight,
        &resumed,
        &format!("step_{:010}.ckpt", k + 100),
        "restart of the interrupted run",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every neighbour mode on 2 GPU ranks ends bitwise like one GPU in `gpu` mode (double): a
/// decomposed run builds on the device after the host's exchange whatever the mode
/// (docs/design.md §7), and the mode is not part of the checkpoint's scene fingerprint.
#[test]
#[ignore = "needs a CUDA GPU"]
fn every_neighbor_mode_on_two_gpu_ranks_matches_one_gpu() {
    let one = temp_dir("mpi-gpu-modes-1");
    run_gpu(
        1,
        "launch/mpi/pour.toml",
        &one,
        "double",
        &["--neighbor-mode", "gpu"],
    );
    for mode in ["gpu", "cpu", "hybrid", "auto"] {
        let dir = temp_dir(&format!("mpi-gpu-modes-2-{mode}"));
        let s = run_gpu(
            2,
            "launch/mpi/pour.toml",
            &dir,
            "double",
            &["--neighbor-mode", mode],
        );
        assert_eq!(s["neighbor"]["mode"], mode);
        assert_eq!(
            s["neighbor"]["builder"], "gpu",
            "a decomposed run builds on the device"
        );
        for step in ["step_0000001000.ckpt", "step_0000002000.ckpt"] {
            same_checkpoint(&one, &dir, step, &format!("2 GPU ranks, mode {mode}"));
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
    let _ = std::fs::remove_dir_all(&one);
}
