// Entry file of the ray-query program (clrt/query/): batches of rays from
// the host, one work-item per ray (query_closest and query_any: per packet of
// eight rays on CPU devices, see answer_rays), answered by the same walks as
// the renderer's closest_hit / any_hit.  The host cuts a batch into chunks, one
// launch each; rays come in through rays.cl, results go straight into the
// caller's arrays, field by field.
//
// Every query takes `cull` (CULL_NONE, CULL_BACK or CULL_FRONT, triangle.cl),
// handed to the leaf action through a HitSink (hit.cl).
//
// Oblique rays walk the binary BVH with the FMA box test here (accel_bvh.cl
// says why only here).
#define OBLIQUE_WALK
#include "layouts.h"
#include "camera.cl"
#include "geometry.cl"
#include "accel.cl"
#include "rays.cl"
#include "accel_packet.cl"
#include "point.cl"
#include "point_group.cl"
#include "point_order.cl"
#include "point_grid.cl"
#include "winding.cl"
#include "instances.cl"

// A sink that stores nothing: the query's options only.
inline HitSink query_options(const int cull)
{
    HitSink s;
    s.ray_ids = 0;
    s.prims = 0;
    s.ts = 0;
    s.instances = 0;
    s.next = 0;
    s.capacity = 0u;
    s.ray = 0;
    s.count = 0u;
    s.cull = cull;
    return s;
}

// Does the ray see the front face of triangle `tri`?  Asked only of a
// triangle it hit: the same arithmetic as the hit test, so culling and this
// flag always agree.
inline bool sees_front(const ShearedRay* r, __global const TriangleVerts* tri)
{
    float t, u, v;
    return intersect_triangle_culled(r, tri, -INFINITY, INFINITY, CULL_BACK, &t, &u, &v);
}

// Unit geometric normal (v1 - v0) x (v2 - v0) of a triangle, computed in
// double precision where the device has it (as the host's Mesh.face_normals);
// zero for a triangle of no area.
inline float3 face_normal(__global const TriangleVerts* tri)
{
#ifdef cl_khr_fp64
    const double3 a = convert_double3(tri->v0.xyz), b = convert_double3(tri->v1.xyz);
    const double3 c = convert_double3(tri->v2.xyz);
    const double3 n = cross(b - a, c - a);
    const double len = sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
    return len > 0.0 ? convert_float3(n / len) : (float3)(0.0f);
#else
    const float3 n = cross(tri->v1.xyz - tri->v0.xyz, tri->v2.xyz - tri->v0.xyz);
    const float len = length(n);
    return len > 0.0f ? n / len : (float3)(0.0f);
#endif
}

// Rays a work-item answers in query_closest and query_any: a packet of
// RAY_PACKETS (eight) on CPU devices that walk them (accel_packet.cl), else one.
#ifdef RAY_PACKETS
#define ITEM_RAYS RAY_PACKETS
#else
#define ITEM_RAYS 1
#endif

// Answer `query` for the rays first .. first + ITEM_RAYS - 1 (those below
// num_rays): hits[k] (Hit.prim a slot; a miss for a bad ray) and its instance
// (instances[k], -1 for a miss), with each ray's origin and unit direction as
// loaded.  Eight rays that make a packet walk together (one-level scenes
// only); any others one by one.
inline void answer_rays(const Geometry* g, const RayInput* in, uint first, uint num_rays, const int query,
                        const int cull, Hit* hits, int* instances, float3* origins, float3* dirs)
{
#ifdef RAY_PACKETS
    RayLanes lanes;
    if (load_ray_lanes(in, first, num_rays, &lanes)) {
        // every ray set up in lanes (the divisions eight at a time), whichever walk it takes
        const ShearRayLanes shear = shear_ray_lanes(lanes.dx, lanes.dy, lanes.dz);
        const VolumeRayLanes volume = volume_ray_lanes(lanes.ox, lanes.oy, lanes.oz, lanes.dx, lanes.dy, lanes.dz,
                                                       tree_reach(SPLIT_AT(g, nodes, 0)));
        for (int k = 0; k < RAY_PACKETS; ++k) {
            origins[k] = (float3)(lanes.ox[k], lanes.oy[k], lanes.oz[k]);
            dirs[k] = (float3)(lanes.dx[k], lanes.dy[k], lanes.dz[k]);
        }
        RayPacket packet;
        if (make_ray_packet(&lanes, &shear, &volume, &packet)) {
            answer_ray_packet(g, &packet, lanes.tmax, query, cull, hits);
        } else {
            ShearRayTable shears;
            VolumeRayTable volumes;
            float tmin[RAY_PACKETS], tmax[RAY_PACKETS];
            shear_ray_table(&shear, &shears);
            volume_ray_table(&volume, &volumes);
            vstore8(lanes.tmin, 0, tmin);
            vstore8(lanes.tmax, 0, tmax);
            for (int k = 0; k < RAY_PACKETS; ++k) {
                const ShearedRay r = sheared_ray_lane(&shears, origins[k], k);
                const VolumeRay vr = volume_ray_lane(&volumes, origins[k], dirs[k], k);
                HitSink options = query_options(cull);
                hits[k] = walk_ray(g, &r, &vr, tmin[k], tmax[k], query, &options);
            }
        }
        for (int k = 0; k < RAY_PACKETS; ++k)
            instances[k] = hits[k].prim >= 0 ? 0 : -1;
        return;
    }
#endif
    // one by one: the last rays of a launch, and eight with a bad ray among them
    for (int k = 0; k < ITEM_RAYS; ++k) {
        hits[k] = miss_hit();
        instances[k] = -1;
        float tmin, tmax;
        if (first + k < num_rays && load_ray(in, first + k, &origins[k], &dirs[k], &tmin, &tmax)) {
            HitSink options = query_options(cull);
            hits[k] = query_instance_hits(g, origins[k], dirs[k], tmin, tmax, query, false, &options, &instances[k]);
        }
    }
}

// Output k of a launch: a pointer into `results` at launch.field_at[k], or 0
// when the caller did not ask for it (NO_RESULT).
#define RESULT_AT(type, k) (launch.field_at[k] == NO_RESULT ? (__global type*)0 \
                            : (__global type*)(results + launch.field_at[k]))

// Closest hit of each ray, written field by field into `results` (outputs
// 0 .. 7: t, instance, prim, u, v, normal, front, hit, as clrt.query.results'
// CLOSEST_FIELDS; any may be absent).  Index: the ray's in the launch; a miss
// writes t = INFINITY, instance = prim = -1, u = v = 0, normal = 0, front =
// hit = 0.  In a two-level scene the normal and the face are the placed
// triangle's, in the world (instances.cl).
__kernel void query_closest(RAY_INPUT_PARAMS, __global uchar* results, GEOMETRY_PARAMS)
{
    const uint num_rays = launch.num_rays;
    const uint first = ITEM_RAYS * get_global_id(0);
    if (first >= num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_ray_input(RAY_INPUT_ARGS);
    Hit hits[ITEM_RAYS];
    int hit_instances[ITEM_RAYS];
    float3 ray_origins[ITEM_RAYS], ray_dirs[ITEM_RAYS];
    answer_rays(&g, &in, first, num_rays, QUERY_CLOSEST, launch.cull, hits, hit_instances, ray_origins, ray_dirs);
    // The outputs only now: made before the walk, their pointers took seven
    // registers through it (6 % of random rays' time on the H200).
    __global float* t_out = RESULT_AT(float, 0);
    __global int* instance_out = RESULT_AT(int, 1);
    __global int* prim_out = RESULT_AT(int, 2);
    __global float* u_out = RESULT_AT(float, 3);
    __global float* v_out = RESULT_AT(float, 4);
    __global float* normal_out = RESULT_AT(float, 5);
    __global uchar* front_out = RESULT_AT(uchar, 6);
    __global uchar* hit_out = RESULT_AT(uchar, 7);
    for (int j = 0; j < ITEM_RAYS && first + j < num_rays; ++j) {
        Hit hit = hits[j];
        const size_t k = (size_t)first + j;
        const bool found = hit.prim >= 0;
        if (normal_out || front_out) {
            float3 n = (float3)(0.0f);
            uchar f = 0;
            if (found) {
                __global const TriangleVerts* tri = SPLIT_AT(&g, tris, hit.prim);
#ifdef ACCEL_INSTANCES
                __global const Instance* placed = SPLIT_AT(&g, instances, hit_instances[j]);
                const ShearedRay r = shear_ray(object_point(placed, ray_origins[j]),
                                               object_vector(placed, ray_dirs[j]), false, INFINITY);
                f = sees_front(&r, tri) != mirrored(placed) ? 1 : 0;
                n = instance_normal(placed, tri);
#else
                const ShearedRay r = shear_ray(ray_origins[j], ray_dirs[j], false, INFINITY);
                f = sees_front(&r, tri) ? 1 : 0;
                n = face_normal(tri);
#endif
            }
            if (normal_out)
                vstore3(n, k, normal_out);
            if (front_out)
                front_out[k] = f;
        }
        hit = reported_hit(&g, hit);
        if (t_out)
            t_out[k] = hit.t;
        if (instance_out)
            instance_out[k] = hit_instances[j];
        if (prim_out)
            prim_out[k] = hit.prim;
        if (u_out)
            u_out[k] = hit.u;
        if (v_out)
            v_out[k] = hit.v;
        if (hit_out)
            hit_out[k] = found ? 1 : 0;
    }
}

// Is anything hit?  Stops at the first hit found.  Output 0: a byte a ray.
__kernel void query_any(RAY_INPUT_PARAMS, __global uchar* results, GEOMETRY_PARAMS)
{
    const uint num_rays = launch.num_rays;
    const uint first = ITEM_RAYS * get_global_id(0);
    if (first >= num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_ray_input(RAY_INPUT_ARGS);
    Hit hits[ITEM_RAYS];
    int hit_instances[ITEM_RAYS];
    float3 ray_origins[ITEM_RAYS], ray_dirs[ITEM_RAYS];
    answer_rays(&g, &in, first, num_rays, QUERY_ANY, launch.cull, hits, hit_instances, ray_origins, ray_dirs);
    __global uchar* occluded = RESULT_AT(uchar, 0);
    for (int j = 0; j < ITEM_RAYS && first + j < num_rays; ++j)
        occluded[(size_t)first + j] = hits[j].prim >= 0 ? 1 : 0;
}

// Number of triangles each ray meets in (tmin, tmax].  Output 0: an int a ray.
__kernel void query_count(RAY_INPUT_PARAMS, __global uchar* results, GEOMETRY_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= launch.num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_ray_input(RAY_INPUT_ARGS);
    float3 origin, dir;
    float tmin, tmax;
    HitSink sink = query_options(launch.cull);
    if (load_ray(&in, i, &origin, &dir, &tmin, &tmax))
        query_hits(&g, origin, dir, tmin, tmax, QUERY_ALL, false, &sink);
    RESULT_AT(int, 0)[i] = (int)sink.count;
}

// Every hit of every ray in one traversal, appended in no particular order to
// outputs 0 .. 2 (ray ids, prims, ts) and 4 (instances, where asked for) at
// the counter, output 3; ray ids relative to the launch's first ray.  The counter ends as the number of hits
// of the whole launch, also when that exceeds launch.capacity (then the host
// runs the chunk again with room for all of them).
__kernel void query_all(RAY_INPUT_PARAMS, __global uchar* results, GEOMETRY_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= launch.num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_ray_input(RAY_INPUT_ARGS);
    float3 origin, dir;
    float tmin, tmax;
    if (!load_ray(&in, i, &origin, &dir, &tmin, &tmax))
        return;
    HitSink sink = query_options(launch.cull);
    sink.ray_ids = RESULT_AT(int, 0);
    sink.prims = RESULT_AT(int, 1);
    sink.ts = RESULT_AT(float, 2);
    sink.next = RESULT_AT(uint, 3);
    sink.instances = RESULT_AT(int, 4);
    sink.capacity = launch.capacity;
    sink.ray = (int)i;
    query_hits(&g, origin, dir, tmin, tmax, QUERY_ALL, false, &sink);
}

// Points a work-item's loop takes: its `count`, but where the warp walks
// together (WARP_WALKS) one more turn with none (count 0: the work-items
// past the last point), walking with the others.
#define ITEM_POINTS(count) (WARP_WALKS ? max((count), 1u) : (count))

// The points of a work-item of query_closest_point or signed_distances: from
// the launch's `first` in the order of point_order.cl (of `num` points),
// ITEM_RAYS of them (or those left), their indices into `ids` and positions into `positions`, all
// read before any is answered (rays.cl's point_position says why: on PoCL the
// read of each point waited a cache miss, a fifth of the time on 1M random
// points).  Returns how many.
inline uint read_item_points(const RayInput* in, __global const uint* order, uint num, uint first, uint* ids,
                             float3* positions)
{
    const uint count = first < num ? min((uint)ITEM_RAYS, num - first) : 0u;
    for (uint k = 0; k < count; ++k) {
        ids[k] = POINT_ORDER(order, num)[first + k];
        positions[k] = point_position(in, ids[k]);
    }
    return count;
}

// Points a work-item of query_closest_point and the signed distances answers
// (CLOSEST_ITEM_POINTS): ITEM_RAYS, or with -DPOINT_GROUPS (CPU devices,
// clrt/query/points.py) POINT_GROUPS groups of POINT_LANES that walk together
// (point_group.cl's walk_wide_point_group), one group after the other.
#ifdef POINT_GROUPS
#define CLOSEST_ITEM_POINTS (POINT_GROUPS * POINT_LANES)
#else
#define CLOSEST_ITEM_POINTS ITEM_RAYS
#endif

#ifdef POINT_GROUPS
// Group `group` of the work-item whose points start at `first`: the points'
// indices (ids) and positions (device frame), and their nearest triangles
// within their largest distances (`limited`; else any) into best, as
// closest_point gives them; *good: the lanes of good points (the bad ones
// are reported).  `seeds`: the slots of the nearest triangles of the group
// before (-1: none), then of this one.  Returns how many points (0: none).
inline uint closest_points_of_group(const Geometry* g, const RayInput* in, __global const uint* order, uint num,
                                    uint first, bool limited, int* seeds, uint* ids, float3* points,
                                    PointHit* best, uint* good)
{
    if (first >= num)
        return 0u;
    float3 positions[POINT_LANES];
    float margin[POINT_LANES];
    const uint count = min((uint)POINT_LANES, num - first);
    for (uint k = 0; k < count; ++k) {
        ids[k] = POINT_ORDER(order, num)[first + k];
        positions[k] = point_position(in, ids[k]);
    }
    *good = 0u;
    for (uint k = 0; k < count; ++k) {
        float max_dist;
        best[k].prim = -1;
        best[k].dist = INFINITY;
        best[k].point = (point_real3)(0);
        best[k].u = best[k].v = 0.0f;
        best[k].slot = -1;
        best[k].feature = FEATURE_FACE;
        best[k].instance = 0;
        if (take_point(in, ids[k], positions[k], points + k, &max_dist)) {
            *good |= 1u << k;
            if (limited)
                best[k].dist = max_dist;
            margin[k] = POINT_MARGIN(points[k], in->scene_lo, in->scene_hi);
        }
    }
    if (*good)
        walk_wide_point_group(g, points, margin, *good, seeds, best);
    for (uint k = 0; k < POINT_LANES; ++k)
        seeds[k] = k < count && best[k].prim >= 0 ? best[k].slot : -1;
    return count;
}
#endif

// The nearest point of the mesh to each query point (point.cl), within the
// point's largest distance (tmaxs: a miss beyond it), written field by field
// into `results` (outputs 0 .. 5: point, distance, prim, u, v, instance, as
// clrt.query.results' POINT_FIELDS; any may be absent).  The point goes back
// to the caller's frame here (+ shift, in double where the device has it,
// rounded to float32 once).  A miss (or a bad point): point NaN, distance
// INFINITY, prim -1, u = v = 0.
typedef struct {
    __global float* point;
    __global float* distance;
    __global int* prim;
    __global float* u;
    __global float* v;
    __global int* instance;
} ClosestPointOutputs;

// A point's answer as the outputs take it, in 32 bytes: (point, distance)
// and (prim, u, v, instance) as bits.
typedef struct {
    float4 point_distance;
    int4 prim_u_v_instance;
} ClosestPointRecord;

inline ClosestPointRecord closest_point_record(const PointHit* best, float3 shift)
{
    const bool found = best->prim >= 0;
    ClosestPointRecord r;
    r.point_distance = (float4)(found ? convert_float3(best->point + TO_POINT_REAL3(shift)) : (float3)(NAN),
                                found ? (float)best->dist : INFINITY);
    r.prim_u_v_instance = (int4)(best->prim, as_int(found ? best->u : 0.0f), as_int(found ? best->v : 0.0f),
                                 found ? best->instance : -1);
    return r;
}

// Point i's answer `r` into the outputs that are there.
inline void write_closest_record(const ClosestPointOutputs* out, uint i, ClosestPointRecord r)
{
    if (out->point)
        vstore3(r.point_distance.xyz, i, out->point);
    if (out->distance)
        out->distance[i] = r.point_distance.w;
    if (out->prim)
        out->prim[i] = r.prim_u_v_instance.x;
    if (out->u)
        out->u[i] = as_float(r.prim_u_v_instance.y);
    if (out->v)
        out->v[i] = as_float(r.prim_u_v_instance.z);
    if (out->instance)
        out->instance[i] = r.prim_u_v_instance.w;
}

inline ClosestPointOutputs closest_point_outputs(const QueryLaunch* launch_, __global uchar* results)
{
    const QueryLaunch launch = *launch_;
    ClosestPointOutputs out;
    out.point = RESULT_AT(float, 0);
    out.distance = RESULT_AT(float, 1);
    out.prim = RESULT_AT(int, 2);
    out.u = RESULT_AT(float, 3);
    out.v = RESULT_AT(float, 4);
    out.instance = RESULT_AT(int, 5);
    return out;
}

// Point i's answer `best` into the outputs that are there -- or, where the
// caller gives `records` (CPU devices, several outputs asked), into record i
// there, which closest_point_fields then spreads into the outputs in the
// points' own order: a point's answer written at its index, which the cell
// order scatters over each output, cost a cache line in every output (on
// PoCL 25 of homer's 200 ms against 2 for the records: docs/benchmark-log.md).
inline void write_closest_point(const ClosestPointOutputs* out, __global ClosestPointRecord* records, uint i,
                                const PointHit* best, float3 shift)
{
    const ClosestPointRecord r = closest_point_record(best, shift);
    if (records)
        records[i] = r;
    else
        write_closest_record(out, i, r);
}

// A work-item answers CLOSEST_ITEM_POINTS points, consecutive in the order of
// point_order.cl: ITEM_RAYS in turn, each walk starting from its cell's seed
// (point_order.cl's POINT_CELL_SEEDS); or POINT_GROUPS groups of POINT_LANES
// (closest_points_of_group), each starting from the group before.
__kernel void query_closest_point(POINT_INPUT_PARAMS, __global uchar* results,
                                  __global ClosestPointRecord* records, GEOMETRY_PARAMS)
{
    const uint first = CLOSEST_ITEM_POINTS * get_global_id(0);
    if (first >= launch.num_rays && !WARP_WALKS)   // (else it walks with its warp: closest_point_item)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_point_input(POINT_INPUT_ARGS);
    const ClosestPointOutputs out = closest_point_outputs(&launch, results);
#ifdef POINT_GROUPS
    uint ids[POINT_LANES];
    int seeds[POINT_LANES];
    for (uint k = 0; k < POINT_LANES; ++k)
        seeds[k] = -1;
    for (uint group = 0; group < POINT_GROUPS; ++group) {
        float3 points[POINT_LANES];
        PointHit best[POINT_LANES];
        uint good;
        const uint count = closest_points_of_group(&g, &in, order, launch.num_rays, first + POINT_LANES * group, true,
                                                   seeds, ids, points, best, &good);
        for (uint k = 0; k < count; ++k)
            write_closest_point(&out, records, ids[k], best + k, in.shift);
    }
#else
    uint ids[ITEM_RAYS];
    float3 positions[ITEM_RAYS];
    const uint count = read_item_points(&in, order, launch.num_rays, first, ids, positions);
    for (uint k = 0; k < ITEM_POINTS(count); ++k) {
        const uint i = k < count ? ids[k] : 0u;
        float3 p = in.scene_lo;
        float max_dist = 0.0f;
        const bool taken = k < count && take_point(&in, i, positions[k], &p, &max_dist);
        const PointHit best = closest_point_item(&g, p, taken, max_dist, POINT_MARGIN(p, in.scene_lo, in.scene_hi),
                                                 POINT_CELL_SEEDS(order)[point_cell(p, in.scene_lo, in.scene_hi)]);
        if (k >= count)
            break;
        write_closest_point(&out, 0, i, &best, in.shift);   // (records: CPU devices' point groups only)
    }
#endif
}

// query_closest_point's records (where it wrote them) into the outputs asked
// for, a work-item a point in the points' own order.
__kernel void closest_point_fields(__global const ClosestPointRecord* records, QueryLaunch launch,
                                   __global uchar* results)
{
    const uint i = get_global_id(0);
    if (i >= launch.num_rays)
        return;
    const ClosestPointOutputs out = closest_point_outputs(&launch, results);
    write_closest_record(&out, i, records[i]);
}

// The closest-point walks' seeds (point_order.cl's POINT_CELL_SEEDS): for
// each cell of its grid over the launch's scene box, the slot of the
// triangle nearest to the cell's centre, or -1.  A work-item a cell, in
// Morton order, so that a warp's centres lie together.
__kernel void point_cell_seeds(__global int* seeds, const QueryLaunch launch, GEOMETRY_PARAMS)
{
    const uint cell = get_global_id(0);
    if (cell >= POINT_CELLS && !WARP_WALKS)   // (else it walks with its warp: closest_point_item)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const float3 lo = launch.scene_lo.xyz, hi = launch.scene_hi.xyz;
    const bool taken = cell < POINT_CELLS;
    const float3 c = taken ? cell_centre(cell, lo, hi) : lo;
    const PointHit best = closest_point_item(&g, c, taken, INFINITY, POINT_MARGIN(c, lo, hi), -1);
    if (taken)
        seeds[cell] = best.prim >= 0 ? best.slot : -1;
}

// ---- Inside and outside (winding.cl, point.cl's sign rules).  Points as
// query_closest_point takes them (their largest distances unused), in the
// order of point_order.cl; each point's answer goes to its own place.

// The winding number of the mesh at each point (winding.cl): output 0, a
// float a point; output 1, a byte a point: 1 where it is at least 1/2 (the
// point is inside), as the float32 value says -- asked alone, by
// winding_inside's shorter walk, which agrees with it.  `winding`: the tree's
// far fields (winding_nodes; unused without a BVH).  A bad point writes 0.
// ITEM_RAYS points a work-item, as query_closest_point.
__kernel void query_winding_number(POINT_INPUT_PARAMS, __global uchar* results,
                                   __global const WindingFarField* winding, GEOMETRY_PARAMS)
{
    const uint first = ITEM_RAYS * get_global_id(0);
    if (first >= launch.num_rays)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_point_input(POINT_INPUT_ARGS);
    __global float* winding_out = RESULT_AT(float, 0);
    __global uchar* inside_out = RESULT_AT(uchar, 1);
    uint ids[ITEM_RAYS];
    float3 positions[ITEM_RAYS];
    const uint count = read_item_points(&in, order, launch.num_rays, first, ids, positions);
    for (uint k = 0; k < count; ++k) {
        const uint i = ids[k];
        float3 p = in.scene_lo;   // (a bad point's walk is not taken)
        float max_dist;
        const bool good = take_point(&in, i, positions[k], &p, &max_dist);
        const PointRegion region = point_region(p, in.scene_lo, in.scene_hi);
        if (!winding_out) {
            if (inside_out)
                inside_out[i] = good && winding_inside(&g, winding, p, &region) ? 1 : 0;
            continue;
        }
        const float w = good ? (float)winding_number(&g, winding, p, &region) : 0.0f;
        winding_out[i] = w;
        if (inside_out)
            inside_out[i] = w >= 0.5f ? 1 : 0;
    }
}

// Signed distances, output 0 (a float a point): the distance to the closest
// point (point.cl), negative inside by one sign rule, a kernel each so that
// each walks only what its rule needs -- the winding number (at least 1/2:
// winding.cl), ray parity, or the pseudo-normal at the closest point.  A bad
// point writes NaN.
#define SIGN_WINDING 0
#define SIGN_PARITY 1
#define SIGN_NORMAL 2

// Point p's distance to the mesh, its nearest triangle `best`, negative
// inside by `rule` (`winding`, `normals`: the rule's buffer, or 0).
inline float signed_distance(const Geometry* g, const RayInput* in, const int rule,
                             __global const WindingFarField* winding, __global const PseudoNormals* normals,
                             const PointHit* best, float3 p)
{
    bool inside;
    const PointRegion region = point_region(p, in->scene_lo, in->scene_hi);
    if (rule == SIGN_WINDING)
        inside = winding_inside(g, winding, p, &region);
    else if (rule == SIGN_PARITY)
        inside = inside_by_parity(g, p, in->scene_lo, in->scene_hi);
    else
#ifdef ACCEL_INSTANCES
        inside = inside_by_placed_normal(g, normals, best, p);
#else
        inside = inside_by_normal(g, normals, best, p);
#endif
    return inside ? -(float)best->dist : (float)best->dist;
}

// The signed distances of the CLOSEST_ITEM_POINTS points from the launch's `first` on
// (in the order of point_order.cl, each walk seeded as query_closest_point's but the winding rule's)
// by `rule` (`winding`, `normals`: the rule's buffer, or 0), into output 0.
inline void signed_distances(const Geometry* g, const RayInput* in, const QueryLaunch* launch,
                             __global uchar* results, __global const uint* order, uint first, const int rule,
                             __global const WindingFarField* winding, __global const PseudoNormals* normals)
{
    __global float* out = (__global float*)(results + launch->field_at[0]);
#ifdef POINT_GROUPS
    uint ids[POINT_LANES];
    int seeds[POINT_LANES];
    for (uint k = 0; k < POINT_LANES; ++k)
        seeds[k] = -1;
    for (uint group = 0; group < POINT_GROUPS; ++group) {
        float3 points[POINT_LANES];
        PointHit best[POINT_LANES];
        uint good;
        const uint count = closest_points_of_group(g, in, order, launch->num_rays, first + POINT_LANES * group, false,
                                                   seeds, ids, points, best, &good);
        for (uint k = 0; k < count; ++k)
            out[ids[k]] = good & (1u << k) ? signed_distance(g, in, rule, winding, normals, best + k, points[k])
                                            : NAN;
    }
#else
    uint ids[ITEM_RAYS];
    float3 positions[ITEM_RAYS];
    const uint count = read_item_points(in, order, launch->num_rays, first, ids, positions);
    for (uint k = 0; k < ITEM_POINTS(count); ++k) {
        const uint i = k < count ? ids[k] : 0u;
        float3 p = in->scene_lo;
        float max_dist;
        float d = NAN;
        const bool taken = k < count && take_point(in, i, positions[k], &p, &max_dist);
        // (Not seeded for the winding rule: on the H200 its kernel took 3 % longer with the seed.)
        const int seed = rule == SIGN_WINDING ? -1 : POINT_CELL_SEEDS(order)[point_cell(p, in->scene_lo, in->scene_hi)];
        const PointHit best = closest_point_item(g, p, taken, INFINITY, POINT_MARGIN(p, in->scene_lo, in->scene_hi),
                                                 seed);
        if (k >= count)
            break;
        if (taken) {
            d = signed_distance(g, in, rule, winding, normals, &best, p);
        }
        out[i] = d;
    }
#endif
}

__kernel void query_signed_distance_winding(POINT_INPUT_PARAMS, __global uchar* results,
                                            __global const WindingFarField* winding, GEOMETRY_PARAMS)
{
    const uint first = CLOSEST_ITEM_POINTS * get_global_id(0);
    if (first >= launch.num_rays && !WARP_WALKS)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_point_input(POINT_INPUT_ARGS);
    signed_distances(&g, &in, &launch, results, order, first, SIGN_WINDING, winding, 0);
}

__kernel void query_signed_distance_parity(POINT_INPUT_PARAMS, __global uchar* results, GEOMETRY_PARAMS)
{
    const uint first = CLOSEST_ITEM_POINTS * get_global_id(0);
    if (first >= launch.num_rays && !WARP_WALKS)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_point_input(POINT_INPUT_ARGS);
    signed_distances(&g, &in, &launch, results, order, first, SIGN_PARITY, 0, 0);
}

__kernel void query_signed_distance_normal(POINT_INPUT_PARAMS, __global uchar* results,
                                           __global const PseudoNormals* normals, GEOMETRY_PARAMS)
{
    const uint first = CLOSEST_ITEM_POINTS * get_global_id(0);
    if (first >= launch.num_rays && !WARP_WALKS)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_point_input(POINT_INPUT_ARGS);
    signed_distances(&g, &in, &launch, results, order, first, SIGN_NORMAL, 0, normals);
}

// The far fields of the rows of one tree level (`level_rows`, `count` of
// them; winding.cl): the host launches the levels from the deepest up, so an
// inner child's row is done before the row that holds it -- in a two-level
// scene the meshes' rows first, then the top level's (`top_level` 1), whose
// leaves are instances of meshes done.
__kernel void winding_nodes(__global RowWindingNode* winding, __global const int* level_rows, const uint count,
                            const uint top_level, GEOMETRY_PARAMS)
{
    const uint i = get_global_id(0);
    if (i >= count)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const int row = level_rows[i];
    const BvhPairNode n = *SPLIT_AT(&g, nodes, row);
    winding[2 * row] = child_winding_node(&g, winding, PAIR_LEFT(n), top_level != 0u);
    winding[2 * row + 1] = child_winding_node(&g, winding, PAIR_RIGHT(n), top_level != 0u);
}

// The directions of the camera's pixel-centre rays (packed float3) for pixels
// first .. first + count - 1 (row major, row 0 at the top): exactly the
// renderer's camera rays (camera.cl); every ray starts at the eye.
__kernel void camera_rays(__global float* dirs, const Camera cam, const ulong first, const uint count)
{
    const uint i = get_global_id(0);
    if (i >= count)
        return;
    const ulong pixel = first + i;
    vstore3(camera_ray(&cam, (uint)(pixel % cam.width), (uint)(pixel / cam.width), 0.5f, 0.5f).dir.xyz, i, dirs);
}

// ---- one-launch kernels of the primary-ray benchmark (benchmarks/speed.py)

// Camera rays made and traced in one kernel (no ray buffer).  Ray model: camera.cl.
__kernel void trace_camera(__global Hit* hits, const Camera cam, GEOMETRY_PARAMS)
{
    const uint px = get_global_id(0), py = get_global_id(1), width = cam.width;
    if (px >= width || py >= cam.height)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Ray ray = camera_ray(&cam, px, py, 0.5f, 0.5f);
    hits[py * width + px] = reported_hit(&g, closest_hit(&g, ray.origin.xyz, ray.dir.xyz, 0.0f, INFINITY, false));
}

// The same rays as any-hit queries (occlusion), for comparing query kinds.
__kernel void occlude_camera(__global uchar* occluded, const Camera cam, GEOMETRY_PARAMS)
{
    const uint px = get_global_id(0), py = get_global_id(1), width = cam.width;
    if (px >= width || py >= cam.height)
        return;
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const Ray ray = camera_ray(&cam, px, py, 0.5f, 0.5f);
    occluded[py * width + px] = any_hit(&g, ray.origin.xyz, ray.dir.xyz, 0.0f, INFINITY, false) ? 1 : 0;
}
