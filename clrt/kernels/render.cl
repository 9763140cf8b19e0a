// Entry file of the render program: the paper's two global kernels (ray
// generation, pixel colour) plus the conversion of linear colour to 8-bit
// sRGB.  The acceleration structure is chosen when the program is built
// (accel.cl).  Anti-aliasing runs the pair once per sample, accumulating
// into the linear image, so memory stays one ray per pixel.
#include "layouts.h"
#include "camera.cl"
#include "geometry.cl"
#include "accel.cl"
#include "shading.cl"
#include "whitted.cl"

// The host renders an image in rectangles ("tiles") so that device memory and
// the length of one launch stay bounded.  Both kernels below run one work-item
// per pixel of the tile (tile_x + gx, tile_y + gy) in a 2-D launch, whose
// work-groups are blocks of neighbouring pixels: their rays walk much the same
// BVH nodes.  Per-pixel buffers are the tile's pixels in row-major order.
#define TILE_PARAMS const uint tile_x, const uint tile_y, const uint tile_w, const uint tile_h

// Rays of the tile's pixels, into rays[0 .. tile_w * tile_h - 1].
__kernel void generate_rays(__global Ray* rays, CAMERA_PARAMS, const uint sample, const uint samples_per_axis,
                            const uint seed, TILE_PARAMS)
{
    const uint gx = get_global_id(0), gy = get_global_id(1);
    if (gx >= tile_w || gy >= tile_h)
        return;
    const Camera cam = make_camera(CAMERA_ARGS);
    const uint px = tile_x + gx, py = tile_y + gy;
    const float2 o = sample_offset(py * width + px, sample, samples_per_axis, seed);
    rays[gy * tile_w + gx] = camera_ray(&cam, px, py, o.x, o.y);
}

// image = (first sample ? 0 : image) + sample_weight * colour.  hits receives
// the camera ray's hit (of the first sample).  Indices are within the tile.
__kernel void shade_pixels(__global const Ray* rays, __global float4* image, __global Hit* hits,
                           const uint tile_w, const uint tile_h, const uint max_depth, const float sample_weight,
                           const uint first_sample, GEOMETRY_PARAMS, SHADING_PARAMS)
{
    const uint gx = get_global_id(0), gy = get_global_id(1);
    if (gx >= tile_w || gy >= tile_h)
        return;
    const uint i = gy * tile_w + gx;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Shading sh = make_shading(SHADING_ARGS);
    const Ray ray = rays[i];
    Hit hit;
    const float3 c = trace_whitted(&g, &sh, max_depth, ray.origin.xyz, ray.dir.xyz,
                                   ray.origin.w, ray.dir.w, &hit);
    if (first_sample) {
        hits[i] = reported_hit(&g, hit);
        image[i] = (float4)(sample_weight * c, 1.0f);
    } else {
        image[i] += (float4)(sample_weight * c, 0.0f);
    }
}

// IEC 61966-2-1 transfer function; linear values are clamped to [0, 1].
inline float srgb_encode(float c)
{
    c = clamp(c, 0.0f, 1.0f);
    return c <= 0.0031308f ? 12.92f * c : 1.055f * pow(c, 1.0f / 2.4f) - 0.055f;
}

// Packed RGB, 3 bytes a pixel: the host array's own layout, so no repacking there.
__kernel void encode_srgb8(__global const float4* image, __global uchar* out, const uint num_pixels)
{
    const uint i = get_global_id(0);
    if (i >= num_pixels)
        return;
    const float4 c = image[i];
    out[3 * i] = convert_uchar_sat_rte(255.0f * srgb_encode(c.x));
    out[3 * i + 1] = convert_uchar_sat_rte(255.0f * srgb_encode(c.y));
    out[3 * i + 2] = convert_uchar_sat_rte(255.0f * srgb_encode(c.z));
}
