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
#include "instances.cl"

#if defined(ACCEL_BVH) && !defined(BVH_WIDE)

#ifndef BVH_STACK_SIZE
#error "build with -DBVH_STACK_SIZE=<at least the tree depth>"
#endif

// The step at a row, shared by both walks below: the children of row
// current->x that the ray meets in [tmin, tmax] -- the nearer next, in
// *current, the other postponed on the stack; false when it meets neither.
__attribute__((always_inline))
inline bool open_row(const Geometry* g, const VolumeRay* vr, const bool oblique, float tmin, float tmax,
                     const int query, int2* current, int2* stack, float* stack_t, int* sp)
{
    const BvhPairNode n = *SPLIT_AT(g, nodes, current->x);
    const int2 left_child = PAIR_LEFT(n), right_child = PAIR_RIGHT(n);
    float t_left, t_right;
    const bool left = left_child.y >= 0 && volume_hit(vr, n.left_a, n.left_b, tmin, tmax, &t_left, oblique);
    const bool right = right_child.y >= 0 && volume_hit(vr, n.right_a, n.right_b, tmin, tmax, &t_right, oblique);
    if (left && right) {
        // Near first finds the closest hit early, and any hit early too
        // (child order instead: any-hit up to 6 % slower on the H200).
        const bool right_first = query != QUERY_ALL && t_right < t_left;
        stack[*sp] = right_first ? left_child : right_child;
        if (query == QUERY_CLOSEST)   // only it drops children by distance (stack.cl)
            stack_t[*sp] = right_first ? t_left : t_right;
        ++*sp;
        *current = right_first ? right_child : left_child;
        return true;
    }
    if (left || right) {
        *current = left ? left_child : right_child;
        return true;
    }
    return false;
}

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
        } else if (open_row(g, vr, oblique, tmin, tmax, query, &current, stack, stack_t, &sp)) {
            continue;
        }
        if (!resume_postponed(stack, stack_t, &sp, tmax, &current, query == QUERY_CLOSEST))
            return best;
    }
}

#ifdef ACCEL_INSTANCES
// A stack entry's count that marks where the walk leaves an instance (rows
// and leaves have counts >= 0).
#define LEAVE_INSTANCE (-2)

// The walk of a two-level scene (docs/instances.md): the same loop over both
// levels, one stack.  The top level's rows (from row 0) hold the instances'
// world boxes, and each of its leaves one instance, by its index.  At such a
// leaf the ray moves into the instance's object space (instances.cl), a
// LEAVE_INSTANCE marker is pushed (at distance -INFINITY, so that the
// closest hit never drops it), and the walk goes on at the root row of the
// instance's mesh, whose rows and slots lie further on in the same buffers;
// when the marker comes off the stack, the world's volume ray is back.  t is
// the world's throughout (the object direction keeps its length), so tmax and
// the postponed distances carry over between levels.  Boxes are tested
// exactly (no FMA test): whether a ray is oblique changes with the space.
// *hit_instance: the instance of the returned hit (-1 for none).
inline Hit walk_instances(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax, const int query,
                          const bool spawned, HitSink* sink, int* hit_instance)
{
    const int cull = sink ? sink->cull : CULL_NONE;
    const float end = tmax;                            // a spawned ray's tmax as it set out
    const VolumeRay world = volume_ray(origin, dir, tree_reach(SPLIT_AT(g, nodes, 0)));
    VolumeRay vr = world;
    ShearedRay r;                                      // set when an instance is entered
    Hit best = miss_hit();
    int best_instance = -1;
    int instance = -1, object_cull = cull;             // the instance walked (-1: the top level), its cull
    int2 stack[BVH_STACK_SIZE];
    float stack_t[BVH_STACK_SIZE];
    int sp = 0;
    int2 current = (int2)(0, 0);
    for (;;) {
        if (current.y > 0 && instance < 0) {
            instance = current.x;
            __global const Instance* in = SPLIT_AT(g, instances, instance);
            const float3 o = object_point(in, origin), d = object_vector(in, dir);
            r = shear_ray(o, d, spawned, end);
            vr = volume_ray(o, d, tree_reach(SPLIT_AT(g, nodes, in->root)));
            object_cull = instance_cull(in, cull);
            stack[sp] = (int2)(0, LEAVE_INSTANCE);
            stack_t[sp] = -INFINITY;
            ++sp;
            current = (int2)(in->root, 0);
            continue;
        }
        if (current.y > 0) {
            for (int s = current.x; s < current.x + current.y; ++s)
                if (visit_instance_triangle(g, &r, s, instance, object_cull, tmin, &tmax, query, &best,
                                            &best_instance, sink)) {
                    *hit_instance = best_instance;
                    return best;
                }
        } else if (current.y == LEAVE_INSTANCE) {
            vr = world;
            instance = -1;
        } else if (open_row(g, &vr, false, tmin, tmax, query, &current, stack, stack_t, &sp)) {
            continue;
        }
        if (!resume_postponed(stack, stack_t, &sp, tmax, &current, query == QUERY_CLOSEST))
            break;
    }
    *hit_instance = best_instance;
    return best;
}

inline Hit query_instance_hits(const Geometry* g, float3 origin, float3 dir, float tmin, float tmax,
                               const int query, const bool spawned, HitSink* sink, int* hit_instance)
{
    return walk_instances(g, origin, dir, tmin, tmax, query, spawned, sink, hit_instance);
}

#else

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

#endif
