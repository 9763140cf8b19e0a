// Traversal work of one closest-hit walk per ray over BVH_PAIR_NODE rows:
// the GPU walk of clrt/kernels/accel_bvh.cl (a row tests both children's
// boxes, the nearer child is entered first, the other postponed with its
// entry distance and dropped when popped beyond the best hit so far), with
// plain float32 slab tests and the Moller-Trumbore triangle test instead of
// the watertight one: counts for comparing trees, not hits to trust bit for
// bit (benchmarks/tree_counts.py).  Box rows only (volume "box").

#define STACK 128

typedef struct {
    float4 left_a, left_b, right_a, right_b;   // a: min xyz, w = ref; b: max xyz, w = count
} PairRow;

inline bool box_hit(float3 lo, float3 hi, float3 o, float3 inv, float tmax, float* t_enter)
{
    const float3 t0 = (lo - o) * inv, t1 = (hi - o) * inv;
    const float3 near = fmin(t0, t1), far = fmax(t0, t1);
    const float enter = fmax(fmax(near.x, near.y), fmax(near.z, 0.0f));
    // (1 + 2 gamma_3): the exit distance grown by its float32 rounding error
    // (pbrt's robust slab test), so that rounding never culls a box a ray meets.
    const float leave = fmin(fmin(far.x, far.y), far.z) * 1.00000036f;
    *t_enter = enter;
    return enter <= fmin(leave, tmax);
}

inline float triangle_t(float3 o, float3 d, float3 v0, float3 v1, float3 v2)
{
    const float3 e1 = v1 - v0, e2 = v2 - v0;
    const float3 p = cross(d, e2);
    const float det = dot(e1, p);
    if (det == 0.0f)
        return INFINITY;
    const float inv = 1.0f / det;
    const float3 s = o - v0;
    const float u = dot(s, p) * inv;
    const float3 q = cross(s, e1);
    const float v = dot(d, q) * inv;
    const float t = dot(e2, q) * inv;
    return (u >= 0.0f && v >= 0.0f && u + v <= 1.0f && t > 0.0f) ? t : INFINITY;
}

// counts[ray]: (rows opened, leaves entered, triangles tested, slot hit or -1).
__kernel void count_walk(__global const PairRow* rows, __global const float4* slotted, __global const float* origins,
                         __global const float* dirs, const uint num_rays, __global int4* counts,
                         __global volatile int* row_visits)
{
    const uint i = get_global_id(0);
    if (i >= num_rays)
        return;
    const float3 o = vload3(i, origins), d = vload3(i, dirs);
    const float3 inv = 1.0f / d;
    int2 stack[STACK];
    float stack_t[STACK];
    int sp = 0;
    int2 current = (int2)(0, 0);
    float tmax = INFINITY;
    int4 count = (int4)(0, 0, 0, -1);
    for (;;) {
        if (current.y > 0) {
            ++count.y;
            for (int s = current.x; s < current.x + current.y; ++s) {
                ++count.z;
                const float t = triangle_t(o, d, slotted[3 * s].xyz, slotted[3 * s + 1].xyz, slotted[3 * s + 2].xyz);
                if (t < INFINITY && t <= tmax && (t < tmax || count.w < 0 || s < count.w)) {
                    tmax = t;
                    count.w = s;
                }
            }
        } else {
            ++count.x;
            if (row_visits)
                atomic_inc(&row_visits[current.x]);
            const PairRow n = rows[current.x];
            const int2 l = (int2)(as_int(n.left_a.w), as_int(n.left_b.w));
            const int2 r = (int2)(as_int(n.right_a.w), as_int(n.right_b.w));
            float tl, tr;
            const bool hl = l.y >= 0 && box_hit(n.left_a.xyz, n.left_b.xyz, o, inv, tmax, &tl);
            const bool hr = r.y >= 0 && box_hit(n.right_a.xyz, n.right_b.xyz, o, inv, tmax, &tr);
            if (hl && hr) {
                const bool right_first = tr < tl;
                stack[sp] = right_first ? l : r;
                stack_t[sp] = right_first ? tl : tr;
                ++sp;
                current = right_first ? r : l;
                continue;
            }
            if (hl || hr) {
                current = hl ? l : r;
                continue;
            }
        }
        for (;;) {                      // the next postponed child still nearer than the best hit
            if (sp == 0) {
                counts[i] = count;
                return;
            }
            --sp;
            if (stack_t[sp] <= tmax) {
                current = stack[sp];
                break;
            }
        }
    }
}
