// First steps of the device builder: the bounds of the triangles' box centres
// (a reduction) and a 30-bit Morton code per triangle, which orders the
// triangles along a Z-order curve through those bounds, so that triangles
// near in space are mostly near in the sorted order -- what PLOC's
// nearest-neighbour search within a window of that order relies on.
//
// Input: the corners, 9 floats per triangle (x, y, z of v0, v1, v2), in input order.
#ifndef CLRT_BUILD_MORTON_CL
#define CLRT_BUILD_MORTON_CL

#include "build_state.cl"

inline float3 corner(const global float* corners, uint tri, uint k)
{
    return vload3(3 * tri + k, corners);
}

inline void triangle_box(const global float* corners, uint tri, float3* lo, float3* hi)
{
    const float3 a = corner(corners, tri, 0), b = corner(corners, tri, 1), c = corner(corners, tri, 2);
    *lo = fmin(fmin(a, b), c);
    *hi = fmax(fmax(a, b), c);
}

// Halves first: the sum of two large coordinates could overflow.
inline float3 box_centre(float3 lo, float3 hi)
{
    return 0.5f * lo + 0.5f * hi;
}

// Floats as unsigned integers in the same order, so that the bounds can be
// reduced with integer atomics across work-groups.
inline uint ordered_bits(float f)
{
    const uint u = as_uint(f + 0.0f);       // + 0.0f: -0 becomes +0
    return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

inline float from_ordered_bits(uint k)
{
    return as_float((k & 0x80000000u) ? (k & 0x7fffffffu) : ~k);
}

// A work-group's boxes my_lo..my_hi (one a work-item) reduced in local
// memory (lo, hi: BUILD_GROUP entries each), then folded into `box` (min
// xyz, max xyz as order-preserving bits) by 6 atomics -- where the group
// had any (finite) box.  Every work-item of the group calls it.
inline void reduce_box(local float3* lo, local float3* hi, float3 my_lo, float3 my_hi, global uint* box)
{
    const uint lid = get_local_id(0);
    lo[lid] = my_lo;
    hi[lid] = my_hi;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint stride = BUILD_GROUP / 2; stride > 0; stride >>= 1) {
        if (lid < stride) {
            lo[lid] = fmin(lo[lid], lo[lid + stride]);
            hi[lid] = fmax(hi[lid], hi[lid + stride]);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0 && lo[0].x <= hi[0].x) {
        atomic_min(box + 0, ordered_bits(lo[0].x));
        atomic_min(box + 1, ordered_bits(lo[0].y));
        atomic_min(box + 2, ordered_bits(lo[0].z));
        atomic_max(box + 3, ordered_bits(hi[0].x));
        atomic_max(box + 4, ordered_bits(hi[0].y));
        atomic_max(box + 5, ordered_bits(hi[0].z));
    }
}

// Bounds of the box centres: a tree reduction in local memory per
// work-group (each work-item first folds a grid-stride share of the
// triangles), then 6 atomics per work-group into the build state.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void centroid_bounds(const global float* corners, const uint num_tris, global uint* state)
{
    local float3 lo[BUILD_GROUP], hi[BUILD_GROUP];
    float3 my_lo = (float3)(INFINITY), my_hi = (float3)(-INFINITY);
    for (uint tri = get_global_id(0); tri < num_tris; tri += get_global_size(0)) {
        float3 box_lo, box_hi;
        triangle_box(corners, tri, &box_lo, &box_hi);
        // The corners, not the box: fmin and fmax drop a NaN.
        if (!all(isfinite(corner(corners, tri, 0))) || !all(isfinite(corner(corners, tri, 1)))
            || !all(isfinite(corner(corners, tri, 2))))
            atomic_min(state + STATE_BAD_TRIANGLE, tri);
        const float3 c = box_centre(box_lo, box_hi);
        my_lo = fmin(my_lo, c);
        my_hi = fmax(my_hi, c);
    }
    reduce_box(lo, hi, my_lo, my_hi, state + STATE_BOUNDS);
}

// 10 bits -> every third bit of 30.
inline uint spread_bits(uint x)
{
    x = (x | (x << 16)) & 0x030000FFu;
    x = (x | (x << 8)) & 0x0300F00Fu;
    x = (x | (x << 4)) & 0x030C30C3u;
    x = (x | (x << 2)) & 0x09249249u;
    return x;
}

// The Morton code of point c on a grid of `cells` (a power of two up to 1024)
// a side over the box lo..hi: 3 * log2(cells) bits.  A flat axis (extent 0)
// maps to cell 0; _sat turns NaN (huge meshes: inf * 0) and points below lo
// into 0.
inline uint morton_code(float3 c, float3 lo, float3 hi, uint cells)
{
    const float3 extent = hi - lo;
    const float3 scale = select((float)cells / extent, (float3)(0.0f), extent <= 0.0f);
    const uint3 cell = min(convert_uint3_sat((c - lo) * scale), (uint3)(cells - 1u));
    return (spread_bits(cell.x) << 2) | (spread_bits(cell.y) << 1) | spread_bits(cell.z);
}

// keys[i]: Morton code of triangle i's box centre on a 1024^3 grid over the
// centre bounds; ids[i] = i, the value the sort carries along.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void morton_codes(const global float* corners, const uint num_tris, const global uint* state,
                  global uint* keys, global uint* ids)
{
    const uint tri = get_global_id(0);
    if (tri >= num_tris)
        return;
    const global uint* bounds = state + STATE_BOUNDS;
    const float3 lo = (float3)(from_ordered_bits(bounds[0]), from_ordered_bits(bounds[1]),
                               from_ordered_bits(bounds[2]));
    const float3 hi = (float3)(from_ordered_bits(bounds[3]), from_ordered_bits(bounds[4]),
                               from_ordered_bits(bounds[5]));
    float3 box_lo, box_hi;
    triangle_box(corners, tri, &box_lo, &box_hi);
    keys[tri] = morton_code(box_centre(box_lo, box_hi), lo, hi, 1024u);
    ids[tri] = tri;
}

#endif
