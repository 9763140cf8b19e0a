// Reinsertion (Bittner et al. 2013, "Fast insertion-based optimization of
// bounding volume hierarchies"), all nodes at once as Meister & Bittner 2018
// do it ("Parallel reinsertion for bounding volume hierarchy optimization"):
// every emitted node looks for the place in the tree where moving it would
// lower the SAH cost most, and the best moves that touch no common node are
// made; then the tree is refitted, and the next iteration looks again.
//
// Why: PLOC's merges (with the SAH top and the treelets) group the triangles
// worse than the host's top-down SAH at every scale -- on bunny00 the half
// areas of the inner nodes of 16 to 4096 triangles sum to 11 % more than the
// host tree's (SAH cost +5.5 %, rows opened by primary rays +13 %:
// benchmarks/tree_counts.py, docs/benchmark-log.md, session 18).  A treelet
// only reshapes the top of a subtree over 7 fixed parts, and more rounds of
// them gained 0.5-0.7 %; a reinsertion takes a subtree anywhere.  It runs
// before the treelets, which then polish the moved nodes' neighbourhoods
// (0.2-0.4 % cheaper trees than after them).
//
// The search of node N (parent P, sibling S) does not take N out of the tree:
// moving N next to X (a new parent P' in X's place, P's place taken by S)
// changes the cost, in half areas (C_TRAVERSAL units), by
//     - A(P) - sum over P's ancestors a_1 .. a_{i-1} of (A(a) - A(a without N))
//     + A(X u N) + sum over X's ancestors below a_i of (A(y u N) - A(y))
// where a_i is the lowest common ancestor of N and X (the junction): from a_i
// up, the boxes hold N before and after.  So the search climbs from P, keeps
// the credit (the first line, negated) and, at each ancestor a_i (up to
// REINSERT_CLIMB of them), tries a_i itself (P' above it: the gain is the
// credit less A(a_i without N)) and descends into a_i's other child (and at
// first into S) depth first, pruned by the bound credit - induced - A(N) (the
// insertion cost below a node is at least the growth of its ancestors plus
// A(N)).  Only the tree the traversal walks is searched: nodes inside a leaf
// (a proper ancestor with rows == 0) neither move nor take a node.
//
// Conflicts: a move rewires N, P, S, P's parent, X and X's parent; each takes
// the highest gain at each of these six nodes (reinsert_search), and of the
// moves at the highest gain the lowest N (reinsert_claim); a move that holds
// all six is made.  Moves made at once can make a cycle (N1 into N2's subtree
// while N2 moves into N1's); a move into the subtree of another node that
// holds its six, below the junction, is dropped (reinsert_check).  The
// search, the choices and the refit depend only on the tree, not on the
// order the work-items run in: no launch reads what another work-item of it
// writes (reinsert_check writes its verdict beside the move, which it reads
// only of its own node).
#ifndef CLRT_BUILD_REINSERT_CL
#define CLRT_BUILD_REINSERT_CL

#include "layouts.h"
#include "fences.cl"
#include "build_treelet.cl"

#if !defined(REINSERT_STACK) || !defined(REINSERT_CLIMB)
#error "build with -DREINSERT_STACK=<subtrees a search holds postponed> and -DREINSERT_CLIMB=<ancestors it climbs to>"
#endif

// A gain must exceed this fraction of the credit it was taken from: smaller
// ones are float32 rounding of the areas, and would move nodes to and fro.
#define REINSERT_MIN_GAIN 1e-6f
#define NO_OWNER 0x7fffffff

inline int other_child(const global BuildNode* nodes, int parent, int child)
{
    const int left = as_int(nodes[parent].lo.w);
    return left == child ? as_int(nodes[parent].hi.w) : left;
}

inline void consider_move(BuildMove* move, int target, float gain, float credit, int junction)
{
    if (gain > move->gain && gain > REINSERT_MIN_GAIN * credit) {
        move->target = target;
        move->gain = gain;
        move->junction = junction;
    }
}

// The best place below `top` for the node of box lo..hi (half area `area`),
// depth first; `skip_top`: top itself is the node's place now (no gain).
inline void search_subtree(const global BuildNode* nodes, int top, bool skip_top, float credit, float3 lo,
                           float3 hi, float area, int junction, BuildMove* move)
{
    int stack[REINSERT_STACK];
    float induced_at[REINSERT_STACK];      // the ancestors' growth above each postponed node
    int sp = 0;
    stack[sp] = top;
    induced_at[sp++] = 0.0f;
    while (sp > 0) {
        --sp;
        const int x = stack[sp];
        const float induced = induced_at[sp];
        if (credit - induced - area <= move->gain)
            continue;
        const float4 x_lo = nodes[x].lo, x_hi = nodes[x].hi;
        const float merged = half_area(fmin(x_lo.xyz, lo), fmax(x_hi.xyz, hi));
        if (!skip_top || x != top)
            consider_move(move, x, credit - induced - merged, credit, junction);
        if (nodes[x].rows > 0) {          // a row: its children are walked too
            const float deeper = induced + merged - half_area(x_lo.xyz, x_hi.xyz);
            if (credit - deeper - area > move->gain && sp + 2 <= REINSERT_STACK) {
                stack[sp] = as_int(x_lo.w);
                induced_at[sp++] = deeper;
                stack[sp] = as_int(x_hi.w);
                induced_at[sp++] = deeper;
            }
        }
    }
}

// Node n's best move (target -1: none) in the tree as it stands.
inline BuildMove best_move(const global BuildNode* nodes, int n, int root)
{
    BuildMove move = {-1, 0.0f, -1, 0};
    const int p = nodes[n].parent;
    if (p < 0 || p == root || nodes[p].rows == 0)
        return move;                      // the root, a child of the root, or inside a leaf
    const float3 lo = nodes[n].lo.xyz, hi = nodes[n].hi.xyz;
    const float area = half_area(lo, hi);
    const int s = other_child(nodes, p, n);
    float credit = half_area(nodes[p].lo.xyz, nodes[p].hi.xyz);     // P goes
    float3 shrunk_lo = nodes[s].lo.xyz, shrunk_hi = nodes[s].hi.xyz; // the path's node without n
    int below = p;
    search_subtree(nodes, s, true, credit, lo, hi, area, nodes[p].parent, &move);
    int climbed = 0;
    for (int a = nodes[p].parent; a >= 0 && climbed++ < REINSERT_CLIMB; a = nodes[a].parent) {
        if (nodes[a].rows == 0) {         // n is inside a leaf after all
            move.target = -1;
            return move;
        }
        const int o = other_child(nodes, a, below);
        shrunk_lo = fmin(shrunk_lo, nodes[o].lo.xyz);
        shrunk_hi = fmax(shrunk_hi, nodes[o].hi.xyz);
        const float shrunk = half_area(shrunk_lo, shrunk_hi);
        if (a != root)                    // (the root keeps its place: the emit pass starts there)
            consider_move(&move, a, credit - shrunk, credit, a);
        search_subtree(nodes, o, false, credit, lo, hi, area, a, &move);
        credit += half_area(nodes[a].lo.xyz, nodes[a].hi.xyz) - shrunk;
        below = a;
    }
    return move;
}

// The six nodes node n's move to `target` rewires: n, P, S, P's parent, the
// target and its parent.
inline void move_nodes(const global BuildNode* nodes, int n, int target, int touched[6])
{
    const int p = nodes[n].parent;
    touched[0] = n;
    touched[1] = p;
    touched[2] = other_child(nodes, p, n);
    touched[3] = nodes[p].parent;
    touched[4] = target;
    touched[5] = nodes[target].parent;
}

inline bool holds_all(const global BuildNode* nodes, const global BuildLock* locks, int n, int target)
{
    int touched[6];
    move_nodes(nodes, n, target, touched);
    for (int k = 0; k < 6; ++k)
        if (locks[touched[k]].owner != n)
            return false;
    return true;
}

// Before the first search: no node locked.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void reinsert_clear(global BuildLock* locks, const int num_nodes)
{
    const int n = get_global_id(0);
    if (n < num_nodes) {
        locks[n].gain = 0u;
        locks[n].owner = NO_OWNER;
    }
}

// One work-item per node: its best move, and the move's gain raised on the
// six nodes it would rewire (positive floats order as their bits); also
// clears reinsert_refit's arrivals.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void reinsert_search(const global BuildNode* nodes, global BuildMove* moves, global BuildLock* locks,
                     global uint* arrivals, const int num_tris)
{
    const int n = get_global_id(0);
    if (n >= 2 * num_tris - 1)
        return;
    if (n < num_tris - 1)
        arrivals[n] = 0u;
    const BuildMove move = best_move(nodes, n, 2 * num_tris - 2);
    moves[n] = move;
    if (move.target < 0)
        return;
    int touched[6];
    move_nodes(nodes, n, move.target, touched);
    for (int k = 0; k < 6; ++k)
        atomic_max(&locks[touched[k]].gain, as_uint(move.gain));
}

// One work-item per node whose move holds the highest gain at all six of
// its nodes: the lowest such node takes each of them.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void reinsert_claim(const global BuildNode* nodes, const global BuildMove* moves, global BuildLock* locks,
                    const int num_tris)
{
    const int n = get_global_id(0);
    if (n >= 2 * num_tris - 1 || moves[n].target < 0)
        return;
    const uint gain = as_uint(moves[n].gain);
    int touched[6];
    move_nodes(nodes, n, moves[n].target, touched);
    for (int k = 0; k < 6; ++k)
        if (locks[touched[k]].gain != gain)
            return;
    for (int k = 0; k < 6; ++k)
        atomic_min(&locks[touched[k]].owner, n);
}

// Does node a hold the six nodes of its move?  (Read of the search's moves
// and the claims, which no work-item of reinsert_check changes: a move that
// holds its nodes but is dropped for a cycle of its own still drops the
// moves below it, so the verdicts do not depend on the order of the checks.)
inline bool holds_its_nodes(const global BuildNode* nodes, const global BuildMove* moves,
                            const global BuildLock* locks, int a)
{
    const int target = moves[a].target;
    return target >= 0 && holds_all(nodes, locks, a, target);
}

// One work-item per node with a move: made (moves[n].made) if it holds its
// six nodes and no node on the way down from the junction to its target
// holds the six of a move of its own (a cycle).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void reinsert_check(const global BuildNode* nodes, global BuildMove* moves, const global BuildLock* locks,
                    const int num_tris)
{
    const int n = get_global_id(0);
    if (n >= 2 * num_tris - 1)
        return;
    const BuildMove move = moves[n];
    bool made = holds_its_nodes(nodes, moves, locks, n);
    if (made && move.target != move.junction)
        for (int a = nodes[move.target].parent; a != move.junction; a = nodes[a].parent)
            // (a < 0: past the root, never on a valid tree, where the junction
            // is an ancestor of the target; a bound on the walk all the same)
            if (a < 0 || holds_its_nodes(nodes, moves, locks, a)) {
                made = false;
                break;
            }
    moves[n].made = made;
}

inline void replace_child(global BuildNode* nodes, int parent, int old_child, int new_child)
{
    if (as_int(nodes[parent].lo.w) == old_child)
        nodes[parent].lo.w = as_float(new_child);
    else
        nodes[parent].hi.w = as_float(new_child);
}

// One work-item per node: its move made (P leaves, S takes its place; P
// comes back as the parent of the target and n), and its lock cleared for
// the next iteration.  The boxes are refitted next.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void reinsert_apply(global BuildNode* nodes, const global BuildMove* moves, global BuildLock* locks,
                    const int num_tris)
{
    const int n = get_global_id(0);
    if (n >= 2 * num_tris - 1)
        return;
    locks[n].gain = 0u;
    locks[n].owner = NO_OWNER;
    if (!moves[n].made)
        return;
    const int x = moves[n].target;
    const int p = nodes[n].parent, s = other_child(nodes, p, n), g = nodes[p].parent;
    const int q = nodes[x].parent;        // (read before any write: q may be g, or s)
    replace_child(nodes, g, p, s);
    nodes[s].parent = g;
    replace_child(nodes, q, x, p);
    nodes[p].parent = q;
    nodes[p].lo.w = as_float(x);
    nodes[p].hi.w = as_float(n);
    nodes[x].parent = p;
}

// One work-item per triangle, climbing: the second child to arrive at a node
// refreshes it (refresh_node: box, count, cost, leaf choice, height), so
// every node is refreshed once, after both its children.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void reinsert_refit(global BuildNode* nodes, global int* heights, global uint* arrivals, const int num_tris,
                    const uint leaf_size)
{
    const int i = get_global_id(0);
    if (i >= num_tris)
        return;
    shared_nodes shared = nodes;
    // (A triangle's node: nothing of this work-item's to hand over yet.)
    for (int n = shared[i].parent; n >= 0; n = shared[n].parent) {
        if (atomic_inc(arrivals + (n - num_tris)) != 1u)
            return;                          // the first: the other child is not done, its climb goes on
        acquire_fence();
        refresh_node(shared, heights, n, num_tris, leaf_size);
        release_fence();                     // the refresh before this node's arrival at its parent
    }
}

#endif
