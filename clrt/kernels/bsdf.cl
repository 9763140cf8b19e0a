// The path tracer's BSDF: glTF 2.0 metallic-roughness (the specification's
// Appendix B) with KHR_materials_specular, KHR_materials_ior and
// KHR_materials_transmission (as a solid dielectric, see below).  With
// dielectric = 1 - metallic and, per half vector h, c = |wo.h| and the
// Schlick weight x = (1 - c)^5:
//
//   f =  dielectric (1 - transmission) W(wo, wi) base / pi            Lambert base
//      + dielectric s Fd D Vis                                         dielectric specular layer
//      + metallic  Fm D Vis                                             metal, Fm = base + (1 - base) x
//      + dielectric transmission (1 - s max(Fd)) base BTDF             rough or smooth refraction
//
//   Fd = f0 + (1 - f0) x,  f0 = min(((ior - 1) / (ior + 1))^2 specular_color, 1)
//
// s = specular_weight (KHR_materials_specular: it scales the layer and frees
// energy for the base; s = 0 leaves pure Lambert), D = GGX (sampling.cl),
// Vis = G2 / (4 |wo.z| |wi.z|) with the height-correlated Smith G2 (the
// appendix writes the separable G1 G1; its sample viewer, Mitsuba and pbrt
// use the height-correlated form, which is what issue #35 asks for).  The
// BTDF is Walter, Marschner, Li, Torrance 2007 with the same D and G2, scaled
// for radiance (1 / eta^2 across the boundary), tinted by base colour at each
// crossing; reflection and refraction share each facet's Fresnel exactly as
// glTF's fresnel_mix writes it.
//
// The one departure from Appendix B is W, the Lambert base's share.  The
// appendix's fresnel_mix gives it 1 - s max(F(wo.h)); with h the half vector
// of two directions that is larger than what the layer leaves at grazing
// views, and a white plastic reflects more than arrives (1.2 times at 75
// degrees, 1.85 at 89 degrees when smooth).  Here the base gets what the
// layer leaves at both ends, reciprocal and normalised (Kelemen and
// Szirmay-Kalos 2001; Kulla and Conty 2017):
//
//   W = (1 - s E(wo)) (1 - s E(wi)) / (1 - s E_avg)
//
// E is the layer's directional albedo (its D, G2 and Fresnel integrated; a
// table, bsdf_albedo.cl) at the largest f0 of the three channels, E_avg its
// hemispherical average; the base then reflects exactly 1 - s E(wo) of white
// light, so layer and base together reflect all of it.  The same as the
// appendix at normal view (1 - f0 either way for a smooth layer).
//
// Sides.  ng decides: wo on ng's side is outside (entering, eta = ior), wo on
// the other side is inside (leaving, eta = 1 / ior).  That only matters for
// transmissive materials (transmission > 0: a closed solid of index ior, not
// glTF's thin wall); an opaque material is two-sided, the same seen from both
// faces.  Inside, Schlick's F uses the cosine on the outer side (the refracted
// one), and F = 1 under total internal reflection; W takes E at f0 = 1 there.
//
// Shading normals.  Everything is evaluated in the frame of the shading
// normal n turned to wo's side.  If wo is not above that plane (a normal map
// or interpolated normal tilted past wo), the geometric normal replaces it.
// A direction wi counts as reflected only if it is above both the geometric
// and the shading plane, as transmitted only if below both; in the wedge
// where the two disagree the BSDF is 0 and sampling fails.  So no light leaks
// through the surface, at the price of some energy lost near grazing angles
// on strongly bent normals (and reflection is reciprocal only where n = ng).
//
// Delta lobes.  Below BSDF_DELTA_ALPHA the microfacet lobes are perfectly
// smooth: mirror reflection and Snell refraction, sampled only (bsdf_eval and
// bsdf_pdf give 0 for them, BsdfSample.delta = 1).
//
// Sampling.  Two lobes, chosen by their albedos estimated from wo alone
// (Fresnel at c = wo.z; each lobe that can contribute at least
// BSDF_MIN_LOBE_PROBABILITY): diffuse (cosine-weighted) with probability
// p_diffuse, else the microfacet lobe: a visible normal h (sampling.cl), then
// reflection or refraction about h with probability proportional to their
// weights at h (R: s mean(Fd) dielectric + mean(Fm) metallic; T:
// refraction's weight above, 0 under total internal reflection).  bsdf_pdf
// returns this whole mixture's density, and a non-delta sample's weight is
// bsdf_eval / bsdf_pdf of the mixture, so the integrator's MIS sees one
// consistent strategy.
//
// Single scattering: light that bounces between microfacets is lost, so rough
// metal and rough glass reflect less than their colour (docs/path-tracing.md,
// "Materials", gives the figures); the dielectric's base takes what its
// layer loses, so white plastic keeps all energy.
#ifndef CLRT_BSDF_CL
#define CLRT_BSDF_CL

#include "sampling.cl"
#include "bsdf_albedo.cl"

// GGX alpha below which the microfacet lobes are treated as perfectly smooth
// (delta).  At alpha = 1e-3 (perceptual roughness 0.03) the lobe is a few
// tenths of a degree wide: narrower than a pixel in most views, and D's peak
// (1 / (pi alpha^2) = 3e5) is still well inside float32.
#define BSDF_DELTA_ALPHA 1e-3f
// Refraction needs the two indices apart: at ior -> 1 the rough BTDF's
// Jacobian diverges (every facet refracts straight on).  Indices closer to 1
// than this are moved to 1 +- BSDF_MIN_IOR_CONTRAST (a nearly straight,
// slightly blurred pass) for refraction; Fresnel's f0 keeps the given ior.
#define BSDF_MIN_IOR_CONTRAST 1e-2f
// Each lobe that can contribute is sampled at least this often, so that a poor
// Fresnel estimate never leaves a lobe (nearly) unsampled.
#define BSDF_MIN_LOBE_PROBABILITY 0.05f

typedef struct {
    float3 base_color;      // linear RGB (albedo of the diffuse lobe, F0 of the metal)
    float metallic;         // 0..1
    float alpha;            // GGX alpha = perceptual roughness^2 (the BSDF clamps tiny alphas itself)
    float3 specular_color;  // KHR_materials_specular colour factor
    float specular_weight;  // KHR_materials_specular factor (0: pure Lambert)
    float transmission;     // 0..1: weight of the dielectric (smooth or rough by alpha) transmission lobe
    float ior;              // of the inside (the outside is 1)
} Bsdf;

typedef struct {
    float3 wi;        // sampled direction, unit, world space
    float3 weight;    // f(wo, wi) |dot(n, wi)| / pdf
    float pdf;        // solid-angle pdf (for delta lobes: the discrete choice probability)
    int delta;        // 1: a specular (delta) lobe was sampled: no MIS with light sampling
} BsdfSample;

// One shading point's BSDF in its local frame, set up once from (Bsdf, n, ng, wo).
typedef struct {
    Frame frame;          // z: the shading normal on wo's side (or the geometric normal)
    float3 ng;            // geometric normal on wo's side, world space
    float3 wo;            // wo in the frame: wo.z > 0
    float3 base;          // base colour, >= 0
    float3 f0;            // dielectric f0: min(((ior - 1) / (ior + 1))^2 specular_color, 1)
    float metallic, alpha, specular, transmission;
    float eta;            // index of the side a refracted wi enters over wo's side
    int opaque;           // transmission == 0: two-sided, Schlick on c as glTF writes it
    int delta;            // alpha < BSDF_DELTA_ALPHA
    float layer_f0;       // the f0 and alpha the layer's albedo is looked up with (see bsdf_setup)
    float layer_alpha;
    float base_o;         // 1 - s E(wo.z): what the specular layer leaves for the base from wo
    float base_scale;     // 1 / (1 - s E_avg), 0 where the layer leaves nothing
    float p_diffuse;      // probability of the diffuse lobe (else the microfacet lobe)
} BsdfLocal;

inline float rgb_mean(float3 c) { return (c.x + c.y + c.z) * (1.0f / 3.0f); }
inline float rgb_max(float3 c) { return fmax(c.x, fmax(c.y, c.z)); }
inline float unit_clamp(float x) { return fmin(fmax(x, 0.0f), 1.0f); }   // NaN -> 0

inline float3 schlick_fresnel(float3 f0, float c)
{
    const float m = unit_clamp(1.0f - c);
    const float m2 = m * m;
    return f0 + (1.0f - f0) * (m2 * m2 * m);
}

// Cosine of the refracted direction for a facet met at cosine c (> 0) from a
// side of index 1 into one of index eta; -1 under total internal reflection.
inline float refracted_cosine(float c, float eta)
{
    const float sin2 = (1.0f - c * c) / (eta * eta);
    return sin2 < 1.0f ? sqrt(1.0f - sin2) : -1.0f;
}

// The cosine Schlick's approximation takes at a facet met at cosine c.
// Schlick's form is for light arriving from the side of lower index: when wo
// is on the denser side (eta < 1) that is the refracted cosine, and under
// total internal reflection 0 (F = 1).  Opaque materials take c (glTF).
inline float schlick_cosine(const BsdfLocal* L, float c)
{
    if (L->opaque || L->eta >= 1.0f)
        return c;
    return fmax(refracted_cosine(c, L->eta), 0.0f);
}

inline float3 dielectric_fresnel(const BsdfLocal* L, float c)
{
    return schlick_fresnel(L->f0, schlick_cosine(L, c));
}

// Weights of reflection and refraction at a facet met at cosine c: the
// microfacet lobe picks between them in this proportion.  T is 0 where
// refraction cannot happen (opaque, total internal reflection).
inline float reflect_probability(const BsdfLocal* L, float c)
{
    const float dielectric = 1.0f - L->metallic;
    const float3 fd = dielectric_fresnel(L, c);
    const float r = dielectric * L->specular * rgb_mean(fd)
                  + L->metallic * rgb_mean(schlick_fresnel(L->base, c));
    float t = 0.0f;
    if (!L->opaque && refracted_cosine(c, L->eta) >= 0.0f)
        t = dielectric * L->transmission * (1.0f - L->specular * rgb_max(fd)) * rgb_mean(L->base);
    return r + t > 0.0f ? r / (r + t) : 1.0f;
}

// The layer's directional albedo E(c, alpha, f0) = f0 A + (1 - f0) B and its
// hemispherical average, bilinear in (sqrt(c), alpha^(1/4)) on the tables of
// bsdf_albedo.cl (their rows and columns are equal steps of those).
inline float layer_albedo(float c, float alpha, float f0)
{
    const float x = sqrt(unit_clamp(c)) * (float)(LAYER_ALBEDO_COSINES - 1);
    const float y = sqrt(sqrt(alpha)) * (float)(LAYER_ALBEDO_ROUGHNESSES - 1);
    const int i = min((int)x, LAYER_ALBEDO_COSINES - 2), j = min((int)y, LAYER_ALBEDO_ROUGHNESSES - 2);
    const float fx = x - (float)i, fy = y - (float)j;
    const float a = mix(mix(LAYER_ALBEDO_A[j][i], LAYER_ALBEDO_A[j][i + 1], fx),
                        mix(LAYER_ALBEDO_A[j + 1][i], LAYER_ALBEDO_A[j + 1][i + 1], fx), fy);
    const float b = mix(mix(LAYER_ALBEDO_B[j][i], LAYER_ALBEDO_B[j][i + 1], fx),
                        mix(LAYER_ALBEDO_B[j + 1][i], LAYER_ALBEDO_B[j + 1][i + 1], fx), fy);
    return f0 * a + (1.0f - f0) * b;
}

inline float layer_albedo_average(float alpha, float f0)
{
    const float y = sqrt(sqrt(alpha)) * (float)(LAYER_ALBEDO_ROUGHNESSES - 1);
    const int j = min((int)y, LAYER_ALBEDO_ROUGHNESSES - 2);
    const float fy = y - (float)j;
    const float a = mix(LAYER_ALBEDO_A_AVERAGE[j], LAYER_ALBEDO_A_AVERAGE[j + 1], fy);
    const float b = mix(LAYER_ALBEDO_B_AVERAGE[j], LAYER_ALBEDO_B_AVERAGE[j + 1], fy);
    return f0 * a + (1.0f - f0) * b;
}

inline bool bsdf_setup(const Bsdf* b, float3 n, float3 ng, float3 wo, BsdfLocal* L)
{
    const float cos_g = dot(wo, ng);
    if (!(fabs(cos_g) > 0.0f))        // along the surface, or NaN
        return false;
    const float3 ng_wo = cos_g > 0.0f ? ng : -ng;
    float3 ns = normalize(dot(n, ng_wo) < 0.0f ? -n : n);
    if (!(dot(wo, ns) > 0.0f))       // wo below the shading plane (or n unusable)
        ns = ng_wo;
    L->frame = frame_from_normal(ns);
    L->ng = ng_wo;
    L->wo = frame_to_local(&L->frame, wo);
    L->wo.z = fmax(L->wo.z, FLT_MIN);   // > 0 as tested, whatever the rounding of the frame

    L->base = fmax(b->base_color, 0.0f);
    L->metallic = unit_clamp(b->metallic);
    L->alpha = unit_clamp(b->alpha);
    L->specular = unit_clamp(b->specular_weight);
    L->transmission = unit_clamp(b->transmission);
    L->delta = L->alpha < BSDF_DELTA_ALPHA;
    L->opaque = !(L->transmission > 0.0f);
    // glTF's default ior where the value is unusable; 0 (allowed by glTF) gives f0 = 1.
    const float ior = isfinite(b->ior) && b->ior >= 0.0f ? b->ior : 1.5f;
    const float r = (ior - 1.0f) / (ior + 1.0f);
    L->f0 = fmin(r * r * fmax(b->specular_color, 0.0f), 1.0f);
    float ior_t = ior >= 1.0f ? fmax(ior, 1.0f + BSDF_MIN_IOR_CONTRAST)
                              : fmin(fmax(ior, FLT_MIN), 1.0f / (1.0f + BSDF_MIN_IOR_CONTRAST));
    L->eta = cos_g > 0.0f || L->opaque ? ior_t : 1.0f / ior_t;

    // Lobe weights estimated with Fresnel at c = wo.z.
    const float dielectric = 1.0f - L->metallic;
    const float3 fd = dielectric_fresnel(L, L->wo.z);
    // The Lambert base's share (top of the file): the layer's albedo taken at the
    // largest f0 of the three channels; inside a transmissive material at f0 = 1
    // (total internal reflection makes the layer nearly a mirror there: an upper bound).
    // A delta layer is a mirror without masking: the tables' alpha = 0 row.
    L->layer_f0 = cos_g > 0.0f || L->opaque ? rgb_max(L->f0) : 1.0f;
    L->layer_alpha = L->delta ? 0.0f : L->alpha;
    L->base_o = 1.0f - L->specular * layer_albedo(L->wo.z, L->layer_alpha, L->layer_f0);
    const float average_left = 1.0f - L->specular * layer_albedo_average(L->layer_alpha, L->layer_f0);
    L->base_scale = average_left > 1e-6f ? 1.0f / average_left : 0.0f;
    const float w_diffuse = dielectric * (1.0f - L->transmission) * L->base_o * rgb_mean(L->base);
    const float w_micro = dielectric * L->specular * rgb_mean(fd)
                        + L->metallic * rgb_mean(schlick_fresnel(L->base, L->wo.z))
                        + dielectric * (1.0f - L->specular * rgb_max(fd)) * L->transmission * rgb_mean(L->base);
    // Can the lobe be non-zero for some wi?  (Fd >= f0, so 1 - s max(f0) bounds refraction's share.)
    const bool diffuse_on = dielectric * (1.0f - L->transmission) * rgb_max(L->base) * L->base_scale > 0.0f;
    const bool micro_on = dielectric * L->specular > 0.0f || L->metallic > 0.0f
                       || dielectric * (1.0f - L->specular * rgb_max(L->f0)) * L->transmission * rgb_max(L->base) > 0.0f;
    if (!diffuse_on && !micro_on)
        return false;
    if (!micro_on)
        L->p_diffuse = 1.0f;
    else if (!diffuse_on)
        L->p_diffuse = 0.0f;
    else {
        const float sum = w_diffuse + w_micro;
        L->p_diffuse = clamp(sum > 0.0f ? w_diffuse / sum : 0.5f,
                             BSDF_MIN_LOBE_PROBABILITY, 1.0f - BSDF_MIN_LOBE_PROBABILITY);
    }
    return true;
}

// 1: wi is reflected (above both planes), -1: transmitted (below both), 0: in
// the wedge where geometric and shading normal disagree (no contribution).
inline int bsdf_side(const BsdfLocal* L, float3 wi_world, float3 wi)
{
    const float g = dot(wi_world, L->ng);
    if (g > 0.0f && wi.z > 0.0f)
        return 1;
    if (g < 0.0f && wi.z < 0.0f)
        return -1;
    return 0;
}

// The half vector of a refraction from wo into wi (Walter et al. 2007, eq. 16)
// turned to +z; the pair is a refraction through it only if wo.h > 0 > wi.h.
inline float3 refraction_half_vector(float3 wo, float3 wi, float eta)
{
    const float3 h = normalize(wo + eta * wi);
    return h.z < 0.0f ? -h : h;
}

// f(wo, wi) |wi.z| (non-delta lobes) for wi on `side`.
inline float3 bsdf_eval_local(const BsdfLocal* L, float3 wi, int side)
{
    const float3 wo = L->wo;
    const float dielectric = 1.0f - L->metallic;
    if (side > 0) {
        const float3 h = normalize(wo + wi);
        const float c = dot(wo, h);
        const float3 fd = dielectric_fresnel(L, c);
        // Lambert under the layer: what the layer leaves at both ends (top of the file)
        const float base_i = 1.0f - L->specular * layer_albedo(wi.z, L->layer_alpha, L->layer_f0);
        float3 f = (dielectric * (1.0f - L->transmission) * L->base_o * base_i * L->base_scale * M_1_PI_F * wi.z)
                   * L->base;
        if (!L->delta) {
            // D Vis |wi.z| = D G2 / (4 wo.z)
            const float spec = 0.25f * ggx_d(h, L->alpha) * ggx_g2_over_cos_o(wo, wi, L->alpha);
            f += (dielectric * L->specular * fd + L->metallic * schlick_fresnel(L->base, c)) * spec;
        }
        return f;
    }
    if (side < 0 && !L->delta && !L->opaque) {
        const float3 h = refraction_half_vector(wo, wi, L->eta);
        const float co = dot(wo, h), ci = dot(wi, h);
        if (!(co > 0.0f && ci < 0.0f))
            return (float3)(0.0f);
        const float3 fd = dielectric_fresnel(L, co);
        const float den = L->eta * ci + co;
        // Walter's BTDF for radiance times |wi.z|: D G2 |wi.h| |wo.h| / (|wo.z| (eta wi.h + wo.h)^2)
        const float btdf = ggx_d(h, L->alpha) * ggx_g2_over_cos_o(wo, wi, L->alpha) * (-ci) * co / (den * den);
        return (dielectric * L->transmission * (1.0f - L->specular * rgb_max(fd)) * btdf) * L->base;
    }
    return (float3)(0.0f);
}

// The density with which bsdf_sample_local draws wi (non-delta lobes).
inline float bsdf_pdf_local(const BsdfLocal* L, float3 wi, int side)
{
    const float3 wo = L->wo;
    const float p_micro = 1.0f - L->p_diffuse;
    if (side > 0) {
        float pdf = L->p_diffuse * cosine_hemisphere_pdf(wi);
        if (!L->delta && p_micro > 0.0f) {
            const float3 h = normalize(wo + wi);
            // visible-normal density D_wo(h) times the reflection Jacobian 1 / (4 wo.h)
            pdf += p_micro * reflect_probability(L, dot(wo, h))
                 * 0.5f * ggx_d(h, L->alpha) / (wo.z + ggx_root(wo, L->alpha));
        }
        return pdf;
    }
    if (side < 0 && !L->delta && !L->opaque && p_micro > 0.0f) {
        const float3 h = refraction_half_vector(wo, wi, L->eta);
        const float co = dot(wo, h), ci = dot(wi, h);
        if (!(co > 0.0f && ci < 0.0f))
            return 0.0f;
        const float den = L->eta * ci + co;
        // D_wo(h) times the refraction Jacobian eta^2 |wi.h| / (eta wi.h + wo.h)^2
        return p_micro * (1.0f - reflect_probability(L, co)) * ggx_visible_normal_pdf(wo, h, L->alpha)
             * L->eta * L->eta * (-ci) / (den * den);
    }
    return 0.0f;
}

#ifdef BSDF_DIFFUSE_ONLY
// Every material of the scene scatters by its Lambert base alone -- no metal,
// no specular layer, no transmission (the host defines BSDF_DIFFUSE_ONLY
// then: clrt/renderer/path.py, bsdf_defines).  The general functions below
// give such a material exactly this: its diffuse lobe chosen with probability
// 1, weights of 1 on the base (base_o, base_i, base_scale), the same frame,
// the same side test and the same cosine warp of u.xy.  Written apart, the
// megakernel holds none of the microfacet code's state: on the H200 that
// decides how many of its warps fit (the register cap, path.py).
inline bool diffuse_setup(const Bsdf* b, float3 n, float3 ng, float3 wo, BsdfLocal* L)
{
    const float cos_g = dot(wo, ng);
    if (!(fabs(cos_g) > 0.0f))
        return false;
    const float3 ng_wo = cos_g > 0.0f ? ng : -ng;
    float3 ns = normalize(dot(n, ng_wo) < 0.0f ? -n : n);
    if (!(dot(wo, ns) > 0.0f))
        ns = ng_wo;
    L->frame = frame_from_normal(ns);
    L->ng = ng_wo;
    L->base = fmax(b->base_color, 0.0f);
    return rgb_max(L->base) > 0.0f;
}

float3 bsdf_eval(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 wi)
{
    BsdfLocal L;
    if (!diffuse_setup(b, n, ng, wo, &L))
        return (float3)(0.0f);
    const float3 wl = frame_to_local(&L.frame, wi);
    return bsdf_side(&L, wi, wl) > 0 ? (M_1_PI_F * wl.z) * L.base : (float3)(0.0f);
}

float bsdf_pdf(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 wi)
{
    BsdfLocal L;
    if (!diffuse_setup(b, n, ng, wo, &L))
        return 0.0f;
    const float3 wl = frame_to_local(&L.frame, wi);
    return bsdf_side(&L, wi, wl) > 0 ? cosine_hemisphere_pdf(wl) : 0.0f;
}

bool bsdf_sample(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 u, BsdfSample* s)
{
    BsdfLocal L;
    if (!diffuse_setup(b, n, ng, wo, &L))
        return false;
    const float3 wi = square_to_cosine_hemisphere(u.xy);
    const float3 wi_world = frame_to_world(&L.frame, wi);
    if (bsdf_side(&L, wi_world, wi) != 1)
        return false;
    const float pdf = cosine_hemisphere_pdf(wi);
    if (!(pdf > 0.0f) || !isfinite(pdf))
        return false;
    s->wi = wi_world;
    s->weight = ((M_1_PI_F * wi.z) * L.base) / pdf;
    s->pdf = pdf;
    s->delta = 0;
    return true;
}
#else
float3 bsdf_eval(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 wi)
{
    BsdfLocal L;
    if (!bsdf_setup(b, n, ng, wo, &L))
        return (float3)(0.0f);
    const float3 wl = frame_to_local(&L.frame, wi);
    return bsdf_eval_local(&L, wl, bsdf_side(&L, wi, wl));
}

float bsdf_pdf(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 wi)
{
    BsdfLocal L;
    if (!bsdf_setup(b, n, ng, wo, &L))
        return 0.0f;
    const float3 wl = frame_to_local(&L.frame, wi);
    return bsdf_pdf_local(&L, wl, bsdf_side(&L, wi, wl));
}

// u.xy: the direction (cosine warp or visible normal); u.z: the lobe, then,
// rescaled, reflection or refraction.  Returns false when no direction comes
// out (a reflection below or a refraction above the surface, a sample in the
// wedge of disagreeing normals, a zero density, a material that scatters
// nothing; refraction under total internal reflection is never chosen); s is
// then untouched.
bool bsdf_sample(const Bsdf* b, float3 n, float3 ng, float3 wo, float3 u, BsdfSample* s)
{
    BsdfLocal L;
    if (!bsdf_setup(b, n, ng, wo, &L))
        return false;
    float3 wi;
    int lobe_side = 1;            // where the chosen lobe sends wi: 1 reflected, -1 refracted
    if (u.z < L.p_diffuse) {
        wi = square_to_cosine_hemisphere(u.xy);
    } else {
        const float3 h = L.delta ? (float3)(0.0f, 0.0f, 1.0f) : ggx_sample_visible_normal(L.wo, L.alpha, u.xy);
        const float c = dot(L.wo, h);
        if (!(c > 0.0f))
            return false;
        const float p_reflect = reflect_probability(&L, c);
        const float choice = (u.z - L.p_diffuse) / (1.0f - L.p_diffuse);
        const bool reflect = choice < p_reflect;
        if (reflect) {
            wi = 2.0f * c * h - L.wo;
        } else {
            const float ct = refracted_cosine(c, L.eta);
            if (!(ct >= 0.0f))
                return false;
            wi = (c / L.eta - ct) * h - L.wo / L.eta;
            lobe_side = -1;
        }
        if (L.delta) {
            const float3 wi_world = frame_to_world(&L.frame, wi);
            if (bsdf_side(&L, wi_world, wi) != lobe_side)
                return false;
            const float dielectric = 1.0f - L.metallic;
            const float3 fd = dielectric_fresnel(&L, c);
            const float p = (1.0f - L.p_diffuse) * (reflect ? p_reflect : 1.0f - p_reflect);
            // The smooth lobes' integrals: F for the mirror; for refraction
            // (1 - s max(Fd)) T base / eta^2, radiance compressed into the denser side's solid angle.
            const float3 value = reflect
                ? dielectric * L.specular * fd + L.metallic * schlick_fresnel(L.base, c)
                : (dielectric * L.transmission * (1.0f - L.specular * rgb_max(fd)) / (L.eta * L.eta)) * L.base;
            if (!(p > 0.0f))
                return false;
            s->wi = wi_world;
            s->weight = value / p;
            s->pdf = p;
            s->delta = 1;
            return true;
        }
    }
    // A facet tilted far from the normal can reflect wi below the surface or
    // refract it back above: such a wi is dropped (its density belongs to no
    // lobe of bsdf_pdf, which counts reflection above and refraction below only).
    const float3 wi_world = frame_to_world(&L.frame, wi);
    const int side = bsdf_side(&L, wi_world, wi);
    if (side != lobe_side)
        return false;
    const float pdf = bsdf_pdf_local(&L, wi, side);
    if (!(pdf > 0.0f) || !isfinite(pdf))
        return false;
    s->wi = wi_world;
    s->weight = bsdf_eval_local(&L, wi, side) / pdf;
    s->pdf = pdf;
    s->delta = 0;
    return true;
}

#endif   // BSDF_DIFFUSE_ONLY

#endif
