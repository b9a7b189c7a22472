//! The step on the GPU against the CPU backend (run on a GPU machine: `--include-ignored`).
//!
//! A dense pour with walls, friction and a rate insertion still running (so the host exchange
//! path, the history upload and the list rebuilds with reordering are all exercised) is run on
//! both backends from the same initial state; particles are matched by global id.

mod common;

use common::*;
use polydem::Precision;
use polydem::pipeline::{RestoredState, Simulation};
use polydem::run_state::RunState;
use polydem::scene::parse_scene;
use std::collections::HashMap;

/// The dense pour of [`dense_pour_text`] (seed 5, 1 m/s).
fn scene_text(kind: &str) -> String {
    dense_pour_text(kind, 5, 1.0)
}

fn scene() -> polydem::scene::Scene {
    parse_scene(
        &scene_text("dodecahedron"),
        &repo_root(),
        "gpu_pipeline.toml",
    )
    .unwrap()
}

fn sphere_scene() -> polydem::scene::Scene {
    parse_scene(&scene_text("sphere"), &repo_root(), "gpu_pipeline.toml").unwrap()
}

fn simulation() -> Simulation {
    Simulation::builder(scene()).build().unwrap()
}

/// A simulation of `scene` restored from the state of `s` (particles, contact history,
/// inserter, time), as a checkpoint restores it.
fn restored(scene: polydem::scene::Scene, s: &RunState) -> Simulation {
    Simulation::builder(scene)
        .restore(RestoredState {
            particles: s.particles.clone(),
            history: s.history.clone(),
            inserter: s.inserter.clone(),
            time: s.time,
            step: s.step,
            next_id: s.next_id,
        })
        .build()
        .unwrap()
}

/// Largest differences, by global id, of position (relative to the particle size), velocity
/// (relative to the largest speed) and force (relative to the largest force).
fn compare(cpu: &RunState, gpu: &RunState) -> (f64, f64, f64) {
    let (a, b) = (&cpu.particles, &gpu.particles);
    assert_eq!(a.len(), b.len(), "particle counts");
    let index: HashMap<u64, usize> = b.id.iter().enumerate().map(|(i, &g)| (g, i)).collect();
    let vmax = a.velocity.iter().map(|v| v.norm()).fold(1e-30, f64::max);
    let fmax = a.force.iter().map(|v| v.norm()).fold(1e-30, f64::max);
    let (mut dx, mut dv, mut df) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..a.len() {
        let j = index[&a.id[i]];
        dx = dx.max((a.position[i] - b.position[j]).norm() / 0.012);
        dv = dv.max((a.velocity[i] - b.velocity[j]).norm() / vmax);
        df = df.max((a.force[i] - b.force[j]).norm() / fmax);
    }
    (dx, dv, df)
}

/// From the same mid-pour state (3000 CPU steps: wall and particle contacts with live
/// springs), moved onto the GPU with its contact history: the first step builds the same
/// candidate pair list on both (compared as global-id pairs), and after three steps the same
/// contacts (pair and wall keys), springs and forces, bit for bit. Double mode follows the
/// CPU's order of operations (no FMA contraction), and the only functions beyond + − × ÷ √ on
/// the step's path, the law's cube roots and the rotation's sin and cos, are portable ones
/// shared with the Rust code (`portable_cbrt`, `portable_sin_cos`); logarithms are taken on
/// the host.
///
/// Mixed mode (f32 pair geometry): the same pair list (it is built in f64), and per-particle
/// forces within 1e-3 of the largest force: each contact's V and S carry at most 1e-4 relative
/// error in f32 (tests/cuda_geometry_host.rs, V > 1e-6 V_small), a particle sums about six
/// contacts, and contacts shallower than that carry forces below 1e-4 of the largest (F ∝
/// V^{1/3} A_n).
#[test]
#[ignore = "needs a CUDA GPU"]
fn three_steps_from_a_cpu_state_match_contact_by_contact() {
    // A dense state: the pour stepped until it holds more than 100 contacts (3000 steps with
    // the damping of the time this test was written; how long depends on the contact law).
    let mut start = simulation();
    while start.state.history.len() <= 100 {
        assert!(
            start.state.step < 20_000,
            "only {} contacts after 20 000 steps",
            start.state.history.len()
        );
        start.step().unwrap();
    }
    let copy = |s: &RunState| restored(scene(), s);
    for precision in [Precision::Double, Precision::Mixed] {
        // Both start from a restored copy, so both build their list at the first step.
        let mut cpu = copy(&start.state);
        let mut engine = gpu_engine(copy(&start.state), precision);
        let gpu = engine.cuda_mut().unwrap();
        cpu.step().unwrap();
        gpu.step().unwrap();
        let (lc, lg) = (cpu.candidate_pair_ids(), gpu.candidate_pair_ids().unwrap());
        println!(
            "{precision:?}: {} candidate pairs on the CPU, {} on the GPU",
            lc.len(),
            lg.len()
        );
        assert!(lc.len() > 200, "{} candidate pairs", lc.len());
        assert!(lc == lg, "{precision:?}: candidate pair lists differ");
        for _ in 0..2 {
            cpu.step().unwrap();
            gpu.step().unwrap();
        }
        let g = gpu.sync_host().unwrap();
        let (dx, dv, df) = compare(&cpu.state, g);
        let keys = |s: &RunState| -> Vec<_> { s.history.entries().iter().map(|e| e.0).collect() };
        if precision == Precision::Mixed {
            println!(
                "Mixed: {} contacts on the CPU, {} on the GPU; worst relative: position {dx:.2e}, \
                 velocity {dv:.2e}, force {df:.2e}",
                cpu.state.history.len(),
                g.history.len()
            );
            assert!(
                df <= 1e-3,
                "mixed: per-particle force off by {df:.2e} of the largest"
            );
            continue;
        }
        assert_eq!(keys(&cpu.state), keys(g), "contact sets differ");
        let smax = cpu
            .state
            .history
            .entries()
            .iter()
            .map(|e| e.1.spring.norm())
            .fold(1e-30, f64::max);
        let worst_spring = cpu
            .state
            .history
            .entries()
            .iter()
            .zip(g.history.entries())
            .map(|(a, b)| (a.1.spring - b.1.spring).norm() / smax)
            .fold(0.0, f64::max);
        println!(
            "Double: {} contacts ({} with walls); worst relative: spring {worst_spring:.2e}, \
             position {dx:.2e}, velocity {dv:.2e}, force {df:.2e}",
            cpu.state.history.len(),
            cpu.state.stats.wall_contacts
        );
        assert_eq!(cpu.state.stats.contacts, g.stats.contacts);
        assert_eq!(cpu.state.stats.wall_contacts, g.stats.wall_contacts);
        assert!(cpu.state.stats.wall_contacts > 0 && cpu.state.stats.contacts > 0);
        assert!(worst_spring == 0.0 && df == 0.0 && dv == 0.0 && dx == 0.0);
    }
}

/// 1000 steps of the pour (with the insertion of the fed particles on the host, list rebuilds
/// with reordering, wall and particle contacts with friction). Double mode: bitwise equal to
/// the CPU (the kernels follow the CPU's order of operations and the reduction is in
/// partner-id order on both), the elastic energy and the walls' forces included (summed in
/// global id order on both). Mixed mode (f32 pair geometry): the overlap volumes carry up to
/// 1e-4 relative error on shallow contacts (the geometry test set's bound) and a granular
/// packing amplifies differences over hundreds of collisions, so the bound is 1e-6 of the
/// particle size for positions and 1e-4 of the largest speed (measured on the H100: 8.6e-9
/// and 1.0e-7).
#[test]
#[ignore = "needs a CUDA GPU"]
fn a_thousand_steps_of_a_dense_pour_match_the_cpu() {
    for precision in [Precision::Double, Precision::Mixed] {
        let mut cpu = simulation();
        let mut engine = gpu_engine(scene_start(scene()), precision);
        let gpu = engine.cuda_mut().unwrap();
        let mut worst = (0.0f64, 0.0f64, 0.0f64);
        for k in 1..=1000 {
            cpu.step().unwrap();
            gpu.step().unwrap();
            if k % 100 == 0 {
                let d = compare(&cpu.state, gpu.sync_host().unwrap());
                println!(
                    "{precision:?} step {k}: position {:.2e} velocity {:.2e} force {:.2e}",
                    d.0, d.1, d.2
                );
                worst = (worst.0.max(d.0), worst.1.max(d.1), worst.2.max(d.2));
            }
        }
        let g = gpu.sync_host().unwrap();
        assert_eq!(g.particles.len(), cpu.state.particles.len());
        assert!(g.particles.len() > 240, "the fed particles arrived");
        if precision == Precision::Double {
            // The diagnostics too: both backends sum the elastic energy and the walls' forces
            // in global id order, whatever the device's order after its list builds.
            let bits = |s: &RunState| {
                let mut v = vec![s.stats.elastic_energy.to_bits()];
                v.extend(
                    s.wall_forces
                        .iter()
                        .flat_map(|f| f.iter().map(|c| c.to_bits())),
                );
                (s.stats.contacts, s.stats.wall_contacts, v)
            };
            assert_eq!(
                bits(g),
                bits(&cpu.state),
                "diagnostics of the GPU against the CPU"
            );
        }
        let (tol_x, tol_v) = match precision {
            Precision::Double => (0.0, 0.0),
            Precision::Mixed => (1e-6, 1e-4),
        };
        assert!(
            worst.0 <= tol_x && worst.1 <= tol_v,
            "{precision:?}: position {:.2e} velocity {:.2e}",
            worst.0,
            worst.1
        );
    }
}

/// The sphere fast path: 6000 steps (0.12 s) of the same pour with spheres (lens and facet-cap
/// overlaps, `cuda/sphere.cuh`), bit for bit equal to the CPU. The sphere geometry is f64 in both
/// modes, so mixed equals double too. The kernels follow the Rust operation order (the headers'
/// host parity is bitwise, tests/cuda_geometry_host.rs) and use only + − × ÷ √, the portable
/// atan2 of `geometry::sphere` and the law's cbrt; with the GPU's own atan2, sin and cos the
/// runs drifted apart from 1e-16 at step 500 to 3e-9 of the size at step 6000.
#[test]
#[ignore = "needs a CUDA GPU"]
fn six_thousand_steps_of_a_sphere_pour_match_the_cpu() {
    let mut cpu = Simulation::builder(sphere_scene()).build().unwrap();
    let mut double = gpu_engine(scene_start(sphere_scene()), Precision::Double);
    let double = double.cuda_mut().unwrap();
    let mut mixed = gpu_engine(scene_start(sphere_scene()), Precision::Mixed);
    let mixed = mixed.cuda_mut().unwrap();
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for k in 1..=6000 {
        cpu.step().unwrap();
        double.step().unwrap();
        mixed.step().unwrap();
        if k % 500 == 0 {
            let d = compare(&cpu.state, double.sync_host().unwrap());
            let m = compare(double.sync_host().unwrap(), mixed.sync_host().unwrap());
            println!(
                "spheres step {k}: {} contacts, {} wall contacts; GPU vs CPU: position {:.2e} \
                 velocity {:.2e} force {:.2e}; mixed vs double {:?}",
                cpu.state.stats.contacts, cpu.state.stats.wall_contacts, d.0, d.1, d.2, m
            );
            assert_eq!(m, (0.0, 0.0, 0.0), "mixed differs from double for spheres");
            worst = (worst.0.max(d.0), worst.1.max(d.1), worst.2.max(d.2));
        }
    }
    assert!(cpu.state.stats.contacts > 100 && cpu.state.stats.wall_contacts > 50);
    assert_eq!(
        double.sync_host().unwrap().particles.len(),
        cpu.state.particles.len()
    );
    assert!(
        worst == (0.0, 0.0, 0.0),
        "position {:.2e} velocity {:.2e} force {:.2e}",
        worst.0,
        worst.1,
        worst.2
    );
}

/// Rolling friction (`[[material_pairs]] rolling_friction`, docs/contact.md §5) on the GPU is
/// the CPU's bit for bit: the dense pour of dodecahedra in double and in mixed precision (against
/// its CPU twin) and of spheres, 10 000 steps each, with the couple on pair and wall contacts.
#[test]
#[ignore = "needs a CUDA GPU"]
fn rolling_friction_on_the_gpu_is_bitwise_the_cpu() {
    let dir = temp_dir("gpu-rolling");
    for (kind, precision) in [
        ("dodecahedron", "double"),
        ("dodecahedron", "mixed"),
        ("sphere", "double"),
    ] {
        let text = rolling_pour_text(kind);
        let scene = dir.join(format!("rolling_{kind}.toml"));
        std::fs::write(&scene, text).unwrap();
        let tag = format!("rolling-{kind}-{precision}");
        let what = format!("rolling friction, {kind}, GPU {precision}");
        both_end_bitwise_equal(precision, &scene, 10_000, &[], 100, &tag, &what);
    }
}

/// The dense pour of `kind` with rolling friction 0.1 between grains and 0.05 on the walls, and
/// a checkpoint at its end.
fn rolling_pour_text(kind: &str) -> String {
    let text = scene_text(kind)
        .replace(
            "friction = 0.5\n",
            "friction = 0.5\nrolling_friction = 0.1\n",
        )
        .replace(
            "friction = 0.4\n",
            "friction = 0.4\nrolling_friction = 0.05\n",
        )
        .replace("[output]\n", "[output]\ncheckpoint_interval = 1.0\n");
    assert_eq!(text.matches("rolling_friction").count(), 2);
    assert!(text.contains("checkpoint_interval"));
    text
}

/// Runs `scene` with `polydem run` on the CPU and on the GPU (double precision), with
/// `--max-steps` when given and with the environment `env` on the GPU run, and returns the
/// final checkpoints (CPU first).
fn run_on_both(
    scene: &std::path::Path,
    max_steps: Option<u64>,
    gpu_env: &[(&str, &str)],
    tag: &str,
) -> Vec<polydem::io::Checkpoint> {
    run_on_both_in("double", scene, max_steps, gpu_env, tag)
}

/// [`run_on_both`] with the pair geometry in `precision` on both backends (`mixed`: the CPU
/// evaluates it as the GPU's mixed precision does).
fn run_on_both_in(
    precision: &str,
    scene: &std::path::Path,
    max_steps: Option<u64>,
    gpu_env: &[(&str, &str)],
    tag: &str,
) -> Vec<polydem::io::Checkpoint> {
    run_on_both_with(precision, scene, max_steps, &[], gpu_env, tag)
}

/// [`run_on_both_in`] with the environment `env` on both runs as well.
fn run_on_both_with(
    precision: &str,
    scene: &std::path::Path,
    max_steps: Option<u64>,
    env: &[(&str, &str)],
    gpu_env: &[(&str, &str)],
    tag: &str,
) -> Vec<polydem::io::Checkpoint> {
    use polydem::io::read_checkpoint;
    let dir = temp_dir(&format!("gpu-run-{tag}"));
    let mut last = Vec::new();
    for (backend, backend_env) in [("cpu", &[][..]), ("cuda", gpu_env)] {
        let out = dir.join(backend);
        let mut cmd = std::process::Command::new(polydem_bin());
        cmd.envs(env.iter().copied());
        cmd.envs(backend_env.iter().copied());
        cmd.args(["run", scene.to_str().unwrap(), "--backend", backend]);
        cmd.args(["--gpu-precision", precision, "--out"]).arg(&out);
        if let Some(n) = max_steps {
            cmd.args(["--max-steps", &n.to_string()]);
        }
        let status = cmd.output().unwrap();
        assert!(
            status.status.success(),
            "{tag} on {backend}: {}",
            String::from_utf8_lossy(&status.stderr)
        );
        last.push(read_checkpoint(&out.join("checkpoints/latest.ckpt")).unwrap());
    }
    last
}

/// Runs `scene` for `steps` on both backends in `precision` (with `env` on both) and requires
/// both to reach the step, the CPU's end to hold more than `contacts` contacts, and the two
/// final states to be bitwise equal (`what` names the comparison).
fn both_end_bitwise_equal(
    precision: &str,
    scene: &std::path::Path,
    steps: u64,
    env: &[(&str, &str)],
    contacts: usize,
    tag: &str,
    what: &str,
) {
    let last = run_on_both_with(precision, scene, Some(steps), env, &[], tag);
    assert_eq!(last[0].step, steps, "{tag}");
    assert!(
        last[0].history.len() > contacts,
        "{tag}: {} contacts",
        last[0].history.len()
    );
    assert_bitwise_equal(checkpoint_view(&last[0]), checkpoint_view(&last[1]), what);
}

/// A state to compare: step, time, particles, contact history.
type StateView<'a> = (
    u64,
    f64,
    &'a polydem::state::Particles,
    &'a polydem::contact::ContactHistory,
);

fn checkpoint_view(c: &polydem::io::Checkpoint) -> StateView<'_> {
    (c.step, c.time, &c.particles, &c.history)
}

fn simulation_view(s: &RunState) -> StateView<'_> {
    (s.step, s.time, &s.particles, &s.history)
}

/// Asserts that two states are bitwise the same: step, time, contact histories, and every
/// particle's position, velocity, orientation, angular velocity, force and torque (matched by
/// id).
fn assert_bitwise_equal(c: StateView, g: StateView, what: &str) {
    assert_eq!(
        (c.0, c.1.to_bits()),
        (g.0, g.1.to_bits()),
        "{what}: step and time"
    );
    let index: HashMap<u64, usize> = g.2.id.iter().enumerate().map(|(i, &x)| (x, i)).collect();
    let (a, b) = (c.2, g.2);
    assert_eq!(a.len(), b.len(), "{what}: particle counts");
    // On a difference, say how many particles differ in which field and by how much at most,
    // and how the contact histories differ, before failing: one failed device run then tells
    // where to look.
    let fields = [
        "position",
        "velocity",
        "orientation",
        "angular velocity",
        "force",
        "torque",
    ];
    let mut differing = [0usize; 6];
    let mut largest = [0.0f64; 6];
    let mut first = None;
    for i in 0..a.len() {
        let j = index[&a.id[i]];
        let gaps = [
            (
                a.position[i] == b.position[j],
                (a.position[i] - b.position[j]).norm(),
            ),
            (
                a.velocity[i] == b.velocity[j],
                (a.velocity[i] - b.velocity[j]).norm(),
            ),
            (
                a.orientation[i] == b.orientation[j],
                a.orientation[i].angle_to(&b.orientation[j]),
            ),
            (
                a.angular_velocity[i] == b.angular_velocity[j],
                (a.angular_velocity[i] - b.angular_velocity[j]).norm(),
            ),
            (a.force[i] == b.force[j], (a.force[i] - b.force[j]).norm()),
            (
                a.torque[i] == b.torque[j],
                (a.torque[i] - b.torque[j]).norm(),
            ),
        ];
        for (k, (same, gap)) in gaps.into_iter().enumerate() {
            if !same {
                differing[k] += 1;
                largest[k] = largest[k].max(gap);
                first.get_or_insert(a.id[i]);
            }
        }
    }
    let (hc, hg) = (c.3.entries(), g.3.entries());
    let history_same = c.3 == g.3;
    if !history_same || first.is_some() {
        let keys_c: std::collections::HashSet<_> = hc.iter().map(|e| e.0).collect();
        let keys_g: std::collections::HashSet<_> = hg.iter().map(|e| e.0).collect();
        let by_key: HashMap<_, _> = hg.iter().map(|(k, s)| (*k, s)).collect();
        let states_differ = hc
            .iter()
            .filter(|(k, s)| by_key.get(k).is_some_and(|sg| *sg != s))
            .count();
        let mut report = format!(
            "{what}: contact histories {} ({} vs {} contacts, {} only on the CPU, {} only on the \
             GPU, {} with different states); particles:",
            if history_same { "equal" } else { "differ" },
            hc.len(),
            hg.len(),
            keys_c.difference(&keys_g).count(),
            keys_g.difference(&keys_c).count(),
            states_differ,
        );
        for k in 0..6 {
            report += &format!(" {} {} (≤ {:.3e})", fields[k], differing[k], largest[k]);
        }
        if let Some(id) = first {
            report += &format!("; first differing id {id}");
        }
        panic!("{report}");
    }
}

/// `polydem run` end to end on both backends: the quickstart (2000 dodecahedra poured into the
/// hopper STL and onto the floor), to the scene's end (t = 0.12 s, when the cone has formed),
/// ends in checkpoints with bitwise equal particle states (matched by id) and contact
/// histories. A second GPU run that merges no grid cells when it builds the wall list
/// (`POLYDEM_WALL_MERGE_CELLS=0`) sends every particle down the fallback walk of the facet
/// grid, and must end bitwise the same too (to step 12000, where the cone fills).
///
/// Before the free rotation's sin and cos were evaluated by `portable_sin_cos` on both
/// backends, the GPU's libdevice and the CPU's libm differed in the last bit for some angle,
/// and the GPU left the CPU from step 6600 on. A third GPU run takes the lean pair passes in
/// batches of 97 pairs (`POLYDEM_PAIR_BATCH`, as a list of millions of pairs takes them) and
/// must end bitwise the same at step 12000.
#[test]
#[ignore = "needs a CUDA GPU"]
fn the_quickstart_on_the_gpu_ends_bitwise_equal_to_the_cpu() {
    let scene = repo_root().join("launch/quickstart/quickstart.toml");
    let last = run_on_both(&scene, None, &[], "quickstart");
    let c = &last[0];
    let dt = c.time / c.step as f64;
    assert!(
        c.time > 0.12 - 1.5 * dt && c.step > 7000,
        "the run ends at the scene's end_time (step {}, t = {})",
        c.step,
        c.time
    );
    assert!(c.history.len() > 1000, "{} contacts", c.history.len());
    assert_bitwise_equal(checkpoint_view(c), checkpoint_view(&last[1]), "GPU");
    let walk = run_on_both(
        &scene,
        Some(12000),
        &[("POLYDEM_WALL_MERGE_CELLS", "0")],
        "quickstart-walk",
    );
    assert_eq!(walk[0].step, 12000);
    assert_bitwise_equal(
        checkpoint_view(&walk[0]),
        checkpoint_view(&walk[1]),
        "GPU, walking the facet grid",
    );
    // The lean pair passes in batches of 97 pairs (a large list's batches, on a small one):
    // the same run, to step 12000 (the first pair contacts form after step 7000).
    let batched = run_on_both(
        &scene,
        Some(12000),
        &[("POLYDEM_PAIR_BATCH", "97")],
        "quickstart-batches",
    );
    assert_bitwise_equal(
        checkpoint_view(&batched[0]),
        checkpoint_view(&batched[1]),
        "GPU, lean passes in batches of 97 pairs",
    );
}

/// Mixed precision has a CPU twin (`--backend cpu --gpu-precision mixed`,
/// `geometry::pair::overlap_pair_mixed`): the same f32 geometry (the CUDA headers are bitwise
/// the Rust code in f32, tests/cuda_geometry_host.rs), the same routing of thin, unproven and
/// bent pairs to f64, f64 for the walls and the rest of the step. The quickstart in mixed
/// precision to step 12000 (pair contacts from step 7000 on, wall contacts before) on both
/// backends ends bitwise the same: a mixed-precision GPU run can be reproduced, and its
/// failures chased, on a CPU.
#[test]
#[ignore = "needs a CUDA GPU"]
fn the_quickstart_in_mixed_precision_is_its_cpu_twin_bit_for_bit() {
    let scene = repo_root().join("launch/quickstart/quickstart.toml");
    let last = run_on_both_in("mixed", &scene, Some(12000), &[], "quickstart-mixed");
    assert_eq!(last[0].step, 12000);
    assert!(
        last[0].history.len() > 100,
        "{} contacts",
        last[0].history.len()
    );
    assert_bitwise_equal(
        checkpoint_view(&last[0]),
        checkpoint_view(&last[1]),
        "GPU mixed against the CPU's mixed twin",
    );
}

/// Every scene of `launch/examples/` for 12000 steps on both backends, in double precision,
/// from the same initial state: bitwise equal states. The shaker's lowest cubes have landed in
/// the moving box by then; the hopper's grains (dt = 4e-7 s) are still falling towards its
/// mesh, and the box pour (dt = 9e-8 s, the default step) has inserted its first two grains:
/// the quickstart (the hopper's STL) and the dense pour above cover their contacts.
#[test]
#[ignore = "needs a CUDA GPU"]
fn the_examples_on_the_gpu_stay_bitwise_equal_to_the_cpu() {
    let dir = repo_root().join("launch/examples");
    let mut scenes: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    scenes.sort();
    assert!(scenes.len() >= 3, "{scenes:?}");
    for path in &scenes {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let mut text = std::fs::read_to_string(path).unwrap();
        if name == "shaker.toml" {
            // A coarse fixed step (the scene's own is 30 times finer), so that cubes land
            // within the 12000 steps: the backends are compared, not the physics.
            text = text.replace("[simulation]\n", "[simulation]\ndt = 2.0e-5\n");
        }
        let scene = || parse_scene(&text, &dir, &name).unwrap();
        let mut cpu = Simulation::builder(scene()).build().unwrap();
        let mut engine = gpu_engine(
            Simulation::builder(scene()).build().unwrap(),
            Precision::Double,
        );
        let gpu = engine.cuda_mut().unwrap();
        for _ in 0..12000 {
            cpu.step().unwrap();
            gpu.step().unwrap();
        }
        let g = gpu.sync_host().unwrap();
        println!(
            "{name}: {} particles, {} contacts at step 12000",
            cpu.state.particles.len(),
            cpu.state.history.len()
        );
        assert!(!cpu.state.particles.is_empty(), "{name}: no particles");
        if name == "shaker.toml" {
            assert!(
                cpu.state.history.len() > 20,
                "shaker: {} contacts",
                cpu.state.history.len()
            );
        }
        assert_bitwise_equal(simulation_view(&cpu.state), simulation_view(g), &name);
    }
}

/// Moving walls: the shaker example (300 cubes dropped into an open box shaken vertically,
/// 2 mm at 15 Hz) and the same box turning about its vertical axis at 120 rpm instead. From
/// the state after 6000 CPU steps (0.12 s: most cubes have landed and press on the floor and
/// on each other), moved onto the GPU with its contact history, 1500 more steps (0.03 s) on
/// both backends in double mode: bitwise equal positions, velocities and forces, as with fixed
/// walls. The GPU evaluates the walls from a list of candidate facets built with the skin
/// (again at each pair-list build, and when a particle or a wall moved half the skin in a
/// wall's frame); the CPU queries the facet grid every step. At 120 rpm the host's bound on the
/// box's motion (at the corners of the domain grown by the cutoff, 0.12 m from the axis)
/// reaches the half skin (0.6 mm) every 20 steps or so, so the wall list must have been built
/// more often than the pair list, or the test would not exercise the walls' part of that rule.
#[test]
#[ignore = "needs a CUDA GPU"]
fn moving_walls_on_the_gpu_match_the_cpu() {
    let dir = repo_root().join("launch/examples");
    // A coarse fixed step, so that most cubes have landed after 6000 steps (the scene's own
    // is 30 times finer): the backends are compared, not the physics.
    let shaker = std::fs::read_to_string(dir.join("shaker.toml"))
        .unwrap()
        .replace("[simulation]\n", "[simulation]\ndt = 2.0e-5\n");
    assert!(
        shaker.contains("dt = 2.0e-5"),
        "the shaker's [simulation] line"
    );
    let shaken = "motion = { kind = \"sinusoidal\", direction = [0.0, 0.0, 1.0], amplitude = 0.002, frequency = 15.0 }";
    assert!(shaker.contains(shaken), "the shaker's motion line");
    let turning = shaker.replace(
        shaken,
        "motion = { kind = \"rotate\", axis = [0.0, 0.0, 1.0], rpm = 120.0 }",
    );
    for (what, text) in [("shaken", &shaker), ("turning", &turning)] {
        let scene = || parse_scene(text, &dir, "shaker.toml").unwrap();
        let mut start = Simulation::builder(scene()).build().unwrap();
        for _ in 0..6000 {
            start.step().unwrap();
        }
        let copy = |s: &RunState| restored(scene(), s);
        let mut cpu = copy(&start.state);
        let mut engine = gpu_engine(copy(&start.state), Precision::Double);
        let gpu = engine.cuda_mut().unwrap();
        let mut worst = (0.0f64, 0.0f64, 0.0f64);
        // Contacts summed over the steps (the shaken bed is loose: 10–40 wall contacts at a
        // time on the CPU).
        let (mut wall_contacts, mut contacts) = (0u64, 0u64);
        for k in 1..=1500 {
            cpu.step().unwrap();
            gpu.step().unwrap();
            wall_contacts += cpu.state.stats.wall_contacts;
            contacts += cpu.state.stats.contacts;
            if k % 300 == 0 {
                let d = compare(&cpu.state, gpu.sync_host().unwrap());
                worst = (worst.0.max(d.0), worst.1.max(d.1), worst.2.max(d.2));
            }
        }
        let (pair_builds, wall_builds) = (gpu.pair_list_builds(), gpu.wall_list_builds());
        println!(
            "{what}: {wall_contacts} wall and {contacts} particle contact-steps; pair lists \
             {pair_builds}, wall lists {wall_builds}; GPU vs CPU: position {:.2e} velocity \
             {:.2e} force {:.2e}",
            worst.0, worst.1, worst.2
        );
        assert!(
            wall_contacts > 10_000 && contacts > 10_000,
            "{what}: the cubes lie in the box ({wall_contacts} wall and {contacts} particle \
             contact-steps)"
        );
        assert!(
            wall_builds >= pair_builds,
            "{what}: a wall list per pair list"
        );
        if what == "turning" {
            assert!(
                wall_builds > pair_builds,
                "turning: the box's motion rebuilt no wall list ({wall_builds} builds, \
                 {pair_builds} pair lists)"
            );
        }
        assert!(
            worst == (0.0, 0.0, 0.0),
            "{what}: position {:.2e} velocity {:.2e} force {:.2e}",
            worst.0,
            worst.1,
            worst.2
        );
        // The wall list the bench reports: built with the skin added to each particle's
        // reach and valid while no particle or wall has moved half the skin, so it holds
        // every facet the CPU finds within the bounding radius now, and more.
        let (cpu_items, cpu_particles) = cpu.wall_candidates();
        let (gpu_items, gpu_particles) = gpu.wall_candidates().unwrap();
        println!(
            "{what}: wall facets within reach: CPU {cpu_items} items on {cpu_particles} \
             particles, GPU list {gpu_items} on {gpu_particles}"
        );
        let n = cpu.state.particles.len() as u64;
        assert!(
            cpu_particles > 0 && cpu_items >= cpu_particles,
            "{what}: the cubes lie on the box's facets"
        );
        assert!(
            gpu_items >= cpu_items && gpu_particles >= cpu_particles && gpu_particles <= n,
            "{what}: the GPU's wall list ({gpu_items} items, {gpu_particles} particles) misses \
             facets the CPU finds ({cpu_items}, {cpu_particles}) or counts beyond {n} particles"
        );
    }
}

/// Many-faced grains, where most contacts keep 9–16 planes: 60 steps of the committed settled
/// cell of 4000 mineral grains (32 triangles; periodic, 14 058 contacts) by `polydem run` on both
/// backends, in double and in mixed precision, with the vertex enumeration taking up to 8
/// planes (`POLYDEM_ENUM_PLANES=8` on both: the GPU's deferred pass hulls the rest) and up to
/// 16 (the default of this many-faced scene, set explicitly: the lean passes stage them). Double ends bitwise equal to
/// the CPU at both settings; mixed, whose CPU twin evaluates the pair geometry as the GPU does,
/// too (the f32 geometry is the headers', bit for bit on the host, tests/cuda_geometry_host.rs).
#[test]
#[ignore = "needs a CUDA GPU"]
fn settled_many_faced_grains_end_bitwise_equal_to_the_cpu() {
    let text = mineral_cell_text();
    let dir = temp_dir("gpu-mineral-cell");
    let scene = dir.join("mineral_cell.toml");
    std::fs::write(&scene, text).unwrap();
    for planes in ["8", "16"] {
        for precision in ["double", "mixed"] {
            let tag = format!("minerals-{planes}-{precision}");
            let env = [("POLYDEM_ENUM_PLANES", planes)];
            let what = format!("GPU {precision}, enumeration up to {planes} planes");
            both_end_bitwise_equal(precision, &scene, 60, &env, 13_000, &tag, &what);
        }
    }
}

/// Rounded grains (`[[particle_types]] rounding`, 62 faces: most of their contacts keep more
/// than the lean passes' 8 planes and go to the deferred full evaluation): the small pour of
/// docs/validation.md §6b with its dodecahedra rounded by 0.3 of their radius, 10 000 steps
/// (the cloud lands from step 8000 on, 692 contacts at the end on the CPU), in double on both
/// backends and in mixed precision against its CPU twin: bitwise equal states.
#[test]
#[ignore = "needs a CUDA GPU"]
fn rounded_grains_on_the_gpu_are_bitwise_the_cpu() {
    let root = repo_root();
    let text = std::fs::read_to_string(root.join("launch/validation/pour_small.toml"))
        .unwrap()
        .replace("../../meshes/", &format!("{}/meshes/", root.display()))
        .replace("scale = 0.004\n", "scale = 0.004\nrounding = 0.3\n");
    assert!(text.contains("rounding = 0.3"));
    let dir = temp_dir("gpu-rounded");
    let scene = dir.join("rounded_pour.toml");
    std::fs::write(&scene, text).unwrap();
    for precision in ["double", "mixed"] {
        let tag = format!("rounded-{precision}");
        let what = format!("rounded grains, GPU {precision}");
        both_end_bitwise_equal(precision, &scene, 10_000, &[], 500, &tag, &what);
    }
}
