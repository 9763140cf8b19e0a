// Fences for what one work-group hands another through global memory while
// both run: data, then a flag, a counter or an exchanged index that tells
// the other where it is.  The writer's release_fence goes between its data
// and the flag, the reader's acquire_fence between the flag and the data.
//
// Why not mem_fence(CLK_GLOBAL_MEM_FENCE): OpenCL 1.2 orders memory only as
// a work-group sees it, and NVIDIA's compiler gives mem_fence just that
// scope (PTX membar.cta), and barrier(CLK_GLOBAL_MEM_FENCE) none beyond its
// bar.sync; read_mem_fence and write_mem_fence it makes device-wide
// (membar.gl).  With mem_fence, an H100 built ploc_hierarchy's nodes from
// another SM's half-written clusters: 4-7 % of builds of a 1M-triangle torus
// lost triangles from the tree, and with reinsertion's moves on such a tree
// some never finished (docs/benchmark-log.md, session 32; tests/test_device_build.py
// reads the compiled fences).  PoCL orders all of them alike.  The cost:
// reinsertion's refit waits on a fence at each level it climbs, bunny00's
// twelve iterations 1.6 -> 1.9 ms on the H100 (PTX fence.acq_rel.gpu, the
// lighter fence of sm_70 on, measured the same).
#ifndef CLRT_FENCES_CL
#define CLRT_FENCES_CL

// This work-item's writes before the flag it writes next.
inline void release_fence(void)
{
    write_mem_fence(CLK_GLOBAL_MEM_FENCE);
}

// The flag this work-item read before what it reads next.
inline void acquire_fence(void)
{
    read_mem_fence(CLK_GLOBAL_MEM_FENCE);
}

#endif
