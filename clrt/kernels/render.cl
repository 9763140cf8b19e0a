// Entry file of the render program: the paper's two global kernels (ray
// generation, pixel colour).  The acceleration structure is chosen when the
// program is built (accel.cl).  Anti-aliasing runs the pair once per sample,
// accumulating into the linear image, so memory stays one ray per pixel; the
// last sample's pixel colour also writes the 8-bit sRGB image the host reads
// back (no launch of its own: one pass over the linear image fewer).
#include "layouts.h"
#include "camera.cl"
#include "geometry.cl"
#include "accel.cl"
#include "shading.cl"
#include "whitted.cl"
#include "rays.cl"
#include "accel_packet.cl"

// The host renders an image in rectangles ("tiles") so that device memory and
// the length of one launch stay bounded.  Both kernels below run one work-item
// per pixel of the tile (tile.x + gx, tile.y + gy) in a 2-D launch, whose
// work-groups are blocks of neighbouring pixels: their rays walk much the same
// BVH nodes.  The tile's per-pixel arrays (rays, hits, linear colours) lie in
// one buffer, `frame`, at the byte offsets the Tile gives (layouts.h), each
// holding the tile's pixels in row-major order; so do its packed sRGB8 colours
// (3 bytes a pixel: the host array's own layout, read back without repacking).
// The buffer's first word, before them, says whether any camera ray of the
// tile's first sample hit a triangle (0 or 1): the host's "nothing visible"
// warning (frame.py), without reading back the hits.
#define TILE_SEEN(frame) ((__global uint*)(frame))
#define TILE_RAYS(frame, tile) ((__global Ray*)((frame) + (tile).rays_at))
#define TILE_HITS(frame, tile) ((__global Hit*)((frame) + (tile).hits_at))
#define TILE_IMAGE(frame, tile) ((__global float4*)((frame) + (tile).image_at))
#define TILE_SRGB(frame, tile) ((frame) + (tile).srgb_at)

// Rays of the tile's pixels, into its ray array.
__kernel void generate_rays(__global uchar* frame, const Camera cam, const Tile tile)
{
    const uint gx = get_global_id(0), gy = get_global_id(1);
    if (gx >= tile.w || gy >= tile.h)
        return;
    const uint px = tile.x + gx, py = tile.y + gy;
    if (tile.first_sample && gx == 0 && gy == 0)
        *TILE_SEEN(frame) = 0u;   // shade_pixels, launched after this kernel, sets it
    const float2 o = sample_offset(py * cam.width + px, tile.sample, tile.samples_per_axis, tile.seed);
    TILE_RAYS(frame, tile)[gy * tile.w + gx] = camera_ray(&cam, px, py, o.x, o.y);
}

// IEC 61966-2-1 transfer function; linear values are clamped to [0, 1].
inline float srgb_encode(float c)
{
    c = clamp(c, 0.0f, 1.0f);
    return c <= 0.0031308f ? 12.92f * c : 1.055f * pow(c, 1.0f / 2.4f) - 0.055f;
}

// image = (first sample ? 0 : image) + sample_weight * colour, pixel i of the
// tile -- on the last sample (tile->srgb_at set) as 8-bit sRGB, the linear
// image then unwritten --; its hit record receives the camera ray's hit (of
// the first sample).  (hit_known: the camera ray's hit is `hit`; lit_known:
// bit i of `lit` says whether light i reaches it.)  The tile's output arrays
// are found here, after the walks: made before them, their pointers would be
// held through them.
inline void shade_pixel(const Geometry* g, const Shading* sh, const Ray ray, __global uchar* frame,
                        const Tile* tile, const uint i, Hit hit, const bool hit_known, const bool lit_known,
                        const uint lit)
{
    const float3 c = trace_whitted(g, sh, tile->max_depth, ray.origin.xyz, ray.dir.xyz, ray.origin.w, ray.dir.w,
                                   &hit, hit_known, lit_known, lit);
    __global float4* image = TILE_IMAGE(frame, *tile);
    float3 total = tile->sample_weight * c;
    if (tile->first_sample) {
        if (hit.prim >= 0 && !*TILE_SEEN(frame))   // read first: one write per tile, near enough
            *TILE_SEEN(frame) = 1u;
        TILE_HITS(frame, *tile)[i] = reported_hit(g, hit);
    } else {
        total += image[i].xyz;
    }
    if (tile->srgb_at) {
        __global uchar* out = TILE_SRGB(frame, *tile) + 3 * i;
        out[0] = convert_uchar_sat_rte(255.0f * srgb_encode(total.x));
        out[1] = convert_uchar_sat_rte(255.0f * srgb_encode(total.y));
        out[2] = convert_uchar_sat_rte(255.0f * srgb_encode(total.z));
    } else {
        image[i] = (float4)(total, 1.0f);
    }
}

#ifdef RAY_PACKETS
// The camera rays of RAY_PACKETS neighbouring pixels in a row, as a packet of
// rays (accel_packet.cl): their closest hits in first[]; false when they make
// no packet.  Camera rays are unit and valid, taken as they are (as
// closest_hit takes them).
inline bool camera_packet_hits(const Geometry* g, __global const Ray* rays, Hit* first)
{
    RayLanes lanes;
    for (int k = 0; k < RAY_PACKETS; ++k) {
        const Ray r = rays[k];
        set_ray_lane(&lanes, k, r.origin.xyz, r.dir.xyz, r.origin.w, r.dir.w);
    }
    RayPacket packet;
    if (!ray_packet_of(g, &lanes, false, &packet))
        return false;
    answer_ray_packet(g, &packet, lanes.tmax, QUERY_CLOSEST, CULL_NONE, first);
    return true;
}

// Which lights reach the camera rays' hits first[] (bit i of lit[k] for light
// i, pixel k; up to 32 lights): each light's shadow rays from the eight
// points go as one packet of rays where they make one (neighbouring points,
// one light: they usually do), else one by one, as local_shading's.  Lanes
// without a hit, or with the light behind their surface, carry a copy of a
// lane that needs its ray, so that they do not break the packet.
inline void camera_packet_lights(const Geometry* g, const Shading* sh, __global const Ray* rays, const Hit* first,
                                 uint* lit)
{
    SurfacePoint s[RAY_PACKETS];
    for (int k = 0; k < RAY_PACKETS; ++k) {
        lit[k] = 0u;
        if (first[k].prim >= 0)
            s[k] = surface_point(g, sh, rays[k].dir.xyz, &first[k], 0);   // (one-level scenes only)
    }
    for (uint i = 0; i < sh->num_lights; ++i) {
        float3 origin[RAY_PACKETS], l[RAY_PACKETS];
        float dist[RAY_PACKETS];
        uint needed = 0u;
        for (int k = 0; k < RAY_PACKETS; ++k)
            if (first[k].prim >= 0 && shadow_ray(sh, &s[k], i, &origin[k], &l[k], &dist[k]))
                needed |= 1u << k;
        if (!needed)
            continue;
        const int model = 31 - clz(needed & (0u - needed));      // the lowest lane that needs its ray
        RayLanes lanes;
        for (int k = 0; k < RAY_PACKETS; ++k) {
            const int j = (needed >> k) & 1u ? k : model;
            set_ray_lane(&lanes, k, origin[j], l[j], 0.0f, dist[j]);
        }
        RayPacket packet;
        Hit blocked[RAY_PACKETS];
        const bool as_packet = ray_packet_of(g, &lanes, true, &packet);
        if (as_packet)
            answer_ray_packet(g, &packet, lanes.tmax, QUERY_ANY, CULL_NONE, blocked);
        for (int k = 0; k < RAY_PACKETS; ++k) {
            if (!((needed >> k) & 1u))
                continue;
            const bool dark = as_packet ? blocked[k].prim >= 0 : any_hit(g, origin[k], l[k], 0.0f, dist[k], true);
            if (!dark)
                lit[k] |= 1u << i;
        }
    }
}
#endif

// On CPU devices that walk packets of rays a work-item shades RAY_PACKETS
// pixels of a row (gx: the row's packet), else one pixel.
__kernel void shade_pixels(__global uchar* frame, const Tile tile, GEOMETRY_PARAMS, SHADING_PARAMS)
{
    const uint gx = get_global_id(0), gy = get_global_id(1);
    const uint tile_w = tile.w, tile_h = tile.h;
    __global const Ray* rays = TILE_RAYS(frame, tile);
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Shading sh = make_shading(SHADING_ARGS, scene);
#ifdef RAY_PACKETS
    const uint x0 = RAY_PACKETS * gx;
    if (x0 >= tile_w || gy >= tile_h)
        return;
    const uint i0 = gy * tile_w + x0;
    Hit first[RAY_PACKETS];
    uint lit[RAY_PACKETS];
    const bool known = x0 + RAY_PACKETS <= tile_w && camera_packet_hits(&g, rays + i0, first);
    const bool lit_known = known && sh.num_lights <= 32u;
    if (lit_known)
        camera_packet_lights(&g, &sh, rays + i0, first, lit);
    for (uint k = 0; k < RAY_PACKETS && x0 + k < tile_w; ++k)
        shade_pixel(&g, &sh, rays[i0 + k], frame, &tile, i0 + k, known ? first[k] : miss_hit(), known, lit_known,
                    lit_known ? lit[k] : 0u);
#else
    if (gx >= tile_w || gy >= tile_h)
        return;
    const uint i = gy * tile_w + gx;
    shade_pixel(&g, &sh, rays[i], frame, &tile, i, miss_hit(), false, false, 0u);
#endif
}
