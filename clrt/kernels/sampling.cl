// Warps: maps from uniform numbers in [0, 1)^2 to points and directions, each
// beside the density it samples (per unit area of the disk, per steradian for
// directions), and the orthonormal frame the local directions live in.  Local
// directions have the normal as +z.  The GGX / Trowbridge-Reitz distribution
// of microfacet normals is here too, since its visible-normal warp and that
// warp's density need it; bsdf.cl builds the glTF material on top.
// Everything is float32 (literals carry the f suffix: no double anywhere).
#ifndef CLRT_SAMPLING_CL
#define CLRT_SAMPLING_CL

// ---------------------------------------------------------------- frames

// An orthonormal basis (t, b, n) around a unit n.
typedef struct {
    float3 t, b, n;
} Frame;

// Duff, Burgess, Christensen, Hery, Kensler, Liani, Villemin 2017, "Building
// an Orthonormal Basis, Revisited": the sign of n.z picks between two
// rotations, so there is no branch and no division that blows up at either
// pole (Frisvad's 2012 form fails at n.z = -1).  copysign keeps -0 on the
// negative side too.
inline Frame frame_from_normal(float3 n)
{
    const float sign = copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    Frame f;
    f.t = (float3)(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    f.b = (float3)(b, sign + n.y * n.y * a, -n.y);
    f.n = n;
    return f;
}

inline float3 frame_to_local(const Frame* f, float3 v)
{
    return (float3)(dot(v, f->t), dot(v, f->b), dot(v, f->n));
}

inline float3 frame_to_world(const Frame* f, float3 v)
{
    return v.x * f->t + v.y * f->b + v.z * f->n;
}

// ---------------------------------------------------------------- disks, hemispheres, spheres

// Shirley and Chiu 1997, the concentric map: squares around the centre become
// rings, so strata of the square stay compact on the disk (the polar map
// r = sqrt(u) stretches them near the centre).  Density 1 / pi on the disk.
inline float2 square_to_disk_concentric(float2 u)
{
    const float x = 2.0f * u.x - 1.0f, y = 2.0f * u.y - 1.0f;
    if (x == 0.0f && y == 0.0f)
        return (float2)(0.0f, 0.0f);
    float r, phi;
    if (fabs(x) > fabs(y)) {
        r = x;
        phi = M_PI_4_F * (y / x);
    } else {
        r = y;
        phi = M_PI_2_F - M_PI_4_F * (x / y);
    }
    return (float2)(r * cos(phi), r * sin(phi));
}

// Malley's method: the concentric disk lifted onto the hemisphere gives
// density cos(theta) / pi.  z is kept >= 0 (rounding may give 1 - r^2 < 0).
inline float3 square_to_cosine_hemisphere(float2 u)
{
    const float2 d = square_to_disk_concentric(u);
    const float z = sqrt(fmax(0.0f, 1.0f - d.x * d.x - d.y * d.y));
    return (float3)(d.x, d.y, z);
}

inline float cosine_hemisphere_pdf(float3 v)
{
    return fmax(v.z, 0.0f) * M_1_PI_F;
}

// z uniform in [0, 1): equal areas on the hemisphere (Archimedes).
inline float3 square_to_uniform_hemisphere(float2 u)
{
    const float z = u.x;
    const float r = sqrt(fmax(0.0f, 1.0f - z * z));
    const float phi = 2.0f * M_PI_F * u.y;
    return (float3)(r * cos(phi), r * sin(phi), z);
}

inline float uniform_hemisphere_pdf(float3 v)
{
    return v.z >= 0.0f ? 0.5f * M_1_PI_F : 0.0f;
}

// z uniform in (-1, 1]: equal areas on the sphere.
inline float3 square_to_uniform_sphere(float2 u)
{
    const float z = 1.0f - 2.0f * u.x;
    const float r = sqrt(fmax(0.0f, 1.0f - z * z));
    const float phi = 2.0f * M_PI_F * u.y;
    return (float3)(r * cos(phi), r * sin(phi), z);
}

inline float uniform_sphere_pdf(void)
{
    return 0.25f * M_1_PI_F;
}

// ---------------------------------------------------------------- GGX / Trowbridge-Reitz

// The distribution of microfacet normals h (local, unit) for roughness alpha
// (glTF: alpha = perceptual roughness^2):
//     D(h) = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2)
// written with h's tangential part, (n.h)^2 (alpha^2 - 1) + 1 = x^2 + y^2 +
// alpha^2 z^2, so that float32 keeps its digits near the peak when alpha is
// small (1 - cos^2 would cancel).  Normalised: the integral of D(h) h.z over
// the hemisphere is 1.
inline float ggx_d(float3 h, float alpha)
{
    if (!(h.z > 0.0f))
        return 0.0f;
    const float a2 = alpha * alpha;
    const float t = (h.x * h.x + h.y * h.y) / a2 + h.z * h.z;
    return 1.0f / (M_PI_F * a2 * t * t);
}

// |w.z| sqrt(1 + alpha^2 tan^2 theta) = sqrt(z^2 + alpha^2 (x^2 + y^2)): the
// root in Smith's Lambda for GGX, Lambda(w) = (root / |w.z| - 1) / 2.  Every
// masking term below is a ratio of these roots and cosines, never divided by
// a cosine alone, so grazing directions give finite values.
inline float ggx_root(float3 w, float alpha)
{
    return sqrt(w.z * w.z + alpha * alpha * (w.x * w.x + w.y * w.y));
}

// Smith's masking G1(w) = 1 / (1 + Lambda(w)).
inline float ggx_g1(float3 w, float alpha)
{
    const float z = fabs(w.z);
    return 2.0f * z / (z + ggx_root(w, alpha));
}

// Height-correlated masking-shadowing (Heitz 2014), G2 = 1 / (1 + Lambda(wo) + Lambda(wi)),
// divided by |wo.z|: 2 |wi.z| / (|wi.z| root(wo) + |wo.z| root(wi)).
inline float ggx_g2_over_cos_o(float3 wo, float3 wi, float alpha)
{
    const float zo = fabs(wo.z), zi = fabs(wi.z);
    const float den = zi * ggx_root(wo, alpha) + zo * ggx_root(wi, alpha);
    return den > 0.0f ? 2.0f * zi / den : 0.0f;
}

// Visible normals (Heitz 2018) sampled as Dupuy and Benyoub 2023 do ("Sampling
// Visible GGX Normals with Spherical Caps"): stretch wo into the configuration
// where alpha = 1, where the visible normals of the hemisphere are the
// spherical cap below wo's horizon shifted by wo; sample that cap uniformly
// (z uniform in (-wo.z, 1], phi uniform), add wo, and unstretch.  No branch,
// no tangent frame around wo.  wo: local, wo.z > 0.  The result has h.z >= 0;
// h.z == 0 (rounding at u.y -> 1) has density 0 and callers drop it.
inline float3 ggx_sample_visible_normal(float3 wo, float alpha, float2 u)
{
    const float3 v = normalize((float3)(alpha * wo.x, alpha * wo.y, wo.z));
    const float phi = 2.0f * M_PI_F * u.x;
    const float z = fma(1.0f - u.y, 1.0f + v.z, -v.z);
    const float r = sqrt(clamp(1.0f - z * z, 0.0f, 1.0f));
    const float3 h = (float3)(r * cos(phi), r * sin(phi), z) + v;
    return normalize((float3)(alpha * h.x, alpha * h.y, fmax(h.z, 0.0f)));
}

// Density of ggx_sample_visible_normal per steradian of h:
//     D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z = 2 max(0, wo.h) D(h) / (wo.z + root(wo)).
inline float ggx_visible_normal_pdf(float3 wo, float3 h, float alpha)
{
    return 2.0f * fmax(dot(wo, h), 0.0f) * ggx_d(h, alpha) / (wo.z + ggx_root(wo, alpha));
}

#endif
