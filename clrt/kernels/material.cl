// What the path tracer reads of a material: the BSDF's parameters and the
// emission -- the one place that reads the physically based fields of the
// Material rows (bytes 48.., layouts.py), so that a change of the rows
// changes this file alone.  The base colour is the Whitted model's `color`
// with its texture and corner colours (surface_point applies them); the
// metallicRoughness texture (G roughness, B metallic, linear) and the
// emissive texture (sRGB) multiply their factors in -DSURFACE_DETAIL builds.
#ifndef CLRT_MATERIAL_CL
#define CLRT_MATERIAL_CL

#include "layouts.h"
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
