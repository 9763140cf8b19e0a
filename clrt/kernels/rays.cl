// Rays as the host hands them to the query kernels: packed float3 arrays (12
// bytes a ray, the caller's own numpy layout, uploaded as they are), any of
// which may be a single row for every ray (stride 0), and the range (tmin,
// tmax] per ray or one for all (stride 0).  The rays are checked and their
// directions normalised here, on the device, so the host makes no pass over
// them: a bad ray is reported by its index, the lowest of each kind, through
// atomic_min on `bad` (one int per kind, BAD_ORIGIN .. BAD_REACH from
// clrt.config.RAY_CHECKS, which the host sets to INT_MAX before the batch).
// BAD_REACH: an origin so far from the scene that the float32 triangle test
// could overflow and lose hits (clrt/device/reach.py): farther than `reach`
// from the far side of the box scene_lo .. scene_hi.
//
// The scene lies on the device in a frame of its own, moved by -shift
// (clrt/scene/arrays.py, device_origin, says why and why nothing changes but
// precision and speed): each origin is moved the same way here, once, before
// anything else reads it.  shift is 0 for scenes near the origin (o - 0 is o,
// bit for bit).
#ifndef CLRT_RAYS_CL
#define CLRT_RAYS_CL

// A launch's rays: the four input arrays and the bad-ray slots, and the
// QueryLaunch (layouts.h) that says how to read them.
typedef struct {
    __global const float* origins;
    __global const float* dirs;
    __global const float* tmins;
    __global const float* tmaxs;
    __global int* bad;
    uint origin_stride, dir_stride, tmin_stride, tmax_stride;   // floats from one ray to the next
    uint in_first;      // element of the input arrays that holds this launch's first ray
    uint ray_first;     // index in the caller's batch of this launch's first ray
    uint normalise;     // 0: the directions are unit vectors already (clrt's own cameras)
    float3 shift;       // the device frame's origin: subtracted from every ray origin
    float3 scene_lo, scene_hi;   // the box of the scene's triangles, device frame
    float reach2;       // the square of the farthest an origin may lie from the box's far side
} RayInput;

#define RAY_INPUT_PARAMS __global const float* origins, __global const float* dirs, \
    __global const float* tmins, __global const float* tmaxs, __global int* bad, const QueryLaunch launch
#define RAY_INPUT_ARGS origins, dirs, tmins, tmaxs, bad, launch

inline RayInput make_ray_input(RAY_INPUT_PARAMS)
{
    RayInput in;
    in.origins = origins;
    in.dirs = dirs;
    in.tmins = tmins;
    in.tmaxs = tmaxs;
    in.bad = bad;
    in.origin_stride = launch.origin_stride;
    in.dir_stride = launch.dir_stride;
    in.tmin_stride = launch.tmin_stride;
    in.tmax_stride = launch.tmax_stride;
    in.in_first = launch.in_first;
    in.ray_first = launch.ray_first;
    in.normalise = launch.normalise;
    in.shift = launch.shift.xyz;
    in.scene_lo = launch.scene_lo.xyz;
    in.scene_hi = launch.scene_hi.xyz;
    in.reach2 = launch.reach2;
    return in;
}

// How far from 1 the square of a float32 unit vector's length may be for
// unit_direction to take it as it is (it says why).
#define UNIT_SQUARE_SLACK 0x1.ffep-25

// load_ray's subnormal components to zeros of their sign, for float3 or
// (load_ray_lanes) float8 values.
#define FLUSH_SUBNORMALS(real_t, x) select((x), copysign((real_t)(0.0f), (x)), isless(fabs(x), (real_t)(FLT_MIN)))

// An origin's distance to the far side of the scene's box, axis by axis
// (float3, or float8 lanes of one axis): the rho of clrt/device/reach.py.
#define FAR_SIDE(lo, hi, x) fmax((hi) - (x), (x) - (lo))

// Does a finite origin lie within reach of the scene (rays.cl's BAD_REACH)?  A
// few flops a ray, once: the host makes no pass over the rays for it.  The
// square is written out with fma so that load_ray_lanes rounds lane by lane
// as this does; it overflows to inf (refused) for origins near the float32
// limit.  Rounding moves the distance by about 1e-7 of itself, far inside
// the bound's own margin (about three, reach.py).
inline bool within_reach(const RayInput* in, float3 o)
{
    const float3 f = FAR_SIDE(in->scene_lo, in->scene_hi, o);
    return fma(f.x, f.x, fma(f.y, f.y, f.z * f.z)) <= in->reach2;
}

// Unit direction of d, normalised in double precision where the device has it
// (as numpy would on the host), so that every device gets the same float32
// direction; false for a zero, infinite or NaN direction.  With `normalise`
// 0, d is taken as it is.
inline bool unit_direction(float3 d, uint normalise, float3* unit)
{
    if (!all(isfinite(d)))
        return false;
    if (!normalise) {
        *unit = d;
        return any(d != 0.0f);
    }
#ifdef cl_khr_fp64
    const double3 dd = convert_double3(d);
    const double square = dd.x * dd.x + dd.y * dd.y + dd.z * dd.z;
    // Where the square is within 2^-24 (1 - 2^-12) of 1, dividing by the
    // length moves each component by less than 2^-25 (1 - 2^-13) of itself,
    // under half of its float32 ulp even with the division's own rounding: the
    // direction would come back unchanged.  So the square root and the
    // division, the longest steps of a ray's set-up on CPUs, are skipped for
    // it -- for 96 % of unit vectors rounded to float32.
    if (fabs(square - 1.0) < UNIT_SQUARE_SLACK) {
        *unit = d;
        return true;
    }
    const double len = sqrt(square);
    if (!(len > 0.0))
        return false;
    *unit = convert_float3(dd / len);
#else
    const float len = length(d);
    if (!(len > 0.0f))
        return false;
    *unit = d / len;
#endif
    return true;
}

// Ray i of the launch: false (and the ray reported in `bad`) when it is not a
// valid ray; then the query answers "no hit" for it and the host raises.
inline bool load_ray(const RayInput* in, uint i, float3* origin, float3* dir, float* tmin, float* tmax)
{
    const size_t k = (size_t)in->in_first + i;
    const int ray = (int)(in->ray_first + i);
    bool ok = true;
    *origin = vload3(0, in->origins + k * in->origin_stride);
    if (!all(isfinite(*origin))) {
        atomic_min(in->bad + BAD_ORIGIN, ray);
        ok = false;
    } else {
        *origin -= in->shift;       // into the device's frame
        if (!within_reach(in, *origin)) {
            atomic_min(in->bad + BAD_REACH, ray);
            ok = false;
        }
    }
    if (!unit_direction(vload3(0, in->dirs + k * in->dir_stride), in->normalise, dir)) {
        atomic_min(in->bad + BAD_DIRECTION, ray);
        ok = false;
    }
    // Subnormal components become zeros (of their sign): on them the watertight
    // test loses nearly all its precision -- a hit's t off by 1e-3 relative was
    // seen, for an origin 2e-43 from a mesh's plane -- while the box tests stay
    // exact, and a BVH then prunes what brute force finds.  Every query reads its
    // rays here, so brute force and every BVH see the same ray.
    *origin = FLUSH_SUBNORMALS(float3, *origin);
    *dir = FLUSH_SUBNORMALS(float3, *dir);
    *tmin = in->tmins[k * in->tmin_stride];
    *tmax = in->tmaxs[k * in->tmax_stride];
    if (isnan(*tmin)) {
        atomic_min(in->bad + BAD_TMIN, ray);
        ok = false;
    }
    if (isnan(*tmax)) {
        atomic_min(in->bad + BAD_TMAX, ray);
        ok = false;
    }
    // An unbounded ray ends at the largest float: a triangle test whose T
    // overflowed gives t = inf, which `t <= tmax` would take as a hit at
    // infinity for any-hit, counts and all hits (the closest hit never takes
    // it); done once per ray here, not per triangle in the walks.
    *tmax = fmin(*tmax, FLT_MAX);
    return ok;
}

// Point i of a point query (point.cl): its position from `origins`, moved
// into the device's frame as load_ray moves an origin, and its largest
// distance from `tmaxs`.  False (and the point reported in `bad`, as an
// origin) when it is not finite; no reach check: a point's distance takes no
// float32 triangle test that could overflow (and the parity sign of signed
// distances casts rays only from points within the scene's box, point.cl).
// Point queries read the origins (the points) and tmaxs (their largest
// distances) of the ray input, and the points' order (point_order.cl).
#define POINT_INPUT_PARAMS __global const float* origins, __global const float* tmaxs, __global int* bad, \
    const QueryLaunch launch, __global const uint* order
#define POINT_INPUT_ARGS origins, tmaxs, bad, launch, order

inline RayInput make_point_input(POINT_INPUT_PARAMS)
{
    return make_ray_input(origins, 0, 0, tmaxs, bad, launch);
}

inline bool load_point(const RayInput* in, uint i, float3* point, float* max_dist)
{
    const size_t k = (size_t)in->in_first + i;
    *point = vload3(0, in->origins + k * in->origin_stride);
    *max_dist = in->tmaxs[k * in->tmax_stride];
    if (!all(isfinite(*point))) {
        atomic_min(in->bad + BAD_ORIGIN, (int)(in->ray_first + i));
        return false;
    }
    *point -= in->shift;
    return true;
}

#ifdef RAY_PACKETS
#if RAY_PACKETS != 8
#error "packets of rays are float8 lanes: build with -DRAY_PACKETS=8"
#endif
// RAY_PACKETS consecutive rays as lanes (float8 k: ray k), for the query
// kernels of CPU devices (trace.cl, accel_packet.cl): load_ray's steps, lane
// by lane, with the same operations, so each lane holds what load_ray gives
// its ray.  False when not all of them are there or valid, or (without
// double precision) the directions need normalising: then each ray goes
// through load_ray, which also reports the bad ones.
typedef struct {
    float8 ox, oy, oz, dx, dy, dz, tmin, tmax;
} RayLanes;

// Ray k of the lanes (the renderer's rays, render.cl).
inline void set_ray_lane(RayLanes* r, int k, float3 origin, float3 dir, float tmin, float tmax)
{
    ((float*)&r->ox)[k] = origin.x;
    ((float*)&r->oy)[k] = origin.y;
    ((float*)&r->oz)[k] = origin.z;
    ((float*)&r->dx)[k] = dir.x;
    ((float*)&r->dy)[k] = dir.y;
    ((float*)&r->dz)[k] = dir.z;
    ((float*)&r->tmin)[k] = tmin;
    ((float*)&r->tmax)[k] = tmax;
}

inline bool load_ray_lanes(const RayInput* in, uint first, uint num_rays, RayLanes* r)
{
    if (first + RAY_PACKETS > num_rays)
        return false;
    float* ox = (float*)&r->ox; float* oy = (float*)&r->oy; float* oz = (float*)&r->oz;
    float* dx = (float*)&r->dx; float* dy = (float*)&r->dy; float* dz = (float*)&r->dz;
    float* tmin = (float*)&r->tmin; float* tmax = (float*)&r->tmax;
    for (int k = 0; k < RAY_PACKETS; ++k) {
        const size_t e = (size_t)in->in_first + first + k;
        __global const float* o = in->origins + e * in->origin_stride;
        __global const float* d = in->dirs + e * in->dir_stride;
        ox[k] = o[0]; oy[k] = o[1]; oz[k] = o[2];
        dx[k] = d[0]; dy[k] = d[1]; dz[k] = d[2];
        tmin[k] = in->tmins[e * in->tmin_stride];
        tmax[k] = in->tmaxs[e * in->tmax_stride];
    }
    const int8 finite = isfinite(r->ox) & isfinite(r->oy) & isfinite(r->oz) &
                        isfinite(r->dx) & isfinite(r->dy) & isfinite(r->dz);
    if (!all(finite) || any(isnan(r->tmin)) || any(isnan(r->tmax)))
        return false;
    r->ox -= in->shift.x;       // into the device's frame, as load_ray
    r->oy -= in->shift.y;
    r->oz -= in->shift.z;
    const float8 fx = FAR_SIDE(in->scene_lo.x, in->scene_hi.x, r->ox);    // within_reach, lane by lane
    const float8 fy = FAR_SIDE(in->scene_lo.y, in->scene_hi.y, r->oy);
    const float8 fz = FAR_SIDE(in->scene_lo.z, in->scene_hi.z, r->oz);
    if (!all(fma(fx, fx, fma(fy, fy, fz * fz)) <= (float8)(in->reach2)))
        return false;
    if (in->normalise) {
#ifdef cl_khr_fp64
        // unit_direction lane by lane: its bound, its double-precision division
        const double8 x = convert_double8(r->dx), y = convert_double8(r->dy), z = convert_double8(r->dz);
        const double8 square = x * x + y * y + z * z;
        const long8 unit = fabs(square - 1.0) < UNIT_SQUARE_SLACK;
        if (!all(unit)) {
            const double8 len = sqrt(square);
            if (!all(len > 0.0))
                return false;
            const int8 keep = convert_int8(unit);
            r->dx = select(convert_float8(x / len), r->dx, keep);
            r->dy = select(convert_float8(y / len), r->dy, keep);
            r->dz = select(convert_float8(z / len), r->dz, keep);
        }
#else
        return false;
#endif
    } else if (any((r->dx == 0.0f) & (r->dy == 0.0f) & (r->dz == 0.0f))) {
        return false;
    }
    r->ox = FLUSH_SUBNORMALS(float8, r->ox);
    r->oy = FLUSH_SUBNORMALS(float8, r->oy);
    r->oz = FLUSH_SUBNORMALS(float8, r->oz);
    r->dx = FLUSH_SUBNORMALS(float8, r->dx);
    r->dy = FLUSH_SUBNORMALS(float8, r->dy);
    r->dz = FLUSH_SUBNORMALS(float8, r->dz);
    r->tmax = fmin(r->tmax, (float8)(FLT_MAX));     // as load_ray: no hit at infinity
    return true;
}
#endif

#endif
