// Entry file of the ray-query program: batches of rays from the host, one
// work-item per ray, the same closest_hit / any_hit as the renderer.
#include "layouts.h"
#include "camera.cl"
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

// Camera rays made and traced in one kernel (no ray buffer): the primary-ray
// throughput benchmark, and depth / primitive images.  Ray model: camera.cl.
__kernel void trace_camera(__global Hit* hits, CAMERA_PARAMS, ACCEL_PARAMS)
{
    const uint px = get_global_id(0), py = get_global_id(1);
    if (px >= width || py >= height)
        return;
    const Camera cam = make_camera(CAMERA_ARGS);
    const Ray ray = camera_ray(&cam, px, py, 0.5f, 0.5f);
    hits[py * width + px] = reported_hit(closest_hit(ACCEL_ARGS, ray.origin.xyz, ray.dir.xyz, 0.0f, INFINITY),
                                         prim_ids);
}

// The same rays as any-hit queries (occlusion), for comparing query kinds.
__kernel void occlude_camera(__global uchar* occluded, CAMERA_PARAMS, ACCEL_PARAMS)
{
    const uint px = get_global_id(0), py = get_global_id(1);
    if (px >= width || py >= height)
        return;
    const Camera cam = make_camera(CAMERA_ARGS);
    const Ray ray = camera_ray(&cam, px, py, 0.5f, 0.5f);
    occluded[py * width + px] = any_hit(ACCEL_ARGS, ray.origin.xyz, ray.dir.xyz, 0.0f, INFINITY) ? 1 : 0;
}
