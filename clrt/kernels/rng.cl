// The path tracer's random numbers: counter-based, so that every number is a
// function of where it is used -- pixel, sample, dimension group, seed -- and
// of nothing else.  A seed then gives the same image on one device whatever
// the tiling, the passes or the order the work-items run in, and no state is
// carried from one launch to the next.
//
// The hash is pcg4d (Jarzynski and Olano, "Hash Functions for GPU Rendering",
// JCGT 9(3), 2020): four 32-bit words in, four well-mixed words out, a few
// multiply-adds, which passes the statistical tests the paper runs on
// structured inputs such as consecutive pixel and sample indices.  Each call
// gives four uniforms; a path takes one call a group of four dimensions
// (path.cl numbers the groups: the camera jitter, then two a bounce).
#ifndef CLRT_RNG_CL
#define CLRT_RNG_CL

inline uint4 pcg4d(uint4 v)
{
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.w;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v.w += v.y * v.z;
    v ^= v >> 16u;
    v.x += v.y * v.w;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v.w += v.y * v.z;
    return v;
}

// Four uniforms in [0, 1) for dimension group `group` of sample `sample` of
// pixel `pixel` (row-major index in the image), under `seed`.  The top 24
// bits of each word, so every value is exact in float and below 1.
inline float4 random4(uint pixel, uint sample, uint group, uint seed)
{
    const uint4 h = pcg4d((uint4)(pixel, sample, group, seed));
    return convert_float4(h >> 8u) * (1.0f / 16777216.0f);
}

#endif
