//! Stopping a run cleanly on a signal: SIGINT (Ctrl-C; a terminal sends it to the whole
//! foreground process group), SIGTERM (what `mpirun` sends every rank when it is itself
//! interrupted or terminated, and what Slurm sends a job's tasks at its time limit or on
//! `scancel`, before SIGKILL) and SIGUSR1 (the batch systems' "checkpoint and stop" request,
//! Slurm's `--signal=USR1@…`, and the one signal `mpirun` passes on to every rank and then
//! waits for them: `launch/mpirun.sh` turns a Ctrl-C or a SIGTERM into it, docs/parallel.md).
//!
//! A handler only raises a flag; the run loop polls it between steps, every rank of a
//! decomposed run agrees on it (so all stop after the same step), writes the interrupt
//! checkpoint and the summary, and the process exits with `128 + signal` (130 for SIGINT, 143
//! for SIGTERM; 0 for SIGUSR1, [`exit_status`]), so that scripts can tell an interrupted run
//! from a finished one. A second
//! SIGINT while the first is being handled ends the process at once with that status, as a
//! user pressing Ctrl-C twice expects, unless it comes within [`DUPLICATE_WINDOW`] of the
//! first: then it is the same request delivered twice, and is ignored. GNU `timeout` sends its
//! signal to the command and then to the command's whole process group; taking such a
//! duplicate for a second request would end the run without its checkpoint (one `timeout -s
//! INT` in six did so). A repeated SIGTERM or SIGUSR1 is always the same request: the senders
//! of SIGTERM repeat it on their way to SIGKILL (`mpirun`'s kill path sends it again a second
//! after a Slurm job's tasks got it directly), and ending at the repeat would lose the
//! checkpoint that SIGKILL leaves time for.
//!
//! `mpirun` (Open MPI 4) does not forward SIGINT or SIGTERM: interrupted, it sends every rank
//! SIGCONT, waits `odls_base_sigkill_timeout` seconds (1 by default), sends SIGTERM, waits as
//! long again and sends SIGKILL, without reaping or forwarding output while it waits. The
//! ranks then have about a second for the agreement and the checkpoint: enough for a small
//! run, not for a large one, and a longer timeout makes mpirun sleep through it even when the
//! ranks are done (a 60 s timeout held interrupted and failed jobs for one to two minutes).
//! SIGUSR1 avoids that path: mpirun forwards it and waits for the ranks to end on their own.

use signal_hook::consts::{SIGINT, SIGTERM, SIGUSR1};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// A second signal of a kind this soon after the first is a duplicate delivery of the same
/// request, not a second request: tools deliver one request twice within microseconds to
/// milliseconds, a person pressing Ctrl-C twice takes longer.
pub const DUPLICATE_WINDOW: Duration = Duration::from_millis(500);

/// How many signals a run stops on.
const KINDS: usize = 3;

/// When the first signal of each kind arrived in this run: nanoseconds since the handlers were
/// installed, plus one (0: not yet).
static FIRST_ARRIVAL: [AtomicU64; KINDS] =
    [AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0)];

/// The signals a run stops on, in the order of [`StopSignals::received`]'s counts.
pub const STOP_SIGNALS: [(i32, &str); KINDS] = [
    (SIGINT, "SIGINT"),
    (SIGTERM, "SIGTERM"),
    (SIGUSR1, "SIGUSR1"),
];

/// The flags SIGINT, SIGTERM and SIGUSR1 raise. The handlers are installed once per process
/// and stay (removing one would leave its signal ignored); each run resets the flags when it
/// starts.
pub struct StopSignals {
    flags: [Arc<AtomicBool>; KINDS],
}

/// The process's flags, with the handlers installed (or why they could not be).
static INSTALLED: OnceLock<Result<[Arc<AtomicBool>; KINDS], String>> = OnceLock::new();

fn install_handlers() -> Result<[Arc<AtomicBool>; KINDS], String> {
    let flags = [0; KINDS].map(|_| Arc::new(AtomicBool::new(false)));
    let installed = Instant::now();
    let window = DUPLICATE_WINDOW.as_nanos() as u64;
    for (k, (signal, name)) in STOP_SIGNALS.into_iter().enumerate() {
        let flag = flags[k].clone();
        let second_ends = signal == SIGINT;
        let action = move || {
            let now = installed.elapsed().as_nanos() as u64 + 1;
            if let Err(first) =
                FIRST_ARRIVAL[k].compare_exchange(0, now, Ordering::SeqCst, Ordering::SeqCst)
                && second_ends
                && now.saturating_sub(first) > window
            {
                signal_hook::low_level::exit(128 + signal);
            }
            flag.store(true, Ordering::SeqCst);
        };
        // SAFETY: the action is async-signal-safe: atomics, clock_gettime(CLOCK_MONOTONIC)
        // (Instant::elapsed) and _exit, nothing that allocates or locks.
        unsafe { signal_hook::low_level::register(signal, action) }
            .map_err(|e| format!("cannot install a handler for {name}: {e}"))?;
    }
    Ok(flags)
}

impl StopSignals {
    /// Installs the handlers (the first time) and clears the flags, for a run that starts now.
    pub fn install() -> Result<Self, String> {
        let flags = INSTALLED.get_or_init(install_handlers).clone()?;
        for (f, first) in flags.iter().zip(&FIRST_ARRIVAL) {
            f.store(false, Ordering::SeqCst);
            first.store(0, Ordering::SeqCst);
        }
        Ok(StopSignals { flags })
    }

    /// Whether each of [`STOP_SIGNALS`] has arrived, as counts (0 or 1) in that order, ready to
    /// be summed over the ranks.
    pub fn received(&self) -> [u64; KINDS] {
        let mut counts = [0; KINDS];
        for (c, f) in counts.iter_mut().zip(&self.flags) {
            *c = u64::from(f.load(Ordering::SeqCst));
        }
        counts
    }
}

/// The signal a run stops for, from the counts of [`StopSignals::received`] summed over the
/// ranks (every rank computes the same): SIGTERM when any rank got it (under `mpirun` every
/// rank does, and SIGKILL follows), else SIGINT, else SIGUSR1; `None` when no rank got any.
pub fn stop_signal(counts: &[u64]) -> Option<(i32, &'static str)> {
    [1, 0, 2]
        .into_iter()
        .find(|&k| counts.get(k).is_some_and(|&c| c > 0))
        .map(|k| STOP_SIGNALS[k])
}

/// The exit status of a run stopped by `signal`: the shell's `128 + signal` for SIGINT and
/// SIGTERM (130, 143), so that scripts can tell an interrupted run from a finished one, and 0
/// for SIGUSR1, a stop that was asked for: the run did what it was told, and `mpirun`, which
/// takes any rank's non-zero exit for a failed job and kills the rest through the path above,
/// ends at once instead (`launch/mpirun.sh` exits 130 or 143 for what it was sent).
pub fn exit_status(signal: i32) -> i32 {
    if signal == SIGUSR1 { 0 } else { 128 + signal }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flags are the process's: the tests that raise signals take turns.
    static RAISING: std::sync::Mutex<()> = std::sync::Mutex::new(());

    #[test]
    fn sigterm_wins_over_sigint_and_statuses_follow_the_shell() {
        assert_eq!(stop_signal(&[0, 0, 0]), None);
        assert_eq!(stop_signal(&[3, 0, 0]).map(|s| s.1), Some("SIGINT"));
        assert_eq!(stop_signal(&[1, 2, 0]).map(|s| s.1), Some("SIGTERM"));
        assert_eq!(stop_signal(&[0, 0, 2]).map(|s| s.1), Some("SIGUSR1"));
        assert_eq!(stop_signal(&[1, 0, 2]).map(|s| s.1), Some("SIGINT"));
        assert_eq!(exit_status(SIGINT), 130);
        assert_eq!(exit_status(SIGTERM), 143);
        assert_eq!(exit_status(SIGUSR1), 0);
    }

    /// A signal raised in the process sets exactly its flag, and the next run starts clean.
    #[test]
    fn raised_signals_set_their_flags() {
        let _turn = RAISING.lock().unwrap_or_else(|e| e.into_inner());
        let s = StopSignals::install().unwrap();
        assert_eq!(s.received(), [0, 0, 0]);
        signal_hook::low_level::raise(SIGTERM).unwrap();
        assert_eq!(s.received(), [0, 1, 0]);
        // Repeated after the duplicate window, as mpirun's kill path repeats it: still the
        // one request (were it taken as a second, this test's process would exit with 143).
        std::thread::sleep(DUPLICATE_WINDOW + Duration::from_millis(100));
        signal_hook::low_level::raise(SIGTERM).unwrap();
        signal_hook::low_level::raise(SIGUSR1).unwrap();
        assert_eq!(s.received(), [0, 1, 1]);
        let s = StopSignals::install().unwrap();
        assert_eq!(s.received(), [0, 0, 0]);
    }

    /// The same request delivered twice at once (`timeout` signals the command, then its
    /// process group) stops the run once: were the second taken for a second request, this
    /// test's own process would exit with 130.
    #[test]
    fn a_duplicate_delivery_is_one_request() {
        let _turn = RAISING.lock().unwrap_or_else(|e| e.into_inner());
        let s = StopSignals::install().unwrap();
        signal_hook::low_level::raise(SIGINT).unwrap();
        signal_hook::low_level::raise(SIGINT).unwrap();
        assert_eq!(s.received(), [1, 0, 0]);
        let s = StopSignals::install().unwrap();
        assert_eq!(s.received(), [0, 0, 0]);
    }
}
