// Whitted-style local shading of one hit: Phong ambient + diffuse + specular
// from every point light, each light blocked or not by one shadow ray.
#ifndef CLRT_SHADING_CL
#define CLRT_SHADING_CL

#include "layouts.h"
#include "split.cl"
#include "geometry.cl"
#include "accel.cl"
#include "texture.cl"

// What shading reads beyond the geometry, gathered once per work-item from the
// kernel's SHADING_PARAMS by make_shading(SHADING_ARGS), as geometry.cl does.
//   tri_info        per slot: vertex indices and material (split like the geometry)
//   vertex_normals  per vertex (split too)
//   materials, lights, num_lights, ambient_light, background
//   ray_epsilon     how far secondary rays start off the surface
// and with -DSURFACE_DETAIL (texture.cl):
//   tri_detail      per slot: corner colours and texture coordinates (split too)
//   textures        the texture table, texels and sRGB decoding table
typedef struct {
    SPLIT_FIELD(TriangleInfo, tri_info);
    SPLIT_FIELD(float4, vertex_normals);
    __global const Material* materials;
    __global const Light* lights;
    uint num_lights;
    float4 ambient_light, background;
    float ray_epsilon;
#ifdef SURFACE_DETAIL
    SPLIT_FIELD(TriangleDetail, tri_detail);
    TextureSet textures;
#endif
} Shading;

#ifdef SURFACE_DETAIL
#define DETAIL_PARAMS , SPLIT_PARAMS(TriangleDetail, tri_detail), TEXTURE_PARAMS
#define DETAIL_ARGS , SPLIT_ARGS(tri_detail), TEXTURE_ARGS
#else
#define DETAIL_PARAMS
#define DETAIL_ARGS
#endif

#define SHADING_PARAMS SPLIT_PARAMS(TriangleInfo, tri_info), SPLIT_PARAMS(float4, vertex_normals), \
    __global const Material* materials, __global const Light* lights, const uint num_lights, \
    const float4 ambient_light, const float4 background, const float ray_epsilon DETAIL_PARAMS
#define SHADING_ARGS SPLIT_ARGS(tri_info), SPLIT_ARGS(vertex_normals), materials, lights, num_lights, \
    ambient_light, background, ray_epsilon DETAIL_ARGS

inline Shading make_shading(SHADING_PARAMS)
{
    Shading sh;
    SPLIT_STORE(sh, tri_info);
    SPLIT_STORE(sh, vertex_normals);
    sh.materials = materials;
    sh.lights = lights;
    sh.num_lights = num_lights;
    sh.ambient_light = ambient_light;
    sh.background = background;
    sh.ray_epsilon = ray_epsilon;
#ifdef SURFACE_DETAIL
    SPLIT_STORE(sh, tri_detail);
    sh.textures = make_texture_set(TEXTURE_ARGS);
#endif
    return sh;
}

// Shading normal: interpolated vertex normals for smooth materials, turned
// to the same side as the geometric normal.
inline float3 shading_normal(const Shading* sh, __global const TriangleInfo* info, const Hit* hit,
                             float3 geometric, uint flags)
{
    if (!(flags & MATERIAL_SMOOTH))
        return geometric;
    const float w0 = 1.0f - hit->u - hit->v;
    const float3 n = w0 * SPLIT_AT(sh, vertex_normals, info->vertex[0])->xyz
                   + hit->u * SPLIT_AT(sh, vertex_normals, info->vertex[1])->xyz
                   + hit->v * SPLIT_AT(sh, vertex_normals, info->vertex[2])->xyz;
    const float len = length(n);
    if (!(len > 0.0f))
        return geometric;
    const float3 s = n / len;
    return dot(s, geometric) < 0.0f ? -s : s;
}

// What shading needs to know about the point a ray hit.
typedef struct {
    float3 p;          // hit point
    float3 ng;         // geometric normal, facing the incoming ray
    float3 n;          // shading normal, on the same side as ng
    bool front;        // the ray hit the side the triangle's winding faces (it is entering)
    Material m;
} SurfacePoint;

inline SurfacePoint surface_point(const Geometry* g, const Shading* sh, float3 origin, float3 dir,
                                  const Hit* hit)
{
    __global const TriangleInfo* info = SPLIT_AT(sh, tri_info, hit->prim);
    __global const TriangleVerts* tri = SPLIT_AT(g, tris, hit->prim);
    SurfacePoint s;
    s.m = sh->materials[info->material];
#ifdef SURFACE_DETAIL
    s.m.color.xyz = surface_albedo(&sh->textures, SPLIT_AT(sh, tri_detail, hit->prim), s.m.color, hit->u, hit->v);
#endif
    const float3 wound = normalize(cross(tri->v1.xyz - tri->v0.xyz, tri->v2.xyz - tri->v0.xyz));
    s.front = dot(wound, dir) < 0.0f;
    s.ng = s.front ? wound : -wound;
    s.n = shading_normal(sh, info, hit, s.ng, s.m.flags);
    s.p = origin + hit->t * dir;
    return s;
}

// The shadow ray from surface point s towards light i: origin (just off the
// surface, on the side the ray came from), unit direction and the light's
// distance; false when the light lies behind the surface, which then blocks it
// itself (no ray needed).
inline bool shadow_ray(const Shading* sh, const SurfacePoint* s, uint i, float3* origin, float3* l, float* dist)
{
    *origin = s->p + sh->ray_epsilon * s->ng;
    const float3 to_light = sh->lights[i].position.xyz - *origin;
    *dist = length(to_light);
    *l = to_light / *dist;
    return dot(s->ng, *l) > 0.0f && dot(s->n, *l) > 0.0f;
}

// Phong ambient + diffuse + specular at a surface point, each light tested by
// a shadow ray -- or, with `shadows_known`, lit where bit i of `lit` is set
// (render.cl's packets of shadow rays found them).  Every surface blocks light
// fully, transparent ones included (no caustics): the same rule in the kernel
// and the reference tracer.
inline float3 local_shading(const Geometry* g, const Shading* sh, const SurfacePoint* s, float3 dir,
                            const bool shadows_known, const uint lit)
{
    const float3 to_eye = -dir;
    float3 color = s->m.ambient * s->m.color.xyz * sh->ambient_light.xyz;
    for (uint i = 0; i < sh->num_lights; ++i) {
        float3 shadow_origin, l;
        float dist;
        if (!shadow_ray(sh, s, i, &shadow_origin, &l, &dist))
            continue;
        if (shadows_known ? !((lit >> i) & 1u) : any_hit(g, shadow_origin, l, 0.0f, dist))
            continue;
        const float n_dot_l = dot(s->n, l);
        const float3 reflected = 2.0f * n_dot_l * s->n - l;
        const float r_dot_v = fmax(dot(reflected, to_eye), 0.0f);
        const float3 light = sh->lights[i].color.xyz;
        color += s->m.diffuse * n_dot_l * s->m.color.xyz * light;
        if (s->m.specular > 0.0f && r_dot_v > 0.0f)
            color += s->m.specular * pow(r_dot_v, s->m.shininess) * light;
    }
    return color;
}

#endif
