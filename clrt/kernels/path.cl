// Entry file of the path tracer: unidirectional path tracing with next-event
// estimation, multiple importance sampling (the power heuristic) between light
// and BSDF sampling for every light that can be both hit and sampled
// (emissive triangles, the background / environment map), Russian roulette,
// and counter-based random numbers (rng.cl).  A megakernel: one work-item a
// pixel of the launch's rectangle, tracing the launch's samples of it one
// path after another, segment by segment, and adding their sums to the
// image's (so a render goes in passes of samples, and a pass's image can be
// shown); path_resolve turns the sums into the means the host reads.
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

// With -DPATH_RECORD_RAYS (clrt.renderer.path.PathTracer.record_rays, for
// benchmarks/path_rays.py): each ray a launch traces after the camera's --
// the bounces (closest hit) and the shadow rays (any hit up to the light) --
// copied to `frame` at record_at, up to record_capacity of each kind, so that
// the ray queries can be timed on the rays a path tracer really traces.
#ifdef PATH_RECORD_RAYS
#if !defined(RECORD_BOUNCE) || !defined(RECORD_SHADOW)
#error "build with the kinds' numbers, -DRECORD_BOUNCE=0u -DRECORD_SHADOW=1u (PathTracer.RECORD_KINDS)"
#endif
inline void record_ray(__global uchar* frame, const PathLaunch* launch, uint kind, float3 origin, float3 dir,
                       float tmax)
{
    __global PathRecordHead* head = (__global PathRecordHead*)(frame + launch->record_at);
    const uint k = atomic_inc(head->traced + kind);
    if (k < launch->record_capacity) {
        __global Ray* ray = (__global Ray*)(head + 1) + kind * launch->record_capacity + k;
        ray->origin = (float4)(origin, 0.0f);
        ray->dir = (float4)(dir, tmax);
    }
}
#define RECORD_RAY(frame, launch, kind, origin, dir, tmax) record_ray(frame, launch, kind, origin, dir, tmax)
#else
#define RECORD_RAY(frame, launch, kind, origin, dir, tmax)
#endif

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

// One path in flight: where its next segment starts and what it carries.
typedef struct {
    float3 origin, dir;     // of the ray of the next segment
    float3 beta;            // throughput so far
    float eta_scale;        // the eta^2 factors beta lost crossing into glass (and got back leaving it)
    float3 radiance;        // gathered so far
    float prev_pdf;         // solid-angle pdf of the BSDF sample that made the ray
    bool prev_delta;        // that choice was a delta one (the camera ray counts as one: nothing to weigh against)
    uint depth;             // of the next segment: 1 is the camera ray's
    uint sample;            // the RNG's sample index
} Path;

// The first-hit guides of a pixel's samples, summed (zeros where a camera ray leaves the scene).
typedef struct {
    float3 albedo, normal;
    bool seen;
} FirstHits;

inline Path start_path(const PathLaunch* launch, uint px, uint py, uint pixel, uint sample)
{
    const float4 jitter = random4(pixel, sample, GROUP_CAMERA, launch->seed);
    const Ray camera = camera_ray(&launch->cam, px, py, jitter.x, jitter.y);
    Path p;
    p.origin = camera.origin.xyz;
    p.dir = camera.dir.xyz;
    p.beta = (float3)(1.0f);
    p.eta_scale = 1.0f;
    p.radiance = (float3)(0.0f);
    p.prev_pdf = 0.0f;
    p.prev_delta = true;
    p.depth = 1u;
    p.sample = sample;
    return p;
}

// Trace the next segment of path p (depth p->depth, `last` the deepest): the
// hit, the emission seen there, next-event estimation and the BSDF-sampled
// continuation; true when the path has ended (p->radiance is then its sample).
inline bool path_segment(const Geometry* g, const Shading* sh, const Lights* lights, const PathLaunch* launch,
                         uint pixel, uint last, Path* p, FirstHits* first, __global uchar* frame)
{
    const uint depth = p->depth, sample = p->sample, seed = launch->seed;
    const uint strategy = launch->strategy;
    const float3 dir = p->dir;
    if (depth > 1u)
        RECORD_RAY(frame, launch, RECORD_BOUNCE, p->origin, dir, INFINITY);
    int instance;
    const Hit hit = closest_instance_hit(g, p->origin, dir, 0.0f, INFINITY, depth > 1u, &instance);
    // Light found by this BSDF-sampled ray: all of it after a delta choice
    // (nothing else could find it), else weighed against light sampling.
    if (hit.prim < 0) {
        const float3 le = background_radiance(lights, dir);
        float w = 1.0f;
        if (!p->prev_delta) {
            const float light_pdf = lights->background_probability * background_pdf(lights, dir);
            w = strategy == PATH_LIGHT ? 0.0f
              : strategy == PATH_BSDF || !(light_pdf > 0.0f) ? 1.0f : mis_weight(p->prev_pdf, light_pdf);
        }
        p->radiance += p->beta * le * w;
        return true;
    }
    SurfacePoint s = surface_point(g, sh, dir, &hit, instance);
    s.n = mapped_normal(g, sh, &s, (uint)hit.prim, hit.u, hit.v);
    __global const Material* m = sh->materials + s.material;
    const Bsdf b = material_bsdf(sh, &s, (uint)hit.prim, hit.u, hit.v);
    if (depth == 1u) {
        first->seen = true;
        first->albedo += b.base_color;
        first->normal += s.n;
    }
    const bool both = emits_both_sides(m);
    if (s.front || both) {
        const float3 le = surface_emission(sh, m, (uint)hit.prim, hit.u, hit.v);
        if (max_component(le) > 0.0f) {
            float w = 1.0f;
            if (!p->prev_delta) {
                const float cos_light = fabs(dot(s.ng, dir));
                const float light_pdf = triangle_light_area_pdf(lights, emission_factor(m), both)
                                      * hit.t * hit.t / cos_light;
                w = strategy == PATH_LIGHT ? 0.0f
                  : strategy == PATH_BSDF || !(light_pdf > 0.0f) ? 1.0f : mis_weight(p->prev_pdf, light_pdf);
            }
            p->radiance += p->beta * le * w;
        }
    }
    if (depth >= last)
        return true;
    // The BSDF's frame: the triangle's front side (glTF's counter-clockwise side).
    const float3 ng = s.front ? s.ng : -s.ng, n = s.front ? s.n : -s.n;
    const float3 wo = -dir;
    const float4 ul = random4(pixel, sample, GROUP_LIGHT(depth), seed);
    // Next-event estimation: one light, one shadow ray.
    LightSample ls;
    if (strategy != PATH_BSDF && sample_light(g, sh, lights, &s, ul.xyz, &ls)) {
        const float3 f = bsdf_eval(&b, n, ng, wo, ls.wi);
        const bool traced = max_component(f * ls.radiance) > 0.0f;
        if (traced)
            RECORD_RAY(frame, launch, RECORD_SHADOW, ls.origin, ls.wi, ls.tmax);
        if (traced && !any_hit(g, ls.origin, ls.wi, 0.0f, ls.tmax, true)) {
            const float w = ls.delta || strategy == PATH_LIGHT ? 1.0f
                          : mis_weight(ls.pdf, bsdf_pdf(&b, n, ng, wo, ls.wi));
            p->radiance += p->beta * f * ls.radiance * (w / ls.pdf);
        }
    }
    const float4 ub = random4(pixel, sample, GROUP_BSDF(depth), seed);
    BsdfSample bs;
    if (!bsdf_sample(&b, n, ng, wo, ub.xyz, &bs))
        return true;
    p->beta *= bs.weight;
    if (!(max_component(p->beta) > 0.0f))
        return true;
#ifndef BSDF_DIFFUSE_ONLY
    // Radiance refracted into a denser side is scaled by 1 / eta^2 (bsdf.cl),
    // and given back on the way out.  The roulette looks at the throughput
    // with that factor undone (pbrt-v4's etaScale): a path inside glass
    // carries no less energy, and culling it for the 1 / eta^2 would send
    // its survivors out with weights up to eta^2 -- noise, not light.
    if (dot(bs.wi, ng) * dot(wo, ng) < 0.0f) {
        const float eta2 = b.ior * b.ior;
        p->eta_scale *= dot(wo, ng) > 0.0f ? eta2 : 1.0f / eta2;   // wo on ng's side: entering
    }
#endif
    if (depth >= launch->rr_depth) {   // Russian roulette: continue with probability q
        const float q = fmin(max_component(p->beta) * p->eta_scale, 0.95f);
        if (ul.w >= q)
            return true;
        p->beta /= q;
    }
    p->prev_pdf = bs.pdf;
    p->prev_delta = bs.delta != 0;
    p->origin = spawn_origin(&s, bs.wi);
    p->dir = bs.wi;
    p->depth = depth + 1u;
    return false;
}

// One work-item a pixel of the launch's rectangle: its samples sample_first ..
// sample_first + sample_count - 1, added to the image's sums (started anew
// when samples_before is 0).  The frame's first word says whether any camera
// ray hit a triangle (renderer/visible.py's warning).
//
// The loop runs segment by segment, and a path that ends makes way for the
// pixel's next sample at once (path regeneration, Novak, Havran and
// Dachsbacher 2010): the lanes of a SIMD group then trace until all of them
// have done all their samples, instead of waiting at each sample for the
// group's longest path.  Each pixel still adds its samples in their order.
__kernel void path_trace(__global uchar* frame, const PathLaunch launch, GEOMETRY_PARAMS, SHADING_PARAMS)
{
    const uint gx = get_global_id(0), gy = get_global_id(1);
    if (gx >= launch.w || gy >= launch.h)
        return;
    const uint px = launch.x + gx, py = launch.y + gy;
    const uint pixel = py * launch.cam.width + px;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Shading sh = make_shading(SHADING_ARGS, scene);
    const Lights lights = make_lights(&launch, tables);
    const uint last = launch.max_depth < 0 ? (uint)MAX_PATH_DEPTH : (uint)launch.max_depth;
    float3 radiance = (float3)(0.0f);
    FirstHits first;
    first.albedo = first.normal = (float3)(0.0f);
    first.seen = false;
    if (last > 0u && launch.sample_count > 0u) {
        uint k = 0u;
        Path p = start_path(&launch, px, py, pixel, launch.sample_first);
        for (;;) {
            if (!path_segment(&g, &sh, &lights, &launch, pixel, last, &p, &first, frame))
                continue;
            // A sample that is not finite (a pdf that underflowed) is dropped
            // rather than let it poison the pixel's sum for good.
            if (isfinite(p.radiance.x) && isfinite(p.radiance.y) && isfinite(p.radiance.z))
                radiance += p.radiance;
            if (++k == launch.sample_count)
                break;
            p = start_path(&launch, px, py, pixel, launch.sample_first + k);
        }
    }
    const ulong i = (ulong)py * launch.cam.width + px;
    const float n = (float)launch.sample_count;
    __global float4* image = PATH_SUMS(frame, launch.image_at) + i;
    __global float4* albedos = PATH_SUMS(frame, launch.albedo_at) + i;
    __global float4* normals = PATH_SUMS(frame, launch.normal_at) + i;
    if (launch.samples_before == 0u) {
        *image = (float4)(radiance, n);
        *albedos = (float4)(first.albedo, n);
        *normals = (float4)(first.normal, n);
    } else {
        *image += (float4)(radiance, n);
        *albedos += (float4)(first.albedo, n);
        *normals += (float4)(first.normal, n);
    }
    if (first.seen && !*PATH_SEEN(frame))
        *PATH_SEEN(frame) = 1u;
}

// The means the host reads: for each pixel of the image, the first `arrays`
// of its sums (radiance, albedo, normal: PathLaunch's image_at, albedo_at,
// normal_at) over its own sample count, as packed RGB floats -- array k at
// out + 3 k pixels.  (Each pixel's count: a render that Ctrl-C ended may
// have added a last launch's samples to some rows only.)
__kernel void path_resolve(__global const uchar* frame, const PathLaunch launch, const uint arrays,
                           __global float* out)
{
    const uint i = get_global_id(0);
    const uint pixels = launch.cam.width * launch.cam.height;
    if (i >= pixels)
        return;
    const ulong at[3] = {launch.image_at, launch.albedo_at, launch.normal_at};
    const float n = fmax(PATH_SUMS(frame, launch.image_at)[i].w, 1.0f);
    for (uint k = 0u; k < arrays && k < 3u; ++k)
        vstore3(PATH_SUMS(frame, at[k])[i].xyz / n, i, out + (ulong)k * 3u * pixels);
}
