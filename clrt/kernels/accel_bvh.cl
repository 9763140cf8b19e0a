// BVH traversal: one loop over an explicit stack, for every volume shape (the
// volume test comes from volumes.cl, chosen at build time) and every query
// (the leaf action comes from hit.cl).  Each row holds both children's
// volumes, so one fetch decides where to go.  The stack holds BVH_STACK_SIZE
// entries, at least the tree's real depth (the host rounds the depth up, so
// that trees of similar depth share one program): a depth-first walk that
// pushes at most one child per level cannot overflow it.
//
// Triangles are stored in leaf order ("slots"); prim_ids maps a slot to the
// input triangle index, which is what decides ties and what queries report.
#ifndef CLRT_ACCEL_BVH_CL
#define CLRT_ACCEL_BVH_CL

#include "geometry.cl"
#include "hit.cl"
#include "volumes.cl"
#include "stack.cl"

#if defined(ACCEL_BVH) && !defined(BVH_WIDE)

#ifndef BVH_STACK_SIZE
#error "build with -DBVH_STACK_SIZE=<at least the tree depth>"
#endif

// The walk of query_hits, `oblique` a constant in each call, so that each walk
// is compiled with one box test and none decides per box which.  Where
// OBLIQUE_WALK is defined (the query program, trace.cl), oblique rays take a
// walk of their own with the FMA test: 3-8 % less kernel time than the exact
// test on incoherent rays on the H200 (and 3-6 % less than one walk deciding
// per box).  Other programs -- the renderer's kernels, each with a closest-hit
// and an any-hit walk -- ran 5-8 % slower with the second walk, and walk every
// ray with the exact test (docs/benchmark-log.md).  (The CPU's wide walk,
// accel_wide.cl, takes the FMA test for oblique rays in every program.)
// The walk holds one current child -- a row to open, or a leaf to test -- and
// a stack of postponed children with the distance where the ray enters them.
// Children are visited near first; for the closest hit tmax shrinks to the
// best hit so far -- inclusively, so that a triangle at the same distance with
// a lower index is still reached -- and a postponed child whose volume starts
// beyond tmax is dropped when it is popped.
inline Hit walk_tree(const Geometry* g, const ShearedRay* r, const VolumeRay* vr, const bool oblique,
                     float tmin, float tmax, const int query, HitSink* sink)
{
    Hit best = miss_hit();
    int2 stack[BVH_STACK_SIZE];        // (row or first slot, leaf count: 0 for a row)
    float stack_t[BVH_STACK_SIZE];
    int sp = 0;
    int2 current = (int2)(0, 0);       // the root row
    for (;;) {
        if (current.y > 0) {
            for (int s = current.x; s < current.x + current.y; ++s)
                if (visit_triangle(g, r, s, tmin, &tmax, query, &best, sink))
                    return best;
        } else {
            const BvhPairNode n = *SPLIT_AT(g, nodes, current.x);
            const int2 left_child = PAIR_LEFT(n), right_child = PAIR_RIGHT(n);
            float t_left, t_right;
            const bool left = left_child.y >= 0 && volume_hit(vr, n.left_a, n.left_b, tmin, tmax, &t_left, oblique);
            const bool right = right_child.y >= 0 && volume_hit(vr, n.right_a, n.right_b, tmin, tmax, &t_right, oblique);
            if (left && right) {
                // Near first finds the closest hit early, and any hit early too
                // (child order instead: any-hit up to 6 % slower on the H200).
                const bool right_first = query != QUERY_ALL && t_right < t_left;
                stack[sp] = right_first ? left_child : right_child;
                if (query == QUERY_CLOSEST)   // only it drops children by distance (stack.cl)
                    stack_t[sp] = right_first ? t_left : t_right;
                ++sp;
                current = right_first ? right_child : left_child;
                continue;
            }
            if (left || right) {
                current = left ? left_child : right_child;
                continue;
            }
        }
        if (!resume_postponed(stack, stack_t, &sp, tmax, &current, query == QUERY_CLOSEST))
            return best;
    }
}

// Answer `query` for one ray (see hit.cl; `spawned`: triangle.cl's shear_ray);
// the returned Hit.prim is a slot.
inline Hit query_hits(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax,
                      const int query, const bool spawned, HitSink* sink)
{
    const ShearedRay r = shear_ray(origin, dir, spawned, tmax);
    const VolumeRay vr = volume_ray(origin, dir, tree_reach(SPLIT_AT(g, nodes, 0)));
#ifdef OBLIQUE_WALK
    return vr.oblique ? walk_tree(g, &r, &vr, true, tmin, tmax, query, sink)
                      : walk_tree(g, &r, &vr, false, tmin, tmax, query, sink);
#else
    return walk_tree(g, &r, &vr, false, tmin, tmax, query, sink);
#endif
}

#endif

#endif
