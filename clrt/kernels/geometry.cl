// The scene buffers every ray query reads, as one struct of __global pointers.
// A kernel receives them as GEOMETRY_PARAMS (the only place they are spelled
// out as parameters) and gathers them once with make_geometry(GEOMETRY_ARGS);
// every helper then takes a `const Geometry*`.
//   tris      triangle corners in slot order (leaf order for a BVH)
//   nodes     BVH rows with both children's volumes (one unused row without a BVH)
//   prim_ids  input triangle index of each slot (the identity without a BVH)
//   wide      with -DBVH_WIDE (CPU devices, clrt/device/geometry.py): the same
//             BVH collapsed into nodes of eight children (accel_wide.cl), then,
//             from byte scene.packets_at on, each leaf's triangles in packets
//             of four -- one buffer, so that a kernel takes one parameter less
//   instances with -DACCEL_INSTANCES (a two-level scene, docs/instances.md):
//             the Instance table (layouts.h), in the caller's order
//   scene     SceneInfo (layouts.h) by value: the triangle count among others
// Each of tris, nodes, prim_ids and instances may arrive in parts (split.cl):
// elements are reached through SPLIT_AT, never by indexing a field.
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
#ifdef ACCEL_INSTANCES
    SPLIT_FIELD(Instance, instances);
    uint num_instances;
#endif
} Geometry;

#ifdef BVH_WIDE
#ifdef SPLIT_BUFFERS
#error "the wide BVH is built only for scenes whose buffers are not split"
#endif
#define WIDE_PARAMS , __global const uchar* wide
#define WIDE_ARGS , wide
#else
#define WIDE_PARAMS
#define WIDE_ARGS
#endif

#ifdef ACCEL_INSTANCES
#ifdef BVH_WIDE
#error "a two-level scene walks the binary BVH rows (clrt.device.geometry.walks_wide)"
#endif
#define INSTANCE_PARAMS , SPLIT_PARAMS(Instance, instances)
#define INSTANCE_ARGS , SPLIT_ARGS(instances)
#else
#define INSTANCE_PARAMS
#define INSTANCE_ARGS
#endif

#define GEOMETRY_PARAMS SPLIT_PARAMS(TriangleVerts, tris), SPLIT_PARAMS(BvhPairNode, nodes), \
    SPLIT_PARAMS(int, prim_ids) WIDE_PARAMS INSTANCE_PARAMS, const SceneInfo scene
#define GEOMETRY_ARGS SPLIT_ARGS(tris), SPLIT_ARGS(nodes), SPLIT_ARGS(prim_ids) WIDE_ARGS INSTANCE_ARGS, scene

// (Kernels call it as make_geometry(GEOMETRY_ARGS).)
inline Geometry make_geometry(GEOMETRY_PARAMS)
{
    Geometry g;
    SPLIT_STORE(g, tris);
    g.num_tris = scene.num_tris;
    SPLIT_STORE(g, nodes);
    SPLIT_STORE(g, prim_ids);
#ifdef BVH_WIDE
    g.wide_nodes = (__global const BvhWideNode*)wide;
    g.packets = (__global const TrianglePacket*)(wide + scene.packets_at);
#endif
#ifdef ACCEL_INSTANCES
    SPLIT_STORE(g, instances);
    g.num_instances = scene.num_instances;
#endif
    return g;
}

#endif
