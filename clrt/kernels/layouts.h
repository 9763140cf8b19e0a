// Structs shared with the host.  The byte layout of each is documented once,
// in clrt/layouts.py next to its numpy dtype; tests/test_layouts.py checks that
// both sides agree on every offset.  Limits and flag values (MAX_BOUNCES,
// MATERIAL_SMOOTH, MATERIAL_DOUBLE_SIDED, CULL_*) come from clrt/config.py as
// -D defines of every program build, never from a #define here.
#ifndef CLRT_LAYOUTS_H
#define CLRT_LAYOUTS_H

#ifndef MAX_BOUNCES
#error "build through clrt.device.program.build_program: it passes clrt.config.kernel_defines()"
#endif

typedef struct {
    float4 origin;   // xyz origin, w = tmin
    float4 dir;      // xyz unit direction, w = tmax
} Ray;

typedef struct {
    float t;         // INFINITY on a miss
    int prim;        // -1 on a miss
    float u, v;      // barycentric weights of vertices 1 and 2
} Hit;

typedef struct {
    float4 v0, v1, v2;
} TriangleVerts;

typedef struct {
    int vertex[3];
    int material;
} TriangleInfo;

// Bytes 0..47: the paper's Whitted model (all the Whitted kernels read);
// 48..111: the path tracer's metallic-roughness model.  Texture rows: -1 none.
typedef struct {
    float4 color;         // linear base colour; w: as_int, row of its Texture (sRGB)
    float ambient, diffuse, specular, shininess;
    uint flags;           // MATERIAL_SMOOTH, MATERIAL_DOUBLE_SIDED
    float reflectivity;   // weight of the mirror ray
    float transparency;   // weight of the refracted ray
    float ior;            // index of refraction
    float4 emission;      // xyz: linear emitted radiance; w: as_int, row of its Texture (sRGB)
    float metallic;       // 0..1
    float roughness;      // perceptual, 0..1 (GGX alpha = roughness^2)
    float specular_weight;   // KHR_materials_specular factor (0: pure Lambert)
    float transmission;   // KHR_materials_transmission factor (dielectric of ior)
    float4 specular_color;   // xyz: KHR specular colour; w: as_int, row of the metallicRoughness Texture (linear)
    int normal_texture;   // row of the tangent-space normal map Texture (linear)
    float normal_scale;   // glTF normalTexture.scale
    uint pad[2];
} Material;

// Only in -DSURFACE_DETAIL builds (textures or colours in the scene).
typedef struct {
    float4 corner[3];     // xyz: linear RGB colour of corner k, w: its texture u
    float4 v;             // xyz: texture v of corners 0, 1, 2
} TriangleDetail;

typedef struct {
    uint first;           // texel of the top-left pixel
    int width, height;
    uint wrap_s, wrap_t;  // WRAP_REPEAT, WRAP_CLAMP, WRAP_MIRROR
    uint linear;          // 0: sRGB colours; 1: linear data (metallicRoughness, normal maps)
} Texture;

typedef struct {
    float4 position;
    float4 color;
    float4 direction;     // xyz: a spot light's unit axis
    float cos_outer;      // -1: a point light (no cone)
    float cos_inner;
    uint pad[2];
} Light;

// One light of the path tracer's table (lights.cl), chosen by the alias method.
typedef struct {
    float threshold;      // keep this entry when u (scaled to it) < threshold
    int alias;            // else this one
    uint kind;            // LIGHT_POINT, LIGHT_TRIANGLE, LIGHT_BACKGROUND
    int index;            // Light row, or the triangle's slot
    float probability;    // of choosing it
    int instance;         // a triangle's instance (two-level scenes; 0 otherwise)
    uint pad[2];
} LightEntry;

// ---- Kernel arguments passed by value: each kernel takes its buffers and at
// most a few of these (clrt/device/signature.py counts them; every kernel
// stays within 12 parameters).  OpenCL allows no pointers in them, so the
// buffers travel beside them and the structs hold byte offsets into buffers.

// A pinhole camera (camera.cl), eye in the device's frame.
typedef struct {
    float4 eye;                  // xyz; w unused
    float4 forward, right, up;   // unit basis; w unused
    float scale_x;               // tan(fov/2) * W/H
    float scale_y;               // tan(fov/2)
    uint width, height;          // pixels
} Camera;

// One launch of a ray query (trace.cl, rays.cl): its rays' layout in the input
// arrays, the device frame, and where the answers go in `results`.
typedef struct {
    float4 shift;                // the device frame's origin: subtracted from every ray origin
    float4 scene_lo, scene_hi;   // xyz: the box of the triangles, device frame
    uint origin_stride, dir_stride, tmin_stride, tmax_stride;   // floats from one ray to the next (0: one for all)
    uint in_first;               // element of the inputs holding the launch's first ray
    uint ray_first;              // its index in the caller's batch (bad rays are reported by it)
    uint num_rays;               // rays of the launch
    uint normalise;              // 0: the directions are unit vectors already
    float reach2;                // square of the farthest an origin may lie from the box's far side
    int cull;                    // CULL_NONE, CULL_BACK or CULL_FRONT
    uint capacity;               // query_all: the most hits `results` holds
    uint pad;
    ulong field_at[RESULT_SLOTS];   // byte offset in `results` of output k, NO_RESULT: not asked for
} QueryLaunch;

// One launch over a tile of the image (render.cl): which pixels, the sample,
// and where the tile's per-pixel arrays lie in the frame buffer.
typedef struct {
    uint x, y, w, h;             // pixels (x, y) .. (x + w - 1, y + h - 1) of the image
    uint rays_at, hits_at, image_at;   // byte offsets in `frame` of the Ray, Hit and float4 colour arrays
    uint sample;                 // this launch's sample, 0 .. samples_per_axis^2 - 1
    uint samples_per_axis;
    uint seed;                   // of the sample jitter
    uint max_depth;              // reflection / refraction bounces
    float sample_weight;         // 1 / samples
    uint first_sample;           // 1: the image starts from this sample
    uint srgb_at;                // 0, or (the last sample) the byte offset in `frame` of the packed sRGB8 colours
} Tile;

// One launch of the path tracer (path.cl) over a rectangle of the image; the
// image's sums lie in `frame`, the light tables in `tables` (layouts.py).
typedef struct {
    Camera cam;
    float4 background;           // xyz: constant background radiance
    float4 environment;          // x, y: cos, sin of the map's turn; z: strength; w: background's probability
    ulong image_at, albedo_at, normal_at;   // byte offsets in `frame` of the float4 sums
    uint x, y, w, h;             // pixels of the image
    uint sample_first, sample_count, samples_before, seed;
    int max_depth;               // Mitsuba's count; -1: unbounded
    uint rr_depth, strategy;
    uint entries_at, num_entries;
    float inv_power;             // 1 / the power of all lights
    uint env_at, env_width, env_height, marginal_at, conditional_at;
    uint record_at, record_capacity;   // -DPATH_RECORD_RAYS: where the traced rays are copied
    uint pad;
} PathLaunch;

// The head of the rays path_trace records (-DPATH_RECORD_RAYS, at PathLaunch's
// record_at); record_capacity Ray rows of each kind follow it, kind by kind.
typedef struct {
    uint traced[4];              // rays of each kind traced, recorded or not (RECORD_BOUNCE, ...)
} PathRecordHead;

// What kernels know of the uploaded scene by value: the triangle count, where
// the packets start in the wide BVH's buffer, and (the renderer) the light
// and colours and where each table lies in the `tables` buffer.
typedef struct {
    float4 ambient_light;        // linear RGB; w unused
    float4 background;
    ulong packets_at;            // BVH_WIDE: byte offset of the first TrianglePacket in `wide`
    uint num_tris;               // slots
    uint num_lights;
    uint materials_at, lights_at, textures_at, srgb_at;   // byte offsets in `tables`
    uint num_instances;          // ACCEL_INSTANCES: rows of the instance table
    uint pad[3];
} SceneInfo;

// One placement of a mesh in a two-level scene (-DACCEL_INSTANCES,
// instances.cl; docs/instances.md): row i of each map holds row i of its
// linear part in xyz and its translation in w.
typedef struct {
    float4 to_world[3];          // object -> world (the device's frames)
    float4 to_object[3];         // world -> object
    float4 lo, hi;               // xyz: the instance's conservative world box
    int mesh;                    // index among the distinct meshes
    int root;                    // row of the mesh's BVH root
    int first, count;            // the mesh's slots: first .. first + count - 1
    uint flags;                  // INSTANCE_MIRROR: to_world's determinant is negative
    int material;                // the renderer: row of its object's first Material (0 for queries)
    float min_scale;             // a lower bound of the linear part's smallest singular value (at most 7 % below)
    uint pad;
} Instance;

typedef struct {
    float4 left_a, left_b;     // left child: volume in the xyz lanes; w: as_int -> left, left_count
    float4 right_a, right_b;   // right child: likewise -> right, right_count
} BvhPairNode;

// A child reference: count 0: row of the child | count > 0: first slot of its
// leaf, count triangles | count -1: no child.
#define PAIR_LEFT(n) ((int2)(as_int((n).left_a.w), as_int((n).left_b.w)))
#define PAIR_RIGHT(n) ((int2)(as_int((n).right_a.w), as_int((n).right_b.w)))

// The wide BVH of CPU devices (accel_wide.cl); fields as layouts.py says.
typedef struct {
    float8 lo_x, lo_y, lo_z;   // lane k: min corner of child k's box
    float8 hi_x, hi_y, hi_z;   // lane k: max corner
    int8 child;                // lane k: node of child k, or its leaf's first packet
    int8 count;                // lane k: 0 inner, > 0 packets of a leaf, -1 no child
} BvhWideNode;

typedef struct {
    float4 v0[3], v1[3], v2[3];   // [axis], lane k: that corner of triangle k
    int4 slot;                    // lane k: slot of triangle k, -1: empty
} TrianglePacket;

// Flat cylinders around the children of a BvhWideNode, lane by lane (point queries on CPU devices);
// fields as layouts.py says.
typedef struct {
    float8 cx, cy, cz;
    float8 nx, ny, nz;
    float8 radius, half_height;
} WideDisk;

// The far field of one BVH child for winding numbers (winding.cl); fields as layouts.py says.
typedef struct {
    float4 centre;       // xyz: area-weighted centroid; w: radius (rounded up)
    float4 normal;       // xyz: sum of area * unit normal; w: area
    float first[6];      // [ij] = xx, xy, xz, yy, yz, zz: symmetric part of sum n_i * integral (x - c)_j
    float second[10];    // [ijk] = xxx, xxy, xxz, xyy, xyz, xzz, yyy, yyz, yzz, zzz: fully symmetric part
                         // of sum n_i * integral (x - c)_j (x - c)_k
} WindingNode;

// The WindingNodes of a BvhWideNode's children, lane by lane (CPU devices); fields as layouts.py says.
typedef struct {
    float8 cx, cy, cz, radius;
    float8 nx, ny, nz, area;
    float8 first[6];
    float8 second[10];
} WideWindingNode;

// The far field of a child in a two-level scene (winding.cl, -DACCEL_INSTANCES): the moments whole, not
// only their symmetric parts, so that any affine map of them can be evaluated (a placement that scales
// unevenly or shears mixes the parts).  A mesh's rows hold them in its own space, the top level's in the world.
typedef struct {
    float4 centre;       // xyz: area-weighted centroid; w: radius (rounded up; INFINITY: never far)
    float4 normal;       // xyz: sum of area * unit normal; w: area (in the world: a bound of it)
    float4 extent;       // xyz: no corner farther from the centre along each axis (rounded up)
    float first[9];      // [3 i + j] = sum n_i * integral (x - c)_j
    float second[18];    // [6 i + jk], jk = xx, xy, xz, yy, yz, zz: sum n_i * integral (x - c)_j (x - c)_k
    uint pad;
} PlacedWindingNode;

// Per slot: pseudo-normals of its edges and corners (signs by normal, point.cl).
typedef struct {
    float4 edge[3];      // edge v0v1, v1v2, v2v0
    float4 vertex[3];    // corner v0, v1, v2
} PseudoNormals;

// Scratch of the device builder (build_bvh.cl); fields as layouts.py says.
typedef struct {
    float4 lo;      // xyz: exact min corner; w: as_int, left child (-1: a triangle)
    float4 hi;      // xyz: exact max corner; w: as_int, right child (-1: a triangle)
    int parent;     // -1 at the root
    int count;      // triangles under the node
    int rows;       // pair rows of its emitted subtree: 0 when emitted as a leaf
    float cost;     // SAH cost of that subtree (not divided by the root's area)
} BuildNode;

typedef struct {
    int target;     // the node to move next to (-1: none)
    float gain;     // the SAH cost it saves, half areas
    int junction;   // the lowest common ancestor of the node and the target
    int made;       // reinsert_check's verdict: 1 if the move is made this iteration
} BuildMove;

typedef struct {
    uint gain;      // the highest gain (as_uint) of the moves that rewire the node
    int owner;      // of those, the lowest moving node
} BuildLock;

typedef struct {
    float4 lo;      // xyz: min corner of the cluster's box; w: as_int, its BuildNode
    float4 hi;      // xyz: max corner; w: as_int, segment (bits 0..7) and on CPUs 1 + rank (8..)
} BuildCluster;

typedef struct {
    uint4 centre_lo;   // xyz: min corner of its triangles' box centres (ordered_bits)
    uint4 centre_hi;   // xyz: max corner
    int count;         // its triangles among the partition's samples
    int child;         // first child, the second follows; -1: not split
    int axis;          // split axis
    int split;         // first bin of the right child
    int segment;       // never split: place among those in depth-first order
    int open;          // 1: to be split at the next level
    int pad[2];
} BuildPart;

#endif
