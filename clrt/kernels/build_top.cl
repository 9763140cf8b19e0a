// The top of the device builder's tree by the surface area heuristic: once
// PLOC is down to SAH_TOP_CLUSTERS clusters, one work-group splits them top
// down, as the host SAH builder splits triangles, and makes the nodes bottom
// up (make_node, so the numbers and leaf choices are PLOC's).
//
// Why: PLOC's last merges pair clusters by the least union area, which knows
// nothing of how many triangles each holds, and a few hundred large clusters
// grouped that way make the levels every ray walks.  Measured on the H200
// (docs/benchmark-log.md, session 12): the host SAH builder's tree over the
// device tree's top few hundred subtrees took 5-7 % off random and diffuse
// rays; the same top by PLOC with every cluster searched recovered less than
// half of that.
//
// Every split is exact: on each axis, each cluster ranks the clusters of its
// segment by box centre (ties by place), and evaluates the split after its
// own rank -- the union boxes of the clusters ranked up to it and after it,
// weighted by their triangles:
//     cost = A(left) N(left) + A(right) N(right)      (A: half area)
// Ranking is O(n) per cluster and axis (one task each), the union boxes come
// from one sweep per segment and axis in rank order, and one set of loops
// serves every segment of a level at once.  The segment takes its
// least cost (ties: the more even split, then the lower axis, then the lower
// rank, so identical boxes halve instead of peeling off one at a time), and
// its clusters move to places in the chosen axis's rank order, which puts
// the left ones first: every segment stays a contiguous range of places.
//
// A split is named by its middle place m (the first place on the right):
// the segments of a tree over places 0..n-1 have distinct middles, 1..n-1.
// The nodes are made level by level from the deepest, so children exist
// before their parents and the root is the last node, as PLOC leaves it.
// The tree depends only on the clusters, not on the work-group's size.
#ifndef CLRT_BUILD_TOP_CL
#define CLRT_BUILD_TOP_CL

#include "layouts.h"

#if !defined(SAH_TOP_CLUSTERS) || !defined(TOP_GROUP)
#error "build with -DSAH_TOP_CLUSTERS=<clusters PLOC leaves to the SAH top; 1: none> and -DTOP_GROUP=<its work-items>"
#endif
#define TOP_PLACES ((SAH_TOP_CLUSTERS + TOP_GROUP - 1) / TOP_GROUP)   // places a work-item takes

// Per place (cluster), per axis and rank, and per split middle; local memory
// of ploc_top (about 110 bytes a cluster).
typedef struct {
    float4 lo[SAH_TOP_CLUSTERS];      // the cluster at each place (BuildCluster.lo: w its node)
    float4 hi[SAH_TOP_CLUSTERS];
    float weight[SAH_TOP_CLUSTERS];   // its triangles
    ushort first[SAH_TOP_CLUSTERS];   // its segment: places first..end-1
    ushort end[SAH_TOP_CLUSTERS];
    ushort parent[SAH_TOP_CLUSTERS];  // middle of the split that made its segment (0: the root segment)
    uchar side[SAH_TOP_CLUSTERS];     // 0: that split's left, 1: its right
    ushort rank[3][SAH_TOP_CLUSTERS]; // per axis: its rank in its segment
    ushort order[3][SAH_TOP_CLUSTERS];   // per axis, at first + rank: the place of that rank
    // per axis, at first + rank: the split after that rank -- the left side's
    // half area and triangles, the right side's product of the two
    float left_area[3][SAH_TOP_CLUSTERS], left_weight[3][SAH_TOP_CLUSTERS];
    float right_cost[3][SAH_TOP_CLUSTERS];
    float cost[SAH_TOP_CLUSTERS];     // per place: the best split after its own rank, and on which axis
    uchar axis[SAH_TOP_CLUSTERS];
    ushort pick[SAH_TOP_CLUSTERS];    // per segment, at its first place: the place whose split it takes
    ushort split_first[SAH_TOP_CLUSTERS], split_end[SAH_TOP_CLUSTERS];   // per middle: its segment
    ushort split_level[SAH_TOP_CLUSTERS];
    ushort child[2][SAH_TOP_CLUSTERS];  // per middle: the middles of its inner children
    // per place: where its cluster moves, and the segment it moves into, read
    // before any cluster moves (a work-item may move several)
    ushort to[SAH_TOP_CLUSTERS], middle[SAH_TOP_CLUSTERS];
    int more;
} TopScratch;

// Lexicographic order of candidate splits: cost, then imbalance, axis, rank.
inline bool better_split(float cost, int imbalance, int axis, int rank,
                         float best_cost, int best_imbalance, int best_axis, int best_rank)
{
    if (cost != best_cost)
        return cost < best_cost;
    if (imbalance != best_imbalance)
        return imbalance < best_imbalance;
    return axis != best_axis ? axis < best_axis : rank < best_rank;
}

inline float centre_key(float4 lo, float4 hi, int axis)
{
    return axis == 0 ? lo.x + hi.x : axis == 1 ? lo.y + hi.y : lo.z + hi.z;
}

// All work-items of the group: the tree over `clusters` (count of them, at
// most SAH_TOP_CLUSTERS), its count - 1 nodes made at next_node, next_node +
// 1, ..., the root last; `made` (global, count entries) holds the clusters of
// the new nodes on the way.  Returns the number of levels made (0 when count
// < 2).  Each work-item takes places lid, lid + group, ...: on a GPU one
// place each, on a CPU (TOP_GROUP 1) all of them in plain loops, which PoCL
// compiles several times faster than a group's barriers (0.74 s of a cold
// bunny00 render's 4.7 s of compiling).
inline int sah_top(const global BuildCluster* clusters, int count, global BuildCluster* made,
                   global BuildNode* nodes, global int* heights, int num_tris, int next_node, uint leaf_size,
                   local TopScratch* s)
{
    const int lid = get_local_id(0), group = get_local_size(0);
    if (count < 2)
        return 0;
    for (int p = lid; p < count; p += group) {
        s->lo[p] = clusters[p].lo;
        s->hi[p] = clusters[p].hi;
        s->weight[p] = (float)nodes[as_int(clusters[p].lo.w)].count;
        s->first[p] = 0;
        s->end[p] = (ushort)count;
        s->parent[p] = 0;
        s->side[p] = 0;
    }
    if (lid == 0)
        s->more = 1;
    barrier(CLK_LOCAL_MEM_FENCE);

    int levels = 0;
    while (s->more) {                 // the same in every work-item
        // 1. Every cluster's rank in its segment on each axis, and the place
        // of each rank: one task per axis and place.
        for (int task = lid; task < 3 * count; task += group) {
            const int a = task / count, c = task - a * count;
            const int first = s->first[c], end = s->end[c];
            if (end - first < 2)
                continue;
            const float key = centre_key(s->lo[c], s->hi[c], a);
            int rank = 0;
            for (int q = first; q < end; ++q) {
                const float other = centre_key(s->lo[q], s->hi[q], a);
                rank += other < key || (other == key && q < c);
            }
            s->rank[a][c] = (ushort)rank;
            s->order[a][first + rank] = (ushort)c;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        // 2. Each segment's sweeps in rank order, one task per axis and
        // segment (its first place): the boxes and triangles on the left and
        // on the right of every split.
        for (int task = lid; task < 3 * count; task += group) {
            const int a = task / count, first = task - a * count;
            const int end = s->end[first];
            if (s->first[first] != first || end - first < 2)
                continue;
            float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
            float weight = 0.0f;
            for (int r = first; r < end - 1; ++r) {
                const int q = s->order[a][r];
                lo = fmin(lo, s->lo[q].xyz);
                hi = fmax(hi, s->hi[q].xyz);
                weight += s->weight[q];
                s->left_area[a][r] = half_area(lo, hi);
                s->left_weight[a][r] = weight;
            }
            lo = (float3)(INFINITY);
            hi = (float3)(-INFINITY);
            weight = 0.0f;
            for (int r = end - 1; r > first; --r) {
                const int q = s->order[a][r];
                lo = fmin(lo, s->lo[q].xyz);
                hi = fmax(hi, s->hi[q].xyz);
                weight += s->weight[q];
                s->right_cost[a][r - 1] = half_area(lo, hi) * weight;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        // 3. Each cluster's best split (after its own rank) over the axes.
        for (int p = lid; p < count; p += group) {
            const int first = s->first[p], n = s->end[p] - first;
            if (n < 2)
                continue;
            float best = INFINITY;
            int best_axis = 0, best_imbalance = INT_MAX, best_rank = 0;
            for (int a = 0; a < 3; ++a) {
                const int mine = s->rank[a][p];
                if (mine == n - 1)
                    continue;                 // nothing on the right
                const int r = first + mine;
                // fma: the same rounding on every device (no compiler may fuse it otherwise)
                const float cost = fma(s->left_area[a][r], s->left_weight[a][r], s->right_cost[a][r]);
                const int imbalance = abs(2 * (mine + 1) - n);
                if (better_split(cost, imbalance, a, mine, best, best_imbalance, best_axis, best_rank)) {
                    best = cost;
                    best_axis = a;
                    best_imbalance = imbalance;
                    best_rank = mine;
                }
            }
            s->cost[p] = best;
            s->axis[p] = (uchar)best_axis;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        // 4. Each segment's least split, found by its first place.  (A
        // cluster last on every axis has no split and is skipped; the first
        // on axis 0 always has one, if only at an infinite cost.)
        for (int first = lid; first < count; first += group) {
            const int end = s->end[first], n = end - first;
            if (s->first[first] != first || n < 2)
                continue;
            int pick = -1;
            for (int q = first; q < end; ++q) {
                const int a = s->axis[q], r = s->rank[a][q];
                if (r == n - 1)
                    continue;
                if (pick < 0)
                    pick = q;
                const int b = s->axis[pick];
                if (better_split(s->cost[q], abs(2 * (r + 1) - n), a, r,
                                 s->cost[pick], abs(2 * (s->rank[b][pick] + 1) - n), b, s->rank[b][pick]))
                    pick = q;
            }
            s->pick[first] = (ushort)pick;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        // 5. Where each cluster goes: its rank on the chosen axis puts the
        // left side first; and each split recorded by its segment's first
        // place.
        for (int p = lid; p < count; p += group) {
            const int first = s->first[p], end = s->end[p];
            if (end - first < 2)
                continue;
            const int pick = s->pick[first];
            const int axis = s->axis[pick], split_rank = s->rank[axis][pick];
            const int middle = first + split_rank + 1;
            s->to[p] = (ushort)(first + s->rank[axis][p]);
            s->middle[p] = (ushort)middle;
            if (p == first) {
                s->split_first[middle] = (ushort)first;
                s->split_end[middle] = (ushort)end;
                s->split_level[middle] = (ushort)levels;
                if (s->parent[p])
                    s->child[s->side[p]][s->parent[p]] = (ushort)middle;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        // 6. The clusters moved, each with its new segment (read first, then
        // written, since places are permuted across work-items).
        float4 lo[TOP_PLACES], hi[TOP_PLACES];
        float weight[TOP_PLACES];
        int to[TOP_PLACES], first_of[TOP_PLACES], end_of[TOP_PLACES], middle_of[TOP_PLACES];
        for (int k = 0, p = lid; p < count; ++k, p += group) {
            to[k] = -1;
            if (s->end[p] - s->first[p] < 2)
                continue;
            lo[k] = s->lo[p];
            hi[k] = s->hi[p];
            weight[k] = s->weight[p];
            to[k] = s->to[p];
            middle_of[k] = s->middle[p];
            first_of[k] = s->first[p];
            end_of[k] = s->end[p];
        }
        if (lid == 0)
            s->more = 0;
        barrier(CLK_LOCAL_MEM_FENCE);
        for (int k = 0, p = lid; p < count; ++k, p += group) {
            if (to[k] < 0)
                continue;
            const int place = to[k], middle = middle_of[k], side = place >= middle;
            const int new_first = side ? middle : first_of[k], new_end = side ? end_of[k] : middle;
            s->lo[place] = lo[k];
            s->hi[place] = hi[k];
            s->weight[place] = weight[k];
            s->first[place] = (ushort)new_first;
            s->end[place] = (ushort)new_end;
            s->parent[place] = (ushort)middle;
            s->side[place] = (uchar)side;
            if (new_end - new_first >= 2)
                s->more = 1;
        }
        ++levels;
        barrier(CLK_LOCAL_MEM_FENCE);
    }

    // The nodes, deepest level first; within a level in the order of their
    // middles.  A split is made by the work-item of its middle, as node
    // next_node + (splits of deeper levels) + (splits of its level before it).
    for (int level = levels - 1; level >= 0; --level) {
        for (int m = lid; m < count; m += group) {
            if (m == 0 || s->split_level[m] != level)    // place 0 is no middle
                continue;
            int index = next_node;
            for (int q = 1; q < count; ++q) {
                const int other = s->split_level[q];
                index += other > level || (other == level && q < m);
            }
            const int first = s->split_first[m], end = s->split_end[m];
            BuildCluster a, b;
            if (m - first == 1) {
                a.lo = s->lo[first];
                a.hi = s->hi[first];
            } else {
                a = made[s->child[0][m]];
            }
            if (end - m == 1) {
                b.lo = s->lo[m];
                b.hi = s->hi[m];
            } else {
                b = made[s->child[1][m]];
            }
            made[m] = make_node(nodes, heights, num_tris, index, a, b, leaf_size);
        }
        barrier(CLK_GLOBAL_MEM_FENCE | CLK_LOCAL_MEM_FENCE);   // this level's nodes before their parents
    }
    return levels;
}

#endif
