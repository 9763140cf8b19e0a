// The hit record and the one rule that orders hits.  Every query uses
// hit_is_closer, so the nearest hit does not depend on the order in which
// triangles are visited: equal distances go to the lower triangle index.
#ifndef CLRT_HIT_CL
#define CLRT_HIT_CL

#include "triangle.cl"

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

inline bool hit_is_closer(float t, int prim, const Hit* best)
{
    return t < best->t || (t == best->t && prim < best->prim);
}

#endif
