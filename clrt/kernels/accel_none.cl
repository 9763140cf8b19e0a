// No acceleration structure: every ray is tested against every triangle.
// This is the paper's "basic" program and the reference every BVH layout
// must reproduce exactly.  Slots are the input order here.
#ifndef CLRT_ACCEL_NONE_CL
#define CLRT_ACCEL_NONE_CL

#include "geometry.cl"
#include "hit.cl"
#include "instances.cl"

#ifndef ACCEL_BVH

#ifdef ACCEL_INSTANCES
// A two-level scene without a BVH: every triangle of every instance, the ray
// moved into each instance's object space (instances.cl) -- what the
// two-level BVH walk must find, bit for bit.  *hit_instance: the instance of
// the returned hit (-1 for none).
inline Hit query_instance_hits(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax,
                               const int query, const bool spawned, HitSink* sink, int* hit_instance)
{
    const int cull = sink ? sink->cull : CULL_NONE;
    const float end = tmax;
    Hit best = miss_hit();
    int best_instance = -1;
    for (uint i = 0; i < g->num_instances; ++i) {
        __global const Instance* in = SPLIT_AT(g, instances, i);
        const ShearedRay r = shear_ray(object_point(in, origin), object_vector(in, dir), spawned, end);
        const int object_cull = instance_cull(in, cull);
        for (int s = in->first; s < in->first + in->count; ++s)
            if (visit_instance_triangle(g, &r, s, (int)i, object_cull, tmin, &tmax, query, &best, &best_instance,
                                        sink)) {
                *hit_instance = best_instance;
                return best;
            }
    }
    *hit_instance = best_instance;
    return best;
}
#else
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

#endif
