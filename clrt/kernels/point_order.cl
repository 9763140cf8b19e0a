// The order a launch of point queries visits its points in: by cell of a
// grid over the scene's box, cells in Morton order.  Random points in the
// caller's order send neighbouring work-items down unrelated branches of the
// BVH; in cell order a work-group's points lie close together and walk much
// the same nodes (on the H200 this halves the walk of a million random
// points).  Each point's answer is its own, so the order changes no result:
// only which work-item computes it.
//
// GPUs (and CPU devices' small launches): a 32 x 32 x 32 grid, three
// launches, a counting sort (the order within a cell is whatever the atomics
// make it, which no answer depends on):
//   point_cells    each point's cell, and the points in each cell
//   point_offsets  those counts into each cell's first place (one work-group)
//   point_scatter  each point's index to its place
// CPU devices from POINT_RUN_POINTS points on: a finer grid and four
// launches without atomics (point_run_*, below).  Both share one buffer,
// `order`, laid out for a launch of n points as
//   uint cell_count[POINT_CELLS]  (point_offsets makes them first places,
//                                  point_scatter moves them on; the runs'
//                                  order leaves them unwritten; for the
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
#define POINT_RUN_CELLS (1u << (3 * POINT_RUN_CELL_BITS))
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

// The grid coordinates (0 .. 2^bits - 1 an axis) of point p's cell in a
// grid of 2^bits cells an axis over the scene's box (lo .. hi, device
// frame): a point outside the box lands in the nearest cell; a NaN
// coordinate (reported by the queries) in the first cell of its axis (fmax
// takes NaN to 0).  The clamp is
// made on the floats and the conversion signed: CPUs convert float vectors to
// signed integers in one instruction, to unsigned ones in several.
inline uint3 grid_coords(float3 p, float3 lo, float3 hi, uint bits)
{
    const float3 extent = fmax(hi - lo, (float3)(FLT_MIN));
    const float3 q = fmin(fmax((p - lo) / extent * (float)(1u << bits), 0.0f), (float)((1u << bits) - 1u));
    return as_uint3(convert_int3(q));
}

// point p's cell of the grid of point_cell (POINT_CELL_BITS an axis).
inline uint3 cell_coords(float3 p, float3 lo, float3 hi)
{
    return grid_coords(p, lo, hi, POINT_CELL_BITS);
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

// Bits b of x at bits 3b, b < 10: four shifts and masks
// (bits 8-9, then 4-7, 2-3 and 1 moved into place) rather than a bit at a time.
#if POINT_CELL_BITS > 10 || POINT_RUN_CELL_BITS > 10
#error "spread_cell_bits spreads 10 bits at most"
#endif
inline uint spread_cell_bits(uint x)
{
    x = (x | (x << 16)) & 0x030000FFu;
    x = (x | (x << 8)) & 0x0300F00Fu;
    x = (x | (x << 4)) & 0x030C30C3u;
    return (x | (x << 2)) & 0x09249249u;
}

// Bits 3b of x at bits b, b < POINT_CELL_BITS (spread_cell_bits undone).
inline uint gather_cell_bits(uint x)
{
    uint out = 0u;
    for (uint b = 0; b < POINT_CELL_BITS; ++b)
        out |= ((x >> (3u * b)) & 1u) << b;
    return out;
}

// The cell of grid coordinates q: their bits interleaved, x lowest (Morton order).
inline uint morton_cell(uint3 q)
{
    return spread_cell_bits(q.x) | (spread_cell_bits(q.y) << 1) | (spread_cell_bits(q.z) << 2);
}

// The cell of point p (device frame) in point_cell's grid over the scene's box (lo .. hi).
inline uint point_cell(float3 p, float3 lo, float3 hi)
{
    return morton_cell(cell_coords(p, lo, hi));
}

// The centre of cell `cell` (point_cell) of the grid over lo .. hi.
inline float3 cell_centre(uint cell, float3 lo, float3 hi)
{
    const float3 q = (float3)((float)gather_cell_bits(cell), (float)gather_cell_bits(cell >> 1),
                              (float)gather_cell_bits(cell >> 2));
    return lo + (q + 0.5f) / (float)(1 << POINT_CELL_BITS) * (hi - lo);
}

// Point i of the launch in the device's frame.
inline float3 launch_point(__global const float* origins, const QueryLaunch* launch, uint i)
{
    return vload3(0, origins + (size_t)(launch->in_first + i) * launch->origin_stride) - launch->shift.xyz;
}

__kernel void point_cells(__global const float* origins, const QueryLaunch launch, __global uint* order)
{
    const uint i = get_global_id(0);
    if (i >= launch.num_rays)
        return;
    const float3 p = launch_point(origins, &launch, i);
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

// CPU devices' order (PoCL runs atomic increments slowly: a million points
// took 13-26 ms by the three launches above, 20 by numpy's stable sort on the
// host, 7-10 by these four), by the cells of a finer grid, 2^POINT_RUN_CELL_BITS
// cells an axis: the walks of point groups (point_group.cl) take neighbours
// sixteen at a time, and sixteen neighbours in the finer Morton order lie in
// a box of 2 x 2 x 1 of its cells, where the coarse order leaves them spread
// over a whole cell of thirty (3-8 % off the walks: docs/benchmark-log.md).
// A counting sort without atomics: the launch's points in get_global_size(0)
// runs of consecutive points (point_run), a work-item a run, each counting
// its run's cells in a row of POINT_RUN_CELLS counters of its own in
// `counts`.  Stable: within a cell, runs in order and each run's points in
// theirs.
//   point_cell_of      each point's cell (of the finer grid), a work-item a point
//   point_run_counts   each run's points in each cell
//   point_run_offsets  those counts into each run's first place in each cell
//                      (one work-item: POINT_RUN_CELLS additions a run)
//   point_run_scatter  each point's index to its place
// In `order` they write `cell` (the finer grid's cells) and `order`, not the
// cell counts: the closest-point kernels of one point a work-item (on CPU
// devices those without point groups: two-level scenes, no BVH) read the
// seeds copied there, of the coarse grid, by their points' own cells
// (point_cell).
inline void point_run(uint n, uint run, uint runs, uint* first, uint* last)
{
    *first = (uint)((ulong)n * run / runs);
    *last = (uint)((ulong)n * (run + 1u) / runs);
}

__kernel void point_cell_of(__global const float* origins, const QueryLaunch launch, __global uint* order)
{
    const uint i = get_global_id(0);
    if (i >= launch.num_rays)
        return;
    const float3 p = launch_point(origins, &launch, i);
    const uint3 q = grid_coords(p, launch.scene_lo.xyz, launch.scene_hi.xyz, POINT_RUN_CELL_BITS);
    POINT_CELL_OF(order)[i] = morton_cell(q);
}

__kernel void point_run_counts(const QueryLaunch launch, __global uint* order, __global uint* counts)
{
    const uint run = get_global_id(0);
    __global uint* count = counts + (size_t)run * POINT_RUN_CELLS;
    for (uint c = 0; c < POINT_RUN_CELLS; ++c)
        count[c] = 0u;
    uint first, last;
    point_run(launch.num_rays, run, get_global_size(0), &first, &last);
    for (uint i = first; i < last; ++i)
        ++count[POINT_CELL_OF(order)[i]];
}

__kernel void point_run_offsets(__global uint* counts, const uint runs)
{
    uint at = 0u;
    for (uint c = 0; c < POINT_RUN_CELLS; ++c) {
        for (uint run = 0; run < runs; ++run) {
            __global uint* count = counts + (size_t)run * POINT_RUN_CELLS + c;
            const uint points = *count;
            *count = at;
            at += points;
        }
    }
}

__kernel void point_run_scatter(const QueryLaunch launch, __global uint* order, __global uint* counts)
{
    const uint run = get_global_id(0);
    __global uint* place = counts + (size_t)run * POINT_RUN_CELLS;
    __global uint* visit = POINT_ORDER(order, launch.num_rays);
    uint first, last;
    point_run(launch.num_rays, run, get_global_size(0), &first, &last);
    for (uint i = first; i < last; ++i)
        visit[place[POINT_CELL_OF(order)[i]]++] = i;
}

#endif
