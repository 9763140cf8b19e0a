// The stack of postponed children that both BVH walks keep (accel_bvh.cl,
// accel_wide.cl): a child reference (int2: row, node or first slot / packet,
// and a count) with the distance where the ray enters its volume, a lower
// bound.
#ifndef CLRT_STACK_CL
#define CLRT_STACK_CL

#include "volumes.cl"

// Take the most recently postponed child that the ray may still reach into
// *current; false when none is left.  With `by_distance` (the closest hit,
// whose tmax shrinks as hits are found) those whose volume starts beyond tmax
// are dropped, and stack_t is read; other queries never shrink tmax, so every
// child they postponed is still reachable and they need not keep stack_t.
// tmax is widened by the volume tests' relative slack, as they widen it
// (volumes.cl): a triangle whose computed distance ties the best hit is
// still reached when rounding puts its exact distance a little beyond.
inline bool resume_postponed(const int2* stack, const float* stack_t, int* sp, float tmax, int2* current,
                             const bool by_distance)
{
    const float reach = SLACK_LATER(tmax);
    do {
        if (*sp == 0)
            return false;
        --*sp;
    } while (by_distance && stack_t[*sp] > reach);
    *current = stack[*sp];
    return true;
}

#endif
