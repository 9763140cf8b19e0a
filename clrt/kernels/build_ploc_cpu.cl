// PLOC on CPU devices (clrt/device/build.py's CPU path): the same merges as
// build_ploc.cl's ploc_merge and ploc_tail, the same tree bit for bit
// (tests/test_device_build.py), in kernels a CPU runs well -- work-groups of
// one work-item striding over tiles, the neighbour search in float16 lanes,
// the last iterations by one work-item.
#ifndef CLRT_BUILD_PLOC_CPU_CL
#define CLRT_BUILD_PLOC_CPU_CL

#include "layouts.h"
#include "build_state.cl"
#include "build_ploc.cl"

// ploc_merge for CPU devices.  A CPU runs a work-group as a loop over its
// work-items, one stretch between barriers at a time, and there ploc_merge's
// barriers and local tables cost far more than its arithmetic (6 ms a launch
// for bunny00's first iterations on 2 cores, 125 of a 130 ms build).  The same
// choices in a plain pass over tiles of BUILD_GROUP places (ploc_merge_tiles)
// leave tile_kept and the ranks as ploc_merge does, for ploc_compact.
// Work-item w takes tiles w, w + size, ... of the clusters there are now: the
// host sizes a batch's launches for the count before it, and a CPU hands each
// core a contiguous run of work-items, so one per tile left one core idle as
// the count fell.  A tile finds the nearest neighbours of its places and of
// PLOC_RADIUS places on each side (find_nearest: whether a neighbour's choice
// is mutual), then merges mutual pairs in place order, its new nodes from one
// atomic, consecutive within the iteration.  (The neighbours of every place
// were first a launch of their own: one launch more an iteration, for an
// eighth less search.)
// A place's hi.w between ploc_merge_tiles and ploc_compact: its segment
// (bits 0..7), 1 + its rank in its tile (0: merged away), and the distance
// to the partner it merges with (0: none).
#define RANK_MASK 0xffff
#define PARTNER_SHIFT 24
#define PARTNER_MASK 0x7f
#if PLOC_RADIUS > PARTNER_MASK || BUILD_GROUP >= RANK_MASK || SEGMENT_BITS + 16 > PARTNER_SHIFT
#error "a place's segment, rank and partner do not fit in hi.w"
#endif
#define SEARCH_PLACES (BUILD_GROUP + 2 * PLOC_RADIUS)   // places a search finds the neighbours of, at most
#if PLOC_RADIUS == 16 && !defined(PLOC_SEGMENTS)
// The search in float16 lanes: PoCL runs these one-work-item groups as
// scalar code, and the scalar search (below) took 55 of bunny00's 86 ms of
// PLOC on 2 cores (3 ms now).  A work-item copies the boxes of its places and
// PLOC_RADIUS places on each side into six rows of floats (lo xyz, hi xyz),
// so that the 16 places behind p and the 16 ahead are each one unaligned
// load a row; both sides' merged areas are computed (twice the scalar
// search's area work, which PLOC_RADIUS lanes repay).  The least area is the
// choice where one candidate has it; a tie, or no finite area, takes the
// scalar choice of consider over the same areas (the rule of the hashes), so
// the tree is ploc_merge's bit for bit (tests/test_device_build.py).
#define SEARCH_WINDOW (SEARCH_PLACES + 2 * PLOC_RADIUS)  // places a search reads
#define SEARCH_SCRATCH (6 * SEARCH_WINDOW)               // floats of find_nearest's scratch

// Merged half areas (half_area, lane by lane) of the box at window place
// `self` with those at places first .. first + 15.  (min and max: fmin's NaN
// rule costs a compare and a blend a lane, and a NaN corner fails the build
// anyway -- STATE_BAD_TRIANGLE.)
inline float16 window_areas(const float* window, int self, int first)
{
    const float16 dx = max(window[3 * SEARCH_WINDOW + self], vload16(0, window + 3 * SEARCH_WINDOW + first))
                     - min(window[self], vload16(0, window + first));
    const float16 dy = max(window[4 * SEARCH_WINDOW + self], vload16(0, window + 4 * SEARCH_WINDOW + first))
                     - min(window[SEARCH_WINDOW + self], vload16(0, window + SEARCH_WINDOW + first));
    const float16 dz = max(window[5 * SEARCH_WINDOW + self], vload16(0, window + 5 * SEARCH_WINDOW + first))
                     - min(window[2 * SEARCH_WINDOW + self], vload16(0, window + 2 * SEARCH_WINDOW + first));
    const float16 a = dx * dy + dy * dz + dz * dx;           // half_area's expression, lane by lane
    return select(a, (float16)(INFINITY), isnan(a));
}

// Reductions of sixteen lanes by halves (PoCL's any() tested the lanes one by one).
inline float least_lane(float16 v)
{
    const float8 a = min(v.lo, v.hi);
    const float4 b = min(a.lo, a.hi);
    const float2 c = min(b.lo, b.hi);
    return min(c.x, c.y);
}

inline int least_int_lane(int16 v)
{
    const int8 a = min(v.lo, v.hi);
    const int4 b = min(a.lo, a.hi);
    const int2 c = min(b.lo, b.hi);
    return min(c.x, c.y);
}

inline int greatest_int_lane(int16 v)
{
    const int8 a = max(v.lo, v.hi);
    const int4 b = max(a.lo, a.hi);
    const int2 c = max(b.lo, b.hi);
    return max(c.x, c.y);
}

// The nearest neighbour of places first .. end - 1 (at most SEARCH_PLACES)
// among `count` clusters, into found[p - first]; window: SEARCH_SCRATCH floats.
inline void find_nearest(const global BuildCluster* clusters, int count, int first, int end, float* window,
                         int* found)
{
    // Candidate k of place p is place p - 16 + k: behind 0..15, ahead 17..32 (16: p itself).
    const int16 lanes = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int base = first - PLOC_RADIUS;                  // the place at window[0]
    for (int k = 0; k < end - base + PLOC_RADIUS; ++k) {
        const int q = base + k;
        // No place: an infinite box, whose merged area (infinite) is no choice.
        const bool there = q >= 0 && q < count;
        const float4 lo = there ? clusters[q].lo : (float4)(-INFINITY);
        const float4 hi = there ? clusters[q].hi : (float4)(INFINITY);
        window[k] = lo.x;
        window[SEARCH_WINDOW + k] = lo.y;
        window[2 * SEARCH_WINDOW + k] = lo.z;
        window[3 * SEARCH_WINDOW + k] = hi.x;
        window[4 * SEARCH_WINDOW + k] = hi.y;
        window[5 * SEARCH_WINDOW + k] = hi.z;
    }
    for (int p = first; p < end; ++p) {
        const int i = p - base;
        const float16 behind = window_areas(window, i, i - PLOC_RADIUS);   // candidates 0..15
        const float16 ahead = window_areas(window, i, i + 1);              // candidates 17..32
        const float least = least_lane(min(behind, ahead));
        const int16 is_behind = behind == least, is_ahead = ahead == least;
        const int16 ahead_lanes = lanes + (PLOC_RADIUS + 1);
        const int best = least_int_lane(min(select((int16)(INT_MAX), lanes, is_behind),
                                            select((int16)(INT_MAX), ahead_lanes, is_ahead)));
        const int last = greatest_int_lane(max(select((int16)(-1), lanes, is_behind),
                                               select((int16)(-1), ahead_lanes, is_ahead)));
        if (isfinite(least) && best == last) {            // one candidate has the least area
            found[p - first] = p - PLOC_RADIUS + best;
            continue;
        }
        float areas[2 * PLOC_RADIUS];
        vstore16(behind, 0, areas);
        vstore16(ahead, 0, areas + PLOC_RADIUS);
        Nearest n = {-1, INFINITY, 0u, false};
        for (int k = 0; k < 2 * PLOC_RADIUS; ++k) {
            const int q = k < PLOC_RADIUS ? p - PLOC_RADIUS + k : p + 1 + k - PLOC_RADIUS;
            if (q >= 0 && q < count)
                consider(&n, p, q, areas[k]);
        }
        found[p - first] = n.best;
    }
}
#else
#define SEARCH_SCRATCH ((PLOC_RADIUS + 1) * PLOC_RADIUS)  // floats of find_nearest's scratch

// find_nearest one candidate at a time (a radius other than 16, or the SAH
// partition's segments).  Each pair's area once, as ploc_merge's table does:
// row p % (PLOC_RADIUS + 1) of `ahead` holds the areas of (p, p + o), o =
// 1..PLOC_RADIUS, and serves p's places ahead now and theirs behind later
// (the rows of the PLOC_RADIUS places before p are still there).  The area
// of a pair is the same from either end (fmin and fmax commute).
inline void find_nearest(const global BuildCluster* clusters, int count, int first, int end, float* ahead,
                         int* found)
{
    for (int p = max(first - PLOC_RADIUS, 0); p < end; ++p) {
        const float3 lo = clusters[p].lo.xyz, hi = clusters[p].hi.xyz;
        float* row = ahead + (p % (PLOC_RADIUS + 1)) * PLOC_RADIUS;
        for (int o = 1; o <= PLOC_RADIUS && p + o < count; ++o)
            row[o - 1] = half_area(fmin(lo, clusters[p + o].lo.xyz), fmax(hi, clusters[p + o].hi.xyz));
        if (p < first)
            continue;
        const int segment = cluster_segment(clusters[p].hi);
        Nearest n = {-1, INFINITY, 0u, false};
        for (int q = max(p - PLOC_RADIUS, 0); q < p; ++q)
            if (SAME_SEGMENT(cluster_segment(clusters[q].hi), segment))
                consider(&n, p, q, ahead[(q % (PLOC_RADIUS + 1)) * PLOC_RADIUS + (p - q - 1)]);
        for (int q = p + 1; q <= min(p + PLOC_RADIUS, count - 1); ++q)
            if (SAME_SEGMENT(cluster_segment(clusters[q].hi), segment))
                consider(&n, p, q, row[q - p - 1]);
        found[p - first] = n.best;
    }
}
#endif

__kernel void ploc_merge_tiles(const global BuildCluster* clusters, global BuildCluster* merged,
                               global uint* tile_kept, global int* state, const int iteration)
{
    const int count = state[CLUSTERS_BEFORE(iteration)];
    if (PLOC_DONE(count))
        return;
    float scratch[SEARCH_SCRATCH];
    int found[SEARCH_PLACES];
    for (int tile = get_global_id(0); tile * BUILD_GROUP < count; tile += get_global_size(0)) {
        const int start = tile * BUILD_GROUP, end = min(start + BUILD_GROUP, count);
        // The neighbours of the tile and of those its places may choose.
        const int first = max(start - PLOC_RADIUS, 0);
        find_nearest(clusters, count, first, min(end + PLOC_RADIUS, count), scratch, found);
#define NEAREST(p) found[(p) - first]
        int rank = 0;
        for (int p = start; p < end; ++p) {
            const int j = NEAREST(p);                       // -1: alone in its segment
            const bool mutual = j >= 0 && NEAREST(j) == p;
            const BuildCluster c = clusters[p];
            // 1 + its rank (0: merged away) above its segment, and the distance
            // to the partner it merges with (0: none), for ploc_compact, which
            // makes the pair's node (it knows how many pairs come before).
            merged[p].lo = c.lo;
            merged[p].hi = (float4)(c.hi.xyz, as_float(cluster_segment(c.hi)
                                                       | (!mutual || p < j ? ++rank : 0) << SEGMENT_BITS
                                                       | (mutual && p < j ? j - p : 0) << PARTNER_SHIFT));
        }
#undef NEAREST
        tile_kept[tile] = (uint)rank;
    }
}

// ploc_tail for CPU devices: the same iterations by one work-item, with no
// barriers (PoCL runs a work-group's barriers as loops over its work-items,
// and compiles them slowly: ploc_tail took 0.3-0.7 s of a first build).  The
// last few thousand clusters' iterations, each of two launches
// (ploc_merge_tiles, ploc_compact), cost more in launches than in work on 2
// cores; here they take about a millisecond.  The same choices
// (find_nearest, every place's into `nearest` first) and the same merges in
// place order, the kept and merged clusters written in order to the other
// buffer; leaves at STATE_TAIL what ploc_tail leaves, for ploc_top.
__kernel __attribute__((reqd_work_group_size(1, 1, 1)))
void ploc_tail_serial(global BuildCluster* clusters, global BuildCluster* spare, global int* nearest,
                      global BuildNode* nodes, global int* heights, const int num_tris, global int* state,
                      const int first_iteration, const uint leaf_size)
{
    int count = state[CLUSTERS_BEFORE(first_iteration)];
    int next_node = state[STATE_NEXT_NODE];
    int iteration = first_iteration;
    global BuildCluster* from = clusters;
    global BuildCluster* to = spare;
    float scratch[SEARCH_SCRATCH];
    int found[SEARCH_PLACES];
    while (!PLOC_DONE(count)) {
        for (int start = 0; start < count; start += BUILD_GROUP) {
            const int end = min(start + BUILD_GROUP, count);
            find_nearest(from, count, start, end, scratch, found);
            for (int p = start; p < end; ++p)
                nearest[p] = found[p - start];
        }
        int kept = 0;
        for (int p = 0; p < count; ++p) {
            const int j = nearest[p];                   // -1: alone in its segment
            const bool mutual = j >= 0 && nearest[j] == p;
            if (!mutual)
                to[kept++] = from[p];
            else if (p < j)
                to[kept++] = make_node(nodes, heights, num_tris, next_node++, from[p], from[j], leaf_size);
        }
        count = kept;
        ++iteration;
        global BuildCluster* t = from;
        from = to;
        to = t;
    }
    hand_over_to_top(state, count, next_node, iteration, first_iteration);
}

// The distance from place p to the partner it merges with (0: none), as
// ploc_merge_tiles leaves it.
inline int merged_partner(const global BuildCluster* merged, int p)
{
    return (as_int(merged[p].hi.w) >> PARTNER_SHIFT) & PARTNER_MASK;
}

// CPU devices: the kept clusters of ploc_merge_tiles moved together, in
// order, the merged pairs' nodes made, and the next iteration's cluster
// count.  Work-item w of the launch takes a run of consecutive tiles (a CPU
// hands each core a run of work-items): their first place is the sum of the
// kept counts of the tiles before (a few hundred at most: a plain loop), and
// each kept cluster goes to that place plus its rank.  The pairs before a
// tile are the places merged away before it plus those that straddle its
// start, which numbers its nodes as ploc_merge does (first_node_of_tile).
// (Before: a prefix sum by one work-item, then a launch of a work-item a
// place -- two launches an iteration, and at 60 us each, most of the later
// iterations' time.)
__kernel void ploc_compact(const global BuildCluster* merged, global BuildCluster* clusters,
                           const global uint* tile_kept, global BuildNode* nodes, global int* heights,
                           const int num_tris, global int* state, const int iteration, const uint leaf_size)
{
    const int count = state[CLUSTERS_BEFORE(iteration)];
    const int w = get_global_id(0), workers = get_global_size(0);
    if (PLOC_DONE(count)) {             // a launch past the end: the count carries on
        if (w == 0)
            state[CLUSTERS_BEFORE(iteration + 1)] = count;
        return;
    }
    const int tiles = (count + BUILD_GROUP - 1) / BUILD_GROUP;
    const int first = (int)((long)tiles * w / workers), last = (int)((long)tiles * (w + 1) / workers);
    uint place = 0;
    for (int tile = 0; tile < first; ++tile)
        place += tile_kept[tile];
    for (int tile = first; tile < last; ++tile) {
        const int start = tile * BUILD_GROUP;
        int straddling = 0;
        for (int q = max(start - PLOC_RADIUS, 0); q < start; ++q)
            straddling += q + merged_partner(merged, q) >= start;
        int node = first_node_of_tile(num_tris, count, start, (int)place, straddling);
        for (int p = start; p < min(start + BUILD_GROUP, count); ++p) {
            BuildCluster c = merged[p];
            const int rank = ((as_int(c.hi.w) >> SEGMENT_BITS) & RANK_MASK) - 1;
            const int partner = merged_partner(merged, p);
            if (partner > 0)
                c = make_node(nodes, heights, num_tris, node++, c, merged[p + partner], leaf_size);
            if (rank >= 0)
                clusters[place + rank] = c;
        }
        place += tile_kept[tile];
    }
    if (w == workers - 1) {             // its place is past every kept cluster: the next count
        state[CLUSTERS_BEFORE(iteration + 1)] = (int)place;
        state[STATE_NEXT_NODE] = first_node_of_tile(num_tris, (int)place, 0, 0, 0);
        if (PLOC_DONE((int)place))
            state[STATE_ITERATIONS] = iteration + 1;    // the last one that merged
    }
}

#endif
