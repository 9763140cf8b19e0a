"""Every buffer the host shares with the kernels, defined once.

The contract between the host and the kernels: every stage that fills or reads
a device buffer takes its dtype from here.  Each numpy structured dtype below
has a twin struct in ``clrt/kernels/layouts.h``;
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

``Material`` (112 B) -- bytes 0..47 are the paper's Whitted model, the only
ones the Whitted kernels read; bytes 48.. the path tracer's metallic-roughness
model (glTF 2.0 appendix B).  The path tracer's base colour is ``color`` (times
the corner colour and texture, as for Whitted: texture.cl's surface_albedo).
Every row fills both parts: a material that gives no PBR values gets them from
its Phong ones (``clrt.scene.scene.Material.pbr_values``, documented there).
    0: color     float4  linear RGB albedo (the base colour); a: as_int, row of the
                         Texture table multiplying it (sRGB), -1 for none (read only
                         in -DSURFACE_DETAIL builds, as every texture row below)
   16: ambient   float   coefficients of the Phong model
   20: diffuse   float
   24: specular  float
   28: shininess float   Phong exponent
   32: flags        uint  bit 0 MATERIAL_SMOOTH: smooth shading (interpolate vertex
                          normals); bit 1 MATERIAL_DOUBLE_SIDED: emission leaves both
                          faces (else only the front one, glTF's counter-clockwise side)
   36: reflectivity float weight of the mirror ray (0..1)
   40: transparency float weight of the refracted ray (0..1)
   44: ior          float index of refraction (>= 1); the path tracer's too
   48: emission     float4 xyz: linear emitted radiance (glTF emissiveFactor x
                          KHR_materials_emissive_strength), >= 0; w: as_int, Texture
                          row of the emissive texture multiplying it (sRGB), -1 none
   64: metallic     float 0..1
   68: roughness    float perceptual roughness 0..1 (GGX alpha = roughness^2)
   72: specular_weight float KHR_materials_specular specularFactor 0..1 (0: pure Lambert)
   76: transmission float KHR_materials_transmission factor 0..1 (a dielectric of ``ior``)
   80: specular_color float4 xyz: KHR_materials_specular specularColorFactor (linear,
                          >= 0); w: as_int, Texture row of the metallicRoughness
                          texture (G = roughness, B = metallic; linear), -1 none
   96: normal_texture int Texture row of the tangent-space normal map (linear), -1 none
  100: normal_scale float glTF normalTexture.scale (1 default)
  104: pad          uint[2]  0

The next three exist only in scenes with textures or colours, whose programs
are built with -DSURFACE_DETAIL; plain scenes upload and read none of them.

``TriangleDetail`` (64 B) -- per slot (split like the geometry): what each corner
adds to the material, interpolated with the hit's barycentrics
    0: corner    float4[3]  corner k: xyz = linear RGB colour (1, 1, 1 without
                            colours), w = texture coordinate u
   48: v         float4     xyz = texture coordinate v of corners 0, 1, 2; w unused (0)

``Texture`` (24 B) -- one row per texture and decoding of the scene (an image
that one material reads as colour and another as data has two rows over the
same texels)
    0: first   uint  texel of the image's top-left pixel in the texel buffer
    4: width   int   pixels
    8: height  int
   12: wrap_s  uint  along u: WRAP_REPEAT, WRAP_CLAMP or WRAP_MIRROR (clrt.config.TEXTURE_WRAPS)
   16: wrap_t  uint  along v
   20: linear  uint  0: colours, 8-bit sRGB (base colour, emission); 1: data, read
                     linearly as code * (1/255) (metallicRoughness, normal maps)

Texels (``TEXEL``, 4 B each): uchar4, xyz = 8-bit codes, w unused (0), every
image's rows top to bottom, one after another, in one buffer (split like the
geometry when it is larger than one allocation); each image once, however many
rows and materials read it.  The kernels decode sRGB through a 256-entry float
table (``SRGB_TABLE``, 1 KiB), so an image costs 4 B a texel on the device -- a
quarter of float4 texels -- and the decoded values are exact float32 constants,
the same on every device and in the reference; a linear code c is
float(c) * float(1/255), one correctly rounded product, the same everywhere too.

``Light`` (64 B) -- point or spot light
    0: position  float4  xyz, w unused
   16: color     float4  linear RGB intensity (radiant intensity for the path tracer), a unused
   32: direction float4  xyz: unit axis of a spot light's cone (zeros for a point light); w unused
   48: cos_outer float   cosine of the cone's half angle, where the light ends; -1: a point light
                         (no cone: Whitted and the path tracer skip the falloff, bit for bit)
   52: cos_inner float   cosine of the half angle where the falloff begins (full intensity inside):
                         falloff = smoothstep(cos_outer, cos_inner, cos(angle to the axis))
   56: pad       uint[2]

``LightEntry`` (32 B) -- one light of the path tracer's light table (lights.cl), chosen
by Walker's alias method in proportion to its power (clrt/scene/emitters.py)
    0: threshold   float  keep this entry when the uniform u, scaled to the entry, lies below it
    4: alias       int    else take this entry
    8: kind        uint   LIGHT_POINT (a Light row: point or spot), LIGHT_TRIANGLE (an emissive
                          triangle's slot), LIGHT_BACKGROUND (the background or environment map)
   12: index       int    the Light row or the triangle's slot (-1 for the background)
   16: probability float  of choosing this entry (its power / all lights' power)
   20: instance    int    a triangle's instance in a two-level scene (the placed triangle:
                          each placement of an emitter is an entry; 0 in a one-level scene)
   24: pad         uint[2]

Kernel arguments passed by value (OpenCL lets no pointer into them: buffers
travel beside them, and they hold byte offsets into those buffers).  Which
kernel takes which is declared once, in the signature tables
(clrt/device/signature.py, clrt/query/kernels.py, clrt/renderer/kernels.py).

``Camera`` (80 B) -- a pinhole camera (camera.cl), eye in the device's frame
    0: eye      float4  xyz; w unused (0)
   16: forward  float4  unit basis, w unused
   32: right    float4
   48: up       float4
   64: scale_x  float   tan(fov/2) * W/H
   68: scale_y  float   tan(fov/2)
   72: width    uint    pixels
   76: height   uint

``QueryLaunch`` (160 B) -- one launch of a ray query (trace.cl, rays.cl)
    0: shift     float4  xyz: the device frame's origin, subtracted from every ray origin
   16: scene_lo  float4  xyz: the box of the triangles, device frame
   32: scene_hi  float4
   48: origin_stride, dir_stride, tmin_stride, tmax_stride  uint  floats from one
                 ray to the next in each input array (0: one row for every ray)
   64: in_first  uint    element of the inputs holding the launch's first ray
   68: ray_first uint    its index in the caller's batch (bad rays are reported by it)
   72: num_rays  uint
   76: normalise uint    0: the directions are unit vectors already
   80: reach2    float   square of the farthest an origin may lie from the box's far side
   84: cull      int     CULL_NONE, CULL_BACK or CULL_FRONT
   88: capacity  uint    query_all: the most hits the results hold
   92: pad       uint
   96: field_at  ulong[RESULT_SLOTS]  byte offset in the launch's results buffer of
                 each output (query_closest: CLOSEST_FIELDS in order; query_all:
                 ray ids, prims, ts, then the hit counter), NO_RESULT: not asked for

``Tile`` (56 B) -- one launch over a tile of the image (render.cl)
    0: x, y, w, h   uint  pixels (x, y) .. (x + w - 1, y + h - 1) of the image
   16: rays_at      uint  byte offset in the frame buffer of the tile's Ray array
   20: hits_at      uint  ... of its Hit array
   24: image_at     uint  ... of its float4 linear colours
   28: sample       uint  this launch's sample (0 .. samples_per_axis^2 - 1)
   32: samples_per_axis uint
   36: seed         uint  of the sample jitter
   40: max_depth    uint  reflection / refraction bounces
   44: sample_weight float 1 / samples
   48: first_sample uint  1: the image starts from this sample
   52: srgb_at      uint  0, or the byte offset in the frame buffer of the tile's packed
                          8-bit sRGB colours, which this launch (the last sample) writes

``PathLaunch`` (224 B) -- one launch of the path tracer (path.cl) over a rectangle of the image
    0: cam          Camera  as above (80 B)
   80: background   float4  xyz: radiance of the constant background (no environment map); w unused
   96: environment  float4  x, y: cos and sin of the environment map's turn about +y; z: its strength;
                            w: probability of choosing the background / environment among the lights
  112: image_at     ulong   byte offset in `frame` of the image's float4 sums of radiance (w: samples)
  120: albedo_at    ulong   ... of the float4 sums of the first hit's albedo
  128: normal_at    ulong   ... of the float4 sums of the first hit's shading normal
  136: x, y, w, h   uint    pixels (x, y) .. (x + w - 1, y + h - 1) of the image
  152: sample_first uint    the launch's first sample of each pixel (the RNG's sample index)
  156: sample_count uint    samples per pixel of this launch
  160: samples_before uint  samples the sums hold already (0: this launch starts them)
  164: seed         uint
  168: max_depth    int     Mitsuba's count: 1 emitters seen directly, 2 direct light, ...; -1 unbounded
  172: rr_depth     uint    Russian roulette from this depth on
  176: strategy     uint    PATH_MIS, PATH_LIGHTS (light sampling only), PATH_BSDF (BSDF sampling only)
  180: entries_at   uint    byte offset in `tables` of the LightEntry rows
  184: num_entries  uint    0: no light to sample
  188: inv_power    float   1 / the power of all lights (the emissive triangles' probabilities)
  192: env_at       uint    byte offset in `tables` of the environment map's float4 texels, row 0 at the top
  196: env_width    uint    0: no environment map (the constant background)
  200: env_height   uint
  204: marginal_at  uint    ... of its rows' CDF (env_height + 1 floats)
  208: conditional_at uint  ... of each row's CDF over its texels (env_height rows of env_width + 1 floats)
  212: record_at    uint    -DPATH_RECORD_RAYS (benchmarks): byte offset in `frame` of the rays
                            recorded (PathTracer.record_rays): a PathRecordHead, then
                            record_capacity Ray rows of each kind, kind by kind
  216: record_capacity uint rays of each kind the record holds
  220: pad          uint

``PathRecordHead`` (16 B) -- the head of the rays path_trace records (-DPATH_RECORD_RAYS)
    0: traced       uint[4] rays of each kind traced (PathTracer.RECORD_KINDS: bounces, shadow
                            rays), recorded or not

``SceneInfo`` (80 B) -- the uploaded scene's values (geometry.cl, shading.cl)
    0: ambient_light float4  linear RGB, w unused (renderer only, as the rest but
                             num_tris, packets_at and num_instances)
   16: background    float4
   32: packets_at    ulong   -DBVH_WIDE: byte offset of the first TrianglePacket in
                             the wide buffer (BvhWideNode rows before it)
   40: num_tris      uint    slots
   44: num_lights    uint
   48: materials_at, lights_at, textures_at, srgb_at  uint  byte offsets in the
                             renderer's `tables` buffer (Material, Light, Texture
                             rows and the SRGB_TABLE)
   64: num_instances uint    -DACCEL_INSTANCES: rows of the instance table (0 otherwise)
   68: pad           uint[3]

``Instance`` (160 B) -- one placement of a mesh in a two-level scene
(-DACCEL_INSTANCES; docs/instances.md), rows in the caller's order (the
index a query reports).  Both maps are computed in float64 on the host and
rounded to float32 once; "world" is the device's frame of the scene, "object"
the mesh's own device frame:
    0: to_world   float4[3]  row i: xyz = row i of the linear part, w = translation i:
                             world_i = dot(to_world[i].xyz, p) + to_world[i].w
   48: to_object  float4[3]  its inverse, rows likewise
   96: lo         float4     xyz: min corner of the instance's world box (the mesh's box
                             mapped and padded for the transform's rounding, rounded
                             outwards); w unused (0)
  112: hi         float4     xyz: max corner; w unused (0)
  128: mesh       int        index of its mesh among the scene's distinct meshes
  132: root       int        row of that mesh's BVH root in the rows (0 without a BVH)
  136: first      int        the mesh's first slot (its slots are first .. first + count - 1)
  140: count      int        the mesh's triangles
  144: flags      uint       INSTANCE_MIRROR (clrt.config): to_world's determinant is negative
  148: material   int        the renderer: the row of its object's first material in the
                             Material table (a triangle's TriangleInfo.material counts from
                             it: materials per placement); 0 for ray queries
  152: min_scale  float      the linear part's smallest singular value, rounded down: no
                             point of the placed mesh lies nearer a point than that times
                             their distance in object space (closest points, point.cl)
  156: pad        uint
In a two-level scene the BvhPairNode rows are the top level's (root at row
0; a leaf holds one instance, its reference the instance's row here), then
each distinct mesh's, every reference global; the slots are each mesh's
triangles in its leaf order, meshes one after another, and ``prim_ids`` gives
a slot's row in its own mesh's faces.

``BvhPairNode`` (64 B) -- the BVH as the kernels walk it: one row per inner node, holding
both children's volumes and references (as Aila & Laine 2009 do with boxes), so
that one fetch decides which children to enter: four float4 loads, two 32-byte
memory sectors.  Rows in depth-first order, the root at 0.  A volume takes six
floats, the xyz lanes of *_a and *_b; the w lanes hold int32 bits (``as_int`` in
the kernels, ``clrt.accel.rows.child_refs`` on the host):
    0: left_a      float4  xyz: volume part a -- box: min corner | sphere: centre
                           | ellipsoid: centre
                           w: left -- left_count == 0: row of the left child | > 0: its first slot
   16: left_b      float4  xyz: volume part b -- box: max corner | sphere: radius
                           in x, y = z = 0 | ellipsoid: reciprocal semi-axes (1/Rx, 1/Ry, 1/Rz)
                           w: left_count -- 0: inner child | > 0: leaf of that many
                           triangles | -1: no child (only the right one, when the
                           whole tree is one leaf, held on the left)
   32: right_a     float4  as left_a, w: right
   48: right_b     float4  as left_b, w: right_count
Every volume encloses all triangles of its subtree, rounded outwards in float32
(clrt/accel/volumes.py).  The triangle buffers of a BVH scene are stored in leaf
order ("slots"); ``prim_ids`` (int32 per slot) maps a slot back to the input
triangle index, which is what queries report.

``BvhWideNode`` (256 B) -- the same BVH as CPU devices walk it (clrt/accel/wide.py;
built only for a CPU device, box volumes, buffers not split): up to eight
children per node, their boxes stored lane by lane, so that one float8
operation treats all of them (lane k = child k).  Nodes level by level, the
root at 0:
    0: lo_x   float8  min corners of the children's boxes, x (bit for bit the
   32: lo_y   float8  boxes of the BvhPairNode rows they come from)
   64: lo_z   float8
   96: hi_x   float8  max corners
  128: hi_y   float8
  160: hi_z   float8
  192: child  int8    count == 0: node of the child | > 0: its leaf's first TrianglePacket
  224: count  int8    0: inner child | > 0: a leaf of that many packets | -1: no child
                      (its lane's box is zeros; the kernels skip it by the count)

``TrianglePacket`` (160 B) -- up to four triangles of one leaf, coordinates lane by
lane (lane k = triangle k), so that one float4 operation tests all four:
    0: v0     float4[3]  x, y, z of the first corners
   48: v1     float4[3]  x, y, z of the second corners
   96: v2     float4[3]  x, y, z of the third corners
  144: slot   int4       slot of each lane's triangle, -1: an empty lane (corners 0)
A leaf's triangles fill its packets in slot order; the triangle buffers and
``prim_ids`` stay as they are (results and shading read them by slot).

``WideDisk`` (256 B) -- for the point queries of CPU devices (point.cl's
walk_wide_points; clrt/accel/disks.py): each child of a BvhWideNode, lane k for
child k, its triangles enclosed in a flat cylinder: every point x of them has
|n.(x - c)| <= half_height and lies within radius of the axis through c along n.
Zeros in lanes without a child.  The point queries' copy of the wide BVH holds
one per node, between the nodes and the packets (geometry.cl):
    0: cx, cy, cz   float8  the centre c
   96: nx, ny, nz   float8  the axis n (unit, rounded to float32)
  192: radius       float8
  224: half_height  float8  half the cylinder's height, along n

``WindingNode`` (96 B) -- the far field of one child of a BvhPairNode row, for
winding numbers (winding.cl; rows x 2, child ``2 * row + side``, side 0 left):
the first three terms of the Taylor series of its triangles' solid angles about
``centre`` (Barill et al. 2018, "Fast winding numbers for soups and clouds"),
made on the device from the rows and the triangles (trace.cl's winding_nodes),
device frame, with d = x - centre over the triangles' points x and n their
unit normals.  Only the symmetric parts of the moments reach the series (and
they alone move to a new centre), so only they are kept:
    0: centre  float4  xyz: the triangles' area-weighted centroid; w: radius, no
                       corner of them farther from the centre (rounded up)
   16: normal  float4  xyz: sum of area * n, the dipole; w: their area (the sum
                       of the triangles' areas: it bounds the series' error)
   32: first   float[6]   the symmetric part of sum of n_i * integral of d_j dA:
                          [ij] = xx, xy, xz, yy, yz, zz
   56: second  float[10]  the fully symmetric part of sum of n_i * integral of
                          d_j d_k dA: [ijk] = xxx, xxy, xxz, xyy, xyz, xzz, yyy,
                          yyz, yzz, zzz
A missing child (the right of a one-leaf tree) holds zeros.

``WideWindingNode`` (768 B) -- the same far fields for the wide BVH of CPU devices
(accel_wide.cl), lane k for child k of a BvhWideNode (the WindingNode of the
binary child the lane holds, ``WideBvh.sources``), so that one float8 series
serves all eight; gathered on the host (clrt/query/inside.py), zeros in lanes
without a child:
    0: cx, cy, cz      float8  the centres
   96: radius          float8
  128: nx, ny, nz      float8  the dipoles
  224: area            float8
  256: first           float8[6]   as WindingNode's, lane by lane
  448: second          float8[10]

``PlacedWindingNode`` (160 B) -- WindingNode's far field in a two-level scene
(-DACCEL_INSTANCES; winding.cl, docs/instances.md), the moments whole: an
affine map that scales unevenly or shears mixes their symmetric and other parts,
so a mesh's node, kept in the mesh's own space, serves every placement only
whole.  The rows of the top level hold the world's: an instance's, its mesh's
moments mapped by its transform, and their joins.
    0: centre  float4  as WindingNode's; w: the radius, or INFINITY for a node
                       never taken from its series (an instance too unevenly scaled)
   16: normal  float4  as WindingNode's (in the world: w bounds the area)
   32: extent  float4  xyz: no corner farther from the centre along each axis
                       (rounded up; a box, which an uneven placement maps to a
                       tighter world radius than the sphere); w unused
   48: first   float[9]   sum of n_i * integral of d_j dA: [3 i + j]
   84: second  float[18]  sum of n_i * integral of d_j d_k dA: [6 i + jk], jk =
                          xx, xy, xz, yy, yz, zz (symmetric in j, k)
  156: pad     uint

``PseudoNormals`` (96 B) -- per slot, for signs by normal (point.cl): the
angle-weighted pseudo-normals (Baerentzen & Aanaes 2005) of the triangle's
edges and corners, unit length (zero where no face around has an area),
made on the host from the mesh (clrt/query/inside.py), vertices merged by position:
    0: edge    float4[3]  xyz: edge v0v1, v1v2, v2v0 -- the sum of the unit normals of
                          the faces on it; w unused (0)
   48: vertex  float4[3]  xyz: corner v0, v1, v2 -- the sum of the unit normals of the
                          faces around it, each times its angle there; w unused (0)

``BuildNode`` (48 B) -- scratch of the device builder (clrt/device/build.py), one per
node of its binary tree: triangles are nodes 0..F-1 (in Morton order), merged
nodes F..2F-2 in the order they are made, the root last:
    0: lo      float4  xyz: exact min corner of the node's triangles
                       w: as_int, left child (-1: the node is a triangle)
   16: hi      float4  xyz: exact max corner; w: as_int, right child (-1: a triangle)
   32: parent  int     -1 at the root
   36: count   int     triangles under the node
   40: rows    int     BvhPairNode rows its emitted subtree takes: 0 when it is
                       emitted as a leaf (a triangle, or a subtree SAH collapses)
   44: cost    float   SAH cost of that subtree, not yet divided by the root's area

``BuildCluster`` (32 B) -- one cluster of the device builder's PLOC merging:
    0: lo      float4  xyz: min corner of the cluster's box; w: as_int, its BuildNode
   16: hi      float4  xyz: max corner; w: as_int, its segment (bits 0..7: only clusters
                       of one segment merge) and, on CPU devices between two kernels of
                       an iteration, 1 + its rank among the kept clusters of its block
                       (bits 8..: 0 when merged away)

``BuildMove`` (16 B) -- per BuildNode, its best move in an iteration of the device
builder's reinsertion (build_reinsert.cl):
    0: target    int    the node to move next to (a new parent takes its place); -1: none
    4: gain      float  the SAH cost the move saves (half areas, C_TRAVERSAL units)
    8: junction  int    the lowest common ancestor of the node and the target
   12: pad       int

``BuildLock`` (8 B) -- per BuildNode, which reinsertion move may rewire it:
    0: gain      uint   the highest gain (its float's bits) of the moves that rewire it
    4: owner     int    the lowest moving node among the moves of that gain

``BuildPart`` (64 B) -- one node of the device builder's SAH partition of the
triangles into segments (build_partition.cl), before PLOC; node 0 is all of them:
    0: centre_lo  uint4  xyz: min corner of its triangles' box centres, as
                         order-preserving bits (build_morton.cl's ordered_bits)
   16: centre_hi  uint4  xyz: max corner, likewise
   32: count      int    its triangles among the samples that the partition looks at
   36: child      int    its first child (the second follows it), -1: not split
   40: axis       int    the split's axis
   44: split      int    the first of the axis's bins that go right
   48: segment    int    a node never split: its place among those in depth-first order
   52: open       int    1: to be split at the next level
   56: pad        int[2]
"""

import numpy as np

from clrt.config import RESULT_SLOTS

float4 = np.dtype((np.float32, 4))

RAY = np.dtype([("origin", float4), ("dir", float4)])
HIT = np.dtype([("t", np.float32), ("prim", np.int32), ("u", np.float32), ("v", np.float32)])
TRIANGLE_VERTS = np.dtype([("v0", float4), ("v1", float4), ("v2", float4)])
TRIANGLE_INFO = np.dtype([("vertex", np.int32, 3), ("material", np.int32)])
MATERIAL = np.dtype([("color", float4), ("ambient", np.float32), ("diffuse", np.float32),
                     ("specular", np.float32), ("shininess", np.float32),
                     ("flags", np.uint32), ("reflectivity", np.float32), ("transparency", np.float32),
                     ("ior", np.float32),
                     ("emission", float4), ("metallic", np.float32), ("roughness", np.float32),
                     ("specular_weight", np.float32), ("transmission", np.float32), ("specular_color", float4),
                     ("normal_texture", np.int32), ("normal_scale", np.float32), ("pad", np.uint32, 2)])
TRIANGLE_DETAIL = np.dtype([("corner", float4, 3), ("v", float4)])
TEXTURE = np.dtype([("first", np.uint32), ("width", np.int32), ("height", np.int32),
                    ("wrap_s", np.uint32), ("wrap_t", np.uint32), ("linear", np.uint32)])
TEXEL = np.dtype((np.uint8, 4))
SRGB_TABLE = np.dtype((np.float32, 256))
LIGHT = np.dtype([("position", float4), ("color", float4), ("direction", float4), ("cos_outer", np.float32),
                  ("cos_inner", np.float32), ("pad", np.uint32, 2)])
LIGHT_ENTRY = np.dtype([("threshold", np.float32), ("alias", np.int32), ("kind", np.uint32), ("index", np.int32),
                        ("probability", np.float32), ("instance", np.int32), ("pad", np.uint32, 2)])
BVH_PAIR_NODE = np.dtype([("left_a", float4), ("left_b", float4), ("right_a", float4), ("right_b", float4)])
float8, int8, int4 = np.dtype((np.float32, 8)), np.dtype((np.int32, 8)), np.dtype((np.int32, 4))
BVH_WIDE_NODE = np.dtype([("lo_x", float8), ("lo_y", float8), ("lo_z", float8), ("hi_x", float8),
                          ("hi_y", float8), ("hi_z", float8), ("child", int8), ("count", int8)])
TRIANGLE_PACKET = np.dtype([("v0", float4, 3), ("v1", float4, 3), ("v2", float4, 3), ("slot", int4)])
WIDE_DISK = np.dtype([(name, float8) for name in ("cx", "cy", "cz", "nx", "ny", "nz", "radius",
                                                  "half_height")])
WINDING_NODE = np.dtype([("centre", float4), ("normal", float4), ("first", np.float32, 6),
                         ("second", np.float32, 10)])
WIDE_WINDING_NODE = np.dtype([(name, float8) for name in ("cx", "cy", "cz", "radius", "nx", "ny", "nz", "area")]
                             + [("first", float8, 6), ("second", float8, 10)])
PLACED_WINDING_NODE = np.dtype([("centre", float4), ("normal", float4), ("extent", float4),
                                ("first", np.float32, 9), ("second", np.float32, 18), ("pad", np.uint32, 1)])
PSEUDO_NORMALS = np.dtype([("edge", float4, 3), ("vertex", float4, 3)])
BUILD_NODE = np.dtype([("lo", float4), ("hi", float4), ("parent", np.int32), ("count", np.int32),
                       ("rows", np.int32), ("cost", np.float32)])
BUILD_CLUSTER = np.dtype([("lo", float4), ("hi", float4)])
BUILD_MOVE = np.dtype([("target", np.int32), ("gain", np.float32), ("junction", np.int32), ("made", np.int32)])
BUILD_LOCK = np.dtype([("gain", np.uint32), ("owner", np.int32)])
BUILD_PART = np.dtype([("centre_lo", np.uint32, 4), ("centre_hi", np.uint32, 4), ("count", np.int32),
                       ("child", np.int32), ("axis", np.int32), ("split", np.int32), ("segment", np.int32),
                       ("open", np.int32), ("pad", np.int32, 2)])
CAMERA = np.dtype([("eye", float4), ("forward", float4), ("right", float4), ("up", float4),
                   ("scale_x", np.float32), ("scale_y", np.float32), ("width", np.uint32), ("height", np.uint32)])
QUERY_LAUNCH = np.dtype([("shift", float4), ("scene_lo", float4), ("scene_hi", float4),
                         ("origin_stride", np.uint32), ("dir_stride", np.uint32), ("tmin_stride", np.uint32),
                         ("tmax_stride", np.uint32), ("in_first", np.uint32), ("ray_first", np.uint32),
                         ("num_rays", np.uint32), ("normalise", np.uint32), ("reach2", np.float32),
                         ("cull", np.int32), ("capacity", np.uint32), ("pad", np.uint32),
                         ("field_at", np.uint64, RESULT_SLOTS)])
TILE = np.dtype([("x", np.uint32), ("y", np.uint32), ("w", np.uint32), ("h", np.uint32),
                 ("rays_at", np.uint32), ("hits_at", np.uint32), ("image_at", np.uint32),
                 ("sample", np.uint32), ("samples_per_axis", np.uint32), ("seed", np.uint32),
                 ("max_depth", np.uint32), ("sample_weight", np.float32), ("first_sample", np.uint32),
                 ("srgb_at", np.uint32)])
PATH_LAUNCH = np.dtype([("cam", CAMERA), ("background", float4), ("environment", float4),
                        ("image_at", np.uint64), ("albedo_at", np.uint64), ("normal_at", np.uint64),
                        ("x", np.uint32), ("y", np.uint32), ("w", np.uint32), ("h", np.uint32),
                        ("sample_first", np.uint32), ("sample_count", np.uint32), ("samples_before", np.uint32),
                        ("seed", np.uint32), ("max_depth", np.int32), ("rr_depth", np.uint32),
                        ("strategy", np.uint32), ("entries_at", np.uint32), ("num_entries", np.uint32),
                        ("inv_power", np.float32), ("env_at", np.uint32), ("env_width", np.uint32),
                        ("env_height", np.uint32), ("marginal_at", np.uint32), ("conditional_at", np.uint32),
                        ("record_at", np.uint32), ("record_capacity", np.uint32), ("pad", np.uint32)])
PATH_RECORD_HEAD = np.dtype([("traced", np.uint32, 4)])
SCENE_INFO = np.dtype([("ambient_light", float4), ("background", float4), ("packets_at", np.uint64),
                       ("num_tris", np.uint32), ("num_lights", np.uint32), ("materials_at", np.uint32),
                       ("lights_at", np.uint32), ("textures_at", np.uint32), ("srgb_at", np.uint32),
                       ("num_instances", np.uint32), ("pad", np.uint32, 3)])
INSTANCE = np.dtype([("to_world", float4, 3), ("to_object", float4, 3), ("lo", float4), ("hi", float4),
                     ("mesh", np.int32), ("root", np.int32), ("first", np.int32), ("count", np.int32),
                     ("flags", np.uint32), ("material", np.int32),
                     ("min_scale", np.float32), ("pad", np.uint32)])

# struct name in layouts.h -> numpy dtype; the layout test walks this table.
STRUCTS = {
    "Ray": RAY,
    "Hit": HIT,
    "TriangleVerts": TRIANGLE_VERTS,
    "TriangleInfo": TRIANGLE_INFO,
    "Material": MATERIAL,
    "TriangleDetail": TRIANGLE_DETAIL,
    "Texture": TEXTURE,
    "Light": LIGHT,
    "LightEntry": LIGHT_ENTRY,
    "BvhPairNode": BVH_PAIR_NODE,
    "BvhWideNode": BVH_WIDE_NODE,
    "TrianglePacket": TRIANGLE_PACKET,
    "WideDisk": WIDE_DISK,
    "WindingNode": WINDING_NODE,
    "WideWindingNode": WIDE_WINDING_NODE,
    "PlacedWindingNode": PLACED_WINDING_NODE,
    "PseudoNormals": PSEUDO_NORMALS,
    "BuildNode": BUILD_NODE,
    "BuildCluster": BUILD_CLUSTER,
    "BuildMove": BUILD_MOVE,
    "BuildLock": BUILD_LOCK,
    "BuildPart": BUILD_PART,
    "Camera": CAMERA,
    "QueryLaunch": QUERY_LAUNCH,
    "Tile": TILE,
    "PathLaunch": PATH_LAUNCH,
    "PathRecordHead": PATH_RECORD_HEAD,
    "SceneInfo": SCENE_INFO,
    "Instance": INSTANCE,
}
