//! The flow in a quasi-two-dimensional rotating drum (seed paper Sec. 3.4, Fig. 15): the
//! time-averaged velocity field on a grid of the drum's cross-section, the dynamic angle of
//! repose of the free surface and the depth of the flowing layer.
//!
//! The drum turns about the y axis; its cross-section is the (x, z) plane. Samples are
//! particle centres and velocities from frames. Three observables follow from the averages:
//!
//! - **Free surface**: in each column of the central half of the chord (|x − x_c| ≤ R/2), the
//!   height where the mean number of centres per cell falls to half its bulk value (the 75th
//!   percentile of the occupied cells), interpolated between cells.
//! - **Dynamic angle of repose**: θ = atan |b| of the least-squares line z = a + b x through
//!   those heights.
//! - **Flowing layer depth**: along the normal to that line through its point nearest the axis
//!   (the middle of the free surface), the streamwise velocity u = v · t̂ (t̂ down the slope) is
//!   positive in the layer that flows down the surface and negative in the bed that turns with
//!   the drum; the depth is where u first changes sign below the surface, interpolated between
//!   cells (the usual definition, e.g. Orpe & Khakhar, J. Fluid Mech. 571 (2007) 1–32).

use nalgebra::Vector3;
use serde::Serialize;

/// The cross-section of one drum: its axis and radius in the (x, z) plane and the slice of y
/// that holds its particles (a scene may hold several drums along y).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrumSection {
    /// The axis' position `(x, z)`, m.
    pub centre: [f64; 2],
    /// Inner radius, m.
    pub radius: f64,
    /// Particles whose centre has `y[0] ≤ y ≤ y[1]` belong to this drum, m.
    pub y: [f64; 2],
}

/// One cell of the averaged field.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FieldCell {
    /// Cell centre, m.
    pub x: f64,
    /// Cell centre, m.
    pub z: f64,
    /// Mean number of particle centres in the cell per frame.
    pub occupancy: f64,
    /// Mean velocity of the centres found in the cell, m/s.
    pub vx: f64,
    /// Mean velocity of the centres found in the cell, m/s.
    pub vz: f64,
    /// Centres found in the cell over all frames.
    pub samples: u64,
}

/// The averaged flow of a drum and what follows from it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DrumFlow {
    /// Frames averaged.
    pub frames: usize,
    /// Samples (particle centres inside the drum) over all frames.
    pub samples: u64,
    /// Cell size of the grid, m.
    pub cell: f64,
    /// Dynamic angle of repose, degrees; `None` when fewer than three columns show a surface.
    pub angle_of_repose_deg: Option<f64>,
    /// The fitted free surface z = a + b x, `[a, b]`.
    pub surface_line: Option<[f64; 2]>,
    /// The middle of the free surface (the line's point nearest the axis), `(x, z)`.
    pub surface_middle: Option<[f64; 2]>,
    /// Depth of the flowing layer below the middle of the surface, m; `None` when the
    /// streamwise velocity does not change sign along the normal.
    pub flowing_layer_depth: Option<f64>,
    /// Largest streamwise velocity along the normal (down the slope), m/s.
    pub surface_speed: Option<f64>,
    /// Streamwise velocity along the normal: `(depth below the surface, u)` per sampled cell.
    pub profile: Vec<[f64; 2]>,
    /// Every cell with a sample.
    pub cells: Vec<FieldCell>,
}

/// Running sums over frames of the particles in one drum's cross-section.
#[derive(Clone, Debug)]
pub struct DrumSamples {
    section: DrumSection,
    cell: f64,
    /// Cells per side of the square grid over the drum's bounding square.
    side: usize,
    frames: usize,
    count: Vec<u64>,
    sum_v: Vec<[f64; 2]>,
}

/// Cells along the surface normal need this many samples for their mean velocity to count.
const MIN_PROFILE_SAMPLES: u64 = 10;

impl DrumSamples {
    /// Empty sums on a grid of square cells of size `cell` (m) over the drum's section.
    pub fn new(section: DrumSection, cell: f64) -> Self {
        let side = ((2.0 * section.radius / cell).ceil() as usize).max(1);
        DrumSamples {
            section,
            cell,
            side,
            frames: 0,
            count: vec![0; side * side],
            sum_v: vec![[0.0; 2]; side * side],
        }
    }

    /// The cell holding `(x, z)`, if inside the grid.
    fn cell_of(&self, x: f64, z: f64) -> Option<usize> {
        let [cx, cz] = self.section.centre;
        let r = self.section.radius;
        let i = ((x - (cx - r)) / self.cell).floor();
        let k = ((z - (cz - r)) / self.cell).floor();
        let n = self.side as f64;
        (i >= 0.0 && k >= 0.0 && i < n && k < n).then(|| k as usize * self.side + i as usize)
    }

    /// Centre of cell `(i, k)`.
    fn centre_of(&self, i: usize, k: usize) -> [f64; 2] {
        let [cx, cz] = self.section.centre;
        let r = self.section.radius;
        [
            cx - r + (i as f64 + 0.5) * self.cell,
            cz - r + (k as f64 + 0.5) * self.cell,
        ]
    }

    /// Adds one frame: the centres and velocities of every particle of the scene (those of
    /// other drums and those outside this one are skipped).
    pub fn add_frame<'a>(
        &mut self,
        particles: impl IntoIterator<Item = (&'a Vector3<f64>, &'a Vector3<f64>)>,
    ) {
        let s = self.section;
        for (x, v) in particles {
            let (dx, dz) = (x.x - s.centre[0], x.z - s.centre[1]);
            if x.y < s.y[0] || x.y > s.y[1] || dx * dx + dz * dz > s.radius * s.radius {
                continue;
            }
            if let Some(c) = self.cell_of(x.x, x.z) {
                self.count[c] += 1;
                self.sum_v[c][0] += v.x;
                self.sum_v[c][1] += v.z;
            }
        }
        self.frames += 1;
    }

    /// The averaged field, the free surface, the angle of repose and the flowing layer.
    pub fn flow(&self) -> DrumFlow {
        let n = self.side;
        let frames = self.frames.max(1) as f64;
        let occ = |c: usize| self.count[c] as f64 / frames;
        let mean_v = |c: usize| {
            let m = self.count[c].max(1) as f64;
            [self.sum_v[c][0] / m, self.sum_v[c][1] / m]
        };
        let mut cells = Vec::new();
        for k in 0..n {
            for i in 0..n {
                let c = k * n + i;
                if self.count[c] > 0 {
                    let [x, z] = self.centre_of(i, k);
                    let [vx, vz] = mean_v(c);
                    cells.push(FieldCell {
                        x,
                        z,
                        occupancy: occ(c),
                        vx,
                        vz,
                        samples: self.count[c],
                    });
                }
            }
        }
        let mut flow = DrumFlow {
            frames: self.frames,
            samples: self.count.iter().sum(),
            cell: self.cell,
            angle_of_repose_deg: None,
            surface_line: None,
            surface_middle: None,
            flowing_layer_depth: None,
            surface_speed: None,
            profile: Vec::new(),
            cells,
        };
        // The bulk's occupancy: the 75th percentile of the occupied cells (the loose cells of
        // the surface and of flying particles are the fewer).
        let mut occupied: Vec<f64> = flow.cells.iter().map(|c| c.occupancy).collect();
        if occupied.is_empty() {
            return flow;
        }
        occupied.sort_by(f64::total_cmp);
        let half = 0.5 * occupied[(occupied.len() * 3 / 4).min(occupied.len() - 1)];
        // The surface in each column of the central half of the chord: from the top down, the
        // first cell at half the bulk's occupancy, interpolated with the cell above.
        let [cx, cz] = self.section.centre;
        let r = self.section.radius;
        let mut points = Vec::new();
        for i in 0..n {
            let x = self.centre_of(i, 0)[0];
            if (x - cx).abs() > 0.5 * r {
                continue;
            }
            if let Some(k) = (0..n).rev().find(|&k| occ(k * n + i) >= half) {
                let z = self.centre_of(i, k)[1];
                let (below, above) = (
                    occ(k * n + i),
                    if k + 1 < n { occ((k + 1) * n + i) } else { 0.0 },
                );
                let up = if below > above {
                    ((below - half) / (below - above)).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                points.push([x, z + up * self.cell]);
            }
        }
        if points.len() < 3 {
            return flow;
        }
        let [a, b] = super::fit_line(&points);
        flow.surface_line = Some([a, b]);
        flow.angle_of_repose_deg = Some(b.abs().atan().to_degrees());
        // Down the slope (t_z ≤ 0) and into the bed (n_z < 0).
        let norm = (1.0 + b * b).sqrt();
        let t = if b > 0.0 {
            [-1.0 / norm, -b / norm]
        } else {
            [1.0 / norm, b / norm]
        };
        let nrm = [b / norm, -1.0 / norm];
        let off = (b * cx - cz + a) / (1.0 + b * b);
        let p = [cx - off * b, cz + off];
        flow.surface_middle = Some(p);
        // The streamwise velocity down the normal, from a cell above the surface to the far
        // wall, at half-cell steps (each cell counted once).
        let mut last = None;
        let mut s = -self.cell;
        while s < 2.0 * r {
            let q = [p[0] + s * nrm[0], p[1] + s * nrm[1]];
            s += 0.5 * self.cell;
            if (q[0] - cx).powi(2) + (q[1] - cz).powi(2) > r * r {
                continue;
            }
            let Some(c) = self.cell_of(q[0], q[1]) else {
                continue;
            };
            if last == Some(c) || self.count[c] < MIN_PROFILE_SAMPLES {
                continue;
            }
            last = Some(c);
            let v = mean_v(c);
            let depth = s - 0.5 * self.cell;
            flow.profile.push([depth, v[0] * t[0] + v[1] * t[1]]);
        }
        flow.surface_speed = flow
            .profile
            .iter()
            .map(|p| p[1])
            .fold(None, |m: Option<f64>, u| Some(m.map_or(u, |m| m.max(u))));
        // The first change of sign below a layer that flows down the slope.
        let mut flowing = false;
        for w in flow.profile.windows(2) {
            let ([d0, u0], [d1, u1]) = (w[0], w[1]);
            flowing |= u0 > 0.0;
            if flowing && u0 > 0.0 && u1 <= 0.0 {
                flow.flowing_layer_depth = Some(d0 + (d1 - d0) * u0 / (u0 - u1));
                break;
            }
        }
        flow
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bed of `n × n` particles per frame on a lattice of spacing `h` below the surface
    /// z = z0 + tan(θ) x, flowing down the slope at `u0` (1 − d/δ) to depth δ, and turning
    /// with the drum below (a solid body at ω about the axis): the field, the angle and the
    /// depth come back.
    #[test]
    fn a_synthetic_flow_gives_back_its_angle_and_layer_depth() {
        let (r, h) = (0.15, 0.0025);
        let section = DrumSection {
            centre: [0.0, 0.0],
            radius: r,
            y: [-0.01, 0.01],
        };
        // ω < 0 about y lifts the bed on the +x side, where the surface is high (b > 0).
        let (theta, z0, delta, u0, omega) = (30f64.to_radians(), -0.02, 0.03, 0.5, -4.0);
        let (b, norm) = (theta.tan(), (1.0 + theta.tan().powi(2)).sqrt());
        // Down the slope for b > 0 is −x.
        let t = Vector3::new(-1.0 / norm, 0.0, -b / norm);
        let mut points = Vec::new();
        let m = (r / h) as i64;
        for k in -m..=m {
            for i in -m..=m {
                let x = Vector3::new((i as f64 + 0.5) * h, 0.0, (k as f64 + 0.5) * h);
                let surface = z0 + b * x.x;
                if x.x * x.x + x.z * x.z > (r - 0.005).powi(2) || x.z > surface {
                    continue;
                }
                let d = (surface - x.z) / norm;
                let v = if d < delta {
                    u0 * (1.0 - d / delta) * t
                } else {
                    // Turning with the drum: ω ŷ × x, slower than the layer above.
                    0.2 * omega * Vector3::new(x.z, 0.0, -x.x)
                };
                points.push((x, v));
            }
        }
        let mut samples = DrumSamples::new(section, 0.005);
        for _ in 0..20 {
            samples.add_frame(points.iter().map(|(x, v)| (x, v)));
        }
        let f = samples.flow();
        assert_eq!(f.frames, 20);
        let angle = f.angle_of_repose_deg.unwrap();
        assert!((angle - 30.0).abs() < 0.5, "angle {angle}");
        let depth = f.flowing_layer_depth.unwrap();
        // The bed below turns up the slope, so u changes sign at δ; cells of 5 mm blur it.
        assert!(
            (depth - delta).abs() < 0.005,
            "depth {depth}, {:?}",
            f.profile
        );
        let speed = f.surface_speed.unwrap();
        assert!(speed > 0.8 * u0 && speed <= u0, "surface speed {speed}");
    }

    #[test]
    fn particles_of_another_drum_or_outside_are_left_out() {
        let section = DrumSection {
            centre: [0.0, 0.0],
            radius: 0.1,
            y: [0.0, 0.01],
        };
        let mut s = DrumSamples::new(section, 0.01);
        let v = Vector3::new(1.0, 0.0, 0.0);
        let inside = Vector3::new(0.05, 0.005, 0.0);
        let other_drum = Vector3::new(0.05, 0.03, 0.0);
        let outside = Vector3::new(0.09, 0.005, 0.09);
        s.add_frame([(&inside, &v), (&other_drum, &v), (&outside, &v)]);
        let f = s.flow();
        assert_eq!(f.samples, 1);
        assert_eq!(f.cells.len(), 1);
        assert!((f.cells[0].x - 0.055).abs() < 1e-12 && (f.cells[0].vx - 1.0).abs() < 1e-15);
    }
}
