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
//! that status, as a user pressing Ctrl-C twice expects.
//!
//! `mpirun` (Open MPI) follows its SIGTERM with SIGKILL after `odls_base_sigkill_timeout`
//! seconds, 1 by default: long enough for the agreement and the checkpoint of a small run, not
//! for a large one, which should be launched with `--mca odls_base_sigkill_timeout 60`
//! (docs/parallel.md).

use signal_hook::consts::{SIGINT, SIGTERM};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

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
    for (k, (signal, name)) in STOP_SIGNALS.into_iter().enumerate() {
        // Registered first, so it sees the flag as it was before this signal: a second
        // signal exits at once with 128 + signal.
        signal_hook::flag::register_conditional_shutdown(signal, 128 + signal, flags[k].clone())
            .and_then(|_| signal_hook::flag::register(signal, flags[k].clone()))
            .map_err(|e| format!("cannot install a handler for {name}: {e}"))?;
    }
    Ok(flags)
}

impl StopSignals {
    /// Installs the handlers (the first time) and clears the flags, for a run that starts now.
    pub fn install() -> Result<Self, String> {
        let flags = INSTALLED.get_or_init(install_handlers).clone()?;
        for f in &flags {
            f.store(false, Ordering::SeqCst);
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
        let s = StopSignals::install().unwrap();
        assert_eq!(s.received(), [0, 0]);
        signal_hook::low_level::raise(SIGTERM).unwrap();
        assert_eq!(s.received(), [0, 1]);
        let s = StopSignals::install().unwrap();
        assert_eq!(s.received(), [0, 0]);
    }
}
