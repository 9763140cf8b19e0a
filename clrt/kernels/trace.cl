// Entry file of the ray-query program (clrt/query/): batches of rays from
// the host, one work-item per ray, answered by the same query_hits() as the
// renderer's closest_hit / any_hit.  The host cuts a batch into chunks; each
// launch covers one chunk, so indices here are chunk-local.
//
// Every query takes `cull` (CULL_NONE, CULL_BACK or CULL_FRONT, triangle.cl),
// handed to the leaf action through a HitSink (hit.cl).
#include "layouts.h"
#include "camera.cl"
#include "geometry.cl"
#include "accel.cl"

// A sink that stores nothing: the query's options only.
inline HitSink query_options(const int cull)
{
    HitSink s;
    s.ray_ids = 0;
    s.prims = 0;
    s.ts = 0;
    s.next = 0;
    s.capacity = 0u;
    s.ray = 0;
    s.count = 0u;
    s.cull = cull;
    return s;
}

// Does the ray see the front face of triangle `tri`?  Asked only of a
// triangle it hit: the same arithmetic as the hit test, so culling and this
// flag always agree.
inline bool sees_front(const ShearedRay* r, __global const TriangleVerts* tri)
{
    float t, u, v;
    return intersect_triangle_culled(r, tri, -INFINITY, INFINITY, CULL_BACK, &t, &u, &v);
}

// Closest hit of each ray: the hit record (Hit.prim the triangle index) and
// whether its front face was hit.
__kernel void query_closest(__global const Ray* rays, __global Hit* hits, __global uchar* front,
                            const uint num_rays, const int cull, GEOMETRY_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Ray ray = rays[i];
    HitSink options = query_options(cull);
    const Hit hit = query_hits(&g, ray.origin.xyz, ray.dir.xyz, ray.origin.w, ray.dir.w,
                               QUERY_CLOSEST, &options);
    uchar f = 0;
    if (hit.prim >= 0) {
        const ShearedRay r = shear_ray(ray.origin.xyz, ray.dir.xyz);
        f = sees_front(&r, SPLIT_AT(&g, tris, hit.prim)) ? 1 : 0;
    }
    front[i] = f;
    hits[i] = reported_hit(&g, hit);
}

// Is anything hit?  Stops at the first hit found.
__kernel void query_any(__global const Ray* rays, __global uchar* occluded, const uint num_rays,
                        const int cull, GEOMETRY_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Ray ray = rays[i];
    HitSink options = query_options(cull);
    occluded[i] = query_hits(&g, ray.origin.xyz, ray.dir.xyz, ray.origin.w, ray.dir.w,
                             QUERY_ANY, &options).prim >= 0 ? 1 : 0;
}

// Number of triangles each ray meets in (tmin, tmax].
__kernel void query_count(__global const Ray* rays, __global uint* counts, const uint num_rays,
                          const int cull, GEOMETRY_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Ray ray = rays[i];
    HitSink sink = query_options(cull);
    query_hits(&g, ray.origin.xyz, ray.dir.xyz, ray.origin.w, ray.dir.w, QUERY_ALL, &sink);
    counts[i] = sink.count;
}

// Every hit of every ray in one traversal, appended in no particular order to
// (ray_ids, prims, ts) at *next.  *next ends as the number of hits of the
// whole launch, also when that exceeds `capacity` (then the host runs the
// chunk again with room for all of them).
__kernel void query_all(__global const Ray* rays, __global int* ray_ids, __global int* prims,
                        __global float* ts, __global uint* next, const uint capacity,
                        const uint num_rays, const int cull, GEOMETRY_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Ray ray = rays[i];
    HitSink sink = query_options(cull);
    sink.ray_ids = ray_ids;
    sink.prims = prims;
    sink.ts = ts;
    sink.next = next;
    sink.capacity = capacity;
    sink.ray = (int)i;
    query_hits(&g, ray.origin.xyz, ray.dir.xyz, ray.origin.w, ray.dir.w, QUERY_ALL, &sink);
}

// The camera's pixel-centre rays for pixels first .. first + count - 1 (row
// major, row 0 at the top): exactly the renderer's camera rays (camera.cl).
__kernel void camera_rays(__global Ray* rays, CAMERA_PARAMS, const ulong first, const uint count)
{
    const uint i = get_global_id(0);
    if (i >= count)
        return;
    const Camera cam = make_camera(CAMERA_ARGS);
    const ulong pixel = first + i;
    rays[i] = camera_ray(&cam, (uint)(pixel % width), (uint)(pixel / width), 0.5f, 0.5f);
}

// ---- one-launch kernels of the primary-ray benchmark (clrt/bench/speed.py)

// Camera rays made and traced in one kernel (no ray buffer).  Ray model: camera.cl.
__kernel void trace_camera(__global Hit* hits, CAMERA_PARAMS, GEOMETRY_PARAMS)
{
    const uint px = get_global_id(0), py = get_global_id(1);
    if (px >= width || py >= height)
        return;
    const Camera cam = make_camera(CAMERA_ARGS);
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Ray ray = camera_ray(&cam, px, py, 0.5f, 0.5f);
    hits[py * width + px] = reported_hit(&g, closest_hit(&g, ray.origin.xyz, ray.dir.xyz, 0.0f, INFINITY));
}

// The same rays as any-hit queries (occlusion), for comparing query kinds.
__kernel void occlude_camera(__global uchar* occluded, CAMERA_PARAMS, GEOMETRY_PARAMS)
{
    const uint px = get_global_id(0), py = get_global_id(1);
    if (px >= width || py >= height)
        return;
    const Camera cam = make_camera(CAMERA_ARGS);
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Ray ray = camera_ray(&cam, px, py, 0.5f, 0.5f);
    occluded[py * width + px] = any_hit(&g, ray.origin.xyz, ray.dir.xyz, 0.0f, INFINITY) ? 1 : 0;
}
