//! A wall's facets binned on a uniform grid in the wall's own frame, each facet in the cells its
//! triangle meets: the broad phase of the wall stage (the GPU uploads the same arrays,
//! [`super::wall::FacetGridParts`]).

use nalgebra::Vector3;

/// Whether triangle `t` meets the axis-aligned box of centre `c` and half-widths `h`, by the
/// separating-axis theorem: the box's three axes, the triangle's normal and the nine cross
/// products of a box axis with a triangle edge (Akenine-Möller's triangle–box test).
pub(super) fn triangle_meets_box(
    t: &[Vector3<f64>; 3],
    c: &Vector3<f64>,
    h: &Vector3<f64>,
) -> bool {
    let v = t.map(|p| p - c);
    let separated = |axis: &Vector3<f64>| {
        let p = v.map(|q| axis.dot(&q));
        let r = h.x * axis.x.abs() + h.y * axis.y.abs() + h.z * axis.z.abs();
        p[0].min(p[1]).min(p[2]) > r || p[0].max(p[1]).max(p[2]) < -r
    };
    let edges = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
    !(axes.iter().any(&separated)
        || separated(&edges[0].cross(&edges[1]))
        || axes
            .iter()
            .any(|a| edges.iter().any(|e| separated(&a.cross(e)))))
}

/// Most cells of a wall's facet grid: 2^21 (8 MiB of cell offsets on either backend).
const MAX_FACET_CELLS: usize = 1 << 21;

/// Facets binned on a uniform grid over the mesh, each in the cells its triangle meets.
#[derive(Clone, Debug)]
pub(super) struct FacetGrid {
    pub(super) min: Vector3<f64>,
    pub(super) size: f64,
    pub(super) dims: [usize; 3],
    pub(super) start: Vec<u32>,
    pub(super) items: Vec<u32>,
}

impl FacetGrid {
    /// The grid of `tris` with cells at least `cell` wide.
    pub(super) fn new(tris: &[[Vector3<f64>; 3]], cell: f64) -> Self {
        let mut lo = Vector3::repeat(f64::MAX);
        let mut hi = Vector3::repeat(f64::MIN);
        for t in tris {
            for v in t {
                lo = lo.inf(v);
                hi = hi.sup(v);
            }
        }
        if tris.is_empty() {
            lo = Vector3::zeros();
            hi = Vector3::zeros();
        }
        let extent = hi - lo;
        // Cubic cells at least `cell` wide (a particle's reach spans at most two per axis), as
        // small as MAX_FACET_CELLS cells over the mesh's box allow: sized by the box's volume,
        // not its longest side, so that a slender mesh (a reactor tube, a silo) gets cells of
        // the particles' size across its width rather than 1/64 of its height.
        let box_volume: f64 = (0..3).map(|k| extent[k].max(cell)).product();
        let size = cell
            .max((box_volume / MAX_FACET_CELLS as f64).cbrt())
            .max(1e-12);
        let dims =
            [0, 1, 2].map(|k| ((extent[k] / size).floor() as usize + 1).min(MAX_FACET_CELLS));
        let mut grid = FacetGrid {
            min: lo,
            size,
            dims,
            start: Vec::new(),
            items: Vec::new(),
        };
        let cells = dims[0] * dims[1] * dims[2];
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); cells];
        // A facet is listed in the cells of its bounding box that the triangle itself meets
        // (separating-axis test on cells widened by a hair, so that rounding never drops a cell
        // the triangle touches): a long slanted facet, like the generators of a cone, then sits
        // in the cells along its surface, not in the whole column its bounding box spans.
        let half = Vector3::repeat(0.5 * size * (1.0 + 1e-9));
        for (f, t) in tris.iter().enumerate() {
            let (a, b) = (t[0].inf(&t[1]).inf(&t[2]), t[0].sup(&t[1]).sup(&t[2]));
            let (ca, cb) = (grid.coords(&a), grid.coords(&b));
            for z in ca[2]..=cb[2] {
                for y in ca[1]..=cb[1] {
                    for x in ca[0]..=cb[0] {
                        let centre = lo
                            + Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * size;
                        if triangle_meets_box(t, &centre, &half) {
                            lists[(z * dims[1] + y) * dims[0] + x].push(f as u32);
                        }
                    }
                }
            }
        }
        grid.start.push(0);
        for l in lists {
            grid.items.extend(l);
            grid.start.push(grid.items.len() as u32);
        }
        grid
    }

    /// The cell of point `x`, clamped into the grid.
    fn coords(&self, x: &Vector3<f64>) -> [usize; 3] {
        [0, 1, 2].map(|k| {
            let c = ((x[k] - self.min[k]) / self.size).floor();
            if c.is_finite() {
                (c.max(0.0) as usize).min(self.dims[k] - 1)
            } else {
                0
            }
        })
    }

    /// Appends to `out` the facets listed in the cells within `reach` of `x` (a facet may
    /// appear more than once).
    pub(super) fn candidates(&self, x: &Vector3<f64>, reach: f64, out: &mut Vec<u32>) {
        let r = Vector3::repeat(reach);
        let (lo, hi) = (x - r, x + r);
        // Entirely outside the mesh's box: nothing to find.
        let top = self.min
            + Vector3::new(
                self.dims[0] as f64,
                self.dims[1] as f64,
                self.dims[2] as f64,
            ) * self.size;
        if (0..3).any(|k| hi[k] < self.min[k] || lo[k] > top[k]) {
            return;
        }
        let (ca, cb) = (self.coords(&lo), self.coords(&hi));
        for z in ca[2]..=cb[2] {
            for y in ca[1]..=cb[1] {
                for xx in ca[0]..=cb[0] {
                    let c = (z * self.dims[1] + y) * self.dims[0] + xx;
                    out.extend_from_slice(
                        &self.items[self.start[c] as usize..self.start[c + 1] as usize],
                    );
                }
            }
        }
    }
}
