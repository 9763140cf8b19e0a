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
// the rule make_node applies), and the treelet is rebuilt if that is cheaper.
//
// Bottom-up, so that a treelet's leaves are final: one work-item per
// triangle climbs towards the root; at each node the first of its two
// children's work-items to arrive stops, the second goes on (an atomic
// counter per node), so every node is processed once, after its whole
// subtree.  Nodes written by another work-item are read through volatile
// pointers (not from a cache that may hold an older copy), after the fence
// that comes with the counter.
//
// Each node's height (nodes on its longest path down) is kept beside it, and
// the root's goes to STATE_HEIGHT: restructuring can deepen the tree, and the
// emit pass's pointer jumping needs a bound.
#ifndef CLRT_BUILD_TREELET_CL
#define CLRT_BUILD_TREELET_CL

#include "layouts.h"
#include "build_state.cl"
#include "build_ploc.cl"

#ifndef TREELET_LEAVES
#error "build with -DTREELET_LEAVES=<leaves of a treelet, 3..8>"
#endif
#define TREELET_SUBSETS (1 << TREELET_LEAVES)

typedef volatile global BuildNode* shared_nodes;

inline float3 node_lo(shared_nodes nodes, int n)
{
    return (float3)(nodes[n].lo.x, nodes[n].lo.y, nodes[n].lo.z);
}

inline float3 node_hi(shared_nodes nodes, int n)
{
    return (float3)(nodes[n].hi.x, nodes[n].hi.y, nodes[n].hi.z);
}

inline int left_of(shared_nodes nodes, int n)
{
    return as_int(nodes[n].lo.w);
}

inline int right_of(shared_nodes nodes, int n)
{
    return as_int(nodes[n].hi.w);
}

// Box, count, cost, rows and height of inner node n from its children (the
// SAH leaf rule of make_node).
inline void refresh_node(shared_nodes nodes, global int* heights, int n, uint num_tris, uint leaf_size)
{
    const int l = left_of(nodes, n), r = right_of(nodes, n);
    const float3 lo = fmin(node_lo(nodes, l), node_lo(nodes, r));
    const float3 hi = fmax(node_hi(nodes, l), node_hi(nodes, r));
    const float area = half_area(lo, hi);
    const int count = nodes[l].count + nodes[r].count;
    float cost = C_TRAVERSAL * area + nodes[l].cost + nodes[r].cost;
    int rows = 1 + nodes[l].rows + nodes[r].rows;
    const float leaf_cost = C_INTERSECT * (float)count * area;
    if (count <= (int)leaf_size && leaf_cost <= cost) {
        cost = leaf_cost;
        rows = 0;
    }
    nodes[n].lo.x = lo.x;
    nodes[n].lo.y = lo.y;
    nodes[n].lo.z = lo.z;
    nodes[n].hi.x = hi.x;
    nodes[n].hi.y = hi.y;
    nodes[n].hi.z = hi.z;
    nodes[n].count = count;
    nodes[n].cost = cost;
    nodes[n].rows = rows;
    const int hl = l < (int)num_tris ? 1 : heights[l - num_tris];
    const int hr = r < (int)num_tris ? 1 : heights[r - num_tris];
    heights[n - num_tris] = 1 + max(hl, hr);
}

// Restructure the treelet rooted at inner node `root` if a cheaper one exists.
inline void restructure(shared_nodes nodes, global int* heights, int root, uint num_tris, uint leaf_size)
{
    int leaf[TREELET_LEAVES];
    int inner[TREELET_LEAVES - 1];       // inner[0] = root
    int leaves = 2, inners = 1;
    leaf[0] = left_of(nodes, root);
    leaf[1] = right_of(nodes, root);
    inner[0] = root;
    while (leaves < TREELET_LEAVES) {
        int pick = -1;
        float largest = -1.0f;
        for (int k = 0; k < leaves; ++k) {
            if (leaf[k] < (int)num_tris)
                continue;                    // a triangle: nothing to open
            const float a = half_area(node_lo(nodes, leaf[k]), node_hi(nodes, leaf[k]));
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
    if (leaves < 3)
        return;                              // one shape only

    // Subset tables: area of each subset's box, its triangles, best cost.
    // (Boxes are rebuilt from the leaves per subset, not stored: private
    // arrays spill to memory, and 7 unions cost less than a spilled table.)
    float3 leaf_lo[TREELET_LEAVES], leaf_hi[TREELET_LEAVES];
    int leaf_count[TREELET_LEAVES];
    for (int k = 0; k < leaves; ++k) {
        leaf_lo[k] = node_lo(nodes, leaf[k]);
        leaf_hi[k] = node_hi(nodes, leaf[k]);
        leaf_count[k] = nodes[leaf[k]].count;
    }
    float area[TREELET_SUBSETS], best[TREELET_SUBSETS];
    int count[TREELET_SUBSETS];
    uchar split[TREELET_SUBSETS];            // the part holding the subset's lowest leaf
    const int full = (1 << leaves) - 1;
    for (int s = 1; s <= full; ++s) {
        float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
        int n = 0;
        for (int k = 0; k < leaves; ++k)
            if (s & (1 << k)) {
                lo = fmin(lo, leaf_lo[k]);
                hi = fmax(hi, leaf_hi[k]);
                n += leaf_count[k];
            }
        area[s] = half_area(lo, hi);
        count[s] = n;
    }
    // Subsets in increasing order: every proper part of s is smaller than s.
    for (int s = 1; s <= full; ++s) {
        const int low = s & -s;
        if (s == low) {
            best[s] = nodes[leaf[31 - clz(low)]].cost;
            split[s] = 0;
            continue;
        }
        float cheapest = INFINITY;
        int cut = low;
        // Parts p holding the lowest leaf, p != s: each split counted once.
        for (int p = (s - 1) & s; p > 0; p = (p - 1) & s) {
            if (!(p & low))
                continue;
            const float c = best[p] + best[s ^ p];
            if (c < cheapest) {
                cheapest = c;
                cut = p;
            }
        }
        float cost = C_TRAVERSAL * area[s] + cheapest;
        const float leaf_cost = C_INTERSECT * (float)count[s] * area[s];
        if (count[s] <= (int)leaf_size && leaf_cost <= cost)
            cost = leaf_cost;                // its node will be emitted as a leaf, however split
        best[s] = cost;
        split[s] = (uchar)cut;
    }
    // Rebuild only when clearly cheaper (the same tree costs the same, up to rounding).
    if (!(best[full] < nodes[root].cost * (1.0f - 1e-5f)))
        return;

    // Pre-order: subset -> node, taking the treelet's inner nodes in turn.
    int order_subset[TREELET_LEAVES - 1], order_node[TREELET_LEAVES - 1];
    int stack_subset[TREELET_LEAVES], stack_node[TREELET_LEAVES];
    int sp = 0, used = 0, made = 0;
    stack_subset[sp] = full;
    stack_node[sp++] = inner[used++];
    while (sp > 0) {
        --sp;
        const int s = stack_subset[sp], n = stack_node[sp];
        order_subset[made] = s;
        order_node[made++] = n;
        const int parts[2] = {split[s], s ^ split[s]};
        int child[2];
        for (int side = 0; side < 2; ++side) {
            const int p = parts[side];
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
    // Children before parents: the reverse of pre-order.
    for (int k = made - 1; k >= 0; --k)
        refresh_node(nodes, heights, order_node[k], num_tris, leaf_size);
}

// One work-item per triangle; visits: one zeroed int per inner node.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void treelet_restructure(global BuildNode* build_nodes, global int* visits, global int* heights,
                         const uint num_tris, const uint leaf_size, global int* state)
{
    const uint i = get_global_id(0);
    if (i >= num_tris)
        return;
    shared_nodes nodes = build_nodes;
    int n = nodes[i].parent;
    while (n >= 0) {
        mem_fence(CLK_GLOBAL_MEM_FENCE);     // this subtree's writes before the counter
        if (atomic_inc(visits + (n - (int)num_tris)) == 0)
            return;                          // the other child's work-item goes on
        mem_fence(CLK_GLOBAL_MEM_FENCE);
        restructure(nodes, heights, n, num_tris, leaf_size);
        refresh_node(nodes, heights, n, num_tris, leaf_size);
        const int parent = nodes[n].parent;
        if (parent < 0)
            state[STATE_HEIGHT] = heights[n - num_tris];
        n = parent;
    }
}

#endif
