//! The pair list built on the host for the GPU backend's particle slots: the host half of the
//! hybrid CPU–GPU scheme (Skorych & Dosta, docs/design.md §10; Sec. 3.1, operations A1,
//! B1, B5 and B12 of its Fig. 1). The host takes the device's positions in the device's slot
//! order, sorts the particles by cell as the device build does (the GPU reorders its arrays by
//! this order when it takes the list, for locality), and lists the candidate pairs in the new
//! numbering with rayon, in the layout the device build makes (`cuda/neighbor.cu`): pairs
//! `(a, b)` with `id[a] < id[b]`, grouped by `a`, and the offsets of each group, which index
//! the contact history by its lower-id member.
//!
//! Which pairs are listed, and in what order, never changes a trajectory: every listed pair
//! is tested for contact exactly, the reduction sums each particle's pairs in the order of
//! partner global id, and the history is keyed by global ids (docs/design.md §4, §7). A list
//! only has to hold every pair that can touch while it is in use.

use super::{Bounds, Grid, Reach, search};
use nalgebra::Vector3;
use rayon::prelude::*;
use std::time::Instant;

/// A pair list for the device's slots, built on the host (see the module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SlotList {
    /// `order[k]`: the slot, before the list is taken, of the particle that goes to slot `k`
    /// (particles sorted by cell, then by global id).
    pub order: Vec<u32>,
    /// Pairs `(a, b)` of the new slots with `id[a] < id[b]`, grouped by `a` in ascending order.
    pub pairs: Vec<[i32; 2]>,
    /// `offset[a]..offset[a + 1]`: the pairs whose first member is slot `a` (n + 1 values).
    pub offset: Vec<u32>,
    /// The skin the list was built with (m): it holds every pair whose bounding spheres come
    /// within this distance at the positions it was built from.
    pub skin: f64,
    /// Wall-clock seconds the build took (the seed's τ_CPU).
    pub seconds: f64,
}

/// Builds the [`SlotList`] of particles at `positions` (three values per slot, the device's
/// slot order) with bounding radii `radii` and global ids `ids`: the pairs closer than
/// `r_i + r_j + skin` (seed Eq. 1, `L_v` = `skin`; [`Reach`]), in the minimum image of
/// `bounds`.
pub fn build_slot_list(
    positions: &[f64],
    radii: &[f64],
    ids: &[u64],
    bounds: &Bounds,
    reach: Reach,
) -> SlotList {
    let skin = reach.skin;
    let t0 = Instant::now();
    let n = radii.len();
    assert_eq!(positions.len(), 3 * n, "three coordinates per slot");
    assert_eq!(ids.len(), n, "one id per slot");
    if n == 0 {
        return SlotList {
            offset: vec![0],
            skin,
            seconds: t0.elapsed().as_secs_f64(),
            ..SlotList::default()
        };
    }
    let x: Vec<Vector3<f64>> = positions
        .par_chunks_exact(3)
        .with_min_len(crate::par::CHEAP)
        .map(|c| Vector3::new(c[0], c[1], c[2]))
        .collect();
    // Slots sorted by cell, then global id (the device build's order, cuda/neighbor.cu
    // `sort_cells`): neighbours sit close in memory when the device gathers its arrays.
    let grid = Grid::new(bounds, reach.cutoff, 4 * n);
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.par_sort_unstable_by_key(|&i| (grid.cell_of(&x[i as usize]), ids[i as usize]));
    let gather = crate::par::CHEAP;
    let xs: Vec<Vector3<f64>> = order
        .par_iter()
        .with_min_len(gather)
        .map(|&i| x[i as usize])
        .collect();
    let rs: Vec<f64> = order
        .par_iter()
        .with_min_len(gather)
        .map(|&i| radii[i as usize])
        .collect();
    let is: Vec<u64> = order
        .par_iter()
        .with_min_len(gather)
        .map(|&i| ids[i as usize])
        .collect();
    let (pairs, counts) = search(&xs, &xs, &rs, &is, n, bounds, bounds, reach);
    let mut offset = Vec::with_capacity(n + 1);
    offset.push(0u32);
    let mut total = 0u32;
    for c in counts {
        total += c;
        offset.push(total);
    }
    let pairs = pairs
        .into_par_iter()
        .with_min_len(crate::par::CHEAP)
        .map(|[a, b]| [a as i32, b as i32])
        .collect();
    SlotList {
        order,
        pairs,
        offset,
        skin,
        seconds: t0.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neighbor::PairList;
    use crate::rng::Rng;

    /// The slot list holds the same pairs (by global id) as the CPU's list, in the layout the
    /// device expects: `order` a permutation sorted by cell, each pair's lower id first, pairs
    /// grouped by first member with consistent offsets.
    #[test]
    fn slot_list_matches_the_cpu_pair_list_in_the_device_layout() {
        for periodic in [[false; 3], [true, true, false]] {
            let bounds = Bounds {
                min: Vector3::new(-1.0, -1.0, 0.0),
                max: Vector3::new(1.0, 1.5, 2.0),
                periodic,
            };
            let mut rng = Rng::new(11);
            let n = 800;
            let x: Vec<Vector3<f64>> = (0..n)
                .map(|_| {
                    Vector3::new(
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.5),
                        rng.range(0.0, 2.0),
                    )
                })
                .collect();
            let radii: Vec<f64> = (0..n).map(|_| rng.range(0.03, 0.09)).collect();
            let ids: Vec<u64> = (0..n as u64).map(|i| (i * 104_729) % 7919).collect();
            let flat: Vec<f64> = x.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
            let reach = Reach {
                skin: 0.04,
                cutoff: 2.0 * 0.09 + 0.04,
            };
            let list = build_slot_list(&flat, &radii, &ids, &bounds, reach);
            let mut seen = vec![false; n];
            for &o in &list.order {
                assert!(
                    !std::mem::replace(&mut seen[o as usize], true),
                    "a permutation"
                );
            }
            let id_of = |slot: i32| ids[list.order[slot as usize] as usize];
            assert_eq!(list.offset.len(), n + 1);
            assert_eq!(*list.offset.last().unwrap() as usize, list.pairs.len());
            for a in 0..n {
                for k in list.offset[a]..list.offset[a + 1] {
                    let [p, q] = list.pairs[k as usize];
                    assert_eq!(p as usize, a, "grouped by first member");
                    assert!(id_of(p) < id_of(q), "lower id first");
                }
            }
            let mut got: Vec<(u64, u64)> = list
                .pairs
                .iter()
                .map(|&[a, b]| (id_of(a), id_of(b)))
                .collect();
            got.sort_unstable();
            let mut cpu = PairList::default();
            cpu.build(&x, &radii, &ids, &bounds, reach);
            let mut want: Vec<(u64, u64)> = cpu
                .pairs
                .iter()
                .map(|p| (ids[p[0] as usize], ids[p[1] as usize]))
                .collect();
            want.sort_unstable();
            assert!(!want.is_empty());
            assert_eq!(got, want, "periodic {periodic:?}");
        }
    }
}
