// The scene buffers every ray query reads, as one struct of __global pointers.
// A kernel receives them as GEOMETRY_PARAMS (the only place they are spelled
// out as parameters) and gathers them once with make_geometry(GEOMETRY_ARGS);
// every helper then takes a `const Geometry*`.
//   tris      triangle corners in slot order (leaf order for a BVH)
//   num_tris  number of slots
//   nodes     BVH rows with both children's volumes (one unused row without a BVH)
//   prim_ids  input triangle index of each slot (the identity without a BVH)
// With -DBVH_WIDE (CPU devices, clrt/device/geometry.py) two more:
//   wide_nodes  the same BVH collapsed into nodes of eight children (accel_wide.cl)
//   packets     each leaf's triangles in packets of four
// Each buffer may arrive in parts (split.cl): elements are reached through
// SPLIT_AT, never by indexing a field.
#ifndef CLRT_GEOMETRY_CL
#define CLRT_GEOMETRY_CL

#include "layouts.h"
#include "split.cl"

typedef struct {
    SPLIT_FIELD(TriangleVerts, tris);
    uint num_tris;
    SPLIT_FIELD(BvhPairNode, nodes);
    SPLIT_FIELD(int, prim_ids);
#ifdef BVH_WIDE
    __global const BvhWideNode* wide_nodes;
    __global const TrianglePacket* packets;
#endif
} Geometry;

#ifdef BVH_WIDE
#ifdef SPLIT_BUFFERS
#error "the wide BVH is built only for scenes whose buffers are not split"
#endif
#define WIDE_PARAMS , __global const BvhWideNode* wide_nodes, __global const TrianglePacket* packets
#define WIDE_ARGS , wide_nodes, packets
#else
#define WIDE_PARAMS
#define WIDE_ARGS
#endif

#define GEOMETRY_PARAMS SPLIT_PARAMS(TriangleVerts, tris), const uint num_tris, \
    SPLIT_PARAMS(BvhPairNode, nodes), SPLIT_PARAMS(int, prim_ids) WIDE_PARAMS
#define GEOMETRY_ARGS tris, num_tris, nodes, prim_ids WIDE_ARGS

#ifdef SPLIT_BUFFERS
#undef GEOMETRY_ARGS
#define GEOMETRY_ARGS tris0, tris1, tris2, tris3, num_tris, nodes0, nodes1, nodes2, nodes3, \
    prim_ids0, prim_ids1, prim_ids2, prim_ids3
#endif

inline Geometry make_geometry(GEOMETRY_PARAMS)
{
    Geometry g;
    SPLIT_STORE(g, tris);
    g.num_tris = num_tris;
    SPLIT_STORE(g, nodes);
    SPLIT_STORE(g, prim_ids);
#ifdef BVH_WIDE
    g.wide_nodes = wide_nodes;
    g.packets = packets;
#endif
    return g;
}

#endif
