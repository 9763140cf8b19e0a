// The acceleration structure behind every ray query, chosen when the program
// is built: -DACCEL_BVH (with a VOLUME_* shape) or nothing (brute force).
// Both take the same buffers, so kernels and host need no variants:
//   tris      triangle corners in slot order (leaf order for a BVH)
//   nodes     BVH inner nodes with their children's volumes (one unused without a BVH)
//   prim_ids  input triangle index of each slot (the identity without a BVH)
// and both provide query_hits(), from which the queries below are made.
// Each buffer may arrive in parts (split.cl): elements are reached through
// SPLIT_AT, never by indexing the parameter.
#ifndef CLRT_ACCEL_CL
#define CLRT_ACCEL_CL

#include "layouts.h"
#include "split.cl"

#define ACCEL_PARAMS SPLIT_PARAMS(TriangleVerts, tris), const uint num_tris, \
    SPLIT_PARAMS(BvhPairNode, nodes), SPLIT_PARAMS(int, prim_ids)
#define ACCEL_ARGS SPLIT_ARGS(tris), num_tris, SPLIT_ARGS(nodes), SPLIT_ARGS(prim_ids)

// Included here, before the choice below: the host expands each include once,
// so a file first met inside a disabled #if branch would be lost to the other.
#include "hit.cl"

#ifdef ACCEL_BVH
#include "accel_bvh.cl"
#else
#include "accel_none.cl"
#endif

// Nearest hit in (tmin, tmax]; Hit.prim is the slot (see reported_hit).
inline Hit closest_hit(ACCEL_PARAMS, float3 origin, float3 dir, float tmin, float tmax)
{
    return query_hits(ACCEL_ARGS, origin, dir, tmin, tmax, QUERY_CLOSEST, 0);
}

// Is anything hit in (tmin, tmax]?  Stops at the first hit (shadow rays).
inline bool any_hit(ACCEL_PARAMS, float3 origin, float3 dir, float tmin, float tmax)
{
    return query_hits(ACCEL_ARGS, origin, dir, tmin, tmax, QUERY_ANY, 0).prim >= 0;
}

// A hit as reported to the host: Hit.prim turned from slot to triangle index.
inline Hit reported_hit(Hit hit, SPLIT_PARAMS(int, prim_ids))
{
    if (hit.prim >= 0)
        hit.prim = *SPLIT_AT(prim_ids, hit.prim);
    return hit;
}

#endif
