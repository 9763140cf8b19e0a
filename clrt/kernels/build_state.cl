// The device builder's small state buffer (ints), written and read by its
// kernels so that the host need not look at it between launches:
//   STATE_NEXT_NODE      next free BuildNode index (atomic allocation)
//   STATE_DEPTH          tree depth: nodes on the longest root-to-leaf path
//   STATE_ERROR          non-zero: a kernel found the tree inconsistent
//   STATE_BAD_TRIANGLE   least index of a triangle with a NaN or infinite
//                        corner (the input is checked here, not on the host:
//                        a host pass over 10M triangles costs more than the build)
//   STATE_ITERATIONS     PLOC iterations that merged (ploc_merge, ploc_compact, a tail or ploc_top)
//   STATE_TICKETS + 0, 1 ploc_merge's tile tickets of even and odd iterations
//   STATE_TREELET_TICKET treelet_restructure's tickets
//   STATE_BOUNDS + 0..5  centre bounds min xyz, max xyz (order-preserving bits)
//   STATE_COUNTS + k     clusters before PLOC iteration j, j % COUNT_RING == k
//   STATE_LEVELS + h     nodes of height h (h < TREELET_LEVELS - 1; the last
//                        entry counts every taller node) whose treelets are
//                        restructured (treelet_levels)
//   STATE_LEVEL_CURSORS + h  nodes of height h placed so far (treelet_order)
//   STATE_SORT_TICKETS + p   radix_scatter_lookback's tile tickets of pass p
//   STATE_SORT_DIGITS + p * RADIX_BINS + d  keys whose pass-p digit is d (radix_digit_counts)
//   STATE_TAIL + TAIL_*  what ploc_tail leaves ploc_top (build_ploc.cl)
// Offsets are -D defines from clrt/device/build.py, which reads the same values.
#ifndef CLRT_BUILD_STATE_CL
#define CLRT_BUILD_STATE_CL

#if !defined(STATE_NEXT_NODE) || !defined(STATE_DEPTH) || !defined(STATE_ERROR) \
    || !defined(STATE_BAD_TRIANGLE) || !defined(STATE_ITERATIONS) || !defined(STATE_TICKETS) \
    || !defined(STATE_TREELET_TICKET) \
    || !defined(STATE_BOUNDS) || !defined(STATE_COUNTS) || !defined(COUNT_RING) \
    || !defined(STATE_LEVELS) || !defined(STATE_LEVEL_CURSORS) || !defined(TREELET_LEVELS) \
    || !defined(STATE_SORT_TICKETS) || !defined(STATE_SORT_DIGITS) || !defined(STATE_TAIL) \
    || !defined(STATE_INTS)
#error "build with the STATE_*, COUNT_RING and TREELET_LEVELS defines of clrt/device/build.py"
#endif

#define CLUSTERS_BEFORE(iteration) (STATE_COUNTS + (iteration) % COUNT_RING)

// ploc_tail's ints at STATE_TAIL (build.py keeps TAIL_INTS of them).
#define TAIL_COUNT 0          // clusters left for the SAH top
#define TAIL_NEXT_NODE 1      // the node counter
#define TAIL_ITERATIONS 2     // PLOC iterations that merged
#define TAIL_FLAGS 3          // TAIL_MERGED | TAIL_IN_SPARE
#define TAIL_MERGED 1         // ploc_tail's loop merged
#define TAIL_IN_SPARE 2       // and left the clusters in its `spare` buffer

// What a tail (ploc_tail, ploc_tail_serial) leaves ploc_top at STATE_TAIL:
// the clusters left, the node counter, the iterations that merged (the
// state's own where the tail merged none) and where the clusters lie (one
// work-item writes it).
inline void hand_over_to_top(global int* state, int count, int next_node, int iteration, int first_iteration)
{
    const bool merged_here = iteration > first_iteration;
    state[STATE_TAIL + TAIL_COUNT] = count;
    state[STATE_TAIL + TAIL_NEXT_NODE] = next_node;
    state[STATE_TAIL + TAIL_ITERATIONS] = merged_here ? iteration : state[STATE_ITERATIONS];
    state[STATE_TAIL + TAIL_FLAGS] = (merged_here ? TAIL_MERGED : 0)
                                   | ((iteration - first_iteration) % 2 ? TAIL_IN_SPARE : 0);
}

// The state before a build of num_tris triangles (one work-item writes it).
inline void clear_build_state(global uint* state, const uint num_tris)
{
    for (uint k = 0; k < STATE_INTS; ++k)
        state[k] = 0u;
    state[STATE_NEXT_NODE] = num_tris;
    state[STATE_BAD_TRIANGLE] = 0xffffffffu;       // none (atomic_min from the largest)
    for (uint k = 0; k < 3; ++k) {
        state[STATE_BOUNDS + k] = 0xffffffffu;     // min: atomic_min from the largest
        state[STATE_BOUNDS + 3 + k] = 0u;          // max: atomic_max from the smallest
    }
    state[CLUSTERS_BEFORE(0)] = num_tris;
}

__kernel void init_build_state(global uint* state, const uint num_tris)
{
    clear_build_state(state, num_tris);
}

#endif
