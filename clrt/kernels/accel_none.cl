// No acceleration structure: every ray is tested against every triangle.
// This is the paper's "basic" program and the reference every BVH layout
// must reproduce exactly.  Slots are the input order here.
#ifndef CLRT_ACCEL_NONE_CL
#define CLRT_ACCEL_NONE_CL

#include "geometry.cl"
#include "hit.cl"

#ifndef ACCEL_BVH

// Answer `query` for one ray (see hit.cl; `spawned`: triangle.cl's shear_ray);
// the returned Hit.prim is a slot.
inline Hit query_hits(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax,
                      const int query, const bool spawned, HitSink* sink)
{
    const ShearedRay r = shear_ray(origin, dir, spawned, tmax);
    Hit best = miss_hit();
    for (uint i = 0; i < g->num_tris; ++i)
        if (visit_triangle(g, &r, (int)i, tmin, &tmax, query, &best, sink))
            break;
    return best;
}

#endif

#endif
