//! Neighbour search: uniform bins, the 1D candidate pair list, and Verlet-list reuse.
//!
//! Particles are binned in cells at least one cutoff wide, sorted by cell, and every particle
//! scans the 27 surrounding cells for partners within `r_i + r_j + skin` (bounding spheres plus
//! the Verlet skin). The result is the seed paper's 1D `int2` pair list (Sec. 2.2, Fig. 3c),
//! built by count, exclusive prefix sum and fill, so that each pair is one independent work item.
//! A pair is stored with the lower global id first (docs/design.md §4). The list is reused until some
//! particle has moved more than half the skin since the build (hybrid paper Eq. 1–2); bounding
//! spheres are centred on the centroid, so rotation never invalidates it.
//!
//! For the deterministic reduction (docs/design.md §4) the build also records, for every particle,
//! its pairs sorted by partner global id.

mod report;
mod slot_list;

pub use report::{Builder, NeighborReport, Switch};
pub use slot_list::{SlotList, build_slot_list};

use nalgebra::Vector3;
use rayon::prelude::*;

/// How far a pair list reaches: it holds the pairs whose centres are closer than
/// `r_i + r_j + skin`, found in cells at least `cutoff` wide. The cutoff is the scene's
/// `2 r_max + skin` (`Scene::cutoff_with_skin`, `r_max` the largest bounding radius any
/// particle type can have), the one that also sizes the GPU's grid, the walls' facet grids and
/// the decomposition's halo; the particles present never need more.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reach {
    /// The Verlet skin (m).
    pub skin: f64,
    /// The least cell width (m), at least the largest two bounding radii plus the skin.
    pub cutoff: f64,
}

/// The domain's box and periodicity, as the neighbour search needs them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub min: Vector3<f64>,
    pub max: Vector3<f64>,
    pub periodic: [bool; 3],
}

impl Bounds {
    /// The minimum-image displacement from `a` to `b`.
    pub fn displacement(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> Vector3<f64> {
        let mut d = b - a;
        for k in 0..3 {
            if self.periodic[k] {
                let l = self.max[k] - self.min[k];
                d[k] -= l * (d[k] / l).round();
            }
        }
        d
    }

    /// Wraps a position into the box along periodic axes: a coordinate outside
    /// `[min, max)` becomes `min + (x − min) mod L` (Euclidean remainder), one inside is left
    /// as it is. So a second wrap changes nothing: `min + (x − min)` need not give `x` back
    /// in floating point, and a coordinate just below `min` can round to `max` itself, which
    /// is taken as `min` (`wrap_coordinate` of cuda/integrate.cu, the same arithmetic).
    pub fn wrap(&self, x: &mut Vector3<f64>) {
        for k in 0..3 {
            if self.periodic[k] {
                x[k] = wrap_coordinate(x[k], self.min[k], self.max[k]);
            }
        }
    }
}

/// One coordinate of [`Bounds::wrap`].
fn wrap_coordinate(x: f64, lo: f64, hi: f64) -> f64 {
    if x >= lo && x < hi {
        return x;
    }
    let y = lo + (x - lo).rem_euclid(hi - lo);
    if y >= hi { lo } else { y }
}

/// One entry of a particle's sorted pair list: the pair's index and whether the particle is the
/// pair's second member.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PairRef {
    pub pair: u32,
    pub is_b: bool,
}

/// The candidate pair list with its Verlet bookkeeping.
#[derive(Clone, Debug, Default)]
pub struct PairList {
    /// Pairs of local indices `(a, b)` with `id[a] < id[b]`.
    pub pairs: Vec<[u32; 2]>,
    /// Per particle, its pairs sorted by partner global id: `refs[offsets[i]..offsets[i+1]]`.
    pub offsets: Vec<u32>,
    pub refs: Vec<PairRef>,
    reference: Vec<Vector3<f64>>,
    skin: f64,
    /// Number of builds so far.
    pub builds: u64,
}

impl PairList {
    /// Whether some particle moved more than half the skin since the last build, or the
    /// particle set changed.
    pub fn needs_rebuild(&self, positions: &[Vector3<f64>], bounds: &Bounds) -> bool {
        positions.len() != self.reference.len() || self.moved_beyond_half_skin(positions, bounds)
    }

    /// Whether some of the first `positions.len()` particles moved more than half the skin
    /// since the last build (the owned particles of a decomposed run: ghosts are checked by
    /// their owners). True before the first build.
    pub fn moved_beyond_half_skin(&self, positions: &[Vector3<f64>], bounds: &Bounds) -> bool {
        if self.builds == 0 || positions.len() > self.reference.len() {
            return true;
        }
        let limit = 0.25 * self.skin * self.skin;
        positions
            .par_iter()
            .zip(self.reference.par_iter())
            .with_min_len(crate::par::CHEAP)
            .any(|(x, r)| bounds.displacement(r, x).norm_squared() > limit)
    }

    /// Builds the list for particles at `positions` with bounding radii `radii` and global ids
    /// `ids`, keeping pairs closer than `r_i + r_j + skin` ([`Reach`]).
    pub fn build(
        &mut self,
        positions: &[Vector3<f64>],
        radii: &[f64],
        ids: &[u64],
        bounds: &Bounds,
        reach: Reach,
    ) {
        self.build_in(
            positions,
            positions,
            radii,
            ids,
            positions.len(),
            bounds,
            bounds,
            reach,
        );
    }

    /// [`PairList::build`] for a rank's owned particles (the first `owned`) and its ghosts (the
    /// rest): particles are binned at `bins` on a grid over `region` (periodic only where the
    /// rank spans the domain), but the pair test uses the minimum-image displacement of the true
    /// `positions` in the whole `bounds`, as on one rank (the evaluation takes each pair's
    /// periodic image the same way, from the centroids of its step). Pairs of two ghosts are
    /// left out: their owners evaluate them.
    #[allow(clippy::too_many_arguments)]
    pub fn build_in(
        &mut self,
        positions: &[Vector3<f64>],
        bins: &[Vector3<f64>],
        radii: &[f64],
        ids: &[u64],
        owned: usize,
        bounds: &Bounds,
        region: &Bounds,
        reach: Reach,
    ) {
        let n = positions.len();
        self.skin = reach.skin;
        self.builds += 1;
        self.reference = positions.to_vec();
        self.pairs.clear();
        if n == 0 {
            self.offsets = vec![0];
            self.refs.clear();
            return;
        }
        let (pairs, _) = search(positions, bins, radii, ids, owned, bounds, region, reach);
        self.pairs = pairs;
        self.index_by_particle(n, ids);
    }

    /// Per-particle pair lists sorted by partner global id (the reduction order).
    fn index_by_particle(&mut self, n: usize, ids: &[u64]) {
        let mut count = vec![0u32; n + 1];
        for p in &self.pairs {
            count[p[0] as usize + 1] += 1;
            count[p[1] as usize + 1] += 1;
        }
        for i in 0..n {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        let mut refs = vec![
            PairRef {
                pair: 0,
                is_b: false
            };
            self.pairs.len() * 2
        ];
        for (k, p) in self.pairs.iter().enumerate() {
            for (member, is_b) in [(p[0], false), (p[1], true)] {
                let slot = &mut fill[member as usize];
                refs[*slot as usize] = PairRef {
                    pair: k as u32,
                    is_b,
                };
                *slot += 1;
            }
        }
        let pairs = &self.pairs;
        let partner = |r: &PairRef| ids[pairs[r.pair as usize][usize::from(!r.is_b)] as usize];
        let mut slices: Vec<&mut [PairRef]> = Vec::with_capacity(n);
        let mut rest = &mut refs[..];
        for i in 0..n {
            let (s, r) = rest.split_at_mut((count[i + 1] - count[i]) as usize);
            slices.push(s);
            rest = r;
        }
        slices
            .into_par_iter()
            .with_min_len(crate::par::SEARCH)
            .for_each(|s| s.sort_unstable_by_key(partner));
        self.offsets = count;
        self.refs = refs;
    }

    /// The pairs of particle `i`, sorted by partner global id.
    pub fn of(&self, i: usize) -> &[PairRef] {
        &self.refs[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

/// The candidate pairs of particles at `positions` (binned at `bins` on a grid over `region`,
/// the first `owned` owned and the rest ghosts, see [`PairList::build_in`]): each pair `(i, j)`
/// with `ids[i] < ids[j]` and a centre distance below `r_i + r_j + skin`, grouped by `i` in
/// ascending order, and how many each `i` has, binned in cells `reach.cutoff` wide or more.
/// Count, exclusive prefix sum and fill on rayon threads (seed Sec. 2.2).
#[allow(clippy::too_many_arguments)]
fn search(
    positions: &[Vector3<f64>],
    bins: &[Vector3<f64>],
    radii: &[f64],
    ids: &[u64],
    owned: usize,
    bounds: &Bounds,
    region: &Bounds,
    reach: Reach,
) -> (Vec<[u32; 2]>, Vec<u32>) {
    let n = positions.len();
    if n == 0 {
        return (Vec::new(), Vec::new());
    }
    let Reach { skin, cutoff } = reach;
    // Cells narrower than a pair's reach would miss pairs silently: a cutoff that does not
    // hold the particles present is a defect of the caller's.
    let r_max = radii.iter().cloned().fold(0.0, f64::max);
    assert!(
        2.0 * r_max + skin <= cutoff,
        "neighbour cutoff {cutoff} below the particles' 2 r_max + skin = {}",
        2.0 * r_max + skin
    );
    let grid = Grid::new(region, cutoff, 4 * n);
    // Bin: cell of each particle, then particles sorted by cell (counting sort).
    let cell: Vec<usize> = bins
        .par_iter()
        .with_min_len(crate::par::CHEAP)
        .map(|x| grid.cell_of(x))
        .collect();
    let mut start = vec![0u32; grid.cells() + 1];
    for &c in &cell {
        start[c + 1] += 1;
    }
    for c in 0..grid.cells() {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut sorted = vec![0u32; n];
    for (i, &c) in cell.iter().enumerate() {
        sorted[fill[c] as usize] = i as u32;
        fill[c] += 1;
    }
    // Candidates of particle i: partners j with a higher id (each pair once) in the 27
    // neighbouring cells, within the bounding-sphere reach plus skin.
    let partners = |i: usize, out: &mut dyn FnMut(usize)| {
        let xi = positions[i];
        for c in grid.neighbours(cell[i]) {
            for &j in &sorted[start[c] as usize..start[c + 1] as usize] {
                let j = j as usize;
                if ids[j] <= ids[i] || (i >= owned && j >= owned) {
                    continue;
                }
                let d = bounds.displacement(&xi, &positions[j]);
                let reach = radii[i] + radii[j] + skin;
                if d.norm_squared() < reach * reach {
                    out(j);
                }
            }
        }
    };
    // Count, exclusive prefix sum, fill (seed Sec. 2.2).
    let counts: Vec<u32> = (0..n)
        .into_par_iter()
        .with_min_len(crate::par::SEARCH)
        .map(|i| {
            let mut k = 0;
            partners(i, &mut |_| k += 1);
            k
        })
        .collect();
    let mut offset = vec![0usize; n + 1];
    for i in 0..n {
        offset[i + 1] = offset[i] + counts[i] as usize;
    }
    let total = offset[n];
    let mut pairs = vec![[0u32; 2]; total];
    let mut chunks: Vec<&mut [[u32; 2]]> = Vec::with_capacity(n);
    {
        let mut rest = &mut pairs[..];
        for &c in &counts {
            let (p, r) = rest.split_at_mut(c as usize);
            chunks.push(p);
            rest = r;
        }
    }
    chunks
        .into_par_iter()
        .enumerate()
        .with_min_len(crate::par::SEARCH)
        .for_each(|(i, p)| {
            let mut k = 0;
            partners(i, &mut |j| {
                p[k] = [i as u32, j as u32];
                k += 1;
            });
        });
    (pairs, counts)
}

/// Cell widths and counts of the neighbour grid for `bounds` and cells at least `cutoff` wide
/// (at most about `max(max_cells, 4096)` cells): the layout the GPU backend bins with too.
pub fn grid_layout(bounds: &Bounds, cutoff: f64, max_cells: usize) -> (Vector3<f64>, [usize; 3]) {
    let g = Grid::new(bounds, cutoff, max_cells);
    (g.size, g.dims)
}

/// A uniform grid of cells at least one cutoff wide over the domain box.
struct Grid {
    min: Vector3<f64>,
    size: Vector3<f64>,
    dims: [usize; 3],
    periodic: [bool; 3],
}

impl Grid {
    /// Cells at least `cutoff` wide, enlarged when needed so that there are at most about
    /// `max(max_cells, 4096)` of them: the counting sort walks every cell, so a big domain with
    /// few particles must not get millions of empty cells.
    fn new(bounds: &Bounds, cutoff: f64, max_cells: usize) -> Self {
        let extent = bounds.max - bounds.min;
        let limit = max_cells.max(4096) as f64;
        let mut width = cutoff.max(f64::MIN_POSITIVE);
        let count = |w: f64| {
            (0..3)
                .map(|k| (extent[k] / w).floor().max(1.0))
                .product::<f64>()
        };
        if count(width) > limit {
            width *= (count(width) / limit).cbrt();
            while count(width) > limit {
                width *= 1.01;
            }
        }
        let mut dims = [1usize; 3];
        let mut size = Vector3::zeros();
        for k in 0..3 {
            let d = ((extent[k] / width).floor() as usize).max(1);
            // Periodic axes need at least 3 cells for the 27-cell stencil to be distinct.
            dims[k] = if bounds.periodic[k] && d < 3 { 1 } else { d };
            size[k] = extent[k] / dims[k] as f64;
        }
        Grid {
            min: bounds.min,
            size,
            dims,
            periodic: bounds.periodic,
        }
    }

    fn cells(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    fn coord(&self, x: &Vector3<f64>, k: usize) -> usize {
        let c = ((x[k] - self.min[k]) / self.size[k]).floor();
        // Particles outside a non-periodic box are binned in the edge cells (still found).
        if c.is_finite() {
            (c.max(0.0) as usize).min(self.dims[k] - 1)
        } else {
            0
        }
    }

    fn cell_of(&self, x: &Vector3<f64>) -> usize {
        let (a, b, c) = (self.coord(x, 0), self.coord(x, 1), self.coord(x, 2));
        (c * self.dims[1] + b) * self.dims[0] + a
    }

    /// The distinct cells of the 3×3×3 stencil around `cell` (wrapping on periodic axes).
    fn neighbours(&self, cell: usize) -> impl Iterator<Item = usize> + '_ {
        let a = cell % self.dims[0];
        let b = (cell / self.dims[0]) % self.dims[1];
        let c = cell / (self.dims[0] * self.dims[1]);
        let axis = move |k: usize, v: usize| -> [Option<usize>; 3] {
            let d = self.dims[k];
            if d == 1 {
                return [Some(0), None, None];
            }
            if d == 2 && !self.periodic[k] {
                return [Some(0), Some(1), None];
            }
            let lo = if v > 0 {
                Some(v - 1)
            } else if self.periodic[k] {
                Some(d - 1)
            } else {
                None
            };
            let hi = if v + 1 < d {
                Some(v + 1)
            } else if self.periodic[k] {
                Some(0)
            } else {
                None
            };
            [lo, Some(v), hi]
        };
        let (xs, ys, zs) = (axis(0, a), axis(1, b), axis(2, c));
        zs.into_iter().flatten().flat_map(move |z| {
            ys.into_iter().flatten().flat_map(move |y| {
                xs.into_iter()
                    .flatten()
                    .map(move |x| (z * self.dims[1] + y) * self.dims[0] + x)
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// The binned list equals the brute-force all-pairs list, with and without periodic axes.
    /// A wrapped coordinate lies in [min, max) and wrapping it again leaves it as it is, for
    /// boxes not at the origin and for coordinates a rounding error below `min` (where
    /// `min + (x − min) mod L` rounds to `max`), beyond a period, and already inside; and a
    /// coordinate inside is never moved.
    #[test]
    fn wrapping_twice_is_wrapping_once() {
        let mut rng = crate::rng::Rng::new(8);
        let mut at_max = 0;
        for case in 0..20_000 {
            let lo = rng.range(-3.0, 3.0);
            let hi = lo + rng.range(0.01, 5.0);
            let l = hi - lo;
            let x = match case % 4 {
                0 => lo - rng.uniform() * 1e-15 * l.max(lo.abs()),
                1 => rng.range(lo - 3.0 * l, hi + 3.0 * l),
                2 => hi + rng.uniform() * 1e-15 * l.max(hi.abs()),
                _ => rng.range(lo, hi),
            };
            let once = wrap_coordinate(x, lo, hi);
            assert!(once >= lo && once < hi, "{x} in [{lo}, {hi}) gave {once}");
            assert_eq!(wrap_coordinate(once, lo, hi).to_bits(), once.to_bits());
            if x >= lo && x < hi {
                assert_eq!(once.to_bits(), x.to_bits());
            }
            let plain = lo + (x - lo).rem_euclid(l);
            at_max += usize::from(plain >= hi);
        }
        assert!(at_max > 100, "the rounding to max was met {at_max} times");
    }

    #[test]
    fn pair_list_matches_brute_force() {
        for periodic in [[false; 3], [true, false, true]] {
            let bounds = Bounds {
                min: Vector3::new(-1.0, -2.0, 0.0),
                max: Vector3::new(3.0, 1.0, 2.5),
                periodic,
            };
            let mut rng = Rng::new(4);
            let n = 600;
            let pos: Vec<_> = (0..n)
                .map(|_| {
                    Vector3::new(
                        rng.range(-1.0, 3.0),
                        rng.range(-2.2, 1.2),
                        rng.range(0.0, 2.5),
                    )
                })
                .collect();
            let radii: Vec<_> = (0..n).map(|_| rng.range(0.05, 0.15)).collect();
            let ids: Vec<u64> = (0..n as u64).map(|i| (i * 7919) % 1009).collect();
            let mut list = PairList::default();
            // Cells for the largest radius the draw allows (0.15), as a scene's cutoff is.
            let reach = Reach {
                skin: 0.05,
                cutoff: 2.0 * 0.15 + 0.05,
            };
            list.build(&pos, &radii, &ids, &bounds, reach);
            let mut got: Vec<(u64, u64)> = list
                .pairs
                .iter()
                .map(|p| (ids[p[0] as usize], ids[p[1] as usize]))
                .collect();
            got.sort();
            let mut want = Vec::new();
            for i in 0..n {
                for j in 0..n {
                    if ids[i] < ids[j]
                        && bounds.displacement(&pos[i], &pos[j]).norm() < radii[i] + radii[j] + 0.05
                    {
                        want.push((ids[i], ids[j]));
                    }
                }
            }
            want.sort();
            assert_eq!(got, want, "periodic {periodic:?}");
            // Per-particle lists are sorted by partner id and cover every pair twice.
            assert_eq!(list.refs.len(), 2 * list.pairs.len());
            for i in 0..n {
                let partners: Vec<u64> = list
                    .of(i)
                    .iter()
                    .map(|r| ids[list.pairs[r.pair as usize][usize::from(!r.is_b)] as usize])
                    .collect();
                assert!(partners.windows(2).all(|w| w[0] < w[1]));
            }
        }
    }
}
