"""Every buffer the host shares with the kernels, defined once.

Each numpy structured dtype below has a twin struct in ``clrt/kernels/layouts.h``;
``tests/test_layouts.py`` asks the OpenCL compiler for ``sizeof``/``offsetof`` of
each struct and compares with these dtypes.  Remember that OpenCL ``float3`` is
16 bytes, so positions are stored as ``float4`` with the 4th lane spare or used.

Byte layout (offset: field):

``Ray`` (32 B) -- one per pixel, written by ``generate_rays``
    0: origin  float4  xyz = origin, w = tmin
   16: dir     float4  xyz = unit direction, w = tmax

``Hit`` (16 B) -- result of a closest-hit query
    0: t       float   distance along the unit direction, INFINITY on a miss
    4: prim    int     triangle index (row of ``Mesh.faces``), -1 on a miss
    8: u       float   barycentric weight of vertex 1
   12: v       float   barycentric weight of vertex 2

``TriangleVerts`` (48 B) -- the three corners, gathered for the intersection test
    0: v0, 16: v1, 32: v2   float4 each, w unused (0)

``TriangleInfo`` (16 B) -- what shading needs beyond the corners
    0: vertex  int[3]  indices into the vertex-normal buffer
   12: material int    row of the material buffer

``Material`` (48 B)
    0: color     float4  linear RGB albedo, a unused
   16: ambient   float   coefficients of the Phong model
   20: diffuse   float
   24: specular  float
   28: shininess float   Phong exponent
   32: flags        uint  bit 0: smooth shading (interpolate vertex normals)
   36: reflectivity float weight of the mirror ray (0..1)
   40: transparency float weight of the refracted ray (0..1)
   44: ior          float index of refraction (>= 1)

``Light`` (32 B) -- point light
    0: position float4  xyz, w unused
   16: color    float4  linear RGB intensity, a unused

``BvhNode`` (48 B) -- one node of a binary BVH, nodes in depth-first order, root at 0.
The bounding-volume shape is fixed per tree (a build-time ``-D`` of the program):
    0: bound_a    float4  box: min corner xyz | sphere: centre xyz, w = radius
                          | ellipsoid: centre xyz
   16: bound_b    float4  box: max corner xyz | sphere: unused
                          | ellipsoid: reciprocal semi-axes xyz (1/Rx, 1/Ry, 1/Rz)
   32: left_first int     inner: index of the left child | leaf: first slot in the
                          leaf-ordered triangle buffers
   36: count      int     0 for an inner node, else the number of triangles in the leaf
   40: right      int     inner: index of the right child | leaf: -1
   44: pad        int
Every volume encloses all triangles of its subtree, rounded outwards in float32.
The triangle buffers of a BVH scene are stored in leaf order; ``prim_id`` (int32 per
slot) maps a slot back to the input triangle index, which is what queries report.
This is the builders' output; the device walks the layout below, made from it.

``BvhPairNode`` (64 B) -- what the kernels walk: one row per inner node, holding
both children's volumes and references (as Aila & Laine 2009 do with boxes), so
that one fetch decides which children to enter: four float4 loads, two 32-byte
memory sectors.  Rows in depth-first order, the root at 0.  A volume takes six
floats, the xyz lanes of *_a and *_b; the w lanes hold int32 bits (``as_int`` in
the kernels, ``geometry.pair_child_refs`` on the host):
    0: left_a      float4  xyz: volume part a, as BvhNode.bound_a.xyz
                           w: left -- left_count == 0: row of the left child | > 0: its first slot
   16: left_b      float4  xyz: volume part b, as BvhNode.bound_b.xyz, except that
                           a sphere keeps its radius in x
                           w: left_count -- 0: inner child | > 0: leaf of that many
                           triangles | -1: no child (only the right one, when the
                           whole tree is one leaf, held on the left)
   32: right_a     float4  as left_a, w: right
   48: right_b     float4  as left_b, w: right_count
"""

import numpy as np

float4 = np.dtype((np.float32, 4))

RAY = np.dtype([("origin", float4), ("dir", float4)])
HIT = np.dtype([("t", np.float32), ("prim", np.int32), ("u", np.float32), ("v", np.float32)])
TRIANGLE_VERTS = np.dtype([("v0", float4), ("v1", float4), ("v2", float4)])
TRIANGLE_INFO = np.dtype([("vertex", np.int32, 3), ("material", np.int32)])
MATERIAL = np.dtype([("color", float4), ("ambient", np.float32), ("diffuse", np.float32),
                     ("specular", np.float32), ("shininess", np.float32),
                     ("flags", np.uint32), ("reflectivity", np.float32), ("transparency", np.float32),
                     ("ior", np.float32)])
LIGHT = np.dtype([("position", float4), ("color", float4)])
BVH_PAIR_NODE = np.dtype([("left_a", float4), ("left_b", float4), ("right_a", float4), ("right_b", float4)])
BVH_NODE = np.dtype([("bound_a", float4), ("bound_b", float4), ("left_first", np.int32),
                     ("count", np.int32), ("right", np.int32), ("pad", np.int32)])

MATERIAL_SMOOTH = 1

# struct name in layouts.h -> numpy dtype; the layout test walks this table.
STRUCTS = {
    "Ray": RAY,
    "Hit": HIT,
    "TriangleVerts": TRIANGLE_VERTS,
    "TriangleInfo": TRIANGLE_INFO,
    "Material": MATERIAL,
    "Light": LIGHT,
    "BvhNode": BVH_NODE,
    "BvhPairNode": BVH_PAIR_NODE,
}
