// Entry file of the refit program: new volumes for a BVH whose triangles
// moved but whose tree stays (Accel.refit, Renderer.refit).  The rows keep
// their child references (the w lanes); only the volumes (xyz lanes) change.
//
// 1. refit_leaves: the exact float32 box of every leaf child, from the
//    triangles of its slots;
// 2. refit_level, once per tree level from the deepest up: the box of every
//    inner child, the union of that child row's two boxes (deeper, so done);
// 3. refit_fit: every child's volume fitted to its box exactly as the builders
//    fit them (build_fit.cl, the argument of clrt/accel/volumes.py), so a
//    refitted tree finds exactly the hits of brute force, as a built one does.
// Boxes are kept per row and side: box_lo[2 * row + side], box_hi[...].
// The rows refitted are first_row .. first_row + num_rows - 1: a whole tree,
// or one mesh's rows among a two-level scene's (Accel.refit(vertices, mesh=k)),
// whose references are global as these kernels read them.
#include "layouts.h"
#include "build_fit.cl"

inline int2 child_ref(const BvhPairNode* n, int side)
{
    return side == 0 ? PAIR_LEFT(*n) : PAIR_RIGHT(*n);
}

__kernel void refit_leaves(__global const BvhPairNode* rows, const uint first_row, const uint num_rows,
                           __global const TriangleVerts* tris, __global float4* box_lo, __global float4* box_hi)
{
    if (get_global_id(0) >= num_rows)
        return;
    const uint r = first_row + get_global_id(0);
    const BvhPairNode n = rows[r];
    for (int side = 0; side < 2; ++side) {
        const int2 ref = child_ref(&n, side);
        if (ref.y <= 0)   // an inner child (refit_level) or none
            continue;
        float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
        for (int s = ref.x; s < ref.x + ref.y; ++s) {
            const TriangleVerts t = tris[s];
            lo = fmin(lo, fmin(t.v0.xyz, fmin(t.v1.xyz, t.v2.xyz)));
            hi = fmax(hi, fmax(t.v0.xyz, fmax(t.v1.xyz, t.v2.xyz)));
        }
        box_lo[2 * r + side] = (float4)(lo, 0.0f);
        box_hi[2 * r + side] = (float4)(hi, 0.0f);
    }
}

// The rows of one level (`level_rows`): their inner children's boxes.
__kernel void refit_level(__global const BvhPairNode* rows, __global const int* level_rows, const uint count,
                          __global float4* box_lo, __global float4* box_hi)
{
    const uint i = get_global_id(0);
    if (i >= count)
        return;
    const int r = level_rows[i];
    const BvhPairNode n = rows[r];
    for (int side = 0; side < 2; ++side) {
        const int2 ref = child_ref(&n, side);
        if (ref.y != 0)
            continue;
        const int c = ref.x;   // the child row: both of its sides are present
        box_lo[2 * r + side] = fmin(box_lo[2 * c], box_lo[2 * c + 1]);
        box_hi[2 * r + side] = fmax(box_hi[2 * c], box_hi[2 * c + 1]);
    }
}

__kernel void refit_fit(__global BvhPairNode* rows, const uint first_row, const uint num_rows,
                        __global const float4* box_lo, __global const float4* box_hi)
{
    if (get_global_id(0) >= num_rows)
        return;
    const uint r = first_row + get_global_id(0);
    BvhPairNode n = rows[r];
    for (int side = 0; side < 2; ++side) {
        if (child_ref(&n, side).y < 0)   // no child
            continue;
        float4 a, b;
        fit_volume(box_lo[2 * r + side].xyz, box_hi[2 * r + side].xyz, &a, &b);
        if (side == 0) {
            n.left_a.xyz = a.xyz;
            n.left_b.xyz = b.xyz;
        } else {
            n.right_a.xyz = a.xyz;
            n.right_b.xyz = b.xyz;
        }
    }
    rows[r] = n;
}
