// Ray tests against one bounding volume (and, point_bound, a lower bound of
// a point's distance to it, for point.cl), the shape fixed when the program is
// built: -DVOLUME_BOX (slab test), -DVOLUME_SPHERE or -DVOLUME_ELLIPSE
// (quadratic in t, solved through the closest approach to the centre, which
// loses far less precision than the textbook discriminant).  Each test is
// conservative: a ray that reaches a triangle inside the volume within
// [tmin, tmax] always passes, grazing rays included, so a BVH can never lose a
// hit that brute force finds.  The builders pad every volume outwards; the
// tests add a few ulps of slack for their own rounding.  *t_enter is a lower
// bound of where the ray enters, so that "t_enter <= tmax" is conservative too.
// The volume comes as the xyz lanes of a BvhPairNode's *_a and *_b (layouts.py;
// their w lanes are child references): box min / max, sphere centre / radius
// in x, ellipsoid centre / reciprocal semi-axes.
#ifndef CLRT_VOLUMES_CL
#define CLRT_VOLUMES_CL

#include "layouts.h"

typedef struct {
    float3 origin;
    float3 dir;
    float3 inv_dir;    // +-INFINITY for zero components: the slab test relies on IEEE rules
#if defined(VOLUME_BOX)
    // The slab test of an oblique ray (see volume_ray): a box plane b is met
    // at no sooner than fma(b, inv_dir, lo_shift) if it is a min plane, and no
    // later than fma(b, inv_dir, hi_shift) if a max plane -- for a ray with
    // positive inv_dir; the other way round where it is negative.
    float3 lo_shift, hi_shift;
#endif
    bool oblique;      // box volumes, every inv_dir and shift finite: those bounds hold
} VolumeRay;

// Relative slack for rounding in the tests below (a few float32 ulps), and a
// distance (float or a vector of them) moved by it, outwards by its own
// magnitude: later, or earlier.
#define VOLUME_SLACK 1e-6f
#define SLACK_LATER(t) ((t) + VOLUME_SLACK * fabs(t))
#define SLACK_EARLIER(t) ((t) - VOLUME_SLACK * fabs(t))

// A bound on |coordinate| of every box plane in the tree, axis by axis (for
// volume_ray; other volumes ignore it), from its root row: three times the
// largest of the root's boxes.  Every node's box holds its triangles, padded
// outwards by a sliver of its size (clrt/accel/volumes.py), so none reaches
// far past the root's boxes; the factor three leaves room for any padding and
// for a root near the origin.  Both walks read it from the binary root row,
// so that their box tests stay the same, lane by lane (accel_wide.cl).
inline float3 tree_reach(__global const BvhPairNode* root)
{
    float3 reach = (float3)(0.0f);
#if defined(VOLUME_BOX)
    if (PAIR_LEFT(*root).y >= 0)
        reach = fmax(fabs(root->left_a.xyz), fabs(root->left_b.xyz));
    if (PAIR_RIGHT(*root).y >= 0)
        reach = fmax(reach, fmax(fabs(root->right_a.xyz), fabs(root->right_b.xyz)));
#endif
    return 3.0f * reach;
}

// The ray as every volume test below takes it.  `reach` bounds |coordinate|
// of every box plane in the tree, axis by axis (box volumes only; see below).
// The tests take the ray's `oblique` as an argument, which each walk holds
// constant (accel_bvh.cl says why); only the box test uses it.
// The shifts of volume_ray below, for rays in float3 or (volume_ray_lanes)
// in float8 lanes: one text, so that both take the same steps.
#define VOLUME_SHIFTS(real_t, mask_t, origin, inv_dir, reach, lo_shift, hi_shift)                \
    do {                                                                                         \
        const real_t scaled_ = (origin) * (inv_dir);                                             \
        const real_t margin_ = 0x1p-20f * ((reach) + fabs(origin)) * fabs(inv_dir);            \
        const real_t lower_ = -(scaled_ + margin_), upper_ = -(scaled_ - margin_);              \
        const mask_t ascending_ = (inv_dir) >= 0.0f;     /* min planes are met first */          \
        (lo_shift) = select(upper_, lower_, ascending_);                                         \
        (hi_shift) = select(lower_, upper_, ascending_);                                         \
    } while (0)

inline VolumeRay volume_ray(float3 origin, float3 dir, float3 reach)
{
    VolumeRay r;
    r.origin = origin;
    r.dir = dir;
    r.inv_dir = (float3)(1.0f) / dir;
#if defined(VOLUME_BOX)
    // The exact distance to plane b is (b - o) / d.  Computed as one FMA,
    // b * inv - o * inv, it carries three roundings -- of inv, of o * inv and
    // of the result -- each within u = 2^-24 of a value no larger than
    // (|b| + |o|) * |inv| <= (reach + |o|) * |inv|; with the shift's own
    // rounding, 4 u of it (inv correctly rounded, -cl-fp32-correctly-rounded-
    // divide-sqrt; 2.5 ulp without it, 8 u in all).  Widening every plane by
    // 2^-20 times that bound (16 u) makes each distance a true bound, so the
    // test needs no per-box slack: 6 FMAs where (b - o) * inv with slack takes 18.
    VOLUME_SHIFTS(float3, int3, origin, r.inv_dir, reach, r.lo_shift, r.hi_shift);
    r.oblique = all(isfinite(r.lo_shift)) && all(isfinite(r.hi_shift));
#else
    r.oblique = false;
#endif
    return r;
}

// The length of v for the point walks' lower bounds (point_bound), within
// some 3 ulps: through rsqrt (2 ulps), not sqrt, which the programs' option
// -cl-fp32-correctly-rounded-divide-sqrt (clrt.device.program) rounds exactly
// at several times the cost -- a fifth of the H200's closest-point walk
// (docs/benchmark-log.md).  point.cl's POINT_MARGIN (2^-16 of the largest
// coordinate: at least some 2^-18 of any distance a walk compares) covers
// the difference many times over.  Squares that would overflow or underflow
// take length()'s careful path.
inline float bound_length(float3 v)
{
    const float d2 = dot(v, v);
    return d2 > 0x1p-100f && d2 < 0x1p100f ? d2 * rsqrt(d2) : length(v);
}

#if defined(VOLUME_BOX)
// Slab test (Kay & Kajiya).  fmin/fmax drop the NaN of 0 * inf, which only
// arises for a ray lying exactly in a padded face plane -- outside all content.
// The exit distance is widened as in Ize's "Robust BVH ray traversal".  The
// slack moves each bound outwards by its magnitude: a negative tmin finds hits
// behind the origin, where scaling by (1 + VOLUME_SLACK) would move them inwards.
inline bool volume_hit(const VolumeRay* r, float4 bound_a, float4 bound_b, float tmin, float tmax,
                       float* t_enter, const bool oblique)
{
    if (oblique) {
        // Bounds (see VolumeRay), never NaN: each slab's fmin is its entry, fmax
        // its exit.  tmin and tmax are widened by the slack as below (a
        // triangle's computed t may lie a little outside the exact box); tmin
        // never changes in a walk, so its widening is hoisted out of the loop.
        const float3 t0 = fma(bound_a.xyz, r->inv_dir, r->lo_shift);
        const float3 t1 = fma(bound_b.xyz, r->inv_dir, r->hi_shift);
        const float3 lo = fmin(t0, t1), hi = fmax(t0, t1);
        const float enter = fmax(fmax(lo.x, lo.y), fmax(lo.z, SLACK_EARLIER(tmin)));
        *t_enter = enter;
        return enter <= fmin(fmin(hi.x, hi.y), fmin(hi.z, SLACK_LATER(tmax)));
    }
    const float3 t0 = (bound_a.xyz - r->origin) * r->inv_dir;
    const float3 t1 = (bound_b.xyz - r->origin) * r->inv_dir;
    const float3 lo = fmin(t0, t1), hi = fmax(t0, t1);
    const float enter = fmax(fmax(lo.x, lo.y), fmax(lo.z, tmin));
    const float far = fmin(fmin(hi.x, hi.y), fmin(hi.z, SLACK_LATER(tmax)));
    const float exit = SLACK_LATER(far);
    *t_enter = SLACK_EARLIER(enter);   // a lower bound: callers compare it with tmax
    return enter <= exit;
}

// A lower bound of the distance from point p to the box (point.cl's walk):
// the length of p's overshoot of the slabs, 0 inside.  Rounded either way by
// a few ulps; point.cl's POINT_MARGIN covers that.
inline float point_bound(float3 p, float4 bound_a, float4 bound_b)
{
    return bound_length(fmax(fmax(bound_a.xyz - p, p - bound_b.xyz), (float3)(0.0f)));
}

#ifdef BVH_WIDE
// The same slab test for the eight children of a BvhWideNode at once (CPU
// devices, accel_wide.cl; other programs never see it), lane k for child k: every lane takes exactly the
// steps above, so each child passes or fails as in its binary row, and
// t_enter is the same bound.  Returns -1 in the lanes whose box the ray meets.
inline int8 box_hit_wide(const VolumeRay* r, __global const BvhWideNode* n, float tmin, float tmax,
                         float8* t_enter)
{
    const float8 t0x = (n->lo_x - r->origin.x) * r->inv_dir.x, t1x = (n->hi_x - r->origin.x) * r->inv_dir.x;
    const float8 t0y = (n->lo_y - r->origin.y) * r->inv_dir.y, t1y = (n->hi_y - r->origin.y) * r->inv_dir.y;
    const float8 t0z = (n->lo_z - r->origin.z) * r->inv_dir.z, t1z = (n->hi_z - r->origin.z) * r->inv_dir.z;
    const float8 enter = fmax(fmax(fmin(t0x, t1x), fmin(t0y, t1y)), fmax(fmin(t0z, t1z), (float8)(tmin)));
    const float8 far = fmin(fmin(fmax(t0x, t1x), fmax(t0y, t1y)),
                            fmin(fmax(t0z, t1z), (float8)(SLACK_LATER(tmax))));
    const float8 exit = SLACK_LATER(far);
    *t_enter = SLACK_EARLIER(enter);
    return enter <= exit;
}

// Which planes of a BvhWideNode a ray enters and leaves by, per axis: indices
// into its six float8 planes (lo_x, lo_y, lo_z, hi_x, hi_y, hi_z), with the
// shifts of their bounds (VolumeRay) -- for box_hit_wide_oblique, which only
// an oblique ray takes.
typedef struct {
    int near_x, near_y, near_z;
    float3 near_shift, far_shift;
} BoxPlanes;

inline BoxPlanes box_planes(const VolumeRay* r)
{
    BoxPlanes p;
    p.near_x = r->inv_dir.x >= 0.0f ? 0 : 3;
    p.near_y = r->inv_dir.y >= 0.0f ? 1 : 4;
    p.near_z = r->inv_dir.z >= 0.0f ? 2 : 5;
    // The near plane's shift is the earlier of the two whichever way the ray
    // runs (volume_ray: the shifts differ by twice the margin, never negative).
    p.near_shift = fmin(r->lo_shift, r->hi_shift);
    p.far_shift = fmax(r->lo_shift, r->hi_shift);
    return p;
}

// max / min without NaN handling, for values known not to be NaN (OpenCL's
// max and min leave infinities undefined).
inline float8 max8(float8 a, float8 b) { return select(a, b, b > a); }
inline float8 min8(float8 a, float8 b) { return select(a, b, b < a); }

// box_hit_wide for an oblique ray, in half its operations: the oblique test of
// volume_hit lane by lane, each plane's distance one FMA and already a bound
// (VolumeRay), so no per-box slack and no NaN.  Only the near and far planes
// are computed, picked once per ray, where volume_hit takes fmin and fmax of
// both: the same values, since each bound lies on its side of the exact one.
inline int8 box_hit_wide_oblique(const VolumeRay* r, BoxPlanes planes, __global const BvhWideNode* n,
                                 float tmin, float tmax, float8* t_enter)
{
    __global const float8* plane = &n->lo_x;
    const float8 near_x = fma(plane[planes.near_x], (float8)(r->inv_dir.x), (float8)(planes.near_shift.x));
    const float8 near_y = fma(plane[planes.near_y], (float8)(r->inv_dir.y), (float8)(planes.near_shift.y));
    const float8 near_z = fma(plane[planes.near_z], (float8)(r->inv_dir.z), (float8)(planes.near_shift.z));
    const float8 far_x = fma(plane[3 - planes.near_x], (float8)(r->inv_dir.x), (float8)(planes.far_shift.x));
    const float8 far_y = fma(plane[5 - planes.near_y], (float8)(r->inv_dir.y), (float8)(planes.far_shift.y));
    const float8 far_z = fma(plane[7 - planes.near_z], (float8)(r->inv_dir.z), (float8)(planes.far_shift.z));
    const float8 enter = max8(max8(near_x, near_y), max8(near_z, (float8)(SLACK_EARLIER(tmin))));
    const float8 far = min8(min8(far_x, far_y), min8(far_z, (float8)(SLACK_LATER(tmax))));
    *t_enter = enter;
    return enter <= far;
}

#ifdef RAY_PACKETS
// volume_ray for eight rays at once, lane k for ray k (the same operations,
// so the same values as each ray's own): the query kernels of CPU devices
// set up eight rays a work-item this way (trace.cl, accel_packet.cl).
typedef struct {
    float8 inv_x, inv_y, inv_z;
    float8 lo_x, lo_y, lo_z, hi_x, hi_y, hi_z;     // VolumeRay's lo_shift, hi_shift
} VolumeRayLanes;

inline VolumeRayLanes volume_ray_lanes(float8 ox, float8 oy, float8 oz, float8 dx, float8 dy, float8 dz,
                                       float3 reach)
{
    VolumeRayLanes v;
    v.inv_x = (float8)(1.0f) / dx;
    v.inv_y = (float8)(1.0f) / dy;
    v.inv_z = (float8)(1.0f) / dz;
    VOLUME_SHIFTS(float8, int8, ox, v.inv_x, (float8)(reach.x), v.lo_x, v.hi_x);
    VOLUME_SHIFTS(float8, int8, oy, v.inv_y, (float8)(reach.y), v.lo_y, v.hi_y);
    VOLUME_SHIFTS(float8, int8, oz, v.inv_z, (float8)(reach.z), v.lo_z, v.hi_z);
    return v;
}

// VolumeRayLanes stored as arrays, a row per axis, for plain loads of ray k
// (volume_ray_lane; triangle.cl's ShearRayTable says why).
typedef struct {
    float inv[3][RAY_PACKETS], lo[3][RAY_PACKETS], hi[3][RAY_PACKETS];
} VolumeRayTable;

inline void volume_ray_table(const VolumeRayLanes* v, VolumeRayTable* t)
{
    vstore8(v->inv_x, 0, t->inv[0]);
    vstore8(v->inv_y, 0, t->inv[1]);
    vstore8(v->inv_z, 0, t->inv[2]);
    vstore8(v->lo_x, 0, t->lo[0]);
    vstore8(v->lo_y, 0, t->lo[1]);
    vstore8(v->lo_z, 0, t->lo[2]);
    vstore8(v->hi_x, 0, t->hi[0]);
    vstore8(v->hi_y, 0, t->hi[1]);
    vstore8(v->hi_z, 0, t->hi[2]);
}

// Ray k of `t` as volume_ray(origin, dir, reach) would give it.
inline VolumeRay volume_ray_lane(const VolumeRayTable* t, float3 origin, float3 dir, int k)
{
    VolumeRay r;
    r.origin = origin;
    r.dir = dir;
    r.inv_dir = (float3)(t->inv[0][k], t->inv[1][k], t->inv[2][k]);
    r.lo_shift = (float3)(t->lo[0][k], t->lo[1][k], t->lo[2][k]);
    r.hi_shift = (float3)(t->hi[0][k], t->hi[1][k], t->hi[2][k]);
    r.oblique = all(isfinite(r.lo_shift)) && all(isfinite(r.hi_shift));
    return r;
}

// Eight oblique rays of one octant, for the packet walk (accel_packet.cl):
// lane k holds what box_planes gives ray k.  The octant makes the choice of
// near and far planes the same for every lane.
typedef struct {
    float8 inv_x, inv_y, inv_z;
    float8 near_x, near_y, near_z, far_x, far_y, far_z;   // the shifts of BoxPlanes
    int near_plane_x, near_plane_y, near_plane_z;          // BoxPlanes' near_x, near_y, near_z
} PacketPlanes;

// box_planes lane by lane; false unless every lane is oblique.
inline bool packet_planes(const VolumeRayLanes* r, PacketPlanes* v)
{
    if (!all(isfinite(r->lo_x) & isfinite(r->lo_y) & isfinite(r->lo_z) &
             isfinite(r->hi_x) & isfinite(r->hi_y) & isfinite(r->hi_z)))
        return false;
    v->inv_x = r->inv_x;
    v->inv_y = r->inv_y;
    v->inv_z = r->inv_z;
    v->near_x = fmin(r->lo_x, r->hi_x);
    v->near_y = fmin(r->lo_y, r->hi_y);
    v->near_z = fmin(r->lo_z, r->hi_z);
    v->far_x = fmax(r->lo_x, r->hi_x);
    v->far_y = fmax(r->lo_y, r->hi_y);
    v->far_z = fmax(r->lo_z, r->hi_z);
    v->near_plane_x = r->inv_x.s0 >= 0.0f ? 0 : 3;
    v->near_plane_y = r->inv_y.s0 >= 0.0f ? 1 : 4;
    v->near_plane_z = r->inv_z.s0 >= 0.0f ? 2 : 5;
    return true;
}

// box_hit_wide_oblique's test of child c of a BvhWideNode, lane k for ray k.
inline int8 box_hit_lanes(const PacketPlanes* v, __global const BvhWideNode* n, int c, float8 tmin, float8 tmax,
                          float8* t_enter)
{
    __global const float* plane = (__global const float*)&n->lo_x;     // plane j of child c: plane[8 j + c]
    const float8 near_x = fma((float8)(plane[8 * v->near_plane_x + c]), v->inv_x, v->near_x);
    const float8 near_y = fma((float8)(plane[8 * v->near_plane_y + c]), v->inv_y, v->near_y);
    const float8 near_z = fma((float8)(plane[8 * v->near_plane_z + c]), v->inv_z, v->near_z);
    const float8 far_x = fma((float8)(plane[8 * (3 - v->near_plane_x) + c]), v->inv_x, v->far_x);
    const float8 far_y = fma((float8)(plane[8 * (5 - v->near_plane_y) + c]), v->inv_y, v->far_y);
    const float8 far_z = fma((float8)(plane[8 * (7 - v->near_plane_z) + c]), v->inv_z, v->far_z);
    const float8 enter = max8(max8(near_x, near_y), max8(near_z, SLACK_EARLIER(tmin)));
    const float8 far = min8(min8(far_x, far_y), min8(far_z, SLACK_LATER(tmax)));
    *t_enter = enter;
    return enter <= far;
}
#endif
#endif
#elif defined(VOLUME_SPHERE)
#ifdef ACCEL_INSTANCES
// A two-level scene's rays inside an instance have directions of any length
// (instances.cl): the test below in units of t, the closest approach and the
// half chord divided by the direction's square length a (1 in the world,
// within rounding), the slack by its length.
inline bool volume_hit(const VolumeRay* r, float4 bound_a, float4 bound_b, float tmin, float tmax,
                       float* t_enter, const bool oblique)
{
    const float3 oc = bound_a.xyz - r->origin;
    const float radius = bound_b.x;
    const float a = dot(r->dir, r->dir);
    const float along = dot(oc, r->dir) / a;             // t of the closest approach
    const float3 perp = oc - along * r->dir;
    const float slack = VOLUME_SLACK * (length(oc) + radius);
    const float reach = radius + slack;
    const float h2 = reach * reach - dot(perp, perp);
    if (h2 < 0.0f)
        return false;
    const float h = sqrt(h2 / a);
    const float slack_t = slack / sqrt(a) + VOLUME_SLACK * (fabs(along) + h);
    const float enter = along - h - slack_t, exit = along + h + slack_t;
    *t_enter = fmax(enter, tmin);
    return exit >= tmin && enter <= tmax;
}
#else
inline bool volume_hit(const VolumeRay* r, float4 bound_a, float4 bound_b, float tmin, float tmax,
                       float* t_enter, const bool oblique)
{
    const float3 oc = bound_a.xyz - r->origin;
    const float radius = bound_b.x;       // BvhPairNode: the w lanes hold child references
    const float along = dot(oc, r->dir);                 // distance to the closest approach
    const float3 perp = oc - along * r->dir;
    const float slack = VOLUME_SLACK * (length(oc) + radius);
    const float reach = radius + slack;
    const float h2 = reach * reach - dot(perp, perp);
    if (h2 < 0.0f)
        return false;
    const float h = sqrt(h2);
    const float enter = along - h - slack, exit = along + h + slack;
    *t_enter = fmax(enter, tmin);
    return exit >= tmin && enter <= tmax;
}
#endif
// A lower bound of the distance from point p to the sphere (point.cl's walk).
inline float point_bound(float3 p, float4 bound_a, float4 bound_b)
{
    return fmax(bound_length(p - bound_a.xyz) - bound_b.x, 0.0f);
}
#elif defined(VOLUME_ELLIPSE)
// Axis-aligned ellipsoid: scale space so it becomes the unit sphere; the ray
// direction then has length^2 = a, and t is unchanged by the scaling.
inline bool volume_hit(const VolumeRay* r, float4 bound_a, float4 bound_b, float tmin, float tmax,
                       float* t_enter, const bool oblique)
{
    const float3 inv_axes = bound_b.xyz;
    const float3 o = (r->origin - bound_a.xyz) * inv_axes;
    const float3 d = r->dir * inv_axes;
    const float a = dot(d, d);
    const float along = -dot(o, d) / a;                  // t of the closest approach
    const float3 perp = o + along * d;
    const float reach = 1.0f + VOLUME_SLACK * (1.0f + length(o));
    const float h2 = reach * reach - dot(perp, perp);
    if (h2 < 0.0f)
        return false;
    const float h = sqrt(h2 / a);
    const float slack = VOLUME_SLACK * (fabs(along) + h);
    const float enter = along - h - slack, exit = along + h + slack;
    *t_enter = fmax(enter, tmin);
    return exit >= tmin && enter <= tmax;
}
// A lower bound of the distance from point p to the ellipsoid (point.cl's
// walk): the distance to its axis-aligned box, centre +- the semi-axes, which
// holds it (the nearest point of the ellipsoid lies no nearer than its box).
inline float point_bound(float3 p, float4 bound_a, float4 bound_b)
{
    const float3 root = rsqrt(bound_b.xyz);   // 1 / bound_b within some 5 ulps (bound_length), no overflow
    const float3 axes = root * root;
    return bound_length(fmax(fmax(bound_a.xyz - axes - p, p - bound_a.xyz - axes), (float3)(0.0f)));
}
#elif defined(ACCEL_BVH)
#error "build with -DVOLUME_BOX, -DVOLUME_SPHERE or -DVOLUME_ELLIPSE"
#endif

#endif
