// The last steps of the device builder: from the PLOC tree (BuildNode, with
// the SAH's leaf decisions) to the layout the traversal walks -- BvhPairNode
// rows in depth-first order, the root at row 0, left subtree before right
// (as clrt/accel/rows.py makes them from host trees) -- and the triangles in
// leaf-slot order.
//
// A node's row and first slot are sums along its path from the root: going
// to a left child adds one row and no slots, going to a right child adds one
// row plus the rows of the left sibling's subtree, and that sibling's
// triangles as slots.  Those path sums come from pointer jumping (Wyllie's
// list ranking, applied to the paths to the root): every node holds the sum
// up to an ancestor and then adds that ancestor's sum and jumps to its
// ancestor, so ceil(log2(path length)) launches reach the root from every
// node at once, O(nodes) work each.  The host knows the bound: the root's
// height, kept up to date by PLOC and the treelet restructuring.
//
// Path sums, int4: x row, y first slot, z level (the root is level 1),
// w > 0 when a proper ancestor is emitted as a leaf (the node is inside it).
#ifndef CLRT_BUILD_EMIT_CL
#define CLRT_BUILD_EMIT_CL

#include "layouts.h"
#include "build_state.cl"
#include "build_morton.cl"
#include "build_fit.cl"

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void init_root_paths(const global BuildNode* nodes, const uint num_nodes,
                     global int* ancestor, global int4* path)
{
    const uint n = get_global_id(0);
    if (n >= num_nodes)
        return;
    const int parent = nodes[n].parent;
    ancestor[n] = parent;
    if (parent < 0) {
        path[n] = (int4)(0, 0, 1, 0);
        return;
    }
    const BuildNode p = nodes[parent];
    const int left = as_int(p.lo.w);
    const BuildNode sibling = nodes[left];
    const int inside_leaf = p.rows == 0;
    path[n] = left == (int)n ? (int4)(1, 0, 1, inside_leaf)
                             : (int4)(1 + sibling.rows, sibling.count, 1, inside_leaf);
}

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void jump_root_paths(const global int* ancestor, const global int4* path, const uint num_nodes,
                     global int* ancestor_out, global int4* path_out)
{
    const uint n = get_global_id(0);
    if (n >= num_nodes)
        return;
    const int a = ancestor[n];
    ancestor_out[n] = a < 0 ? a : ancestor[a];
    path_out[n] = a < 0 ? path[n] : path[n] + path[a];
}

// One child of a row: its volume and reference (layouts.py, BvhPairNode).
inline void write_child(global float4* child_a_b, float3 lo, float3 hi, int ref, int count,
                        global float4* exact_a_b)
{
    float4 a, b;
    fit_volume(lo, hi, &a, &b);
    a.w = as_float(ref);
    b.w = as_float(count);
    child_a_b[0] = a;
    child_a_b[1] = b;
    if (exact_a_b) {
        exact_a_b[0] = (float4)(lo, as_float(ref));
        exact_a_b[1] = (float4)(hi, as_float(count));
    }
}

// Per node: a triangle goes to its slot; an emitted inner node writes its
// row; an emitted leaf raises the depth.  exact_rows (may be NULL) gets the
// same rows with the exact, unpadded boxes (box layout) for statistics.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void emit_tree(const global BuildNode* nodes, const uint num_nodes, const int root,
               const global float* corners, const global uint* sorted_ids,
               const global int* ancestor, const global int4* path,
               global BvhPairNode* rows, global BvhPairNode* exact_rows,
               global TriangleVerts* tris, global int* prim_ids, global int* state)
{
    const uint n = get_global_id(0);
    if (n >= num_nodes)
        return;
    if (ancestor[n] != -1)
        state[STATE_ERROR] = 1;          // too few jumps: a host bug, reported there
    const int4 at = path[n];
    const uint num_tris = (num_nodes + 1) / 2;
    if (n < num_tris) {
        const uint prim = sorted_ids[n];
        TriangleVerts t;
        t.v0 = (float4)(corner(corners, prim, 0), 0.0f);
        t.v1 = (float4)(corner(corners, prim, 1), 0.0f);
        t.v2 = (float4)(corner(corners, prim, 2), 0.0f);
        tris[at.y] = t;
        prim_ids[at.y] = (int)prim;
    }
    if (at.w > 0)
        return;                          // inside a leaf
    const BuildNode node = nodes[n];
    global BvhPairNode* exact = 0;
    if (node.rows == 0) {
        // Most leaves are no deeper than one seen already: a plain read skips
        // their atomic, which queued every leaf on one word (H200, 10M
        // triangles: emit_tree 1.55 -> 1.24 ms).  The depth only grows, so a
        // stale read can only let an atomic through.
        if (at.z > ((volatile global int*)state)[STATE_DEPTH])
            atomic_max(state + STATE_DEPTH, at.z);
        if ((int)n == root) {            // the whole tree is one leaf: on the left of a root row
            if (exact_rows)
                exact = exact_rows;
            write_child(&rows[0].left_a, node.lo.xyz, node.hi.xyz, 0, node.count,
                        exact ? &exact->left_a : 0);
            rows[0].right_a = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
            rows[0].right_b = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
            if (exact) {
                exact->right_a = rows[0].right_a;
                exact->right_b = rows[0].right_b;
            }
        }
        return;
    }
    const BuildNode left = nodes[as_int(node.lo.w)], right = nodes[as_int(node.hi.w)];
    global BvhPairNode* row = rows + at.x;
    if (exact_rows)
        exact = exact_rows + at.x;
    write_child(&row->left_a, left.lo.xyz, left.hi.xyz,
                left.rows == 0 ? at.y : at.x + 1, left.rows == 0 ? left.count : 0,
                exact ? &exact->left_a : 0);
    write_child(&row->right_a, right.lo.xyz, right.hi.xyz,
                right.rows == 0 ? at.y + left.count : at.x + 1 + left.rows, right.rows == 0 ? right.count : 0,
                exact ? &exact->right_a : 0);
}

#endif
