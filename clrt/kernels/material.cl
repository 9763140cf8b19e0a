// What the path tracer reads of a material: the BSDF's parameters and the
// emission.  The one place that reads the physically based fields of the
// Material rows (docs/pbr-contract.md), so that a change of the rows changes
// this file alone.  Until the materials branch lands, the rows hold only the
// paper's Phong fields: the BSDF is Lambert with albedo colour x diffuse, and
// nothing emits.
#ifndef CLRT_MATERIAL_CL
#define CLRT_MATERIAL_CL

#include "layouts.h"
#include "shading.cl"
#include "bsdf.cl"

// The BSDF at surface point s (its colour already textured by surface_point).
inline Bsdf material_bsdf(const SurfacePoint* s)
{
    Bsdf b;
    b.base_color = fmin(s->m.color.xyz * s->m.diffuse, (float3)(1.0f));
    b.metallic = 0.0f;
    b.alpha = 1.0f;
    b.specular_color = (float3)(1.0f);
    b.specular_weight = 0.0f;
    b.transmission = 0.0f;
    b.ior = s->m.ior;
    return b;
}

// The emitted radiance factor of a material (its texture aside): what the
// light table's power is made of (clrt/scene/emitters.py does the same).
inline float3 emission_factor(__global const Material* m)
{
    return (float3)(0.0f);
}

inline bool emits_both_sides(__global const Material* m)
{
    return false;
}

// The radiance material m emits at the point (u, v) of triangle `slot`
// (barycentric weights of its corners 1 and 2), from whichever side emits.
inline float3 surface_emission(const Shading* sh, __global const Material* m, uint slot, float u, float v)
{
    return emission_factor(m);
}

#endif
