// Entry file of the path tracer: unidirectional path tracing with next-event
// estimation, multiple importance sampling (the power heuristic) between light
// and BSDF sampling for every light that can be both hit and sampled
// (emissive triangles, the background / environment map), Russian roulette,
// and counter-based random numbers (rng.cl).  A megakernel: one work-item a
// pixel of the launch's rectangle, tracing the launch's samples of it one
// whole path after another, and adding their sums to the image's (so a render
// goes in passes of samples, and a pass's image can be shown).
//
// Depth is counted as Mitsuba counts max_depth: the camera ray's segment is 1;
// a path of max_depth 1 sees emitters only, 2 adds direct light, -1 is
// unbounded (paths then end by Russian roulette from rr_depth on, or at
// MAX_PATH_DEPTH).  Light reached by a shadow ray from the vertex at depth d
// counts as a path of depth d + 1, as in Mitsuba.
#include "layouts.h"
#include "camera.cl"
#include "geometry.cl"
#include "accel.cl"
#include "shading.cl"
#include "rng.cl"
#include "bsdf.cl"
#include "material.cl"
#include "lights.cl"

#define PATH_SEEN(frame) ((__global uint*)(frame))
#define PATH_SUMS(frame, at) ((__global float4*)((frame) + (at)))

// Dimension groups of a sample (random4): the camera jitter, then two a vertex.
#define GROUP_CAMERA 0u
#define GROUP_LIGHT(depth) (2u * (depth) - 1u)    // light choice, its point (2), Russian roulette
#define GROUP_BSDF(depth) (2u * (depth))          // the BSDF's three

inline float mis_weight(float chosen, float other)
{
    const float a = chosen * chosen, b = other * other;
    return a / (a + b);
}

inline float max_component(float3 c)
{
    return fmax(c.x, fmax(c.y, c.z));
}

// What one camera sample brings back: its radiance, and the first hit's albedo
// and shading normal (zeros where the camera ray leaves the scene).
typedef struct {
    float3 radiance, albedo, normal;
    bool seen;
} PathSample;

inline PathSample trace_path(const Geometry* g, const Shading* sh, const Lights* lights, const PathLaunch* launch,
                             uint px, uint py, uint sample)
{
    const uint pixel = py * launch->cam.width + px;
    const uint seed = launch->seed;
    const uint last = launch->max_depth < 0 ? (uint)MAX_PATH_DEPTH : (uint)launch->max_depth;
    PathSample out;
    out.radiance = out.albedo = out.normal = (float3)(0.0f);
    out.seen = false;
    if (last == 0u)
        return out;
    const float4 jitter = random4(pixel, sample, GROUP_CAMERA, seed);
    const Ray camera = camera_ray(&launch->cam, px, py, jitter.x, jitter.y);
    float3 origin = camera.origin.xyz, dir = camera.dir.xyz;
    float3 beta = (float3)(1.0f), radiance = (float3)(0.0f);
    float prev_pdf = 0.0f;          // solid-angle pdf of the BSDF sample that made the ray
    bool prev_delta = true;         // the camera ray counts as a delta choice: nothing to weigh against
    float3 prev_p = origin;
    const uint strategy = launch->strategy;
    for (uint depth = 1u;; ++depth) {
        const Hit hit = closest_hit(g, origin, dir, 0.0f, INFINITY, depth > 1u);
        // Light found by this BSDF-sampled ray: all of it after a delta choice
        // (nothing else could find it), else weighed against light sampling.
        if (hit.prim < 0) {
            const float3 le = background_radiance(lights, dir);
            float w = 1.0f;
            if (!prev_delta) {
                const float light_pdf = lights->background_probability * background_pdf(lights, dir);
                w = strategy == PATH_LIGHT ? 0.0f
                  : strategy == PATH_BSDF || !(light_pdf > 0.0f) ? 1.0f : mis_weight(prev_pdf, light_pdf);
            }
            radiance += beta * le * w;
            break;
        }
        const SurfacePoint s = surface_point(g, sh, dir, &hit);
        __global const Material* m = sh->materials + SPLIT_AT(sh, tri_info, hit.prim)->material;
        const Bsdf b = material_bsdf(sh, &s, (uint)hit.prim, hit.u, hit.v);
        if (depth == 1u) {
            out.seen = true;
            out.albedo = b.base_color;
            out.normal = s.n;
        }
        const bool both = emits_both_sides(m);
        if (s.front || both) {
            const float3 le = surface_emission(sh, m, (uint)hit.prim, hit.u, hit.v);
            if (max_component(le) > 0.0f) {
                float w = 1.0f;
                if (!prev_delta) {
                    const float cos_light = fabs(dot(s.ng, dir));
                    const float light_pdf = triangle_light_area_pdf(lights, emission_factor(m), both)
                                          * hit.t * hit.t / cos_light;
                    w = strategy == PATH_LIGHT ? 0.0f
                      : strategy == PATH_BSDF || !(light_pdf > 0.0f) ? 1.0f : mis_weight(prev_pdf, light_pdf);
                }
                radiance += beta * le * w;
            }
        }
        if (depth >= last)
            break;
        // The BSDF's frame: the triangle's front side (glTF's counter-clockwise side).
        const float3 ng = s.front ? s.ng : -s.ng, n = s.front ? s.n : -s.n;
        const float3 wo = -dir;
        const float4 ul = random4(pixel, sample, GROUP_LIGHT(depth), seed);
        // Next-event estimation: one light, one shadow ray.
        LightSample ls;
        if (strategy != PATH_BSDF && sample_light(g, sh, lights, &s, ul.xyz, &ls)) {
            const float3 f = bsdf_eval(&b, n, ng, wo, ls.wi);
            if (max_component(f * ls.radiance) > 0.0f && !any_hit(g, ls.origin, ls.wi, 0.0f, ls.tmax, true)) {
                const float w = ls.delta || strategy == PATH_LIGHT ? 1.0f
                              : mis_weight(ls.pdf, bsdf_pdf(&b, n, ng, wo, ls.wi));
                radiance += beta * f * ls.radiance * (w / ls.pdf);
            }
        }
        const float4 ub = random4(pixel, sample, GROUP_BSDF(depth), seed);
        BsdfSample bs;
        if (!bsdf_sample(&b, n, ng, wo, ub.xyz, &bs))
            break;
        beta *= bs.weight;
        if (!(max_component(beta) > 0.0f))
            break;
        if (depth >= launch->rr_depth) {   // Russian roulette: continue with probability q
            const float q = fmin(max_component(beta), 0.95f);
            if (ul.w >= q)
                break;
            beta /= q;
        }
        prev_pdf = bs.pdf;
        prev_delta = bs.delta != 0;
        origin = spawn_origin(&s, bs.wi);
        dir = bs.wi;
    }
    // A sample that is not finite (a pdf that underflowed) is dropped rather
    // than let it poison the pixel's sum for good.
    out.radiance = isfinite(radiance.x) && isfinite(radiance.y) && isfinite(radiance.z) ? radiance : (float3)(0.0f);
    return out;
}

// One work-item a pixel of the launch's rectangle: its samples sample_first ..
// sample_first + sample_count - 1, added to the image's sums (started anew
// when samples_before is 0).  The frame's first word says whether any camera
// ray hit a triangle (renderer/visible.py's warning).
__kernel void path_trace(__global uchar* frame, const PathLaunch launch, GEOMETRY_PARAMS, SHADING_PARAMS)
{
    const uint gx = get_global_id(0), gy = get_global_id(1);
    if (gx >= launch.w || gy >= launch.h)
        return;
    const uint px = launch.x + gx, py = launch.y + gy;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Shading sh = make_shading(SHADING_ARGS, scene);
    const Lights lights = make_lights(&launch, tables);
    float3 radiance = (float3)(0.0f), albedo = (float3)(0.0f), normal = (float3)(0.0f);
    bool seen = false;
    for (uint k = 0; k < launch.sample_count; ++k) {
        const PathSample p = trace_path(&g, &sh, &lights, &launch, px, py, launch.sample_first + k);
        radiance += p.radiance;
        albedo += p.albedo;
        normal += p.normal;
        seen = seen || p.seen;
    }
    const ulong i = (ulong)py * launch.cam.width + px;
    const float n = (float)launch.sample_count;
    __global float4* image = PATH_SUMS(frame, launch.image_at) + i;
    __global float4* albedos = PATH_SUMS(frame, launch.albedo_at) + i;
    __global float4* normals = PATH_SUMS(frame, launch.normal_at) + i;
    if (launch.samples_before == 0u) {
        *image = (float4)(radiance, n);
        *albedos = (float4)(albedo, n);
        *normals = (float4)(normal, n);
    } else {
        *image += (float4)(radiance, n);
        *albedos += (float4)(albedo, n);
        *normals += (float4)(normal, n);
    }
    if (seen && !*PATH_SEEN(frame))
        *PATH_SEEN(frame) = 1u;
}
