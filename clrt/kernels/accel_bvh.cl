// BVH traversal: one loop over an explicit stack, for every volume shape (the
// volume test comes from volumes.cl, chosen at build time) and every query
// (the leaf action comes from hit.cl).  Each row holds both children's
// volumes, so one fetch decides where to go; leaf children are tested on the
// spot.  The stack holds BVH_STACK_SIZE entries, set by the host from the
// tree's real depth: a depth-first walk that pushes at most one row per level
// cannot overflow it.
//
// Triangles are stored in leaf order ("slots"); prim_ids maps a slot to the
// input triangle index, which is what decides ties and what queries report.
#ifndef CLRT_ACCEL_BVH_CL
#define CLRT_ACCEL_BVH_CL

#include "hit.cl"
#include "volumes.cl"

#ifndef BVH_STACK_SIZE
#error "build with -DBVH_STACK_SIZE=<tree depth>"
#endif

// Test the triangles of a leaf; true once the query is answered.
inline bool visit_leaf(ACCEL_PARAMS, const ShearedRay* r, int first, int count, float tmin, float* tmax,
                       const int query, Hit* best, int* best_id, HitSink* sink)
{
    for (int s = first; s < first + count; ++s)
        if (visit_triangle(ACCEL_ARGS, r, s, tmin, tmax, query, best, best_id, sink))
            return true;
    return false;
}

// Answer `query` for one ray (see hit.cl); the returned Hit.prim is a slot.
// For the closest hit, children are visited near first, and tmax shrinks to
// the best hit so far -- inclusively, so that a triangle at the same distance
// with a lower index is still reached; a postponed child whose volume starts
// beyond tmax is dropped when it is popped.
inline Hit query_hits(ACCEL_PARAMS, float3 origin, float3 dir, float tmin, float tmax,
                      const int query, HitSink* sink)
{
    const ShearedRay r = shear_ray(origin, dir);
    const VolumeRay vr = volume_ray(origin, dir);
    Hit best = miss_hit();
    int best_id = -1;
    int stack[BVH_STACK_SIZE];
    float stack_t[BVH_STACK_SIZE];
    int sp = 0;
    int row = 0;
    for (;;) {
        const BvhPairNode n = nodes[row];
        float t_left, t_right;
        bool left = n.left_count >= 0 && volume_hit(&vr, n.left_a, n.left_b, tmin, tmax, &t_left);
        bool right = n.right_count >= 0 && volume_hit(&vr, n.right_a, n.right_b, tmin, tmax, &t_right);
        // Leaves are tested at once, the nearer first.
        const bool right_first = t_right < t_left;
        if (right && n.right_count > 0 && right_first) {
            if (visit_leaf(ACCEL_ARGS, &r, n.right, n.right_count, tmin, &tmax, query, &best, &best_id, sink))
                return best;
            right = false;
        }
        if (left && n.left_count > 0) {
            if (visit_leaf(ACCEL_ARGS, &r, n.left, n.left_count, tmin, &tmax, query, &best, &best_id, sink))
                return best;
            left = false;
        }
        if (right && n.right_count > 0 && t_right <= tmax) {
            if (visit_leaf(ACCEL_ARGS, &r, n.right, n.right_count, tmin, &tmax, query, &best, &best_id, sink))
                return best;
            right = false;
        }
        left = left && t_left <= tmax;
        right = right && n.right_count == 0 && t_right <= tmax;
        if (left && right) {
            const bool far_left = query == QUERY_CLOSEST && right_first;
            stack[sp] = far_left ? n.left : n.right;
            stack_t[sp++] = far_left ? t_left : t_right;
            row = far_left ? n.right : n.left;
            continue;
        }
        if (left || right) {
            row = left ? n.left : n.right;
            continue;
        }
        // Pop the next postponed row that may still hold something nearer than tmax.
        do {
            if (sp == 0)
                return best;
            row = stack[--sp];
        } while (stack_t[sp] > tmax);
    }
}

#endif
