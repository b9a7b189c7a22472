//! Fill height of a packing in a vertical container (seed paper Sec. 3.3: the height 63
//! dodecahedra reach in a cylinder).

use super::solids::PackedSolids;
use rayon::prelude::*;
use serde::Serialize;

/// A horizontal disk: the container's cross-section, from its floor up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disk {
    /// Axis position `(x, y)`, m.
    pub centre: [f64; 2],
    /// Inner radius, m.
    pub radius: f64,
    /// Floor height, m.
    pub floor: f64,
}

/// How high a packing fills a container.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FillHeight {
    /// Particles counted (all of the state).
    pub particles: usize,
    /// Highest point of any particle above the floor, m: what a ruler laid across the rim of
    /// the packing reads.
    pub highest: f64,
    /// Mean over the cross-section of the highest solid point above each point of the floor,
    /// m (zero where no particle is above it): the height of the packing's top surface.
    pub mean_surface: f64,
    /// Particle volume over the container's volume up to `mean_surface`: the bulk solid
    /// fraction of the fill.
    pub solid_fraction: f64,
    /// Vertical lines sampled (a square grid of the given spacing inside the disk).
    pub samples: usize,
}

/// The fill height of `solids` in the container of cross-section `disk`, the top surface
/// sampled on a square grid of spacing `spacing`. Particles wholly outside the disk count too:
/// pass only the state of one container.
pub fn fill_height(solids: &PackedSolids, disk: &Disk, spacing: f64) -> FillHeight {
    let m = (disk.radius / spacing).ceil() as i64;
    let lines: Vec<(f64, f64)> = (-m..=m)
        .flat_map(|j| (-m..=m).map(move |i| (i as f64 * spacing, j as f64 * spacing)))
        .filter(|(x, y)| x * x + y * y <= disk.radius * disk.radius)
        .map(|(x, y)| (disk.centre[0] + x, disk.centre[1] + y))
        .collect();
    let tops: Vec<f64> = lines
        .par_iter()
        .with_min_len(crate::par::SEARCH)
        .map(|&(x, y)| {
            solids
                .top_at(x, y)
                .map_or(0.0, |z| (z - disk.floor).max(0.0))
        })
        .collect();
    // Summed in order: the same result at any thread count.
    let mean_surface = tops.iter().sum::<f64>() / tops.len().max(1) as f64;
    let volume: f64 = (0..solids.len()).map(|i| solids.volume(i)).sum();
    let container = std::f64::consts::PI * disk.radius * disk.radius * mean_surface;
    FillHeight {
        particles: solids.len(),
        highest: solids.highest_point().map_or(0.0, |z| z - disk.floor),
        mean_surface,
        solid_fraction: if container > 0.0 {
            volume / container
        } else {
            0.0
        },
        samples: lines.len(),
    }
}
