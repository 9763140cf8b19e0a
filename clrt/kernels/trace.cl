// Entry file of the ray-query program: batches of rays from the host, one
// work-item per ray, the same closest_hit / any_hit as the renderer.
#include "layouts.h"
#include "accel.cl"

__kernel void trace_closest(__global const Ray* rays, __global Hit* hits, const uint num_rays,
                            ACCEL_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= num_rays)
        return;
    const Ray ray = rays[i];
    hits[i] = reported_hit(closest_hit(ACCEL_ARGS, ray.origin.xyz, ray.dir.xyz, ray.origin.w, ray.dir.w),
                           prim_ids);
}

__kernel void trace_any(__global const Ray* rays, __global uchar* occluded, const uint num_rays,
                        ACCEL_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= num_rays)
        return;
    const Ray ray = rays[i];
    occluded[i] = any_hit(ACCEL_ARGS, ray.origin.xyz, ray.dir.xyz, ray.origin.w, ray.dir.w) ? 1 : 0;
}
