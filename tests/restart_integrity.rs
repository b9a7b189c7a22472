//! Restarts keep nothing silent and lose nothing: a checkpoint with bad contents or for another
//! scene is refused naming what is wrong, harmless scene edits are accepted, a restarted time
//! series equals the uninterrupted one byte for byte, temporary files of killed writes are
//! removed, and `output.checkpoint_keep` prunes old periodic checkpoints.

mod common;

use common::*;
use polydem::io::{read_checkpoint, write_checkpoint};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs polydem expecting failure; returns its stderr (which must not show a panic).
fn run_fails(args: &[&str]) -> String {
    let out = Command::new(polydem_bin())
        .arg("run")
        .args(args)
        .output()
        .expect("run polydem");
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "polydem run {args:?} succeeded");
    assert!(
        !err.contains("panicked"),
        "polydem run {args:?} panicked:\n{err}"
    );
    err
}

/// A run of `steps` steps of `scene` into `out`, its `latest.ckpt` returned.
fn first_run(scene: &Path, out: &Path, steps: &str) -> PathBuf {
    polydem_run(&[
        scene.to_str().unwrap(),
        "--backend",
        "cpu",
        "--out",
        out.to_str().unwrap(),
        "--max-steps",
        steps,
    ]);
    out.join("checkpoints/latest.ckpt")
}

/// Restart arguments: `scene` from `ckpt` into `out` for `steps` steps.
fn restart_args<'a>(
    scene: &'a Path,
    ckpt: &'a Path,
    out: &'a Path,
    steps: &'a str,
) -> Vec<&'a str> {
    vec![
        scene.to_str().unwrap(),
        "--backend",
        "cpu",
        "--out",
        out.to_str().unwrap(),
        "--restart",
        ckpt.to_str().unwrap(),
        "--max-steps",
        steps,
    ]
}

#[test]
fn checkpoints_with_bad_contents_are_refused_naming_the_field() {
    let dir = temp_dir("ckpt-contents");
    let scene = restart_scene(&dir);
    let good = read_checkpoint(&first_run(&scene, &dir.join("first"), "100")).unwrap();
    let bad = dir.join("bad.ckpt");
    let out = dir.join("out");
    type Edit = fn(&mut polydem::io::Checkpoint);
    let cases: [(Edit, &[&str]); 9] = [
        (
            |c| c.particles.kind[3] = 7,
            &["particle 3", "`kind` is 7", "1 particle type"],
        ),
        (
            |c| {
                c.particles.orientation[2] = nalgebra::UnitQuaternion::new_unchecked(
                    nalgebra::Quaternion::new(0.0, 0.0, 0.0, 0.0),
                )
            },
            &["particle 2", "`orientation`", "unit quaternion"],
        ),
        (
            |c| c.particles.id[1] = c.particles.id[0],
            &["particle 1", "`id`", "twice"],
        ),
        (
            |c| c.particles.scale[0] = -1.0,
            &["particle 0", "`scale` is -1", "> 0"],
        ),
        // Past the type's largest scale (1.2) by a relative 1e-13, the mass to match: the
        // neighbour cutoff and the halo are sized from that scale.
        (
            |c| {
                let s = 1.2 * (1.0 + 1e-13);
                c.particles.mass[0] *= (s / c.particles.scale[0]).powi(3);
                c.particles.scale[0] = s;
            },
            &[
                "particle 0",
                "`scale` is 1.2000000000001",
                "has scales 0.8 to 1.2",
            ],
        ),
        (
            |c| c.particles.mass[4] = 0.0,
            &["particle 4", "`mass` is 0", "> 0"],
        ),
        (
            |c| c.particles.mass[4] *= 2.0,
            &["particle 4", "`mass`", "has mass"],
        ),
        (|c| c.time = f64::NAN, &["`time` is NaN", "finite"]),
        (|c| c.time *= 2.0, &["`time`", "`step` 100"]),
    ];
    for (k, (edit, want)) in cases.iter().enumerate() {
        let mut c = good.clone();
        edit(&mut c);
        write_checkpoint(&bad, &c).unwrap();
        let err = run_fails(&restart_args(&scene, &bad, &out, "10"));
        for w in want.iter().chain(&["bad.ckpt"]) {
            assert!(err.contains(w), "case {k}: `{w}` missing in:\n{err}");
        }
        // `polydem analyze` reads checkpoints through the same checks (a bad kind used to
        // panic there with an index out of bounds). Its particles' time is not used.
        if !want[0].contains("`time`") {
            let err = polydem::analysis::load_state(&scene, &bad)
                .map(|_| ())
                .unwrap_err()
                .to_string();
            for w in want.iter().chain(&["bad.ckpt"]) {
                assert!(
                    err.contains(w),
                    "analysis, case {k}: `{w}` missing in:\n{err}"
                );
            }
        }
    }
    // The unedited state restarts.
    write_checkpoint(&bad, &good).unwrap();
    polydem_run(&restart_args(&scene, &bad, &out, "10"));
}

/// A closed OBJ cube of half side `h`, outward triangles.
fn cube_obj(h: f64) -> String {
    let mut s = String::new();
    for (x, y, z) in [
        (-1, -1, -1),
        (1, -1, -1),
        (1, 1, -1),
        (-1, 1, -1),
        (-1, -1, 1),
        (1, -1, 1),
        (1, 1, 1),
        (-1, 1, 1),
    ] {
        s.push_str(&format!(
            "v {} {} {}\n",
            x as f64 * h,
            y as f64 * h,
            z as f64 * h
        ));
    }
    for f in [
        [1, 3, 2],
        [1, 4, 3],
        [5, 6, 7],
        [5, 7, 8],
        [1, 2, 6],
        [1, 6, 5],
        [4, 8, 7],
        [4, 7, 3],
        [1, 5, 8],
        [1, 8, 4],
        [2, 3, 7],
        [2, 7, 6],
    ] {
        s.push_str(&format!("f {} {} {}\n", f[0], f[1], f[2]));
    }
    s
}

#[test]
fn restart_accepts_harmless_edits_and_lists_the_sections_that_differ() {
    let dir = temp_dir("scene-edits");
    let scene_path = restart_scene(&dir);
    // The particles from a mesh file and the wall from a copy, both edited below.
    std::fs::write(dir.join("grain.obj"), cube_obj(0.003)).unwrap();
    let wall = repo_root().join("meshes/walls/box_open_top.stl");
    std::fs::copy(&wall, dir.join("box.stl")).unwrap();
    let text = std::fs::read_to_string(&scene_path)
        .unwrap()
        .replace(
            r#"generator = { kind = "dodecahedron", size = 0.012 }"#,
            r#"mesh = "grain.obj""#,
        )
        .replace(&wall.display().to_string(), "box.stl");
    std::fs::write(&scene_path, &text).unwrap();
    let ckpt = first_run(&scene_path, &dir.join("first"), "50");
    let out = dir.join("out");
    let args = restart_args(&scene_path, &ckpt, &out, "5");

    // A comment, a longer end time, other output settings, a relaxed guard and an outflow
    // allowed (what a run they stopped is continued with): accepted.
    let edited = format!("# a comment\n{text}")
        .replace("end_time = 10.0", "end_time = 20.0")
        .replace("frame_interval = 0.002", "frame_interval = 0.004")
        .replace("[output]\n", "[output]\nlog_interval_steps = 7\n")
        .replace("[domain]\n", "[domain]\non_leaving = \"remove\"\n")
        + "\n[simulation.guard]\nmax_overlap = 0.2\n";
    assert!(edited.contains("on_leaving"), "the scene's [domain] line");
    std::fs::write(&scene_path, &edited).unwrap();
    polydem_run(&args);

    // A changed friction: refused, naming the section.
    std::fs::write(
        &scene_path,
        edited.replace("friction = 0.4", "friction = 0.3"),
    )
    .unwrap();
    let err = run_fails(&args);
    assert!(err.contains("material_pairs changed"), "{err}");
    assert!(err.contains("simulation.end_time"), "{err}");
    std::fs::write(&scene_path, &edited).unwrap();

    // A changed particle mesh, and a changed wall mesh: refused, naming them.
    std::fs::write(dir.join("grain.obj"), cube_obj(0.0033)).unwrap();
    let err = run_fails(&args);
    assert!(err.contains("particle_types[0] (d) changed"), "{err}");
    assert!(!err.contains("walls[0]"), "{err}");
    std::fs::write(dir.join("grain.obj"), cube_obj(0.003)).unwrap();
    let mut stl = std::fs::read(&wall).unwrap();
    // The first vertex's x of the first triangle (binary STL: 80 + 4 + 12 bytes in).
    let x = f32::from_le_bytes(stl[96..100].try_into().unwrap());
    stl[96..100].copy_from_slice(&(x * 1.5).to_le_bytes());
    std::fs::write(dir.join("box.stl"), stl).unwrap();
    let err = run_fails(&args);
    assert!(err.contains("walls[0] (box) changed"), "{err}");
}

/// Stopped at step 2000, a series event, and restarted in the same folder: `series.csv` equals
/// the uninterrupted run's byte for byte (no repeated row at the stop or the end; the same
/// energies to the last bit). Thousands of steps, with dozens of particles in contact, so that a
/// summation order that varies between runs (a parallel reduction's) shows in the last bits.
#[test]
fn restarted_series_equals_the_uninterrupted_one_byte_for_byte() {
    let dir = temp_dir("series-restart");
    let scene = restart_scene(&dir);
    let text = std::fs::read_to_string(&scene)
        .unwrap()
        .replace("[output]\n", "[output]\nseries_interval = 0.001\n");
    std::fs::write(&scene, text).unwrap();
    first_run(&scene, &dir.join("full"), "4000");
    let ckpt = first_run(&scene, &dir.join("part"), "2000");
    polydem_run(&restart_args(&scene, &ckpt, &dir.join("part"), "2000"));
    let full = std::fs::read_to_string(dir.join("full/series.csv")).unwrap();
    let part = std::fs::read_to_string(dir.join("part/series.csv")).unwrap();
    let steps: Vec<u64> = full
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(steps, (0..=4000).step_by(50).collect::<Vec<u64>>());
    assert!(full == part, "series differ:\n{full}\n---\n{part}");
}

#[test]
fn a_run_removes_temporary_files_left_in_its_output_folder() {
    let dir = temp_dir("tmp-clean");
    let scene = restart_scene(&dir);
    let out = dir.join("out");
    // A run killed while writing (its temporary files left), continued in the same folder.
    let ckpt = first_run(&scene, &out, "5");
    let ours = [
        out.join("series.csv.tmp-4242"),
        out.join("checkpoints/latest.ckpt.tmp-17"),
    ];
    let theirs = [
        out.join("notes.tmp-draft"),
        out.join("data.tmp"),
        dir.join("elsewhere.ckpt.tmp-99"),
    ];
    for p in ours.iter().chain(&theirs) {
        std::fs::write(p, b"left over").unwrap();
    }
    polydem_run(&restart_args(&scene, &ckpt, &out, "5"));
    for p in &ours {
        assert!(!p.exists(), "{} was left", p.display());
    }
    for p in &theirs {
        assert!(p.exists(), "{} was removed", p.display());
    }
}

#[test]
fn checkpoint_keep_prunes_old_periodic_checkpoints_only() {
    let dir = temp_dir("ckpt-keep");
    let scene = restart_scene(&dir);
    let text = std::fs::read_to_string(&scene).unwrap().replace(
        "checkpoint_interval = 0.004",
        "checkpoint_interval = 0.002\ncheckpoint_keep = 2",
    );
    std::fs::write(&scene, &text).unwrap();
    let out = dir.join("out");
    // Periodic checkpoints every 100 steps; the run ends off the schedule at 550.
    let ckpt = first_run(&scene, &out, "550");
    // A guard stop's checkpoint is never pruned.
    let unstable = out.join("checkpoints/unstable-step-0000000050.ckpt");
    std::fs::write(&unstable, b"kept").unwrap();
    let names = |out: &Path| {
        let mut v: Vec<String> = std::fs::read_dir(out.join("checkpoints"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect();
        v.sort();
        v
    };
    assert_eq!(
        names(&out),
        [
            "latest.ckpt",
            "step_0000000400.ckpt",
            "step_0000000500.ckpt",
            "step_0000000550.ckpt",
            "unstable-step-0000000050.ckpt"
        ]
    );
    // A restart counts the periodic checkpoints already there.
    polydem_run(&restart_args(&scene, &ckpt, &out, "150"));
    assert_eq!(
        names(&out),
        [
            "latest.ckpt",
            "step_0000000550.ckpt",
            "step_0000000600.ckpt",
            "step_0000000700.ckpt",
            "unstable-step-0000000050.ckpt"
        ]
    );
    // 0 is refused, naming the key.
    std::fs::write(
        &scene,
        text.replace("checkpoint_keep = 2", "checkpoint_keep = 0"),
    )
    .unwrap();
    let err = run_fails(&[
        scene.to_str().unwrap(),
        "--backend",
        "cpu",
        "--max-steps",
        "1",
    ]);
    assert!(
        err.contains("output.checkpoint_keep") && err.contains("at least 1"),
        "{err}"
    );
}
