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

/// The top surface of a fill as a function of the distance from the container's axis, and the
/// cone that fits it: a heap poured on the axis (or a crater drained through it).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeapProfile {
    /// Distances from the axis of the rings sampled, m.
    pub radii: Vec<f64>,
    /// Mean height of the top surface above the floor on each ring, m.
    pub heights: Vec<f64>,
    /// The least-squares line `h = h0 − ρ tan α` over the rings from `fit[0]` to `fit[1]`:
    /// `[h0, tan α]`.
    pub line: [f64; 2],
    /// The angle α of the fitted cone to the horizontal, degrees: positive for a heap
    /// (highest on the axis), negative for a crater.
    pub angle_deg: f64,
    /// The range of distances fitted, m.
    pub fit: [f64; 2],
}

/// The top surface of `solids` in the container of cross-section `disk` on `rings` rings of
/// equal width (the middle of each), each sampled at points `spacing` apart, and the cone
/// fitted to the rings between `fit[0]` and `fit[1]` (fractions of the radius): the angle of
/// repose of a heap (the region near the axis, where the feed lands, and the region near the
/// wall, which holds the grains up, are usually left out).
pub fn heap_profile(
    solids: &PackedSolids,
    disk: &Disk,
    rings: usize,
    spacing: f64,
    fit: [f64; 2],
) -> HeapProfile {
    let width = disk.radius / rings as f64;
    let radii: Vec<f64> = (0..rings).map(|k| (k as f64 + 0.5) * width).collect();
    let heights: Vec<f64> = radii
        .par_iter()
        .map(|&rho| {
            let n = ((std::f64::consts::TAU * rho / spacing).ceil() as usize).max(8);
            // Summed in order: the same result at any thread count.
            (0..n)
                .map(|j| {
                    let phi = std::f64::consts::TAU * j as f64 / n as f64;
                    let (x, y) = (
                        disk.centre[0] + rho * phi.cos(),
                        disk.centre[1] + rho * phi.sin(),
                    );
                    solids
                        .top_at(x, y)
                        .map_or(0.0, |z| (z - disk.floor).max(0.0))
                })
                .sum::<f64>()
                / n as f64
        })
        .collect();
    let (lo, hi) = (fit[0] * disk.radius, fit[1] * disk.radius);
    let pts: Vec<[f64; 2]> = radii
        .iter()
        .zip(&heights)
        .filter(|(r, _)| **r >= lo && **r <= hi)
        .map(|(r, h)| [*r, *h])
        .collect();
    let [h0, slope] = super::fit_line(&pts);
    HeapProfile {
        radii,
        heights,
        line: [h0, -slope],
        angle_deg: (-slope).atan().to_degrees(),
        fit: [lo, hi],
    }
}
