// Textures and corner colours: what a file adds to a material's colour.  Only
// in -DSURFACE_DETAIL builds (the host defines it for scenes with textures or
// colours), so plain scenes compile none of this.
//
// Sampling is bilinear on linear values: the 8-bit texels of a colour texture
// (base colour, emission) are sRGB, decoded through a 256-entry table (exact
// float32 constants from the host); those of a data texture (the row's
// `linear`: metallicRoughness, normal maps) are linear, code * (1/255).  Then
// the four texels around the point are blended.  Texel centres sit at half-integer
// coordinates; (u, v) = (0, 0) is the image's bottom-left corner.  Out-of-range
// coordinates wrap per axis (WRAP_REPEAT, WRAP_CLAMP, WRAP_MIRROR: glTF's
// sampler modes).  clrt/reference.py samples the same way in numpy float32; the
// functions below switch FP_CONTRACT off so that no compiler fuses a multiply
// and an add into an fma, and both agree to the bit.
#ifndef CLRT_TEXTURE_CL
#define CLRT_TEXTURE_CL

#include "layouts.h"
#include "split.cl"

#ifdef SURFACE_DETAIL

// Every texture of the scene: the table, the texels (split like the geometry
// when large) and the sRGB decoding table (the first and last in the scene's
// `tables` buffer, shading.cl).
typedef struct {
    __global const Texture* table;
    SPLIT_FIELD(uchar4, texels);
    __global const float* srgb;
} TextureSet;

#define TEXTURE_PARAMS SPLIT_PARAMS(uchar4, texels)
#define TEXTURE_ARGS SPLIT_ARGS(texels)

inline TextureSet make_texture_set(__global const uchar* tables, const SceneInfo scene, TEXTURE_PARAMS)
{
    TextureSet t;
    t.table = (__global const Texture*)(tables + scene.textures_at);
    SPLIT_STORE(t, texels);
    t.srgb = (__global const float*)(tables + scene.srgb_at);
    return t;
}

// Texel index i of an axis of n texels after wrapping.
inline int wrap_texel(int i, int n, uint mode)
{
    if (mode == WRAP_CLAMP)
        return clamp(i, 0, n - 1);
    if (mode == WRAP_MIRROR) {
        int m = i % (2 * n);
        m = m < 0 ? m + 2 * n : m;
        return m < n ? m : 2 * n - 1 - m;
    }
    const int m = i % n;
    return m < 0 ? m + n : m;
}

inline float3 texel(const TextureSet* ts, __global const volatile Texture* tex, int x, int y)
{
    const uchar4 c = *SPLIT_AT(ts, texels, tex->first + (uint)y * (uint)tex->width + (uint)x);
    if (tex->linear)   // one correctly rounded product: the same on every device and in numpy
        return convert_float3(c.xyz) * (1.0f / 255.0f);
    return (float3)(ts->srgb[c.x], ts->srgb[c.y], ts->srgb[c.z]);
}

// Split a coordinate in texel units into the texel left of it and the weight of the next one.
inline int texel_floor(float x, float* frac)
{
    x = fmin(fmax(x, -TEXEL_LIMIT), TEXEL_LIMIT);   // fmax also maps NaN to the limit
    const float f = floor(x);
    *frac = x - f;
    return (int)f;
}

// Linear values of texture row `index` at (u, v), bilinearly filtered.
inline float3 sample_texture(const TextureSet* ts, int index, float2 uv)
{
    #pragma OPENCL FP_CONTRACT OFF
    // The row is read through a volatile pointer: read in place, NVIDIA's
    // compiler (driver 580.159, H200, 2026-12-03) made a path_trace of a
    // two-level scene with a normal map that never finished, and any change
    // to the code about these reads (constants in place of the row, a printf
    // of it; not the texel index clamped, nor the register cap) made one that
    // finishes: tests/test_instanced_render.py's normal-map test on the GPU.
    __global const volatile Texture* tex = ts->table + index;
    const int w = tex->width, h = tex->height;
    float fx, fy;
    const int x = texel_floor(uv.x * (float)w - 0.5f, &fx);
    const int y = texel_floor((1.0f - uv.y) * (float)h - 0.5f, &fy);
    const int x0 = wrap_texel(x, w, tex->wrap_s), x1 = wrap_texel(x + 1, w, tex->wrap_s);
    const int y0 = wrap_texel(y, h, tex->wrap_t), y1 = wrap_texel(y + 1, h, tex->wrap_t);
    const float3 t00 = texel(ts, tex, x0, y0), t10 = texel(ts, tex, x1, y0);
    const float3 t01 = texel(ts, tex, x0, y1), t11 = texel(ts, tex, x1, y1);
    const float3 top = t00 + fx * (t10 - t00);
    const float3 bottom = t01 + fx * (t11 - t01);
    return top + fy * (bottom - top);
}

// Barycentric blend of a corner value, w0 = 1 - u - v.
#define CORNER_BLEND(a0, a1, a2, u, v) ((1.0f - (u) - (v)) * (a0) + (u) * (a1) + (v) * (a2))

// The albedo at a hit: material colour x corner colour x texture (when the
// material has one).
inline float3 surface_albedo(const TextureSet* ts, __global const TriangleDetail* d, float4 color,
                             float u, float v)
{
    #pragma OPENCL FP_CONTRACT OFF
    const float3 corner_color = CORNER_BLEND(d->corner[0].xyz, d->corner[1].xyz, d->corner[2].xyz, u, v);
    float3 albedo = color.xyz * corner_color;
    const int texture = as_int(color.w);
    if (texture >= 0) {
        const float2 uv = (float2)(CORNER_BLEND(d->corner[0].w, d->corner[1].w, d->corner[2].w, u, v),
                                   CORNER_BLEND(d->v.x, d->v.y, d->v.z, u, v));
        albedo *= sample_texture(ts, texture, uv);
    }
    return albedo;
}

#endif

#endif
