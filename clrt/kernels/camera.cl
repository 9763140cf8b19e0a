// Ray generation: one primary ray per pixel of a pinhole camera, through the
// pixel centre.  The ray model is fixed so that every system we compare with
// traces exactly the same rays:
//   sx = (2 (px + 0.5) / W - 1) tan(fov/2) W/H,  sy = (1 - 2 (py + 0.5) / H) tan(fov/2)
//   dir = normalize(forward + sx right + sy up), row py = 0 at the top.
// The host computes forward/right/up and the two scale factors once per frame.
#ifndef CLRT_CAMERA_CL
#define CLRT_CAMERA_CL

#include "layouts.h"

// The Camera struct (layouts.h) arrives by value: the host fills it once per
// frame (clrt.device.signature.camera_value).

// Ray through the point (px + ox, py + oy) of the image, (ox, oy) in [0, 1)^2
// ((0.5, 0.5): the pixel centre).
inline Ray camera_ray(const Camera* cam, uint px, uint py, float ox, float oy)
{
    const float sx = (2.0f * ((float)px + ox) / (float)cam->width - 1.0f) * cam->scale_x;
    const float sy = (1.0f - 2.0f * ((float)py + oy) / (float)cam->height) * cam->scale_y;
    const float3 d = normalize(cam->forward.xyz + sx * cam->right.xyz + sy * cam->up.xyz);
    Ray r;
    r.origin = (float4)(cam->eye.xyz, 0.0f);
    r.dir = (float4)(d, INFINITY);
    return r;
}

// Integer hash "lowbias32" (C. Wellons): the reproducible source of the
// jitter of anti-aliasing samples; clrt/reference.py computes the same.
inline uint hash_u32(uint x)
{
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

inline float hash_unit(uint x)
{
    return (float)(hash_u32(x) >> 8) * (1.0f / 16777216.0f);   // [0, 1), exact in float
}

// Offset of sample `sample` of a pixel: the pixel centre for one sample per
// pixel, else a jittered point in cell (sample % n, sample / n) of an n x n grid.
inline float2 sample_offset(uint pixel, uint sample, uint n, uint seed)
{
    if (n <= 1u)
        return (float2)(0.5f, 0.5f);
    const uint key = hash_u32(seed) ^ (pixel * n * n + sample) * 2u;
    const float jx = hash_unit(key), jy = hash_unit(key + 1u);
    return (float2)(((float)(sample % n) + jx) / (float)n, ((float)(sample / n) + jy) / (float)n);
}

#endif
