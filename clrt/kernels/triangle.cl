// Ray/triangle intersection: the watertight test of Woop, Benthin and Wald
// (JCGT 2013).  Rays are sheared so that they run along +z; the three 2D edge
// functions are then evaluated with the same operands for the two triangles
// that share an edge, so a ray through an edge or a vertex can never slip
// between neighbours -- provided each edge function has the sign of its exact
// value.  A plain a*b - c*d does not guarantee that, least of all when a
// compiler contracts it into an FMA (NVIDIA's does, FP_CONTRACT OFF or not),
// so the edge functions use Kahan's difference of products: within 1.5 ulp,
// exactly zero only when the exact value is, and so always correctly signed.
#ifndef CLRT_TRIANGLE_CL
#define CLRT_TRIANGLE_CL

#include "layouts.h"

#pragma OPENCL FP_CONTRACT OFF

// a*b - c*d with the sign of the exact value (Kahan; see Jeannerod et al.
// 2013): w = c*d rounded, fma(-c, d, w) = w - c*d exactly, fma(a, b, -w) =
// a*b - w rounded once.  One macro for scalars and vectors, so that every
// width takes the same steps.
#define DIFF_OF_PRODUCTS(a, b, c, d) (fma((a), (b), -((c) * (d))) + fma(-(c), (d), (c) * (d)))

inline float diff_of_products(float a, float b, float c, float d)
{
    return DIFF_OF_PRODUCTS(a, b, c, d);
}

// Per-ray constants of the shear transform, computed once per ray.
typedef struct {
    float4 origin;
    uint4 perm;        // (kx, ky, kz, 3): kz = dominant axis of the direction
    float3 shear;      // (Sx, Sy, Sz)
    float end;         // a spawned ray's tmax as it set out (only read when spawned)
    int spawned;       // the ray leaves a surface (shading.cl's spawn_origin): see certain_t_error
} ShearedRay;

// `spawned`: the ray starts on a surface, and takes only hits certainly in
// (0, tmax] (certain_t_error below); other rays take every hit the test finds.
inline ShearedRay shear_ray(float3 origin, float3 dir, const bool spawned, float tmax)
{
    const float3 a = fabs(dir);
    uint kz = (a.x >= a.y) ? ((a.x >= a.z) ? 0u : 2u) : ((a.y >= a.z) ? 1u : 2u);
    uint kx = (kz + 1u) % 3u;
    uint ky = (kx + 1u) % 3u;
    const float d[3] = {dir.x, dir.y, dir.z};
    if (d[kz] < 0.0f) { const uint s = kx; kx = ky; ky = s; }   // keep winding
    ShearedRay s;
    s.origin = (float4)(origin, 0.0f);
    s.perm = (uint4)(kx, ky, kz, 3u);
    s.shear = (float3)(d[kx] / d[kz], d[ky] / d[kz], 1.0f / d[kz]);
    s.end = tmax;
    s.spawned = spawned;
    return s;
}

// Rays that leave a surface.  shading.cl's spawn_origin puts such a ray's
// origin strictly on the side of the surface's plane that the ray leaves, so
// in exact arithmetic it cannot meet its own triangle (nor a coplanar
// neighbour) at t > 0.  The test below is not exact: it measures the triangle
// from the origin, and a triangle L across around the origin carries rounding
// of about u L (u = 2^-24) in its sheared corners and in T, so that from an
// origin 1e-7 above a level ground 2e6 across about a quarter of the rays
// leaving it "hit" it again at t up to 0.1 (tilted by 30 degrees: up to 60).
// Spawned rays therefore take a hit only when its t, less a bound of its
// error, is still > 0 (and, plus the bound, still <= the ray's end: a shadow
// ray is not blocked by a surface that may lie beyond its light).  Small
// triangles away from the origin have small bounds and cost spawned rays
// nothing; what is lost is a large triangle's hits closer to the origin than
// its own precision, where float32 cannot tell in front from behind.
//
// The bound.  Take the shear constants as exact (they define the direction
// the test traces) and compare the corners as computed -- X, Y sheared, Az
// the depth before Sz, Z = Sz Az -- with the exact ones:
//   |dX| <= u (2 max|X| + 3 |Sx| max|Az|), |dY| likewise, |dZ| <= 2u max|Z|
// (the origin subtracted, Sx Az, the difference; Az, Sz Az).  Let b be the
// weights of the ray's point (0, 0) in the computed triangle (exactly: the
// edge functions' signs are exact, so b >= 0), and Z = c + g.(X, Y) the
// exact triangle's plane, c the exact t.  Since sum b (X, Y) = 0 over the
// computed corners, sum b Z over the exact corners is c - g.sum b (dX, dY),
// so the computed corners' sum b Z is within
//   dZ + |gx| dX + |gy| dY
// of c: an error of the corners moves t only as far as the plane's slope
// along it (the plane's X and Y gradients, g = -(nx, ny) / nz for its normal
// n = (B - A) x (C - A)).  T / det computes that sum with weights within 2u
// (Kahan's difference of products) and the rounding of T (3u), det and a
// division of up to 2.5 ulp: within 5u max|Z| + 9u |t|.  |g| is bounded
// from the computed corners: |nx| <= |computed nx| + its error (the edges'
// rounding and dY, dZ; below), |nz| >= |det| - e, with e = 6 (max|X| dY +
// max|Y| dX + dX dY) + 4u |det| (each edge function's error from dX, dY and
// its own rounding); where |det| <= e the plane may lie along the ray and no
// hit is certain.  In all, with 2u |t| for the rounding of t + bound:
//   |t - c| <= 7u max|Z| + 10u |t| + ((|nx| + err nx) dX + (|ny| + err ny) dY) / (|det| - e)
// u is taken as 6.0e-8 (u + 0.7 %), which covers the second-order terms and
// the rounding of the bound's own operations.  FMA contraction (NVIDIA's)
// only removes roundings.  One text for the scalar and the lane tests, so
// that they agree bit for bit; tests/test_spawned_rays.py holds the bound to
// float64 on large, far and grazing triangles.
#define T_ERROR_U 6.0e-8f
#define DEFINE_CERTAIN_T_ERROR(name, real_t)                                                                   \
    inline real_t name(real_t Ax, real_t Ay, real_t Az, real_t Bx, real_t By, real_t Bz, real_t Cx, real_t Cy,  \
                       real_t Cz, real_t Za, real_t Zb, real_t Zc, real_t shear_x, real_t shear_y, real_t det,  \
                       real_t t)                                                                               \
    {                                                                                                          \
        const real_t max_x = fmax(fabs(Ax), fmax(fabs(Bx), fabs(Cx)));                                         \
        const real_t max_y = fmax(fabs(Ay), fmax(fabs(By), fabs(Cy)));                                         \
        const real_t max_az = fmax(fabs(Az), fmax(fabs(Bz), fabs(Cz)));                                        \
        const real_t max_z = fmax(fabs(Za), fmax(fabs(Zb), fabs(Zc)));                                         \
        const real_t dx = T_ERROR_U * (2.0f * max_x + 3.0f * fabs(shear_x) * max_az);                          \
        const real_t dy = T_ERROR_U * (2.0f * max_y + 3.0f * fabs(shear_y) * max_az);                          \
        const real_t dz = 2.0f * T_ERROR_U * max_z;                                                            \
        /* the plane's normal (B - A) x (C - A), its x and y, and their errors */                              \
        const real_t x1 = Bx - Ax, y1 = By - Ay, z1 = Zb - Za, x2 = Cx - Ax, y2 = Cy - Ay, z2 = Zc - Za;       \
        const real_t nx = y1 * z2 - z1 * y2, ny = z1 * x2 - x1 * z2;                                           \
        const real_t sx = fmax(fabs(x1), fabs(x2)), sy = fmax(fabs(y1), fabs(y2)), sz = fmax(fabs(z1), fabs(z2)); \
        const real_t ex = T_ERROR_U * sx + 2.0f * dx, ey = T_ERROR_U * sy + 2.0f * dy;                         \
        const real_t ez = T_ERROR_U * sz + 2.0f * dz;                                                          \
        const real_t err_nx = 4.0f * T_ERROR_U * sy * sz + 2.0f * (sy * ez + sz * ey + ey * ez);               \
        const real_t err_ny = 4.0f * T_ERROR_U * sx * sz + 2.0f * (sx * ez + sz * ex + ex * ez);               \
        const real_t e = 6.0f * (max_x * dy + max_y * dx + dx * dy) + 4.0f * T_ERROR_U * fabs(det);            \
        const real_t room = fabs(det) - e;                                                                     \
        const real_t bound = 7.0f * T_ERROR_U * max_z + 10.0f * T_ERROR_U * fabs(t)                            \
                           + ((fabs(nx) + err_nx) * dx + (fabs(ny) + err_ny) * dy) / room;                     \
        return select((real_t)(INFINITY), bound, room > 0.0f);                                                 \
    }

DEFINE_CERTAIN_T_ERROR(certain_t_error, float)

// Face culling, a choice of each query.  A triangle shows its front face to a
// ray that meets it against its normal (v1 - v0) x (v2 - v0), i.e. that sees
// v0, v1, v2 counter-clockwise; the determinant below is then positive (the
// shear keeps orientation).  The codes come from clrt.config.CULL_MODES as -D
// defines: CULL_NONE double-sided, CULL_BACK ignores triangles seen from
// behind, CULL_FRONT those seen from the front.

// On a hit with tmin < t <= tmax, store t and the barycentric weights of
// vertices 1 and 2.  With CULL_NONE both faces count.
inline bool intersect_triangle_culled(const ShearedRay* r, __global const TriangleVerts* tri,
                                      float tmin, float tmax, const int cull,
                                      float* t_out, float* u_out, float* v_out)
{
    const float4 A = shuffle(tri->v0 - r->origin, r->perm);
    const float4 B = shuffle(tri->v1 - r->origin, r->perm);
    const float4 C = shuffle(tri->v2 - r->origin, r->perm);
    const float Ax = A.x - r->shear.x * A.z, Ay = A.y - r->shear.y * A.z;
    const float Bx = B.x - r->shear.x * B.z, By = B.y - r->shear.y * B.z;
    const float Cx = C.x - r->shear.x * C.z, Cy = C.y - r->shear.y * C.z;

    const float U = diff_of_products(Cx, By, Cy, Bx);
    const float V = diff_of_products(Ax, Cy, Ay, Cx);
    const float W = diff_of_products(Bx, Ay, By, Ax);
    if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f))
        return false;
    const float det = U + V + W;
    if (det == 0.0f)
        return false;
    if ((cull == CULL_BACK && det < 0.0f) || (cull == CULL_FRONT && det > 0.0f))
        return false;
    const float Za = r->shear.z * A.z, Zb = r->shear.z * B.z, Zc = r->shear.z * C.z;
    const float T = U * Za + V * Zb + W * Zc;
    const float t = T / det;
    if (!(t > tmin && t <= tmax))
        return false;
    if (r->spawned) {
        const float error = certain_t_error(Ax, Ay, A.z, Bx, By, B.z, Cx, Cy, C.z, Za, Zb, Zc, r->shear.x,
                                            r->shear.y, det, t);
        if (!(t > error && t + error <= r->end))
            return false;
    }
    *t_out = t;
    *u_out = V / det;
    *v_out = W / det;
    return true;
}

#ifdef BVH_WIDE
// The packet tests of CPU devices (accel_wide.cl, accel_packet.cl); other
// programs never see them.

// intersect_triangle_culled's steps from the sheared corners on, lane by lane
// (FP_CONTRACT is off, the products are Kahan's, so each lane's answer is the
// scalar test's bit for bit; only the early exits become masks), for lanes of
// width real_t / mask_t: four triangles against one ray (intersect_packet_culled)
// or one triangle against eight rays (intersect_lanes_culled).  One text makes
// both, so that neither can drift from the other.  Returns -1 in the lanes of
// `candidate` that hit with tmin < t <= tmax (and, for `spawned` rays, certainly
// before `end`: certain_t_error), with t and the barycentric weights in *t_out,
// *u_out, *v_out (set only when some lane hits).
#define DEFINE_WATERTIGHT_LANES(name, real_t, mask_t, t_error)                                                 \
    __attribute__((always_inline))                                                                             \
    inline mask_t name(mask_t candidate, real_t Ax, real_t Ay, real_t Az, real_t Bx, real_t By, real_t Bz,     \
                       real_t Cx, real_t Cy, real_t Cz, real_t shear_x, real_t shear_y, real_t shear_z,          \
                       real_t tmin, real_t tmax, const int cull, const int spawned, real_t end,                \
                       real_t* t_out, real_t* u_out, real_t* v_out)                                            \
    {                                                                                                          \
        const real_t U = DIFF_OF_PRODUCTS(Cx, By, Cy, Bx);                                                     \
        const real_t V = DIFF_OF_PRODUCTS(Ax, Cy, Ay, Cx);                                                     \
        const real_t W = DIFF_OF_PRODUCTS(Bx, Ay, By, Ax);                                                     \
        mask_t hit = candidate & !(((U < 0.0f) | (V < 0.0f) | (W < 0.0f)) & ((U > 0.0f) | (V > 0.0f) | (W > 0.0f))); \
        if (!any(hit))      /* most of the time: no lane passes the edge test, no division needed */          \
            return hit;                                                                                        \
        const real_t det = U + V + W;                                                                          \
        const real_t Za = shear_z * Az, Zb = shear_z * Bz, Zc = shear_z * Cz;                                  \
        const real_t T = U * Za + V * Zb + W * Zc;                                                             \
        const real_t t = T / det;                                                                              \
        hit &= (det != 0.0f) & (t > tmin) & (t <= tmax);                                                       \
        if (cull == CULL_BACK)                                                                                 \
            hit &= det >= 0.0f;                                                                                \
        else if (cull == CULL_FRONT)                                                                           \
            hit &= det <= 0.0f;                                                                                \
        if (spawned && any(hit)) {                                                                             \
            const real_t error = t_error(Ax, Ay, Az, Bx, By, Bz, Cx, Cy, Cz, Za, Zb, Zc, shear_x, shear_y, det, t); \
            hit &= (t > error) & (t + error <= end);                                                           \
        }                                                                                                      \
        *t_out = t;                                                                                            \
        *u_out = V / det;                                                                                      \
        *v_out = W / det;                                                                                      \
        return hit;                                                                                            \
    }

DEFINE_CERTAIN_T_ERROR(certain_t_error4, float4)
DEFINE_WATERTIGHT_LANES(watertight_lanes4, float4, int4, certain_t_error4)

// The same test for the four triangles of a TrianglePacket (layouts.h) at once,
// lane k for triangle k (empty lanes never hit): the corners sheared as
// above, then watertight_lanes4.  Inlined into the walk (accel_wide.cl says why).
__attribute__((always_inline))
inline int4 intersect_packet_culled(const ShearedRay* r, __global const TrianglePacket* p,
                                    float tmin, float tmax, const int cull,
                                    float4* t_out, float4* u_out, float4* v_out)
{
    // shuffle(v - origin, perm) lane by lane: the packet holds one float4 per axis
    const uint kx = r->perm.x, ky = r->perm.y, kz = r->perm.z;
    const float4 o = shuffle(r->origin, r->perm);
    const float4 Az = p->v0[kz] - o.z, Bz = p->v1[kz] - o.z, Cz = p->v2[kz] - o.z;
    const float4 Ax = (p->v0[kx] - o.x) - r->shear.x * Az, Ay = (p->v0[ky] - o.y) - r->shear.y * Az;
    const float4 Bx = (p->v1[kx] - o.x) - r->shear.x * Bz, By = (p->v1[ky] - o.y) - r->shear.y * Bz;
    const float4 Cx = (p->v2[kx] - o.x) - r->shear.x * Cz, Cy = (p->v2[ky] - o.y) - r->shear.y * Cz;
    return watertight_lanes4(p->slot >= 0, Ax, Ay, Az, Bx, By, Bz, Cx, Cy, Cz, (float4)(r->shear.x),
                             (float4)(r->shear.y), (float4)(r->shear.z), (float4)(tmin), (float4)(tmax), cull,
                             r->spawned, (float4)(r->end), t_out, u_out, v_out);
}

#ifdef RAY_PACKETS
// shear_ray for eight rays at once, lane k for ray k (the same operations,
// so the same values as each ray's own): the query kernels of CPU devices
// set up eight rays a work-item this way (trace.cl, accel_packet.cl).
typedef struct {
    int8 kx, ky, kz;
    float8 shear_x, shear_y, shear_z;
} ShearRayLanes;

// Lane by lane: x where axis is 0, y where 1, z where 2.
inline float8 per_lane_axis(float8 x, float8 y, float8 z, int8 axis)
{
    return select(select(z, y, axis == (int8)(1)), x, axis == (int8)(0));
}

inline ShearRayLanes shear_ray_lanes(float8 dx, float8 dy, float8 dz)
{
    ShearRayLanes s;
    const float8 ax = fabs(dx), ay = fabs(dy), az = fabs(dz);
    s.kz = select(select((int8)(2), (int8)(1), ay >= az), select((int8)(2), (int8)(0), ax >= az), ax >= ay);
    const int8 kx = select(s.kz + 1, (int8)(0), s.kz == (int8)(2));
    const int8 ky = select(kx + 1, (int8)(0), kx == (int8)(2));
    const float8 d_kz = per_lane_axis(dx, dy, dz, s.kz);
    const int8 negative = d_kz < 0.0f;              // keep winding: swap kx and ky
    s.kx = select(kx, ky, negative);
    s.ky = select(ky, kx, negative);
    s.shear_x = per_lane_axis(dx, dy, dz, s.kx) / d_kz;
    s.shear_y = per_lane_axis(dx, dy, dz, s.ky) / d_kz;
    s.shear_z = (float8)(1.0f) / d_kz;
    return s;
}

// ShearRayLanes stored as arrays, a row per field, from which each ray's
// ShearedRay is read by plain loads (sheared_ray_lane).  Taking lane k of the
// float8 values themselves, k known only at run time, made PoCL copy every
// vector to the stack again for each ray: 1M random rays 2-4 % slower, rays
// that miss the scene 6-9 % (docs/benchmark-log.md, session 30).
typedef struct {
    int axis[3][RAY_PACKETS];       // kx, ky, kz
    float shear[3][RAY_PACKETS];
} ShearRayTable;

inline void shear_ray_table(const ShearRayLanes* s, ShearRayTable* t)
{
    vstore8(s->kx, 0, t->axis[0]);
    vstore8(s->ky, 0, t->axis[1]);
    vstore8(s->kz, 0, t->axis[2]);
    vstore8(s->shear_x, 0, t->shear[0]);
    vstore8(s->shear_y, 0, t->shear[1]);
    vstore8(s->shear_z, 0, t->shear[2]);
}

// Ray k of `t` as shear_ray(origin, dir, false, tmax) would give it.
inline ShearedRay sheared_ray_lane(const ShearRayTable* t, float3 origin, int k)
{
    ShearedRay r;
    r.origin = (float4)(origin, 0.0f);
    r.perm = (uint4)((uint)t->axis[0][k], (uint)t->axis[1][k], (uint)t->axis[2][k], 3u);
    r.shear = (float3)(t->shear[0][k], t->shear[1][k], t->shear[2][k]);
    r.end = INFINITY;
    r.spawned = 0;
    return r;
}

// The other way round, for the packet walk (accel_packet.cl): one triangle
// against eight rays, lane k for ray k.  The rays share shear_ray's axis
// order (kx, ky, kz), so one triangle's corners serve all lanes.
typedef struct {
    float8 origin_x, origin_y, origin_z;   // the origins' (kx, ky, kz) components
    float8 shear_x, shear_y, shear_z;      // ShearedRay.shear
    float8 end;                            // ShearedRay.end
    int kx, ky, kz;
    int spawned;                           // ShearedRay.spawned, for all eight
} PacketShear;

inline float8 axis_lanes(float8 x, float8 y, float8 z, int axis)
{
    return axis == 0 ? x : axis == 1 ? y : z;
}

DEFINE_CERTAIN_T_ERROR(certain_t_error8, float8)
DEFINE_WATERTIGHT_LANES(watertight_lanes8, float8, int8, certain_t_error8)

// The lanes of `r` as one PacketShear (not spawned); false unless they share
// one axis order (the same dominant axis, and its sign).
inline bool packet_shear(const ShearRayLanes* r, float8 ox, float8 oy, float8 oz, PacketShear* s)
{
    const int kx = r->kx.s0, ky = r->ky.s0, kz = r->kz.s0;
    if (!all((r->kx == (int8)(kx)) & (r->ky == (int8)(ky)) & (r->kz == (int8)(kz))))
        return false;
    s->kx = kx;
    s->ky = ky;
    s->kz = kz;
    s->origin_x = axis_lanes(ox, oy, oz, kx);
    s->origin_y = axis_lanes(ox, oy, oz, ky);
    s->origin_z = axis_lanes(ox, oy, oz, kz);
    s->shear_x = r->shear_x;
    s->shear_y = r->shear_y;
    s->shear_z = r->shear_z;
    s->end = (float8)(INFINITY);
    s->spawned = 0;
    return true;
}

// intersect_triangle_culled for triangle k of a TrianglePacket against the
// eight rays of `s`, lane k for ray k: the corners sheared as there, then
// watertight_lanes8.
__attribute__((always_inline))
inline int8 intersect_lanes_culled(const PacketShear* s, __global const TrianglePacket* p, int k, float8 tmin,
                                   float8 tmax, const int cull, float8* t_out, float8* u_out, float8* v_out)
{
    __global const float* v0 = (__global const float*)p->v0;    // corner 0 of triangle k on axis a: v0[4 a + k]
    __global const float* v1 = (__global const float*)p->v1;
    __global const float* v2 = (__global const float*)p->v2;
    const float8 Az = (float8)(v0[4 * s->kz + k]) - s->origin_z;
    const float8 Bz = (float8)(v1[4 * s->kz + k]) - s->origin_z;
    const float8 Cz = (float8)(v2[4 * s->kz + k]) - s->origin_z;
    const float8 Ax = ((float8)(v0[4 * s->kx + k]) - s->origin_x) - s->shear_x * Az;
    const float8 Ay = ((float8)(v0[4 * s->ky + k]) - s->origin_y) - s->shear_y * Az;
    const float8 Bx = ((float8)(v1[4 * s->kx + k]) - s->origin_x) - s->shear_x * Bz;
    const float8 By = ((float8)(v1[4 * s->ky + k]) - s->origin_y) - s->shear_y * Bz;
    const float8 Cx = ((float8)(v2[4 * s->kx + k]) - s->origin_x) - s->shear_x * Cz;
    const float8 Cy = ((float8)(v2[4 * s->ky + k]) - s->origin_y) - s->shear_y * Cz;
    return watertight_lanes8((int8)(-1), Ax, Ay, Az, Bx, By, Bz, Cx, Cy, Cz, s->shear_x, s->shear_y, s->shear_z,
                             tmin, tmax, cull, s->spawned, s->end, t_out, u_out, v_out);
}
#endif
#endif

#endif
