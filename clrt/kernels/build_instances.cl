// The top level of a scene of instances, built on the device (docs/instances.md,
// "Moving instances"; clrt/device/top_level.py queues the launches):
//
//   place_instances  each transform checked and its mesh's box mapped into
//                    the world (the caller's frame); per work-group the
//                    bounds of those boxes and of their centres, and the
//                    first instance each check names
//   instance_frame   the world's device frame (device_origin's choice) from
//                    them, and a summary the host reads at the end
//   instance_rows    each instance's Instance row in that frame (both maps,
//                    the padded world box, the mirror flag, the smallest
//                    scale's bound) and the Morton code of its box's centre
//   (the radix sort of build_sort.cl orders the codes)
//   lbvh_nodes       a linear BVH over the sorted codes (Karras 2012): inner
//                    node i is row i, the root row 0, one instance a leaf
//   lbvh_fit         bottom up: a leaf climbs while it is the second child to
//                    arrive at a node, and writes that node's row
//
// Fourteen launches on a GPU, queued at once (one read at the end): moving 10k
// instances is bound by launches, not by arithmetic.  The row arithmetic is
// clrt/accel/instances.py's, operation for operation in float64 without
// contraction into fma (the host rounds each product) and without a function that rounds
// otherwise than IEEE's +, -, *, / and sqrt, so the table is the host's bit
// for bit (tests/test_instances.py) and a scene answers alike whichever built
// its top level.
#ifndef CLRT_BUILD_INSTANCES_CL
#define CLRT_BUILD_INSTANCES_CL

#include "layouts.h"
#include "fences.cl"
#include "build_state.cl"
#include "build_morton.cl"
#include "build_fit.cl"
#include "build_emit.cl"

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#if !defined(INSTANCE_BOX_PAD) || !defined(MIN_SCALE_SLACK) || !defined(INVERSE_SLACK) \
    || !defined(RECHECK_CONDITION) || !defined(MAX_COORDINATE) || !defined(INSTANCE_MIRROR) \
    || !defined(GROUP_RESULTS)
#error "build with the instance constants of clrt/accel/instances.py (instance_defines)"
#endif

// Per work-group results of place_instances, GROUP_RESULTS doubles (a -D
// define of clrt/device/build.py): box lo xyz, box hi xyz, centre lo xyz,
// centre hi xyz, then the first instance to check on the host and the first
// placed past MAX_COORDINATE (num_instances: none).
#if GROUP_RESULTS != 14
#error "place_instances writes 14 doubles a work-group"
#endif

inline double dot3(double3 p, double3 q)
{
    return (p.x * q.x + p.y * q.y) + p.z * q.z;
}

// (Not the built-in cross: its rounding is not specified.)
inline double3 cross3(double3 p, double3 q)
{
    return (double3)(p.y * q.z - p.z * q.y, p.z * q.x - p.x * q.z, p.x * q.y - p.y * q.x);
}

// The square of the symmetric 3x3 matrix with diagonal *d and off-diagonal
// (01, 02, 12) *o, in place.
inline void square_symmetric(double3* d, double3* o)
{
    const double3 s = *d, t = *o;
    *d = (double3)((s.x * s.x + t.x * t.x) + t.y * t.y, (t.x * t.x + s.y * s.y) + t.z * t.z,
                   (t.y * t.y + t.z * t.z) + s.z * s.z);
    *o = (double3)((s.x * t.x + t.x * s.y) + t.y * t.z, (s.x * t.y + t.x * t.z) + t.y * s.z,
                   (t.x * t.y + s.y * t.z) + t.z * s.z);
}

// An upper bound of the largest eigenvalue of R R^T, R's rows r0, r1, r2
// (instances.py's eigenvalue_bound: the trace times tr(S^8)^(1/8), S the
// matrix over its trace -- at most 3^(1/8) above it).
inline double eigenvalue_bound(double3 r0, double3 r1, double3 r2)
{
    double3 d = (double3)(dot3(r0, r0), dot3(r1, r1), dot3(r2, r2));
    double3 o = (double3)(dot3(r0, r1), dot3(r0, r2), dot3(r1, r2));
    const double trace = (d.x + d.y) + d.z;
    d = d / trace;
    o = o / trace;
    square_symmetric(&d, &o);
    square_symmetric(&d, &o);
    const double f = ((d.x * d.x + d.y * d.y) + d.z * d.z) + 2.0 * ((o.x * o.x + o.y * o.y) + o.z * o.z);
    return trace * sqrt(sqrt(sqrt(f)));
}

// A linear part (rows a0, a1, a2) and what the table needs of it: the
// inverse's rows (adjugate over determinant), the determinant, a bound of
// the condition number at least the true one, and a lower bound of the
// smallest singular value (instances.py's linear_part).
typedef struct {
    double3 inv0, inv1, inv2;
    double det, condition, min_scale;
} LinearPart;

inline LinearPart linear_part(double3 a0, double3 a1, double3 a2)
{
    LinearPart p;
    const double3 u = cross3(a1, a2), v = cross3(a2, a0), x = cross3(a0, a1);
    p.det = dot3(a0, u);
    p.inv0 = (double3)(u.x, v.x, x.x) / p.det;
    p.inv1 = (double3)(u.y, v.y, x.y) / p.det;
    p.inv2 = (double3)(u.z, v.z, x.z) / p.det;
    const double largest = sqrt(eigenvalue_bound(a0, a1, a2));
    const double inverse = sqrt(eigenvalue_bound(p.inv0, p.inv1, p.inv2));
    p.condition = largest * inverse;
    p.min_scale = fmax((1.0 / inverse) * (1.0 - (MIN_SCALE_SLACK + INVERSE_SLACK * p.condition * p.condition)),
                       0.0);
    return p;
}

// The box lo..hi mapped by the affine map of rows a0, a1, a2 (linear part,
// translation in w): centre mapped, half extent through |linear part|
// (clrt.scene.instances.mapped_boxes).
inline void mapped_box(double4 a0, double4 a1, double4 a2, double3 lo, double3 hi, double3* out_lo,
                       double3* out_hi)
{
    const double3 centre = 0.5 * (lo + hi), extent = 0.5 * (hi - lo);
    const double3 mid = (double3)(dot3(a0.xyz, centre) + a0.w, dot3(a1.xyz, centre) + a1.w,
                                  dot3(a2.xyz, centre) + a2.w);
    const double3 reach = (double3)(dot3(fabs(a0.xyz), extent), dot3(fabs(a1.xyz), extent),
                                    dot3(fabs(a2.xyz), extent));
    *out_lo = mid - reach;
    *out_hi = mid + reach;
}

inline bool finite_affine(const global double4* m)
{
    bool finite = true;
    for (int r = 0; r < 4; ++r)
        finite = finite && all(isfinite(m[r]));
    return finite && all(m[3] == (double4)(0.0, 0.0, 0.0, 1.0));
}

// transforms: (I, 4, 4) float64 row-major; meshes: per mesh three double4,
// its box lo, hi (the caller's frame) and its device origin; mesh_of: (I,).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void place_instances(const global double4* transforms, const global int* mesh_of, const global double4* meshes,
                     const uint num_instances, global double* group_results, global uint* state)
{
    local double lows[6 * BUILD_GROUP], highs[6 * BUILD_GROUP];
    local uint firsts[2 * BUILD_GROUP];
    const uint lid = get_local_id(0);
    if (get_global_id(0) == 0)
        clear_build_state(state, num_instances);     // for the sort, later in the queue
    double3 box_lo = (double3)(INFINITY), box_hi = (double3)(-INFINITY);
    double3 mid_lo = box_lo, mid_hi = box_hi;
    uint recheck = num_instances, far = num_instances;
    for (uint i = get_global_id(0); i < num_instances; i += get_global_size(0)) {
        const global double4* m = transforms + 4 * i;
        const int mesh = mesh_of[i];
        double3 lo, hi;
        mapped_box(m[0], m[1], m[2], meshes[3 * mesh].xyz, meshes[3 * mesh + 1].xyz, &lo, &hi);
        const LinearPart p = linear_part(m[0].xyz, m[1].xyz, m[2].xyz);
        if (!finite_affine(m) || !(p.condition <= RECHECK_CONDITION * (1.0 - (MIN_SCALE_SLACK
                + INVERSE_SLACK * p.condition * p.condition))))
            recheck = min(recheck, i);
        if (!(fmax(fmax(fabs(lo.x), fabs(lo.y)), fmax(fmax(fabs(lo.z), fabs(hi.x)), fmax(fabs(hi.y), fabs(hi.z))))
              <= MAX_COORDINATE))
            far = min(far, i);
        box_lo = fmin(box_lo, lo);
        box_hi = fmax(box_hi, hi);
        mid_lo = fmin(mid_lo, 0.5 * (lo + hi));
        mid_hi = fmax(mid_hi, 0.5 * (lo + hi));
    }
    const double3 mine[4] = {box_lo, box_hi, mid_lo, mid_hi};
    for (int k = 0; k < 4; ++k) {
        local double* to = k % 2 ? highs : lows;
        const int at = 3 * (k / 2);
        to[(at + 0) * BUILD_GROUP + lid] = mine[k].x;
        to[(at + 1) * BUILD_GROUP + lid] = mine[k].y;
        to[(at + 2) * BUILD_GROUP + lid] = mine[k].z;
    }
    firsts[lid] = recheck;
    firsts[BUILD_GROUP + lid] = far;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint stride = BUILD_GROUP / 2; stride > 0; stride >>= 1) {
        if (lid < stride) {
            for (int k = 0; k < 6; ++k) {
                lows[k * BUILD_GROUP + lid] = fmin(lows[k * BUILD_GROUP + lid], lows[k * BUILD_GROUP + lid + stride]);
                highs[k * BUILD_GROUP + lid] = fmax(highs[k * BUILD_GROUP + lid],
                                                    highs[k * BUILD_GROUP + lid + stride]);
            }
            for (int k = 0; k < 2; ++k)
                firsts[k * BUILD_GROUP + lid] = min(firsts[k * BUILD_GROUP + lid],
                                                    firsts[k * BUILD_GROUP + lid + stride]);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) {
        global double* out = group_results + GROUP_RESULTS * get_group_id(0);
        for (int k = 0; k < 3; ++k) {
            out[k] = lows[k * BUILD_GROUP];
            out[3 + k] = highs[k * BUILD_GROUP];
            out[6 + k] = lows[(3 + k) * BUILD_GROUP];
            out[9 + k] = highs[(3 + k) * BUILD_GROUP];
        }
        out[12] = (double)firsts[0];
        out[13] = (double)firsts[BUILD_GROUP];
    }
}

// The world's device frame from place_instances' per-group results (`groups`
// of them, at most MAX_REDUCE_GROUPS: one work-item reads them all): the
// device origin of the instances' box, as the host's device_origin chooses
// it, and the box of the centres in that frame, into `frame` (instance_rows
// reads it: no wait for the host between the passes); and for the host, read
// at the end, `summary`: the box lo, hi, the origin (xyz each) and the first
// instance each check names (num_instances: none), as doubles.
__kernel void instance_frame(const global double* group_results, const uint groups,
                             const double recentre_distance, global float4* frame, global double* summary)
{
    if (get_global_id(0) != 0)
        return;
    double r[GROUP_RESULTS];
    for (int k = 0; k < GROUP_RESULTS; ++k)
        r[k] = group_results[k];
    for (uint g = 1; g < groups; ++g) {
        const global double* o = group_results + GROUP_RESULTS * g;
        for (int k = 0; k < GROUP_RESULTS; ++k)                      // lo xyz, hi xyz, mid lo, mid hi, firsts
            r[k] = (k / 3) % 2 == 0 || k >= 12 ? fmin(r[k], o[k]) : fmax(r[k], o[k]);
    }
    const double3 o3 = frame_origin((double3)(r[0], r[1], r[2]), (double3)(r[3], r[4], r[5]), recentre_distance);
    frame[0] = (float4)(convert_float3(o3), 0.0f);
    frame[1] = (float4)(convert_float3((double3)(r[6], r[7], r[8]) - o3), 0.0f);
    frame[2] = (float4)(convert_float3((double3)(r[9], r[10], r[11]) - o3), 0.0f);
    for (int k = 0; k < 6; ++k)
        summary[k] = r[k];
    summary[6] = o3.x;
    summary[7] = o3.y;
    summary[8] = o3.z;
    summary[9] = r[12];
    summary[10] = r[13];
}

// frame: the world's device origin (float32 values, as device_origin chooses
// them) and the box over which the Morton codes are taken, both in xyz.
// Writes every field of each row but mesh, root, first, count and material,
// which the scene keeps; clears the arrivals of lbvh_fit.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void instance_rows(const global double4* transforms, const global int* mesh_of, const global double4* meshes,
                   const global float4* frame, const uint num_instances, global Instance* table, global uint* keys,
                   global uint* ids, global uint* arrivals)
{
    const uint i = get_global_id(0);
    if (i >= num_instances)
        return;
    if (i + 1 < num_instances)
        arrivals[i] = 0u;
    const global double4* m = transforms + 4 * i;
    const int mesh = mesh_of[i];
    const double origin[3] = {frame[0].x, frame[0].y, frame[0].z};
    const double3 c = meshes[3 * mesh + 2].xyz;
    const double4 a[3] = {m[0], m[1], m[2]};
    // to_world: p_world - origin = A (p_mesh + c) + t - origin
    double4 w[3];
    for (int r = 0; r < 3; ++r)
        w[r] = (double4)(a[r].xyz, a[r].w + (dot3(a[r].xyz, c) - origin[r]));
    const LinearPart p = linear_part(a[0].xyz, a[1].xyz, a[2].xyz);
    const double3 t = (double3)(w[0].w, w[1].w, w[2].w);
    const double4 inv[3] = {(double4)(p.inv0, -dot3(p.inv0, t)), (double4)(p.inv1, -dot3(p.inv1, t)),
                            (double4)(p.inv2, -dot3(p.inv2, t))};
    double3 lo, hi;
    mapped_box(w[0], w[1], w[2], meshes[3 * mesh].xyz - c, meshes[3 * mesh + 1].xyz - c, &lo, &hi);
    const double3 d = hi - lo;
    const double3 far = fmax(fabs(lo), fabs(hi));
    const double size = sqrt((d.x * d.x + d.y * d.y) + d.z * d.z) + fmax(fmax(far.x, far.y), far.z);
    const double pad = (INSTANCE_BOX_PAD * p.condition) * size;
    global Instance* row = table + i;
    for (int r = 0; r < 3; ++r) {
        row->to_world[r] = convert_float4(w[r]);
        row->to_object[r] = convert_float4(inv[r]);
    }
    const float3 lo32 = convert_float3_rtn(lo - pad), hi32 = convert_float3_rtp(hi + pad);
    row->lo = (float4)(lo32, 0.0f);
    row->hi = (float4)(hi32, 0.0f);
    row->flags = p.det < 0.0 ? INSTANCE_MIRROR : 0u;
    row->min_scale = convert_float_rtn(p.min_scale);
    keys[i] = morton_code(box_centre(lo32, hi32), frame[1].xyz, frame[2].xyz, 1024u);
    ids[i] = i;
}

// Karras's delta: the length of the common prefix of the keys of leaves i
// and j, their places breaking ties (so every key is distinct); -1 past the ends.
inline int common_prefix(const global uint* keys, int n, int i, int j)
{
    if (j < 0 || j >= n)
        return -1;
    const uint a = keys[i], b = keys[j];
    return a == b ? 32 + clz((uint)(i ^ j)) : clz(a ^ b);
}

// Inner node i (< n - 1) of the linear BVH over the n sorted keys: the range
// of leaves it covers and where that range splits (Karras 2012, "Maximizing
// parallelism in the construction of BVHs, octrees, and k-d trees", fig. 4).
// children[i]: its children, an inner node's index or ~leaf; parents: of
// the inner nodes, then of the leaves (n - 1 + leaf); the root's is -1.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void lbvh_nodes(const global uint* keys, const uint num_instances, global int2* children, global int* parents)
{
    const int n = (int)num_instances, i = (int)get_global_id(0);
    if (i >= n - 1)
        return;
    const int d = common_prefix(keys, n, i, i + 1) - common_prefix(keys, n, i, i - 1) > 0 ? 1 : -1;
    const int lowest = common_prefix(keys, n, i, i - d);
    int reach = 2;
    while (common_prefix(keys, n, i, i + reach * d) > lowest)
        reach *= 2;
    int length = 0;
    for (int step = reach / 2; step >= 1; step /= 2)
        if (common_prefix(keys, n, i, i + (length + step) * d) > lowest)
            length += step;
    const int j = i + length * d;
    const int prefix = common_prefix(keys, n, i, j);
    int split = 0, step = length;
    do {
        step = (step + 1) >> 1;
        if (common_prefix(keys, n, i, i + (split + step) * d) > prefix)
            split += step;
    } while (step > 1);
    const int gamma = i + split * d + min(d, 0);
    const int left = min(i, j) == gamma ? ~gamma : gamma;
    const int right = max(i, j) == gamma + 1 ? ~(gamma + 1) : gamma + 1;
    children[i] = (int2)(left, right);
    parents[left >= 0 ? left : n - 1 + ~left] = i;
    parents[right >= 0 ? right : n - 1 + ~right] = i;
    if (i == 0)
        parents[0] = -1;
}

// One child of a row: an inner node (row `node`, count 0) or a leaf (the
// instance it holds, count 1), its box read from `boxes` (volatile: another
// work-item wrote it during this launch).
inline void write_top_child(global float4* child_a_b, global float4* exact_a_b, int node, int n,
                            const global uint* sorted_ids, const volatile global float4* boxes)
{
    const int at = node >= 0 ? node : n - 1 + ~node;
    const float4 lo = boxes[2 * at], hi = boxes[2 * at + 1];
    write_child(child_a_b, lo.xyz, hi.xyz, node >= 0 ? node : (int)sorted_ids[~node], node >= 0 ? 0 : 1, exact_a_b);
}

// boxes: exact boxes of the inner nodes, then of the leaves (two float4 a
// node); arrivals: one per inner node, zeroed by instance_rows.  Rows and
// exact rows (the unpadded boxes, for statistics) as emit_tree writes them;
// a single instance is a root row with the leaf on its left.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void lbvh_fit(const global int2* children, const global int* parents, const global uint* sorted_ids,
              const global Instance* table, const uint num_instances, global float4* boxes,
              global uint* arrivals, global BvhPairNode* rows, global BvhPairNode* exact_rows)
{
    const int n = (int)num_instances, leaf = (int)get_global_id(0);
    if (leaf >= n)
        return;
    const global Instance* in = table + sorted_ids[leaf];
    boxes[2 * (n - 1 + leaf)] = in->lo;
    boxes[2 * (n - 1 + leaf) + 1] = in->hi;
    if (n == 1) {
        write_top_child(&rows[0].left_a, &exact_rows[0].left_a, ~0, n, sorted_ids, boxes);
        rows[0].right_a = rows[0].right_b = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
        exact_rows[0].right_a = exact_rows[0].right_b = rows[0].right_a;
        return;
    }
    for (int node = parents[n - 1 + leaf]; node >= 0; node = parents[node]) {
        release_fence();                            // this child's box before its arrival
        if (atomic_inc(arrivals + node) == 0u)
            return;                                 // the sibling's work-item goes on
        acquire_fence();
        const int2 child = children[node];
        const volatile global float4* shared = boxes;
        const int l = child.x >= 0 ? child.x : n - 1 + ~child.x, r = child.y >= 0 ? child.y : n - 1 + ~child.y;
        boxes[2 * node] = fmin(shared[2 * l], shared[2 * r]);
        boxes[2 * node + 1] = fmax(shared[2 * l + 1], shared[2 * r + 1]);
        write_top_child(&rows[node].left_a, &exact_rows[node].left_a, child.x, n, sorted_ids, shared);
        write_top_child(&rows[node].right_a, &exact_rows[node].right_a, child.y, n, sorted_ids, shared);
    }
}

#endif
