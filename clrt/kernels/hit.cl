// The hit record, the one rule that orders hits, and the leaf action every
// acceleration structure shares (visit_triangle), so that brute force and
// each BVH answer every query by the same code.
//
// Ties: equal distances go to the lower input triangle index, so the nearest
// hit never depends on the order in which triangles are visited.  In a
// two-level scene (-DACCEL_INSTANCES) to the lower instance, then the lower
// triangle of its mesh: the flattened scene's order (visit_instance_triangle).
#ifndef CLRT_HIT_CL
#define CLRT_HIT_CL

#include "geometry.cl"
#include "triangle.cl"

#define QUERY_CLOSEST 0   // the nearest hit; tmax shrinks to it as the walk goes on
#define QUERY_ANY 1       // stop at the first hit found
#define QUERY_ALL 2       // hand every hit in (tmin, tmax] to a HitSink

inline Hit miss_hit(void)
{
    Hit h;
    h.t = INFINITY;
    h.prim = -1;
    h.u = 0.0f;
    h.v = 0.0f;
    return h;
}

inline Hit make_hit(float t, int prim, float u, float v)
{
    Hit h;
    h.t = t;
    h.prim = prim;
    h.u = u;
    h.v = v;
    return h;
}

// Where QUERY_ALL puts hits: appended to shared output arrays through one
// atomic counter (a full output still counts every hit, so the host can size
// a second try).  With ray_ids == 0 hits are only counted.  It also carries the
// query's face culling (triangle.cl), for every query kind; without a sink
// (sink == 0) triangles are double-sided.
typedef struct {
    __global int* ray_ids;
    __global int* prims;
    __global float* ts;
    __global int* instances;  // the hits' instances (0 in a one-level scene), where asked for (else 0)
    __global uint* next;      // shared append position
    uint capacity;            // length of the output arrays
    int ray;                  // this ray's index
    uint count;               // hits seen along this ray
    int cull;                 // CULL_NONE, CULL_BACK or CULL_FRONT
} HitSink;

inline void sink_hit(HitSink* sink, int instance, int prim, float t)
{
    sink->count++;
    if (sink->ray_ids) {
        const uint k = atomic_inc(sink->next);
        if (k < sink->capacity) {
            sink->ray_ids[k] = sink->ray;
            sink->prims[k] = prim;
            sink->ts[k] = t;
            if (sink->instances)
                sink->instances[k] = instance;
        }
    }
}

// Take a hit (t, u, v) of the triangle in `slot` of `instance` for `query`
// (*best_instance: the best hit's); true once the query is answered.  The
// closest hit reads input indices only on a tie of distances (both
// triangles' then), which is rare, so the walks keep no index of their best
// hit (the same kernel times on the H200, docs/benchmark-log.md).
inline bool record_instance_hit(const Geometry* g, int instance, int slot, float t, float u, float v, float* tmax,
                                const int query, Hit* best, int* best_instance, HitSink* sink)
{
    if (query == QUERY_ANY) {
        *best = make_hit(t, slot, u, v);
        *best_instance = instance;
        return true;
    }
    if (query == QUERY_ALL) {
        sink_hit(sink, instance, *SPLIT_AT(g, prim_ids, slot), t);
        return false;
    }
    if (t < best->t || (t == best->t && best->prim >= 0
                        && (instance < *best_instance || (instance == *best_instance
                            && *SPLIT_AT(g, prim_ids, slot) < *SPLIT_AT(g, prim_ids, best->prim))))) {
        *best = make_hit(t, slot, u, v);
        *best_instance = instance;
        *tmax = t;   // inclusive: an equal distance with a lower index is still taken
    }
    return false;
}

// record_instance_hit in a one-level scene: one instance, 0 (its comparisons
// fold away).
inline bool record_hit(const Geometry* g, int slot, float t, float u, float v, float* tmax,
                       const int query, Hit* best, HitSink* sink)
{
    int best_instance = 0;
    return record_instance_hit(g, 0, slot, t, u, v, tmax, query, best, &best_instance, sink);
}

// Test the triangle in `slot` for `query`; true once the query is answered.
inline bool visit_triangle(const Geometry* g, const ShearedRay* r, int slot, float tmin, float* tmax,
                           const int query, Hit* best, HitSink* sink)
{
    float t, u, v;
    if (!intersect_triangle_culled(r, SPLIT_AT(g, tris, slot), tmin, *tmax, sink ? sink->cull : CULL_NONE, &t, &u, &v))
        return false;
    return record_hit(g, slot, t, u, v, tmax, query, best, sink);
}

// The same for the triangle in `slot` of `instance`, `r` in its object space
// and `cull` as the instance sees it (instances.cl's instance_cull).
inline bool visit_instance_triangle(const Geometry* g, const ShearedRay* r, int slot, int instance, const int cull,
                                    float tmin, float* tmax, const int query, Hit* best, int* best_instance,
                                    HitSink* sink)
{
    float t, u, v;
    if (!intersect_triangle_culled(r, SPLIT_AT(g, tris, slot), tmin, *tmax, cull, &t, &u, &v))
        return false;
    return record_instance_hit(g, instance, slot, t, u, v, tmax, query, best, best_instance, sink);
}

#endif
