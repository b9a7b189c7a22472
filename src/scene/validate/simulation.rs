//! The run-wide sections: `[simulation]` (time step, guard, neighbor list), `[domain]`,
//! `[parallel]` and `[output]`.

use super::*;
use crate::contact::FaceWindow;

impl Validator<'_> {
    pub(super) fn simulation(&mut self, s: &schema::SimulationSection) -> SimulationSettings {
        let dt = match (s.dt, s.dt_fraction) {
            (Some(dt), None) => TimeStep::Fixed(self.positive("simulation.dt", dt)),
            (None, Some(f)) => {
                if !(f > 0.0 && f <= 1.0) {
                    self.err(
                        "simulation.dt_fraction",
                        format!("must be in (0, 1], got {f}"),
                    );
                }
                TimeStep::FractionOfCritical(f)
            }
            (Some(_), Some(_)) => {
                self.err(
                    "simulation.dt_fraction",
                    "give either dt or dt_fraction, not both",
                );
                TimeStep::FractionOfCritical(0.1)
            }
            // The default of docs/accuracy.md (DEFAULT_DT_FRACTION).
            (None, None) => TimeStep::FractionOfCritical(DEFAULT_DT_FRACTION),
        };
        let end_time = self.positive("simulation.end_time", s.end_time);
        let n = s.neighbor.as_ref();
        let skin = n
            .and_then(|n| n.skin)
            .map_or(0.0, |x| self.non_negative("simulation.neighbor.skin", x));
        let mode = match n
            .and_then(|n| n.mode)
            .unwrap_or(schema::NeighborModeName::Auto)
        {
            schema::NeighborModeName::Auto => NeighborMode::Auto,
            schema::NeighborModeName::Gpu => NeighborMode::Gpu,
            schema::NeighborModeName::Cpu => NeighborMode::Cpu,
            schema::NeighborModeName::Hybrid => NeighborMode::Hybrid,
        };
        let mut guard = GuardSettings::default();
        if let Some(g) = s.guard.as_ref() {
            guard.enabled = g.enabled.unwrap_or(true);
            if let Some(x) = g.max_overlap {
                guard.max_overlap = self.positive("simulation.guard.max_overlap", x);
            }
            if let Some(x) = g.max_speed {
                guard.max_speed = Some(self.positive("simulation.guard.max_speed", x));
            }
            if let Some(x) = g.speed_factor {
                guard.speed_factor = self.positive("simulation.guard.speed_factor", x);
            }
        }
        SimulationSettings {
            dt,
            end_time,
            seed: s.seed,
            neighbor: NeighborSettings {
                skin,
                mode,
                // Resolved with the default skin (assemble.rs).
                hybrid_skin: n.and_then(|n| n.hybrid_skin).unwrap_or(f64::NAN),
            },
            guard,
            face_window: match s.face_window {
                Some(schema::FaceWindowName::Trajectory) => FaceWindow::Trajectory,
                Some(schema::FaceWindowName::Secant) => FaceWindow::Secant,
                None => FaceWindow::default(),
            },
        }
    }

    pub(super) fn domain(&mut self, d: &schema::DomainSection) -> Domain {
        let min = self.vector("domain.min", d.min);
        let max = self.vector("domain.max", d.max);
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            if max[a] <= min[a] {
                self.err(
                    "domain.max",
                    format!(
                        "must exceed domain.min on every axis; on {axis}: max {} ≤ min {}",
                        max[a], min[a]
                    ),
                );
            }
        }
        Domain {
            min,
            max,
            periodic: d.periodic,
            on_leaving: match d.on_leaving {
                Some(schema::LeavingName::Remove) => LeavingDomain::Remove,
                Some(schema::LeavingName::Error) | None => LeavingDomain::Error,
            },
        }
    }

    pub(super) fn parallel(&mut self, p: Option<&schema::ParallelSection>) -> ParallelSettings {
        let mut out = ParallelSettings::default();
        let Some(p) = p else {
            return out;
        };
        let grid = p.grid;
        if let Some(g) = grid
            && g.contains(&0)
        {
            self.err(
                "parallel.grid",
                format!("ranks per axis must be ≥ 1, got {g:?}"),
            );
        }
        out.decomposition = match p.decomposition {
            Some(schema::DecompositionName::Grid) => Decomposition::Grid(grid),
            Some(schema::DecompositionName::Rcb) | None => {
                if grid.is_some() {
                    self.err(
                        "parallel.grid",
                        "only with decomposition = \"grid\" (recursive bisection places its own cuts)",
                    );
                }
                Decomposition::Rcb
            }
        };
        if let Some(w) = p.weight {
            out.weight = match w {
                schema::BalanceWeightName::Count => BalanceWeight::Count,
                schema::BalanceWeightName::Cost => BalanceWeight::Cost,
            };
        }
        if let Some(t) = p.imbalance_threshold {
            if !(t > 1.0 && t.is_finite()) {
                self.err(
                    "parallel.imbalance_threshold",
                    format!("must be a finite number > 1 (max load / mean load), got {t}"),
                );
            }
            out.imbalance_threshold = t;
        }
        if let Some(n) = p.balance_interval {
            if n == 0 {
                self.err(
                    "parallel.balance_interval",
                    "must be ≥ 1 (neighbour-list rebuilds)",
                );
            }
            out.balance_interval = n;
        }
        out
    }

    pub(super) fn output(&mut self, o: &schema::OutputSection) -> OutputSettings {
        let dir = self.resolve(o.dir.as_deref().unwrap_or("out"));
        let frame_interval = o
            .frame_interval
            .map(|x| self.positive("output.frame_interval", x));
        let formats_given = o.formats.clone().unwrap_or_else(|| vec!["vtu".into()]);
        if formats_given.is_empty() {
            self.err(
                "output.formats",
                format!(
                    "must name at least one format; allowed: {}",
                    OUTPUT_FORMATS.join(", ")
                ),
            );
        }
        let mut formats = OutputFormats {
            vtu: false,
            csv: false,
        };
        for (i, f) in formats_given.iter().enumerate() {
            let slot = match f.as_str() {
                "vtu" => &mut formats.vtu,
                "csv" => &mut formats.csv,
                _ => {
                    self.err(
                        &format!("output.formats[{i}]"),
                        format!(
                            "unknown format \"{f}\"; allowed: {}",
                            OUTPUT_FORMATS.join(", ")
                        ),
                    );
                    continue;
                }
            };
            if std::mem::replace(slot, true) {
                self.err(
                    &format!("output.formats[{i}]"),
                    format!("format \"{f}\" is listed twice"),
                );
            }
        }
        let fields = o
            .fields
            .clone()
            .unwrap_or_else(|| DEFAULT_FIELDS.iter().map(|s| s.to_string()).collect());
        for (i, f) in fields.iter().enumerate() {
            if !OUTPUT_FIELDS.contains(&f.as_str()) {
                self.err(
                    &format!("output.fields[{i}]"),
                    format!(
                        "unknown field \"{f}\"; allowed: {}",
                        OUTPUT_FIELDS.join(", ")
                    ),
                );
            } else if fields[..i].contains(f) {
                self.err(
                    &format!("output.fields[{i}]"),
                    format!("field \"{f}\" is listed twice"),
                );
            }
        }
        let checkpoint_interval = o
            .checkpoint_interval
            .map(|x| self.positive("output.checkpoint_interval", x));
        let series_interval = o
            .series_interval
            .map_or(0.0, |x| self.positive("output.series_interval", x));
        let log_interval_steps = o.log_interval_steps.unwrap_or(DEFAULT_LOG_INTERVAL);
        if log_interval_steps == 0 {
            self.err("output.log_interval_steps", "must be at least 1");
        }
        if o.checkpoint_keep == Some(0) {
            self.err(
                "output.checkpoint_keep",
                "must be at least 1 (leave it out to keep every checkpoint)",
            );
        }
        if o.checkpoint_keep.is_some() && checkpoint_interval.is_none() {
            self.err(
                "output.checkpoint_keep",
                "needs output.checkpoint_interval (there are no periodic checkpoints to keep)",
            );
        }
        OutputSettings {
            dir,
            frame_interval,
            formats,
            fields,
            checkpoint_interval,
            series_interval,
            log_interval_steps,
            checkpoint_keep: o.checkpoint_keep,
        }
    }
}
