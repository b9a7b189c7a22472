//! A run's output folder and what goes into it while the run steps: ParaView frames (each
//! rank its piece), the particle CSV files, the time series, and the schedules that say when.
use super::summary::whole_run;
use crate::domain::Comm;
use crate::domain::collect::global_stats;
use crate::io::{FrameView, FrameWriter, SeriesRow, SeriesWriter, WallView, write_particle_csv};
use crate::run_state::RunState;
use anyhow::{Context, Result, bail};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// What `polydem run` writes into its output folder: `--overwrite` removes these (and
/// temporary files of interrupted writes), and nothing else.
pub const OUTPUT_ENTRIES: [&str; 7] = [
    "summary.json",
    "series.csv",
    "frames.pvd",
    "walls.pvd",
    "frames",
    "checkpoints",
    "particles",
];

/// Whether `name` is one of the run's outputs ([`OUTPUT_ENTRIES`]) or a temporary file of an
/// interrupted atomic write (`NAME.tmp-PID`).
fn is_run_output(name: &str) -> bool {
    OUTPUT_ENTRIES.contains(&name)
        || name
            .rsplit_once(".tmp-")
            .is_some_and(|(_, pid)| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// Makes `dir` ready for a run's output (rank 0, before the run).
///
/// - A path blocked by a file is refused, naming the file (not only the folder it blocks).
/// - A new run into a folder that already holds output is refused unless `overwrite`: its
///   series, summary and collections would be overwritten and a previous run's later
///   checkpoints and frames left mixed with the new ones. With `overwrite` the previous run's
///   outputs are removed ([`OUTPUT_ENTRIES`]); other files are kept and named in the log.
/// - A restart (`restart`) continues in the folder as it is.
pub fn prepare_output_dir(dir: &Path, overwrite: bool, restart: bool) -> Result<()> {
    // A symbolic link whose target does not exist: creating the folder fails with "File
    // exists", which names neither the link nor its target.
    if let Ok(m) = std::fs::symlink_metadata(dir)
        && m.file_type().is_symlink()
        && std::fs::metadata(dir).is_err()
    {
        let target = std::fs::read_link(dir)
            .map(|t| t.display().to_string())
            .unwrap_or_else(|_| "?".into());
        bail!(
            "{}: is a symbolic link to {target}, which does not exist; create that folder or \
             give another --out (or output.dir)",
            dir.display()
        );
    }
    // The nearest part of the path that exists must be a folder.
    for ancestor in dir.ancestors() {
        match std::fs::metadata(ancestor) {
            Ok(m) if m.is_dir() => break,
            Ok(_) if ancestor == dir => {
                bail!(
                    "{}: the output folder's path is a file, not a folder; give another --out \
                     (or output.dir)",
                    dir.display()
                )
            }
            Ok(_) => bail!(
                "{}: is a file, not a folder, so the output folder {} cannot be created in it; \
                 give another --out (or output.dir)",
                ancestor.display(),
                dir.display()
            ),
            // Not there yet, or below a file (which a shorter ancestor then names).
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory
                ) =>
            {
                continue;
            }
            Err(e) => {
                return Err(e).with_context(|| format!("{}: cannot inspect", ancestor.display()));
            }
        }
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the output directory", dir.display()))?;
    if restart {
        return Ok(());
    }
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list the output directory", dir.display()))?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    if names.is_empty() {
        return Ok(());
    }
    let (ours, others): (Vec<String>, Vec<String>) =
        names.into_iter().partition(|n| is_run_output(n));
    if !overwrite {
        if ours.is_empty() {
            // Only files the run does not write (notes, a scene copy): nothing is overwritten.
            return Ok(());
        }
        let shown: Vec<&str> = ours.iter().take(6).map(String::as_str).collect();
        bail!(
            "{}: the output folder holds a previous run's output ({}{}); give --overwrite to \
             remove it, --restart CHECKPOINT to continue that run, or another --out",
            dir.display(),
            shown.join(", "),
            if ours.len() > shown.len() {
                ", …"
            } else {
                ""
            }
        );
    }
    for name in &ours {
        let path = dir.join(name);
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        removed.with_context(|| format!("{}: cannot remove (--overwrite)", path.display()))?;
    }
    tracing::info!(
        "--overwrite: removed the previous output in {} ({})",
        dir.display(),
        ours.join(", ")
    );
    if !others.is_empty() {
        tracing::warn!(
            "{}: kept {} entries that polydem does not write: {}",
            dir.display(),
            others.len(),
            others.join(", ")
        );
    }
    Ok(())
}

/// Events that happen every so many seconds of simulated time.
pub(super) struct Schedule {
    interval: Option<f64>,
    next: f64,
}

impl Schedule {
    /// The schedule at time `now` (steps of `dt`): where [`Schedule::due`] would have left it
    /// had the run stepped from 0 to `now`. The next event is found by the same accumulation
    /// `due` does, not as `floor(now / i) · i`, whose round-off differs: a restart on an event
    /// then repeats it, or skips one, where the uninterrupted run did not.
    pub(super) fn new(interval: Option<f64>, now: f64, dt: f64) -> Self {
        let next = match interval {
            Some(i) if i > 0.0 => {
                let mut next = i;
                while next <= now + 0.5 * dt {
                    next += i;
                }
                next
            }
            _ => f64::INFINITY,
        };
        Schedule { interval, next }
    }

    /// True once per interval, at the first step at or past each multiple (half a step early
    /// counts, so round-off in the accumulated time never skips a frame).
    pub(super) fn due(&mut self, t: f64, dt: f64) -> bool {
        match self.interval {
            Some(i) if i > 0.0 && t + 0.5 * dt >= self.next => {
                while self.next <= t + 0.5 * dt {
                    self.next += i;
                }
                true
            }
            _ => false,
        }
    }
}

/// Output of a run in progress. Every rank writes its own frame piece; rank 0 writes the
/// collections, walls, series, checkpoints and summary from whole-run values.
pub(super) struct Outputs {
    pub(super) dir: PathBuf,
    frames: Option<FrameWriter>,
    series: Option<SeriesWriter>,
    type_template: Vec<usize>,
    pub(super) comm: Arc<dyn Comm>,
    /// Step of the last series row (on every rank: the row's sums are collective).
    series_step: Option<u64>,
}

impl Outputs {
    /// The writers of `sim`'s run into `dir`: new collections and series, or for a resumed run
    /// (`resumed`) the existing ones continued from the checkpoint's time and step.
    pub(super) fn open(
        sim: &RunState,
        dir: &Path,
        comm: Arc<dyn Comm>,
        resumed: bool,
    ) -> Result<Self> {
        let s = &sim.scene;
        let (rank, ranks) = (comm.rank(), comm.size());
        let type_template: Vec<usize> = s.particle_types.iter().map(|t| t.template).collect();
        let wall_names: Vec<String> = s.walls.iter().map(|w| w.name.clone()).collect();
        let series_path = dir.join("series.csv");
        let (nr, r) = (ranks as u32, rank as u32);
        let frames = if s.output.formats.vtu && s.output.frame_interval.is_some() {
            Some(if resumed {
                FrameWriter::resume_rank(dir, nr, r, sim.time)?
            } else {
                FrameWriter::new_rank(dir, nr, r)?
            })
        } else {
            None
        };
        let series = match (rank, resumed) {
            (0, true) => Some(SeriesWriter::resume(&series_path, &wall_names, sim.step)?),
            (0, false) => Some(SeriesWriter::new(&series_path, &wall_names)?),
            _ => None,
        };
        Ok(Outputs {
            dir: dir.to_path_buf(),
            frames,
            series,
            type_template,
            comm,
            // A resumed series ends at the checkpoint's step at most: its row there, if any, is
            // kept, never written twice.
            series_step: resumed.then_some(sim.step),
        })
    }

    pub(super) fn frame(&mut self, sim: &RunState) -> Result<()> {
        let s = &sim.scene;
        let rank = self.comm.rank();
        let ranks = self.comm.size();
        let wall_forces = if ranks > 1 {
            global_stats(&*self.comm, sim).wall_forces
        } else {
            sim.wall_forces.clone()
        };
        let view = FrameView {
            particles: &sim.particles,
            templates: &s.templates,
            type_template: &self.type_template,
            rank: rank as u32,
            fields: &s.output.fields,
        };
        if let Some(fw) = self.frames.as_mut() {
            let placed: Vec<Vec<[Vector3<f64>; 3]>> = s
                .walls
                .iter()
                .map(|w| {
                    let pose = w.motion.transform(sim.time);
                    w.triangles
                        .iter()
                        .map(|t| t.map(|v| (pose * nalgebra::Point3::from(v)).coords))
                        .collect()
                })
                .collect();
            let walls: Vec<WallView> = s
                .walls
                .iter()
                .zip(&placed)
                .zip(&wall_forces)
                .map(|((w, tris), f)| WallView {
                    name: &w.name,
                    triangles: tris,
                    force: *f,
                })
                .collect();
            fw.write_frame(sim.step, sim.time, std::slice::from_ref(&view), &walls)?;
        }
        if s.output.formats.csv {
            let particles_dir = self.dir.join("particles");
            std::fs::create_dir_all(&particles_dir)
                .with_context(|| format!("{}: cannot create", particles_dir.display()))?;
            let name = if ranks > 1 {
                format!("step_{:010}_r{rank:04}.csv", sim.step)
            } else {
                format!("step_{:010}.csv", sim.step)
            };
            write_particle_csv(&particles_dir.join(name), sim.time, &view)?;
        }
        // The .pvtu names every rank's piece: all are on disk before the frame is complete.
        self.comm.barrier();
        Ok(())
    }

    /// Appends the series row of the current step, once: the closing row of a run that
    /// ends on a series event is that event's row.
    pub(super) fn series(&mut self, sim: &RunState) -> Result<()> {
        if self.series_step == Some(sim.step) {
            return Ok(());
        }
        self.series_step = Some(sim.step);
        let g = whole_run(&*self.comm, sim);
        let (kt, kr, pg) = g.energies;
        if let Some(series) = self.series.as_mut() {
            series.append(&SeriesRow {
                step: sim.step,
                time: sim.time,
                kinetic_translational: kt,
                kinetic_rotational: kr,
                potential_gravity: pg,
                elastic: g.stats.elastic_energy,
                contacts: g.stats.contacts,
                wall_contacts: g.stats.wall_contacts,
                wall_forces: g.wall_forces,
            })?;
        }
        Ok(())
    }
}
