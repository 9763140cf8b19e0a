// No acceleration structure: every ray is tested against every triangle.
// This is the paper's "basic" program and the reference every BVH layout
// must reproduce exactly.  It provides the same two queries as a traversal:
// closest_hit (camera and reflected rays) and any_hit (shadow rays).
// Slots are the input order here, so Hit.prim is the triangle index.
#ifndef CLRT_ACCEL_NONE_CL
#define CLRT_ACCEL_NONE_CL

#include "hit.cl"

inline Hit closest_hit(ACCEL_PARAMS, float3 origin, float3 dir, float tmin, float tmax)
{
    const ShearedRay r = shear_ray(origin, dir);
    Hit best = miss_hit();
    for (uint i = 0; i < num_tris; ++i) {
        float t, u, v;
        if (intersect_triangle(&r, tris + i, tmin, tmax, &t, &u, &v)
            && hit_is_closer(t, (int)i, &best)) {
            best = make_hit(t, (int)i, u, v);
            tmax = t;
        }
    }
    return best;
}

inline bool any_hit(ACCEL_PARAMS, float3 origin, float3 dir, float tmin, float tmax)
{
    const ShearedRay r = shear_ray(origin, dir);
    for (uint i = 0; i < num_tris; ++i) {
        float t, u, v;
        if (intersect_triangle(&r, tris + i, tmin, tmax, &t, &u, &v))
            return true;
    }
    return false;
}

#endif
