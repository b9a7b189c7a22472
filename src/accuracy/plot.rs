//! The Pareto plot `accuracy.svg`: every case's error against its run time.

use super::AccuracyRow;
use anyhow::{Result, anyhow};
use std::path::Path;

/// Error against run time on log axes, one series per case and backend, points labelled by
/// dt_fraction; the 1 % line dashed.
pub(super) fn plot(path: &Path, rows: &[AccuracyRow]) -> Result<()> {
    use plotters::prelude::*;
    let floor = 1e-7;
    let (mut t_lo, mut t_hi) = (f64::MAX, f64::MIN);
    let (mut e_lo, mut e_hi) = (f64::MAX, f64::MIN);
    for r in rows {
        t_lo = t_lo.min(r.seconds);
        t_hi = t_hi.max(r.seconds);
        e_lo = e_lo.min(r.error.max(floor));
        e_hi = e_hi.max(r.error.max(floor));
    }
    if rows.is_empty() {
        return Ok(());
    }
    let root = SVGBackend::new(path, (960, 640)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<std::io::Error>| anyhow!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "polydem bench accuracy: error against run time",
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(
            (t_lo * 0.7..t_hi * 1.4).log_scale(),
            (e_lo * 0.5..e_hi.max(0.02) * 2.0).log_scale(),
        )
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("run time of the case (s)")
        .y_desc("relative error")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(LineSeries::new(
            [(t_lo * 0.7, 0.01), (t_hi * 1.4, 0.01)],
            BLACK.mix(0.4).stroke_width(1),
        ))
        .map_err(err)?
        .label("1 %");
    let mut series: Vec<(String, Vec<&AccuracyRow>)> = Vec::new();
    for r in rows {
        let key = format!("{} ({})", r.case, r.backend);
        match series.iter_mut().find(|(k, _)| *k == key) {
            Some((_, v)) => v.push(r),
            None => series.push((key, vec![r])),
        }
    }
    for (k, (key, pts)) in series.iter().enumerate() {
        let colour = Palette99::pick(k).to_rgba();
        let points: Vec<(f64, f64)> = pts
            .iter()
            .map(|r| (r.seconds, r.error.max(floor)))
            .collect();
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
            .map_err(err)?
            .label(key.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
        chart
            .draw_series(pts.iter().map(|r| {
                EmptyElement::at((r.seconds, r.error.max(floor)))
                    + Circle::new((0, 0), 3, colour.filled())
                    + Text::new(
                        format!("{}", r.dt_fraction),
                        (5, -12),
                        ("sans-serif", 11).into_font(),
                    )
            }))
            .map_err(err)?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}
