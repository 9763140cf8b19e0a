// The stack of postponed children that both BVH walks keep (accel_bvh.cl,
// accel_wide.cl): a child reference (int2: row, node or first slot / packet,
// and a count) with the distance where the ray enters its volume, a lower
// bound.
#ifndef CLRT_STACK_CL
#define CLRT_STACK_CL

// Take the most recently postponed child that the ray may still reach -- its
// volume starts at or before tmax, which only shrinks as hits are found --
// into *current, dropping those it passes over; false when none is left.
inline bool resume_postponed(const int2* stack, const float* stack_t, int* sp, float tmax, int2* current)
{
    do {
        if (*sp == 0)
            return false;
        --*sp;
    } while (stack_t[*sp] > tmax);
    *current = stack[*sp];
    return true;
}

#endif
