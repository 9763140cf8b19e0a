// The device's frame (clrt.scene.arrays.device_origin) chosen on the device,
// and triangles given as vertices and faces (clrt.device.build's
// IndexedTriangles) gathered into corners there:
//   gather_corners   each triangle's corners as given, and their box (the
//                    box of the vertices the faces use), reduced into `box`
//   shift_corners    the origin device_origin chooses for that box, every
//                    corner moved by it, and for the host lo, hi and origin
// The host's way -- the box over the used vertices, the origin, the corners
// gathered and moved by numpy -- took 14 ms of a 24 ms Accel of a million
// triangles on the H200's host, whose device build takes 7
// (docs/benchmarks.md); here the triangles cross PCIe as 12 bytes of faces
// and some 6 of vertices instead of 36 of corners.  The same float32
// subtraction (exact: the origin is chosen so) gives the host's corners bit
// for bit.  Also the top level's instance_frame (build_instances.cl) takes
// its origin from frame_origin.
#ifndef CLRT_BUILD_FRAME_CL
#define CLRT_BUILD_FRAME_CL

// clrt.scene.arrays.device_origin on one axis: the box lo..hi on it, the
// box's diagonal (its rounding as the host's: no contraction, same order).
inline double origin_on_axis(double lo, double hi, double diagonal, double recentre_distance)
{
    const double near = fmin(fabs(lo), fabs(hi));
    if (lo * hi <= 0.0 || !(near >= recentre_distance * diagonal))
        return 0.0;
    const double far = fmax(fabs(lo), fabs(hi));
    const float far32 = convert_float(far);
    double grain = (double)(nextafter(far32, INFINITY) - far32);     // numpy's spacing of a float32
    if (diagonal > 0.0) {
        int e;
        frexp(diagonal / 4.0, &e);                                    // 2^(e - 1) <= diagonal / 4 < 2^e
        grain = fmax(grain, ldexp(1.0, e - 1));
    }
    const double c = rint(0.5 * (lo + hi) / grain) * grain;          // rint: ties to even, as Python's round
    return (double)convert_float(c) == c && c * lo > 0.0 && fabs(c) <= 2.0 * near && far <= 2.0 * fabs(c) ? c
                                                                                                        : 0.0;
}

// clrt.scene.arrays.device_origin of the box lo..hi, step for step.
inline double3 frame_origin(double3 lo, double3 hi, double recentre_distance)
{
    const double dx = hi.x - lo.x, dy = hi.y - lo.y, dz = hi.z - lo.z;
    const double diagonal = sqrt((dx * dx + dy * dy) + dz * dz);
    if (!isfinite(diagonal))
        return (double3)(0.0);
    return (double3)(origin_on_axis(lo.x, hi.x, diagonal, recentre_distance),
                     origin_on_axis(lo.y, hi.y, diagonal, recentre_distance),
                     origin_on_axis(lo.z, hi.z, diagonal, recentre_distance));
}

// corners[t] = the vertices faces[t] names (indices checked on the host),
// and the box of them all (build_morton.cl's reduce_box) in `box` (min xyz,
// max xyz; the host clears it to the largest and smallest values).  fmin and fmax
// drop a NaN: centroid_bounds then finds the triangle and the build fails.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void gather_corners(const global float* vertices, const global int* faces, const uint num_tris,
                    global float* corners, global uint* box)
{
    local float3 lo[BUILD_GROUP], hi[BUILD_GROUP];
    float3 my_lo = (float3)(INFINITY), my_hi = (float3)(-INFINITY);
    for (uint tri = get_global_id(0); tri < num_tris; tri += get_global_size(0)) {
        for (uint k = 0; k < 3; ++k) {
            const float3 v = vload3(faces[3 * tri + k], vertices);
            vstore3(v, 3 * tri + k, corners);
            my_lo = fmin(my_lo, v);
            my_hi = fmax(my_hi, v);
        }
    }
    reduce_box(lo, hi, my_lo, my_hi, box);
}

// Every corner moved by the origin device_origin chooses for `box` (each
// work-item chooses it: a few dozen operations, no wait for another pass),
// in float32 as the host moves them (exact); `frame` for the host: lo xyz,
// hi xyz, origin xyz as doubles (no box, no corner at all: zeros).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void shift_corners(global float* corners, const uint num_tris, const global uint* box,
                   const double recentre_distance, global double* frame)
{
    const double3 lo = convert_double3((float3)(from_ordered_bits(box[0]), from_ordered_bits(box[1]),
                                                from_ordered_bits(box[2])));
    const double3 hi = convert_double3((float3)(from_ordered_bits(box[3]), from_ordered_bits(box[4]),
                                                from_ordered_bits(box[5])));
    const bool any = lo.x <= hi.x;
    const double3 origin = any ? frame_origin(lo, hi, recentre_distance) : (double3)(0.0);
    if (get_global_id(0) == 0) {
        vstore3(any ? lo : (double3)(0.0), 0, frame);
        vstore3(any ? hi : (double3)(0.0), 1, frame);
        vstore3(origin, 2, frame);
    }
    const float3 shift = convert_float3(origin);      // a float32 (device_origin chooses one) or 0
    if (all(shift == (float3)(0.0f)))
        return;
    for (uint i = get_global_id(0); i < 3 * num_tris; i += get_global_size(0))
        vstore3(vload3(i, corners) - shift, i, corners);
}

#endif
