// The wide BVH of CPU devices collapsed on the device (clrt/device/wide_build.py
// drives it): BvhPairNode rows -> BvhWideNodes of WIDE children and
// TrianglePackets of PACKET triangles, the same nodes and packets, bit for bit,
// as clrt/accel/wide.py's collapse (Ylitie et al. 2017, section 3: the
// SAH-optimal collapse by dynamic programming; that module says how it works).
//
// Why here: the host's collapse is many numpy passes a tree level each (26 of
// the 100 ms of bunny00's Accel on 2 cores), and it needed the rows and the
// slot-ordered triangles read back and the wide BVH uploaded.  The dynamic
// program is a few dozen float64 operations a row; one work-item does it
// bottom up in row order (rows are depth-first, so a row's children come
// after it: no tree levels, no atomics), numbers the wide nodes breadth first,
// and the packets in slot order (wide_plan); then every node and every leaf's
// packets are written in parallel (wide_write).
//
// Part of the device builder's program (build_bvh.cl: one program front end
// on a first call, not two), which passes the constants of clrt/accel/wide.py
// as WIDE, PACKET, MERGE, C_NODE and C_PACKET.
#ifndef CLRT_BUILD_WIDE_CL
#define CLRT_BUILD_WIDE_CL

#include "layouts.h"

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
// The costs in float64 operation by operation as numpy computes them: no fused multiply-adds.
#pragma OPENCL FP_CONTRACT OFF

#if !defined(WIDE) || !defined(PACKET) || !defined(MERGE) || !defined(C_NODE) || !defined(C_PACKET) \
    || !defined(BUILD_GROUP)
#error "build with the constants of clrt/accel/wide.py (WIDE, PACKET, MERGE, C_NODE, C_PACKET) and BUILD_GROUP"
#endif
#if WIDE != 8 || PACKET != 4
#error "the wide nodes hold float8 lanes and the packets float4 lanes"
#endif

#define BUDGETS (WIDE + 1)          // a child's lane budgets 0..WIDE
// Decisions for a child and a lane budget (clrt/accel/wide.py's LEAF, NODE,
// ABSENT); a positive one splits the child over its two children's lanes,
// giving the left child that many.
#define CHOICE_LEAF (-1)
#define CHOICE_NODE (-2)
#define CHOICE_ABSENT (-3)

// wide_plan's state (ints), read by the host before wide_write.
#define WIDE_NODES 0
#define WIDE_LEAVES 1
#define WIDE_PACKETS 2
#define WIDE_LEVELS 3
#define WIDE_STATE_INTS 4

// One binary child of a row (side 0: left), as wide.py's _entries reads it.
typedef struct {
    int ref, count;         // count > 0: a leaf's first slot and triangles; 0: a row; -1: none
    double area;            // half area of its box, in float64 (topdown.py's surface_area)
} PairChild;

inline PairChild pair_child(const global BvhPairNode* rows, int entry)
{
    const global BvhPairNode* row = rows + (entry >> 1);
    const float4 a = entry & 1 ? row->right_a : row->left_a, b = entry & 1 ? row->right_b : row->left_b;
    PairChild c;
    c.ref = as_int(a.w);
    c.count = as_int(b.w);
    const double dx = (double)b.x - (double)a.x, dy = (double)b.y - (double)a.y, dz = (double)b.z - (double)a.z;
    c.area = dx * dy + dy * dz + dz * dx;
    return c;
}

inline int packets_of(int triangles)
{
    return (triangles + PACKET - 1) / PACKET;
}

// Per row r, the child that row r is: cost[r * BUDGETS + k], choice[r * BUDGETS + k]
// (budget k), and its subtree's (first slot, triangles); best[r]: the left
// child's lanes when r is a wide node.  Until r's parent is planned, cost and
// choice hold r's own best split over k = 2..WIDE lanes (wide.py's _spread);
// the parent finishes them (finish_child) with r's area, which its row holds.
typedef struct {
    global double* cost;
    global char* choice;
    global char* best;
    global int2* subtree;
} Plan;

// The least SAH costs of child `c` over at most 1..WIDE lanes (lane j: j + 1 lanes).
inline double8 child_costs(Plan* plan, PairChild c)
{
    if (c.count == 0)
        return vload8(0, plan->cost + c.ref * BUDGETS + 1);
    return (double8)(c.count > 0 ? C_PACKET * c.area * (double)packets_of(c.count) : 0.0);
}

// Inner child row `r` of area `area`: one lane as a leaf (at most MERGE
// triangles) or as a wide node, or its split where cheaper (wide.py's
// settle), lane j for a budget of j + 1 lanes.
inline void finish_child(Plan* plan, int r, double area)
{
    global double* cost = plan->cost + r * BUDGETS;
    global char* choice = plan->choice + r * BUDGETS;
    const int n = plan->subtree[r].y;
    const double8 split_cost = vload8(0, cost + 1);        // (one lane: no split, infinite)
    const double node = C_NODE * area + split_cost.s7;
    const double leaf = n <= MERGE ? C_PACKET * area * (double)packets_of(n) : INFINITY;
    const double one = fmin(leaf, node);
    const char one_choice = leaf <= node ? CHOICE_LEAF : CHOICE_NODE;
    const long8 split = split_cost < one;
    vstore8(select((double8)(one), split_cost, split), 0, cost + 1);
    vstore8(select((char8)(one_choice), vload8(0, choice + 1), convert_char8(split)), 0, choice + 1);
    cost[0] = INFINITY;
    choice[0] = CHOICE_ABSENT;
}

// Row r's best split of its two children over k = 2..WIDE lanes (wide.py's
// _spread: of equal costs the split giving the left child fewest lanes), k
// in the lanes of a double8 (lane j: k = j + 1; k = 1 has none: infinite).
// The right child's costs lie in `right` after 8 infinite budgets (0 and
// below), so that a split giving the left child i lanes reads the right
// child's k - i lanes for every k at once.
inline void plan_row(Plan* plan, const global BvhPairNode* rows, int r)
{
    const PairChild left = pair_child(rows, 2 * r), right = pair_child(rows, 2 * r + 1);
    if (left.count == 0)
        finish_child(plan, left.ref, left.area);
    if (right.count == 0)
        finish_child(plan, right.ref, right.area);
    const double8 l = child_costs(plan, left);
    double padded[16];
    vstore8((double8)(INFINITY), 0, padded);
    vstore8(child_costs(plan, right), 0, padded + 8);
    double8 least = l.s0 + vload8(0, padded + 7);          // i = 1
    long8 at = select((long8)(0), (long8)(1), least < INFINITY);
#define SPLIT(i, left_cost) { \
        const double8 c = (left_cost) + vload8(0, padded + 8 - (i)); \
        const long8 better = c < least; \
        least = select(least, c, better); \
        at = select(at, (long8)(i), better); }
    SPLIT(2, l.s1) SPLIT(3, l.s2) SPLIT(4, l.s3) SPLIT(5, l.s4) SPLIT(6, l.s5) SPLIT(7, l.s6)
#undef SPLIT
    vstore8(least, 0, plan->cost + r * BUDGETS + 1);
    vstore8(convert_char8(at), 0, plan->choice + r * BUDGETS + 1);
    plan->best[r] = (char)at.s7;
    const int2 below_left = left.count == 0 ? plan->subtree[left.ref] : (int2)(left.ref, max(left.count, 0));
    const int right_tris = right.count == 0 ? plan->subtree[right.ref].y : max(right.count, 0);
    plan->subtree[r] = (int2)(below_left.x, below_left.y + right_tris);
}

// Binary child `entry`'s reference and count (pair_child without the area).
inline int2 pair_ref(const global BvhPairNode* rows, int entry)
{
    const global BvhPairNode* row = rows + (entry >> 1);
    return entry & 1 ? (int2)(as_int(row->right_a.w), as_int(row->right_b.w))
                     : (int2)(as_int(row->left_a.w), as_int(row->left_b.w));
}

// The decision for a binary child (pair_ref) at lane budget k.
inline int decision(Plan* plan, int2 child, int k)
{
    if (k == 0 || child.y < 0)
        return CHOICE_ABSENT;
    return child.y > 0 ? CHOICE_LEAF : plan->choice[child.x * BUDGETS + k];
}

// One work-item: the plan bottom up, then the wide nodes numbered breadth
// first (wide.py's _numbers: level after level, each in the order of its
// parents and their lanes), each node's lanes in the binary tree's order
// (`lanes`: per node and lane, int4 child -- a node's number, or a leaf's
// index in `leaves` until its first packet is known --, count -- 0 a node,
// its leaf's packets, -1 none --, the binary child it holds, row * 2 + side,
// or -1); `leaves`: per leaf its first slot, triangles and first packet,
// the packets numbered leaf after leaf in slot order (a depth-first walk of
// the wide nodes, lanes in order).  Scratch: node_rows, a row per wide node
// (the breadth-first queue), and a stack of int2 (as many as rows, and 2).
__kernel __attribute__((reqd_work_group_size(1, 1, 1)))
void wide_plan(const global BvhPairNode* rows, const int num_rows, global double* cost, global char* choice,
               global char* best, global int2* subtree, global int* node_rows, global int2* stack,
               global int4* lanes, global int4* leaves, global int* state)
{
    Plan plan = {cost, choice, best, subtree};
    for (int r = num_rows - 1; r >= 0; --r)
        plan_row(&plan, rows, r);

    int num_nodes = 1, num_leaves = 0, levels = 1, level_end = 1;
    node_rows[0] = 0;
    for (int node = 0; node < num_nodes; ++node) {
        if (node == level_end) {                           // the first node of the next level
            ++levels;
            level_end = num_nodes;
        }
        const int r = node_rows[node], split = best[r];
        int top = 0, lane = 0;
        stack[top++] = (int2)(2 * r + 1, WIDE - split);   // the left child's lanes first: pushed last
        stack[top++] = (int2)(2 * r, split);
        while (top > 0) {
            const int2 at = stack[--top];
            const int2 child = pair_ref(rows, at.x);       // (reference, count)
            const int c = decision(&plan, child, at.y);
            if (c == CHOICE_ABSENT)
                continue;
            if (c > 0) {                                   // spread over its children's lanes
                stack[top++] = (int2)(2 * child.x + 1, at.y - c);
                stack[top++] = (int2)(2 * child.x, c);
                continue;
            }
            if (c == CHOICE_NODE) {
                node_rows[num_nodes] = child.x;
                lanes[node * WIDE + lane] = (int4)(num_nodes++, 0, at.x, 0);
            } else {                                       // a leaf: its subtree's slots
                const int2 slots = child.y > 0 ? child : plan.subtree[child.x];
                leaves[num_leaves] = (int4)(slots, 0, 0);
                lanes[node * WIDE + lane] = (int4)(num_leaves++, packets_of(slots.y), at.x, 0);
            }
            ++lane;
        }
        for (; lane < WIDE; ++lane)
            lanes[node * WIDE + lane] = (int4)(0, -1, -1, 0);
    }

    // Packets in slot order: the leaves as a depth-first walk meets them.
    int num_packets = 0, top = 0;
    stack[top++] = (int2)(0, 0);                           // (node, next lane)
    while (top > 0) {
        const int2 at = stack[--top];
        for (int lane = at.y; lane < WIDE; ++lane) {
            global int4* l = lanes + at.x * WIDE + lane;
            if (l->y == 0) {                               // a node: it first, then this node's next lanes
                stack[top++] = (int2)(at.x, lane + 1);
                stack[top++] = (int2)(l->x, 0);
                break;
            }
            if (l->y > 0) {
                leaves[l->x].z = num_packets;
                l->x = num_packets;
                num_packets += l->y;
            }
        }
    }
    state[WIDE_NODES] = num_nodes;
    state[WIDE_LEAVES] = num_leaves;
    state[WIDE_PACKETS] = num_packets;
    state[WIDE_LEVELS] = levels;
}

// Work-item i writes wide node i (its lanes' boxes are the binary children's,
// bit for bit; empty lanes zeros) and its lanes' binary children to
// `sources`, and leaf i's packets (corners from the slot-ordered triangles,
// empty lanes zeros and slot -1).  `wide`: the nodes, then the packets from
// byte packets_at on (geometry.cl's layout).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void wide_write(const global BvhPairNode* rows, const global TriangleVerts* tris, const global int4* lanes,
                const global int4* leaves, const int num_nodes, const int num_leaves, global char* wide,
                const ulong packets_at, global int* sources)
{
    const int i = get_global_id(0);
    if (i < num_nodes) {
        global BvhWideNode* node = (global BvhWideNode*)wide + i;
        float lo[3][WIDE], hi[3][WIDE];
        int child[WIDE], count[WIDE];
        for (int k = 0; k < WIDE; ++k) {
            const int4 l = lanes[i * WIDE + k];
            child[k] = l.x;
            count[k] = l.y;
            sources[i * WIDE + k] = l.z;
            float4 a = (float4)(0.0f), b = (float4)(0.0f);
            if (l.z >= 0) {
                const global BvhPairNode* row = rows + (l.z >> 1);
                a = l.z & 1 ? row->right_a : row->left_a;
                b = l.z & 1 ? row->right_b : row->left_b;
            }
            lo[0][k] = a.x;
            lo[1][k] = a.y;
            lo[2][k] = a.z;
            hi[0][k] = b.x;
            hi[1][k] = b.y;
            hi[2][k] = b.z;
        }
        node->lo_x = vload8(0, lo[0]);
        node->lo_y = vload8(0, lo[1]);
        node->lo_z = vload8(0, lo[2]);
        node->hi_x = vload8(0, hi[0]);
        node->hi_y = vload8(0, hi[1]);
        node->hi_z = vload8(0, hi[2]);
        node->child = vload8(0, child);
        node->count = vload8(0, count);
    }
    if (i < num_leaves) {
        const int4 leaf = leaves[i];                       // first slot, triangles, first packet
        global TrianglePacket* packets = (global TrianglePacket*)(wide + packets_at) + leaf.z;
        for (int p = 0; p < packets_of(leaf.y); ++p) {
            TrianglePacket out;
            float corner[9][PACKET];                       // [corner * 3 + axis][lane]
            int slot[PACKET];
            for (int k = 0; k < PACKET; ++k) {
                const int within = p * PACKET + k;
                slot[k] = within < leaf.y ? leaf.x + within : -1;
                TriangleVerts t;
                t.v0 = t.v1 = t.v2 = (float4)(0.0f);
                if (slot[k] >= 0)
                    t = tris[slot[k]];
                corner[0][k] = t.v0.x;
                corner[1][k] = t.v0.y;
                corner[2][k] = t.v0.z;
                corner[3][k] = t.v1.x;
                corner[4][k] = t.v1.y;
                corner[5][k] = t.v1.z;
                corner[6][k] = t.v2.x;
                corner[7][k] = t.v2.y;
                corner[8][k] = t.v2.z;
            }
            for (int axis = 0; axis < 3; ++axis) {
                out.v0[axis] = vload4(0, corner[axis]);
                out.v1[axis] = vload4(0, corner[3 + axis]);
                out.v2[axis] = vload4(0, corner[6 + axis]);
            }
            out.slot = vload4(0, slot);
            packets[p] = out;
        }
    }
}

#endif
