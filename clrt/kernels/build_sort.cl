// Least-significant-digit radix sort of (key, id) pairs: the triangles by
// Morton code.  Each pass sorts stably by one RADIX_BITS-bit digit.  Two
// drivers (clrt/device/build.py chooses by device type):
//
// CPU devices, three launches a pass:
//   radix_histogram  digit counts of each tile of SORT_TILE keys
//   scan_counts      exclusive prefix sum of those counts, digit-major, so that
//                    entry (digit, tile) is where the tile's keys of that
//                    digit start in the output
//   radix_scatter    every key to its place
// GPUs, one launch a pass after one for all of them (as Onesweep, Adinets &
// Merrill 2022): a GPU's host spends longer queueing a launch than a small
// sort's launch runs, so launches are what a small build waits for:
//   radix_digit_counts      every pass's digit counts over all keys, at once
//   radix_scatter_lookback  a pass: each tile learns where its keys of each
//                           digit go from the tiles before it, by decoupled
//                           look-back (build_scan.cl), and scatters them
// Both are stable, since work-item w of a tile holds the tile's keys
// w*SORT_ITEMS .. and counts before them go first; so both give the same
// order, and ties keep their input order: equal Morton codes stay by
// triangle id.
#ifndef CLRT_BUILD_SORT_CL
#define CLRT_BUILD_SORT_CL

#include "build_scan.cl"

#ifndef RADIX_BITS
#error "build with -DRADIX_BITS=<bits per pass>"
#endif
#define RADIX_BINS (1 << RADIX_BITS)
#ifndef SORT_PASSES
#error "build with -DSORT_PASSES=<passes over the key bits>"
#endif
#define SORT_ITEMS 8                               // keys per work-item
#define SORT_TILE (BUILD_GROUP * SORT_ITEMS)       // keys per work-group

// counts[digit * BUILD_GROUP + lid]: keys with that digit among work-item
// lid's SORT_ITEMS keys of this group's tile.  (Column lid belongs to
// work-item lid alone, so no atomics are needed.)
inline void count_tile_digits(const global uint* keys, uint n, uint shift, uint tile, local uint* counts)
{
    const uint lid = get_local_id(0);
    for (uint d = 0; d < RADIX_BINS; ++d)
        counts[d * BUILD_GROUP + lid] = 0u;
    const uint first = tile * SORT_TILE + lid * SORT_ITEMS;
    for (uint k = 0; k < SORT_ITEMS; ++k)
        if (first + k < n)
            ++counts[((keys[first + k] >> shift) & (RADIX_BINS - 1)) * BUILD_GROUP + lid];
    barrier(CLK_LOCAL_MEM_FENCE);
}

// tile_counts[digit * tiles + tile]: keys of the tile with that digit.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void radix_histogram(const global uint* keys, const uint n, const uint shift, global uint* tile_counts)
{
    local uint counts[RADIX_BINS * BUILD_GROUP];
    count_tile_digits(keys, n, shift, get_group_id(0), counts);
    for (uint d = get_local_id(0); d < RADIX_BINS; d += BUILD_GROUP) {
        uint sum = 0;
        for (uint w = 0; w < BUILD_GROUP; ++w)
            sum += counts[d * BUILD_GROUP + w];
        tile_counts[d * get_num_groups(0) + get_group_id(0)] = sum;
    }
}

// One work-group: exclusive prefix sum of the n tile counts, in place.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void scan_counts(global uint* counts, const uint n)
{
    local uint scratch[BUILD_GROUP];
    scan_in_one_group(counts, n, scratch);
}

// The counts of count_tile_digits turned into ranks: an exclusive prefix sum
// in their digit-major order, so that counts[d * BUILD_GROUP + w] is the
// rank in the tile of work-item w's first key of digit d, and digit_start[d]
// the rank of the tile's first key of digit d; returns the tile's keys.  Each
// work-item scans RADIX_BINS consecutive entries.
inline uint rank_tile_keys(local uint* counts, local uint* digit_start, local uint* scratch)
{
    const uint lid = get_local_id(0);
    uint sum = 0;
    for (uint k = 0; k < RADIX_BINS; ++k)
        sum += counts[lid * RADIX_BINS + k];
    uint total;
    uint prefix = group_exclusive_scan(sum, scratch, &total);
    for (uint k = 0; k < RADIX_BINS; ++k) {
        const uint value = counts[lid * RADIX_BINS + k];
        counts[lid * RADIX_BINS + k] = prefix;
        prefix += value;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint d = lid; d < RADIX_BINS; d += BUILD_GROUP)
        digit_start[d] = counts[d * BUILD_GROUP];
    barrier(CLK_LOCAL_MEM_FENCE);
    return total;
}

// Every key of the tile to tile_base[its digit] + its rank among the tile's
// keys of that digit.
inline void scatter_tile(const global uint* keys, const global uint* ids, uint n, uint shift, uint tile,
                         local uint* counts, local const uint* digit_start, local const uint* tile_base,
                         global uint* keys_out, global uint* ids_out)
{
    const uint lid = get_local_id(0);
    const uint first = tile * SORT_TILE + lid * SORT_ITEMS;
    for (uint k = 0; k < SORT_ITEMS; ++k) {
        if (first + k < n) {
            const uint key = keys[first + k];
            const uint d = (key >> shift) & (RADIX_BINS - 1);
            const uint to = tile_base[d] + (counts[d * BUILD_GROUP + lid]++ - digit_start[d]);
            keys_out[to] = key;
            ids_out[to] = ids[first + k];
        }
    }
}

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void radix_scatter(const global uint* keys, const global uint* ids, const uint n, const uint shift,
                   const global uint* tile_offsets, global uint* keys_out, global uint* ids_out)
{
    local uint counts[RADIX_BINS * BUILD_GROUP];
    local uint digit_start[RADIX_BINS], tile_base[RADIX_BINS];
    local uint scratch[BUILD_GROUP];
    const uint tile = get_group_id(0);
    count_tile_digits(keys, n, shift, tile, counts);
    rank_tile_keys(counts, digit_start, scratch);
    for (uint d = get_local_id(0); d < RADIX_BINS; d += BUILD_GROUP)
        tile_base[d] = tile_offsets[d * get_num_groups(0) + tile];
    barrier(CLK_LOCAL_MEM_FENCE);
    scatter_tile(keys, ids, n, shift, tile, counts, digit_start, tile_base, keys_out, ids_out);
}

// ---- GPUs: one launch a pass

// state[STATE_SORT_DIGITS + p * RADIX_BINS + d] += keys whose pass-p digit is
// d, for every pass at once (grid-stride over the keys; the state starts at
// zero, init_build_state).  Also zeroes the first pass's look-back words,
// status[0, status_words).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void radix_digit_counts(const global uint* keys, const uint n, global uint* state, global uint* status,
                        const uint status_words)
{
    local uint counts[SORT_PASSES * RADIX_BINS];
    const uint lid = get_local_id(0);
    for (uint k = lid; k < SORT_PASSES * RADIX_BINS; k += BUILD_GROUP)
        counts[k] = 0u;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint i = get_global_id(0); i < n; i += get_global_size(0)) {
        const uint key = keys[i];
        for (uint p = 0; p < SORT_PASSES; ++p)
            atomic_inc(&counts[p * RADIX_BINS + ((key >> (p * RADIX_BITS)) & (RADIX_BINS - 1))]);
    }
    for (uint k = get_global_id(0); k < status_words; k += get_global_size(0))
        status[k] = 0u;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint k = lid; k < SORT_PASSES * RADIX_BINS; k += BUILD_GROUP)
        if (counts[k])
            atomic_add(&state[STATE_SORT_DIGITS + k], counts[k]);
}

// Pass `pass` (digit shift pass * RADIX_BITS) in one launch of one work-group
// per tile.  Tiles are taken by ticket in the order the groups start, so a
// tile only waits for tiles already running.  The look-back words of this
// pass are the half pass % 2 of `status` (RADIX_BINS words a tile, digit-major:
// one look-back chain per digit); the other half, used by the pass before,
// is zeroed here for the pass after.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void radix_scatter_lookback(const global uint* keys, const global uint* ids, const uint n, const uint pass,
                            global uint* state, global uint* status, global uint* keys_out, global uint* ids_out)
{
    local uint counts[RADIX_BINS * BUILD_GROUP];
    local uint digit_start[RADIX_BINS], tile_base[RADIX_BINS];
    local uint scratch[BUILD_GROUP];
    local uint ticket;
    const uint lid = get_local_id(0), tiles = get_num_groups(0);
    global uint* mine = status + (pass % 2) * tiles * RADIX_BINS;
    global uint* next = status + (1 - pass % 2) * tiles * RADIX_BINS;
    if (lid == 0)
        ticket = atomic_inc(&state[STATE_SORT_TICKETS + pass]);
    for (uint k = get_global_id(0); k < tiles * RADIX_BINS; k += get_global_size(0))
        next[k] = 0u;
    barrier(CLK_LOCAL_MEM_FENCE);
    const uint tile = ticket, shift = pass * RADIX_BITS;
    count_tile_digits(keys, n, shift, tile, counts);
    const uint total = rank_tile_keys(counts, digit_start, scratch);
    if (lid < RADIX_BINS) {
        const uint d = lid;
        const uint here = (d + 1 < RADIX_BINS ? digit_start[d + 1] : total) - digit_start[d];
        uint base = tile_exclusive_prefix(mine + d * tiles, tile, here);
        for (uint e = 0; e < d; ++e)                  // the keys of lower digits go first
            base += state[STATE_SORT_DIGITS + pass * RADIX_BINS + e];
        tile_base[d] = base;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    scatter_tile(keys, ids, n, shift, tile, counts, digit_start, tile_base, keys_out, ids_out);
}

#endif
