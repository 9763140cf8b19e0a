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
// build_ploc_cpu.cl says why).
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
// place of launches (on a CPU ploc_tail_serial: one work-item, no barriers).
// It makes the same choices as the other kernels, so the tree does not depend
// on where the host hands over.  (A wider search in the
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

// The leaf node of a triangle of box lo, hi (children -1; ploc_hierarchy
// makes a leaf's numbers from its cluster's box by it too).
inline BuildNode leaf_node(float3 lo, float3 hi)
{
    BuildNode node;
    node.lo = (float4)(lo, as_float(-1));
    node.hi = (float4)(hi, as_float(-1));
    node.parent = -1;
    node.count = 1;
    node.rows = 0;
    node.cost = C_INTERSECT * half_area(lo, hi);
    return node;
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
    nodes[i] = leaf_node(lo, hi);
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

// The number of the first node made by the pairs of the tile at place
// `start`, in an iteration that starts with `count` clusters: the leaves are
// nodes 0 .. num_tris - 1, each merge so far made one node and took one
// cluster away, and the pairs of this iteration are numbered in the order of
// their first places -- those before `start` are the places merged away
// before it (start - kept_before) and the pairs that straddle it.  The same
// numbers however the tiles are scheduled (an atomic counter numbered them
// in the order the work-groups ran, and the reinsertion, which breaks ties
// of gain by node number, then made different trees from build to build).
inline int first_node_of_tile(int num_tris, int count, int start, int kept_before, int straddling)
{
    return 2 * num_tris - count + (start - kept_before) + straddling;
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
    // New nodes: numbered in the order of their pairs' first places (first_node_of_tile).
    uint merges;
    const uint my_merge = group_exclusive_scan(partner >= 0 ? 1u : 0u, scratch, &merges);
    uint kept_in_tile;
    const uint rank = group_exclusive_scan(kept ? 1u : 0u, scratch, &kept_in_tile);
    if (lid == 0) {
        tile_offset = tile_exclusive_prefix(status, tile, kept_in_tile);
        int straddling = 0;             // pairs from the places before the tile into it
        for (int q = max(start - PLOC_RADIUS, 0); q < start; ++q) {
            const int j = nearest[q - start + PLOC_RADIUS];
            straddling += j >= start && nearest[j - start + PLOC_RADIUS] == q;
        }
        node_base = first_node_of_tile(num_tris, count, start, (int)tile_offset, straddling);
        if (tile == tiles - 1) {      // the last tile knows the total
            const int left = (int)(tile_offset + kept_in_tile);
            state[CLUSTERS_BEFORE(iteration + 1)] = left;
            state[STATE_NEXT_NODE] = first_node_of_tile(num_tris, left, 0, 0, 0);
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
    if (lid == 0)
        hand_over_to_top(state, count, next_node, iteration, first_iteration);
}

// One work-group, after ploc_tail (with the same buffers): the SAH top over
// the clusters it left (build_top.cl; each of its levels counts as an
// iteration).  Writes the node counter, the iteration total and the last
// count to the state, unless nothing merged since ploc_merge or
// ploc_compact wrote them.
__kernel __attribute__((reqd_work_group_size(TOP_GROUP, 1, 1)))
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

#endif
