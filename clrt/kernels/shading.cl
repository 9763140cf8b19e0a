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
// kernel's SHADING_PARAMS and the scene's SceneInfo (GEOMETRY_PARAMS) by
// make_shading(SHADING_ARGS, scene), as geometry.cl does.
//   tri_info        per slot: vertex indices and material (split like the geometry)
//   vertex_normals  per vertex (split too)
//   tables          the scene's small tables in one buffer, at the byte offsets
//                   of SceneInfo: materials, lights (and with textures the
//                   Texture rows and the sRGB decoding table)
// and with -DSURFACE_DETAIL (texture.cl):
//   tri_detail      per slot: corner colours and texture coordinates (split too)
//   texels          every texture's texels (split too)
typedef struct {
    SPLIT_FIELD(TriangleInfo, tri_info);
    SPLIT_FIELD(float4, vertex_normals);
    __global const Material* materials;
    __global const Light* lights;
    uint num_lights;
    float4 ambient_light, background;
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
    __global const uchar* tables DETAIL_PARAMS
#define SHADING_ARGS SPLIT_ARGS(tri_info), SPLIT_ARGS(vertex_normals), tables DETAIL_ARGS

inline Shading make_shading(SHADING_PARAMS, const SceneInfo scene)
{
    Shading sh;
    SPLIT_STORE(sh, tri_info);
    SPLIT_STORE(sh, vertex_normals);
    sh.materials = (__global const Material*)(tables + scene.materials_at);
    sh.lights = (__global const Light*)(tables + scene.lights_at);
    sh.num_lights = scene.num_lights;
    sh.ambient_light = scene.ambient_light;
    sh.background = scene.background;
#ifdef SURFACE_DETAIL
    SPLIT_STORE(sh, tri_detail);
    sh.textures = make_texture_set(tables, scene, TEXTURE_ARGS);
#endif
    return sh;
}

// The materials-table row of the triangle in `slot` as `instance` places it:
// in a two-level scene a triangle's TriangleInfo.material counts from its
// instance's object's first material (Instance.material: materials per
// placement, one mesh); else it is the row itself.
inline uint triangle_material(const Geometry* g, const Shading* sh, int instance, int slot)
{
    const int material = SPLIT_AT(sh, tri_info, slot)->material;
#ifdef ACCEL_INSTANCES
    return (uint)(material + SPLIT_AT(g, instances, instance)->material);
#else
    return (uint)material;
#endif
}

// Vertex `vertex`'s normal as `instance` places it (instances.cl's
// world_normal: each vertex's own normal turned into the world and made unit
// before they are blended, as the flattened scene's are); in a one-level
// scene the stored normal itself.
inline float3 vertex_normal(const Geometry* g, const Shading* sh, int instance, int vertex)
{
    const float3 n = SPLIT_AT(sh, vertex_normals, vertex)->xyz;
#ifdef ACCEL_INSTANCES
    return world_normal(SPLIT_AT(g, instances, instance), n);
#else
    return n;
#endif
}

// Shading normal: interpolated vertex normals for smooth materials, turned
// to the same side as the geometric normal.
inline float3 shading_normal(const Geometry* g, const Shading* sh, int instance, __global const TriangleInfo* info,
                             const Hit* hit, float3 geometric, uint flags)
{
    if (!(flags & MATERIAL_SMOOTH))
        return geometric;
    const float w0 = 1.0f - hit->u - hit->v;
    const float3 n = w0 * vertex_normal(g, sh, instance, info->vertex[0])
                   + hit->u * vertex_normal(g, sh, instance, info->vertex[1])
                   + hit->v * vertex_normal(g, sh, instance, info->vertex[2]);
    const float len = length(n);
    if (!(len > 0.0f))
        return geometric;
    const float3 s = n / len;
    return dot(s, geometric) < 0.0f ? -s : s;
}

// What shading needs to know about the point a ray hit.
typedef struct {
    float3 p;          // hit point, from the triangle's corners (surface_point)
    float3 ng;         // geometric normal, facing the incoming ray
    float3 n;          // shading normal, on the same side as ng
    float offset;      // how far along ng rays leaving p start (spawn_origin)
    bool front;        // the ray hit the side the triangle's winding faces (it is entering)
    uint material;     // the row of m in the materials table
    int instance;      // the hit's instance (0 in a one-level scene): where its triangle is placed
    Material m;
} SurfacePoint;

// Rays that leave a surface (shadow, reflection, refraction) start off it by
// the float32 error of the hit point, no farther: in the spirit of PBRT-v3
// (Pharr, Jakob, Humphreys, section 3.9).  The point is taken from the
// triangle's corners, p = w0 v0 + u v1 + v v2 with w0 = 1 - u - v, not from
// origin + t dir, whose error grows with t.  With u = 2^-24, per component:
//   |p - P| <= 3u (|w0 v0| + |u v1| + |v v2|) + 2u |v0|
// where P = (1 - u - v) v0 + u v1 + v v2 exactly, a point of the triangle's
// plane (the sums and products round three times at most; w0 itself is
// within 2u of 1 - u - v, which moves p by 2u |v0| off the plane).  So p lies
// within dot(|n|, error) of the plane along its exact unit normal n.  The
// float32 normal ng is off n by at most a = 10u |e1| |e2| / |e1 x e2| + 16u
// (the edges' and the cross product's rounding, and normalize's), and
//   offset = (dot(|ng|, error) + 3a (error.x + error.y + error.z)) / (1 - 2a)
// moved along ng, with each component rounded away from the surface
// (spawn_origin), puts the origin strictly on the side of the exact plane that
// the ray leaves.  That is all the origin can promise; triangle.cl's
// certain_t_error makes the triangle test keep the rest of the promise
// (shear_ray says why it must).  u is taken as 6.0e-8 (u + 0.7 %) to cover
// the rounding of these few operations; a is capped at 0.25 (a sliver whose
// normal is that uncertain is not really a triangle).
//
// In a two-level scene the point is taken from the triangle's corners placed
// in the world (instances.cl's placed_corners), so it shades as the flattened
// scene's triangle does, but the ray leaving it is traced against the mesh's
// own corners after a move into the instance's object space -- and the placed
// corners, the move and the float32 maps both ways each round by a few ulps
// of the coordinates, times the map's condition number.  The offset grows by
// a bound of that (instance_spawn_error) to keep its promise.
#define OFFSET_U 6.0e-8f

#ifdef ACCEL_INSTANCES
// A bound, in the world, of how far the rounding of instance `in` moves a
// ray's origin off the placed triangle's plane through the mesh's own (corners
// w placed, point p): 24 u cond^2 (|w|max + |p| + |translation|), max norms,
// cond = |A| |A^-1| of the maps' linear parts (each step's rounding is a few
// u of its operands, which the maps scale by up to cond; sqrt 3 from the
// max norm to the distance along the normal).
inline float instance_spawn_error(__global const Instance* in, float3 w0, float3 w1, float3 w2, float3 p)
{
    __global const float4* a = in->to_world;
    __global const float4* b = in->to_object;
    float norm_a = 0.0f, norm_b = 0.0f, shift = 0.0f;
    for (int i = 0; i < 3; ++i) {
        norm_a = fmax(norm_a, fabs(a[i].x) + fabs(a[i].y) + fabs(a[i].z));
        norm_b = fmax(norm_b, fabs(b[i].x) + fabs(b[i].y) + fabs(b[i].z));
        shift = fmax(shift, fabs(a[i].w));
    }
    const float3 w = fmax(fabs(w0), fmax(fabs(w1), fabs(w2)));
    const float3 q = fabs(p);
    const float cond = norm_a * norm_b;
    return 24.0f * OFFSET_U * cond * cond * (fmax(w.x, fmax(w.y, w.z)) + fmax(q.x, fmax(q.y, q.z)) + shift);
}
#endif

// `instance`: the hit's (closest_instance_hit; 0 in a one-level scene).
inline SurfacePoint surface_point(const Geometry* g, const Shading* sh, float3 dir, const Hit* hit,
                                  const int instance)
{
    __global const TriangleInfo* info = SPLIT_AT(sh, tri_info, hit->prim);
    SurfacePoint s;
    s.instance = instance;
    s.material = triangle_material(g, sh, instance, hit->prim);
    s.m = sh->materials[s.material];
#ifdef SURFACE_DETAIL
    s.m.color.xyz = surface_albedo(&sh->textures, SPLIT_AT(sh, tri_detail, hit->prim), s.m.color, hit->u, hit->v);
#endif
    float3 v0, v1, v2;
    placed_corners(g, instance, hit->prim, &v0, &v1, &v2);
    const float3 e1 = v1 - v0, e2 = v2 - v0;
    const float3 c = cross(e1, e2);
    const float3 wound = normalize(c);
    s.front = dot(wound, dir) < 0.0f;
    s.ng = s.front ? wound : -wound;
    s.n = shading_normal(g, sh, instance, info, hit, s.ng, s.m.flags);
    const float w0 = 1.0f - hit->u - hit->v;
    s.p = w0 * v0 + hit->u * v1 + hit->v * v2;
    const float3 error = 3.0f * OFFSET_U * (fabs(w0 * v0) + fabs(hit->u * v1) + fabs(hit->v * v2))
                       + 2.0f * OFFSET_U * fabs(v0);
    const float a = fmin(10.0f * OFFSET_U * (length(e1) * length(e2) / length(c)) + 16.0f * OFFSET_U, 0.25f);
    s.offset = (dot(fabs(s.ng), error) + 3.0f * a * (error.x + error.y + error.z)) / (1.0f - 2.0f * a);
#ifdef ACCEL_INSTANCES
    s.offset += instance_spawn_error(SPLIT_AT(g, instances, instance), v0, v1, v2, s.p) * (1.0f + 3.0f * a)
              / (1.0f - 2.0f * a);
#endif
    return s;
}

// The origin of a ray that leaves surface point s in direction w: s->offset
// off the surface on w's side of it, each component rounded away from the
// surface (so that the rounding of the sum takes back none of the offset).
// Shadow, reflection and refraction rays all start here, and are traced as
// spawned rays (accel.cl).
inline float3 spawn_origin(const SurfacePoint* s, float3 w)
{
    const float3 away = dot(w, s->ng) < 0.0f ? -s->ng : s->ng;
    const float3 o = s->p + s->offset * away;
    return select(o, nextafter(o, copysign((float3)(INFINITY), away)), isnotequal(away, (float3)(0.0f)));
}

// The shadow ray from surface point s towards light i: origin (spawn_origin),
// unit direction and the light's distance; false when the light lies behind
// the surface, which then blocks it itself (no ray needed).  The ray ends at
// the light: a point, on no surface, so nothing is held back from that end
// but what the spawned ray's test cannot place before the light for certain
// (triangle.cl's certain_t_error): a surface through the light itself does
// not shadow it.
inline bool shadow_ray(const Shading* sh, const SurfacePoint* s, uint i, float3* origin, float3* l, float* dist)
{
    const float3 light = sh->lights[i].position.xyz;
    *origin = spawn_origin(s, light - s->p);
    const float3 to_light = light - *origin;
    *dist = length(to_light);
    *l = to_light / *dist;
    return dot(s->ng, *l) > 0.0f && dot(s->n, *l) > 0.0f;
}

// A spot light's intensity towards unit direction w (from the light), as a
// share of its colour: 1 within the beam, 0 outside the cone, smoothstep of
// the cosine between (pbrt-v4's spot light falloff).  Whitted's Phong model
// and the path tracer (lights.cl) use it alike.
inline float spot_falloff(__global const Light* light, float3 w)
{
    const float c = dot(light->direction.xyz, w);
    const float width = light->cos_inner - light->cos_outer;
    if (!(width > 0.0f))   // beam == cutoff: a hard edge
        return c >= light->cos_outer ? 1.0f : 0.0f;
    const float t = clamp((c - light->cos_outer) / width, 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
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
        if (shadows_known ? !((lit >> i) & 1u) : any_hit(g, shadow_origin, l, 0.0f, dist, true))
            continue;
        const float n_dot_l = dot(s->n, l);
        const float3 reflected = 2.0f * n_dot_l * s->n - l;
        const float r_dot_v = fmax(dot(reflected, to_eye), 0.0f);
        float3 light = sh->lights[i].color.xyz;
        if (sh->lights[i].cos_outer > -1.0f)   // a spot light (point lights skip this: bit for bit as before)
            light *= spot_falloff(&sh->lights[i], -l);
        color += s->m.diffuse * n_dot_l * s->m.color.xyz * light;
        if (s->m.specular > 0.0f && r_dot_v > 0.0f)
            color += s->m.specular * pow(r_dot_v, s->m.shininess) * light;
    }
    return color;
}

#endif
