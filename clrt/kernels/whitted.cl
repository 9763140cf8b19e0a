// Whitted ray tracing without recursion: the rays still to be traced wait on
// an explicit stack, each with the weight it contributes to the pixel.
//
//   colour = local + kr * C(reflected) + kt * [F * C(reflected) + (1 - F) * colour * C(refracted)]
//
// local is Phong with shadows (shading.cl), kr the material's reflectivity,
// kt its transparency, F the Fresnel reflectance by Schlick's approximation
// (F = 1 under total internal reflection).  A ray that hits nothing adds the
// background.  Rays stop after max_depth bounces or once their weight drops
// below MIN_RAY_WEIGHT.  Each hit pops one ray and pushes at most two, one
// level deeper, so max_depth + 1 entries always suffice.
#ifndef CLRT_WHITTED_CL
#define CLRT_WHITTED_CL

#include "shading.cl"

// MAX_BOUNCES (clrt.config, a -D define): the host rejects a larger max_depth.
#define MIN_RAY_WEIGHT 1e-3f

typedef struct {
    float3 origin, dir, weight;
    uint depth;
} PendingRay;

inline PendingRay pending_ray(float3 origin, float3 dir, float3 weight, uint depth)
{
    PendingRay r;
    r.origin = origin;
    r.dir = dir;
    r.weight = weight;
    r.depth = depth;
    return r;
}

// Mirror direction of dir about n; about the geometric normal when the
// interpolated normal would send it into the surface.
inline float3 reflect_dir(float3 dir, const SurfacePoint* s)
{
    const float3 r = dir - 2.0f * dot(dir, s->n) * s->n;
    return dot(r, s->ng) > 0.0f ? r : dir - 2.0f * dot(dir, s->ng) * s->ng;
}

// Refracted direction and Fresnel reflectance (Schlick) at a surface of index
// ior, entering when s->front.  Returns F; *refracted is set when F < 1.
inline float fresnel_refract(float3 dir, const SurfacePoint* s, float3* refracted)
{
    const float ior = s->m.ior;
    const float eta = s->front ? 1.0f / ior : ior;
    float3 n = s->n;
    float cos_i = -dot(dir, n);
    if (!(cos_i > 0.0f)) {         // interpolated normal faces away: use the true one
        n = s->ng;
        cos_i = -dot(dir, n);
    }
    const float k = 1.0f - eta * eta * (1.0f - cos_i * cos_i);
    if (k < 0.0f)
        return 1.0f;               // total internal reflection
    const float cos_t = sqrt(k);
    *refracted = normalize(eta * dir + (eta * cos_i - cos_t) * n);
    const float r0 = ((ior - 1.0f) / (ior + 1.0f)) * ((ior - 1.0f) / (ior + 1.0f));
    const float c = 1.0f - (s->front ? cos_i : cos_t);   // the angle on the less dense side
    return r0 + (1.0f - r0) * c * c * c * c * c;
}

inline bool worth_tracing(float3 w)
{
    return fmax(w.x, fmax(w.y, w.z)) >= MIN_RAY_WEIGHT;
}

// Colour seen along one camera ray; *first receives the camera ray's own hit
// -- or, with `first_known`, holds it already, and with `lit_known` the
// lights that reach it are known too (bit i of `lit`): render.cl's packets of
// rays found them.
inline float3 trace_whitted(const Geometry* g, const Shading* sh, const uint max_depth,
                            float3 origin, float3 dir, float tmin, float tmax, Hit* first, const bool first_known,
                            const bool lit_known, const uint lit)
{
    PendingRay stack[MAX_BOUNCES + 1];
    int sp = 0;
    stack[sp++] = pending_ray(origin, dir, (float3)(1.0f), 0u);
    float3 color = (float3)(0.0f);
    bool camera_ray = true;
    while (sp > 0) {
        const PendingRay r = stack[--sp];
        int instance = 0;   // the hit's (packets of camera rays, first_known, walk one-level scenes only)
        const Hit hit = camera_ray && first_known ? *first
                                                  : closest_instance_hit(g, r.origin, r.dir, camera_ray ? tmin : 0.0f,
                                                                         camera_ray ? tmax : INFINITY, !camera_ray,
                                                                         &instance);
        if (camera_ray)
            *first = hit;
        const bool lights_known = camera_ray && lit_known;
        camera_ray = false;
        if (hit.prim < 0) {
            color += r.weight * sh->background.xyz;
            continue;
        }
        const SurfacePoint s = surface_point(g, sh, r.dir, &hit, instance);
        color += r.weight * local_shading(g, sh, &s, r.dir, lights_known, lit);
        const float kr = s.m.reflectivity, kt = s.m.transparency;
        if (r.depth >= max_depth || (kr <= 0.0f && kt <= 0.0f))
            continue;
        float reflect_weight = kr;
        if (kt > 0.0f) {
            float3 refracted;
            const float f = fresnel_refract(r.dir, &s, &refracted);
            reflect_weight += kt * f;
            const float3 w = r.weight * (kt * (1.0f - f)) * s.m.color.xyz;
            if (f < 1.0f && worth_tracing(w))
                stack[sp++] = pending_ray(spawn_origin(&s, refracted), refracted, w, r.depth + 1);
        }
        const float3 w = r.weight * reflect_weight;
        if (worth_tracing(w)) {
            const float3 reflected = reflect_dir(r.dir, &s);
            stack[sp++] = pending_ray(spawn_origin(&s, reflected), reflected, w, r.depth + 1);
        }
    }
    return color;
}

#endif
