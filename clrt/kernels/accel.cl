// The acceleration structure behind every ray query, chosen when the program
// is built: -DACCEL_BVH (with a VOLUME_* shape and BVH_STACK_SIZE; on CPU
// devices also -DBVH_WIDE, the wide walk of accel_wide.cl) or nothing (brute
// force), each with -DACCEL_INSTANCES for a two-level scene (docs/instances.md).  Both read the same Geometry (geometry.cl), so kernels and
// host need no variants, and both provide query_hits(), from which the
// queries below are made.
#ifndef CLRT_ACCEL_CL
#define CLRT_ACCEL_CL

#include "geometry.cl"
#include "hit.cl"
// Each file holds its code under its own #ifdef: the host expands includes
// unconditionally (clrt/device/program.py), so the choice lives in the files.
#include "accel_bvh.cl"
#include "accel_wide.cl"
#include "accel_none.cl"

#ifdef ACCEL_INSTANCES
// A two-level scene's walks give the hit's instance too (query_instance_hits:
// accel_bvh.cl, accel_none.cl); query_hits leaves it out.
inline Hit query_hits(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax,
                      const int query, const bool spawned, HitSink* sink)
{
    int instance;
    return query_instance_hits(g, origin, dir, tmin, tmax, query, spawned, sink, &instance);
}
#else
// A one-level scene is instance 0 of itself: *hit_instance 0 for a hit, -1
// for none.
inline Hit query_instance_hits(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax,
                               const int query, const bool spawned, HitSink* sink, int* hit_instance)
{
    const Hit hit = query_hits(g, origin, dir, tmin, tmax, query, spawned, sink);
    *hit_instance = hit.prim >= 0 ? 0 : -1;
    return hit;
}
#endif

// Nearest hit in (tmin, tmax]; Hit.prim is the slot (see reported_hit).
// `spawned`: the ray leaves a surface (shading.cl's spawn_origin) and takes
// only hits certainly in (tmin, tmax] (triangle.cl's shear_ray).
inline Hit closest_hit(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax, const bool spawned)
{
    return query_hits(g, origin, dir, tmin, tmax, QUERY_CLOSEST, spawned, 0);
}

// closest_hit and the hit's instance (*instance: 0 in a one-level scene, -1
// for no hit): what the renderer shades (shading.cl's surface_point).
inline Hit closest_instance_hit(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax,
                                const bool spawned, int* instance)
{
    return query_instance_hits(g, origin, dir, tmin, tmax, QUERY_CLOSEST, spawned, 0, instance);
}

// Is anything hit in (tmin, tmax]?  Stops at the first hit (shadow rays).
inline bool any_hit(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax, const bool spawned)
{
    return query_hits(g, origin, dir, tmin, tmax, QUERY_ANY, spawned, 0).prim >= 0;
}

// A hit as reported to the host: Hit.prim turned from slot to triangle index.
inline Hit reported_hit(const Geometry* g, Hit hit)
{
    if (hit.prim >= 0)
        hit.prim = *SPLIT_AT(g, prim_ids, hit.prim);
    return hit;
}

#endif
