//! Checkpoints of a run: the scheduled ones (pruned to the newest kept), the one of an
//! interrupt, the state at a stability stop, and reading one back for a restart on any rank
//! count.
use super::output::Schedule;
use crate::backend::Engine;
use crate::domain::Comm;
use crate::domain::collect::gather_state;
use crate::io::checkpoint::fnv1a64;
use crate::io::{Checkpoint, read_checkpoint, write_checkpoint};
use crate::pipeline::SimulationError;
use crate::run_state::RunState;
use crate::scene::Scene;
use crate::scene::restart::{SECTIONS_RECORD, SceneFingerprint, check_against_scene};
use anyhow::{Context, Result, anyhow, bail};
use std::path::{Path, PathBuf};

/// What identifies a scene for restarts: its parsed sections ([`SceneFingerprint`]), and the
/// hash of the file's bytes that older checkpoints store.
pub(super) struct SceneId {
    fingerprint: SceneFingerprint,
    legacy: u64,
}

impl SceneId {
    pub(super) fn of(scene: &Scene, path: &Path) -> Result<Self> {
        let bytes =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        Ok(SceneId {
            fingerprint: SceneFingerprint::of(scene),
            legacy: fnv1a64(&bytes),
        })
    }
}

/// The checkpoint of the current state, particles by global id whatever the backend's order;
/// in a decomposed run the whole run's state gathered on rank 0 (`None` on the other ranks).
pub(super) fn checkpoint_of(
    comm: &dyn Comm,
    sim: &RunState,
    id: &SceneId,
) -> Result<Option<Checkpoint>> {
    let inserter = serde_json::to_vec(&sim.inserter.state())?;
    let (particles, history, removed) = if comm.size() > 1 {
        let removed = comm.sum_u64(&[sim.stats.removed])[0];
        match gather_state(comm, sim, 0) {
            Some((p, h)) => (p, h, removed),
            None => return Ok(None),
        }
    } else {
        // By global id, as gathered from many ranks: the GPU keeps its own (cell) order.
        (
            crate::domain::collect::sorted_by_id(&sim.particles),
            sim.history.clone(),
            sim.stats.removed,
        )
    };
    Ok(Some(Checkpoint {
        step: sim.step,
        time: sim.time,
        particles,
        history,
        rng_state: sim.inserter.state().rng,
        inserter,
        next_id: sim.next_id,
        scene_hash: id.fingerprint.hash(),
        extra: vec![
            ("removed".into(), removed.to_le_bytes().to_vec()),
            (SECTIONS_RECORD.into(), id.fingerprint.record()),
        ],
    }))
}

/// A run stopped by the stability guard (`crate::stability`), a non-finite value or a particle
/// leaving the domain through a closed face (`domain.on_leaving`): the last scheduled
/// checkpoint is left as it is, and the state at the stop (the end of the step that failed its
/// checks) is written beside it as `checkpoints/unstable-step-<step>.ckpt` for a post-mortem
/// or a restart with a smaller step, when every value is finite. In a decomposed run every
/// rank is here after the same step ([`SimulationError::stops_every_rank`]): they gather the
/// state together as for a scheduled checkpoint, agreeing first that each could read its part
/// and that it is finite. Other errors pass through unchanged.
pub(super) fn stopped_unstable(
    e: anyhow::Error,
    comm: &dyn Comm,
    engine: &mut Engine,
    dir: &Path,
    id: &SceneId,
) -> anyhow::Error {
    let stopped = e
        .downcast_ref::<SimulationError>()
        .is_some_and(SimulationError::stops_every_rank);
    if !stopped {
        return e;
    }
    let (sim, read) = match engine.synced() {
        Ok(sim) => (Some(sim), None),
        Err(sync) => (None, Some(sync.to_string())),
    };
    if comm.any(read.is_some()) {
        return e.context(match read {
            Some(why) => format!("the stopped state could not be read: {why}"),
            None => "no checkpoint of the stopped state: another rank could not read its part"
                .to_string(),
        });
    }
    let sim = sim.expect("read on every rank");
    let p = &sim.particles;
    let finite = (0..p.len()).all(|i| {
        p.position[i].iter().all(|x| x.is_finite())
            && p.velocity[i].iter().all(|x| x.is_finite())
            && p.angular_velocity[i].iter().all(|x| x.is_finite())
            && p.orientation[i].coords.iter().all(|x| x.is_finite())
    });
    if comm.any(!finite) {
        return e.context("no checkpoint of the stopped state: it holds non-finite values");
    }
    let path = dir
        .join("checkpoints")
        .join(format!("unstable-step-{}.ckpt", sim.step));
    // Collective in a decomposed run; rank 0 writes, and tells the others how it went.
    let written = checkpoint_of(comm, sim, id).and_then(|c| match c {
        Some(c) => {
            std::fs::create_dir_all(dir.join("checkpoints"))?;
            write_checkpoint(&path, &c).map_err(anyhow::Error::from)
        }
        None => Ok(()),
    });
    let mut outcome = match &written {
        Ok(()) => Vec::new(),
        Err(w) => format!("{w:#}").into_bytes(),
    };
    comm.broadcast(&mut outcome, 0);
    if outcome.is_empty() {
        e.context(format!(
            "the state at the stop is in {} (the last scheduled checkpoint is unchanged)",
            path.display()
        ))
    } else {
        e.context(format!(
            "the state at the stop could not be written: {}",
            String::from_utf8_lossy(&outcome)
        ))
    }
}

/// Writes the checkpoint (a collective call in a decomposed run; rank 0 writes) and returns
/// its path.
pub(super) fn save_checkpoint(
    comm: &dyn Comm,
    sim: &RunState,
    dir: &Path,
    id: &SceneId,
) -> Result<PathBuf> {
    let ckdir = dir.join("checkpoints");
    let path = checkpoint_path(dir, sim.step);
    if let Some(checkpoint) = checkpoint_of(comm, sim, id)? {
        std::fs::create_dir_all(&ckdir)
            .with_context(|| format!("{}: cannot create", ckdir.display()))?;
        write_checkpoint(&path, &checkpoint)?;
        // The newest is also `latest.ckpt`, so that a restart needs no step number.
        write_checkpoint(&ckdir.join("latest.ckpt"), &checkpoint)?;
    }
    comm.barrier();
    Ok(path)
}

/// The periodic checkpoints (those of the `checkpoint_interval` schedule) on disk, oldest first,
/// pruned to the newest `output.checkpoint_keep`. `latest.ckpt`, the checkpoint of an
/// interrupt or of the end of a run off the schedule, and `unstable-step-*.ckpt` are never
/// among them, so never deleted.
pub(super) struct KeptCheckpoints {
    keep: Option<u64>,
    periodic: std::collections::VecDeque<PathBuf>,
}

impl KeptCheckpoints {
    /// The periodic checkpoints already on disk in `dir` at step `step` (a restart): the steps
    /// the schedule fires at, found by replaying it with the run's own time accumulation.
    pub(super) fn new(scene: &Scene, dir: &Path, step: u64) -> Self {
        let keep = scene.output.checkpoint_keep;
        let mut periodic = std::collections::VecDeque::new();
        if keep.is_some() && step > 0 {
            let dt = scene.time_step();
            let mut at = Schedule::new(scene.output.checkpoint_interval, 0.0, dt);
            let mut t = 0.0;
            for k in 1..=step {
                t += dt;
                if at.due(t, dt) {
                    let path = checkpoint_path(dir, k);
                    if path.is_file() {
                        periodic.push_back(path);
                    }
                }
            }
        }
        KeptCheckpoints { keep, periodic }
    }

    /// Records the periodic checkpoint just written at `path` and, on rank 0, deletes the
    /// oldest beyond the number kept.
    pub(super) fn push(&mut self, rank: usize, path: PathBuf) -> Result<()> {
        let Some(keep) = self.keep else {
            return Ok(());
        };
        if self.periodic.back() != Some(&path) {
            self.periodic.push_back(path);
        }
        while self.periodic.len() as u64 > keep {
            if let Some(old) = self.periodic.pop_front()
                && rank == 0
            {
                std::fs::remove_file(&old)
                    .or_else(|e| match e.kind() {
                        std::io::ErrorKind::NotFound => Ok(()),
                        _ => Err(e),
                    })
                    .with_context(|| format!("{}: cannot delete", old.display()))?;
            }
        }
        Ok(())
    }
}

/// The file of the checkpoint at `step`.
pub(super) fn checkpoint_path(dir: &Path, step: u64) -> PathBuf {
    dir.join("checkpoints")
        .join(format!("step_{step:010}.ckpt"))
}

/// What every rank needs of a checkpoint to restart: all but the particles and history, which
/// stay on rank 0 until the first exchange sends them to their owners.
pub(super) struct RestartHeader {
    pub(super) step: u64,
    pub(super) time: f64,
    pub(super) next_id: u64,
    pub(super) inserter: Vec<u8>,
    pub(super) removed: u64,
}

/// Reads a checkpoint on rank 0 and shares its header with every rank; rank 0 also gets the
/// particles and history. An unreadable checkpoint stops every rank with rank 0's message.
pub(super) fn read_restart(
    comm: &dyn Comm,
    path: &Path,
    scene: &Scene,
    id: &SceneId,
) -> Result<(RestartHeader, Option<Checkpoint>)> {
    use crate::domain::pack::{Reader, Writer};
    let mut w = Writer::default();
    let mut local = None;
    if comm.rank() == 0 {
        // The scene first: a state checked against the wrong scene would report the wrong
        // field.
        let checked = read_checkpoint(path)
            .map_err(anyhow::Error::from)
            .and_then(|c| {
                id.fingerprint
                    .check(&c, id.legacy)
                    .and_then(|_| check_against_scene(&c, scene))
                    .map_err(|e| anyhow!("checkpoint {}: {e}", path.display()))?;
                Ok(c)
            });
        match checked {
            Ok(c) => {
                let removed = c
                    .extra
                    .iter()
                    .find(|(k, _)| k == "removed")
                    .and_then(|(_, b)| b.as_slice().try_into().ok().map(u64::from_le_bytes))
                    .unwrap_or(0);
                w.u64(0);
                w.u64(c.step);
                w.f64(c.time);
                w.u64(c.next_id);
                w.u64(removed);
                w.bytes(&c.inserter);
                local = Some(c);
            }
            Err(e) => {
                w.u64(1);
                w.bytes(format!("{e:#}").as_bytes());
            }
        }
    }
    let mut buf = w.buf;
    comm.broadcast(&mut buf, 0);
    let mut r = Reader::new(&buf);
    if r.u64() != 0 {
        bail!("{}", String::from_utf8_lossy(r.bytes()));
    }
    let header = RestartHeader {
        step: r.u64(),
        time: r.f64(),
        next_id: r.u64(),
        removed: r.u64(),
        inserter: r.bytes().to_vec(),
    };
    Ok((header, local))
}
