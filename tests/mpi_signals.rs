//! Interrupts and failures of decomposed runs as users meet them (docs/parallel.md,
//! "Interrupting a run"): `launch/mpirun.sh` on 2 and 3 ranks sent a terminal's Ctrl-C (SIGINT
//! to its process group), `kill` (SIGTERM) and SIGHUP; SIGTERM delivered to every rank at once,
//! as Slurm's `scancel` and time limit deliver it to a job's tasks; a rank killed with SIGKILL;
//! a panic on one rank; a decomposition the ranks cannot run.
//!
//! Each interrupted run must stop every rank after the same step with that step's checkpoint
//! and the summary written, exit with the shell's status for the signal, and leave no rank
//! behind; a failed run must end the whole job. The bound on how long a job may take to end
//! after the signal or the failure (`ENDS_WITHIN`, 15 s) is a hang detector on a loaded 2-core
//! machine, not a speed figure: under Open MPI 4 with a 60 s `odls_base_sigkill_timeout`
//! (what the launch script used to set) these jobs took one to two minutes, and the runs here
//! end in well under a second after an interrupt and about two seconds after a failure.
//!
//! Needs Open MPI's `mpirun` and util-linux's `setsid` (scripts/setup.sh).

mod common;

use common::{long_pour, polydem_bin, repo_root, temp_dir};
use polydem::io::read_checkpoint;
use serde_json::Value;
use std::io::{BufRead, BufReader, Lines};
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Child, ChildStderr, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// How long a job may take to end after its signal or failure before it counts as hung.
const ENDS_WITHIN: Duration = Duration::from_secs(15);

/// A job started in a process group of its own (as a shell starts a foreground job), its log
/// read as it comes.
struct Job {
    child: Child,
    lines: Lines<BufReader<ChildStderr>>,
    log: String,
}

impl Job {
    fn start(mut cmd: Command) -> Job {
        cmd.env("OMPI_ALLOW_RUN_AS_ROOT", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
            .env("RAYON_NUM_THREADS", "1")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .process_group(0);
        let mut child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {:?} ({e})", cmd.get_program()));
        let lines = BufReader::new(child.stderr.take().unwrap()).lines();
        Job {
            child,
            lines,
            log: String::new(),
        }
    }

    /// `launch/mpirun.sh ranks scene --out out` on the CPU.
    fn script(ranks: usize, scene: &Path, out: &Path) -> Job {
        Job::start(script_command(ranks, scene, out))
    }

    /// Reads the log up to the line that reports `step`.
    fn wait_for_step(&mut self, step: u64) {
        let mark = format!("step {step} ");
        for line in self.lines.by_ref() {
            let line = line.unwrap();
            self.log.push_str(&line);
            self.log.push('\n');
            if line.contains(&mark) {
                return;
            }
        }
        panic!("the job ended before step {step}:\n{}", self.log);
    }

    /// Reads the rest of the log and waits for the job; fails if it takes longer than
    /// [`ENDS_WITHIN`] from `since`.
    fn finish(&mut self, since: Instant, what: &str) -> ExitStatus {
        for line in self.lines.by_ref() {
            self.log.push_str(&line.unwrap());
            self.log.push('\n');
        }
        let status = self.child.wait().unwrap();
        let took = since.elapsed();
        println!(
            "{what}: ended {:.2} s after it, {status}",
            took.as_secs_f64()
        );
        assert!(
            took <= ENDS_WITHIN,
            "{what}: the job took {took:?} to end:\n{}",
            self.log
        );
        status
    }
}

/// The command of [`Job::script`], for callers that add arguments or settings.
fn script_command(ranks: usize, scene: &Path, out: &Path) -> Command {
    let mut cmd = Command::new(repo_root().join("launch/mpirun.sh"));
    cmd.arg(ranks.to_string())
        .arg(scene)
        .arg("--out")
        .arg(out)
        .env("POLYDEM_BIN", polydem_bin())
        .env("POLYDEM_BACKEND", "cpu");
    cmd
}

/// `kill -SIGNAL -- TARGET`.
fn kill(signal: &str, target: &str) {
    let ok = Command::new("kill")
        .args([&format!("-{signal}"), "--", target])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -{signal} {target}");
}

/// The processes whose parent is `pid`.
fn children(pid: u32) -> Vec<u32> {
    let o = Command::new("pgrep")
        .args(["-P", &pid.to_string()])
        .output()
        .unwrap();
    String::from_utf8_lossy(&o.stdout)
        .split_whitespace()
        .map(|p| p.parse().unwrap())
        .collect()
}

/// No process, zombies aside, has `out` on its command line within [`RANK_EXIT`] of the job's
/// end: every rank has ended. mpirun can return while the ranks it killed are still being torn
/// down (seen on a loaded machine: a rank's process 1.7 s after a panic, gone moments later);
/// a rank left hanging is still there at the deadline.
fn no_rank_left(out: &Path, what: &str) {
    let start = Instant::now();
    loop {
        let o = Command::new("pgrep")
            .args(["-f", out.to_str().unwrap()])
            .output()
            .unwrap();
        let left = String::from_utf8_lossy(&o.stdout).trim().to_string();
        if left.is_empty() {
            return;
        }
        assert!(
            start.elapsed() < RANK_EXIT,
            "{what}: still running {:.1} s after the job ended: {left}",
            start.elapsed().as_secs_f64()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// How long a killed rank may take to leave after mpirun has returned.
const RANK_EXIT: Duration = Duration::from_secs(5);

/// Checks an interrupted run's output and returns the step it stopped after: the summary says
/// it was interrupted by `signal`, rank 0 reported the stop once, and the checkpoint of that
/// step holds every particle the summary counts.
fn interrupted_at(out: &Path, log: &str, signal: &str, what: &str) -> u64 {
    let summary: Value = serde_json::from_slice(
        &std::fs::read(out.join("summary.json"))
            .unwrap_or_else(|e| panic!("{what}: no summary.json ({e}):\n{log}")),
    )
    .unwrap();
    assert_eq!(summary["interrupted"], true, "{what}");
    assert_eq!(summary["signal"], signal, "{what}");
    let k = summary["final_step"].as_u64().unwrap();
    assert!(k >= 300, "{what}: stopped at step {k}");
    assert_eq!(
        log.matches(&format!("after step {k}:")).count(),
        1,
        "{what}: one message, from rank 0:\n{log}"
    );
    let c = read_checkpoint(&out.join(format!("checkpoints/step_{k:010}.ckpt"))).unwrap();
    let n = summary["particles"].as_u64().unwrap() as usize;
    assert_eq!((c.step, c.particles.len()), (k, n), "{what}");
    assert!(n > 200, "{what}: {n} particles");
    k
}

/// Ctrl-C in a terminal (SIGINT to the script's process group), `kill` (SIGTERM to the
/// script) and SIGHUP, on 2 and 3 ranks: every rank stops after the same step with its
/// checkpoint and the summary written, the script exits 130, 143 and 129, and no rank is left.
/// The 3-rank run's checkpoint then restarts on 2 ranks and ends byte-identical to the
/// uninterrupted single-rank run.
#[test]
fn the_launch_script_stops_every_rank_on_ctrl_c_kill_and_hangup() {
    let dir = temp_dir("mpi-signals-script");
    let scene = long_pour(&dir);
    let mut three = None;
    for (signal, status, group, ranks) in [
        ("INT", 130, true, 2),
        ("TERM", 143, false, 3),
        ("HUP", 129, false, 2),
    ] {
        let what = format!("SIG{signal} to the script on {ranks} ranks");
        let out = dir.join(format!("{signal}_{ranks}"));
        let mut job = Job::script(ranks, &scene, &out);
        job.wait_for_step(300);
        let pid = job.child.id();
        // A terminal's Ctrl-C goes to the foreground job's process group; `kill` to a pid.
        let target = if group {
            format!("-{pid}")
        } else {
            pid.to_string()
        };
        let sent = Instant::now();
        kill(signal, &target);
        let exit = job.finish(sent, &what);
        assert_eq!(exit.code(), Some(status), "{what}:\n{}", job.log);
        no_rank_left(&out, &what);
        // The script asks the ranks through mpirun with SIGUSR1 (src/interrupt.rs).
        let k = interrupted_at(&out, &job.log, "SIGUSR1", &what);
        if ranks == 3 {
            three = Some((out, k));
        }
    }
    let (stopped, k) = three.unwrap();
    let ck = stopped.join(format!("checkpoints/step_{k:010}.ckpt"));
    let name = format!("checkpoints/step_{:010}.ckpt", k + 100);
    let resumed = dir.join("resumed");
    let mut cmd = script_command(2, &scene, &resumed);
    cmd.arg("--restart").arg(&ck).args(["--max-steps", "100"]);
    let mut job = Job::start(cmd);
    let exit = job.finish(Instant::now(), "restart on 2 ranks");
    assert!(exit.success(), "restart:\n{}", job.log);
    let straight = dir.join("straight");
    let o = Command::new(polydem_bin())
        .arg("run")
        .arg(&scene)
        .args([
            "--backend",
            "cpu",
            "--max-steps",
            &(k + 100).to_string(),
            "--out",
        ])
        .arg(&straight)
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (a, b) = (
        std::fs::read(straight.join(&name)).unwrap(),
        std::fs::read(resumed.join(&name)).unwrap(),
    );
    assert!(
        a == b,
        "the restart of step {k} differs from the uninterrupted run"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// SIGTERM to every rank at once, as Slurm delivers `scancel` and its time limit to a job's
/// tasks (with `srun` there is no mpirun; here mpirun's own reaction to a rank's exit with
/// 143 follows, SIGCONT and SIGTERM a second apart): all 3 ranks stop after the same step,
/// write the checkpoint and the summary, and the job ends.
#[test]
fn sigterm_to_every_rank_as_slurm_sends_it_stops_them_at_one_step() {
    let dir = temp_dir("mpi-signals-slurm");
    let scene = long_pour(&dir);
    let out = dir.join("out");
    let mut cmd = Command::new("mpirun");
    cmd.args(["--oversubscribe", "-n", "3"])
        .arg(polydem_bin())
        .arg("run")
        .arg(&scene)
        .args(["--backend", "cpu", "--out"])
        .arg(&out)
        .stdin(Stdio::null());
    let mut job = Job::start(cmd);
    job.wait_for_step(300);
    let ranks = children(job.child.id());
    assert_eq!(ranks.len(), 3, "mpirun's ranks: {ranks:?}");
    let sent = Instant::now();
    for r in &ranks {
        kill("TERM", &r.to_string());
    }
    let what = "SIGTERM to each of 3 ranks";
    let exit = job.finish(sent, what);
    assert!(!exit.success(), "{what}: mpirun reports the ranks' 143");
    no_rank_left(&out, what);
    interrupted_at(&out, &job.log, "SIGTERM", what);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A rank killed with SIGKILL mid-run (the out-of-memory killer, a node lost): the other ranks,
/// waiting for it in the step's collectives, are ended by mpirun and the job exits non-zero.
#[test]
fn a_rank_killed_mid_run_ends_the_whole_job() {
    let dir = temp_dir("mpi-signals-kill9");
    let scene = long_pour(&dir);
    let out = dir.join("out");
    let mut job = Job::script(2, &scene, &out);
    job.wait_for_step(300);
    let mpirun = children(job.child.id());
    assert_eq!(mpirun.len(), 1, "the script's mpirun: {mpirun:?}");
    let ranks = children(mpirun[0]);
    assert_eq!(ranks.len(), 2, "mpirun's ranks: {ranks:?}");
    let sent = Instant::now();
    kill("KILL", &ranks[1].to_string());
    let what = "SIGKILL to rank 1 of 2";
    let exit = job.finish(sent, what);
    assert!(!exit.success(), "{what}:\n{}", job.log);
    no_rank_left(&out, what);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A panic on one rank mid-run (`POLYDEM_PANIC_AT`, a test knob of `tuning`): the panic hook
/// prints it once and aborts MPI, and mpirun ends the other rank, which waits in the step's
/// collectives.
#[test]
fn a_panic_on_one_rank_ends_the_whole_job() {
    let dir = temp_dir("mpi-signals-panic");
    let scene = long_pour(&dir);
    let out = dir.join("out");
    let mut cmd = script_command(2, &scene, &out);
    cmd.env("POLYDEM_PANIC_AT", "1:300");
    let mut job = Job::start(cmd);
    let start = Instant::now();
    let what = "a panic on rank 1 of 2 after step 300";
    let exit = job.finish(start, what);
    assert!(!exit.success(), "{what}:\n{}", job.log);
    assert_eq!(
        job.log.matches("panics after step 300 as asked").count(),
        1,
        "{what}: the panic printed once:\n{}",
        job.log
    );
    no_rank_left(&out, what);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A decomposition the ranks cannot run (a 2×1×2 grid on 2 ranks), through the launch script:
/// the error is printed once and the job ends at once.
#[test]
fn a_decomposition_the_ranks_cannot_run_ends_at_once() {
    let dir = temp_dir("mpi-signals-refused");
    let out = dir.join("out");
    let mut job = Job::script(2, &repo_root().join("launch/mpi/periodic.toml"), &out);
    let start = Instant::now();
    let what = "a 4-subdomain grid on 2 ranks";
    let exit = job.finish(start, what);
    assert!(!exit.success(), "{what}");
    assert_eq!(
        job.log.matches("has 4 subdomains").count(),
        1,
        "{what}:\n{}",
        job.log
    );
    no_rank_left(&out, what);
    let _ = std::fs::remove_dir_all(&dir);
}
