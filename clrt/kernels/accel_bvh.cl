// BVH traversal: one loop over an explicit stack, for every volume shape (the
// volume test comes from volumes.cl, chosen at build time) and every query
// (the leaf action comes from hit.cl).  The stack holds BVH_STACK_SIZE
// entries, set by the host from the tree's real depth: a depth-first walk that
// pushes at most one node per level cannot overflow it.
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

// Answer `query` for one ray (see hit.cl); the returned Hit.prim is a slot.
// For the closest hit, children are visited near first, and tmax shrinks to
// the best hit so far -- inclusively, so that a triangle at the same distance
// with a lower index is still reached.
inline Hit query_hits(ACCEL_PARAMS, float3 origin, float3 dir, float tmin, float tmax,
                      const int query, HitSink* sink)
{
    const ShearedRay r = shear_ray(origin, dir);
    const VolumeRay vr = volume_ray(origin, dir);
    Hit best = miss_hit();
    int best_id = -1;
    int stack[BVH_STACK_SIZE];
    int sp = 0;
    float t_left, t_right;
    if (!volume_hit(&vr, nodes, tmin, tmax, &t_left))
        return best;
    int node = 0;
    for (;;) {
        const BvhNode n = nodes[node];
        if (n.count > 0) {
            for (int s = n.left_first; s < n.left_first + n.count; ++s)
                if (visit_triangle(ACCEL_ARGS, &r, s, tmin, &tmax, query, &best, &best_id, sink))
                    return best;
        } else {
            const bool left = volume_hit(&vr, nodes + n.left_first, tmin, tmax, &t_left);
            const bool right = volume_hit(&vr, nodes + n.right, tmin, tmax, &t_right);
            if (left && right) {
                const bool right_first = query == QUERY_CLOSEST && t_right < t_left;
                stack[sp++] = right_first ? n.left_first : n.right;
                node = right_first ? n.right : n.left_first;
                continue;
            }
            if (left || right) {
                node = left ? n.left_first : n.right;
                continue;
            }
        }
        if (sp == 0)
            break;
        node = stack[--sp];
    }
    return best;
}

#endif
