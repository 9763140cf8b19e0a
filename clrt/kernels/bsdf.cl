// The path tracer's BSDF (docs/pbr-contract.md, section 2): until the bsdf
// branch lands, a Lambert-only stand-in with exactly its interface -- the
// integrator (path.cl) is written against these three functions alone.
//   bsdf_eval(b, n, ng, wo, wi)   f(wo, wi) |dot(n, wi)|
//   bsdf_pdf(b, n, ng, wo, wi)    the solid-angle pdf with which bsdf_sample picks wi
//   bsdf_sample(b, n, ng, wo, u)  wi, weight f |cos| / pdf, pdf, delta
// n: unit shading normal, ng: unit geometric normal on the triangle's front
// side; wo: unit direction toward where the path came from.  Both sides
// reflect (the lobe on wo's side of ng); light never passes through.
#ifndef CLRT_BSDF_CL
#define CLRT_BSDF_CL

typedef struct {
    float3 base_color;      // linear RGB (albedo of the diffuse lobe, F0 of the metal)
    float metallic;         // 0..1
    float alpha;            // GGX alpha = perceptual roughness^2
    float3 specular_color;  // KHR_materials_specular colour factor
    float specular_weight;  // KHR_materials_specular factor (0: pure Lambert)
    float transmission;     // 0..1
    float ior;              // of the inside (the outside is 1)
} Bsdf;

typedef struct {
    float3 wi;        // sampled direction, unit, world space
    float3 weight;    // f(wo, wi) |dot(n, wi)| / pdf
    float pdf;        // solid-angle pdf (for delta lobes: the discrete choice probability)
    int delta;        // 1: a specular (delta) lobe was sampled: no MIS with light sampling
} BsdfSample;

// The shading normal turned to wo's side of the surface; 0 where wo grazes it.
inline float3 lambert_normal(float3 n, float3 ng, float3 wo)
{
    return dot(wo, ng) < 0.0f ? -n : n;
}

inline float bsdf_pdf(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 wi)
{
    if (dot(wo, ng) * dot(wi, ng) <= 0.0f)
        return 0.0f;
    return fmax(dot(lambert_normal(n, ng, wo), wi), 0.0f) * M_1_PI_F;
}

inline float3 bsdf_eval(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 wi)
{
    return b->base_color * bsdf_pdf(b, n, ng, wo, wi);
}

// Cosine-weighted about the shading normal (Malley's method: a uniform point
// of the unit disc, lifted to the hemisphere).
inline bool bsdf_sample(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 u, BsdfSample* s)
{
    const float3 nn = lambert_normal(n, ng, wo);
    const float r = sqrt(u.x), phi = 2.0f * M_PI_F * u.y;
    const float3 t = normalize(fabs(nn.x) > 0.5f ? (float3)(nn.y, -nn.x, 0.0f) : (float3)(0.0f, nn.z, -nn.y));
    const float3 bt = cross(nn, t);
    const float3 wi = normalize(r * cos(phi) * t + r * sin(phi) * bt + sqrt(fmax(1.0f - u.x, 0.0f)) * nn);
    const float pdf = bsdf_pdf(b, n, ng, wo, wi);
    if (!(pdf > 0.0f))
        return false;
    s->wi = wi;
    s->weight = b->base_color;   // f cos / pdf = (albedo / pi) cos / (cos / pi)
    s->pdf = pdf;
    s->delta = 0;
    return true;
}

#endif
