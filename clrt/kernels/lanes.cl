// Eight lanes (int8 of 0 or -1, as vector comparisons give them) and eight
// bits of a uint, one for each other: the CPU kernels' walks (accel_wide.cl,
// accel_packet.cl) keep sets of children and rays as bits, and test them as
// lanes.
#ifndef CLRT_LANES_CL
#define CLRT_LANES_CL

// Bit k set where lane k of `lanes` is set.  On x86 (PoCL's compiler defines
// __AVX__ where the host has it) that is one vmovmskps of the lanes' sign
// bits: about 5 % less kernel time on incoherent rays than the portable form
// below, which LLVM does not see through (docs/benchmark-log.md).  Elsewhere, or
// with -DPORTABLE_LANE_BITS (tests/test_wide.py builds both): the lanes as
// eight bytes of 0 or 1 in one ulong, whose multiply by 2^56 + 2^49 + ... +
// 2^7 moves byte k's bit to bit 56 + k, and no other product reaches the top
// byte.
inline uint lane_bits(int8 lanes)
{
#if defined(__AVX__) && !defined(PORTABLE_LANE_BITS)
    return (uint)__builtin_ia32_movmskps256(as_float8(lanes));
#else
    const ulong bytes = as_ulong(convert_uchar8(lanes & 1));
    return (uint)((bytes * 0x0102040810204080UL) >> 56);
#endif
}

// -1 in lane k where bit k of `bits` is set (lane_bits the other way).
inline int8 lane_mask(uint bits)
{
    return ((((int8)((int)bits)) >> (int8)(0, 1, 2, 3, 4, 5, 6, 7)) & (int8)(1)) != (int8)(0);
}

// Sixteen lanes and sixteen bits, the same way (point_group.cl's groups of
// sixteen points): with AVX-512 (__AVX512DQ__) one vpmovd2m or vpmovm2d --
// 3 % of the closest-point walk on PoCL against two halves of eight
// (docs/benchmark-log.md) --, else, or with -DPORTABLE_LANE_BITS, the halves.
inline uint lane16_bits(int16 lanes)
{
#if defined(__AVX512DQ__) && !defined(PORTABLE_LANE_BITS)
    return (uint)__builtin_ia32_cvtd2mask512(lanes);
#else
    return lane_bits(lanes.lo) | (lane_bits(lanes.hi) << 8);
#endif
}

inline int16 lane16_mask(uint bits)
{
#if defined(__AVX512DQ__) && !defined(PORTABLE_LANE_BITS)
    return __builtin_ia32_cvtmask2d512((ushort)bits);
#else
    return (int16)(lane_mask(bits), lane_mask(bits >> 8));
#endif
}

#endif
