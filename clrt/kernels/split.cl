// Scene buffers larger than one allocation.  A device allocates at most
// CL_DEVICE_MAX_MEM_ALLOC_SIZE bytes per buffer (35 GiB on an H200, whose
// memory is 139 GiB), so a big enough scene cannot keep its triangles or BVH
// rows in one buffer.  The host then builds the program with -DSPLIT_BUFFERS
// and passes every scene buffer NAME as MAX_PARTS (4) parts NAME0 .. NAME3,
// part k holding elements [k << NAME_PART_SHIFT, (k + 1) << NAME_PART_SHIFT) (a
// buffer that needs fewer parts repeats its last one).  Four parts always
// suffice: OpenCL promises a largest allocation of at least a quarter of the
// memory.
//
// A kernel takes a buffer as SPLIT_PARAMS(type, name) and stores it once in a
// struct field declared SPLIT_FIELD(type, name) (SPLIT_STORE); helpers then
// name an element as SPLIT_AT(struct_pointer, name, i), a pointer; SPLIT_ARGS(name)
// passes the parameters on.  Without the
// define these are one plain pointer and indexing, so scenes that fit pay
// nothing.  The parts are picked by a chain of selects rather than an array
// of pointers: an indexed private array would live in (slow) stack memory.
#ifndef CLRT_SPLIT_CL
#define CLRT_SPLIT_CL

#ifdef SPLIT_BUFFERS

#if MAX_PARTS != 4
#error "split.cl is written for MAX_PARTS == 4 (clrt.config)"
#endif
#define SPLIT_PARAMS(type, name) __global const type* name##0, __global const type* name##1, \
    __global const type* name##2, __global const type* name##3
#define SPLIT_FIELD(type, name) __global const type *name##0, *name##1, *name##2, *name##3
#define SPLIT_STORE(s, name) ((s).name##0 = name##0, (s).name##1 = name##1, \
    (s).name##2 = name##2, (s).name##3 = name##3)
#define SPLIT_ARGS(name) name##0, name##1, name##2, name##3
#define SPLIT_PART_OF(name, i) ((uint)(i) >> name##_PART_SHIFT)
#define SPLIT_AT(s, name, i) \
    ((SPLIT_PART_OF(name, i) == 0u ? (s)->name##0 : SPLIT_PART_OF(name, i) == 1u ? (s)->name##1 \
      : SPLIT_PART_OF(name, i) == 2u ? (s)->name##2 : (s)->name##3) \
     + ((uint)(i) & ((1u << name##_PART_SHIFT) - 1u)))

#else

#define SPLIT_PARAMS(type, name) __global const type* name
#define SPLIT_FIELD(type, name) __global const type* name
#define SPLIT_STORE(s, name) ((s).name = name)
#define SPLIT_ARGS(name) name
#define SPLIT_AT(s, name, i) ((s)->name + (i))

#endif

#endif
