// Conservative bounding volumes from exact float32 boxes, on the device: the
// fit of clrt/accel/volumes.py step for step, in float64 as there, so the
// argument made there (pad, outward rounding, EVAL_SLACK, ELLIPSE_FLOOR,
// sqrt(3) semi-axes) holds here unchanged -- and the rows are bit for bit
// those the host would fit to the same boxes (tests/test_device_build.py
// checks it).  Float64 costs a few dozen operations per emitted child, once
// per build; a float32 version would need its own error bounds for every
// step.  The constants arrive as -D defines made from volumes.py itself.
//
// No contraction of a * b + c into fma: the host rounds the product first.
#ifndef CLRT_BUILD_FIT_CL
#define CLRT_BUILD_FIT_CL

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#if !defined(REL_PAD) || !defined(ULP_PAD) || !defined(PAD_FLOOR) || !defined(EVAL_SLACK) \
    || !defined(ELLIPSE_FLOOR) || !defined(SQRT3)
#error "build with the constants of clrt/accel/volumes.py as defines"
#endif

// numpy's spacing of a non-negative float32 (the gap to the next float32
// up), exactly, as a double: 2^(e - 150) for biased exponent e, the smallest
// subnormal for 0 and subnormals, and infinity at FLT_MAX (numpy overflows there).
inline double spacing32(float m)
{
    if (m == FLT_MAX)
        return INFINITY;
    const int e = (as_uint(m) >> 23) & 0xff;
    return ldexp(1.0, max(e, 1) - 150);
}

// volumes.padded_boxes: the box widened by
// REL_PAD * largest extent + ULP_PAD ulps of the coordinate + PAD_FLOOR on every side.
inline void padded_box(float3 lo32, float3 hi32, double3* lo, double3* hi)
{
    *lo = convert_double3(lo32);
    *hi = convert_double3(hi32);
    const double3 d = *hi - *lo;
    const double extent = fmax(fmax(d.x, d.y), d.z);
    const float3 magnitude = fmax(fabs(lo32), fabs(hi32));
    double3 pad = (double3)(spacing32(magnitude.x), spacing32(magnitude.y), spacing32(magnitude.z));
    pad = ULP_PAD * pad;
    pad = pad + REL_PAD * extent;
    pad = pad + PAD_FLOOR;
    *lo = *lo - pad;
    *hi = *hi + pad;
}

// The volume of a box as a BvhPairNode child's xyz lanes (layouts.py): *a,
// *b; w lanes are left 0 for the caller's references.
inline void fit_volume(float3 lo32, float3 hi32, float4* a, float4* b)
{
    double3 lo, hi;
    padded_box(lo32, hi32, &lo, &hi);
#if defined(VOLUME_BOX)
    *a = (float4)(convert_float3_rtn(lo), 0.0f);           // round_down32
    *b = (float4)(convert_float3_rtp(hi), 0.0f);           // round_up32
#else
    // The centre is rounded to float32 first, and the reach measured from it.
    const float3 centre = convert_float3(0.5 * (lo + hi));
    const double3 c = convert_double3(centre);
    const double3 reach = fmax(c - lo, hi - c);
    *a = (float4)(centre, 0.0f);
#if defined(VOLUME_SPHERE)
    const double radius = sqrt(reach.x * reach.x + reach.y * reach.y + reach.z * reach.z) * (1.0 + EVAL_SLACK);
    *b = (float4)(convert_float_rtp(radius), 0.0f, 0.0f, 0.0f);   // BvhPairNode: radius in x
#elif defined(VOLUME_ELLIPSE)
    double3 semi = SQRT3 * reach;
    semi = fmax(semi, ELLIPSE_FLOOR * fmax(fmax(semi.x, semi.y), semi.z));
    semi = semi * (1.0 + EVAL_SLACK);
    *b = (float4)(convert_float3_rtn(1.0 / semi), 0.0f);   // smaller 1/R = larger R
#else
#error "build with -DVOLUME_BOX, -DVOLUME_SPHERE or -DVOLUME_ELLIPSE"
#endif
#endif
}

#endif
