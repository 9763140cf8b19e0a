// Prefix sums for the device builder: over one work-group (local memory), and
// over a short global array by one work-group.  Every kernel of the builder
// runs in work-groups of BUILD_GROUP work-items (-D from clrt/device/build.py).
#ifndef CLRT_BUILD_SCAN_CL
#define CLRT_BUILD_SCAN_CL

#ifndef BUILD_GROUP
#error "build with -DBUILD_GROUP=<work-group size, a power of two>"
#endif

// Entries each work-item sums serially in scan_in_one_group: fewer, longer
// steps than one entry per work-item, so a short array takes few barriers.
#define SCAN_ITEMS 8

// Exclusive prefix sum of one value per work-item over the work-group
// (Hillis-Steele in local memory: log2(work-group size) steps; any power of
// two, as ploc_tail's group is larger than BUILD_GROUP); *total gets the sum
// of all.  Every work-item of the group must call it; scratch holds one uint
// per work-item.
inline uint group_exclusive_scan(uint x, local uint* scratch, uint* total)
{
    const uint lid = get_local_id(0), size = get_local_size(0);
    scratch[lid] = x;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint offset = 1; offset < size; offset <<= 1) {
        const uint add = lid >= offset ? scratch[lid - offset] : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        scratch[lid] += add;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    const uint inclusive = scratch[lid];
    *total = scratch[size - 1];
    barrier(CLK_LOCAL_MEM_FENCE);       // the caller may reuse scratch at once
    return inclusive - x;
}

// Exclusive prefix sum, in place, of data[0, n) by one work-group, chunk after
// chunk (each work-item takes SCAN_ITEMS consecutive entries); returns the
// total.  For the short arrays of per-tile counts, where one work-group
// suffices.
inline uint scan_in_one_group(global uint* data, uint n, local uint* scratch)
{
    uint carry = 0;
    for (uint base = 0; base < n; base += BUILD_GROUP * SCAN_ITEMS) {
        const uint first = base + get_local_id(0) * SCAN_ITEMS;
        uint sum = 0;
        for (uint k = 0; k < SCAN_ITEMS; ++k)
            if (first + k < n)
                sum += data[first + k];
        uint chunk_total;
        uint prefix = carry + group_exclusive_scan(sum, scratch, &chunk_total);
        for (uint k = 0; k < SCAN_ITEMS; ++k)
            if (first + k < n) {
                const uint value = data[first + k];
                data[first + k] = prefix;
                prefix += value;
            }
        carry += chunk_total;
    }
    return carry;
}

// Exclusive prefix sum across the work-groups of one launch, in the launch
// itself: decoupled look-back (Merrill & Garland 2016, "Single-pass Parallel
// Prefix Scan with Decoupled Look-back").  Called by one work-item per group
// with the group's `tile` -- a ticket taken in the order the groups start, so
// that a group only ever waits for groups already running -- and the group's
// value.  Each tile publishes its value (AGGREGATE), walks back over its
// predecessors' entries until one holds its inclusive prefix (PREFIX), then
// publishes its own.  Flag and value share one word, written and read by
// atomics, so that a reader never sees one without the other.  status[0 ..
// tiles) must be 0 when the launch starts.  Values up to 2^30 - 1.
#define TILE_AGGREGATE 0x40000000u
#define TILE_PREFIX 0x80000000u
#define TILE_VALUE 0x3fffffffu

inline uint tile_exclusive_prefix(volatile global uint* status, uint tile, uint value)
{
    uint prefix = 0;
    if (tile > 0) {
        atomic_xchg(&status[tile], TILE_AGGREGATE | value);
        uint j = tile - 1;
        for (;;) {
            const uint entry = atomic_or(&status[j], 0u);
            if (entry & TILE_PREFIX) {
                prefix += entry & TILE_VALUE;
                break;
            }
            if (entry & TILE_AGGREGATE) {
                prefix += entry & TILE_VALUE;
                --j;                      // tile 0 always publishes its PREFIX
            }                             // else: not published yet, read again
        }
    }
    atomic_xchg(&status[tile], TILE_PREFIX | (prefix + value));
    return prefix;
}

#endif
