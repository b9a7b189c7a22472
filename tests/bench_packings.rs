//! Settled random packings for the benchmarks: `polydem pack` compresses a loose periodic box
//! to a target number of contacts per particle, and `[[insertions]] packing` tiles the cell.
//!
//! - Frictionless spheres compressed to Z = 6 (isostatic) must land at random close packing,
//!   φ ≈ 0.64 (O'Hern et al., Phys. Rev. E 68, 011306, 2003: φ_J = 0.639 ± 0.001 for
//!   monodisperse frictionless spheres; faster compressions jam slightly lower).
//! - A tiled packing is the cell repeated: `tiles` times its contacts, each particle the force
//!   of its image in the cell.
//! - Bad packing insertions are refused with the key named.

mod common;

use common::{repo_root, temp_dir};
use polydem::io::Packing;
use polydem::pipeline::Simulation;
use polydem::run::{PackOptions, pack};
use polydem::run_state::RunState;
use polydem::scene::{SceneError, parse_scene};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const SPHERES: usize = 500;

/// A fully periodic box `[0, max]` of 1 mm spheres without gravity, friction `mu`, and one
/// insertion of `insertion` (TOML lines after `type`).
fn sphere_box(max: [f64; 3], mu: f64, insertion: &str) -> String {
    let [x, y, z] = max;
    format!(
        r#"gravity = [0.0, 0.0, 0.0]
[simulation]
dt_fraction = 0.05
end_time = 1.0
seed = 5
[domain]
min = [0.0, 0.0, 0.0]
max = [{x:?}, {y:?}, {z:?}]
periodic = [true, true, true]
[[materials]]
name = "grain"
youngs_modulus = 1.0e7
poisson_ratio = 0.3
density = 2500.0
[[material_pairs]]
materials = ["grain", "grain"]
restitution = 0.5
friction = {mu:?}
[[particle_types]]
name = "sphere"
material = "grain"
generator = {{ kind = "sphere", size = 0.001 }}
[[insertions]]
type = "sphere"
{insertion}
"#
    )
}

/// A loose box of `SPHERES` frictionless spheres at solid fraction 0.15.
fn loose_spheres() -> String {
    let l = (SPHERES as f64 * std::f64::consts::PI / 6.0 * 1e-9 / 0.15).cbrt();
    let m = l - 0.0005;
    sphere_box(
        [l; 3],
        0.0,
        &format!(
            "region = {{ kind = \"box\", min = [0.0005, 0.0005, 0.0005], max = [{m}, {m}, {m}] }}\n\
             count = {SPHERES}\nmax_attempts = 100000"
        ),
    )
}

/// [`loose_spheres`] compressed to Z = 6 on `backend` in double precision, in a fresh folder
/// `dir`: the packing file and `pack`'s report.
fn pack_loose_spheres(
    dir: &str,
    backend: polydem::backend::BackendChoice,
) -> (PathBuf, serde_json::Value) {
    let dir = temp_dir(dir);
    let scene = dir.join("loose.toml");
    std::fs::write(&scene, loose_spheres()).unwrap();
    let out = dir.join("spheres.packing");
    let report = pack(&PackOptions {
        scene,
        contacts: 6.0,
        out: out.clone(),
        backend,
        precision: polydem::Precision::Double,
    })
    .expect("pack");
    (out, report)
}

/// The packing of [`loose_spheres`] at Z = 6 on the CPU (made once) and `pack`'s report.
fn packed() -> &'static (PathBuf, serde_json::Value) {
    static PACKED: OnceLock<(PathBuf, serde_json::Value)> = OnceLock::new();
    PACKED.get_or_init(|| pack_loose_spheres("bench-packing", polydem::backend::BackendChoice::Cpu))
}

/// A scene tiling `packing` `tiles` times, μ = 0.5 (with `extra` lines added to the insertion).
fn tiled_scene(packing: &Path, cell: [f64; 3], tiles: [u64; 3], count: u64, extra: &str) -> String {
    let [x, y, z] = [0, 1, 2].map(|a| cell[a] * tiles[a] as f64);
    sphere_box(
        [x, y, z],
        0.5,
        &format!(
            "region = {{ kind = \"box\", min = [0.0, 0.0, 0.0], max = [{x:?}, {y:?}, {z:?}] }}\n\
             count = {count}\npacking = \"{}\"\n{extra}",
            packing.display()
        ),
    )
}

fn cell_of(packing: &Path) -> ([f64; 3], usize) {
    let p = Packing::read(packing).unwrap();
    ([p.cell.x, p.cell.y, p.cell.z], p.particles.len())
}

#[test]
fn frictionless_spheres_compress_to_random_close_packing() {
    let (out, report) = packed();
    let z = report["contacts_per_particle"].as_f64().unwrap();
    let phi = report["solid_fraction"].as_f64().unwrap();
    assert!(z >= 6.0, "stopped at Z = {z}");
    assert!(
        (0.60..=0.66).contains(&phi),
        "φ = {phi} at Z = {z}: random close packing is 0.64 (0.60–0.66 allowed for the rate)"
    );
    let p = Packing::read(out).unwrap();
    assert_eq!(p.particles.len(), SPHERES);
    // The solid fraction of the written cell is the report's.
    let v = SPHERES as f64 * std::f64::consts::PI / 6.0 * 1e-9;
    let cell_phi = v / (p.cell.x * p.cell.y * p.cell.z);
    assert!((cell_phi - phi).abs() <= 1e-9 * phi, "{cell_phi} vs {phi}");
}

/// The compression on the GPU in double precision is the CPU's, bit for bit: the same cycles
/// and steps and the same packing. Each rescale of the box is followed by a refresh of the
/// forces (`Backend::refresh`), on the device on the GPU and by the pipeline on the CPU; the
/// step of a sphere packing is bitwise the same on both (tests/gpu_pipeline.rs), so any
/// difference is the refresh's.
#[test]
#[ignore = "needs a CUDA GPU"]
fn compression_on_the_gpu_is_the_cpus() {
    let (cpu_out, cpu_report) = packed();
    let (out, report) =
        pack_loose_spheres("bench-packing-gpu", polydem::backend::BackendChoice::Cuda);
    println!("CPU: {cpu_report}\nGPU: {report}");
    for key in ["cycles", "steps", "contacts_per_particle", "solid_fraction"] {
        assert_eq!(report[key], cpu_report[key], "{key}");
    }
    let (g, c) = (
        Packing::read(&out).unwrap(),
        Packing::read(cpu_out).unwrap(),
    );
    if g != c {
        // Say how: the cell, the order (the same grains in another order) or the grains.
        let key = |p: &polydem::io::packing::PackedParticle| {
            [p.position.x, p.position.y, p.position.z].map(f64::to_bits)
        };
        let (mut kg, mut kc): (Vec<_>, Vec<_>) = (
            g.particles.iter().map(key).collect(),
            c.particles.iter().map(key).collect(),
        );
        let in_order = g
            .particles
            .iter()
            .zip(&c.particles)
            .filter(|(a, b)| a != b)
            .count();
        let gap = g
            .particles
            .iter()
            .zip(&c.particles)
            .map(|(a, b)| (a.position - b.position).norm())
            .fold(0.0, f64::max);
        kg.sort();
        kc.sort();
        panic!(
            "the GPU's packing differs from the CPU's: cells {:?} vs {:?}; {in_order} of {} \
             particles differ in file order (positions by ≤ {gap:.3e} m); as sets of positions \
             they are {}",
            g.cell,
            c.cell,
            g.particles.len(),
            if kg == kc { "the same" } else { "different" }
        );
    }
}

#[test]
fn a_tiled_packing_repeats_the_cell_s_contacts_and_forces() {
    let (out, _) = packed();
    let (cell, n) = cell_of(out);
    let dir = temp_dir("bench-packing-tiled");
    let build = |tiles: [u64; 3]| {
        let count = n as u64 * tiles.iter().product::<u64>();
        let text = tiled_scene(out, cell, tiles, count, "");
        let scene = parse_scene(&text, &dir, "tiled.toml").expect("tiled scene");
        Simulation::builder(scene).build().expect("placed")
    };
    let one = build([1, 1, 1]);
    let tiles = [2, 1, 3];
    let many = build(tiles);
    assert_eq!(many.state.particles.len(), 6 * n);
    assert!(
        one.state.stats.contacts > 2 * n as u64,
        "{} contacts",
        one.state.stats.contacts
    );
    assert_eq!(many.state.stats.contacts, 6 * one.state.stats.contacts);
    // Particle j of tile t is particle j mod n of the cell, shifted by whole cells: the same
    // force up to the rounding of the shifted centres.
    let scale = one
        .state
        .particles
        .force
        .iter()
        .map(|f| f.norm())
        .fold(0.0, f64::max);
    let by_id = |s: &RunState| {
        let mut v: Vec<(u64, usize)> = s.particles.id.iter().copied().zip(0..).collect();
        v.sort();
        v
    };
    let (ones, manys) = (by_id(&one.state), by_id(&many.state));
    for (k, &(_, i)) in manys.iter().enumerate() {
        let j = ones[k % n].1;
        let (a, b) = (many.state.particles.force[i], one.state.particles.force[j]);
        assert!(
            (a - b).norm() <= 1e-6 * scale,
            "particle {k}: {a:?} against its cell image {b:?}"
        );
    }
}

#[test]
fn bad_packing_insertions_name_the_key() {
    let (out, _) = packed();
    let (cell, n) = cell_of(out);
    let dir = temp_dir("bench-packing-bad");
    let n = n as u64;
    let reject = |text: String, key: &str, words: &str| {
        let e: SceneError = match parse_scene(&text, &dir, "bad.toml") {
            Ok(_) => panic!("accepted, want {key} refused"),
            Err(e) => e,
        };
        let msg = e.to_string();
        assert!(
            e.keys().contains(&key) && msg.contains(words),
            "want {key} / {words:?}: {msg}"
        );
    };
    reject(
        tiled_scene(out, cell, [2, 1, 1], n, ""),
        "insertions[0].count",
        "× 2×1×1 cells = ",
    );
    let off = [cell[0] * 1.5, cell[1], cell[2]];
    reject(
        tiled_scene(out, off, [1, 1, 1], n, ""),
        "insertions[0].region",
        "whole number of the packing's cells",
    );
    reject(
        tiled_scene(out, cell, [1, 1, 1], n, r#"orientation = "random""#),
        "insertions[0].orientation",
        "not allowed with packing",
    );
    reject(
        tiled_scene(&dir.join("none.packing"), cell, [1, 1, 1], n, ""),
        "insertions[0].packing",
        "none.packing",
    );
    let scaled = tiled_scene(out, cell, [1, 1, 1], n, "")
        .replace("size = 0.001 }", "size = 0.001 }\nscale = 2.0");
    reject(scaled, "insertions[0].packing", "fixed scale (Fixed(2.0))");
}

/// The committed packings parse, and each bench scene that tiles one is valid, with a count
/// the tiling gives (scripts/settled_benches.py writes them).
#[test]
fn committed_settled_benches_load() {
    let dir = repo_root().join("launch/bench/settled");
    let mut scenes = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let scene = parse_scene(&text, &dir, &path.display().to_string())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let tiled = scene.insertions[0].packing.as_ref().expect("a packing");
        assert_eq!(tiled.count(), tiled.tiles.iter().product::<u64>() * 4000);
        scenes += 1;
    }
    assert_eq!(scenes, 12, "four shapes at three sizes");
}

/// The restart fingerprint covers the packing's contents, not the path it was reached by: the
/// same scene read from two directories fingerprints alike, and a changed packing does not.
#[test]
fn the_fingerprint_follows_the_packing_not_its_path() {
    use polydem::scene::restart::SceneFingerprint;
    let (out, _) = packed();
    let (cell, n) = cell_of(out);
    let (a, b) = (
        temp_dir("bench-packing-fp-a"),
        temp_dir("bench-packing-fp-b"),
    );
    let mut text = Packing::read(out).unwrap().to_text(&[]);
    std::fs::write(a.join("cell.packing"), &text).unwrap();
    std::fs::write(b.join("cell.packing"), &text).unwrap();
    let scene = |dir: &Path| {
        let t = tiled_scene(Path::new("cell.packing"), cell, [1, 1, 1], n as u64, "");
        SceneFingerprint::of(&parse_scene(&t, dir, "fp.toml").unwrap())
    };
    assert_eq!(scene(&a), scene(&b));
    // One particle moved by a micrometre: another fingerprint.
    let line = text.lines().nth(4).unwrap().to_string();
    let first: f64 = line.split_whitespace().next().unwrap().parse().unwrap();
    text = text.replacen(
        &line,
        &line.replacen(
            line.split_whitespace().next().unwrap(),
            &format!("{:.11e}", first + 1e-6),
            1,
        ),
        1,
    );
    std::fs::write(b.join("cell.packing"), &text).unwrap();
    assert_ne!(scene(&a), scene(&b));
}
