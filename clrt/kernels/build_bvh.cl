// The device BVH builder (issue #17), one program: triangles -> SAH partition
// into segments (GPUs) -> Morton codes (from vertices and faces: corners
// gathered and moved into the device frame first, build_frame.cl)
// -> radix sort -> PLOC merging with SAH leaf collapse -> reinsertion ->
// treelet restructuring -> depth-first
// BvhPairNode rows, slot-ordered triangles and slot -> triangle ids.  The
// host driver, and the order of the launches, is clrt/device/build.py.
// Also the top level of a scene of instances (build_instances.cl, driven by
// clrt/device/top_level.py), which shares the sort and the volume fit, and
// the wide BVH of CPU devices collapsed from the rows (build_wide.cl, driven
// by clrt/device/wide_build.py).
// Build-time choices arrive as -D defines: BUILD_GROUP, RADIX_BITS,
// PLOC_RADIUS, the state offsets, the SAH constants of clrt/accel/topdown.py, the
// padding constants of clrt/accel/volumes.py and the volume shape (VOLUME_*).
#include "layouts.h"
#include "build_state.cl"
#include "build_scan.cl"
#include "build_morton.cl"
#include "build_sort.cl"
#include "build_partition.cl"
#include "build_ploc.cl"
#include "build_hierarchy.cl"
#include "build_ploc_cpu.cl"
#include "build_reinsert.cl"
#include "build_treelet.cl"
#include "build_emit.cl"
#include "build_frame.cl"
#include "build_instances.cl"
#include "build_wide.cl"
