// Stage 2, neighbours: the GPU twin of src/neighbor/mod.rs. Particles are binned in cells at
// least one cutoff wide, sorted by cell (and by global id within a cell, so the order is
// deterministic although the scatter uses atomics), and the particle arrays are reordered in
// that order for locality. Each particle then scans the 27 surrounding cells for partners with a
// higher global id within r_i + r_j + skin, and the 1D int2 pair list is built by count,
// exclusive prefix sum (scan.cu) and fill (seed paper Sec. 2.2, Fig. 3c). Pairs of one particle
// are contiguous, so the pair offsets also index the contact history by its lower-id member.
// For the deterministic reduction (docs/design.md §4), every particle gets its pair references
// sorted by partner global id.
#include "common.cuh"
#include "state.cuh"

using namespace pd;

// cell[i] = its cell; cell_count[cell] += 1.
extern "C" __global__ void bin_particles(int n, const double* position, GridParams grid, unsigned int* cell,
                                         unsigned int* cell_count) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    unsigned int c = (unsigned int)cell_of(grid, load3(position, i));
    cell[i] = c;
    atomicAdd(&cell_count[c], 1u);
}

// order[cell_start[c] + k] = some particle of cell c (k-th to arrive).
extern "C" __global__ void scatter_by_cell(int n, const unsigned int* cell, const unsigned int* cell_start,
                                           unsigned int* cell_fill, unsigned int* order) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    unsigned int c = cell[i];
    unsigned int slot = cell_start[c] + atomicAdd(&cell_fill[c], 1u);
    order[slot] = (unsigned int)i;
}

// Sorts each cell's particles by global id (insertion sort: cells hold a handful), which makes
// the order independent of the atomics' arrival order.
extern "C" __global__ void sort_cells(int n_cells, const unsigned int* cell_start, unsigned int* order,
                                      const pd_u64* id) {
    int c = blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) {
        return;
    }
    unsigned int s = cell_start[c], e = cell_start[c + 1];
    for (unsigned int k = s + 1; k < e; ++k) {
        unsigned int v = order[k];
        pd_u64 key = id[v];
        unsigned int j = k;
        while (j > s && id[order[j - 1]] > key) {
            order[j] = order[j - 1];
            --j;
        }
        order[j] = v;
    }
}

// dst[k·w .. k·w + w] = src[order[k]·w ..] for k < n: reorders one particle array of `width`
// doubles per particle.
extern "C" __global__ void gather_f64(int n, int width, const double* src, double* dst, const unsigned int* order) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= n) {
        return;
    }
    unsigned int o = order[k];
    for (int c = 0; c < width; ++c) {
        dst[(size_t)k * width + c] = src[(size_t)o * width + c];
    }
}

extern "C" __global__ void gather_u64(int n, const pd_u64* src, pd_u64* dst, const unsigned int* order) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k < n) {
        dst[k] = src[order[k]];
    }
}

// As gather_f64, for arrays of `width` unsigned ints per particle.
extern "C" __global__ void gather_u32(int n, int width, const unsigned int* src, unsigned int* dst,
                                      const unsigned int* order) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= n) {
        return;
    }
    unsigned int o = order[k];
    for (int c = 0; c < width; ++c) {
        dst[(size_t)k * width + c] = src[(size_t)o * width + c];
    }
}

// Visits the candidate partners of particle i (after reordering, cell c holds the particles
// cell_start[c] .. cell_start[c+1]): partners j with a higher global id, in the 27 cells around
// i's, within the bounding-sphere reach plus skin. Calls visit(j, shift) with the periodic image
// shift to add to x_j.
//
// In a decomposed run (PD_GHOSTS) `ghost[i]` marks the neighbours' particles held as ghosts;
// pairs of two ghosts are skipped (their owners evaluate them), and `part` selects the pairs of
// two owned particles (1), which need nothing from the halo, or those with a ghost (2), which
// wait for it; 0 takes both. Otherwise `ghost` and `part` are not read.
template <class Visit>
PD_DEVICE void for_each_partner(int i, const double* position, const double* radius, const pd_u64* id,
                                const unsigned int* ghost, int part, const unsigned int* cell_start,
                                const GridParams& grid, double skin, Visit visit) {
    V3<double> xi = load3(position, i);
    double ri = radius[i];
    pd_u64 idi = id[i];
#if PD_GHOSTS
    bool ghost_i = ghost[i] != 0u;
#else
    (void)ghost;
    (void)part;
#endif
    int cell = cell_of(grid, xi);
    int a = cell % grid.dims[0];
    int b = (cell / grid.dims[0]) % grid.dims[1];
    int c = cell / (grid.dims[0] * grid.dims[1]);
    int xs[3], ys[3], zs[3];
    int nx = stencil_axis(grid, 0, a, xs);
    int ny = stencil_axis(grid, 1, b, ys);
    int nz = stencil_axis(grid, 2, c, zs);
    for (int kz = 0; kz < nz; ++kz) {
        for (int ky = 0; ky < ny; ++ky) {
            for (int kx = 0; kx < nx; ++kx) {
                int cc = (zs[kz] * grid.dims[1] + ys[ky]) * grid.dims[0] + xs[kx];
                for (unsigned int j = cell_start[cc]; j < cell_start[cc + 1]; ++j) {
                    if (id[j] <= idi) {
                        continue;
                    }
#if PD_GHOSTS
                    bool ghost_j = ghost[j] != 0u;
                    if ((ghost_i && ghost_j) || (part == 1 && (ghost_i || ghost_j)) ||
                        (part == 2 && !ghost_i && !ghost_j)) {
                        continue;
                    }
#endif
                    V3<double> xj = load3(position, (int)j);
                    V3<double> d = displacement(grid, xi, xj);
                    double reach = ri + radius[j] + skin;
                    if (norm2(d) < reach * reach) {
                        visit((int)j, d - (xj - xi));
                    }
                }
            }
        }
    }
}

struct CountVisit {
    unsigned int count;
    PD_DEVICE void operator()(int, V3<double>) { ++count; }
};

extern "C" __global__ void count_pairs(PairSearchParams args, unsigned int* counts) {
    const int n = args.n;
    const double* position = args.position;
    const double* radius = args.radius;
    const pd_u64* id = args.id;
    const unsigned int* ghost = args.ghost;
    const int part = args.part;
    const unsigned int* cell_start = args.cell_start;
    const GridParams& grid = args.grid;
    const double skin = args.skin;
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    CountVisit v;
    v.count = 0;
    for_each_partner(i, position, radius, id, ghost, part, cell_start, grid, skin,
                     [&](int j, V3<double> s) { v(j, s); });
    counts[i] = v.count;
}

// Pairs (i, j) at pair_offset[i] .. (no periodic shift is stored: the pair kernels take each
// pair's image from the step's centroids).
extern "C" __global__ void fill_pairs(PairSearchParams args, const unsigned int* pair_offset, int2* pairs) {
    const int n = args.n;
    const double* position = args.position;
    const double* radius = args.radius;
    const pd_u64* id = args.id;
    const unsigned int* ghost = args.ghost;
    const int part = args.part;
    const unsigned int* cell_start = args.cell_start;
    const GridParams& grid = args.grid;
    const double skin = args.skin;
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    unsigned int k = pair_offset[i];
    for_each_partner(i, position, radius, id, ghost, part, cell_start, grid, skin, [&](int j, V3<double>) {
        pairs[k] = make_int2(i, j);
        ++k;
    });
}

// ref_count[i] = number of pairs particle i is a member of.
extern "C" __global__ void count_refs(int n_pairs, const int2* pairs, unsigned int* ref_count) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= n_pairs) {
        return;
    }
    atomicAdd(&ref_count[pairs[k].x], 1u);
    atomicAdd(&ref_count[pairs[k].y], 1u);
}

// refs[ref_offset[i] + …] = 2·pair + (1 if i is the pair's second member).
extern "C" __global__ void fill_refs(int n_pairs, const int2* pairs, const unsigned int* ref_offset,
                                     unsigned int* ref_fill, unsigned int* refs) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= n_pairs) {
        return;
    }
    int a = pairs[k].x, b = pairs[k].y;
    refs[ref_offset[a] + atomicAdd(&ref_fill[a], 1u)] = 2u * (unsigned int)k;
    refs[ref_offset[b] + atomicAdd(&ref_fill[b], 1u)] = 2u * (unsigned int)k + 1u;
}

// Sorts each particle's references by partner global id: the reduction order (docs/design.md §4).
extern "C" __global__ void sort_refs(int n, const unsigned int* ref_offset, unsigned int* refs, const int2* pairs,
                                     const pd_u64* id) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    unsigned int s = ref_offset[i], e = ref_offset[i + 1];
    for (unsigned int k = s + 1; k < e; ++k) {
        unsigned int r = refs[k];
        int2 p = pairs[r >> 1];
        pd_u64 key = id[(r & 1u) ? p.x : p.y];
        unsigned int j = k;
        while (j > s) {
            unsigned int q = refs[j - 1];
            int2 pq = pairs[q >> 1];
            if (id[(q & 1u) ? pq.x : pq.y] <= key) {
                break;
            }
            refs[j] = q;
            --j;
        }
        refs[j] = r;
    }
}

// Before a rebuild: the partner global id of every pair of the current list, so the history
// can be found again after the particles are reordered.
extern "C" __global__ void history_partners(int n_pairs, const int2* pairs, const pd_u64* id, pd_u64* partner) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k < n_pairs) {
        partner[k] = id[pairs[k].y];
    }
}

// After a rebuild: the contact history (PD_HISTORY_WIDTH doubles: the tangential spring, the
// approach speed, the twist) of each new pair (a, b) from the old list, where the
// pairs of old particle order[a] are old_offset[order[a]] .. old_offset[order[a] + 1] with
// partners old_partner[…] (global ids). A pair not found starts with no spring, as on the CPU
// (ContactHistory keeps only contacts that were live).
extern "C" __global__ void remap_history(int n_pairs, const int2* pairs, const pd_u64* id, const unsigned int* order,
                                         const unsigned int* old_offset, const pd_u64* old_partner,
                                         const double* old_spring, double* spring) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= n_pairs) {
        return;
    }
    int2 p = pairs[k];
    unsigned int o = order[p.x];
    pd_u64 partner = id[p.y];
    double s[PD_HISTORY_WIDTH];
    for (int c = 0; c < PD_HISTORY_WIDTH; ++c) s[c] = 0.0;
    for (unsigned int m = old_offset[o]; m < old_offset[o + 1]; ++m) {
        if (old_partner[m] == partner) {
            for (int c = 0; c < PD_HISTORY_WIDTH; ++c) s[c] = old_spring[PD_HISTORY_WIDTH * (size_t)m + c];
            break;
        }
    }
    for (int c = 0; c < PD_HISTORY_WIDTH; ++c) spring[PD_HISTORY_WIDTH * (size_t)k + c] = s[c];
}

// After a decomposed run's rebuild on the device (src/backend/cuda/exchange.rs): the contact
// history of each new pair (a, b), a the lower-id member, from the union the host round trip
// would hold. First the rank's own list before the rebuild: the particle at slot a before the
// build was at upload index order[a], and at old_slot[order[a]] before the exchange
// (PD_NO_SLOT: it was not on this rank); its references there (old_ref_offset, old_refs, sorted
// by partner id) name its old pairs, and a pair it was the first member of, with the same
// partner id and in contact (old_contact live), gives its spring. Otherwise the entries that
// migrating particles brought along, sorted by (recv_a, recv_b), are searched. A pair found in
// neither starts with no spring, as on the CPU.
extern "C" __global__ void remap_history_exchanged(int n_pairs, const int2* pairs, const pd_u64* id,
                                                   const unsigned int* order, const unsigned int* old_slot,
                                                   const unsigned int* old_ref_offset, const unsigned int* old_refs,
                                                   const int2* old_pairs, const pd_u64* old_id,
                                                   const unsigned int* old_contact, const double* old_spring,
                                                   int n_recv, const pd_u64* recv_a, const pd_u64* recv_b,
                                                   const double* recv_spring, double* spring) {
    int k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= n_pairs) {
        return;
    }
    int2 p = pairs[k];
    pd_u64 a = id[p.x];
    pd_u64 b = id[p.y];
    const double* from = nullptr;
    unsigned int s = old_slot[order[p.x]];
    if (s != PD_NO_SLOT) {
        for (unsigned int m = old_ref_offset[s]; m < old_ref_offset[s + 1]; ++m) {
            unsigned int r = old_refs[m];
            // Slot s is the pair's first member when the reference's low bit is clear.
            if ((r & 1u) == 0u && old_id[old_pairs[r >> 1].y] == b) {
                if (old_contact[r >> 1] == PD_CONTACT_LIVE) {
                    from = old_spring + PD_HISTORY_WIDTH * (size_t)(r >> 1);
                }
                break;
            }
        }
    }
    if (from == nullptr && n_recv > 0) {
        int lo = 0, hi = n_recv;
        while (lo < hi) {
            int mid = lo + (hi - lo) / 2;
            if (recv_a[mid] < a || (recv_a[mid] == a && recv_b[mid] < b)) {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        if (lo < n_recv && recv_a[lo] == a && recv_b[lo] == b) {
            from = recv_spring + PD_HISTORY_WIDTH * (size_t)lo;
        }
    }
    for (int c = 0; c < PD_HISTORY_WIDTH; ++c) {
        spring[PD_HISTORY_WIDTH * (size_t)k + c] = from != nullptr ? from[c] : 0.0;
    }
}

// The hybrid list's consistency check (hybrid paper Eq. 2, operation B10 of its Fig. 1): `flag`
// (zeroed by the host) is set when some of the n particles moved more than `half_skin` from
// `reference`, the positions a host-built list was built from (minimum image, as kick_drift).
extern "C" __global__ void moved_beyond(int n, const double* position, const double* reference, GridParams grid,
                                        double half_skin, unsigned int* flag) {
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) {
        return;
    }
    V3<double> dx = displacement(grid, load3(reference, i), load3(position, i));
    if (norm2(dx) > half_skin * half_skin) {
        *flag = 1u;
    }
}
