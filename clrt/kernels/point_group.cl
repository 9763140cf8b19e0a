// Closest points many at a time, on CPU devices (-DPOINT_GROUPS, which
// clrt/query/points.py's point_group_defines sets where the device walks the
// wide BVH of a one-level scene and ray packets): trace.cl's
// query_closest_point and signed distances take a work-item's points in
// groups of POINT_LANES (16) neighbours in the order of point_order.cl, one
// point a lane of `lanes_float` values, and walk the wide BVH once for the
// group (walk_wide_point_group) instead of once for each point (point.cl's
// walk_wide_points).  A node's children are tested once for the box of the
// group, then those within its reach for each point (lane_child_bounds); a
// leaf's triangles once each for the whole group (POINT_TRIANGLE_BOUNDS with
// the points in lanes).  What makes that pay: neighbours need much the same
// leaves -- on elephant (1M points in its box) a point's bounds admit 6.7
// leaves, and eight neighbours' 10.5 between them, sixteen's 11.8.  The walk's
// steps, and the branches that decide them, are shared by all; the work of a
// step grows with the lanes, but float16 operations are what the CPU's widest
// units take (docs/benchmark-log.md).
//
// Exact as walk_wide_points is, bit for bit: a lane skips a child only where
// its own lower bound exceeds its reach, and a triangle only where its lower
// bound exceeds its visit bound (POINT_TIE_SLACK above its best); the box of
// the group lies no farther than any of its points (each float32 step of the
// box distance rounds a difference no larger than the point's: monotone).
// What bounds a lane's distance from above, for both, is the least of its
// best visited distance and the float32 upper bounds (POINT_TRIANGLE_BOUNDS)
// of the triangles tested for it: a triangle whose upper bound lowers that is
// itself within reach, and visited.  A lane visits a triangle within its
// visit bound at the end of the walk, not at once (up to POINT_CANDIDATES of
// them a lane; beyond, at once): in the group's order of nodes a lane meets
// many triangles nearer than its best so far but farther than its answer.
// Before the walk the nearest triangles of the group before (seeds) give
// upper bounds; a work-item's first group first takes a leaf near all its
// points (the group's nearest child at each level).
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
#error "POINT_GROUPS takes accel_packet.cl's lanes: build it with -DRAY_PACKETS=8"
#endif
// One value a point of the group: POINT_LANES of them, and their lanes as
// bits (LANES_BITS, LANES_MASK) and reduced (LANES_MIN, LANES_MAX).
#if POINT_LANES == 16
typedef float16 lanes_float;
typedef int16 lanes_int;
#define LANES_BITS(x) lane16_bits(x)
#define LANES_MASK(bits) lane16_mask(bits)
#define LANES_MIN(x) min_lane(fmin((x).lo, (x).hi))
#define LANES_MAX(x) max_lane(fmax((x).lo, (x).hi))
#elif POINT_LANES == 8
typedef float8 lanes_float;
typedef int8 lanes_int;
#define LANES_BITS(x) lane_bits(x)
#define LANES_MASK(bits) lane_mask(bits)
#define LANES_MIN(x) min_lane(x)
#define LANES_MAX(x) max_lane(x)
#else
#error "build with -DPOINT_LANES=8 or 16 (clrt/config.py)"
#endif
#ifndef POINT_CANDIDATES
#error "build with -DPOINT_CANDIDATES=<triangles a lane keeps to visit> (clrt/config.py)"
#endif

// Lower bounds of the distances from the group's points to one triangle (a,
// b, c), and upper bounds: POINT_TRIANGLE_BOUNDS with the points in lanes.
__attribute__((always_inline))
inline lanes_float lane_distance_bounds(float3 a, float3 b, float3 c, lanes_float px, lanes_float py,
                                        lanes_float pz, lanes_float* upper_out)
{
    const lanes_float apx = px - a.x, apy = py - a.y, apz = pz - a.z;
    const float abx = b.x - a.x, aby = b.y - a.y, abz = b.z - a.z;
    const float acx = c.x - a.x, acy = c.y - a.y, acz = c.z - a.z;
    POINT_TRIANGLE_BOUNDS(lanes_float, lanes_int, float);
    *upper_out = upper;
    return lower;
}

// Squared lower bounds of the distances from the box lo .. hi to node n's
// children, a lane each (boxes only: where the points lie apart, a disk's
// lateral reach is mostly its box's).
__attribute__((always_inline))
inline float8 group_child_bounds(__global const BvhWideNode* n, float3 lo, float3 hi)
{
    const float8 dx = fmax(fmax(n->lo_x - hi.x, lo.x - n->hi_x), 0.0f);
    const float8 dy = fmax(fmax(n->lo_y - hi.y, lo.y - n->hi_y), 0.0f);
    const float8 dz = fmax(fmax(n->lo_z - hi.z, lo.z - n->hi_z), 0.0f);
    return dx * dx + dy * dy + dz * dz;
}

// Squared lower bounds of the distances from the group's points to child k
// of node n: walk_wide_points' box and, for a leaf, disk (WideDisk) bounds.  An inner
// child takes its box alone: its disk, around a larger curved patch, rarely
// prunes what the box does not, and the test is made for every child within
// the group's reach.
__attribute__((always_inline))
inline lanes_float lane_child_bounds(__global const BvhWideNode* n, __global const WideDisk* disk, int k,
                                     bool leaf, lanes_float px, lanes_float py, lanes_float pz)
{
    const lanes_float dx = fmax(fmax(n->lo_x[k] - px, px - n->hi_x[k]), 0.0f);
    const lanes_float dy = fmax(fmax(n->lo_y[k] - py, py - n->hi_y[k]), 0.0f);
    const lanes_float dz = fmax(fmax(n->lo_z[k] - pz, pz - n->hi_z[k]), 0.0f);
    const lanes_float box = dx * dx + dy * dy + dz * dz;
    if (!leaf)
        return box;
    const float nx = disk->nx[k], ny = disk->ny[k], nz = disk->nz[k];
    const lanes_float vx = px - disk->cx[k], vy = py - disk->cy[k], vz = pz - disk->cz[k];
    const lanes_float h = vx * nx + vy * ny + vz * nz;
    const lanes_float lx = vx - h * nx, ly = vy - h * ny, lz = vz - h * nz;
    const lanes_float across = fmax(fabs(h) - disk->half_height[k], 0.0f);
    const lanes_float beside = fmax(sqrt(lx * lx + ly * ly + lz * lz) - disk->radius[k], 0.0f);
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
    lanes_float px = 0.0f, py = 0.0f, pz = 0.0f;
    lanes_float tie = 0.0f, reach_margin = 0.0f;
    lanes_float best_up = -INFINITY;   // each lane's best distance, rounded up to float32
    lanes_float upper = INFINITY;      // the least upper bound of each lane's distance met so far
    float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
    int candidates[POINT_LANES];       // a lane's triangles within its visit bound, visited at the end
    int candidate_slot[POINT_LANES][POINT_CANDIDATES];
    float candidate_lower[POINT_LANES][POINT_CANDIDATES];
    for (int k = 0; k < POINT_LANES; ++k) {
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
    for (int k = 0; k < POINT_LANES; ++k) {   // each seed once (neighbours share them)
        const int slot = seeds[k];
        bool seen = false;
        for (int j = 0; j < k; ++j)
            seen |= seeds[j] == slot;
        if (slot >= 0 && !seen) {
            float3 a, b, c;
            placed_corners(g, 0, slot, &a, &b, &c);
            lanes_float seed_upper;
            (void)lane_distance_bounds(a, b, c, px, py, pz, &seed_upper);
            upper = fmin(upper, seed_upper);
        }
    }
    // A lane visits triangles whose lower bounds lie at or below `visit` and
    // enters children whose squared bounds lie at or below reach^2: both from
    // the least upper bound, sums rounded up (inactive lanes: -inf).
    lanes_float cap = fmin(best_up, upper);
    lanes_float visit = nextafter(cap + tie, (lanes_float)(INFINITY));
    lanes_float reach = cap + reach_margin;
#define UPDATE_LANE_BOUNDS()                                    \
    do {                                                        \
        cap = fmin(best_up, upper);                             \
        visit = nextafter(cap + tie, (lanes_float)(INFINITY));  \
        reach = cap + reach_margin;                             \
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
                    lanes_float tri_upper;
                    const lanes_float lower = lane_distance_bounds(a, b, c, px, py, pz, &tri_upper);
                    if (LANES_BITS(tri_upper < upper) & active) {
                        upper = fmin(upper, tri_upper);
                        UPDATE_LANE_BOUNDS();
                    }
                    for (uint near = LANES_BITS(!(lower > visit)) & current_lanes; near; near &= near - 1u) {
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
                            best_up = select(best_up, (lanes_float)(float_up(best[l].dist)), LANES_MASK(1u << l));
                            UPDATE_LANE_BOUNDS();
                        }
                    }
                }
            }
        } else {
            __global const BvhWideNode* n = g->wide_nodes + current.x;
            const lanes_int walking = LANES_MASK(current_lanes);
            const float group_reach = LANES_MAX(select((lanes_float)(-INFINITY), reach, walking));
            uint lanes = lane_bits((n->count >= 0) & (group_child_bounds(n, lo, hi) <= group_reach * group_reach));
            const lanes_float reach2 = select((lanes_float)(-1.0f), reach * reach, walking);
            __global const int* child = (__global const int*)&n->child;
            __global const int* count = (__global const int*)&n->count;
            float8 key = 0.0f;             // the least bound of a child's lanes: the order of the walk
            uint child_lanes[8];
            for (uint open = lanes; open; open &= open - 1u) {
                const int k = LOWEST_LANE(open);
                const lanes_float bound = lane_child_bounds(n, disks + current.x, k, count[k] > 0, px, py, pz);
                const uint use = LANES_BITS(bound <= reach2);
                child_lanes[k] = use;
                if (use)
                    key[k] = LANES_MIN(select((lanes_float)(INFINITY), bound, LANES_MASK(use)));
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
            const float r = LANES_MAX(select((lanes_float)(-INFINITY), reach, LANES_MASK((uint)stack[sp].z)));
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
#undef UPDATE_LANE_BOUNDS
}

#endif
#endif
