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
// Bottom-up, so that a treelet's leaves are final, in one launch: one
// work-group per node with a treelet, the nodes listed by height (as PLOC
// left them, lowest first) and taken by tickets in the order the groups
// start.  A group first waits until its node's children are done (a flag
// per node, set after a fence once the node's treelet is rebuilt): they are
// lower, so their groups took earlier tickets and are running or finished,
// and the lowest unfinished node never waits -- the launch cannot stall.
// Every inner node below is then done too, and restructuring a subtree moves
// no node out of it: each node's treelet depends only on its own finished
// subtree, and the tree is the same whatever the order the groups run in.
// treelet_levels counts the nodes of each height and treelet_order lists
// the nodes by height, on the device; the work-groups take nodes until none
// are left, so the host need not know how many there are.
// (Tried first, on the H200 for bunny00: climbing from every triangle with a
// counter per node, one work-item per treelet, 9 ms; restructuring inside
// make_node, on ploc_tail's single work-group, 7 ms; one launch per PLOC
// iteration, 1.2 ms, and one per height, 0.6 ms, nearly all of it the latency
// of the launches, one after another.)
#ifndef CLRT_BUILD_TREELET_CL
#define CLRT_BUILD_TREELET_CL

#include "layouts.h"
#include "fences.cl"

#if !defined(TREELET_LEAVES) || !defined(TREELET_GROUP) || !defined(TREELET_LEVELS) \
    || !defined(TREELET_SMALL_LEAVES) || !defined(TREELET_FULL_MIN)
#error "build with -DTREELET_LEAVES=<3..8; 0: none>, -DTREELET_SMALL_LEAVES, -DTREELET_FULL_MIN, -DTREELET_GROUP=<work-items a treelet> and -DTREELET_LEVELS"
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

// Nodes and heights are read through volatile pointers: in the one-launch
// restructuring (below) a work-group reads what other work-groups wrote
// during the launch, which must come from memory, not from a cache that may
// hold an older copy.  (Elsewhere a launch boundary separates writes and
// reads; the loads only lose their first-level cache there.)
typedef volatile global BuildNode* shared_nodes;
typedef volatile global int* shared_ints;

inline int left_of(shared_nodes nodes, int n)
{
    return as_int(nodes[n].lo.w);
}

inline int right_of(shared_nodes nodes, int n)
{
    return as_int(nodes[n].hi.w);
}

inline int height_of(shared_ints heights, int n, int num_tris)
{
    return n < num_tris ? 1 : heights[n - num_tris];
}

inline BuildNode load_node(shared_nodes nodes, int n)
{
    BuildNode b;
    b.lo = nodes[n].lo;
    b.hi = nodes[n].hi;
    b.parent = nodes[n].parent;
    b.count = nodes[n].count;
    b.rows = nodes[n].rows;
    b.cost = nodes[n].cost;
    return b;
}

// The SAH's one rule for every node the builder makes (refresh_node,
// rebuild_treelet, the treelets' dynamic program): a node of `count`
// triangles and half area `area` whose cost kept as a node is *cost
// (C_TRAVERSAL * area plus its children's best costs) is emitted as one leaf
// when it has at most leaf_size triangles and a leaf cost (C_INTERSECT *
// count * area) no higher -- the rule of the host's SAH builder (sah.py: split
// only when strictly cheaper).  Then *cost becomes the leaf cost and it
// returns true.
inline bool emitted_as_leaf(float area, int count, uint leaf_size, float* cost)
{
    const float leaf_cost = C_INTERSECT * (float)count * area;
    if (count <= (int)leaf_size && leaf_cost <= *cost) {
        *cost = leaf_cost;
        return true;
    }
    return false;
}

// The box, count, cost and rows (0: emitted as a leaf, emitted_as_leaf) of
// the node over children a and b, from theirs (its children's references and
// parent are the caller's).  refresh_node and ploc_hierarchy's merges
// (build_hierarchy.cl, whose children are in local memory) make nodes by it.
inline BuildNode join_children(const BuildNode* a, const BuildNode* b, uint leaf_size)
{
    BuildNode n;
    n.lo = (float4)(fmin(a->lo.xyz, b->lo.xyz), 0.0f);
    n.hi = (float4)(fmax(a->hi.xyz, b->hi.xyz), 0.0f);
    const float area = half_area(n.lo.xyz, n.hi.xyz);
    n.count = a->count + b->count;
    n.cost = C_TRAVERSAL * area + a->cost + b->cost;
    n.rows = emitted_as_leaf(area, n.count, leaf_size, &n.cost) ? 0 : 1 + a->rows + b->rows;
    n.parent = -1;
    return n;
}

// Box, count, cost, rows and height of inner node n from its children, whose
// references it holds.  The height
// (nodes on the longest path down; a triangle has 1) bounds the emit pass's
// pointer jumps.  PLOC's make_node and the treelet restructuring both make
// nodes through it.
inline void refresh_node(shared_nodes nodes, shared_ints heights, int n, int num_tris, uint leaf_size)
{
    const int l = left_of(nodes, n), r = right_of(nodes, n);
    const BuildNode a = load_node(nodes, l), b = load_node(nodes, r);
    const BuildNode joined = join_children(&a, &b, leaf_size);
    nodes[n].lo.xyz = joined.lo.xyz;
    nodes[n].hi.xyz = joined.hi.xyz;
    nodes[n].count = joined.count;
    nodes[n].cost = joined.cost;
    nodes[n].rows = joined.rows;
    heights[n - num_tris] = 1 + max(height_of(heights, l, num_tris), height_of(heights, r, num_tris));
}

#if TREELET_LEAVES > 0
#define TREELET_SUBSETS (1 << TREELET_LEAVES)

// A treelet in local memory: its leaves (subtrees kept as they are) with the
// numbers refresh_node reads of them, and its inner nodes, whose places the
// rebuilt shape reuses.  Solving and rebuilding read only this copy: each
// leaf is read from global memory once, when the treelet is formed.
typedef struct {
    int node[TREELET_LEAVES];             // leaf k's BuildNode
    float4 lo[TREELET_LEAVES];            // its box, w: its children (as the BuildNode's)
    float4 hi[TREELET_LEAVES];
    float area[TREELET_LEAVES];           // half area; -1 for a triangle (nothing to open)
    float cost[TREELET_LEAVES];
    int count[TREELET_LEAVES], rows[TREELET_LEAVES], height[TREELET_LEAVES];
    int inner[TREELET_LEAVES - 1];        // inner[0] is the treelet's root
    int leaves;
} Treelet;

inline void load_treelet_leaf(local Treelet* t, int k, shared_nodes nodes, shared_ints heights, int n, int num_tris)
{
    const BuildNode b = load_node(nodes, n);
    t->node[k] = n;
    t->lo[k] = b.lo;
    t->hi[k] = b.hi;
    t->area[k] = n < num_tris ? -1.0f : half_area(b.lo.xyz, b.hi.xyz);
    t->cost[k] = b.cost;
    t->count[k] = b.count;
    t->rows[k] = b.rows;
    t->height[k] = height_of(heights, n, num_tris);
}

// The treelet below inner node `root`: starting from its two children, opens
// the leaf of largest area until `target` leaves (at most TREELET_LEAVES; or
// only triangles are left).
inline void form_treelet(local Treelet* t, shared_nodes nodes, shared_ints heights, int root, int num_tris,
                         int target)
{
    int leaves = 2, inners = 1;
    t->inner[0] = root;
    load_treelet_leaf(t, 0, nodes, heights, left_of(nodes, root), num_tris);
    load_treelet_leaf(t, 1, nodes, heights, right_of(nodes, root), num_tris);
    while (leaves < target) {
        int pick = -1;
        float largest = -1.0f;
        for (int k = 0; k < leaves; ++k)
            if (t->area[k] > largest) {
                largest = t->area[k];
                pick = k;
            }
        if (pick < 0)
            break;
        t->inner[inners++] = t->node[pick];
        const int left = as_int(t->lo[pick].w), right = as_int(t->hi[pick].w);
        load_treelet_leaf(t, pick, nodes, heights, left, num_tris);
        load_treelet_leaf(t, leaves++, nodes, heights, right, num_tris);
    }
    t->leaves = leaves;
}

// Give the treelet the shape `split` describes (for each subset of leaves,
// the part holding its lowest leaf), reusing its inner nodes in pre-order.
// The new inner nodes' numbers come from the local copy, children first, by
// refresh_node's arithmetic (the same values, bit for bit, as refreshing
// them in global memory would give).
inline void rebuild_treelet(local const Treelet* t, global BuildNode* nodes, global int* heights, int full,
                            const local uchar* split, int num_tris, uint leaf_size)
{
    // Slots: leaf k is slot k, the u-th inner node (in the order its place
    // is taken) slot TREELET_LEAVES + u; a node's children have higher u.
    float3 lo[2 * TREELET_LEAVES - 1], hi[2 * TREELET_LEAVES - 1];
    float cost[2 * TREELET_LEAVES - 1];
    int count[2 * TREELET_LEAVES - 1], rows[2 * TREELET_LEAVES - 1], height[2 * TREELET_LEAVES - 1];
    int child_slot[TREELET_LEAVES - 1][2];
    for (int k = 0; k < t->leaves; ++k) {
        lo[k] = t->lo[k].xyz;
        hi[k] = t->hi[k].xyz;
        cost[k] = t->cost[k];
        count[k] = t->count[k];
        rows[k] = t->rows[k];
        height[k] = t->height[k];
    }
    int stack_subset[TREELET_LEAVES], stack_slot[TREELET_LEAVES];
    int sp = 0, used = 0;
    stack_subset[sp] = full;
    stack_slot[sp++] = used++;
    while (sp > 0) {
        --sp;
        const int s = stack_subset[sp], u = stack_slot[sp];
        for (int side = 0; side < 2; ++side) {
            const int p = side == 0 ? split[s] : s ^ split[s];
            if (p == (p & -p)) {
                child_slot[u][side] = 31 - clz(p);
            } else {
                child_slot[u][side] = TREELET_LEAVES + used;
                stack_subset[sp] = p;
                stack_slot[sp++] = used++;
            }
        }
    }
    for (int u = used - 1; u >= 0; --u) {
        const int a = child_slot[u][0], b = child_slot[u][1], me = TREELET_LEAVES + u;
        const int n = t->inner[u];
        const int left = a < TREELET_LEAVES ? t->node[a] : t->inner[a - TREELET_LEAVES];
        const int right = b < TREELET_LEAVES ? t->node[b] : t->inner[b - TREELET_LEAVES];
        lo[me] = fmin(lo[a], lo[b]);
        hi[me] = fmax(hi[a], hi[b]);
        const float area = half_area(lo[me], hi[me]);
        count[me] = count[a] + count[b];
        float node_cost = C_TRAVERSAL * area + cost[a] + cost[b];
        rows[me] = emitted_as_leaf(area, count[me], leaf_size, &node_cost) ? 0 : 1 + rows[a] + rows[b];
        cost[me] = node_cost;
        height[me] = 1 + max(height[a], height[b]);
        nodes[n].lo = (float4)(lo[me], as_float(left));
        nodes[n].hi = (float4)(hi[me], as_float(right));
        nodes[n].count = count[me];
        nodes[n].cost = cost[me];
        nodes[n].rows = rows[me];
        heights[n - num_tris] = height[me];
        nodes[left].parent = n;
        nodes[right].parent = n;
    }
}

#endif

// Does inner node n get its treelet restructured?  Only with at least
// min_count triangles (more than leaf_size: smaller subtrees are one leaf or a
// few, however shaped; clrt/device/build.py says why not all of those).
inline bool has_treelet(const volatile global BuildNode* nodes, int n, uint min_count)
{
    return nodes[n].count >= (int)min_count;
}

// One work-item per inner node (index F + i): count the nodes with a treelet
// per height, into STATE_LEVELS (the last entry takes every taller node; the
// host then leaves the tree as it is).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void treelet_levels(const global BuildNode* nodes, const global int* heights, const int num_tris,
                    const uint min_count, global int* state)
{
    const int i = get_global_id(0);
    if (i >= num_tris - 1 || !has_treelet(nodes, num_tris + i, min_count))
        return;
    atomic_inc(&state[STATE_LEVELS + min(heights[i], TREELET_LEVELS - 1)]);
}

// One work-item per inner node: its place in `order`, the nodes with a
// treelet listed by height (lowest first; any order within a height).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void treelet_order(const global BuildNode* nodes, const global int* heights, const int num_tris,
                   const uint min_count, global int* state, global int* order)
{
    const int i = get_global_id(0);
    if (i >= num_tris - 1 || !has_treelet(nodes, num_tris + i, min_count))
        return;
    const int height = min(heights[i], TREELET_LEVELS - 1);
    int place = 0;
    for (int h = 0; h < height; ++h)
        place += state[STATE_LEVELS + h];
    order[place + atomic_inc(&state[STATE_LEVEL_CURSORS + height])] = num_tris + i;
}

// Work-groups of TREELET_GROUP work-items, as many as the device runs at
// once (the host's choice), each taking the nodes of `order` by tickets until
// none are left; treelet_done[i] is 0 for inner node F + i at the start.
// The first work-item takes the ticket, waits for the children, refreshes
// the node (its children's treelets may have become cheaper) and forms its
// treelet; then the group solves the dynamic program together: the subsets
// of one size at a time, in parallel -- a subset's parts are all smaller --
// with a barrier between sizes, so that the longest chain is about 130 steps
// instead of one work-item's 1,100.  (One work-item per treelet, the first
// version, took 3.6 ms for bunny00 on the H200.)  (With TREELET_LEAVES 0 the
// host does not launch it.)
__kernel __attribute__((reqd_work_group_size(TREELET_GROUP, 1, 1)))
void treelet_restructure(global BuildNode* nodes, global int* heights, const global int* order,
                         global uint* treelet_done, global int* state, const int num_tris, const uint min_count,
                         const uint leaf_size)
{
#if TREELET_LEAVES > 0
    local Treelet t;
    local float area[TREELET_SUBSETS], best[TREELET_SUBSETS];
    local int count[TREELET_SUBSETS];
    local uchar split[TREELET_SUBSETS];    // the part holding the subset's lowest leaf
    local int root;
    const int lid = get_local_id(0);
    // The listed nodes, none when one is taller than TREELET_LEVELS - 1 (the
    // list is then not in height order).
    int listed = 0;
    for (int h = 0; h < TREELET_LEVELS; ++h)
        listed += state[STATE_LEVELS + h];
    if (state[STATE_LEVELS + TREELET_LEVELS - 1] != 0)
        listed = 0;
    if (lid == 0) {
        const int ticket = atomic_inc(state + STATE_TREELET_TICKET);
        root = ticket < listed ? order[ticket] : -1;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    // (The loop tests the shared ticket at its top: the same loop left by a
    // `break` after a barrier never ended on PoCL 3.1.)
    while (root >= 0) {                    // a node a turn, while tickets last
        if (lid == 0) {
            const int child[2] = {left_of(nodes, root), right_of(nodes, root)};
            for (int side = 0; side < 2; ++side) {
                const int c = child[side];
                if (c >= num_tris && has_treelet(nodes, c, min_count))
                    while (atomic_or(treelet_done + (c - num_tris), 0u) == 0u)
                        ;
            }
            acquire_fence();
        }
        // (A barrier as well as the fences, here and before the flag: PoCL's
        // compiler keeps no memory access on the wrong side of a barrier.)
        barrier(CLK_GLOBAL_MEM_FENCE);
        if (lid == 0) {
            refresh_node(nodes, heights, root, num_tris, leaf_size);
            // Nodes of fewer than TREELET_FULL_MIN triangles take smaller treelets:
            // the height of the tree is the chain of treelets one waits for,
            // and the lower ones change its cost least.
            form_treelet(&t, nodes, heights, root, num_tris,
                         nodes[root].count >= TREELET_FULL_MIN ? TREELET_LEAVES : TREELET_SMALL_LEAVES);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        const int n = t.leaves;                // the same in every work-item
        const int full = (1 << n) - 1;
        if (n >= 3) {                          // (fewer: one shape only)
            for (int s = lid + 1; s <= full; s += TREELET_GROUP) {
                float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
                int c = 0;
                for (int k = 0; k < n; ++k)
                    if (s & (1 << k)) {
                        lo = fmin(lo, t.lo[k].xyz);
                        hi = fmax(hi, t.hi[k].xyz);
                        c += t.count[k];
                    }
                area[s] = half_area(lo, hi);
                count[s] = c;
                if (s == (s & -s)) {
                    best[s] = t.cost[31 - clz(s)];
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
                    emitted_as_leaf(area[s], count[s], leaf_size, &cost);   // then however split
                    best[s] = cost;
                    split[s] = (uchar)cut;
                }
                barrier(CLK_LOCAL_MEM_FENCE);
            }
            // Rebuild only when clearly cheaper (the same tree costs the same, up to rounding).
            if (lid == 0 && best[full] < nodes[root].cost * (1.0f - 1e-5f))
                rebuild_treelet(&t, nodes, heights, full, split, num_tris, leaf_size);
        }
        barrier(CLK_GLOBAL_MEM_FENCE);
        if (lid == 0) {
            release_fence();       // the subtree's writes before the flag
            atomic_xchg(treelet_done + (root - num_tris), 1u);
            const int ticket = atomic_inc(state + STATE_TREELET_TICKET);
            root = ticket < listed ? order[ticket] : -1;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
#endif
}

#endif
