//! Subdomains: one axis-aligned box per rank that together tile the domain, laid out as a
//! Cartesian grid or by recursive coordinate bisection (seed paper Sec. 2.6; RCB as in Berger &
//! Bokhari 1987), and the queries the halo exchange and migration need on them.
//!
//! Neighbouring boxes share their cut coordinates bitwise (a cut is one number used by both
//! sides), and ownership is half-open (`lo ≤ x < hi`, the domain's upper face included in the
//! last box), so every point of the domain has exactly one owner.

use super::comm::Comm;
use crate::neighbor::Bounds;
use nalgebra::Vector3;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub lo: Vector3<f64>,
    pub hi: Vector3<f64>,
}

impl Aabb {
    /// Distance from `x` to the box (0 inside).
    pub fn distance(&self, x: &Vector3<f64>) -> f64 {
        let d = Vector3::from_fn(|k, _| (self.lo[k] - x[k]).max(x[k] - self.hi[k]).max(0.0));
        d.norm()
    }

    /// Distance between two boxes (0 when they touch or overlap).
    pub fn box_distance(&self, o: &Aabb) -> f64 {
        let d = Vector3::from_fn(|k, _| (self.lo[k] - o.hi[k]).max(o.lo[k] - self.hi[k]).max(0.0));
        d.norm()
    }

    /// The box moved by `shift`.
    pub fn shifted(&self, shift: &Vector3<f64>) -> Aabb {
        Aabb {
            lo: self.lo + shift,
            hi: self.hi + shift,
        }
    }

    /// The box grown by `h` on every side.
    pub fn grown(&self, h: f64) -> Aabb {
        Aabb {
            lo: self.lo.add_scalar(-h),
            hi: self.hi.add_scalar(h),
        }
    }
}

/// Why a domain cannot be split as asked.
#[derive(Debug, thiserror::Error)]
pub enum DecompositionError {
    #[error(
        "{ranks} ranks cannot split the domain {extent:?} m: every split subdomain must be at \
         least 2 × the halo width ({halo:e} m, twice the largest bounding radius plus the skin) \
         wide on a split axis; run on fewer ranks or give `[parallel] grid` explicitly"
    )]
    TooManyRanks {
        ranks: usize,
        extent: [f64; 3],
        halo: f64,
    },
    #[error(
        "`[parallel] grid = {grid:?}` has {product} subdomains but the run has {ranks} ranks; \
         the product of the grid must equal the rank count"
    )]
    GridMismatch {
        grid: [u32; 3],
        product: usize,
        ranks: usize,
    },
    #[error(
        "`[parallel] grid = {grid:?}` makes subdomains {width:e} m wide along {axis}, less than \
         2 × the halo width {halo:e} m"
    )]
    GridTooFine {
        grid: [u32; 3],
        axis: char,
        width: f64,
        halo: f64,
    },
}

impl DecompositionError {
    /// The scene key the error is about: the grid when one was given, else the domain, whose
    /// extent is too small for the rank count.
    pub fn scene_key(&self) -> &'static str {
        match self {
            DecompositionError::TooManyRanks { .. } => "domain",
            DecompositionError::GridMismatch { .. } | DecompositionError::GridTooFine { .. } => {
                "parallel.grid"
            }
        }
    }
}

/// The subdomains of all ranks.
#[derive(Clone, Debug, PartialEq)]
pub struct Subdomains {
    /// Box of each rank.
    pub boxes: Vec<Aabb>,
    /// The whole domain and its periodicity.
    pub domain: Bounds,
    /// Width of the region whose particles a neighbour needs as ghosts: twice the largest
    /// bounding radius plus the Verlet skin (the pair-list cutoff).
    pub halo: f64,
}

impl Subdomains {
    /// The domain's extent per axis.
    pub fn period(&self) -> Vector3<f64> {
        self.domain.max - self.domain.min
    }

    /// Whether rank `r`'s box covers the whole domain along axis `k` (its own periodic images
    /// are then handled by the pair search's periodic wrap, not by ghosts).
    pub fn spans(&self, r: usize, k: usize) -> bool {
        let b = &self.boxes[r];
        b.lo[k] <= self.domain.min[k] && b.hi[k] >= self.domain.max[k]
    }

    /// Whether rank `r` owns a particle at `x` (half-open boxes; the upper face of the domain
    /// belongs to the last box).
    pub fn contains(&self, r: usize, x: &Vector3<f64>) -> bool {
        let b = &self.boxes[r];
        (0..3).all(|k| {
            let c = x[k].clamp(self.domain.min[k], self.domain.max[k]);
            b.lo[k] <= c && (c < b.hi[k] || (b.hi[k] >= self.domain.max[k] && c <= b.hi[k]))
        })
    }

    /// The rank owning a particle at `x` (clamped into the domain).
    pub fn owner(&self, x: &Vector3<f64>) -> usize {
        (0..self.boxes.len())
            .find(|&r| self.contains(r, x))
            .unwrap_or(0)
    }

    /// Periodic image offsets (each component −1, 0 or 1, non-zero only on periodic axes) of
    /// the domain, all of them when `only_for` is `None`, else only along the axes rank
    /// `only_for` does not span.
    pub fn image_offsets(&self, only_for: Option<usize>) -> Vec<[i8; 3]> {
        let range = |k: usize| -> Vec<i8> {
            let wraps = self.domain.periodic[k] && only_for.is_none_or(|r| !self.spans(r, k));
            if wraps { vec![-1, 0, 1] } else { vec![0] }
        };
        let mut out = Vec::new();
        for &z in &range(2) {
            for &y in &range(1) {
                for &x in &range(0) {
                    out.push([x, y, z]);
                }
            }
        }
        out
    }

    /// The shift of image `o`.
    pub fn shift(&self, o: &[i8; 3]) -> Vector3<f64> {
        let p = self.period();
        Vector3::new(o[0] as f64 * p.x, o[1] as f64 * p.y, o[2] as f64 * p.z)
    }

    /// The ranks other than `r` whose boxes (or periodic images) come within the halo of `r`'s
    /// box, sorted: a symmetric relation, so both sides of each halo message agree.
    pub fn neighbours(&self, r: usize) -> Vec<usize> {
        let offsets = self.image_offsets(None);
        (0..self.boxes.len())
            .filter(|&s| {
                s != r
                    && offsets.iter().any(|o| {
                        self.boxes[r]
                            .shifted(&self.shift(o))
                            .box_distance(&self.boxes[s])
                            < self.halo
                    })
            })
            .collect()
    }

    /// A single box: the whole domain (one rank).
    pub fn single(domain: Bounds, halo: f64) -> Self {
        Subdomains {
            boxes: vec![Aabb {
                lo: domain.min,
                hi: domain.max,
            }],
            domain,
            halo,
        }
    }

    /// A Cartesian grid of `grid[k]` equal slabs per axis; ranks ordered x fastest.
    pub fn grid(domain: Bounds, halo: f64, grid: [u32; 3]) -> Self {
        let cuts = |k: usize| -> Vec<f64> {
            let n = grid[k] as usize;
            let (a, b) = (domain.min[k], domain.max[k]);
            (0..=n)
                .map(|i| match i {
                    0 => a,
                    i if i == n => b,
                    i => a + (b - a) * i as f64 / n as f64,
                })
                .collect()
        };
        let (cx, cy, cz) = (cuts(0), cuts(1), cuts(2));
        let mut boxes = Vec::new();
        for z in 0..grid[2] as usize {
            for y in 0..grid[1] as usize {
                for x in 0..grid[0] as usize {
                    boxes.push(Aabb {
                        lo: Vector3::new(cx[x], cy[y], cz[z]),
                        hi: Vector3::new(cx[x + 1], cy[y + 1], cz[z + 1]),
                    });
                }
            }
        }
        Subdomains {
            boxes,
            domain,
            halo,
        }
    }

    /// A given grid, checked against the rank count and the halo.
    pub fn checked_grid(
        domain: Bounds,
        halo: f64,
        grid: [u32; 3],
        ranks: usize,
    ) -> Result<Self, DecompositionError> {
        let product = grid.iter().map(|&g| g as usize).product::<usize>();
        if product != ranks {
            return Err(DecompositionError::GridMismatch {
                grid,
                product,
                ranks,
            });
        }
        for k in 0..3 {
            let width = (domain.max[k] - domain.min[k]) / grid[k] as f64;
            if grid[k] > 1 && width < 2.0 * halo {
                return Err(DecompositionError::GridTooFine {
                    grid,
                    axis: ['x', 'y', 'z'][k],
                    width,
                    halo,
                });
            }
        }
        Ok(Self::grid(domain, halo, grid))
    }

    /// The rank grid for `ranks` ranks that cuts the least interface area (the halo traffic)
    /// among those whose subdomains are at least 2 × the halo wide on every split axis.
    pub fn choose_grid(
        domain: &Bounds,
        halo: f64,
        ranks: usize,
    ) -> Result<[u32; 3], DecompositionError> {
        let e = domain.max - domain.min;
        let mut best: Option<(f64, [u32; 3])> = None;
        for px in 1..=ranks {
            if !ranks.is_multiple_of(px) {
                continue;
            }
            for py in 1..=ranks / px {
                if !(ranks / px).is_multiple_of(py) {
                    continue;
                }
                let g = [px, py, ranks / px / py];
                let fits = (0..3).all(|k| g[k] == 1 || e[k] / g[k] as f64 >= 2.0 * halo);
                if !fits {
                    continue;
                }
                // Interfaces normal to axis k: g_k − 1 of them, plus the periodic seam.
                let area: f64 = (0..3)
                    .map(|k| {
                        let cuts = (g[k] - 1) + usize::from(domain.periodic[k] && g[k] > 1);
                        cuts as f64 * e[(k + 1) % 3] * e[(k + 2) % 3]
                    })
                    .sum();
                if best.is_none_or(|(a, _)| area < a * (1.0 - 1e-12)) {
                    best = Some((area, g.map(|v| v as u32)));
                }
            }
        }
        best.map(|b| b.1).ok_or(DecompositionError::TooManyRanks {
            ranks,
            extent: e.into(),
            halo,
        })
    }

    /// Recursive coordinate bisection of the domain into `comm.size()` boxes holding equal
    /// shares of the weight of the particles at `positions` (this rank's; every rank calls it
    /// with its own). Each cut is along the longest axis of the box being split that can be cut
    /// with both parts at least 2 × halo wide, at the weighted quantile of the share the lower
    /// part's ranks should carry, located by histograms summed over the ranks and refined three
    /// times (to 1/128³ of the box). Every rank makes the same calls in the same order.
    pub fn bisection(
        comm: &dyn Comm,
        domain: Bounds,
        halo: f64,
        positions: &[Vector3<f64>],
        weights: &[f64],
    ) -> Result<Self, DecompositionError> {
        let ranks = comm.size();
        let mut out = Subdomains {
            boxes: vec![
                Aabb {
                    lo: domain.min,
                    hi: domain.max,
                };
                ranks
            ],
            domain,
            halo,
        };
        let all: Vec<usize> = (0..positions.len()).collect();
        let whole = out.boxes[0];
        out.bisect(comm, whole, 0, ranks, positions, weights, &all)?;
        Ok(out)
    }

    #[allow(clippy::too_many_arguments)]
    fn bisect(
        &mut self,
        comm: &dyn Comm,
        b: Aabb,
        first: usize,
        count: usize,
        x: &[Vector3<f64>],
        w: &[f64],
        members: &[usize],
    ) -> Result<(), DecompositionError> {
        if count == 1 {
            self.boxes[first] = b;
            return Ok(());
        }
        let extent = b.hi - b.lo;
        let min_width = 2.0 * self.halo;
        // Longest axis that leaves both parts wide enough (ties: lowest axis).
        let axis = (0..3)
            .filter(|&k| extent[k] >= 2.0 * min_width)
            .fold(None, |best: Option<usize>, k| match best {
                Some(j) if extent[j] >= extent[k] => Some(j),
                _ => Some(k),
            })
            .ok_or(DecompositionError::TooManyRanks {
                ranks: comm.size(),
                extent: (self.domain.max - self.domain.min).into(),
                halo: self.halo,
            })?;
        let lower = count / 2;
        let share = lower as f64 / count as f64;
        let (mut a, mut z) = (b.lo[axis] + min_width, b.hi[axis] - min_width);
        let total = comm.sum_f64(&[members.iter().map(|&i| w[i]).sum()])[0];
        let cut = if total > 0.0 {
            // Weight left of `a`, then histogram refinement of [a, z].
            let left_of = |c: f64| {
                members
                    .iter()
                    .filter(move |&&i| x[i][axis] < c)
                    .map(|&i| w[i])
            };
            let mut below = comm.sum_f64(&[left_of(a).sum()])[0];
            let target = share * total;
            const BINS: usize = 128;
            for _ in 0..3 {
                let width = (z - a) / BINS as f64;
                let mut hist = vec![0.0; BINS];
                for &i in members {
                    let c = x[i][axis];
                    if c >= a && c < z {
                        let bin = (((c - a) / width) as usize).min(BINS - 1);
                        hist[bin] += w[i];
                    }
                }
                let hist = comm.sum_f64(&hist);
                let mut acc = below;
                let mut chosen = BINS - 1;
                for (k, h) in hist.iter().enumerate() {
                    if acc + h >= target {
                        chosen = k;
                        break;
                    }
                    acc += h;
                }
                below = acc;
                let new_a = a + chosen as f64 * width;
                z = if chosen + 1 == BINS {
                    z
                } else {
                    a + (chosen + 1) as f64 * width
                };
                a = new_a;
            }
            0.5 * (a + z)
        } else {
            // No weight: cut by volume.
            b.lo[axis] + share * extent[axis]
        };
        // Leave each side room for its ranks along this axis where the box has it (a cut at
        // 2h from a face would starve a side of several ranks), else the minimum 2h.
        let (room_lo, room_hi) = (min_width * lower as f64, min_width * (count - lower) as f64);
        let cut = if room_lo + room_hi <= extent[axis] {
            cut.clamp(b.lo[axis] + room_lo, b.hi[axis] - room_hi)
        } else {
            cut.clamp(b.lo[axis] + min_width, b.hi[axis] - min_width)
        };
        let (mut lo_box, mut hi_box) = (b, b);
        lo_box.hi[axis] = cut;
        hi_box.lo[axis] = cut;
        let (lo_members, hi_members): (Vec<usize>, Vec<usize>) =
            members.iter().partition(|&&i| x[i][axis] < cut);
        self.bisect(comm, lo_box, first, lower, x, w, &lo_members)?;
        self.bisect(
            comm,
            hi_box,
            first + lower,
            count - lower,
            x,
            w,
            &hi_members,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::comm::SerialComm;

    fn bounds(periodic: [bool; 3]) -> Bounds {
        Bounds {
            min: Vector3::new(0.0, -1.0, 0.0),
            max: Vector3::new(4.0, 1.0, 8.0),
            periodic,
        }
    }

    /// Every point of the domain has exactly one owner, including the upper faces.
    #[test]
    fn grid_boxes_tile_the_domain() {
        let s = Subdomains::grid(bounds([false; 3]), 0.1, [2, 1, 3]);
        let mut rng = crate::rng::Rng::new(3);
        for i in 0..5000 {
            let mut x = Vector3::new(
                rng.range(0.0, 4.0),
                rng.range(-1.0, 1.0),
                rng.range(0.0, 8.0),
            );
            if i % 10 == 0 {
                x.z = 8.0;
            }
            if i % 7 == 0 {
                x.x = 2.0;
            }
            let owners = (0..6).filter(|&r| s.contains(r, &x)).count();
            assert_eq!(owners, 1, "{x}");
        }
    }

    /// The chosen grid cuts across the longest axis first and respects the halo.
    #[test]
    fn chosen_grid_minimises_interfaces() {
        let b = bounds([false; 3]);
        assert_eq!(Subdomains::choose_grid(&b, 0.1, 2).unwrap(), [1, 1, 2]);
        assert_eq!(Subdomains::choose_grid(&b, 0.1, 4).unwrap(), [1, 1, 4]);
        assert_eq!(Subdomains::choose_grid(&b, 0.1, 8).unwrap(), [2, 1, 4]);
        // z can take at most 8 / (2·1.5) = 2 slabs of 3 m; x none.
        assert_eq!(Subdomains::choose_grid(&b, 1.5, 2).unwrap(), [1, 1, 2]);
        assert!(Subdomains::choose_grid(&b, 1.5, 3).is_err());
    }

    /// Neighbours are symmetric, and the periodic seam makes the end slabs neighbours.
    #[test]
    fn neighbours_are_symmetric_across_periodic_seams() {
        for periodic in [[false; 3], [false, false, true]] {
            let s = Subdomains::grid(bounds(periodic), 0.1, [1, 1, 4]);
            for r in 0..4 {
                for n in s.neighbours(r) {
                    assert!(s.neighbours(n).contains(&r));
                }
            }
            assert_eq!(s.neighbours(0).contains(&3), periodic[2]);
            assert_eq!(s.neighbours(1), vec![0, 2]);
        }
    }

    /// Bisection on one rank returns the domain; the split logic places a cut at the weighted
    /// median for two ranks' worth of recursion (checked through a two-box grid of weights).
    #[test]
    fn bisection_single_rank_is_the_domain() {
        let b = bounds([false; 3]);
        let x = vec![Vector3::new(1.0, 0.0, 1.0)];
        let s = Subdomains::bisection(&SerialComm, b, 0.1, &x, &[1.0]).unwrap();
        assert_eq!(s.boxes.len(), 1);
        assert_eq!(s.boxes[0].lo, b.min);
        assert_eq!(s.boxes[0].hi, b.max);
    }

    /// The histogram quantile search puts the cut where the weights split as asked.
    #[test]
    fn bisection_cut_splits_the_weight() {
        // A fake two-rank communicator: one process, size 2, whose collectives see only local
        // data (all particles are "here"); enough to exercise the cut search.
        struct Two;
        impl Comm for Two {
            fn rank(&self) -> usize {
                0
            }
            fn size(&self) -> usize {
                2
            }
            fn barrier(&self) {}
            fn all_gather(&self, local: &[u8]) -> Vec<Vec<u8>> {
                vec![local.to_vec()]
            }
            fn all_to_all(&self, s: &[Vec<u8>]) -> Vec<Vec<u8>> {
                s.to_vec()
            }
            fn neighbor_exchange(&self, _: &[(usize, Vec<u8>)], f: &[usize]) -> Vec<Vec<u8>> {
                vec![Vec::new(); f.len()]
            }
            fn broadcast(&self, _: &mut Vec<u8>, _: usize) {}
            fn abort(&self, code: i32) -> ! {
                std::process::exit(code)
            }
        }
        let b = bounds([false; 3]);
        let mut rng = crate::rng::Rng::new(9);
        // Particles packed in the bottom eighth of a tall box (a silo being filled).
        let x: Vec<_> = (0..20000)
            .map(|_| {
                Vector3::new(
                    rng.range(0.0, 4.0),
                    rng.range(-1.0, 1.0),
                    rng.range(0.0, 1.0),
                )
            })
            .collect();
        let w = vec![1.0; x.len()];
        let s = Subdomains::bisection(&Two, b, 0.05, &x, &w).unwrap();
        let below = x.iter().filter(|p| s.contains(0, p)).count();
        assert!(
            (below as f64 / x.len() as f64 - 0.5).abs() < 0.01,
            "{below}"
        );
        // The cut is along z (longest axis) inside the packed layer.
        assert!(
            s.boxes[0].hi.z < 1.0 && s.boxes[0].hi.z > 0.3,
            "{:?}",
            s.boxes[0]
        );
    }
}
