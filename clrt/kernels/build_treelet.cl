// Treelet restructuring (Karras & Aila 2013) of the PLOC tree: better trees
// for the same triangles, before the rows are emitted.
//
// PLOC merges only clusters that are near in the Morton order, so some of its
// subtrees are grouped worse than a full SAH sweep would group them (SAH cost
// 8-11 % above the host SAH builder's on the reference meshes).  A treelet is
// a node and TREELET_LEAVES of its descendants: starting from the node's two
// children, the treelet leaf with the largest surface area is replaced by its
// two children until there are TREELET_LEAVES of them.  Every binary tree
// over those leaves is a valid replacement of the treelet's inner nodes; the
// cheapest by the SAH is found by dynamic programming over the 2^n subsets
// of leaves (cost of a subset: its node's area times C_TRAVERSAL plus the best
// split into two subsets; or, with at most leaf_size triangles, one leaf --
// the rule refresh_node applies), and the treelet is rebuilt if that is cheaper.
//
// Bottom-up, so that a treelet's leaves are final: one launch per PLOC
// iteration, over the nodes that iteration made.  Those are consecutive
// (nodes are numbered as they are made), their subtrees are disjoint, and
// every node below them was made -- and restructured -- by an earlier
// launch.  (Tried first: climbing from every triangle with a counter per
// node, in one launch; one launch per tree height; restructuring inside
// make_node.  The first two left most work-items of a SIMD group idle, since
// the nodes of one height are scattered; the third put thousands of treelets
// on ploc_tail's single work-group.  On the H200 they cost 7, 2 and 7 ms for
// bunny00.)
#ifndef CLRT_BUILD_TREELET_CL
#define CLRT_BUILD_TREELET_CL

#include "layouts.h"

#if !defined(TREELET_LEAVES) || !defined(TREELET_GROUP)
#error "build with -DTREELET_LEAVES=<leaves of a treelet, 3..8; 0: none> and -DTREELET_GROUP=<work-items per treelet>"
#endif
#if !defined(C_TRAVERSAL) || !defined(C_INTERSECT)
#error "build with the SAH constants C_TRAVERSAL and C_INTERSECT of clrt/accel/topdown.py"
#endif

// Half the surface area of a box, as topdown.py's surface_area (only ratios matter).
inline float half_area(float3 lo, float3 hi)
{
    const float3 d = hi - lo;
    const float a = d.x * d.y + d.y * d.z + d.z * d.x;
    return isnan(a) ? INFINITY : a;           // inf * 0 of huge, flat boxes
}

inline int left_of(const global BuildNode* nodes, int n)
{
    return as_int(nodes[n].lo.w);
}

inline int right_of(const global BuildNode* nodes, int n)
{
    return as_int(nodes[n].hi.w);
}

inline int height_of(const global int* heights, int n, int num_tris)
{
    return n < num_tris ? 1 : heights[n - num_tris];
}

// Box, count, cost, rows and height of inner node n from its children, whose
// references it holds.  The SAH decides whether the subtree is emitted as one
// leaf: with at most leaf_size triangles and a leaf cost (C_INTERSECT * count
// * area) no higher than keeping the node (C_TRAVERSAL * area plus the
// children's best costs) -- the rule of the host's SAH builder (sah.py: split
// only when strictly cheaper).  The height (nodes on the longest path down; a
// triangle has 1) bounds the emit pass's pointer jumps.  PLOC's make_node and
// the treelet restructuring both make nodes through it.
inline void refresh_node(global BuildNode* nodes, global int* heights, int n, int num_tris, uint leaf_size)
{
    const int l = left_of(nodes, n), r = right_of(nodes, n);
    const BuildNode a = nodes[l], b = nodes[r];
    const float3 lo = fmin(a.lo.xyz, b.lo.xyz), hi = fmax(a.hi.xyz, b.hi.xyz);
    const float area = half_area(lo, hi);
    const int count = a.count + b.count;
    float cost = C_TRAVERSAL * area + a.cost + b.cost;
    int rows = 1 + a.rows + b.rows;
    const float leaf_cost = C_INTERSECT * (float)count * area;
    if (count <= (int)leaf_size && leaf_cost <= cost) {
        cost = leaf_cost;
        rows = 0;
    }
    nodes[n].lo.xyz = lo;
    nodes[n].hi.xyz = hi;
    nodes[n].count = count;
    nodes[n].cost = cost;
    nodes[n].rows = rows;
    heights[n - num_tris] = 1 + max(height_of(heights, l, num_tris), height_of(heights, r, num_tris));
}

#if TREELET_LEAVES > 0
#define TREELET_SUBSETS (1 << TREELET_LEAVES)

// The treelet below inner node `root`: its leaves (leaf[0 .. return value))
// and inner nodes (inner[0] = root, then the opened ones, one fewer than
// leaves).  Opens the leaf of largest area until TREELET_LEAVES.
inline int form_treelet(const global BuildNode* nodes, int root, int num_tris, local int* leaf, local int* inner)
{
    int leaves = 2, inners = 1;
    leaf[0] = left_of(nodes, root);
    leaf[1] = right_of(nodes, root);
    inner[0] = root;
    while (leaves < TREELET_LEAVES) {
        int pick = -1;
        float largest = -1.0f;
        for (int k = 0; k < leaves; ++k) {
            if (leaf[k] < num_tris)
                continue;                    // a triangle: nothing to open
            const float a = half_area(nodes[leaf[k]].lo.xyz, nodes[leaf[k]].hi.xyz);
            if (a > largest) {
                largest = a;
                pick = k;
            }
        }
        if (pick < 0)
            break;
        const int opened = leaf[pick];
        inner[inners++] = opened;
        leaf[pick] = left_of(nodes, opened);
        leaf[leaves++] = right_of(nodes, opened);
    }
    return leaves;
}

// Give the treelet the shape `split` describes (for each subset of leaves,
// the part holding its lowest leaf), reusing its inner nodes in pre-order,
// then refresh them children first.
inline void rebuild_treelet(global BuildNode* nodes, global int* heights, int full, const local uchar* split,
                            const local int* leaf, const local int* inner, int num_tris, uint leaf_size)
{
    int order_node[TREELET_LEAVES - 1];
    int stack_subset[TREELET_LEAVES], stack_node[TREELET_LEAVES];
    int sp = 0, used = 0, made = 0;
    stack_subset[sp] = full;
    stack_node[sp++] = inner[used++];
    while (sp > 0) {
        --sp;
        const int s = stack_subset[sp], n = stack_node[sp];
        order_node[made++] = n;
        int child[2];
        for (int side = 0; side < 2; ++side) {
            const int p = side == 0 ? split[s] : s ^ split[s];
            if (p == (p & -p)) {
                child[side] = leaf[31 - clz(p)];
            } else {
                child[side] = inner[used++];
                stack_subset[sp] = p;
                stack_node[sp++] = child[side];
            }
            nodes[child[side]].parent = n;
        }
        nodes[n].lo.w = as_float(child[0]);
        nodes[n].hi.w = as_float(child[1]);
    }
    for (int k = made - 1; k >= 0; --k)
        refresh_node(nodes, heights, order_node[k], num_tris, leaf_size);
}

#endif

// One work-group of TREELET_GROUP work-items per node made in one PLOC
// iteration (nodes first, first + 1, ...; one group each).  The first
// work-item refreshes the node (its children's treelets may have become
// cheaper) and forms its treelet; then the group solves the dynamic program
// together: the subsets of one size at a time, in parallel -- a subset's
// parts are all smaller -- with a barrier between sizes, so that the longest
// chain is about 130 steps instead of one work-item's 1,100.  (One work-item
// per treelet, the first version, took 3.6 ms for bunny00 on the H200.)
// Subtrees of at most leaf_size triangles are left as they are: one leaf or a
// few, however shaped.  (With TREELET_LEAVES 0 the host does not launch it.)
__kernel __attribute__((reqd_work_group_size(TREELET_GROUP, 1, 1)))
void treelet_restructure(global BuildNode* nodes, global int* heights, const int num_tris, const int first,
                         const uint leaf_size)
{
#if TREELET_LEAVES > 0
    local int leaf[TREELET_LEAVES], inner[TREELET_LEAVES - 1];
    local int leaves;
    local float area[TREELET_SUBSETS], best[TREELET_SUBSETS];
    local int count[TREELET_SUBSETS];
    local uchar split[TREELET_SUBSETS];    // the part holding the subset's lowest leaf
    const int lid = get_local_id(0);
    const int root = first + get_group_id(0);
    if (lid == 0) {
        refresh_node(nodes, heights, root, num_tris, leaf_size);
        leaves = nodes[root].count > (int)leaf_size ? form_treelet(nodes, root, num_tris, leaf, inner) : 0;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    const int n = leaves;                  // the same in every work-item
    const int full = (1 << n) - 1;
    if (n >= 3) {                          // (fewer: one shape only)
        for (int s = lid + 1; s <= full; s += TREELET_GROUP) {
            float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
            int c = 0;
            for (int k = 0; k < n; ++k)
                if (s & (1 << k)) {
                    lo = fmin(lo, nodes[leaf[k]].lo.xyz);
                    hi = fmax(hi, nodes[leaf[k]].hi.xyz);
                    c += nodes[leaf[k]].count;
                }
            area[s] = half_area(lo, hi);
            count[s] = c;
            if (s == (s & -s)) {
                best[s] = nodes[leaf[31 - clz(s)]].cost;
                split[s] = 0;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        for (int size = 2; size <= n; ++size) {
            for (int s = lid + 1; s <= full; s += TREELET_GROUP) {
                if (popcount(s) != size)
                    continue;
                const int low = s & -s, rest = s ^ low;
                float cheapest = INFINITY;
                int cut = low;
                // Parts p holding the lowest leaf, p != s: each split counted
                // once (p = low plus every proper part q of the rest, q = 0 included).
                for (int q = (rest - 1) & rest; ; q = (q - 1) & rest) {
                    const int p = low | q;
                    const float c = best[p] + best[s ^ p];
                    if (c < cheapest) {
                        cheapest = c;
                        cut = p;
                    }
                    if (q == 0)
                        break;
                }
                float cost = C_TRAVERSAL * area[s] + cheapest;
                const float leaf_cost = C_INTERSECT * (float)count[s] * area[s];
                if (count[s] <= (int)leaf_size && leaf_cost <= cost)
                    cost = leaf_cost;      // its node will be emitted as a leaf, however split
                best[s] = cost;
                split[s] = (uchar)cut;
            }
            barrier(CLK_LOCAL_MEM_FENCE);
        }
        // Rebuild only when clearly cheaper (the same tree costs the same, up to rounding).
        if (lid == 0 && best[full] < nodes[root].cost * (1.0f - 1e-5f))
            rebuild_treelet(nodes, heights, full, split, leaf, inner, num_tris, leaf_size);
    }
#endif
}

#endif
