// PLOC up a linear BVH, in one launch (H-PLOC: Benthin, Meister, Barczak,
// Parikh, Sheng and Kensler, "H-PLOC: Hierarchical Parallel Locally-Ordered
// Clustering for Bounding Volume Hierarchy Construction", HPG 2024), on GPUs
// for builds with the SAH partition (build_partition.cl's segments).
//
// Why: ploc_merge (build_ploc.cl) is one launch per iteration over every
// cluster left, about 46 launches for 10M triangles and 11 ms of the H200's
// 22 ms build, most of it the first iterations' passes over millions of
// clusters that merge a fifth of them.  Here every merge is decided among at
// most HIERARCHY_GROUP clusters that lie together in the Morton order: the
// sorted keys' linear BVH (Karras 2012) is climbed from the leaves, and a
// node of more than HIERARCHY_KEEP triangles gathers its two children's
// clusters (at most HIERARCHY_KEEP each) and merges them by PLOC's rule --
// nearest neighbour by merged area among PLOC_RADIUS on each side,
// mutual pairs merge, ties by ploc_merge's pair hash -- until at most
// HIERARCHY_KEEP are left; a whole segment's node merges down to one cluster,
// and ploc_top makes the tree above the segments by the SAH, as after PLOC.
//
// The climb (Apetrei 2014, "Fast and simple agglomerative LBVH
// construction"): every work-item starts at its leaf; a node's parent is on
// the side whose neighbouring key differs in a lower bit, and the two
// children meet at the parent's split through one atomic exchange of their
// far ends, `bounds[split]`: the first to arrive stops, the second goes on
// with the parent's range.  A segment's keys share their top SEGMENT_BITS, so
// every segment is one subtree.  No work-item waits for another: the launch
// cannot stall, however the work-groups are scheduled.
//
// A team is HIERARCHY_GROUP work-items (a warp on NVIDIA GPUs, whose
// work-groups hold HIERARCHY_WARPS teams; elsewhere a work-group is one
// team): the nodes its work-items reach in one step of the climb are merged
// one after the other by the whole team, each work-item one cluster.
//
// Where things lie.  A node's clusters are at its first places in
// `clusters` (the leaves' own places until then), the valid ones first (a
// node of lo.w -1 ends them); a node of at most HIERARCHY_KEEP triangles is
// never merged and holds its leaves.  The nodes made: every range of places
// [first, last] of the segment of rank j (its place among the segments that
// hold triangles, segment_ranks) owns BuildNode numbers num_tris + first - j
// .. num_tris + last - 1 - j (one per inner node of the linear BVH under it:
// its left child's, its own split's, its right child's), so the numbers do
// not depend on the order the work-groups run in, and the segments' nodes
// fill num_tris .. 2 num_tris - 1 - segments, leaving ploc_top the last
// segments - 1 (the root 2 num_tris - 2, as after PLOC).  A merged node with
// c clusters left has c - 1 of its numbers unused, listed at `spare_numbers`
// [first ..]; its parent takes numbers from the left child's list, its own
// split's, then the right child's, in that order, one per pair merged.
#ifndef CLRT_BUILD_HIERARCHY_CL
#define CLRT_BUILD_HIERARCHY_CL

#include "layouts.h"
#include "fences.cl"
#include "build_state.cl"
#include "build_partition.cl"
#include "build_ploc.cl"
#include "build_scan.cl"

#if !defined(HIERARCHY_GROUP) || !defined(HIERARCHY_WARPS)
#error "build with -DHIERARCHY_GROUP=<work-items that merge together> and -DHIERARCHY_WARPS=<teams a work-group>"
#endif
#if HIERARCHY_GROUP != 32
#error "a team's ballot holds one bit for each of its work-items: 32"
#endif

#define HIERARCHY_KEEP (HIERARCHY_GROUP / 2)    // clusters a node keeps (each child brings at most this many)
#define TOP_SEGMENTS (1 << SEGMENT_BITS)        // segment_ranks' table, one entry a segment
#define NO_CLUSTER (-1)                         // lo.w of a place past a node's clusters

// The HIERARCHY_GROUP work-items that merge together, and their
// synchronisation.  On NVIDIA's GPUs (-DHIERARCHY_WARP_VOTE) they are a warp:
// a PTX vote is their ballot and `bar.warp.sync` their barrier (which also
// orders their memory accesses), so the HIERARCHY_WARPS warps of a
// work-group go their own ways -- a work-group of one warp would leave half
// an SM's warps unused (32 work-groups an SM at most).  Elsewhere a
// work-group is one set of 32 with barriers, and a ballot reads every
// work-item's flags from local memory.  (A local word that every work-item
// ORs its bit into lost bits on PoCL 3.1.)
#ifdef HIERARCHY_WARP_VOTE
#define TEAM_SYNC() asm volatile("bar.warp.sync -1;" ::: "memory")

inline uint warp_ballot(bool p)
{
    uint r;
    asm volatile("{ .reg .pred a; setp.ne.s32 a, %1, 0; vote.sync.ballot.b32 %0, a, 0xffffffff; }"
                 : "=r"(r) : "r"((int)p) : "memory");
    return r;
}

inline void team_ballot(bool p, bool q, local uint* flags, uint lane, uint* p_bits, uint* q_bits)
{
    (void)flags;
    (void)lane;
    *p_bits = warp_ballot(p);
    *q_bits = warp_ballot(q);
}
#else
#if HIERARCHY_WARPS != 1
#error "without warp votes a work-group is one set of HIERARCHY_GROUP work-items"
#endif
#define TEAM_SYNC() barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE)

inline void team_ballot(bool p, bool q, local uint* flags, uint lane, uint* p_bits, uint* q_bits)
{
    flags[lane] = (p ? 1u : 0u) | (q ? 2u : 0u);
    barrier(CLK_LOCAL_MEM_FENCE);
    uint a = 0u, b = 0u;
    for (uint k = 0; k < HIERARCHY_GROUP; ++k) {
        const uint f = flags[k];
        a |= (f & 1u) << k;
        b |= (f >> 1) << k;
    }
    barrier(CLK_LOCAL_MEM_FENCE);      // read by all before the next call writes them
    *p_bits = a;
    *q_bits = b;
}
#endif

// Between places p and p + 1: the bits in which their keys differ, the place
// below the key (Apetrei's tie-break: equal keys differ by place).  The higher
// this, the higher up the linear BVH the two are joined.
inline ulong key_distance(const global uint* keys, int p)
{
    const ulong a = (ulong)keys[p] << 32 | (uint)p, b = (ulong)keys[p + 1] << 32 | (uint)(p + 1);
    return a ^ b;
}

inline int segment_of_place(const global uint* keys, int p)
{
    return (int)(keys[p] >> (32 - SEGMENT_BITS));
}

// Whether places [first, last] are a whole segment.
inline bool whole_segment(const global uint* keys, int n, int first, int last)
{
    const int s = segment_of_place(keys, first);
    return segment_of_place(keys, last) == s && (first == 0 || segment_of_place(keys, first - 1) != s)
           && (last == n - 1 || segment_of_place(keys, last + 1) != s);
}

// The first of the BuildNode numbers owned by the range starting at place
// `first` of the segment of rank `rank`.
inline int first_number(int num_tris, int first, int rank)
{
    return num_tris + first - rank;
}

inline uint bits_below(uint bits, uint lane)
{
    return popcount(bits & ((1u << lane) - 1u));
}

inline BuildCluster load_cluster(const volatile global BuildCluster* clusters, int p)
{
    BuildCluster c;
    c.lo = clusters[p].lo;
    c.hi = clusters[p].hi;
    return c;
}

// A team's clusters while it merges one node: each as the BuildNode that
// refresh_node would read (lo.w: the node's number, hi.w: the cluster's
// segment, as a BuildCluster's) and its height, so that a merge reads
// nothing from global memory.
typedef struct {
    BuildNode slot[HIERARCHY_GROUP];
    int height[HIERARCHY_GROUP];
    int nearest[HIERARCHY_GROUP];
    int numbers[HIERARCHY_GROUP];           // the node numbers this node may use, in order
    uint flags[HIERARCHY_GROUP];            // team_ballot's
    int task_first[HIERARCHY_GROUP], task_split[HIERARCHY_GROUP], task_last[HIERARCHY_GROUP];
} HierarchyScratch;

// The whole team merges the node of places [first, last] whose right child
// starts at `split`: its children's clusters are gathered, merged until at
// most HIERARCHY_KEEP are left (one for a whole segment: it goes to
// top[its rank]) and written back at `first`.  A new node's numbers are
// refresh_node's (join_children), from its children's in local memory.
inline void merge_node(volatile global BuildCluster* clusters, const global uint* keys,
                       const global int* ranks, volatile global int* spare_numbers, volatile global BuildNode* nodes,
                       volatile global int* heights, int num_tris, global BuildCluster* top, uint leaf_size,
                       int first, int split, int last, bool whole, uint lane, local HierarchyScratch* s)
{
    const int rank = ranks[segment_of_place(keys, first)];         // (first_number says why a rank)
    const bool right = lane >= HIERARCHY_KEEP;
    const int k = right ? lane - HIERARCHY_KEEP : lane;
    // Each child: its clusters, and the node numbers it left unused (a child
    // never merged: all those of its range).
    const int child_first = right ? split : first, child_last = right ? last : split - 1;
    const bool merged_child = child_last - child_first + 1 > HIERARCHY_KEEP;
    const int place = child_first + k;
    BuildCluster c;
    c.lo = (float4)(0.0f, 0.0f, 0.0f, as_float(NO_CLUSTER));
    c.hi = (float4)(0.0f);
    if (place <= child_last)
        c = load_cluster(clusters, place);
    const int node = as_int(c.lo.w);
    const bool valid = place <= child_last && node != NO_CLUSTER;
    BuildNode own = leaf_node(c.lo.xyz, c.hi.xyz);                 // a triangle's (init_leaves)
    int height = 1;
    if (valid && node >= num_tris) {
        own.count = nodes[node].count;
        own.cost = nodes[node].cost;
        own.rows = nodes[node].rows;
        height = heights[node - num_tris];
    }
    own.lo.w = c.lo.w;
    own.hi.w = c.hi.w;
    uint valid_bits, unused;
    team_ballot(valid, false, s->flags, lane, &valid_bits, &unused);
    const int left_count = popcount(valid_bits & ((1u << HIERARCHY_KEEP) - 1u));
    const int count0 = popcount(valid_bits);
    // Numbers: the left child's left_count - 1, the split's, the right child's.
    const int child_spare = (right ? count0 - left_count : left_count) - 1;
    if (k < child_spare)
        s->numbers[(right ? left_count : 0) + k] = merged_child ? spare_numbers[place]
                                                              : first_number(num_tris, child_first, rank) + k;
    if (lane == 0)
        s->numbers[left_count - 1] = first_number(num_tris, split - 1, rank);
    if (valid) {
        const int at = right ? left_count + k : k;
        s->slot[at] = own;
        s->height[at] = height;
    }
    TEAM_SYNC();

    const int target = whole ? 1 : HIERARCHY_KEEP;
    int left = count0, used = 0;
    while (left > target) {             // the same in every work-item
        Nearest n = {-1, INFINITY, 0u, false};
        if ((int)lane < left) {
            const float3 lo = s->slot[lane].lo.xyz, hi = s->slot[lane].hi.xyz;
            for (int o = -PLOC_RADIUS; o <= PLOC_RADIUS; ++o) {
                const int q = (int)lane + o;
                if (o != 0 && q >= 0 && q < left)
                    consider(&n, lane, q, half_area(fmin(lo, s->slot[q].lo.xyz), fmax(hi, s->slot[q].hi.xyz)));
            }
            s->nearest[lane] = n.best;
        }
        TEAM_SYNC();
        const int j = (int)lane < left ? s->nearest[lane] : -1;
        const bool mutual = j >= 0 && s->nearest[j] == (int)lane;
        const bool kept = (int)lane < left && (!mutual || (int)lane < j);
        const bool merges = mutual && (int)lane < j;
        uint kept_bits, merge_bits;
        team_ballot(kept, merges, s->flags, lane, &kept_bits, &merge_bits);
        BuildNode out;
        if (kept) {
            out = s->slot[lane];
            height = s->height[lane];
        }
        if (merges) {                   // the node over lane (left) and j (right)
            const BuildNode b = s->slot[j];
            const int index = s->numbers[used + bits_below(merge_bits, lane)];
            const int segment = as_int(out.hi.w);
            BuildNode made = join_children(&out, &b, leaf_size);
            made.lo.w = out.lo.w;                   // its children
            made.hi.w = b.lo.w;
            nodes[index] = made;
            height = 1 + max(height, s->height[j]);
            heights[index - num_tris] = height;
            nodes[as_int(out.lo.w)].parent = index;
            nodes[as_int(b.lo.w)].parent = index;
            out = made;                             // as the cluster: its number and segment
            out.lo.w = as_float(index);
            out.hi.w = as_float(segment);
        }
        TEAM_SYNC();
        if (kept) {
            const int at = bits_below(kept_bits, lane);
            s->slot[at] = out;
            s->height[at] = height;
        }
        used += popcount(merge_bits);
        left = popcount(kept_bits);
        TEAM_SYNC();
    }

    // The clusters left: a whole segment's one to the top (lane 0), else the
    // node's to its first HIERARCHY_KEEP places (it has more places than that).
    // (One branch: PoCL 5.0 asserted forming the work-group function of an
    // if / else-if here, after the loop's last barrier.)
    if (whole ? lane == 0 : lane < HIERARCHY_KEEP) {
        volatile global BuildCluster* to = whole ? (volatile global BuildCluster*)(top + rank)
                                                 : clusters + first + lane;
        const bool kept = (int)lane < left;
        to->lo = kept ? s->slot[lane].lo : (float4)(0.0f, 0.0f, 0.0f, as_float(NO_CLUSTER));
        to->hi = kept ? s->slot[lane].hi : (float4)(0.0f);
        if (!whole && (int)lane < left - 1)
            spare_numbers[first + lane] = s->numbers[used + lane];
    }
    // Everything written before the node's work-item passes its range on
    // (the exchange in ploc_hierarchy's climb) -- each writer's own fence,
    // ordered before that work-item's exchange by the team's sync --, and
    // before local memory is reused.
    release_fence();
    TEAM_SYNC();
}

// bounds: num_tris - 1 ints for the climb's exchanges (-1: nobody yet).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void hierarchy_clear(global int* bounds, const uint num_tris)
{
    const uint i = get_global_id(0);
    if (i + 1 < num_tris)
        bounds[i] = -1;
}

// One work-group of TOP_SEGMENTS work-items: ranks[s], the rank of segment s
// among the segments that hold triangles (found by a binary search of the
// sorted keys), and ranks[TOP_SEGMENTS] their count.  The partition makes
// none empty (each holds the samples that made it), so the ranks are the
// segments themselves; the numbering does not rest on it.
__kernel __attribute__((reqd_work_group_size(TOP_SEGMENTS, 1, 1)))
void segment_ranks(const global uint* keys, const uint num_tris, global int* ranks)
{
    local uint scratch[TOP_SEGMENTS];
    const uint s = get_local_id(0);
    // The first place whose segment is s or later.
    uint lo = 0, hi = num_tris;
    while (lo < hi) {
        const uint mid = lo + (hi - lo) / 2;
        if ((keys[mid] >> (32 - SEGMENT_BITS)) < s)
            lo = mid + 1;
        else
            hi = mid;
    }
    const bool held = lo < num_tris && (keys[lo] >> (32 - SEGMENT_BITS)) == s;
    uint total;
    const uint rank = group_exclusive_scan(held ? 1u : 0u, scratch, &total);
    ranks[s] = (int)rank;
    if (s == 0)
        ranks[TOP_SEGMENTS] = (int)total;
}

// Every merge of PLOC below the segments, in one launch of one work-item per
// triangle (after init_leaves; keys: the sorted keys, segment above Morton
// code; ranks: segment_ranks').  Leaves each segment's one cluster at
// top[its rank].
__kernel __attribute__((reqd_work_group_size(HIERARCHY_GROUP * HIERARCHY_WARPS, 1, 1)))
void ploc_hierarchy(volatile global BuildCluster* clusters, const global uint* keys, const global int* ranks,
                    global int* bounds, volatile global int* spare_numbers, volatile global BuildNode* nodes,
                    volatile global int* heights, const int num_tris, global BuildCluster* top, const uint leaf_size)
{
    local HierarchyScratch scratch[HIERARCHY_WARPS];
    const uint lane = get_local_id(0) % HIERARCHY_GROUP;
    local HierarchyScratch* s = scratch + get_local_id(0) / HIERARCHY_GROUP;
    const int n = num_tris, leaf = get_global_id(0);
    int first = leaf, last = leaf, split = leaf;
    bool active = leaf < n;
    if (active && whole_segment(keys, n, leaf, leaf)) {      // a segment of one triangle
        const BuildCluster c = load_cluster(clusters, leaf);
        top[ranks[segment_of_place(keys, leaf)]] = c;
        active = false;
    }
    // (The loop tests the team's ballot at its top: PoCL 5's compiler
    // asserted on a `break` after the ballot's barriers.)
    uint alive = 1u;
    while (alive) {                      // the same in every work-item of the team
        bool whole = false, merge = false;
        if (active) {
            // Up one level: to the parent on the side of the nearer key.
            const bool left_child = first == 0
                                    || (last != n - 1 && key_distance(keys, last) < key_distance(keys, first - 1));
            const int at = left_child ? last : first - 1;
            const int other = atomic_xchg(bounds + at, left_child ? first : last);
            if (other < 0) {
                active = false;          // the sibling's work-item goes on
            } else {
                acquire_fence();    // the sibling's writes, read after its exchange
                split = at + 1;
                if (left_child)
                    last = other;
                else
                    first = other;
                whole = whole_segment(keys, n, first, last);
                merge = whole || last - first + 1 > HIERARCHY_KEEP;
                active = !whole;         // a whole segment ends as one cluster, at the top
            }
        }
        s->task_first[lane] = first;
        s->task_split[lane] = split;
        s->task_last[lane] = whole ? -1 - last : last;
        uint tasks;
        team_ballot(merge, active, s->flags, lane, &tasks, &alive);
        TEAM_SYNC();                     // (the tasks' ranges)
        while (tasks) {
            const int t = 31 - clz(tasks & (0u - tasks));
            tasks &= tasks - 1u;
            const int t_last = s->task_last[t];
            merge_node(clusters, keys, ranks, spare_numbers, nodes, heights, n, top, leaf_size, s->task_first[t],
                       s->task_split[t], t_last < 0 ? -1 - t_last : t_last, t_last < 0, lane, s);
        }
    }
}

// One work-item after ploc_hierarchy: what ploc_top reads at STATE_TAIL
// (build_state.cl) -- the segments' clusters, in `top` in rank order, their
// count and the node counter (ploc_hierarchy made num_tris - count nodes).
__kernel void hierarchy_top(const global int* ranks, const int num_tris, global int* state)
{
    const int count = ranks[TOP_SEGMENTS];
    state[STATE_TAIL + TAIL_COUNT] = count;
    state[STATE_TAIL + TAIL_NEXT_NODE] = 2 * num_tris - count;
    state[STATE_TAIL + TAIL_ITERATIONS] = 0;
    state[STATE_TAIL + TAIL_FLAGS] = TAIL_MERGED;
}

#endif
