// The order a launch of point queries visits its points in: by cell of a
// 32 x 32 x 32 grid over the scene's box, cells in Morton order.  Random
// points in the caller's order send neighbouring work-items down unrelated
// branches of the BVH; in cell order a work-group's points lie close together
// and walk much the same nodes (on the H200 this halves the walk of a million
// random points).  Each point's answer is its own, so the order changes no
// result: only which work-item computes it.
//
// Three launches, a counting sort (the order within a cell is whatever the
// atomics make it, which no answer depends on):
//   point_cells    each point's cell, and the points in each cell
//   point_offsets  those counts into each cell's first place (one work-group)
//   point_scatter  each point's index to its place
// They share one buffer, `order`, laid out for a launch of n points as
//   uint cell_count[POINT_CELLS]  (point_offsets makes them first places,
//                                  point_scatter moves them on; for the
//                                  closest-point kernels the host then
//                                  copies the cells' seeds over them: int
//                                  seed[POINT_CELLS], POINT_CELL_SEEDS)
//   uint cell[n]                  each point's cell
//   uint order[n]                 point indices in cell order: what
//                                 query_closest_point reads (POINT_ORDER)
// and the host zeroes the counts before point_cells.
//
// The seeds: the slot of the triangle nearest to each cell's centre (-1:
// none), made once for a tree (trace.cl's point_cell_seeds) and read by the
// walks of one point a work-item (the closest points and signed distances
// of GPUs), which visit their cell's first: a point's best distance then
// starts within the cell's half diagonal of the centre's and prunes its walk
// from the root on -- where a warp's points walk together (point_warp.cl),
// no point's first, distant leaf holds the others to its nodes.  Any
// triangle visited first changes no answer (point.cl's closest_point).
#ifndef CLRT_POINT_ORDER_CL
#define CLRT_POINT_ORDER_CL

#include "layouts.h"

// POINT_CELL_BITS (cells an axis: 2^bits) and POINT_OFFSETS_GROUP come from
// clrt/config.py, as every limit does.
#define POINT_CELLS (1u << (3 * POINT_CELL_BITS))
#define POINT_CELL_OF(order) ((order) + POINT_CELLS)
#define POINT_ORDER(order, n) ((order) + POINT_CELLS + (n))
#define POINT_CELL_SEEDS(order) ((__global const int*)(order))

// The box that steers a point's walk where the walk may take the same steps
// for every point of a cell (winding.cl's far fields): with
// -DPOINT_CELL_REGIONS (GPUs) the point's cell of the grid above, padded by
// 2^-20 of the scene's size and coordinates against the rounding of its
// corners and stretched to hold the point (one outside the scene's box lies
// beyond its clamped cell) -- so every point of a cell, walked by the
// neighbouring work-items point_order puts together, opens the same nodes and
// reads them at once; else the point itself.  A child far from the whole box
// is far from the point: the choice can only open more children than the
// point alone would, so no answer loses accuracy.
typedef struct {
    float3 lo, hi;
} PointRegion;

// The grid coordinates (0 .. 2^POINT_CELL_BITS - 1 an axis) of point p's
// cell in the grid over the scene's box (lo .. hi, device frame): a point
// outside the box lands in the nearest cell; NaN points (reported by the
// queries) in cell 0 -- convert_uint_sat takes NaN to 0.
inline uint3 cell_coords(float3 p, float3 lo, float3 hi)
{
    const float3 extent = fmax(hi - lo, (float3)(FLT_MIN));
    return min(convert_uint3_sat((p - lo) / extent * (float)(1 << POINT_CELL_BITS)),
               (uint3)((1u << POINT_CELL_BITS) - 1u));
}

inline PointRegion point_region(float3 p, float3 scene_lo, float3 scene_hi)
{
    PointRegion r;
#ifdef POINT_CELL_REGIONS
    const float3 extent = fmax(scene_hi - scene_lo, (float3)(FLT_MIN));
    const float3 cells = (float3)(float)(1 << POINT_CELL_BITS);
    const float3 q = convert_float3(cell_coords(p, scene_lo, scene_hi));
    const float3 size = fmax(fmax(fabs(scene_lo), fabs(scene_hi)), extent);
    const float pad = 0x1p-20f * fmax(fmax(size.x, size.y), size.z);
    r.lo = fmin(scene_lo + q / cells * extent - pad, p);
    r.hi = fmax(scene_lo + (q + 1.0f) / cells * extent + pad, p);
#else
    r.lo = p;
    r.hi = p;
#endif
    return r;
}

// The square distance from c to the region (0 inside it): |c - p|^2 bit for
// bit where the region is the point p.
inline float region_distance2(const PointRegion* r, float3 c)
{
    const float3 gap = fmax(fmax(r->lo - c, c - r->hi), (float3)(0.0f));
    return dot(gap, gap);
}

// Bits b of x at bits 3b, b < POINT_CELL_BITS.
inline uint spread_cell_bits(uint x)
{
    uint out = 0u;
    for (uint b = 0; b < POINT_CELL_BITS; ++b)
        out |= ((x >> b) & 1u) << (3u * b);
    return out;
}

// Bits 3b of x at bits b, b < POINT_CELL_BITS (spread_cell_bits undone).
inline uint gather_cell_bits(uint x)
{
    uint out = 0u;
    for (uint b = 0; b < POINT_CELL_BITS; ++b)
        out |= ((x >> (3u * b)) & 1u) << b;
    return out;
}

// The cell of point p (device frame) in the grid over the scene's box (lo ..
// hi): its coordinates' (cell_coords) bits interleaved, x lowest (Morton order).
inline uint point_cell(float3 p, float3 lo, float3 hi)
{
    const uint3 q = cell_coords(p, lo, hi);
    return spread_cell_bits(q.x) | (spread_cell_bits(q.y) << 1) | (spread_cell_bits(q.z) << 2);
}

// The centre of cell `cell` (point_cell) of the grid over lo .. hi.
inline float3 cell_centre(uint cell, float3 lo, float3 hi)
{
    const float3 q = (float3)((float)gather_cell_bits(cell), (float)gather_cell_bits(cell >> 1),
                              (float)gather_cell_bits(cell >> 2));
    return lo + (q + 0.5f) / (float)(1 << POINT_CELL_BITS) * (hi - lo);
}

__kernel void point_cells(__global const float* origins, const QueryLaunch launch, __global uint* order)
{
    const uint i = get_global_id(0);
    if (i >= launch.num_rays)
        return;
    const float3 p = vload3(0, origins + (size_t)(launch.in_first + i) * launch.origin_stride) - launch.shift.xyz;
    const uint cell = point_cell(p, launch.scene_lo.xyz, launch.scene_hi.xyz);
    POINT_CELL_OF(order)[i] = cell;
    atomic_inc(order + cell);
}

// One work-group of POINT_OFFSETS_GROUP work-items: each sums its run of
// consecutive cells, the group scans the sums in local memory, each writes its
// cells' first places.
__kernel void point_offsets(__global uint* order)
{
    __local uint sums[POINT_OFFSETS_GROUP];
    const uint lid = get_local_id(0);
    const uint per_item = POINT_CELLS / POINT_OFFSETS_GROUP;
    const uint first = lid * per_item;
    uint total = 0u;
    for (uint c = first; c < first + per_item; ++c)
        total += order[c];
    sums[lid] = total;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint step = 1; step < POINT_OFFSETS_GROUP; step <<= 1) {   // inclusive scan (Hillis-Steele)
        const uint add = lid >= step ? sums[lid - step] : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        sums[lid] += add;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    uint at = sums[lid] - total;
    for (uint c = first; c < first + per_item; ++c) {
        const uint count = order[c];
        order[c] = at;
        at += count;
    }
}

__kernel void point_scatter(const QueryLaunch launch, __global uint* order)
{
    const uint i = get_global_id(0);
    if (i >= launch.num_rays)
        return;
    POINT_ORDER(order, launch.num_rays)[atomic_inc(order + POINT_CELL_OF(order)[i])] = i;
}

#endif
