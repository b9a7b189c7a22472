//! Stopping a run cleanly on a signal: SIGINT (Ctrl-C; a terminal sends it to the whole
//! foreground process group, `mpirun` and its ranks included) and SIGTERM (what `mpirun` sends
//! every rank when it is itself interrupted or terminated, and what Slurm sends a job's tasks
//! at its time limit, before SIGKILL).
//!
//! A handler only raises a flag; the run loop polls it between steps, every rank of a
//! decomposed run agrees on it (so all stop after the same step), writes the interrupt
//! checkpoint and the summary, and the process exits with `128 + signal` (130 for SIGINT, 143
//! for SIGTERM), so that scripts can tell an interrupted run from a finished one. A second
//! signal of the same kind while the first is being handled ends the process at once with
//! that status, as a user pressing Ctrl-C twice expects, unless it comes within
//! [`DUPLICATE_WINDOW`] of the first: then it is the same request delivered twice, and is
//! ignored. GNU `timeout` sends its signal to the command and then to the command's whole
//! process group, and a terminal's Ctrl-C reaches `mpirun`'s ranks both directly and forwarded
//! by `mpirun`; taking such a duplicate for a second request would end the run without its
//! checkpoint (one `timeout -s INT` in six did so).
//!
//! `mpirun` (Open MPI) follows its SIGTERM with SIGKILL after `odls_base_sigkill_timeout`
//! seconds, 1 by default: long enough for the agreement and the checkpoint of a small run, not
//! for a large one, which should be launched with `--mca odls_base_sigkill_timeout 60`
//! (docs/parallel.md).

use signal_hook::consts::{SIGINT, SIGTERM};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// A second signal of a kind this soon after the first is a duplicate delivery of the same
/// request, not a second request: tools deliver one request twice within microseconds to
/// milliseconds, a person pressing Ctrl-C twice takes longer.
pub const DUPLICATE_WINDOW: Duration = Duration::from_millis(500);

/// When the first signal of each kind arrived in this run: nanoseconds since the handlers were
/// installed, plus one (0: not yet).
static FIRST_ARRIVAL: [AtomicU64; 2] = [AtomicU64::new(0), AtomicU64::new(0)];

/// The signals a run stops on, in the order of [`StopSignals::received`]'s counts.
pub const STOP_SIGNALS: [(i32, &str); 2] = [(SIGINT, "SIGINT"), (SIGTERM, "SIGTERM")];

/// The flags SIGINT and SIGTERM raise. The handlers are installed once per process and stay
/// (removing one would leave its signal ignored); each run resets the flags when it starts.
pub struct StopSignals {
    flags: [Arc<AtomicBool>; 2],
}

/// The process's flags, with the handlers installed (or why they could not be).
static INSTALLED: OnceLock<Result<[Arc<AtomicBool>; 2], String>> = OnceLock::new();

fn install_handlers() -> Result<[Arc<AtomicBool>; 2], String> {
    let flags = [0, 1].map(|_| Arc::new(AtomicBool::new(false)));
    let installed = Instant::now();
    let window = DUPLICATE_WINDOW.as_nanos() as u64;
    for (k, (signal, name)) in STOP_SIGNALS.into_iter().enumerate() {
        let flag = flags[k].clone();
        let action = move || {
            let now = installed.elapsed().as_nanos() as u64 + 1;
            if let Err(first) =
                FIRST_ARRIVAL[k].compare_exchange(0, now, Ordering::SeqCst, Ordering::SeqCst)
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
    pub fn received(&self) -> [u64; 2] {
        [0, 1].map(|k| u64::from(self.flags[k].load(Ordering::SeqCst)))
    }
}

/// The signal a run stops for, from the counts of [`StopSignals::received`] summed over the
/// ranks (every rank computes the same): SIGTERM when any rank got it (under `mpirun` every
/// rank does, and SIGKILL follows), else SIGINT; `None` when no rank got either.
pub fn stop_signal(counts: [u64; 2]) -> Option<(i32, &'static str)> {
    if counts[1] > 0 {
        Some(STOP_SIGNALS[1])
    } else if counts[0] > 0 {
        Some(STOP_SIGNALS[0])
    } else {
        None
    }
}

/// The exit status of a run stopped by `signal` (the shell's convention, `128 + signal`).
pub fn exit_status(signal: i32) -> i32 {
    128 + signal
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flags are the process's: the tests that raise signals take turns.
    static RAISING: std::sync::Mutex<()> = std::sync::Mutex::new(());

    #[test]
    fn sigterm_wins_over_sigint_and_statuses_follow_the_shell() {
        assert_eq!(stop_signal([0, 0]), None);
        assert_eq!(stop_signal([3, 0]).map(|s| s.1), Some("SIGINT"));
        assert_eq!(stop_signal([1, 2]).map(|s| s.1), Some("SIGTERM"));
        assert_eq!(exit_status(SIGINT), 130);
        assert_eq!(exit_status(SIGTERM), 143);
    }

    /// A signal raised in the process sets exactly its flag, and the next run starts clean.
    #[test]
    fn raised_signals_set_their_flags() {
        let _turn = RAISING.lock().unwrap_or_else(|e| e.into_inner());
        let s = StopSignals::install().unwrap();
        assert_eq!(s.received(), [0, 0]);
        signal_hook::low_level::raise(SIGTERM).unwrap();
        assert_eq!(s.received(), [0, 1]);
        let s = StopSignals::install().unwrap();
        assert_eq!(s.received(), [0, 0]);
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
        assert_eq!(s.received(), [1, 0]);
        let s = StopSignals::install().unwrap();
        assert_eq!(s.received(), [0, 0]);
    }
}
