// Closest points eight at a time, on CPU devices (-DPOINT_GROUPS, which
// clrt/query/points.py's point_group_defines sets where the device walks the
// wide BVH of a one-level scene, eight rays a work-item): trace.cl's
// query_closest_point and signed distances take a work-item's points in
// groups of eight neighbours (the order of point_order.cl), one point a lane
// of float8 values, and walk the wide BVH once for the eight
// (walk_wide_point_group) instead of once for each (point.cl's
// walk_wide_points).  A node's children are tested once for the box of the
// eight, then those within its reach for each point (lane_child_bounds); a
// leaf's triangles once each for all eight (POINT_TRIANGLE_BOUNDS with the
// points in lanes).  What makes that pay: neighbours need much the same
// leaves -- on bunny00 (1M points in its box) eight need 23 between them,
// each 9 (docs/benchmark-log.md).
//
// Exact as walk_wide_points is, bit for bit: a lane skips a child only where
// its own lower bound exceeds its reach, and a triangle only where its lower
// bound exceeds its visit bound (POINT_TIE_SLACK above its best); the box of
// the eight lies no farther than any of its points (each float32 step of the
// box distance rounds a difference no larger than the point's: monotone).
// What bounds a lane's distance from above, for both, is the least of its
// best visited distance and the float32 upper bounds (POINT_TRIANGLE_BOUNDS)
// of the triangles tested for it: a triangle whose upper bound lowers that is
// itself within reach, and visited.  A lane visits a triangle within its
// visit bound at the end of the walk, not at once (up to POINT_CANDIDATES of
// them a lane; beyond, at once): in the group's order of nodes a lane meets
// many triangles nearer than its best so far but farther than its answer.
// Before the walk the nearest triangles of the group before (seeds) give
// upper bounds; a work-item's first group first takes a leaf near all eight
// (the group's nearest child at each level).
#ifndef CLRT_POINT_GROUP_CL
#define CLRT_POINT_GROUP_CL

#include "point.cl"
#include "lanes.cl"
#include "accel_packet.cl"

#ifdef POINT_GROUPS
#if !defined(ACCEL_BVH) || !defined(BVH_WIDE) || defined(ACCEL_INSTANCES)
#error "POINT_GROUPS walks the wide BVH of a one-level scene"
#endif
#ifndef RAY_PACKETS
#error "POINT_GROUPS walks eight points in float8 lanes: build it with -DRAY_PACKETS=8"
#endif
#ifndef POINT_CANDIDATES
#error "build with -DPOINT_CANDIDATES=<triangles a lane keeps to visit> (clrt/config.py)"
#endif

// Lower bounds of the distances from eight points to one triangle (a, b, c),
// and upper bounds (*upper): POINT_TRIANGLE_BOUNDS with the points in lanes.
__attribute__((always_inline))
inline float8 lane_distance_bounds(float3 a, float3 b, float3 c, float8 px, float8 py, float8 pz, float8* upper_out)
{
    const float8 apx = px - a.x, apy = py - a.y, apz = pz - a.z;
    const float abx = b.x - a.x, aby = b.y - a.y, abz = b.z - a.z;
    const float acx = c.x - a.x, acy = c.y - a.y, acz = c.z - a.z;
    POINT_TRIANGLE_BOUNDS(float8, int8, float);
    *upper_out = upper;
    return lower;
}

// Squared lower bounds of the distances from the box lo .. hi to node n's
// children (boxes only: where the eight points lie apart, the disks' lateral
// reach is mostly the box's).
__attribute__((always_inline))
inline float8 group_child_bounds(__global const BvhWideNode* n, float3 lo, float3 hi)
{
    const float8 dx = fmax(fmax(n->lo_x - hi.x, lo.x - n->hi_x), 0.0f);
    const float8 dy = fmax(fmax(n->lo_y - hi.y, lo.y - n->hi_y), 0.0f);
    const float8 dz = fmax(fmax(n->lo_z - hi.z, lo.z - n->hi_z), 0.0f);
    return dx * dx + dy * dy + dz * dz;
}

// Squared lower bounds of the distances from eight points to child k of node
// n: walk_wide_points' box and, for a leaf, disk (WideDisk) bounds.  An inner
// child takes its box alone: its disk, around a larger curved patch, rarely
// prunes what the box does not, and the test is made for every child within
// the group's reach.
__attribute__((always_inline))
inline float8 lane_child_bounds(__global const BvhWideNode* n, __global const WideDisk* disk, int k, bool leaf,
                                float8 px, float8 py, float8 pz)
{
    const float8 dx = fmax(fmax(n->lo_x[k] - px, px - n->hi_x[k]), 0.0f);
    const float8 dy = fmax(fmax(n->lo_y[k] - py, py - n->hi_y[k]), 0.0f);
    const float8 dz = fmax(fmax(n->lo_z[k] - pz, pz - n->hi_z[k]), 0.0f);
    const float8 box = dx * dx + dy * dy + dz * dz;
    if (!leaf)
        return box;
    const float nx = disk->nx[k], ny = disk->ny[k], nz = disk->nz[k];
    const float8 vx = px - disk->cx[k], vy = py - disk->cy[k], vz = pz - disk->cz[k];
    const float8 h = vx * nx + vy * ny + vz * nz;
    const float8 lx = vx - h * nx, ly = vy - h * ny, lz = vz - h * nz;
    const float8 across = fmax(fabs(h) - disk->half_height[k], 0.0f);
    const float8 beside = fmax(sqrt(lx * lx + ly * ly + lz * lz) - disk->radius[k], 0.0f);
    return fmax(box, across * across + beside * beside);
}

// The bit number of the lowest set bit of `bits` (not 0).
#define LOWEST_LANE(bits) (31 - clz((bits) & (0u - (bits))))

// The nearest triangles to the points p[k] of the lanes set in `active`
// (margin[k]: POINT_MARGIN), into best[k] (set up as closest_point does);
// seeds: the slots of the nearest triangles of the group before (-1: none).
inline void walk_wide_point_group(const Geometry* g, const float3* p, const float* margin, uint active,
                                  const int* seeds, PointHit* best)
{
    float8 px = 0.0f, py = 0.0f, pz = 0.0f;
    float8 tie = 0.0f, reach_margin = 0.0f;
    float8 best_up = -INFINITY;    // each lane's best distance, rounded up to float32
    float8 upper = INFINITY;       // the least upper bound of each lane's distance met so far
    float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
    int candidates[8];             // a lane's triangles within its visit bound, visited at the end
    int candidate_slot[8][POINT_CANDIDATES];
    float candidate_lower[8][POINT_CANDIDATES];
    for (int k = 0; k < 8; ++k) {
        candidates[k] = 0;
        if (!(active & (1u << k)))
            continue;
        px[k] = p[k].x;
        py[k] = p[k].y;
        pz[k] = p[k].z;
        tie[k] = POINT_TIE_SLACK(margin[k]);
        reach_margin[k] = margin[k];
        best_up[k] = float_up(best[k].dist);
        lo = fmin(lo, p[k]);
        hi = fmax(hi, p[k]);
    }
    for (int k = 0; k < 8; ++k) {
        const int slot = seeds[k];
        if (slot >= 0 && (k == 0 || seeds[k - 1] != slot)) {
            float3 a, b, c;
            placed_corners(g, 0, slot, &a, &b, &c);
            float8 seed_upper;
            (void)lane_distance_bounds(a, b, c, px, py, pz, &seed_upper);
            upper = fmin(upper, seed_upper);
        }
    }
    // A lane visits triangles whose lower bounds lie at or below `visit` and
    // enters children whose squared bounds lie at or below reach^2: both from
    // the least upper bound, sums rounded up (inactive lanes: -inf).
    float8 cap = fmin(best_up, upper);
    float8 visit = nextafter(cap + tie, (float8)(INFINITY));
    float8 reach = cap + reach_margin;
#define POINT_LANES_BOUNDS()                               \
    do {                                                   \
        cap = fmin(best_up, upper);                        \
        visit = nextafter(cap + tie, (float8)(INFINITY));  \
        reach = cap + reach_margin;                        \
    } while (0)
    __global const WideDisk* disks = wide_disks(g);
    int4 stack[WIDE_STACK_SIZE];   // child, count (0: a node), lanes, lower bound (its bits)
    int sp = 0;
    int2 current = (int2)(0, 0);   // the root, with every lane
    uint current_lanes = active;
    int first_leaf = -1;           // a leaf walked before the root, then not again
    bool first_walked = false;
    if (seeds[0] < 0) {
        for (int node = 0;;) {
            __global const BvhWideNode* n = g->wide_nodes + node;
            const float8 d = select((float8)(INFINITY), group_child_bounds(n, lo, hi), n->count >= 0);
            const float least = min_lane(d);
            if (!(least < INFINITY))
                break;
            const int k = LOWEST_LANE(lane_bits(d == least));
            const int child = ((__global const int*)&n->child)[k], count = ((__global const int*)&n->count)[k];
            if (count > 0) {
                stack[sp++] = (int4)(0, 0, (int)active, as_int(0.0f));
                current = (int2)(child, count);
                first_leaf = child;
                break;
            }
            node = child;
        }
    }
    for (;;) {
        if (current.y > 0) {
            if (current.x == first_leaf) {
                if (first_walked)
                    goto next;
                first_walked = true;
            }
            for (int k = current.x; k < current.x + current.y; ++k) {
                __global const TrianglePacket* t = g->packets + k;
                for (int j = 0; j < 4; ++j) {
                    const int slot = t->slot[j];
                    if (slot < 0)
                        continue;
                    const float3 a = (float3)(t->v0[0][j], t->v0[1][j], t->v0[2][j]);
                    const float3 b = (float3)(t->v1[0][j], t->v1[1][j], t->v1[2][j]);
                    const float3 c = (float3)(t->v2[0][j], t->v2[1][j], t->v2[2][j]);
                    float8 tri_upper;
                    const float8 lower = lane_distance_bounds(a, b, c, px, py, pz, &tri_upper);
                    if (lane_bits(tri_upper < upper) & active) {
                        upper = fmin(upper, tri_upper);
                        POINT_LANES_BOUNDS();
                    }
                    for (uint near = lane_bits(!(lower > visit)) & current_lanes; near; near &= near - 1u) {
                        const int l = LOWEST_LANE(near);
                        int m = candidates[l];
                        if (m == POINT_CANDIDATES) {            // full: keep those still within reach
                            int kept = 0;
                            for (int e = 0; e < m; ++e) {
                                if (!(candidate_lower[l][e] > visit[l])) {
                                    candidate_slot[l][kept] = candidate_slot[l][e];
                                    candidate_lower[l][kept] = candidate_lower[l][e];
                                    ++kept;
                                }
                            }
                            m = kept;
                        }
                        if (m < POINT_CANDIDATES) {
                            candidate_slot[l][m] = slot;
                            candidate_lower[l][m] = lower[l];
                            candidates[l] = m + 1;
                        } else {                                 // still full: visited now
                            candidates[l] = m;
                            visit_point_triangle(g, TO_POINT_REAL3(p[l]), 0, slot, best + l);
                            best_up = select(best_up, (float8)(float_up(best[l].dist)), lane_mask(1u << l));
                            POINT_LANES_BOUNDS();
                        }
                    }
                }
            }
        } else {
            __global const BvhWideNode* n = g->wide_nodes + current.x;
            const int8 walking = lane_mask(current_lanes);
            const float group_reach = max_lane(select((float8)(-INFINITY), reach, walking));
            uint lanes = lane_bits((n->count >= 0) & (group_child_bounds(n, lo, hi) <= group_reach * group_reach));
            const float8 reach2 = select((float8)(-1.0f), reach * reach, walking);
            __global const int* child = (__global const int*)&n->child;
            __global const int* count = (__global const int*)&n->count;
            float8 key = 0.0f;             // the least bound of a child's lanes: the order of the walk
            uint child_lanes[8];
            for (uint open = lanes; open; open &= open - 1u) {
                const int k = LOWEST_LANE(open);
                const float8 bound = lane_child_bounds(n, disks + current.x, k, count[k] > 0, px, py, pz);
                const uint use = lane_bits(bound <= reach2);
                child_lanes[k] = use;
                if (use)
                    key[k] = min_lane(select((float8)(INFINITY), bound, lane_mask(use)));
                else
                    lanes &= ~(1u << k);
            }
            if (lanes) {
                int k = LOWEST_LANE(lanes);
                lanes &= lanes - 1u;
                if (!lanes) {                     // one child near: no stack
                    current = (int2)(child[k], count[k]);
                    current_lanes = child_lanes[k];
                    continue;
                }
                // the others onto the stack farthest first (insertion sort; the
                // bounds, >= 0, order as their bits do), the nearest taken
                const int base = sp;
                for (;;) {
                    const int bits = as_int(key[k]);
                    int j = sp++;
                    for (; j > base && stack[j - 1].w < bits; --j)
                        stack[j] = stack[j - 1];
                    stack[j] = (int4)(child[k], count[k], (int)child_lanes[k], bits);
                    if (!lanes)
                        break;
                    k = LOWEST_LANE(lanes);
                    lanes &= lanes - 1u;
                }
                --sp;
                current = stack[sp].xy;
                current_lanes = (uint)stack[sp].z;
                continue;
            }
        }
    next:
        // the next postponed child that one of its lanes still reaches
        for (;;) {
            if (sp == 0)
                goto walked;
            --sp;
            const float r = max_lane(select((float8)(-INFINITY), reach, lane_mask((uint)stack[sp].z)));
            if (as_float(stack[sp].w) <= r * r) {
                current = stack[sp].xy;
                current_lanes = (uint)stack[sp].z;
                break;
            }
        }
    }
walked:
    // each lane's candidates still within its visit bound (which the upper
    // bounds have made the answer's, or nearly)
    for (uint open = active; open; open &= open - 1u) {
        const int l = LOWEST_LANE(open);
        const point_real3 pr = TO_POINT_REAL3(p[l]);
        for (int e = 0; e < candidates[l]; ++e)
            if (!(candidate_lower[l][e] > visit[l]))
                visit_point_triangle(g, pr, 0, candidate_slot[l][e], best + l);
    }
#undef POINT_LANES_BOUNDS
}

#endif
#endif
