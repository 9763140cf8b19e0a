// What the path tracer reads of a material: the BSDF's parameters and the
// emission -- the one place that reads the physically based fields of the
// Material rows (bytes 48.., layouts.py), so that a change of the rows
// changes this file alone.  The base colour is the Whitted model's `color`
// with its texture and corner colours (surface_point applies them); the
// metallicRoughness texture (G roughness, B metallic, linear) and the
// emissive texture (sRGB) multiply their factors in -DSURFACE_DETAIL builds,
// where the normal map (mapped_normal) bends the shading normal too.
#ifndef CLRT_MATERIAL_CL
#define CLRT_MATERIAL_CL

#include "layouts.h"
#include "geometry.cl"
#include "shading.cl"
#include "texture.cl"
#include "bsdf.cl"

#ifdef SURFACE_DETAIL
// The texture coordinates of the point (u, v) of triangle `slot`.
inline float2 surface_uv(const Shading* sh, uint slot, float u, float v)
{
    __global const TriangleDetail* d = SPLIT_AT(sh, tri_detail, slot);
    return (float2)(CORNER_BLEND(d->corner[0].w, d->corner[1].w, d->corner[2].w, u, v),
                    CORNER_BLEND(d->v.x, d->v.y, d->v.z, u, v));
}
#endif

// Normal mapping, glTF 2.0's normalTexture: the texel c (linear, 0..1) is
// the tangent-space normal 2c - 1, x towards increasing u, y towards
// increasing v (up the image: clrt's v; glTF's runs down, and the loaders
// turn it), z along the shading normal N; normal_scale multiplies x and y,
// then the vector is made unit.  glTF's TANGENT attributes are not read: the
// tangent frame is the triangle's own, from its texture coordinates (as the
// glTF sample viewer and pbrt derive it without tangents) --
// T = dp/du made perpendicular to N, B = N x T, turned to dp/dv's side, so
// that a mirrored texture layout bends its bumps the mirrored way too (the
// sign glTF's tangent.w carries).  N is the shading normal on the front
// (counter-clockwise) side; seen from the back the whole frame turns over
// with it, as glTF's viewer does for back faces.
//
// The result stays on the ray's side of the triangle: a mapped normal more
// than acos(NORMAL_MAP_MIN_COS) from the geometric normal is bent back to
// that angle (bsdf.cl then handles directions between the two planes).  A
// triangle whose texture coordinates span no area has no tangent frame and
// keeps its normal unmapped.
#define NORMAL_MAP_MIN_COS 0.02f

#ifdef SURFACE_DETAIL
// The shading normal at surface point s, the point (u, v) of triangle `slot`,
// with its material's normal map applied (s->n itself without one).
inline float3 mapped_normal(const Geometry* g, const Shading* sh, const SurfacePoint* s, uint slot,
                            float u, float v)
{
    const int texture = s->m.normal_texture;
    if (texture < 0)
        return s->n;
    __global const TriangleDetail* d = SPLIT_AT(sh, tri_detail, slot);
    float3 v0, v1, v2;   // as placed in the world (instances.cl; a one-level scene's own)
    placed_corners(g, s->instance, (int)slot, &v0, &v1, &v2);
    const float3 e1 = v1 - v0, e2 = v2 - v0;
    const float du1 = d->corner[1].w - d->corner[0].w, du2 = d->corner[2].w - d->corner[0].w;
    const float dv1 = d->v.y - d->v.x, dv2 = d->v.z - d->v.x;
    const float det = du1 * dv2 - du2 * dv1;
    if (!(fabs(det) > 0.0f))
        return s->n;
    // dp/du and dp/dv times |det|: their directions are all that is needed.
    const float side = det > 0.0f ? 1.0f : -1.0f;
    const float3 dpdu = side * (dv2 * e1 - dv1 * e2), dpdv = side * (du1 * e2 - du2 * e1);
    const float3 n = s->front ? s->n : -s->n;
    const float3 t_plane = dpdu - dot(n, dpdu) * n;
    const float t_len = length(t_plane);
    if (!(t_len > 0.0f) || !isfinite(t_len))
        return s->n;
    const float3 t = t_plane / t_len;
    float3 b = cross(n, t);
    if (dot(b, dpdv) < 0.0f)
        b = -b;
    float3 c = 2.0f * sample_texture(&sh->textures, texture, surface_uv(sh, slot, u, v)) - 1.0f;
    c.xy *= s->m.normal_scale;
    float3 m = c.x * t + c.y * b + c.z * n;
    const float len = length(m);
    if (!(len > 0.0f) || !isfinite(len))
        return s->n;
    m = (s->front ? m : -m) / len;
    const float cos_g = dot(m, s->ng);
    if (cos_g < NORMAL_MAP_MIN_COS)
        m = normalize(m + (NORMAL_MAP_MIN_COS - cos_g) * s->ng);
    return m;
}
#else
inline float3 mapped_normal(const Geometry* g, const Shading* sh, const SurfacePoint* s, uint slot,
                            float u, float v)
{
    return s->n;
}
#endif

// The BSDF at surface point s, the point (u, v) of triangle `slot`.
inline Bsdf material_bsdf(const Shading* sh, const SurfacePoint* s, uint slot, float u, float v)
{
    Bsdf b;
    b.base_color = s->m.color.xyz;
    float metallic = s->m.metallic, roughness = s->m.roughness;
#ifdef SURFACE_DETAIL
    const int texture = as_int(s->m.specular_color.w);
    if (texture >= 0) {
        const float3 mr = sample_texture(&sh->textures, texture, surface_uv(sh, slot, u, v));
        roughness *= mr.y;
        metallic *= mr.z;
    }
#endif
    b.metallic = clamp(metallic, 0.0f, 1.0f);
    b.alpha = roughness * roughness;
    b.specular_color = s->m.specular_color.xyz;
    b.specular_weight = s->m.specular_weight;
    b.transmission = s->m.transmission;
    b.ior = s->m.ior;
    return b;
}

// The emitted radiance factor of a material (its texture aside): what the
// light table's power is made of (clrt/scene/emitters.py does the same).
inline float3 emission_factor(__global const Material* m)
{
    return m->emission.xyz;
}

inline bool emits_both_sides(__global const Material* m)
{
    return (m->flags & MATERIAL_DOUBLE_SIDED) != 0u;
}

// The radiance material m emits at the point (u, v) of triangle `slot`
// (barycentric weights of its corners 1 and 2), from whichever side emits.
inline float3 surface_emission(const Shading* sh, __global const Material* m, uint slot, float u, float v)
{
    float3 e = m->emission.xyz;
#ifdef SURFACE_DETAIL
    const int texture = as_int(m->emission.w);
    if (texture >= 0 && e.x + e.y + e.z > 0.0f)
        e *= sample_texture(&sh->textures, texture, surface_uv(sh, slot, u, v));
#endif
    return e;
}

#endif
