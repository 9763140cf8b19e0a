// BVH traversal on CPU devices (-DBVH_WIDE, box volumes): the tree of
// accel_bvh.cl collapsed into nodes of eight children, and its leaves'
// triangles in packets of four (clrt/accel/wide.py says how and why).  A CPU
// runs each work-item's walk as scalar code, so the SIMD units are reached
// only through vector types inside one work-item: one float8 slab test
// (volumes.cl) decides all children of a node, one float4 watertight test
// (triangle.cl) a packet of triangles, as in Embree's single-ray BVH8 walk.
//
// The answers are accel_bvh.cl's bit for bit: every box is its binary row's,
// tested lane by lane with the same arithmetic; every triangle lane computes
// the scalar test's t, u, v; every hit goes through the same leaf action
// (record_hit, hit.cl), whose tie rule does not depend on the visiting order.
// Only the order of the walk differs, and tmax only ever shrinks to a hit.
#ifndef CLRT_ACCEL_WIDE_CL
#define CLRT_ACCEL_WIDE_CL

#include "geometry.cl"
#include "hit.cl"
#include "triangle.cl"
#include "volumes.cl"
#include "stack.cl"
#include "lanes.cl"

#if defined(ACCEL_BVH) && defined(BVH_WIDE)

#ifndef WIDE_STACK_SIZE
#error "build with -DWIDE_STACK_SIZE=<at least 7 x the wide tree's depth + 1>"
#endif

// Test the packet `packet` for `query`, its hits in lane order; true once the
// query is answered.  Forced inline, with the packet test: PoCL keeps both as
// calls otherwise, and around a call the walk's float8 values (the ray's
// broadcast origin and inverse direction) go through the stack (80 stack
// accesses in the walk's code, 30 inlined): 1.5-5 % faster, docs/benchmark-log.md.
__attribute__((always_inline))
inline bool visit_packet(const Geometry* g, const ShearedRay* r, int packet, float tmin, float* tmax,
                         const int query, Hit* best, HitSink* sink)
{
    __global const TrianglePacket* p = g->packets + packet;
    float4 t, u, v;
    const int4 hit = intersect_packet_culled(r, p, tmin, *tmax, sink ? sink->cull : CULL_NONE, &t, &u, &v);
    if (!any(hit))
        return false;
    for (int k = 0; k < 4; ++k)
        if (hit[k] && record_hit(g, p->slot[k], t[k], u[k], v[k], tmax, query, best, sink))
            return true;
    return false;
}

// The walk of query_hits for a ray whose VolumeRay has `oblique`, a constant
// in each of its two calls (as in accel_bvh.cl).  As accel_bvh.cl: one current
// child -- a node, or a leaf's packets -- and a stack of postponed children
// with the distance where the ray enters them.  For the closest hit, a node's
// children that the ray meets are pushed farthest first (insertion sort:
// rarely more than three), and the nearest is taken at once.  Other queries
// take them in lane order and keep no distances: on PoCL that made any-hit
// 3-9 % faster on random and diffuse rays (the binary walk's any-hit stays
// near first: in its order it was up to 6 % slower on the H200).
// Left a call (PoCL does not inline it): forced inline into the queries,
// whose eight rays each pay its entry (the ray's float8 constants stored to
// the stack), 1M random rays were 2-4 % faster, but PoCL's first compile of
// a query 0.4-0.8 s longer (docs/benchmark-log.md, session 30).
inline Hit walk_wide_tree(const Geometry* g, const ShearedRay* r, const VolumeRay* vr, const bool oblique,
                          float tmin, float tmax, const int query, HitSink* sink)
{
    const BoxPlanes planes = box_planes(vr);
    Hit best = miss_hit();
    int2 stack[WIDE_STACK_SIZE];       // (node or first packet, packet count: 0 for a node)
    float stack_t[WIDE_STACK_SIZE];
    int sp = 0;
    int2 current = (int2)(0, 0);       // the root node
    for (;;) {
        if (current.y > 0) {
            for (int p = current.x; p < current.x + current.y; ++p)
                if (visit_packet(g, r, p, tmin, &tmax, query, &best, sink))
                    return best;
        } else {
            __global const BvhWideNode* n = g->wide_nodes + current.x;
            float8 enter;
            const int8 met = oblique ? box_hit_wide_oblique(vr, planes, n, tmin, tmax, &enter)
                                     : box_hit_wide(vr, n, tmin, tmax, &enter);
            uint lanes = lane_bits(met & (n->count >= 0));
            if (lanes) {
                __global const int* child = (__global const int*)&n->child;
                __global const int* count = (__global const int*)&n->count;
                int k = 31 - clz(lanes & (0u - lanes));   // the lowest lane left
                lanes &= lanes - 1u;
                if (!lanes) {                             // one child met: no stack
                    current = (int2)(child[k], count[k]);
                    continue;
                }
                if (!(lanes & (lanes - 1u))) {            // two met: no loop
                    // the loop's order (the closest hit: the nearer, the higher
                    // lane on a tie; else the higher lane first), by selects rather
                    // than its compare-and-shift: 1-4 % faster, docs/benchmark-log.md
                    const int k2 = 31 - clz(lanes);
                    const float t1 = enter[k], t2 = enter[k2];
                    const int2 c1 = (int2)(child[k], count[k]), c2 = (int2)(child[k2], count[k2]);
                    const bool first_near = query == QUERY_CLOSEST && t1 < t2;
                    current = first_near ? c1 : c2;
                    stack[sp] = first_near ? c2 : c1;
                    if (query == QUERY_CLOSEST)
                        stack_t[sp] = first_near ? t2 : t1;
                    ++sp;
                    continue;
                }
                const int base = sp;
                for (;;) {
                    const float t = enter[k];
                    int j = sp++;
                    if (query == QUERY_CLOSEST)
                        for (; j > base && stack_t[j - 1] < t; --j) {
                            stack[j] = stack[j - 1];
                            stack_t[j] = stack_t[j - 1];
                        }
                    stack[j] = (int2)(child[k], count[k]);
                    if (query == QUERY_CLOSEST)
                        stack_t[j] = t;
                    if (!lanes)
                        break;
                    k = 31 - clz(lanes & (0u - lanes));
                    lanes &= lanes - 1u;
                }
                current = stack[--sp];    // the nearest
                continue;
            }
        }
        if (!resume_postponed(stack, stack_t, &sp, tmax, &current, query == QUERY_CLOSEST))
            return best;
    }
}

// Answer `query` for one ray set up by shear_ray and volume_ray (or their
// lane forms: trace.cl's answer_rays sets up eight rays at a time); Hit.prim
// is a slot.
inline Hit walk_ray(const Geometry* g, const ShearedRay* r, const VolumeRay* vr, float tmin, float tmax,
                    const int query, HitSink* sink)
{
    return vr->oblique ? walk_wide_tree(g, r, vr, true, tmin, tmax, query, sink)
                       : walk_wide_tree(g, r, vr, false, tmin, tmax, query, sink);
}

// Answer `query` for one ray (see hit.cl; `spawned`: triangle.cl's shear_ray);
// the returned Hit.prim is a slot.
inline Hit query_hits(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax,
                      const int query, const bool spawned, HitSink* sink)
{
    const ShearedRay r = shear_ray(origin, dir, spawned, tmax);
    const VolumeRay vr = volume_ray(origin, dir, tree_reach(SPLIT_AT(g, nodes, 0)));
    return walk_ray(g, &r, &vr, tmin, tmax, query, sink);
}

#endif

#endif
