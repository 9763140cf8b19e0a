// The samples of sdf_grid (clrt/query/points.py), made on the device a chunk
// at a time into the chunk's point buffer, where the host would otherwise
// make and upload three floats a sample: sample s (C order over an X x Y x Z
// grid) is (xs[s / (Y Z)], ys[s / Z % Y], zs[s % Z]), the axes' float32
// values as the host rounded them (np.linspace in float64), in `axes` as
// zs, then ys, then xs -- so the samples are the host's, bit for bit.
#ifndef CLRT_POINT_GRID_CL
#define CLRT_POINT_GRID_CL

// Samples first .. first + count - 1 into `points` (packed float3, caller's
// frame, as a host batch of points gives them).
__kernel void grid_points(__global float* points, __global const float* axes, const ulong first, const uint count,
                          const uint size_y, const uint size_z)
{
    const uint i = get_global_id(0);
    if (i >= count)
        return;
    const ulong s = first + i;
    const ulong row = s / size_z;
    const uint z = (uint)(s - row * size_z);
    const uint y = (uint)(row % size_y);
    const uint x = (uint)(row / size_y);
    vstore3((float3)(axes[size_z + size_y + x], axes[size_z + y], axes[z]), i, points);
}

#endif
