// Exclusive prefix sum of u32 counts (the "count, exclusive prefix sum, fill" of seed paper
// Sec. 2.2, used for cells, pairs and per-particle pair references). Two kernels: each block
// scans PD_SCAN_BLOCK elements in shared memory and writes its total; the host scans the block
// totals with the same kernels (recursively) and `scan_add` adds them back. Integer sums: the
// result is exact and independent of the launch configuration.
#include "common.cuh"

#ifndef PD_SCAN_BLOCK
#define PD_SCAN_BLOCK 1024
#endif

// out[i] = Σ_{j<i} in[j] within each block of PD_SCAN_BLOCK elements; block_sums[b] = the
// block's total. Elements past n read as 0.
extern "C" __global__ void scan_blocks(int n, const unsigned int* in, unsigned int* out,
                                       unsigned int* block_sums) {
    __shared__ unsigned int buf[PD_SCAN_BLOCK];
    int t = threadIdx.x;
    int i = blockIdx.x * PD_SCAN_BLOCK + t;
    unsigned int v = i < n ? in[i] : 0u;
    buf[t] = v;
    __syncthreads();
    // Hillis–Steele inclusive scan.
    for (int offset = 1; offset < PD_SCAN_BLOCK; offset <<= 1) {
        unsigned int add = t >= offset ? buf[t - offset] : 0u;
        __syncthreads();
        buf[t] += add;
        __syncthreads();
    }
    if (i < n) {
        out[i] = buf[t] - v;
    }
    if (t == PD_SCAN_BLOCK - 1) {
        block_sums[blockIdx.x] = buf[t];
    }
}

// out[i] += scanned_block_sums[block of i].
extern "C" __global__ void scan_add(int n, unsigned int* out, const unsigned int* scanned_block_sums) {
    int i = blockIdx.x * PD_SCAN_BLOCK + threadIdx.x;
    if (i < n) {
        out[i] += scanned_block_sums[blockIdx.x];
    }
}
