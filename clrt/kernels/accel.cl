// The acceleration structure behind closest_hit / any_hit, chosen when the
// program is built: -DACCEL_BVH (with a VOLUME_* shape) or nothing (brute force).
// Both take the same buffers, so the kernels and the host need no variants:
//   tris      triangle corners in slot order (leaf order for a BVH)
//   nodes     BVH nodes (one unused node without a BVH)
//   prim_ids  input triangle index of each slot (the identity without a BVH)
#ifndef CLRT_ACCEL_CL
#define CLRT_ACCEL_CL

#include "hit.cl"

#define ACCEL_PARAMS __global const TriangleVerts* tris, const uint num_tris, \
    __global const BvhNode* nodes, __global const int* prim_ids
#define ACCEL_ARGS tris, num_tris, nodes, prim_ids

#ifdef ACCEL_BVH
#include "accel_bvh.cl"
#else
#include "accel_none.cl"
#endif

// A hit as reported to the host: Hit.prim turned from slot to triangle index.
inline Hit reported_hit(Hit hit, __global const int* prim_ids)
{
    if (hit.prim >= 0)
        hit.prim = prim_ids[hit.prim];
    return hit;
}

#endif
