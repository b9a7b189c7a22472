//! Grain sizes of the CPU backend's data-parallel loops.
//!
//! A rayon loop that splits hands part of its work to the pool's other threads: each split is a
//! `join`, which wakes a sleeping worker and waits for it (futex calls, tens of microseconds on
//! a loaded machine). A loop whose length is below twice its minimum length never splits and
//! runs on the calling thread without touching the pool at all (rayon's `LengthSplitter`), so
//! each loop carries `with_min_len` of the item count whose work outweighs one split. Without
//! it a 63-particle scene spent 87 % of its step in futex and `sched_yield` (strace, 2 cores):
//! 4600 steps/s.
//!
//! Results do not depend on these sizes: every loop computes its items independently and
//! collects them in index order (docs/design.md §4: a run is bitwise the same at any thread
//! count), so the split only decides who computes what.

/// Items of a per-particle loop of a few arithmetic operations each (kick, drift, guard,
/// energies, gathers): about 10–100 ns an item.
pub const CHEAP: usize = 2048;

/// Items of a per-particle loop that searches (neighbour cells, wall facets, its contacts):
/// about 0.3–3 µs an item.
pub const SEARCH: usize = 256;

/// Items of contact geometry: pairs (bounding spheres, GJK, overlap volume, contact law) and
/// particles against walls (facet search and clipping): from 50 ns for a pair beyond reach to
/// tens of µs for a face on a face, so that even a few are worth sharing.
pub const CONTACT: usize = 4;
