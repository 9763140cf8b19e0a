// Closest points walked by the 32 work-items of a warp together (NVIDIA
// GPUs, -DPOINT_WARP_WALK: clrt.query.kernels.point_defines), included by
// point.cl after its walks.  The 32 points -- of one cell or two, as
// point_order.cl lays them out -- walk the binary BVH together.  Each
// computes its own children's bounds against its own best distance; a child
// is entered when any point needs it (a PTX vote), nearer first by a count
// of the points that find it so, and each point visits every leaf entered (a
// triangle more changes no answer: the best is the least (distance, index)
// of those seen, and every triangle a point could need is seen).  Every
// decision is the same for all 32, so they keep one path through the tree:
// no work-item waits on another's branch, and each node is read once for all
// of them.  Alone, the points' walks diverged: a third of the closest points'
// time on the H200 (docs/benchmarks.md).  The caller calls warp_closest_walk
// from every work-item of the warp (`active` false where there is no point),
// none returning before.
//
// With -DPOINT_WARP_EMULATE the votes are those of a warp of one work-item
// (warp_any(p) = p), so that every device runs the same walk, one point a
// work-item: tests/test_warp_walk.py compares it with the plain walk on PoCL.
#ifndef CLRT_POINT_WARP_CL
#define CLRT_POINT_WARP_CL

#if defined(POINT_WARP_WALK) && defined(ACCEL_BVH) && !defined(BVH_WIDE) && !defined(ACCEL_INSTANCES)
#define WARP_WALKS 1
#else
#define WARP_WALKS 0
#endif

#if WARP_WALKS
// Does p hold in any work-item of the warp; in how many?
#ifdef POINT_WARP_EMULATE
inline bool warp_any(bool p)
{
    return p;
}

inline uint warp_count(bool p)
{
    return p ? 1u : 0u;
}
#else
inline bool warp_any(bool p)
{
    int r;
    asm volatile("{ .reg .pred a, b; setp.ne.s32 a, %1, 0; vote.sync.any.pred b, a, 0xffffffff; "
                 "selp.s32 %0, 1, 0, b; }" : "=r"(r) : "r"((int)p));
    return r != 0;
}

inline uint warp_count(bool p)
{
    uint r;
    asm volatile("{ .reg .pred a; setp.ne.s32 a, %1, 0; vote.sync.ballot.b32 %0, a, 0xffffffff; }"
                 : "=r"(r) : "r"((int)p));
    return popcount(r);
}
#endif

inline void warp_closest_walk(const Geometry* g, float3 p, bool active, float margin, PointHit* best)
{
    const point_real3 pr = TO_POINT_REAL3(p);
    int2 stack[BVH_STACK_SIZE];        // the same rows and leaves in every work-item
    float stack_d[BVH_STACK_SIZE];     // each its own point's bound
    int sp = 0;
    int2 current = (int2)(0, 0);
    for (;;) {
        if (current.y > 0) {
            if (active)
                for (int s = current.x; s < current.x + current.y; ++s)
                    visit_point_triangle(g, pr, 0, s, best);
        } else {
            const BvhPairNode n = *SPLIT_AT(g, nodes, current.x);
            const int2 left_child = PAIR_LEFT(n), right_child = PAIR_RIGHT(n);
            const float reach = active ? (float)best->dist + margin : -INFINITY;
            const float d_left = left_child.y >= 0 ? point_bound(p, n.left_a, n.left_b) : INFINITY;
            const float d_right = right_child.y >= 0 ? point_bound(p, n.right_a, n.right_b) : INFINITY;
            const bool left = d_left <= reach, right = d_right <= reach;
            const bool any_left = warp_any(left), any_right = warp_any(right);
            if (any_left && any_right) {
                const bool right_first = warp_count(right && (!left || d_right < d_left))
                                         > warp_count(left && (!right || d_left <= d_right));
                stack[sp] = right_first ? left_child : right_child;
                stack_d[sp] = right_first ? d_left : d_right;
                ++sp;
                current = right_first ? right_child : left_child;
                continue;
            }
            if (any_left || any_right) {
                current = any_left ? left_child : right_child;
                continue;
            }
        }
        for (;;) {                     // the deepest postponed child that a point still needs
            if (sp == 0)
                return;
            --sp;
            if (warp_any(active && stack_d[sp] <= (float)best->dist + margin))
                break;
        }
        current = stack[sp];
    }
}
#endif

#endif
