// The device builder's SAH partition (GPUs): before the Morton codes, the
// triangles are split top-down by the binned SAH into at most `budget`
// segments of about F / budget triangles each; PLOC then merges clusters of
// one segment only, and the SAH top (build_top.cl) joins the segments.
//
// Why: PLOC's merges follow the Morton curve, and the tree it makes groups
// triangles worse than a top-down SAH build does where the groups are large.
// Emulated on the host (session 13, docs/benchmark-log.md): PLOC's clusters
// rebuilt with the SAH inside and above them stayed 3-4 % above the host
// SAH tree's cost, while an SAH partition into 100-200 segments with PLOC
// inside came within 1-2 %.  The middle levels are the SAH's, the bottom
// levels PLOC's (with treelets), the top the exact SAH of build_top.cl.
//
// Per level (the host queues PART_LEVELS of them, without reading anything),
// on a sample of the triangles (below):
//   partition_bin     every sample in an open node adds its box to the
//                     node's bin of its box centre, PART_BINS bins an axis
//                     over the node's centre bounds
//   partition_split   one work-group: each open node's cheapest split by the
//                     bins (A(L) N(L) + A(R) N(R)), then, in node order, the
//                     splits that keep the segments within the budget
//   partition_assign  every sample of a split node moves to the child its
//                     bin falls in, and widens that child's centre bounds
// then partition_order numbers the segments depth-first, and
// partition_morton_codes takes every triangle down the splits to its segment
// and keys it segment << 24 | a 24-bit Morton code within the segment's
// centre bounds, an order in which each segment is one run of places.
//
// A node whose centres all fall into one bin on every axis cannot be split
// and stays a segment however large; so does every node still open after the
// last level.  Either way PLOC merges inside it as it always did.
#ifndef CLRT_BUILD_PARTITION_CL
#define CLRT_BUILD_PARTITION_CL

#include "layouts.h"
#include "build_morton.cl"
#include "build_treelet.cl"

#if !defined(PART_BINS) || !defined(PART_MAX_NODES) || !defined(PART_LEVELS) || !defined(STATE_PART_NODES) \
    || !defined(STATE_PART_SEGMENTS) || !defined(STATE_PART_FIRST) || !defined(STATE_PART_END)
#error "build with the PART_* and STATE_PART_* defines of clrt/device/build.py"
#endif

#if PART_LEVELS >= 64
#error "partition_order's stack holds a path of at most 64 levels"
#endif

#define PART_VALUES 7       // a bin: count, box min xyz, box max xyz (ordered bits)
#ifndef SEGMENT_BITS
#error "build with -DSEGMENT_BITS=<a key's top bits that hold its segment> (clrt/device/build.py)"
#endif
#if SEGMENT_BITS != 8
#error "partition_morton_codes keys a segment above a 24-bit Morton code"
#endif
#define SEGMENT_MASK ((1 << SEGMENT_BITS) - 1)

// Where a node's bin on an axis starts in the bins buffer.
inline int bin_at(int node, int axis, int bin)
{
    return ((node * 3 + axis) * PART_BINS + bin) * PART_VALUES;
}

inline float3 decode_bits(uint4 bits)
{
    return (float3)(from_ordered_bits(bits.x), from_ordered_bits(bits.y), from_ordered_bits(bits.z));
}

// The bin of a centre coordinate c in [lo, hi] (0 for a flat axis; _sat turns
// the NaN of a huge extent into 0).  partition_bin and partition_assign call
// it with the same arguments, so a triangle lands on the side its bin counted.
inline int centre_bin(float c, float lo, float hi)
{
    const float extent = hi - lo;
    if (!(extent > 0.0f))
        return 0;
    return clamp(convert_int_sat((c - lo) * ((float)PART_BINS / extent)), 0, PART_BINS - 1);
}

inline float axis_of(float3 v, int axis)
{
    return axis == 0 ? v.x : (axis == 1 ? v.y : v.z);
}

// A bin's values, b a local or a global uint* (macros: OpenCL C 1.2 has no
// pointer to either): empty, and a triangle's box added (count, min, max).
#define CLEAR_BIN(b) do { \
        (b)[0] = 0u; \
        for (int v_ = 1; v_ <= 3; ++v_) { \
            (b)[v_] = 0xffffffffu;      /* min: atomic_min from the largest */ \
            (b)[v_ + 3] = 0u;           /* max: atomic_max from the smallest */ \
        } \
    } while (0)
#define ADD_TO_BIN(b, lo, hi) do { \
        atomic_inc(b); \
        atomic_min((b) + 1, ordered_bits((lo).x)); \
        atomic_min((b) + 2, ordered_bits((lo).y)); \
        atomic_min((b) + 3, ordered_bits((lo).z)); \
        atomic_max((b) + 4, ordered_bits((hi).x)); \
        atomic_max((b) + 5, ordered_bits((hi).y)); \
        atomic_max((b) + 6, ordered_bits((hi).z)); \
    } while (0)
// Centre bounds (min at lo_at, max at hi_at, ordered bits) widened to c.
#define WIDEN_BOUNDS(lo_at, hi_at, c) do { \
        atomic_min((lo_at) + 0, ordered_bits((c).x)); \
        atomic_min((lo_at) + 1, ordered_bits((c).y)); \
        atomic_min((lo_at) + 2, ordered_bits((c).z)); \
        atomic_max((hi_at) + 0, ordered_bits((c).x)); \
        atomic_max((hi_at) + 1, ordered_bits((c).y)); \
        atomic_max((hi_at) + 2, ordered_bits((c).z)); \
    } while (0)

// A node of `count` samples, not split, its centre bounds empty (to be
// widened), open when it has more than `limit`.
inline BuildPart part_node(int count, int limit)
{
    BuildPart p;
    p.centre_lo = (uint4)(0xffffffffu);
    p.centre_hi = (uint4)(0u);
    p.count = count;
    p.child = -1;
    p.axis = 0;
    p.split = 0;
    p.segment = 0;
    p.open = count > limit;
    p.pad[0] = p.pad[1] = 0;
    return p;
}

// The child of split node n on whose side centre c lies: the bin its split
// axis puts c in, as partition_bin binned it.
inline int child_holding(const global BuildPart* parts, int n, float3 c)
{
    const int axis = parts[n].axis;
    const float lo = axis_of(decode_bits(parts[n].centre_lo), axis);
    const float hi = axis_of(decode_bits(parts[n].centre_hi), axis);
    return parts[n].child + (centre_bin(axis_of(c, axis), lo, hi) >= parts[n].split);
}

// Every bin empty (the bins of a node are used at the one level it is open,
// so one clearing serves the whole partition), every sample in node 0.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void partition_clear(global uint* bins, global int* sample_part, const uint samples)
{
    const int i = get_global_id(0);
    if (i < samples)
        sample_part[i] = 0;
    if (i >= PART_MAX_NODES * 3 * PART_BINS)
        return;
    global uint* b = bins + i * PART_VALUES;
    CLEAR_BIN(b);
}

// One work-item: node 0 holds every sample (its centre bounds are
// centroid_bounds' result), open when it has more than `limit`.
__kernel void partition_init(global BuildPart* parts, global int* state, const int samples, const int limit)
{
    BuildPart root = part_node(samples, limit);
    root.centre_lo = (uint4)(state[STATE_BOUNDS + 0], state[STATE_BOUNDS + 1], state[STATE_BOUNDS + 2], 0u);
    root.centre_hi = (uint4)(state[STATE_BOUNDS + 3], state[STATE_BOUNDS + 4], state[STATE_BOUNDS + 5], 0u);
    parts[0] = root;
    state[STATE_PART_NODES] = 1;
    state[STATE_PART_SEGMENTS] = 1;
    state[STATE_PART_FIRST] = 0;
    state[STATE_PART_END] = 1;
}

// The levels decide on a sample of the triangles, every `stride`-th (all of
// them up to PART_SAMPLES): binning 50M triangles at every level cost more
// than the rest of the build, and the splits need only the shape of the
// distribution.  partition_morton_codes then takes every triangle down the
// finished tree.
//
// The first levels have a node or a few, so every triangle's atomics would
// meet on the same few cache lines (0.5 ms a level for bunny00 on the H200):
// there each work-group pools its samples in local memory (levels of at most
// PART_POOL nodes) and adds the pool to the global bins once.  A work-group
// takes samples grid-stride.
#define PART_POOL 8

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void partition_bin(const global float* corners, const uint samples, const uint stride,
                   const global int* sample_part, const global BuildPart* parts, global uint* bins,
                   const global int* state)
{
    local uint pool[PART_POOL * 3 * PART_BINS * PART_VALUES];
    const int first = state[STATE_PART_FIRST], end = state[STATE_PART_END];
    const bool pooled = end - first <= PART_POOL;
    const int lid = get_local_id(0);
    if (pooled) {
        for (int k = lid; k < (end - first) * 3 * PART_BINS; k += BUILD_GROUP) {
            local uint* b = pool + k * PART_VALUES;
            CLEAR_BIN(b);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    for (uint i = get_global_id(0); i < samples; i += get_global_size(0)) {
        const int n = sample_part[i];
        if (!parts[n].open)
            continue;
        float3 lo, hi;
        triangle_box(corners, i * stride, &lo, &hi);
        const float3 c = box_centre(lo, hi);
        const float3 clo = decode_bits(parts[n].centre_lo), chi = decode_bits(parts[n].centre_hi);
        for (int axis = 0; axis < 3; ++axis) {
            const int bin = centre_bin(axis_of(c, axis), axis_of(clo, axis), axis_of(chi, axis));
            if (pooled) {
                local uint* b = pool + bin_at(n - first, axis, bin);
                ADD_TO_BIN(b, lo, hi);
            } else {
                global uint* b = bins + bin_at(n, axis, bin);
                ADD_TO_BIN(b, lo, hi);
            }
        }
    }
    if (!pooled)
        return;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int k = lid; k < (end - first) * 3 * PART_BINS; k += BUILD_GROUP) {
        const local uint* b = pool + k * PART_VALUES;
        if (b[0] == 0u)
            continue;
        global uint* g = bins + first * 3 * PART_BINS * PART_VALUES + k * PART_VALUES;
        atomic_add(g, b[0]);
        for (int v = 1; v <= 3; ++v) {
            atomic_min(g + v, b[v]);
            atomic_max(g + v + 3, b[v + 3]);
        }
    }
}

inline void bin_box(const global uint* b, float3* lo, float3* hi)
{
    *lo = (float3)(from_ordered_bits(b[1]), from_ordered_bits(b[2]), from_ordered_bits(b[3]));
    *hi = (float3)(from_ordered_bits(b[4]), from_ordered_bits(b[5]), from_ordered_bits(b[6]));
}

// One work-group.  The nodes made by the last level (STATE_PART_FIRST ..
// STATE_PART_END) that are open find their cheapest split, a work-item each;
// work-item 0 then grants the splits in node order while the segments stay
// within `budget` (so the ids and the tree do not depend on timing), makes
// the children and closes the level.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void partition_split(global BuildPart* parts, const global uint* bins, global int* state, const int limit,
                     const int budget)
{
    local int chosen_axis[PART_MAX_NODES], chosen_split[PART_MAX_NODES], chosen_left[PART_MAX_NODES];
    local int chosen_child[PART_MAX_NODES];
    const int first = state[STATE_PART_FIRST], end = state[STATE_PART_END];
    for (int n = first + get_local_id(0); n < end; n += BUILD_GROUP) {
        int best_axis = -1, best_split = 0, best_left = 0;
        if (parts[n].open) {
            float best = INFINITY;
            for (int axis = 0; axis < 3; ++axis) {
                // Left of bin b: bins 0..b-1, costed from the left; the right
                // side from the right, each split's cost as it comes.
                float left_cost[PART_BINS];
                int left_count[PART_BINS];
                float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY), blo, bhi;
                int count = 0;
                for (int b = 0; b < PART_BINS - 1; ++b) {
                    const global uint* bin = bins + bin_at(n, axis, b);
                    if (bin[0]) {
                        bin_box(bin, &blo, &bhi);
                        lo = fmin(lo, blo);
                        hi = fmax(hi, bhi);
                        count += (int)bin[0];
                    }
                    left_count[b] = count;
                    left_cost[b] = count ? half_area(lo, hi) * (float)count : 0.0f;
                }
                lo = (float3)(INFINITY);
                hi = (float3)(-INFINITY);
                count = 0;
                for (int b = PART_BINS - 1; b > 0; --b) {
                    const global uint* bin = bins + bin_at(n, axis, b);
                    if (bin[0]) {
                        bin_box(bin, &blo, &bhi);
                        lo = fmin(lo, blo);
                        hi = fmax(hi, bhi);
                        count += (int)bin[0];
                    }
                    if (count == 0 || left_count[b - 1] == 0)
                        continue;
                    const float cost = left_cost[b - 1] + half_area(lo, hi) * (float)count;
                    if (cost < best) {
                        best = cost;
                        best_axis = axis;
                        best_split = b;
                        best_left = left_count[b - 1];
                    }
                }
            }
        }
        chosen_axis[n - first] = best_axis;
        chosen_split[n - first] = best_split;
        chosen_left[n - first] = best_left;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    // The grants, in node order, by one work-item over local memory (a few
    // microseconds; the same loop writing the children to global memory took
    // 0.1-0.2 ms a level), then the children made in parallel.
    local int granted_nodes, granted_segments;
    if (get_local_id(0) == 0) {
        int nodes = state[STATE_PART_NODES], segments = state[STATE_PART_SEGMENTS];
        for (int k = 0; k < end - first; ++k) {
            const bool grant = chosen_axis[k] >= 0 && segments < budget && nodes + 2 <= PART_MAX_NODES;
            chosen_child[k] = grant ? nodes : -1;
            if (grant) {
                nodes += 2;
                segments += 1;
            }
        }
        granted_nodes = nodes;
        granted_segments = segments;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int n = first + get_local_id(0); n < end; n += BUILD_GROUP) {
        const int k = n - first, child = chosen_child[k];
        parts[n].open = 0;
        if (child < 0)
            continue;
        parts[n].child = child;
        parts[n].axis = chosen_axis[k];
        parts[n].split = chosen_split[k];
        const int counts[2] = {chosen_left[k], parts[n].count - chosen_left[k]};
        for (int side = 0; side < 2; ++side)
            parts[child + side] = part_node(counts[side], limit);    // bounds: partition_assign
    }
    if (get_local_id(0) == 0) {
        state[STATE_PART_FIRST] = end;
        state[STATE_PART_END] = granted_nodes;
        state[STATE_PART_NODES] = granted_nodes;
        state[STATE_PART_SEGMENTS] = granted_segments;
    }
}

// Every sample of a node split at this level moves to the child its bin
// falls in and widens that child's centre bounds (pooled per work-group
// while the level's children are few, as partition_bin's bins).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void partition_assign(const global float* corners, const uint samples, const uint stride,
                      global int* sample_part, global BuildPart* parts, const global int* state)
{
    local uint pool[2 * PART_POOL * 6];    // the children's centre min xyz, max xyz
    const int first = state[STATE_PART_FIRST], end = state[STATE_PART_END];   // this level's children
    const bool pooled = end - first <= 2 * PART_POOL;
    const int lid = get_local_id(0);
    if (pooled) {
        for (int k = lid; k < (end - first) * 6; k += BUILD_GROUP)
            pool[k] = k % 6 < 3 ? 0xffffffffu : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    for (uint i = get_global_id(0); i < samples; i += get_global_size(0)) {
        const int n = sample_part[i];
        if (parts[n].child < first)     // not split at this level (-1: not split)
            continue;
        float3 lo, hi;
        triangle_box(corners, i * stride, &lo, &hi);
        const float3 c = box_centre(lo, hi);
        const int child = child_holding(parts, n, c);
        sample_part[i] = child;
        if (pooled) {
            local uint* b = pool + (child - first) * 6;
            WIDEN_BOUNDS(b, b + 3, c);
        } else {
            global uint* bounds = (global uint*)&parts[child];    // centre_lo, then centre_hi
            WIDEN_BOUNDS(bounds, bounds + 4, c);
        }
    }
    if (!pooled)
        return;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int k = lid; k < (end - first) * 6; k += BUILD_GROUP) {
        global uint* bounds = (global uint*)&parts[first + k / 6];
        const int v = k % 6;
        if (v < 3)
            atomic_min(bounds + v, pool[k]);
        else
            atomic_max(bounds + 4 + v - 3, pool[k]);
    }
}

// keys[i]: triangle i's segment -- found by taking it down the partition's
// splits from the root, as partition_assign took the samples -- above a
// 24-bit Morton code of its box centre on a 256^3 grid over the segment's
// centre bounds (morton_codes' 30-bit code is over the whole mesh's; the
// bounds are the samples', so a triangle outside them takes the nearest
// cell); ids[i] = i.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void partition_morton_codes(const global float* corners, const uint num_tris, const global BuildPart* parts,
                            global uint* keys, global uint* ids)
{
    const uint tri = get_global_id(0);
    if (tri >= num_tris)
        return;
    float3 box_lo, box_hi;
    triangle_box(corners, tri, &box_lo, &box_hi);
    const float3 c = box_centre(box_lo, box_hi);
    int n = 0;
    while (parts[n].child >= 0)
        n = child_holding(parts, n, c);
    keys[tri] = ((uint)parts[n].segment << (32 - SEGMENT_BITS))
              | morton_code(c, decode_bits(parts[n].centre_lo), decode_bits(parts[n].centre_hi), 256u);
    ids[tri] = tri;
}

// One work-item: the segments (nodes never split) numbered depth-first, left
// child first, into their `segment`; their count into STATE_PART_SEGMENTS.
__kernel void partition_order(global BuildPart* parts, global int* state)
{
    int stack[64];           // a path's pending right children: at most one a level
    int top = 0, next = 0, n = 0;
    for (;;) {
        if (parts[n].child >= 0) {
            stack[top++] = parts[n].child + 1;
            n = parts[n].child;
            continue;
        }
        parts[n].segment = next++;
        if (top == 0)
            break;
        n = stack[--top];
    }
    state[STATE_PART_SEGMENTS] = next;
}

#endif
