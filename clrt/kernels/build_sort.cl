// Least-significant-digit radix sort of (key, id) pairs: the triangles by
// Morton code.  Each pass sorts stably by one RADIX_BITS-bit digit, in three
// launches:
//   radix_histogram  digit counts of each tile of SORT_TILE keys
//   scan_counts      exclusive prefix sum of those counts, digit-major, so that
//                    entry (digit, tile) is where the tile's keys of that
//                    digit start in the output
//   radix_scatter    every key to its place; stable, since work-item w of a
//                    tile holds the tile's keys w*SORT_ITEMS .. and counts
//                    before them go first.
// Ties keep their input order, so equal Morton codes stay by triangle id.
#ifndef CLRT_BUILD_SORT_CL
#define CLRT_BUILD_SORT_CL

#include "build_scan.cl"

#ifndef RADIX_BITS
#error "build with -DRADIX_BITS=<bits per pass>"
#endif
#define RADIX_BINS (1 << RADIX_BITS)
#define SORT_ITEMS 8                               // keys per work-item
#define SORT_TILE (BUILD_GROUP * SORT_ITEMS)       // keys per work-group

// counts[digit * BUILD_GROUP + lid]: keys with that digit among work-item
// lid's SORT_ITEMS keys of this group's tile.  (Column lid belongs to
// work-item lid alone, so no atomics are needed.)
inline void count_tile_digits(const global uint* keys, uint n, uint shift, local uint* counts)
{
    const uint lid = get_local_id(0);
    for (uint d = 0; d < RADIX_BINS; ++d)
        counts[d * BUILD_GROUP + lid] = 0u;
    const uint first = get_group_id(0) * SORT_TILE + lid * SORT_ITEMS;
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
    count_tile_digits(keys, n, shift, counts);
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

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void radix_scatter(const global uint* keys, const global uint* ids, const uint n, const uint shift,
                   const global uint* tile_offsets, global uint* keys_out, global uint* ids_out)
{
    local uint counts[RADIX_BINS * BUILD_GROUP];
    local uint digit_start[RADIX_BINS];
    local uint scratch[BUILD_GROUP];
    const uint lid = get_local_id(0);
    count_tile_digits(keys, n, shift, counts);

    // Exclusive prefix sum over counts in its digit-major order: then
    // counts[d * BUILD_GROUP + w] is the rank in the tile of work-item w's
    // first key of digit d.  Each work-item scans RADIX_BINS consecutive entries.
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

    const uint first = get_group_id(0) * SORT_TILE + lid * SORT_ITEMS;
    for (uint k = 0; k < SORT_ITEMS; ++k) {
        if (first + k < n) {
            const uint key = keys[first + k];
            const uint d = (key >> shift) & (RADIX_BINS - 1);
            const uint to = tile_offsets[d * get_num_groups(0) + get_group_id(0)]
                            + (counts[d * BUILD_GROUP + lid]++ - digit_start[d]);
            keys_out[to] = key;
            ids_out[to] = ids[first + k];
        }
    }
}

#endif
