// PLOC: Parallel Locally-Ordered Clustering (Meister & Bittner 2018), with the
// single-block neighbour search and merge of PLOC++ (Benthin et al. 2022).
//
// Why PLOC and not LBVH with treelet restructuring: LBVH alone traces about
// 20-30 % slower than SAH trees, and treelet optimisation needs many
// enumerated treelet shapes per node; PLOC reaches the quality of a full SAH
// sweep with one simple step repeated -- every cluster finds the cluster
// whose merged box has the least surface area among the PLOC_RADIUS clusters
// on each side of it in the Morton order, and mutual nearest neighbours
// merge; each iteration removes a fifth to a quarter of the clusters (about
// 50 iterations for 75k triangles, most of them on a few hundred clusters).
//
// The clusters start as the triangles in Morton order (init_leaves).  On a
// GPU an iteration is one launch, ploc_merge: per tile of BUILD_GROUP
// clusters it loads the tile and 2 * PLOC_RADIUS clusters on each side into
// local memory, finds the nearest neighbour of the tile's clusters and of
// PLOC_RADIUS on each side (enough to know whether a neighbour's choice is
// mutual), merges mutual pairs into new nodes (the merged cluster takes the
// lower place, the higher one drops out), learns where its kept clusters go
// from the tiles before it (decoupled look-back, build_scan.cl) and writes
// them there, in order, into the other cluster buffer.  On a CPU an iteration
// is two plain passes (ploc_merge_tiles: the neighbours and the merges of a
// tile of places; ploc_compact, which moves the kept clusters together;
// below says why).
// Each kernel reads the cluster count from the state buffer, so the host can
// queue iterations without waiting for one; once SAH_TOP_CLUSTERS or fewer
// are left (PLOC_DONE) the kernels do nothing, and ploc_top makes the top of
// the tree over those by the SAH (build_top.cl).
//
// Launches pay off while there are many clusters.  Each iteration removes
// only a fifth to a quarter of them, so most iterations (about 40 of 50 for
// 75k triangles) run on a few thousand clusters, where a launch costs more
// than its work.  Below a threshold the host queues ploc_tail instead: one
// work-group that runs all remaining iterations in a loop, with barriers in
// place of launches.  It makes the same choices as the other kernels, so the
// tree does not depend on where the host hands over.  (A wider search in the
// tail, where it is cheap, was tried: SAH cost over the host SAH builder's
// went from 1.110 to 1.064 on camel at radius 32, but from 1.082 to 1.089 on
// bunny00, and 1.101 at radius 64.)
//
// Each new node also decides, bottom-up as it is made, whether its subtree
// is cheaper as a leaf by the surface area heuristic (refresh_node); the
// treelets below each node are reshaped afterwards (build_treelet.cl).
#ifndef CLRT_BUILD_PLOC_CL
#define CLRT_BUILD_PLOC_CL

#include "layouts.h"
#include "build_state.cl"
#include "build_scan.cl"
#include "build_morton.cl"
#include "build_treelet.cl"
#include "build_partition.cl"

#ifndef PLOC_RADIUS
#error "build with -DPLOC_RADIUS=<clusters searched on each side>"
#endif
#if !defined(C_TRAVERSAL) || !defined(C_INTERSECT)
#error "build with the SAH constants C_TRAVERSAL and C_INTERSECT of clrt/accel/topdown.py"
#endif

#ifndef TAIL_GROUP
#error "build with -DTAIL_GROUP=<work-items of ploc_tail>"
#endif

// PLOC merges until this many clusters are left; build_top.cl says why.
#define PLOC_DONE(count) ((count) <= SAH_TOP_CLUSTERS)

#define TILE_SPAN (BUILD_GROUP + 4 * PLOC_RADIUS)     // clusters a tile loads
#define SEARCHED (BUILD_GROUP + 2 * PLOC_RADIUS)      // clusters whose neighbour it finds
#define PAIR_ROWS (BUILD_GROUP + 3 * PLOC_RADIUS)     // first places of the pairs those need

// Tie-break between neighbours at the same distance, a hash of the pair (its
// two places, lower first).  Any order of pairs that both members agree on
// guarantees progress -- the least pair of all is always mutual -- but an
// order by place alone makes chains on regular meshes (identical distances
// everywhere: each cluster picks its left neighbour, and one pair merges per
// iteration); a hash makes the choices look random, and a fixed fraction of
// the clusters merge in every iteration.
inline uint pair_hash(uint lower, uint upper)
{
    uint h = lower * 0x9E3779B1u ^ (upper + 0x7F4A7C15u) * 0x85EBCA77u;
    h ^= h >> 15;
    h *= 0x2C1B3C6Du;
    h ^= h >> 12;
    return h;
}

// One candidate q of place p, taken in increasing q: the least area wins,
// a tie goes to the lower pair hash (computed only for ties), a tie of both
// to the earlier candidate -- ploc_merge's order.
typedef struct {
    int best;
    float area;
    uint hash;
    bool hashed;
} Nearest;

inline void consider(Nearest* n, int p, int q, float area)
{
    if (n->best < 0 || area < n->area) {
        n->best = q;
        n->area = area;
        n->hashed = false;
    } else if (area == n->area) {
        if (!n->hashed) {
            n->hash = pair_hash(min(p, n->best), max(p, n->best));
            n->hashed = true;
        }
        const uint hash = pair_hash(min(p, q), max(p, q));
        if (hash < n->hash) {
            n->best = q;
            n->hash = hash;
        }
    }
}

// Leaf nodes and the first clusters: node i is the triangle ids[i], the i-th
// in Morton order; the look-back entries of ploc_merge's first iteration and
// the inner nodes' flags of treelet_restructure, cleared.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void init_leaves(const global float* corners, const global uint* sorted_ids, const global uint* sorted_keys,
                 const int segmented, const uint num_tris, global BuildNode* nodes, global BuildCluster* clusters,
                 global uint* tile_status, global uint* treelet_done)
{
    const uint i = get_global_id(0);
    if (i < (num_tris + BUILD_GROUP - 1) / BUILD_GROUP)
        tile_status[i] = 0u;
    if (i + 1 < num_tris)
        treelet_done[i] = 0u;
    if (i >= num_tris)
        return;
    float3 lo, hi;
    triangle_box(corners, sorted_ids[i], &lo, &hi);
    BuildNode node;
    node.lo = (float4)(lo, as_float(-1));
    node.hi = (float4)(hi, as_float(-1));
    node.parent = -1;
    node.count = 1;
    node.rows = 0;
    node.cost = C_INTERSECT * half_area(lo, hi);
    nodes[i] = node;
    clusters[i].lo = (float4)(lo, as_float((int)i));
    // Its segment: the top bits of the key (partition_morton_codes), else 0.
    clusters[i].hi = (float4)(hi, as_float(segmented ? (int)(sorted_keys[i] >> (32 - SEGMENT_BITS)) : 0));
}

// The segment of a cluster: only clusters of one segment merge (the SAH
// partition's segments stay runs of places, since merges and compaction keep
// the order).
inline int cluster_segment(float4 hi)
{
    return as_int(hi.w) & SEGMENT_MASK;
}

// Whether clusters of these segments may merge: compiled out of builds
// without the partition (-DPLOC_SEGMENTS), whose clusters are all of segment
// 0 (the test cost bunny00's PLOC 7 %, 0.06 ms on the H200).
#ifdef PLOC_SEGMENTS
#define SAME_SEGMENT(a, b) ((a) == (b))
#else
#define SAME_SEGMENT(a, b) ((void)(a), (void)(b), true)   // (uses both: no unused-variable warning)
#endif

// The node that merges clusters a (left) and b (right), its numbers and leaf
// decision made by refresh_node (build_treelet.cl).  Returns the new cluster.
inline BuildCluster make_node(global BuildNode* nodes, global int* heights, int num_tris, int index,
                              BuildCluster a, BuildCluster b, uint leaf_size)
{
    const int left = as_int(a.lo.w), right = as_int(b.lo.w);
    nodes[index].lo.w = as_float(left);
    nodes[index].hi.w = as_float(right);
    nodes[index].parent = -1;
    nodes[left].parent = index;
    nodes[right].parent = index;
    refresh_node(nodes, heights, index, num_tris, leaf_size);
    BuildCluster merged;
    merged.lo = (float4)(fmin(a.lo.xyz, b.lo.xyz), as_float(index));
    merged.hi = (float4)(fmax(a.hi.xyz, b.hi.xyz), as_float(cluster_segment(a.hi)));
    return merged;
}

// One PLOC iteration on a GPU, one launch: clusters (count of them, from the
// state) -> next (the kept and merged clusters, compacted in order), and the
// next iteration's count in the state.  Tiles are numbered by tickets in the
// order their work-groups start, and find where their kept clusters go by
// decoupled look-back (tile_exclusive_prefix) over tile_status[iteration % 2]
// (two halves of as many uints as iteration 0 has tiles; the half of iteration 0 zeroed by init_leaves, each
// iteration zeroes the other half for the next).  (The first version took
// three launches an iteration -- merge, a prefix sum of the tiles' counts in
// one work-group, compaction -- as the CPU passes still do.)
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void ploc_merge(const global BuildCluster* clusters, global BuildCluster* next, global uint* tile_status,
                global BuildNode* nodes, global int* heights, const int num_tris, global int* state,
                const int iteration, const uint leaf_size)
{
    local float4 box_lo[TILE_SPAN], box_hi[TILE_SPAN];    // w: node of the cluster
    local float pair_area[PAIR_ROWS * PLOC_RADIUS];
    local int nearest[SEARCHED];
    local uint scratch[BUILD_GROUP];
    local int node_base, ticket;
    local uint tile_offset;
    const int count = state[CLUSTERS_BEFORE(iteration)];
    if (PLOC_DONE(count)) {                       // the same for every work-group
        // An iteration the host queued past the end: the clusters go on to
        // the other buffer all the same, where the host (which counts the
        // launches, not the merges) tells ploc_tail to find them.
        if (get_group_id(0) == 0)
            for (int k = get_local_id(0); k < count; k += BUILD_GROUP)
                next[k] = clusters[k];
        if (get_global_id(0) == 0)
            state[CLUSTERS_BEFORE(iteration + 1)] = count;
        return;
    }
    const int lid = get_local_id(0);
    const int tiles = (count + BUILD_GROUP - 1) / BUILD_GROUP;
    const uint status_half = (num_tris + BUILD_GROUP - 1) / BUILD_GROUP;   // tiles of the first iteration
    if (lid == 0)
        ticket = atomic_inc(state + STATE_TICKETS + iteration % 2);
    barrier(CLK_LOCAL_MEM_FENCE);
    const int tile = ticket;
    if (tile >= tiles)
        return;
    global uint* status = tile_status + (iteration % 2) * status_half;
    global uint* status_next = tile_status + ((iteration + 1) % 2) * status_half;
    if (lid == 0) {
        status_next[tile] = 0u;       // for the next iteration, which has no more tiles
        if (tile == 0)
            state[STATE_TICKETS + (iteration + 1) % 2] = 0;
    }
    const int start = tile * BUILD_GROUP;
    const int loaded = start - 2 * PLOC_RADIUS;   // place of box_lo[0]
    for (int k = lid; k < TILE_SPAN; k += BUILD_GROUP) {
        const int p = loaded + k;
        if (p >= 0 && p < count) {
            box_lo[k] = clusters[p].lo;
            box_hi[k] = clusters[p].hi;
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    // The merged area of every pair (a, a + o), o = 1..PLOC_RADIUS, that a
    // search below needs, computed once per pair (PLOC++): row a - loaded of
    // pair_area, INFINITY where a + o is past the last cluster.
    for (int k = lid; k < PAIR_ROWS; k += BUILD_GROUP) {
        const int a = loaded + k;
        const bool valid = a >= 0;
        const float3 lo = box_lo[k].xyz, hi = box_hi[k].xyz;
        for (int o = 1; o <= PLOC_RADIUS; ++o) {
            const bool pair = valid && a + o < count;
            pair_area[k * PLOC_RADIUS + o - 1] = pair
                ? half_area(fmin(lo, box_lo[k + o].xyz), fmax(hi, box_hi[k + o].xyz)) : INFINITY;
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    // Nearest neighbour of places start - PLOC_RADIUS .. start + BUILD_GROUP + PLOC_RADIUS - 1,
    // by (area, pair hash); candidates in increasing place, and equal keys
    // keep the earlier one: the lower pair (see pair_hash), so both ends of a
    // pair see one order.  INFINITY marks no pair: a real area is finite
    // here or, for huge boxes, ties with it and loses nothing.
    for (int k = lid; k < SEARCHED; k += BUILD_GROUP) {
        const int p = start - PLOC_RADIUS + k;
        Nearest n = {-1, INFINITY, 0u, false};
        if (p >= 0 && p < count) {
            const int row = p - loaded;
            const int segment = cluster_segment(box_hi[row]);
            for (int o = -PLOC_RADIUS; o <= PLOC_RADIUS; ++o) {
                const int q = p + o;
                if (o == 0 || q < 0 || q >= count || !SAME_SEGMENT(cluster_segment(box_hi[row + o]), segment))
                    continue;
                consider(&n, p, q, o < 0 ? pair_area[(row + o) * PLOC_RADIUS - o - 1]
                                         : pair_area[row * PLOC_RADIUS + o - 1]);
            }
        }
        nearest[k] = n.best;
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    const int i = start + lid;
    int partner = -1;            // i merges with partner (i < partner)
    bool kept = false;
    if (i < count) {
        const int j = nearest[i - start + PLOC_RADIUS];     // -1: alone in its segment
        const bool mutual = j >= 0 && nearest[j - start + PLOC_RADIUS] == i;
        kept = !mutual || i < j;
        if (mutual && i < j)
            partner = j;
    }
    // New nodes: consecutive indices per work-group, from one atomic.
    uint merges;
    const uint my_merge = group_exclusive_scan(partner >= 0 ? 1u : 0u, scratch, &merges);
    if (lid == 0)
        node_base = merges > 0 ? atomic_add(state + STATE_NEXT_NODE, (int)merges) : 0;
    uint kept_in_tile;
    const uint rank = group_exclusive_scan(kept ? 1u : 0u, scratch, &kept_in_tile);   // its barriers publish node_base
    if (lid == 0) {
        tile_offset = tile_exclusive_prefix(status, tile, kept_in_tile);
        if (tile == tiles - 1) {      // the last tile knows the total
            const int left = (int)(tile_offset + kept_in_tile);
            state[CLUSTERS_BEFORE(iteration + 1)] = left;
            if (PLOC_DONE(left))
                state[STATE_ITERATIONS] = iteration + 1;    // the last one that merged
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    // (An if, not a return: PoCL 3.1 ran the writes of returned work-items when
    // the return followed the barriers.)
    if (i < count && kept) {
        BuildCluster out;
        out.lo = box_lo[i - loaded];
        out.hi = box_hi[i - loaded];
        if (partner >= 0) {
            BuildCluster b;
            b.lo = box_lo[partner - loaded];
            b.hi = box_hi[partner - loaded];
            out = make_node(nodes, heights, num_tris, node_base + (int)my_merge, out, b, leaf_size);
        }
        next[tile_offset + rank] = out;
    }
}

// CPU devices: the kept clusters of ploc_merge_tiles moved together, in
// order, and the next iteration's cluster count.  Work-item w of the launch
// takes a run of consecutive tiles (a CPU hands each core a run of
// work-items): their first place is the sum of the kept counts of the tiles
// before (a few hundred at most: a plain loop), and each kept cluster goes to
// that place plus its rank.  (Before: a prefix sum by one work-item, then a
// launch of a work-item a place -- two launches an iteration, and at 60 us
// each, most of the later iterations' time.)
__kernel void ploc_compact(const global BuildCluster* merged, global BuildCluster* clusters,
                           const global uint* tile_kept, global int* state, const int iteration)
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
        for (int p = tile * BUILD_GROUP; p < min((tile + 1) * BUILD_GROUP, count); ++p) {
            const BuildCluster c = merged[p];
            const int rank = (as_int(c.hi.w) >> SEGMENT_BITS) - 1;
            if (rank >= 0)
                clusters[place + rank] = c;
        }
        place += tile_kept[tile];
    }
    if (w == workers - 1) {             // its place is past every kept cluster: the next count
        state[CLUSTERS_BEFORE(iteration + 1)] = (int)place;
        if (PLOC_DONE((int)place))
            state[STATE_ITERATIONS] = iteration + 1;    // the last one that merged
    }
}

// The cluster at place p's nearest neighbour among the PLOC_RADIUS places on
// each side, read from global memory: ploc_merge's choice (least area, then
// least pair hash; the area of a pair is the same from either end, since
// fmin and fmax commute).
inline int tail_nearest(const global BuildCluster* clusters, int count, int p)
{
    const float3 lo = clusters[p].lo.xyz, hi = clusters[p].hi.xyz;
    const int segment = cluster_segment(clusters[p].hi);
    Nearest n = {-1, INFINITY, 0u, false};
    for (int q = max(p - PLOC_RADIUS, 0); q <= min(p + PLOC_RADIUS, count - 1); ++q)
        if (q != p && SAME_SEGMENT(cluster_segment(clusters[q].hi), segment))
            consider(&n, p, q, half_area(fmin(lo, clusters[q].lo.xyz), fmax(hi, clusters[q].hi.xyz)));
    return n.best;
}

// The SAH top (after make_node, which it calls).
#include "build_top.cl"

// One work-group: every PLOC iteration from first_iteration until
// SAH_TOP_CLUSTERS or fewer clusters are left, between `clusters` (holding
// the clusters at the start) and `spare`; nearest: scratch of at least the
// starting count of ints.  Leaves at STATE_TAIL what ploc_top, launched next,
// needs: the clusters left, the node counter, the iterations that merged
// (this loop's count, or else the total that ploc_merge or ploc_compact
// wrote: the host may have queued more launches, which merged nothing, so
// that the total does not depend on where the host handed over), and
// whether this loop merged and left the clusters in `spare`.
// Each work-item keeps a contiguous block of places, so that its kept
// clusters and new nodes are ranked by one prefix sum over the group.
// (The SAH top was once the end of this kernel: PoCL took 1.4 s to compile
// the two loops of barriers in one kernel, 0.7 s as two kernels.)
__kernel __attribute__((reqd_work_group_size(TAIL_GROUP, 1, 1)))
void ploc_tail(global BuildCluster* clusters, global BuildCluster* spare, global int* nearest,
               global BuildNode* nodes, global int* heights, const int num_tris, global int* state,
               const int first_iteration, const uint leaf_size)
{
    local uint scratch[TAIL_GROUP];
    const int lid = get_local_id(0);
    int count = state[CLUSTERS_BEFORE(first_iteration)];
    int next_node = state[STATE_NEXT_NODE];
    int iteration = first_iteration;
    global BuildCluster* from = clusters;
    global BuildCluster* to = spare;
    while (!PLOC_DONE(count)) {            // count is the same in every work-item
        for (int p = lid; p < count; p += TAIL_GROUP)
            nearest[p] = tail_nearest(from, count, p);
        barrier(CLK_GLOBAL_MEM_FENCE);

        const int block = (count + TAIL_GROUP - 1) / TAIL_GROUP;
        const int first = min(lid * block, count), last = min(first + block, count);
        uint kept = 0, merges = 0;
        for (int p = first; p < last; ++p) {
            const int j = nearest[p];               // -1: alone in its segment
            const bool mutual = j >= 0 && nearest[j] == p;
            kept += !mutual || p < j;
            merges += mutual && p < j;
        }
        // Both counts in one prefix sum, merges in the high half (the host
        // keeps the tail's clusters below 2^16).
        uint totals;
        const uint ranks = group_exclusive_scan(kept | merges << 16, scratch, &totals);
        const uint kept_total = totals & 0xffffu, merges_total = totals >> 16;
        uint place = ranks & 0xffffu;
        uint node = (uint)next_node + (ranks >> 16);
        for (int p = first; p < last; ++p) {
            const int j = nearest[p];
            const bool mutual = j >= 0 && nearest[j] == p;
            if (!mutual)
                to[place++] = from[p];
            else if (p < j)
                to[place++] = make_node(nodes, heights, num_tris, (int)node++, from[p], from[j], leaf_size);
        }
        next_node += (int)merges_total;
        count = (int)kept_total;
        ++iteration;
        barrier(CLK_GLOBAL_MEM_FENCE);     // `to` and the nodes complete before the next search
        global BuildCluster* t = from;
        from = to;
        to = t;
    }
    if (lid == 0) {
        const bool merged_here = iteration > first_iteration;
        state[STATE_TAIL + TAIL_COUNT] = count;
        state[STATE_TAIL + TAIL_NEXT_NODE] = next_node;
        state[STATE_TAIL + TAIL_ITERATIONS] = merged_here ? iteration : state[STATE_ITERATIONS];
        state[STATE_TAIL + TAIL_FLAGS] = (merged_here ? TAIL_MERGED : 0)
                                       | ((iteration - first_iteration) % 2 ? TAIL_IN_SPARE : 0);
    }
}

// One work-group, after ploc_tail (with the same buffers): the SAH top over
// the clusters it left (build_top.cl; each of its levels counts as an
// iteration).  Writes the node counter, the iteration total and the last
// count to the state, unless nothing merged since ploc_merge or
// ploc_compact wrote them.
__kernel __attribute__((reqd_work_group_size(TAIL_GROUP, 1, 1)))
void ploc_top(global BuildCluster* clusters, global BuildCluster* spare, global BuildNode* nodes,
              global int* heights, const int num_tris, global int* state, const uint leaf_size)
{
    local TopScratch top;
    // Read before sah_top's barriers: only work-item 0 writes the state, after them.
    const int count = state[STATE_TAIL + TAIL_COUNT];
    const int next_node = state[STATE_TAIL + TAIL_NEXT_NODE];
    const int merged_iterations = state[STATE_TAIL + TAIL_ITERATIONS];
    const int flags = state[STATE_TAIL + TAIL_FLAGS];
    global BuildCluster* from = flags & TAIL_IN_SPARE ? spare : clusters;
    global BuildCluster* to = flags & TAIL_IN_SPARE ? clusters : spare;
    const int levels = sah_top(from, count, to, nodes, heights, num_tris, next_node, leaf_size, &top);
    if (get_local_id(0) == 0 && ((flags & TAIL_MERGED) || levels)) {
        state[STATE_NEXT_NODE] = next_node + (levels ? count - 1 : 0);
        state[STATE_ITERATIONS] = merged_iterations + levels;
        state[CLUSTERS_BEFORE(merged_iterations + levels)] = levels ? 1 : count;
    }
}

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
#define SEARCH_PLACES (BUILD_GROUP + 2 * PLOC_RADIUS)   // places a search finds the neighbours of, at most
#if PLOC_RADIUS == 16 && !defined(PLOC_SEGMENTS) && !defined(PLOC_SCALAR_SEARCH)
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
                               global uint* tile_kept, global BuildNode* nodes, global int* heights,
                               const int num_tris, global int* state, const int iteration, const uint leaf_size)
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
        int merges = 0;
        for (int p = start; p < end; ++p)
            merges += NEAREST(p) >= 0 && NEAREST(NEAREST(p)) == p && p < NEAREST(p);
        int node = merges > 0 ? atomic_add(state + STATE_NEXT_NODE, merges) : 0;
        int rank = 0;
        for (int p = start; p < end; ++p) {
            const int j = NEAREST(p);                       // -1: alone in its segment
            const bool mutual = j >= 0 && NEAREST(j) == p;
            BuildCluster out = clusters[p];
            if (mutual && p < j)
                out = make_node(nodes, heights, num_tris, node++, out, clusters[j], leaf_size);
            // 1 + its rank (0: merged away) above its segment, for ploc_compact.
            out.hi.w = as_float(cluster_segment(out.hi) | (!mutual || p < j ? ++rank : 0) << SEGMENT_BITS);
            merged[p] = out;
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
    const bool merged_here = iteration > first_iteration;
    state[STATE_TAIL + TAIL_COUNT] = count;
    state[STATE_TAIL + TAIL_NEXT_NODE] = next_node;
    state[STATE_TAIL + TAIL_ITERATIONS] = merged_here ? iteration : state[STATE_ITERATIONS];
    state[STATE_TAIL + TAIL_FLAGS] = (merged_here ? TAIL_MERGED : 0)
                                   | ((iteration - first_iteration) % 2 ? TAIL_IN_SPARE : 0);
}

#endif
