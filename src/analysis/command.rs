//! `polydem analyze`: its subcommands' arguments and their checks, and the observable each
//! computes from a state or a run's frames, as JSON.

use super::{
    Disk, DrumSamples, DrumSection, PackedSolids, Tube, fill_height, frame_tables, heap_profile,
    load_state, radial_porosity, solids_in_cylinder,
};
use anyhow::{Context, Result, anyhow, bail};
use std::path::{Path, PathBuf};

/// The state an analysis reads and the vertical cylinder it looks in.
#[derive(clap::Args)]
pub struct AnalyzedCylinder {
    /// The scene the checkpoint was written for.
    pub scene: PathBuf,
    /// The state analysed.
    pub checkpoint: PathBuf,
    /// The cylinder's axis, x and y (m). Only the particles whose centre lies inside the
    /// cylinder count, so a scene of several containers side by side is analysed one at a time.
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 0.0])]
    pub centre: Vec<f64>,
    /// The cylinder's inner radius (m).
    #[arg(long)]
    pub radius: f64,
}

#[derive(clap::Subcommand)]
pub enum AnalyzeWhat {
    /// Fill height in a vertical cylindrical container: the highest particle point, the mean
    /// height of the packing's top surface over the cross-section, and the bulk solid fraction.
    FillHeight {
        #[command(flatten)]
        at: AnalyzedCylinder,
        /// Floor height (m).
        #[arg(long, default_value_t = 0.0)]
        floor: f64,
        /// Spacing of the vertical lines sampled (m; default radius / 200).
        #[arg(long)]
        spacing: Option<f64>,
    },
    /// Porosity of a section of a vertical tube: overall, and in annuli from the wall to the
    /// axis.
    Porosity {
        #[command(flatten)]
        at: AnalyzedCylinder,
        /// Lower and upper ends of the section (m).
        #[arg(long, value_delimiter = ',', required = true)]
        z: Vec<f64>,
        /// Annuli from the wall to the axis.
        #[arg(long, default_value_t = 50)]
        annuli: usize,
        /// Spacing of the sampled points (m; default radius / 100).
        #[arg(long)]
        spacing: Option<f64>,
    },
    /// The top surface of a fill in a vertical cylinder by distance from the axis, and the
    /// angle of the cone fitted to it: a heap's angle of repose (negative for a crater).
    Heap {
        #[command(flatten)]
        at: AnalyzedCylinder,
        /// Floor height (m).
        #[arg(long, default_value_t = 0.0)]
        floor: f64,
        /// Rings of equal width from the axis to the wall.
        #[arg(long, default_value_t = 20)]
        rings: usize,
        /// Fitted range of distances from the axis, as fractions of the radius.
        #[arg(long, value_delimiter = ',', default_values_t = [0.2, 0.8])]
        fit: Vec<f64>,
        /// Spacing of the points sampled on each ring (m; default radius / 200).
        #[arg(long)]
        spacing: Option<f64>,
    },
    /// The flow of a quasi-2D drum turning about the y axis, averaged over frames: velocity
    /// field, dynamic angle of repose and flowing layer depth (docs/production.md §2).
    Drum {
        /// The run's frame folder (`<output.dir>/particles`, written with formats = ["csv"]).
        frames: PathBuf,
        /// The drum's inner radius (m).
        #[arg(long)]
        radius: f64,
        /// The drum's axis, x and z (m).
        #[arg(long, value_delimiter = ',', default_values_t = [0.0, 0.0])]
        centre: Vec<f64>,
        /// The slice of y holding this drum's particles, YMIN,YMAX (m; default: every particle).
        #[arg(long, value_delimiter = ',')]
        y: Option<Vec<f64>>,
        /// Frames before this time (s) are skipped: the start-up.
        #[arg(long, default_value_t = 0.0)]
        from: f64,
        /// Cell size of the averaging grid (m; default radius / 30).
        #[arg(long)]
        cell: Option<f64>,
        /// Writes the averaged field here as CSV: x,z,occupancy,vx,vz,samples per cell.
        #[arg(long)]
        field: Option<PathBuf>,
    },
}

/// `v` when it is a positive length, else the error naming option `--name`.
fn positive(name: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(anyhow!("--{name} {v}: must be a positive length (m)"))
    }
}

/// The observable `what` asks for, as JSON, with every argument checked first (a message that
/// names the option and what is allowed).
pub fn analyze(what: AnalyzeWhat) -> Result<serde_json::Value> {
    // The state, placed as solids, and the cylinder's axis and radius.
    let open = |at: &AnalyzedCylinder| -> Result<(PackedSolids, [f64; 2], f64)> {
        if at.centre.len() != 2 {
            bail!("--centre {:?}: two numbers, x,y (m)", at.centre);
        }
        let radius = positive("radius", at.radius)?;
        let (s, p) = load_state(&at.scene, &at.checkpoint)?;
        let centre = [at.centre[0], at.centre[1]];
        Ok((solids_in_cylinder(&s, &p, centre, radius), centre, radius))
    };
    Ok(match what {
        AnalyzeWhat::FillHeight { at, floor, spacing } => {
            let r = positive("radius", at.radius)?;
            let spacing = positive("spacing", spacing.unwrap_or(r / 200.0))?;
            let (solids, centre, radius) = open(&at)?;
            let disk = Disk {
                centre,
                radius,
                floor,
            };
            serde_json::to_value(fill_height(&solids, &disk, spacing))?
        }
        AnalyzeWhat::Porosity {
            at,
            z,
            annuli,
            spacing,
        } => {
            let r = positive("radius", at.radius)?;
            let spacing = positive("spacing", spacing.unwrap_or(r / 100.0))?;
            if z.len() != 2
                || z[1].partial_cmp(&z[0]) != Some(std::cmp::Ordering::Greater)
                || annuli == 0
            {
                bail!(
                    "--z {z:?}: two heights ZMIN,ZMAX (m), the upper above the lower; \
                     --annuli {annuli}: at least 1"
                );
            }
            let (solids, centre, radius) = open(&at)?;
            let tube = Tube {
                centre,
                radius,
                z: [z[0], z[1]],
            };
            serde_json::to_value(radial_porosity(&solids, &tube, annuli, spacing))?
        }
        AnalyzeWhat::Heap {
            at,
            floor,
            rings,
            fit,
            spacing,
        } => {
            let r = positive("radius", at.radius)?;
            let spacing = positive("spacing", spacing.unwrap_or(r / 200.0))?;
            let fit = match fit.as_slice() {
                [a, b] if (0.0..1.0).contains(a) && b > a && *b <= 1.0 => [*a, *b],
                v => bail!("--fit {v:?}: two fractions of the radius A,B with 0 ≤ A < B ≤ 1"),
            };
            if rings < 2 {
                bail!("--rings {rings}: at least 2");
            }
            let (solids, centre, radius) = open(&at)?;
            let disk = Disk {
                centre,
                radius,
                floor,
            };
            serde_json::to_value(heap_profile(&solids, &disk, rings, spacing, fit))?
        }
        AnalyzeWhat::Drum {
            frames,
            radius,
            centre,
            y,
            from,
            cell,
            field,
        } => drum(
            &frames,
            radius,
            &centre,
            y.as_deref(),
            from,
            cell,
            field.as_deref(),
        )?,
    })
}

/// `polydem analyze drum`: the averaged flow of one drum's particles over the frames from
/// `from` on (docs/production.md, `polydem analyze`), the field written to `field` as CSV.
fn drum(
    frames: &Path,
    radius: f64,
    centre: &[f64],
    y: Option<&[f64]>,
    from: f64,
    cell: Option<f64>,
    field: Option<&Path>,
) -> Result<serde_json::Value> {
    let radius = positive("radius", radius)?;
    let cell = positive("cell", cell.unwrap_or(radius / 30.0))?;
    if centre.len() != 2 {
        bail!("--centre {centre:?}: two numbers, x,z (m)");
    }
    let y = match y {
        None => [f64::NEG_INFINITY, f64::INFINITY],
        Some([a, b]) if b > a => [*a, *b],
        Some(v) => {
            bail!("--y {v:?}: two numbers YMIN,YMAX (m), the second above the first")
        }
    };
    let section = DrumSection {
        centre: [centre[0], centre[1]],
        radius,
        y,
    };
    let mut samples = DrumSamples::new(section, cell);
    let mut times = Vec::new();
    for tables in frame_tables(frames)? {
        let mut rows = Vec::new();
        for t in &tables {
            rows.extend(crate::io::read_particle_csv(t)?);
        }
        let Some(time) = rows.first().map(|r| r.time) else {
            continue;
        };
        if time < from {
            continue;
        }
        times.push(time);
        samples.add_frame(rows.iter().map(|r| (&r.position, &r.velocity)));
    }
    if times.is_empty() {
        bail!("{}: no frame at or after --from {from} s", frames.display());
    }
    let flow = samples.flow();
    if let Some(path) = field {
        let mut csv = String::from("x,z,occupancy,vx,vz,samples\n");
        for c in &flow.cells {
            csv.push_str(&format!(
                "{},{},{},{},{},{}\n",
                c.x, c.z, c.occupancy, c.vx, c.vz, c.samples
            ));
        }
        crate::io::write_atomic(path, csv.as_bytes())
            .with_context(|| format!("{}: cannot write the field", path.display()))?;
    }
    let mut v = serde_json::to_value(&flow)?;
    if let Some(o) = v.as_object_mut() {
        o.remove("cells");
        o.insert("radius".into(), radius.into());
        o.insert("first_time".into(), times[0].into());
        o.insert("last_time".into(), times[times.len() - 1].into());
    }
    Ok(v)
}
