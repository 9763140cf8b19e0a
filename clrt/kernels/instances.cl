// Instances of a two-level scene (-DACCEL_INSTANCES; docs/instances.md): a
// ray moved into an instance's object space, and what a hit there looks like
// from the world (face culling, the front flag, the normal).  The walks are
// in accel_bvh.cl (walk_instances) and accel_none.cl; the table's rows are
// layouts.h's Instance.
//
// The object-space direction is the world's unit direction mapped by the
// linear part, not normalised: the object point at t maps to the world point
// at t, so every distance a walk compares is the world's.
#ifndef CLRT_INSTANCES_CL
#define CLRT_INSTANCES_CL

#include "geometry.cl"

#ifdef ACCEL_INSTANCES

// Row i of an affine map (Instance.to_world / to_object) applied to p (unit
// 1), or to a direction (unit 0: no translation).  In double where the device has it, rounded
// to float32 once: the move into object space then costs a ray one rounding
// per coordinate.
#ifdef cl_khr_fp64
#define AFFINE_ROW(m, i, p, unit) convert_float((double)(m)[i].x * (p).x + (double)(m)[i].y * (p).y \
                                                + (double)(m)[i].z * (p).z + (unit) * (double)(m)[i].w)
#else
#define AFFINE_ROW(m, i, p, unit) ((m)[i].x * (p).x + (m)[i].y * (p).y + (m)[i].z * (p).z + (unit) * (m)[i].w)
#endif

inline float3 object_point(__global const Instance* in, float3 p)
{
    return (float3)(AFFINE_ROW(in->to_object, 0, p, 1.0f), AFFINE_ROW(in->to_object, 1, p, 1.0f),
                    AFFINE_ROW(in->to_object, 2, p, 1.0f));
}

inline float3 object_vector(__global const Instance* in, float3 d)
{
    return (float3)(AFFINE_ROW(in->to_object, 0, d, 0.0f), AFFINE_ROW(in->to_object, 1, d, 0.0f),
                    AFFINE_ROW(in->to_object, 2, d, 0.0f));
}

// p (object space) where the instance places it: to_world, rounded once.
inline float3 world_point(__global const Instance* in, float3 p)
{
    return (float3)(AFFINE_ROW(in->to_world, 0, p, 1.0f), AFFINE_ROW(in->to_world, 1, p, 1.0f),
                    AFFINE_ROW(in->to_world, 2, p, 1.0f));
}

// A normal n of the mesh as the instance places it, unit: through the
// inverse transpose of to_world (to_object's linear part, transposed), so it
// stays perpendicular to the placed surface under any scale or shear, on the
// same side of it (for a mirror too: the side, not the winding); 0 for 0.
inline float3 world_normal(__global const Instance* in, float3 n)
{
    __global const float4* m = in->to_object;
    const float3 w = n.x * m[0].xyz + n.y * m[1].xyz + n.z * m[2].xyz;
    const float len = length(w);
    return len > 0.0f ? w / len : (float3)(0.0f);
}

inline bool mirrored(__global const Instance* in)
{
    return (in->flags & INSTANCE_MIRROR) != 0u;
}

// The cull mode inside an instance: a mirror turns every triangle's winding
// over in the world, so the face the object-space test calls the front is
// the world's back face.
inline int instance_cull(__global const Instance* in, const int cull)
{
    if (!mirrored(in) || cull == CULL_NONE)
        return cull;
    return cull == CULL_BACK ? CULL_FRONT : CULL_BACK;
}

// The unit world normal of triangle `tri` of instance `in`, as the placed
// triangle is wound: (w1 - w0) x (w2 - w0) for its world corners w = A v + b,
// which is det(A) A^-T ((v1 - v0) x (v2 - v0)), and A^-1 is to_object's
// linear part -- so the object normal through to_object transposed, negated in
// a mirror.  In double where the device has it (as trace.cl's face_normal).
inline float3 instance_normal(__global const Instance* in, __global const TriangleVerts* tri)
{
    __global const float4* m = in->to_object;
#ifdef cl_khr_fp64
    const double3 a = convert_double3(tri->v0.xyz), b = convert_double3(tri->v1.xyz);
    const double3 c = convert_double3(tri->v2.xyz);
    const double3 n = cross(b - a, c - a);
    double3 w = n.x * convert_double3(m[0].xyz) + n.y * convert_double3(m[1].xyz) + n.z * convert_double3(m[2].xyz);
    if (mirrored(in))
        w = -w;
    const double len = sqrt(w.x * w.x + w.y * w.y + w.z * w.z);
    return len > 0.0 ? convert_float3(w / len) : (float3)(0.0f);
#else
    const float3 n = cross(tri->v1.xyz - tri->v0.xyz, tri->v2.xyz - tri->v0.xyz);
    float3 w = n.x * m[0].xyz + n.y * m[1].xyz + n.z * m[2].xyz;
    if (mirrored(in))
        w = -w;
    const float len = length(w);
    return len > 0.0f ? w / len : (float3)(0.0f);
#endif
}

#endif

// The corners of the triangle in `slot` where `instance` places it: in the
// world (the device's frame), as the renderer shades it and samples it as a
// light -- the instance's map of its mesh's corners, each coordinate rounded
// once; in a one-level scene, or for instance -1 (a mesh's own space: the
// signs by normal, point.cl), the corners as they are.
inline void placed_corners(const Geometry* g, int instance, int slot, float3* v0, float3* v1, float3* v2)
{
    __global const TriangleVerts* tri = SPLIT_AT(g, tris, slot);
#ifdef ACCEL_INSTANCES
    if (instance >= 0) {
        __global const Instance* in = SPLIT_AT(g, instances, instance);
        *v0 = world_point(in, tri->v0.xyz);
        *v1 = world_point(in, tri->v1.xyz);
        *v2 = world_point(in, tri->v2.xyz);
        return;
    }
#endif
    *v0 = tri->v0.xyz;
    *v1 = tri->v1.xyz;
    *v2 = tri->v2.xyz;
}

#endif
