// The path tracer's lights (path.cl): what each kind sends towards a point,
// how it is sampled, and the pdf with which a direction would have been
// sampled (for multiple importance sampling).  One table of LightEntry rows
// holds every light -- point and spot lights, emissive triangles, the
// background -- and is sampled by Walker's alias method in proportion to each
// light's power (the host builds it: clrt/scene/emitters.py):
//   point, spot      intensity I: L = I falloff / d^2 (a delta light: never hit)
//   triangle         area-uniform points; emission leaves the front face
//                    (counter-clockwise side) only, both for MATERIAL_DOUBLE_SIDED
//   background       a constant radiance: uniform directions; or an
//                    equirectangular environment map: a texel by its rows'
//                    marginal and its row's conditional CDF (luminance x
//                    sin(theta), the host's tables), a uniform point within it
#ifndef CLRT_LIGHTS_CL
#define CLRT_LIGHTS_CL

#include "layouts.h"
#include "shading.cl"
#include "material.cl"

// The light tables of one launch (PathLaunch's fields, pointers made once).
typedef struct {
    __global const LightEntry* entries;
    uint num_entries;
    float inv_power;
    float background_probability;
    float3 background;             // the constant background (no map)
    __global const float4* env;    // the map's texels, row 0 at the top (theta = 0, +y)
    __global const float* marginal;
    __global const float* conditional;
    uint env_width, env_height;
    float turn_cos, turn_sin, strength;
} Lights;

inline Lights make_lights(const PathLaunch* launch, __global const uchar* tables)
{
    Lights l;
    l.entries = (__global const LightEntry*)(tables + launch->entries_at);
    l.num_entries = launch->num_entries;
    l.inv_power = launch->inv_power;
    l.background_probability = launch->environment.w;
    l.background = launch->background.xyz;
    l.env = (__global const float4*)(tables + launch->env_at);
    l.marginal = (__global const float*)(tables + launch->marginal_at);
    l.conditional = (__global const float*)(tables + launch->conditional_at);
    l.env_width = launch->env_width;
    l.env_height = launch->env_height;
    l.turn_cos = launch->environment.x;
    l.turn_sin = launch->environment.y;
    l.strength = launch->environment.z;
    return l;
}

// What a light sample gives the integrator.
typedef struct {
    float3 wi;          // unit, from the shading point towards the light
    float3 origin;      // of the shadow ray (spawn_origin)
    float tmax;         // its length (INFINITY: the background)
    float3 radiance;    // arriving along -wi, before visibility
    float pdf;          // solid angle, the choice of the light included; delta: the choice's probability
    int delta;
} LightSample;

inline float luminance(float3 c)
{
    return dot(c, (float3)(0.2126f, 0.7152f, 0.0722f));
}

// ----------------------------------------------------------------------------- the environment map
//
// Direction d (world space) -> map coordinates: the map is turned by the
// launch's angle about +y, then u = 0.5 + atan2(x, -z) / 2 pi (the image's
// middle column looks along -z, u grows towards +x) and v = acos(y) / pi
// (row 0 at the top, +y).  Texels are nearest (the pdf is constant over a
// texel, as the sampling is).

inline float3 env_to_map(const Lights* l, float3 d)
{
    return (float3)(l->turn_cos * d.x - l->turn_sin * d.z, d.y, l->turn_sin * d.x + l->turn_cos * d.z);
}

inline float3 env_from_map(const Lights* l, float3 d)
{
    return (float3)(l->turn_cos * d.x + l->turn_sin * d.z, d.y, -l->turn_sin * d.x + l->turn_cos * d.z);
}

// The texel column and row of map direction d, and sin(theta) there.
inline uint2 env_texel(const Lights* l, float3 d, float* sin_theta)
{
    const float u = 0.5f + atan2(d.x, -d.z) * (0.5f * M_1_PI_F);
    const float v = acos(clamp(d.y, -1.0f, 1.0f)) * M_1_PI_F;
    *sin_theta = sqrt(fmax(1.0f - d.y * d.y, 0.0f));
    const uint col = min((uint)fmax(u * (float)l->env_width, 0.0f), l->env_width - 1u);
    const uint row = min((uint)fmax(v * (float)l->env_height, 0.0f), l->env_height - 1u);
    return (uint2)(col, row);
}

// Radiance arriving from the background along -d (d: unit, pointing away from the scene).
inline float3 background_radiance(const Lights* l, float3 d)
{
    if (l->env_width == 0u)
        return l->background;
    float sin_theta;
    const uint2 t = env_texel(l, env_to_map(l, d), &sin_theta);
    return l->strength * l->env[t.y * l->env_width + t.x].xyz;
}

// The CDF cell that u falls in: the largest i < n with cdf[i] <= u (cdf[0] =
// 0, cdf[n] = 1), so empty cells (cdf[i] == cdf[i + 1]) are never chosen.
inline uint cdf_find(__global const float* cdf, uint n, float u)
{
    uint lo = 0u, hi = n;
    while (lo + 1u < hi) {
        const uint mid = (lo + hi) >> 1;
        if (cdf[mid] <= u)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

// Solid-angle pdf with which background_sample picks direction d, without the
// choice of the background among the lights.
inline float background_pdf(const Lights* l, float3 d)
{
    if (l->env_width == 0u)
        return 0.25f * M_1_PI_F;
    float sin_theta;
    const uint2 t = env_texel(l, env_to_map(l, d), &sin_theta);
    if (!(sin_theta > 0.0f))
        return 0.0f;
    const uint w = l->env_width, h = l->env_height;
    const float row = l->marginal[t.y + 1u] - l->marginal[t.y];
    __global const float* c = l->conditional + t.y * (w + 1u);
    const float col = c[t.x + 1u] - c[t.x];
    return row * col * (float)(w * h) / (2.0f * M_PI_F * M_PI_F * sin_theta);
}

// A direction towards the background and its pdf (solid angle, without the choice).
inline float3 background_sample(const Lights* l, float2 u, float* pdf)
{
    if (l->env_width == 0u) {   // uniform over the sphere
        const float z = 1.0f - 2.0f * u.x, r = sqrt(fmax(1.0f - z * z, 0.0f)), phi = 2.0f * M_PI_F * u.y;
        *pdf = 0.25f * M_1_PI_F;
        return (float3)(r * cos(phi), r * sin(phi), z);
    }
    const uint w = l->env_width, h = l->env_height;
    const uint row = cdf_find(l->marginal, h, u.x);
    __global const float* c = l->conditional + row * (w + 1u);
    const uint col = cdf_find(c, w, u.y);
    // Where u fell within the chosen cells: the point within the texel.
    const float fy = clamp((u.x - l->marginal[row]) / (l->marginal[row + 1u] - l->marginal[row]), 0.0f, 1.0f);
    const float fx = clamp((u.y - c[col]) / (c[col + 1u] - c[col]), 0.0f, 1.0f);
    const float theta = M_PI_F * ((float)row + fy) / (float)h;
    const float phi = 2.0f * M_PI_F * (((float)col + fx) / (float)w - 0.5f);
    const float st = sin(theta);
    const float3 m = (float3)(st * sin(phi), cos(theta), -st * cos(phi));
    const float3 d = env_from_map(l, m);
    *pdf = background_pdf(l, d);   // the texel d lands in (the same one but at its edges)
    return d;
}

// ----------------------------------------------------------------------------- emissive triangles

// The area pdf of light sampling at a point of an emissive triangle: the
// probability with which the table picks it (its power, pi x luminance of its
// material's emission factor x area x sides, over all lights' power, as the
// host computes it) over its area -- so the area cancels.
inline float triangle_light_area_pdf(const Lights* l, float3 emission_factor, bool both)
{
    return M_PI_F * luminance(emission_factor) * (both ? 2.0f : 1.0f) * l->inv_power;
}

// ----------------------------------------------------------------------------- sampling a light

// A light for the surface point s, chosen from the table by u.x and sampled by
// u.yz; false when it sends nothing towards s.
inline bool sample_light(const Geometry* g, const Shading* sh, const Lights* l, const SurfacePoint* s, float3 u,
                         LightSample* out)
{
    if (l->num_entries == 0u)
        return false;
    const float x = u.x * (float)l->num_entries;
    const uint i = min((uint)x, l->num_entries - 1u);
    __global const LightEntry* e = l->entries + i;
    if (x - (float)i >= e->threshold)
        e = l->entries + e->alias;
    const float chosen = e->probability;
    if (e->kind == LIGHT_POINT) {
        __global const Light* light = sh->lights + e->index;
        const float3 at = light->position.xyz;
        out->origin = spawn_origin(s, at - s->p);
        const float3 to = at - out->origin;
        const float d2 = dot(to, to);
        out->tmax = sqrt(d2);
        out->wi = to / out->tmax;
        float3 intensity = light->color.xyz;
        if (light->cos_outer > -1.0f)
            intensity *= spot_falloff(light, -out->wi);
        out->radiance = intensity / d2;
        out->pdf = chosen;
        out->delta = 1;
        return d2 > 0.0f;
    }
    if (e->kind == LIGHT_TRIANGLE) {
        const uint slot = (uint)e->index;
        __global const Material* m = sh->materials + triangle_material(g, sh, e->instance, slot);
        float3 v0, v1, v2;   // (a two-level scene's: placed by the entry's instance)
        placed_corners(g, e->instance, slot, &v0, &v1, &v2);
        // Area-uniform: b0 = 1 - sqrt(u1), b1 = u2 sqrt(u1) (weights of v0, v1).
        const float su = sqrt(u.y);
        const float w1 = u.z * su, w2 = 1.0f - (1.0f - su) - w1;
        const float3 y = (1.0f - su) * v0 + w1 * v1 + w2 * v2;
        const float3 c = cross(v1 - v0, v2 - v0);
        const float area2 = length(c);
        if (!(area2 > 0.0f))
            return false;
        const float3 front = c / area2;
        out->origin = spawn_origin(s, y - s->p);
        const float3 to = y - out->origin;
        const float d2 = dot(to, to);
        const float d = sqrt(d2);
        out->wi = to / d;
        const float cos_light = -dot(front, out->wi);   // > 0: the point sees the front face
        const bool both = emits_both_sides(m);
        if (!(cos_light > 0.0f || (both && cos_light < 0.0f)))
            return false;
        const float3 emission = surface_emission(sh, m, slot, w1, w2);
        // Stop short of the light itself, by its points' float32 error.
        out->tmax = d * (1.0f - 1e-4f);
        out->radiance = emission;
        out->pdf = chosen * 2.0f / area2 * d2 / fabs(cos_light);
        out->delta = 0;
        return out->pdf > 0.0f;
    }
    float pdf;
    out->wi = background_sample(l, u.yz, &pdf);
    out->origin = spawn_origin(s, out->wi);
    out->tmax = INFINITY;
    out->radiance = background_radiance(l, out->wi);
    out->pdf = chosen * pdf;
    out->delta = 0;
    return out->pdf > 0.0f;
}

#endif
