//! `polydem run` end to end: a run stopped at step k and restarted from its checkpoint ends
//! bitwise equal to the uninterrupted run; the summary and output files are written.

mod common;

use common::*;
use polydem::io::read_checkpoint;
use std::process::Command;

#[test]
fn restart_continues_bitwise_and_outputs_are_written() {
    let dir = temp_dir("restart");
    let scene = restart_scene(&dir);
    let s = scene.to_str().unwrap();
    let (full, first, second) = (dir.join("full"), dir.join("first"), dir.join("second"));
    polydem_run(&[
        s,
        "--backend",
        "cpu",
        "--out",
        full.to_str().unwrap(),
        "--max-steps",
        "800",
    ]);
    polydem_run(&[
        s,
        "--backend",
        "cpu",
        "--out",
        first.to_str().unwrap(),
        "--max-steps",
        "400",
    ]);
    let ckpt = first.join("checkpoints/latest.ckpt");
    let c = read_checkpoint(&ckpt).unwrap();
    assert_eq!(c.step, 400);
    assert!(
        !c.history.is_empty(),
        "the restart point should have live contacts"
    );
    std::fs::create_dir_all(&second).unwrap();
    polydem_run(&[
        s,
        "--backend",
        "cpu",
        "--out",
        second.to_str().unwrap(),
        "--restart",
        ckpt.to_str().unwrap(),
        "--max-steps",
        "400",
    ]);
    let a = read_checkpoint(&full.join("checkpoints/latest.ckpt")).unwrap();
    let b = read_checkpoint(&second.join("checkpoints/latest.ckpt")).unwrap();
    assert_eq!((a.step, a.time.to_bits()), (b.step, b.time.to_bits()));
    assert_eq!(a.particles.len(), 60);
    assert!(
        a.particles == b.particles,
        "particle state differs after the restart"
    );
    assert!(
        a.history == b.history,
        "contact history differs after the restart"
    );
    assert_eq!(a.inserter, b.inserter);
    // Outputs: summary, frames collection, series, particle CSV.
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(full.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["steps"], 800);
    assert_eq!(summary["particles"], 60);
    assert!(summary["particle_steps_per_second"].as_f64().unwrap() > 0.0);
    for k in [
        "pairs",
        "walls",
        "neighbor",
        "integrate",
        "reduce",
        "exchange",
    ] {
        assert!(summary["stage_seconds"][k].is_number(), "stage {k} missing");
    }
    let pvd = std::fs::read_to_string(full.join("frames.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 9, "{pvd}"); // t = 0, 0.002 … 0.016 (the last is the end)
    let series = std::fs::read_to_string(full.join("series.csv")).unwrap();
    assert!(series.lines().count() > 5);
    assert!(full.join("particles").read_dir().unwrap().count() >= 9);
}

#[test]
fn check_reports_time_steps_and_counts() {
    let dir = temp_dir("check");
    let scene = restart_scene(&dir);
    let out = Command::new(polydem_bin())
        .arg("check")
        .arg(&scene)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    println!("{v:#}");
    assert!(v.to_string().contains("rayleigh"));
}

/// Ctrl-C (SIGINT) ends a run cleanly: exit status 130 (the shell's 128 + 2, so that scripts
/// can tell), a checkpoint at the step it stopped at, `interrupted: true` and the signal in the
/// summary, and a restart from that checkpoint ends bitwise equal to a run that was never
/// interrupted. SIGTERM (Slurm at a job's time limit) does the same with status 143. The SIGINT
/// is delivered twice at once, as `timeout` does: the duplicate must not end the run early.
#[cfg(unix)]
#[test]
fn ctrl_c_writes_a_checkpoint_that_restarts_bitwise() {
    for (signal, status) in [("-TERM", 143), ("-INT", 130)] {
        interrupted_run_restarts_bitwise(signal, status);
    }
}

#[cfg(unix)]
fn interrupted_run_restarts_bitwise(signal: &str, expected: i32) {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let dir = temp_dir(&format!("ctrl-c{signal}"));
    let scene = restart_scene(&dir);
    // Log every 20 steps, so the test sees the run going before it interrupts it.
    let text = std::fs::read_to_string(&scene)
        .unwrap()
        .replace("[output]\n", "[output]\nlog_interval_steps = 20\n");
    std::fs::write(&scene, text).unwrap();
    let s = scene.to_str().unwrap();
    let stopped = dir.join("stopped");
    let mut child = Command::new(polydem_bin())
        .args(["run", s, "--backend", "cpu", "--out"])
        .arg(&stopped)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("start polydem");
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let mut log = String::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        log.push_str(&line);
        log.push('\n');
        if line.contains("step 100 ") {
            break;
        }
    }
    // SIGINT arrives twice, a moment apart, as GNU `timeout` delivers it (to the command,
    // then to its process group): one request, one clean stop.
    let deliveries = if signal == "-INT" { 2 } else { 1 };
    let mut kill = None;
    for _ in 0..deliveries {
        kill = Some(
            Command::new("kill")
                .args([signal, &child.id().to_string()])
                .status()
                .unwrap(),
        );
    }
    let kill = kill.unwrap();
    assert!(kill.success());
    for line in lines {
        log.push_str(&line.unwrap());
        log.push('\n');
    }
    let status = child.wait().unwrap();
    assert_eq!(
        status.code(),
        Some(expected),
        "{signal}: interrupted run exited with {status}:\n{log}"
    );
    let name = format!("SIG{}", &signal[1..]);
    assert!(
        log.contains(&format!("interrupted by {name} after step")),
        "{log}"
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(stopped.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["interrupted"], true);
    assert_eq!(summary["signal"], name.as_str());
    assert_eq!(summary["exit_status"], expected);
    let k = summary["final_step"].as_u64().unwrap();
    let c = read_checkpoint(&stopped.join("checkpoints/latest.ckpt")).unwrap();
    assert_eq!(c.step, k, "checkpoint at the step the run stopped at");
    assert!(k >= 100, "stopped at step {k}, before it was interrupted");

    // Restart for 50 more steps and compare with an uninterrupted run of k + 50 steps.
    let (resumed, full) = (dir.join("resumed"), dir.join("full"));
    let ckpt = stopped.join("checkpoints/latest.ckpt");
    polydem_run(&[
        s,
        "--backend",
        "cpu",
        "--out",
        resumed.to_str().unwrap(),
        "--restart",
        ckpt.to_str().unwrap(),
        "--max-steps",
        "50",
    ]);
    polydem_run(&[
        s,
        "--backend",
        "cpu",
        "--out",
        full.to_str().unwrap(),
        "--max-steps",
        &(k + 50).to_string(),
    ]);
    let a = read_checkpoint(&full.join("checkpoints/latest.ckpt")).unwrap();
    let b = read_checkpoint(&resumed.join("checkpoints/latest.ckpt")).unwrap();
    assert_eq!((a.step, a.time.to_bits()), (b.step, b.time.to_bits()));
    assert!(
        a.particles == b.particles,
        "particle state differs after Ctrl-C and restart"
    );
    assert!(
        a.history == b.history,
        "contact history differs after Ctrl-C and restart"
    );
}

/// A new run into a folder holding a previous run's output is refused (its series, summary and
/// collections would be overwritten, its later checkpoints and frames left mixed in), naming
/// what is there and the ways out; `--overwrite` removes that output (a later checkpoint of the
/// old run included) and keeps files polydem does not write; `--restart` continues in place.
/// An output path blocked by a file names the file.
#[test]
fn a_used_output_folder_needs_overwrite_or_restart() {
    let dir = temp_dir("reuse-out");
    let scene = restart_scene(&dir);
    let s = scene.to_str().unwrap();
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    polydem_run(&[s, "--backend", "cpu", "--out", o, "--max-steps", "20"]);
    let again = |extra: &[&str]| {
        Command::new(polydem_bin())
            .args([
                "run",
                s,
                "--backend",
                "cpu",
                "--out",
                o,
                "--max-steps",
                "30",
            ])
            .args(extra)
            .output()
            .unwrap()
    };
    let refused = again(&[]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success(),
        "a second run into {o} was accepted"
    );
    assert!(
        err.contains("previous run's output")
            && err.contains("checkpoints")
            && err.contains("summary.json")
            && err.contains("--overwrite")
            && err.contains("--restart"),
        "{err}"
    );
    // A stale later checkpoint of the old run, a temporary file of a killed write, and a file
    // of the user's.
    let stale = out.join("checkpoints/step_0000099999.ckpt");
    std::fs::copy(out.join("checkpoints/latest.ckpt"), &stale).unwrap();
    std::fs::write(out.join("series.csv.tmp-4242"), "cut short").unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let o2 = again(&["--overwrite"]);
    assert!(
        o2.status.success(),
        "{}",
        String::from_utf8_lossy(&o2.stderr)
    );
    assert!(!stale.exists(), "--overwrite left the old run's checkpoint");
    assert!(!out.join("series.csv.tmp-4242").exists());
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
    let c = read_checkpoint(&out.join("checkpoints/latest.ckpt")).unwrap();
    assert_eq!(c.step, 30);
    // Only files polydem does not write: accepted as it is.
    let notes_only = dir.join("notes_only");
    std::fs::create_dir_all(&notes_only).unwrap();
    std::fs::write(notes_only.join("README"), "x").unwrap();
    polydem_run(&[
        s,
        "--backend",
        "cpu",
        "--out",
        notes_only.to_str().unwrap(),
        "--max-steps",
        "5",
    ]);
    // A path through a file.
    let file = dir.join("a_file");
    std::fs::write(&file, "x").unwrap();
    for (out, named) in [(file.join("sub"), &file), (file.clone(), &file)] {
        let o = Command::new(polydem_bin())
            .args(["run", s, "--backend", "cpu", "--max-steps", "5", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert!(
            err.contains(&format!("{}: ", named.display())) && err.contains("not a folder"),
            "{err}"
        );
    }
}

/// A `--max-steps` stop at a step off the series schedule, restarted into the same folder,
/// gives the uninterrupted run's `series.csv` and `frames.pvd` byte for byte: the stop writes
/// its checkpoint but no closing row or frame (a row at step 1234 once stayed in the series).
#[test]
fn a_max_steps_stop_restarted_in_place_gives_the_uninterrupted_series() {
    let dir = temp_dir("max-steps-series");
    let scene = repo_root().join("launch/mpi/pour.toml");
    let s = scene.to_str().unwrap();
    let (full, cut) = (dir.join("full"), dir.join("cut"));
    for d in [&full, &cut] {
        let _ = std::fs::remove_dir_all(d);
    }
    polydem_run(&[s, "--backend", "cpu", "--out", full.to_str().unwrap()]);
    let c = cut.to_str().unwrap();
    polydem_run(&[s, "--backend", "cpu", "--out", c, "--max-steps", "1234"]);
    let ckpt = cut.join("checkpoints/latest.ckpt");
    assert_eq!(read_checkpoint(&ckpt).unwrap().step, 1234);
    polydem_run(&[
        s,
        "--backend",
        "cpu",
        "--out",
        c,
        "--restart",
        ckpt.to_str().unwrap(),
    ]);
    for f in ["series.csv", "frames.pvd"] {
        let (a, b) = (
            std::fs::read(full.join(f)).unwrap(),
            std::fs::read(cut.join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs after the stop and restart");
    }
}
