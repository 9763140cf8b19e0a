// A packet of rays: eight coherent rays walked together through the wide
// BVH (CPU devices, -DRAY_PACKETS=8 beside -DBVH_WIDE; the query kernels of
// trace.cl give each work-item eight consecutive rays).  accel_wide.cl tests
// one ray against a node's eight boxes, or a triangle packet's four
// triangles, in a vector; here lane k of every float8 is ray k instead, and
// the loop runs over a node's children and a triangle packet's triangles.
// For rays that travel together -- a camera's neighbouring pixels, shadow
// rays from neighbouring points to one light -- that visits each node once
// for eight rays, and fills all eight lanes of the triangle test where the
// single-ray walk fills at most four.  Rays that do not travel together
// (random queries, diffuse bounces) never come here: make_ray_packet turns
// them away and each takes the single-ray walk.
//
// Answers are accel_wide.cl's bit for bit: each lane's box test is that of its
// ray (volumes.cl, box_hit_lanes), each lane's triangle test is the scalar
// one (triangle.cl, intersect_lanes_culled), and every hit passes the same
// tie rule (record_hit's, hit.cl), which does not depend on the order of the
// walk.  A lane may visit more than its own ray would (it goes where any ray
// of the packet goes), never less.
#ifndef CLRT_ACCEL_PACKET_CL
#define CLRT_ACCEL_PACKET_CL

#include "accel_wide.cl"
#include "rays.cl"

#if defined(ACCEL_BVH) && defined(BVH_WIDE) && defined(RAY_PACKETS)

typedef struct {
    PacketShear shear;      // triangle.cl
    PacketPlanes volume;    // volumes.cl
    float8 tmin;
} RayPacket;

// The rays' answers, lane k for ray k; slot -1 where none was found.
typedef struct {
    float8 t, u, v;
    int8 slot, id;          // slot and input triangle id of the best hit (closest: the tie rule)
} RayPacketHits;

inline float max_lane(float8 x)
{
    const float4 a = fmax(x.lo, x.hi);
    const float2 b = fmax(a.lo, a.hi);
    return fmax(b.x, b.y);
}

inline float min_lane(float8 x)
{
    const float4 a = fmin(x.lo, x.hi);
    const float2 b = fmin(a.lo, a.hi);
    return fmin(b.x, b.y);
}

// Eight rays, set up lane by lane (shear_ray_lanes, volume_ray_lanes), as a
// packet; false when they do not make one: the same octant, the same shear
// order, every ray oblique (volume_ray).  The octant lets every lane take the
// same near planes and the same near-first order; the shear order, the same
// triangle corners.
inline bool make_ray_packet(const RayLanes* rays, const ShearRayLanes* shear, const VolumeRayLanes* volume,
                        RayPacket* p)
{
    const int8 neg_x = signbit(rays->dx), neg_y = signbit(rays->dy), neg_z = signbit(rays->dz);
    if (!all((neg_x == (int8)(neg_x.s0)) & (neg_y == (int8)(neg_y.s0)) & (neg_z == (int8)(neg_z.s0))))
        return false;
    if (!packet_shear(shear, rays->ox, rays->oy, rays->oz, &p->shear) || !packet_planes(volume, &p->volume))
        return false;
    p->tmin = rays->tmin;
    return true;
}

// make_ray_packet for lanes that need nothing else of their set-up (the
// renderer's camera and shadow rays): false when they make no packet.
// `spawned`: the rays leave surfaces (triangle.cl's shear_ray), each lane's
// end its tmax.
inline bool ray_packet_of(const Geometry* g, const RayLanes* rays, const bool spawned, RayPacket* p)
{
    const ShearRayLanes shear = shear_ray_lanes(rays->dx, rays->dy, rays->dz);
    const VolumeRayLanes volume = volume_ray_lanes(rays->ox, rays->oy, rays->oz, rays->dx, rays->dy, rays->dz,
                                                   tree_reach(SPLIT_AT(g, nodes, 0)));
    if (!make_ray_packet(rays, &shear, &volume, p))
        return false;
    p->shear.spawned = spawned;
    p->shear.end = rays->tmax;
    return true;
}

// Take the hits of the triangle in `slot` for the lanes in `hit` (any hit:
// those rays are answered, in *done).
inline void record_lanes(const Geometry* g, int slot, int8 hit, float8 t, float8 u, float8 v, float8* tmax,
                         const int query, RayPacketHits* best, uint* done)
{
    if (query == QUERY_ANY) {
        best->slot = select(best->slot, (int8)(slot), hit);
        *done |= lane_bits(hit);
        return;
    }
    // record_hit's rule, lane by lane: nearer, or as near with a lower id
    const int id = *SPLIT_AT(g, prim_ids, slot);
    hit &= (t < best->t) | ((t == best->t) & ((int8)(id) < best->id));
    best->t = select(best->t, t, hit);
    best->u = select(best->u, u, hit);
    best->v = select(best->v, v, hit);
    best->slot = select(best->slot, (int8)(slot), hit);
    best->id = select(best->id, (int8)(id), hit);
    *tmax = select(*tmax, t, hit);      // inclusive, as record_hit's
}

// Answer `query` (QUERY_CLOSEST or QUERY_ANY) for the packet's rays.  As
// walk_wide_tree: one current child with the rays that met it (a bit mask),
// and a stack of postponed children with theirs.  For the closest hit a
// node's children are taken nearest first by the nearest lane's entry, the
// rest pushed farthest first; any hit takes the lowest lane first, then the
// others from the highest down.
inline void walk_ray_packet(const Geometry* g, const RayPacket* p, float8 tmax, const int query, const int cull,
                            RayPacketHits* best)
{
    int2 stack[WIDE_STACK_SIZE];         // (node or first packet, packet count: 0 for a node)
    uint stack_rays[WIDE_STACK_SIZE];    // the rays that met it
    float stack_t[WIDE_STACK_SIZE];      // closest hit: the nearest of their entries
    int sp = 0;
    int2 current = (int2)(0, 0);         // the root node
    uint rays = 0xFFu;
    uint done = 0u;                      // any hit: the rays answered
    for (;;) {
        if (current.y > 0) {
            const int8 lanes = lane_mask(rays);
            for (int q = current.x; q < current.x + current.y; ++q) {
                __global const TrianglePacket* tp = g->packets + q;
                for (int k = 0; k < 4; ++k) {
                    const int slot = tp->slot[k];
                    if (slot < 0)
                        continue;
                    float8 t, u, v;
                    const int8 hit = intersect_lanes_culled(&p->shear, tp, k, p->tmin, tmax, cull, &t, &u, &v) & lanes;
                    if (any(hit))
                        record_lanes(g, slot, hit, t, u, v, &tmax, query, best, &done);
                }
            }
            if (query == QUERY_ANY && done == 0xFFu)
                return;
        } else {
            __global const BvhWideNode* n = g->wide_nodes + current.x;
            __global const int* child = (__global const int*)&n->child;
            __global const int* count = (__global const int*)&n->count;
            const int8 lanes = lane_mask(rays);
            const int base = sp;
            int2 first = (int2)(-1, 0);
            uint first_rays = 0u;
            float first_t = INFINITY;
            for (int c = 0; c < 8; ++c) {
                if (count[c] < 0)
                    continue;
                float8 enter;
                const int8 met = box_hit_lanes(&p->volume, n, c, p->tmin, tmax, &enter) & lanes;
                const uint met_rays = lane_bits(met);
                if (!met_rays)
                    continue;
                int2 ref = (int2)(child[c], count[c]);
                uint ref_rays = met_rays;
                float ref_t = query == QUERY_CLOSEST ? min_lane(select((float8)(INFINITY), enter, met)) : 0.0f;
                if (first.x < 0) {
                    first = ref;
                    first_rays = ref_rays;
                    first_t = ref_t;
                    continue;
                }
                if (query == QUERY_CLOSEST && ref_t < first_t) {     // the nearer stays current
                    const int2 r = first; first = ref; ref = r;
                    const uint m = first_rays; first_rays = ref_rays; ref_rays = m;
                    const float t = first_t; first_t = ref_t; ref_t = t;
                }
                int j = sp++;
                if (query == QUERY_CLOSEST)
                    for (; j > base && stack_t[j - 1] < ref_t; --j) {
                        stack[j] = stack[j - 1];
                        stack_rays[j] = stack_rays[j - 1];
                        stack_t[j] = stack_t[j - 1];
                    }
                stack[j] = ref;
                stack_rays[j] = ref_rays;
                stack_t[j] = ref_t;
            }
            if (first.x >= 0) {
                current = first;
                rays = first_rays;
                continue;
            }
        }
        // The most recently postponed child that a ray can still use: not yet
        // answered (any hit), and (closest hit) entered no later than some
        // ray's tmax -- resume_postponed's rule for the farthest-reaching ray.
        for (;;) {
            if (sp == 0)
                return;
            --sp;
            const uint open = stack_rays[sp] & ~done;
            if (!open)
                continue;
            if (query == QUERY_CLOSEST &&
                stack_t[sp] > SLACK_LATER(max_lane(select((float8)(-INFINITY), tmax, lane_mask(open)))))
                continue;
            current = stack[sp];
            rays = open;
            break;
        }
    }
}

// Answer `query` for the packet's rays, hits[k] for ray k (Hit.prim a slot),
// their tmax lane by lane.
inline void answer_ray_packet(const Geometry* g, const RayPacket* p, float8 tmax, const int query, const int cull,
                              Hit* hits)
{
    RayPacketHits best;
    best.t = (float8)(INFINITY);
    best.u = best.v = (float8)(0.0f);
    best.slot = best.id = (int8)(-1);
    walk_ray_packet(g, p, tmax, query, cull, &best);
    for (int k = 0; k < RAY_PACKETS; ++k)
        hits[k] = best.slot[k] >= 0 ? make_hit(best.t[k], best.slot[k], best.u[k], best.v[k]) : miss_hit();
}

#endif

#endif
