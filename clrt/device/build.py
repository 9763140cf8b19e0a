"""The BVH built on the device: triangles in host memory -> rows ready to trace.

    >>> from clrt.device.build import build_on_device
    >>> bvh = build_on_device(context, queue, corners, volume="box", leaf_size=4)
    >>> bvh.rows, bvh.tri_verts, bvh.prim_ids      # cl.Buffers, ready for the traversal
    >>> rows, prim_ids = bvh.read_back()            # host copies (tests, statistics)

The algorithm (kernels in ``clrt/kernels/build_*.cl``, entry ``build_bvh.cl``):

1. bounds of the triangles' box centres, and a 30-bit Morton code per triangle;
   on GPUs from ``PART_MIN_TRIANGLES`` on (``SAH_PARTITION``) first the SAH
   partition (``build_partition.cl``):
   the triangles split top-down by the binned SAH, ``PART_LEVELS`` launched
   levels, into at most ``SAH_TOP_CLUSTERS`` segments of about F / that many
   triangles; then a key per triangle of its segment above a 24-bit Morton
   code within the segment's bounds, and PLOC (3.) merges only clusters of
   one segment -- the middle of the tree is the SAH's, which PLOC's merges
   along the Morton curve did worse (docs/benchmark-log.md, session 13);
2. a least-significant-digit radix sort of (code, triangle id), ``RADIX_BITS``
   per pass: on GPUs one launch a pass (the tiles' offsets by decoupled
   look-back) after one that counts the digits of every pass; on CPU devices
   the host sorts (clrt.device.host_sort: as fast, and three kernels fewer to
   compile on a first call);
3. PLOC (Meister & Bittner 2018; the one-block search of PLOC++, Benthin et
   al. 2022).  With the partition, on GPUs (``HIERARCHY``): up the sorted
   keys' linear BVH in one launch (``build_hierarchy.cl``, H-PLOC, Benthin et
   al. 2024): each node of more than 16 triangles merges its children's at
   most 16 clusters each by PLOC's rule down to 16, a segment to one; then
   ploc_top as below.  Otherwise clusters start as the sorted triangles; in
   each iteration every cluster finds the cluster within ``PLOC_RADIUS``
   places on either side whose merged box has the least area, and mutual
   nearest neighbours merge; one
   launch an iteration on GPUs (the kept clusters placed by a decoupled
   look-back across the work-groups), two on CPU devices (the neighbours and
   merges of tiles, a compaction), until at most ``tail_threshold``
   clusters are left; then one work-group runs the remaining iterations in
   one launch (``ploc_tail``; on CPU devices one work-item,
   ``ploc_tail_serial``; the same choices in a loop: the tree does not depend
   on where the host hands over) until ``SAH_TOP_CLUSTERS`` clusters are left,
   and one more (``ploc_top``) splits those top-down by the SAH
   (``build_top.cl``: exact splits over the clusters, weighted by their
   triangles).  Every new node decides
   by the SAH whether its subtree (at most ``leaf_size`` triangles) is emitted
   as one leaf, and records its height;
3a. reinsertion (clrt.device.reinsert; by default on GPUs, below a million
   triangles): subtrees moved where the SAH falls most;
3b. treelet restructuring (Karras & Aila 2013, ``TREELET_LEAVES``; GPUs only
   by default): one launch, a work-group per node (of at least
   ``TREELET_MIN_TRIANGLES`` on large meshes), lowest first, each waiting
   for its children and replacing the treelet of 7 leaves below it (6
   below 16 triangles) by the cheapest by the SAH;
4. rows and slots as sums along each node's path from the root (pointer
   jumping: ceil(log2(depth)) launches, EMIT_JUMPS on GPUs), then one launch
   writes the ``BVH_PAIR_NODE`` rows, fitting each child's volume exactly as
   ``clrt/accel/volumes.py`` does (float64 on the device), the triangles in
   slot order and the slot -> triangle ids.

The host only queues launches: the cluster count lives in a device buffer
that the PLOC kernels read, so the host queues iterations in batches, as
many as should bring the count below ``tail_threshold`` (``MIN_SHRINK``),
and reads the count once after each batch; then it queues the tail, the
treelet restructuring and the emit pass without waiting for the device.
(Reading each iteration's count without blocking was the first version:
NVIDIA's driver completes a read into ordinary memory before it returns, so
every iteration waited for the device, about 80 us each.)  Besides the
counts, a build reads the state once at the end (the row count, the depth,
the first triangle with a NaN or infinite corner: the input is checked on
the device); only a tree whose rows need more than ``EARLY_ROWS_BYTES``, or
on a CPU, has the root's row count (which sizes the row buffer) and height
(which bounds the pointer jumps) read before the rows are emitted.

Builds on one context share scratch buffers and kernel objects: they take
turns on the context's lock (threads building Accels at once wait for each
other's device builds).

:func:`clrt.device.acceleration.build_acceleration` is the one front end the
renderer and the ray queries call: clrt.accel.build for the host builders,
this one for ``builder="device"``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from clrt import layouts
from clrt.accel import as_triangles, check_options, volumes, wide
from clrt.accel.instances import instance_defines
from clrt.accel.rows import tree_stats
from clrt.accel.topdown import C_INTERSECT, C_TRAVERSAL
from clrt.config import VOLUME_DEFINES, VOLUMES
from clrt.device import pinned
from clrt.device.context import device_kind
from clrt.device.build_kernels import (SAH_TOP_MAX, build_queue, check_tuning, launched_kernels,
                                       one_build_per_context, workspace)
from clrt.device.host_sort import sort_on_host
from clrt.device.program import build_program
from clrt.device.reinsert import check_iterations, default_iterations, queue_reinsertion, reinsert_defines
from clrt.errors import DeviceError, InputError
from clrt.scene import arrays
from clrt.scene.mesh import Mesh

BUILD_GROUP = 256        # work-items per work-group of every build kernel
RADIX_BITS = 4           # digit of one radix-sort pass: 16 bins, 8 passes for 30-bit codes
# The sort covers the whole 32-bit key: the SAH partition's keys put the
# segment in the top 8 bits.  An even number of passes leaves the sorted keys
# in the first key buffer, which init_leaves reads while it clears the second
# (treelet_done).
SORT_PASSES = -(-32 // RADIX_BITS)
assert SORT_PASSES % 2 == 0, "init_leaves reads the sorted keys from keys[0]"
# Clusters searched on each side, per device type (Meister & Bittner's default
# 16; PLOC++ uses 8).  Of PLOC alone, the SAH cost over the host SAH builder's
# (leaf size 4) was camel 1.13 / 1.11 / 1.06 and bunny 1.09 / 1.08 / - at radius
# 8 / 16 / 32; with the reinsertion and treelets after it, radius 16, 8 and 4
# give trees that trace alike on bunny00, camel, elephant, homer and knot1
# (within the runs' 2-4 %), and at 10M and 50M triangles radius 4's trace
# 2-4 % faster (H200: 10M primary / random 0.246 / 0.739 ms against 0.255 /
# 0.747 at 8), while the search time grows with the radius: a GPU takes 4
# (PLOC's merges at 10M 17.6 / 12.4 / 11.1 ms at 16 / 8 / 4, at 50M 62.0 ->
# 54.3 from 8 to 4: docs/benchmark-log.md, sessions 25-26).  A CPU device
# keeps 16, which its merge passes search sixteen lanes at a time
# (build_ploc_cpu.cl; at 8 bunny00's PLOC took 23-25 ms on 2 cores against
# 9-20).  At 32 the pair table no longer fits 48 KiB of local memory.
# ``python -m benchmarks.build`` prints the ratio (``--builders
# device/ploc-radius=N``).
PLOC_RADIUS = {"gpu": 4, "cpu": 16}
# Clusters at which the host hands over to ploc_tail, per device type: a GPU
# runs a few thousand clusters' iteration in one work-group faster than three
# launches (on the H200, 2048 against 4096: bunny00 2.07 against 2.12 ms,
# 1M triangles 7.7 against 7.9 ms, 10M the same).  A CPU device hands over to
# ploc_tail_serial, one work-item without barriers (PoCL compiled ploc_tail's
# barriers in 0.3-0.7 s of a first call on 2 cores, docs/benchmarks.md, "The
# first call with empty caches"): the last 8192 clusters' iterations take it
# under a millisecond, less than the passes' launches (paired builds on 2
# cores: bunny00 0.8 ms less, camel 6.64 -> 5.68 ms, homer 3.75 -> 3.06;
# a tail from 32768 clusters: camel the same, bunny00 1.8 ms more).
TAIL_THRESHOLD = {"gpu": 2048, "cpu": 8192}
TAIL_MAX = 32768         # ploc_tail counts its clusters in 16 bits
TAIL_GROUP = {"gpu": 1024, "cpu": BUILD_GROUP}
# ploc_top's work-items: a GPU's tail group, one place each; on a CPU one
# work-item in plain loops (build_top.cl: PoCL compiled the group's barriers
# in 0.5-0.7 s of a first call).
TOP_GROUP = {"gpu": None, "cpu": 1}
# PLOC stops at this many clusters, and ploc_top splits them top-down by the
# SAH (build_top.cl says why; 1: PLOC up to the root).  At most the tail's
# work-group and SAH_TOP_MAX (its tables in local memory).
# On the H200 (docs/benchmark-log.md, session 12), 1M random rays: bunny00 -5 %,
# camel -4 % (128 against none; 256: -7 % and -5 % for 0.1 ms more build).
SAH_TOP_CLUSTERS = {"gpu": 128, "cpu": 128}
# The SAH partition before PLOC (build_partition.cl): the triangles split
# top-down by the binned SAH into at most as many segments as the SAH top
# takes, of about F / that many triangles, PART_BINS bins an axis, in at most
# PART_LEVELS levels (launched without reading the device; the levels past the
# last split cost a few microseconds each), decided on at most PART_SAMPLES
# evenly spaced triangles.  PLOC merges within a segment.
# On the H200 (docs/benchmark-log.md, session 13) it lowers the SAH cost of
# bunny00's tree by 3 % (random, diffuse, AO and camera rays 3-6 % faster) for
# 1.1 ms more build (1.9 -> 3.0 ms), of 1M triangles (14 bunnies) by 2 % for
# 1 ms more, of 10M by 11 % and of 50M by 28 % for no more build time (its
# segments' own Morton codes are finer than one code over the whole mesh).
# Since PLOC below the segments climbs the linear BVH (HIERARCHY), the
# partition pays on small meshes too: on the H200 (2026-12-04, primary /
# random rays over the host SAH tree's) camel 1.04 / 1.00 -> 0.99 / 1.02,
# elephant 1.04 / 1.02 -> 0.98 / 1.02, bunny00 1.01 / 1.01 -> 0.99 / 1.00
# for 0.2-0.6 ms more build, and 1M triangles trace 4 % / 2 % faster for 0.1
# ms more.  So GPUs partition from PART_MIN_TRIANGLES on: 128 segments of 32
# triangles; below, each would hold a leaf's few (benchmarks: --builders
# device/partition=0|1).
SAH_PARTITION = {"gpu": True, "cpu": False}
PART_MIN_TRIANGLES = 4096
# PLOC's merges below the partition's segments by climbing the sorted keys'
# linear BVH, in one launch (build_hierarchy.cl, H-PLOC), instead of one
# ploc_merge launch an iteration over every cluster; only with the partition
# (above its segments ploc_top's SAH top does the rest), per device type.
# It searches PLOC_RADIUS clusters on each side, as ploc_merge.
HIERARCHY = {"gpu": True, "cpu": False}
# Its teams of 32 vote by PTX and sync by `bar.warp.sync` where the compiler
# takes PTX (NVIDIA's), four teams a work-group; False: barriers and local
# memory, one team a work-group, as elsewhere (the same trees; for tests).
WARP_VOTES = True
SEGMENT_BITS = 8         # a key's top bits that hold its segment (at most 1 << SEGMENT_BITS segments)
PART_BINS = 16
PART_LEVELS = 10
PART_SAMPLES = 1 << 17
PART_MAX_NODES = 2 * SAH_TOP_MAX
# Treelet restructuring after PLOC (build_treelet.cl): leaves per treelet,
# per device type; 0: none.  Karras & Aila use 7.  TREELET_SMALL: (leaves,
# below triangles) -- nodes of fewer triangles take treelets of fewer leaves.
# A group waits for its children's treelets, so the restructuring takes as
# long as the chain of treelets up the tree's height, and a smaller treelet
# is quicker (its dynamic program runs over 63 subsets instead of 127, and
# one node fewer is opened); the low nodes change the tree's cost least.
# On the H200 (docs/benchmark-log.md, session 6; build ms, primary rays over
# the host SAH tree's): bunny00 7 leaves 1.92 ms / +4.2 %, 6 leaves 1.69 /
# +5.4 %, 7 and 6 below 16 triangles 1.87 / +4.3 %; camel 1.45 / +2.3 %,
# 1.26 / +6.1 %, 1.41 / +3.0 %.  (On PoCL 8 lowered the SAH cost by 0.4 %
# more than 7 at 7x the time.)  On a CPU it would add a third to the build
# (bunny00 on 2 cores: 114 -> 156 ms), where the build is what a user waits
# for: off there.
TREELET_LEAVES = {"gpu": 7, "cpu": 0}
TREELET_SMALL = {"gpu": (6, 16), "cpu": (6, 16)}
TREELET_GROUP = 32       # work-items that solve one treelet together
TREELET_GROUPS_PER_UNIT = 32   # treelet work-groups launched per compute unit (each takes node after node)
# Treelets of nodes with fewer triangles are not restructured (nodes of at
# most leaf_size never are), by mesh size: (triangles from, minimum), the
# last entry that applies.  Measured on the H200 (benchmarks.build,
# device/treelet-min=N; trace: primary rays, trees launched in turn):
#   minimum           leaf_size + 1      8           16
#   bunny00 trace     +3.8 %             +5.4 %      +6.0 %   (over the host SAH tree)
#   camel trace       +3.0 %             +2.0 %      +5.0 %
#   SAH cost (bunny)  1.061              1.062       1.065
# Restructuring every node keeps small meshes' primary rays near the host SAH
# trees'.  On large meshes the small subtrees' treelets take most of the
# restructuring's time for a few tenths of a percent of SAH cost, and their
# trace times are one within the runs' 1-2 % (2026-12-04, PLOC radius 8;
# device ms, then primary / random ms):
#   minimum        16                      32                      64
#   1M             4.74  0.213 / 0.569     4.27  0.213 / 0.573
#   2M             8.36  0.227 / 0.635     7.30  0.218 / 0.637
#   4M            13.90  0.236 / 0.681    12.23  0.238 / 0.682    11.11  0.236 / 0.684
#   10M           30.78  0.259 / 0.738    26.40  0.258 / 0.742    23.61  0.254 / 0.745
#   50M          145.49  0.289 / 0.896   121.68  0.283 / 0.898   110.26  0.287 / 0.895
TREELET_MIN_TRIANGLES = ((0, 0), (500_000, 32), (4_000_000, 64))
# Heights by which the nodes to restructure are listed (lowest first): a
# taller tree (PLOC's are about 30 high at 1M triangles, 40 at 50M) keeps
# PLOC's shape.
TREELET_LEVELS = 64
# Clusters an iteration keeps, about (bunny00: 0.76 in the first iteration,
# then 0.80-0.83; camel 0.64, then 0.77-0.85): the host queues
# log(count / tail_threshold) / log(1 / MIN_SHRINK) iterations before it
# reads the count again.  Too few cost another round trip to the device
# (about 50 us on the H200); one too many only does the tail's work in a
# launch, about 15 us more.
MIN_SHRINK = 0.83
CPU_TILE_WORKERS = 4     # work-items per core of the CPU merge passes (build_ploc_cpu.cl)
MAX_REDUCE_GROUPS = 256  # work-groups of the bounds reduction (grid-stride beyond)
# gather_corners' box before it: min xyz from the largest, max xyz from the
# smallest order-preserving bits (build_morton.cl's ordered_bits).
_EMPTY_BOX = np.array([0xFFFFFFFF] * 3 + [0] * 3, np.uint32)
EARLY_ROWS_BYTES = 64 << 20   # row buffers made before the row count is known, up to this size
EMIT_JUMPS = 7           # pointer jumps queued without reading the tree's height (2**7 levels)
GROUP_RESULTS = 14       # doubles each work-group of place_instances writes (build_instances.cl)
HIERARCHY_GROUP = 32     # work-items that merge together in ploc_hierarchy (a team: a warp on NVIDIA's GPUs)
HIERARCHY_WARPS = 4      # teams a work-group where they are warps (-DHIERARCHY_WARP_VOTE; else one)

# The state buffer (build_state.cl): int offsets, and the ring of cluster counts.
STATE = {"STATE_NEXT_NODE": 0, "STATE_DEPTH": 1, "STATE_ERROR": 2, "STATE_BAD_TRIANGLE": 3, "STATE_BOUNDS": 4,
         "STATE_ITERATIONS": 10, "STATE_TICKETS": 11, "STATE_TREELET_TICKET": 13, "STATE_COUNTS": 16,
         "COUNT_RING": 64}   # one batch of iterations (50M triangles: 51)
STATE["STATE_LEVELS"] = STATE["STATE_COUNTS"] + STATE["COUNT_RING"]
STATE["STATE_LEVEL_CURSORS"] = STATE["STATE_LEVELS"] + TREELET_LEVELS
STATE["STATE_SORT_TICKETS"] = STATE["STATE_LEVEL_CURSORS"] + TREELET_LEVELS
STATE["STATE_SORT_DIGITS"] = STATE["STATE_SORT_TICKETS"] + SORT_PASSES
STATE["STATE_PART_NODES"] = STATE["STATE_SORT_DIGITS"] + SORT_PASSES * (1 << RADIX_BITS)
STATE["STATE_PART_SEGMENTS"] = STATE["STATE_PART_NODES"] + 1
STATE["STATE_PART_FIRST"] = STATE["STATE_PART_NODES"] + 2
STATE["STATE_PART_END"] = STATE["STATE_PART_NODES"] + 3
STATE["STATE_TAIL"] = STATE["STATE_PART_NODES"] + 4
TAIL_INTS = 4            # ploc_tail's hand-over to ploc_top (build_state.cl's TAIL_*)
STATE_INTS = STATE["STATE_INTS"] = STATE["STATE_TAIL"] + TAIL_INTS

def sah_top_clusters(kind: str, tail_group: int | None = None, top_clusters: int | None = None) -> int:
    """Clusters the SAH top takes (SAH_TOP_CLUSTERS), no more than ploc_tail's work-items."""
    group = TAIL_GROUP[kind] if tail_group is None else int(tail_group)
    return min(SAH_TOP_CLUSTERS[kind] if top_clusters is None else int(top_clusters), group)


def top_group(kind: str, tail_group: int | None = None) -> int:
    """Work-items of ploc_top (TOP_GROUP, else the tail's group)."""
    return TOP_GROUP[kind] or (TAIL_GROUP[kind] if tail_group is None else int(tail_group))


def build_defines(volume: str, kind: str = "gpu", treelet_leaves: int | None = None,
                  tail_group: int | None = None, top_clusters: int | None = None, segmented: bool = False,
                  warp_vote: bool = False) -> dict:
    """Program defines: the shape, the work-group and state layout, and the
    constants of topdown.py, volumes.py and instances.py (one source of truth:
    repr() of a float is a C double literal of the same value)."""
    return {
        VOLUME_DEFINES[volume]: None, "BUILD_GROUP": BUILD_GROUP, "RADIX_BITS": RADIX_BITS,
        "SORT_PASSES": SORT_PASSES,
        "PLOC_RADIUS": PLOC_RADIUS[kind], "TAIL_GROUP": TAIL_GROUP[kind] if tail_group is None else int(tail_group),
        "TOP_GROUP": top_group(kind, tail_group),
        "SAH_TOP_CLUSTERS": sah_top_clusters(kind, tail_group, top_clusters),
        "TREELET_LEAVES": TREELET_LEAVES[kind] if treelet_leaves is None else int(treelet_leaves),
        "TREELET_SMALL_LEAVES": min(TREELET_SMALL[kind][0], TREELET_LEAVES[kind] if treelet_leaves is None
                                    else int(treelet_leaves)),
        "TREELET_FULL_MIN": TREELET_SMALL[kind][1],
        "TREELET_GROUP": TREELET_GROUP, "TREELET_LEVELS": TREELET_LEVELS, **reinsert_defines(), **STATE,
        "PART_BINS": PART_BINS, "PART_MAX_NODES": PART_MAX_NODES, "PART_LEVELS": PART_LEVELS,
        "SEGMENT_BITS": SEGMENT_BITS,
        "GROUP_RESULTS": GROUP_RESULTS,
        **({"PLOC_SEGMENTS": None} if segmented else {}), "HIERARCHY_GROUP": HIERARCHY_GROUP,
        "HIERARCHY_WARPS": HIERARCHY_WARPS if warp_vote else 1,
        **({"HIERARCHY_WARP_VOTE": None} if warp_vote else {}),
        "C_TRAVERSAL": f"((float){C_TRAVERSAL!r})", "C_INTERSECT": f"((float){C_INTERSECT!r})",
        **volumes.fit_defines(), **instance_defines(), **wide.collapse_defines(),
    }


@dataclass
class DeviceBvh:
    """A BVH built on the device, its buffers ready for the traversal.

    rows:      ``num_rows`` BVH_PAIR_NODE, depth-first, root at row 0.
    tri_verts: ``num_triangles`` TRIANGLE_VERTS in slot (leaf) order.
    prim_ids:  ``num_triangles`` int32, slot -> input triangle index.
    exact_rows: the rows with the exact (unpadded) boxes of the children in
               box layout, only when built with ``keep_boxes``; for statistics.
    depth:     nodes on the longest root-to-leaf path (root counts 1): the
               traversal stack (BVH_STACK_SIZE) must hold it.
    kernels:   the program's kernels (the wide BVH of CPU devices is
               collapsed by two of them: clrt.device.wide_build).
    iterations: PLOC iterations; timings: ``wall`` (host clock, from the
               call to the rows being ready), and when built with
               ``device_times``, device ms per phase (profiling events;
               ``device`` is their sum).
    launches:  with ``profile``, (kernel name, device start ns, end ns) of
               every launch, in order.
    frame:     built from a Mesh, the box of its used vertices (lo, hi:
               clrt.scene.mesh.Mesh.bounds) and the device origin chosen for
               it (clrt.scene.arrays.device_origin), rows of a (3, 3) array.
    """

    rows: cl.Buffer
    tri_verts: cl.Buffer
    prim_ids: cl.Buffer
    num_rows: int
    num_triangles: int
    depth: int
    volume: str
    leaf_size: int
    iterations: int
    timings: dict
    queue: cl.CommandQueue = field(repr=False)
    exact_rows: cl.Buffer | None = field(default=None, repr=False)
    builder: str = "device"
    launches: list = field(default_factory=list, repr=False)
    frame: np.ndarray | None = field(default=None, repr=False)   # from a Mesh: (3, 3) lo, hi, origin
    kernels: dict | None = field(default=None, repr=False)
    _stats: dict | None = field(default=None, repr=False)

    @property
    def device_bytes(self) -> int:
        return self.num_rows * layouts.BVH_PAIR_NODE.itemsize + self.num_triangles * (
            layouts.TRIANGLE_VERTS.itemsize + 4)

    @property
    def build_ms(self) -> float:
        return self.timings["wall"]

    def read_back(self) -> tuple[np.ndarray, np.ndarray]:
        """Host copies: rows (num_rows,) BVH_PAIR_NODE and prim_ids (F,) int32."""
        return self.read_rows(), self.read_prim_ids()

    def read_rows(self) -> np.ndarray:
        """Host copy of the rows, (num_rows,) BVH_PAIR_NODE."""
        rows = np.empty(self.num_rows, layouts.BVH_PAIR_NODE)
        cl.enqueue_copy(self.queue, rows, self.rows, is_blocking=True)
        return rows

    def read_prim_ids(self) -> np.ndarray:
        """Host copy of the slot -> triangle ids, (F,) int32."""
        prim_ids = np.empty(self.num_triangles, np.int32)
        cl.enqueue_copy(self.queue, prim_ids, self.prim_ids, is_blocking=True)
        return prim_ids

    def read_triangles(self) -> np.ndarray:
        """Host copy of the slot-ordered triangles, (F,) TRIANGLE_VERTS."""
        tris = np.empty(self.num_triangles, layouts.TRIANGLE_VERTS)
        cl.enqueue_copy(self.queue, tris, self.tri_verts, is_blocking=True)
        return tris

    def read_exact_rows(self) -> np.ndarray:
        if self.exact_rows is None:
            raise ValueError("build with keep_boxes=True to keep the exact boxes")
        exact = np.empty(self.num_rows, layouts.BVH_PAIR_NODE)
        cl.enqueue_copy(self.queue, exact, self.exact_rows, is_blocking=True)
        return exact

    def stats(self) -> dict:
        """The numbers of clrt.accel.bvh.Bvh.stats, from the exact rows (needs
        ``keep_boxes``); computed once, so they outlive :meth:`release`."""
        if self._stats is None:
            self._stats = {**tree_stats(self.read_exact_rows(), self.depth), "build_ms": self.build_ms,
                           "device_bytes": self.device_bytes}
        return self._stats

    def release(self) -> None:
        """Free the device buffers now (statistics computed before stay)."""
        for buffer in (self.rows, self.tri_verts, self.prim_ids, self.exact_rows):
            if buffer is not None:
                buffer.release()
        self.rows = self.tri_verts = self.prim_ids = self.exact_rows = None


def _groups(n: int) -> int:
    return max(-(-int(n) // BUILD_GROUP), 1)


class _Phases:
    """First and last profiling event of each phase (device ms = their span)."""

    def __init__(self):
        self.spans: dict[str, list] = {}

    def add(self, phase: str, event: cl.Event) -> cl.Event:
        span = self.spans.setdefault(phase, [event, event])
        span[1] = event
        return event

    def ms(self) -> dict:
        out = {phase: 1e-6 * (last.profile.end - first.profile.start)
               for phase, (first, last) in self.spans.items()}
        out["device"] = sum(out.values())
        return out


class _BuildChoice:
    """What build_on_device makes of its tuning options for ``F`` triangles on
    a device of ``kind`` (None: the device type's defaults): the program's
    defines and kernels, and the settings the launches take."""

    def __init__(self, device: cl.Device, volume: str, F: int, indexed: bool, tail_threshold=None,
                 treelet_leaves=None, tail_group=None, top_clusters=None, partition=None, reinsert_iterations=None,
                 hierarchy=None):
        kind = device_kind(device)
        self.tail_threshold = min(TAIL_THRESHOLD[kind] if tail_threshold is None else int(tail_threshold), TAIL_MAX)
        self.tail_group = TAIL_GROUP[kind] if tail_group is None else int(tail_group)
        self.top_clusters = sah_top_clusters(kind, self.tail_group, top_clusters)
        self.reinserts = check_iterations(default_iterations(kind, F) if reinsert_iterations is None
                                          else reinsert_iterations)
        if partition is None:
            partition = SAH_PARTITION[kind] and F >= PART_MIN_TRIANGLES
        self.segmented = bool(partition) and 1 < self.top_clusters < F
        self.hierarchical = self.segmented and bool(HIERARCHY[kind] if hierarchy is None else hierarchy)
        # (ploc_hierarchy's ballots: a PTX vote where the compiler takes PTX)
        warp_vote = self.hierarchical and WARP_VOTES and "cl_nv_compiler_options" in device.extensions.split()
        self.defines = build_defines(volume, kind, treelet_leaves, self.tail_group, self.top_clusters,
                                     self.segmented, warp_vote)
        treelets = TREELET_LEAVES[kind] if treelet_leaves is None else int(treelet_leaves)
        self.treelets = treelets if F > 2 else 0
        self.kernels = launched_kernels(kind, self.segmented, self.treelets > 0,
                                        self.tail_threshold > self.top_clusters, indexed, volume == "box",
                                        self.reinserts > 0 and F > 2, self.hierarchical)


def default_build_program(context: cl.Context, volume: str, num_tris: int,
                          indexed: bool = False) -> tuple[str, dict, tuple]:
    """The entry, defines and kernels of the program that build_on_device
    builds with its default options for ``num_tris`` triangles on ``context``
    -- from a Mesh's vertices and faces where ``indexed`` --
    (clrt.device.first_build keys its record on them)."""
    choice = _BuildChoice(context.devices[0], volume, int(num_tris), bool(indexed))
    return "build_bvh.cl", choice.defines, tuple(choice.kernels)


@one_build_per_context
def build_on_device(context: cl.Context, queue: cl.CommandQueue, corners, volume: str = "box",
                    leaf_size: int = 4, keep_boxes: bool = False,
                    tail_threshold: int | None = None, staged_upload: bool | None = None,
                    treelet_leaves: int | None = None, treelet_min: int | None = None,
                    tail_group: int | None = None, top_clusters: int | None = None,
                    partition: bool | None = None, reinsert_iterations: int | None = None,
                    hierarchy: bool | None = None, device_times: bool = False, profile: bool = False,
                    uploaded=None) -> DeviceBvh:
    """Build a BVH over ``corners`` on the queue's device.

    corners: (F, 3, 3) triangle corners (converted to float32, checked as
        clrt.accel.build checks them); row order is the triangle id.  Or a
        Mesh: its vertices and faces are uploaded, the corners gathered on
        the device and moved into the device frame there
        (build_frame.cl), which ``DeviceBvh.frame`` gives.
    uploaded: for a Mesh, its vertices and faces on the device already (the
        buffers of clrt.device.crease.UploadedMesh, the copies complete): not
        uploaded again.
    volume: one of ``VOLUMES``; leaf_size: 1..255, the most triangles per leaf.
    keep_boxes: also keep the exact child boxes (``DeviceBvh.stats``).
    tail_threshold: clusters at which PLOC hands over to one work-group
        (a CPU's: one work-item; default: TAIL_THRESHOLD of the device type;
        for benchmarks); at most top_clusters: no hand-over, no tail is launched.
    staged_upload: the triangles through page-locked staging or not
        (default: clrt.device.pinned.upload's choice; for benchmarks).
    treelet_leaves: leaves of the treelets restructured after PLOC (0: the
        plain PLOC tree; default: TREELET_LEAVES of the device type).
    treelet_min: triangles a node needs to be restructured (default: by
        TREELET_MIN_TRIANGLES; always more than leaf_size).
    tail_group: work-items of ploc_tail (a power of two; default: TAIL_GROUP
        of the device type; for benchmarks).
    top_clusters: clusters the SAH top takes over from PLOC, 1..SAH_TOP_MAX
        (1: none; default: SAH_TOP_CLUSTERS of the device type; never more
        than the tail's work-items; for benchmarks).
    partition: the SAH partition into at most top_clusters segments before
        PLOC (default: SAH_PARTITION of the device type, from
        PART_MIN_TRIANGLES triangles on; for benchmarks).
    reinsert_iterations: reinsertion's iterations (0: none; default: clrt.device.reinsert.default_iterations).
    hierarchy: with the partition, PLOC's merges up the linear BVH in one
        launch (build_hierarchy.cl) or, False, ploc_merge's iterations
        (default: HIERARCHY of the device type; for benchmarks and tests).
    device_times: time the phases on the device (``DeviceBvh.timings``; for
        benchmarks).  The build then runs on ``queue``, which must have
        profiling enabled (clrt.device.context.create_context's does);
        otherwise on a queue of the same device without it (build_queue).
    profile: keep every launch's kernel name and device start and end
        (``DeviceBvh.launches``; benchmarks.build --profile); implies device_times.
    Either way the build is complete when this returns, so ``queue`` and any
    other queue of the context may use the buffers at once.
    Raises InputError on bad input, DeviceError when the device lacks float64.
    """
    start = time.perf_counter()
    if volume not in VOLUMES:
        raise InputError(f"unknown bounding volume {volume!r} (choose from {', '.join(VOLUMES)})")
    check_options(volume, "device", leaf_size)
    leaf_size = int(leaf_size)
    indexed = isinstance(corners, Mesh)
    tri = None if indexed else as_triangles(corners, check_finite=False)     # checked on the device
    device = queue.device
    check_tuning(tail_threshold, treelet_leaves, treelet_min, tail_group, int(device.max_work_group_size),
                 top_clusters)
    if "cl_khr_fp64" not in device.extensions:
        raise DeviceError(f"the device BVH builder fits volumes in float64, which {device.name.strip()} lacks")
    kind = device_kind(device)
    F = len(corners.faces) if indexed else len(tri)
    choice = _BuildChoice(device, volume, F, indexed, tail_threshold, treelet_leaves, tail_group, top_clusters,
                          partition, reinsert_iterations, hierarchy)
    tail_threshold, tail_group, top_clusters = choice.tail_threshold, choice.tail_group, choice.top_clusters
    reinserts, segmented, defines, treelets = choice.reinserts, choice.segmented, choice.defines, choice.treelets
    program = build_program(context, "build_bvh.cl", defines, kernels=choice.kernels)
    ws = workspace(context)
    k = ws.kernels_of(program, defines)
    num_nodes = 2 * F - 1
    root = 2 * F - 2 if F > 1 else 0        # the last merge makes the root
    phases = _Phases() if device_times or profile else None
    caller_queue = queue
    if phases is None:
        queue = build_queue(context, queue.device)
    launched = [] if profile else None

    def launch(phase: str, kernel: cl.Kernel, groups: int, *args, group: int = BUILD_GROUP) -> cl.Event:
        if args:
            kernel.set_args(*args)
        event = cl.enqueue_nd_range_kernel(queue, kernel, (groups * group,), (group,))
        if launched is not None:
            launched.append((kernel.function_name, event))
        return event if phases is None else phases.add(phase, event)

    state = ws.get("state", 4 * STATE_INTS)
    corners_buf = ws.get("corners", 36 * F)
    if indexed and uploaded is not None:
        vertices, faces, uploads = uploaded.vertices, uploaded.faces, []
    elif indexed:
        vertices, faces = ws.get("vertices", corners.vertices.nbytes), ws.get("faces", corners.faces.nbytes)
        uploads = pinned.upload_together(context, queue, [(vertices, corners.vertices), (faces, corners.faces)],
                                         staged_upload)
    if indexed:
        box, frame = ws.get("box", 4 * 6), ws.get("frame", 8 * 9)
        uploads.append(cl.enqueue_copy(queue, box, _EMPTY_BOX, is_blocking=False))
    else:
        uploads = [pinned.upload(context, queue, corners_buf, tri, staged_upload)]
    if phases is not None:
        for uploaded in uploads:
            phases.add("upload", uploaded)
    # The outputs are made while the device works: making them between the
    # last launches cost 0.2 ms (bunny00) to 0.4 ms (1M) on the H200.  The
    # rows' count is known at the end; up to EARLY_ROWS_BYTES they are made
    # now for the most a tree can have (F - 1).
    tri_verts = cl.Buffer(context, cl.mem_flags.READ_WRITE, F * layouts.TRIANGLE_VERTS.itemsize)
    prim_ids = cl.Buffer(context, cl.mem_flags.READ_WRITE, F * 4)
    rows = exact_rows = None
    if max(F - 1, 1) * layouts.BVH_PAIR_NODE.itemsize <= EARLY_ROWS_BYTES:
        rows, exact_rows = _row_buffers(context, max(F - 1, 1), keep_boxes)
    made = [buffer for buffer in (tri_verts, prim_ids, rows, exact_rows) if buffer is not None]
    cl.enqueue_migrate_mem_objects(queue, made, cl.mem_migration_flags.CONTENT_UNDEFINED)
    keys = [ws.get("keys0", 4 * F), ws.get("keys1", 4 * F)]
    ids = [ws.get("ids0", 4 * F), ws.get("ids1", 4 * F)]

    # 1. Morton codes.
    launch("morton", k["init_build_state"], 1, state, np.uint32(F))
    if indexed:
        groups = min(_groups(F), MAX_REDUCE_GROUPS)
        launch("morton", k["gather_corners"], groups, vertices, faces, np.uint32(F), corners_buf, box)
        launch("morton", k["shift_corners"], groups, corners_buf, np.uint32(F), box,
               np.float64(arrays.RECENTRE_DISTANCE), frame)
    launch("morton", k["centroid_bounds"], min(_groups(F), MAX_REDUCE_GROUPS), corners_buf, np.uint32(F), state)
    if segmented:
        _partition(k, launch, ws, F, top_clusters, corners_buf, state, sample_part=ids[1], keys=keys[0],
                   ids=ids[0])
    else:
        launch("morton", k["morton_codes"], _groups(F), corners_buf, np.uint32(F), state, keys[0], ids[0])

    # 2. Radix sort; a CPU device's by the host (host_sort.py says why).
    if kind == "cpu":
        # (the sorted keys in keys[0], as queue_sort leaves them, where init_leaves reads their segments)
        sorted_ids = sort_on_host(queue, F, keys[0], ids[0], keep_keys=segmented)
    else:
        sorted_ids = queue_sort(k, launch, ws, kind, F, keys, ids, state)

    # 3. PLOC.
    nodes = ws.get("nodes", layouts.BUILD_NODE.itemsize * num_nodes)
    clusters = ws.get("clusters", layouts.BUILD_CLUSTER.itemsize * F)
    # (also ploc_hierarchy's top: a cluster a segment)
    merged = ws.get("merged", layouts.BUILD_CLUSTER.itemsize * max(F, 1 << SEGMENT_BITS))
    tile_kept = ws.get("tile_kept", 4 * max(_groups(F), F))    # also the tails' nearest neighbours
    tile_status = ws.get("tile_status", 8 * _groups(F))         # ploc_merge's look-back, two halves
    heights = ws.get("heights", 4 * max(F - 1, 1))             # of the inner nodes, index - F
    treelet_done = keys[1]             # the sort keys are spent: F ints each
    launch("ploc", k["init_leaves"], _groups(F), corners_buf, sorted_ids, keys[0], np.int32(segmented),
           np.uint32(F), nodes, clusters, tile_status, treelet_done)
    cpu = kind == "cpu"
    if choice.hierarchical:
        # PLOC up the linear BVH to one cluster a segment, in `merged`
        # (build_hierarchy.cl), then the SAH top over them.  Scratch: the
        # climb's bounds in the sort's spare ids, the spare node numbers in
        # tile_kept.
        bounds, spare_numbers = ids[1], tile_kept
        ranks = ws.get("segment_ranks", 4 * ((1 << SEGMENT_BITS) + 1))
        launch("ploc", k["hierarchy_clear"], _groups(F), bounds, np.uint32(F))
        launch("ploc", k["segment_ranks"], 1, keys[0], np.uint32(F), ranks, group=1 << SEGMENT_BITS)
        group = HIERARCHY_GROUP * defines["HIERARCHY_WARPS"]
        launch("ploc", k["ploc_hierarchy"], -(-F // group), clusters, keys[0], ranks, bounds, spare_numbers,
               nodes, heights, np.int32(F), merged, np.uint32(leaf_size), group=group)
        launch("ploc", k["hierarchy_top"], 1, ranks, np.int32(F), state, group=1)
        launch("ploc", k["ploc_top"], 1, merged, clusters, nodes, heights, F, state, leaf_size,
               group=top_group(kind, tail_group))
    else:
        queued = _ploc(queue, k, launch, F, clusters, merged, tile_kept, tile_status, nodes, heights, state,
                       leaf_size, max(tail_threshold, top_clusters), cpu)
        # ploc_tail starts from the clusters of the last iteration: on the CPU
        # passes always `clusters` (compacted back into it), from ploc_merge the
        # two buffers in turn.  With no more than the SAH top's clusters left it
        # would merge nothing: the host writes what it would leave ploc_top.
        last, spare = (merged, clusters) if not cpu and queued % 2 else (clusters, merged)
        if tail_threshold > top_clusters and cpu:    # one work-item (build_ploc_cpu.cl)
            launch("ploc", k["ploc_tail_serial"], 1, last, spare, tile_kept, nodes, heights, F, state, queued,
                   leaf_size, group=1)
        elif tail_threshold > top_clusters:
            launch("ploc", k["ploc_tail"], 1, last, spare, tile_kept, nodes, heights, F, state, queued, leaf_size,
                   group=tail_group)
        else:
            _hand_over(queue, state, queued)
        launch("ploc", k["ploc_top"], 1, last, spare, nodes, heights, F, state, leaf_size,
               group=top_group(kind, tail_group))

    # 3a. Reinsertion (build_reinsert.cl), in PLOC's spent cluster buffers.
    queue_reinsertion(k, launch, _groups, reinserts, F, nodes, heights, clusters, merged, tile_kept, leaf_size)
    # 3b. Treelet restructuring: the nodes with a treelet counted per height
    # and listed by height, then one launch (build_treelet.cl) of as many
    # work-groups as the device runs at once, which take the listed nodes
    # until none are left: the host need not read their count.  A tree
    # taller than TREELET_LEVELS keeps PLOC's shape.
    if treelets:
        if treelet_min is None:
            treelet_min = [minimum for first, minimum in TREELET_MIN_TRIANGLES if F >= first][-1]
        min_count = max(leaf_size + 1, int(treelet_min))
        order = keys[0]
        launch("treelet", k["treelet_levels"], _groups(F - 1), nodes, heights, F, min_count, state)
        launch("treelet", k["treelet_order"], _groups(F - 1), nodes, heights, F, min_count, state, order)
        groups = min(F - 1, TREELET_GROUPS_PER_UNIT * device.max_compute_units)
        launch("treelet", k["treelet_restructure"], groups, nodes, heights, order, treelet_done, state, F,
               min_count, leaf_size, group=TREELET_GROUP)

    # 4. Path sums, then the rows.  With the rows' buffer made already, a
    # GPU's host does not wait for the tree either: it queues EMIT_JUMPS pointer
    # jumps (enough for a tree of 2**EMIT_JUMPS levels) and, should the tree be
    # taller (emit_tree reports a node whose path did not reach the root),
    # the rest of the jumps and emit_tree again.  Otherwise it reads the
    # root's row count and height first.
    ancestor = [ws.get("ancestor0", 4 * num_nodes), ws.get("ancestor1", 4 * num_nodes)]
    path = [ws.get("path0", 16 * num_nodes), ws.get("path1", 16 * num_nodes)]
    root_rows = np.empty(1, np.int32)
    offset = root * layouts.BUILD_NODE.itemsize + layouts.BUILD_NODE.fields["rows"][1]
    guessed = rows is not None and kind == "gpu"    # (a CPU waits for nothing, and a jump costs it more)
    if guessed:
        jumps = EMIT_JUMPS
    else:
        cl.enqueue_copy(queue, root_rows, nodes, src_offset=offset, is_blocking=False)
        jumps = _root_height(queue, heights, F).bit_length()   # 2**jumps > height - 1, the longest path's edges
        if rows is None:
            rows, exact_rows = _row_buffers(context, max(int(root_rows[0]), 1), keep_boxes)
    launch("emit", k["init_root_paths"], _groups(num_nodes), nodes, np.uint32(num_nodes), ancestor[0], path[0])

    def jump_and_emit(first_jump: int, last_jump: int) -> None:
        for j in range(first_jump, last_jump):
            launch("emit", k["jump_root_paths"], _groups(num_nodes), ancestor[j % 2], path[j % 2],
                   np.uint32(num_nodes), ancestor[1 - j % 2], path[1 - j % 2])
        launch("emit", k["emit_tree"], _groups(num_nodes), nodes, np.uint32(num_nodes), np.int32(root), corners_buf,
               sorted_ids, ancestor[last_jump % 2], path[last_jump % 2], rows, exact_rows, tri_verts, prim_ids,
               state)

    jump_and_emit(0, jumps)
    head = np.empty(STATE_INTS, np.int32)
    cl.enqueue_copy(queue, root_rows, nodes, src_offset=offset, is_blocking=False)
    placed = np.empty((3, 3)) if indexed else None      # lo, hi, origin
    if indexed:
        cl.enqueue_copy(queue, placed, frame, is_blocking=False)
    cl.enqueue_copy(queue, head, state, is_blocking=True)
    if head[STATE["STATE_ERROR"]] and guessed:      # a taller tree: more jumps, emit again
        more = _root_height(queue, heights, F).bit_length()
        cl.enqueue_copy(queue, state, np.zeros(1, np.int32), dst_offset=4 * STATE["STATE_ERROR"])
        jump_and_emit(jumps, more)
        cl.enqueue_copy(queue, head, state, is_blocking=True)
    if head[STATE["STATE_BAD_TRIANGLE"]] >= 0:
        for buffer in (rows, exact_rows, tri_verts, prim_ids):
            if buffer is not None:
                buffer.release()
        raise InputError(f"triangle corners contain NaN or infinite (or beyond float32) values "
                         f"(first: triangle {int(head[STATE['STATE_BAD_TRIANGLE']])})")
    if head[STATE["STATE_ERROR"]]:
        raise RuntimeError("device BVH build: a node did not reach the root (too few pointer jumps)")
    num_rows = max(int(root_rows[0]), 1)
    iterations = int(head[STATE["STATE_ITERATIONS"]])
    timings = {} if phases is None else phases.ms()
    timings["wall"] = 1e3 * (time.perf_counter() - start)
    launches = [(name, event.profile.start, event.profile.end) for name, event in launched or ()]
    return DeviceBvh(rows=rows, tri_verts=tri_verts, prim_ids=prim_ids, num_rows=num_rows, num_triangles=F,
                     depth=int(head[STATE["STATE_DEPTH"]]), volume=volume, leaf_size=leaf_size,
                     iterations=iterations, timings=timings, queue=caller_queue, exact_rows=exact_rows,
                     launches=launches, frame=placed, kernels=k)


def _row_buffers(context: cl.Context, num_rows: int, keep_boxes: bool):
    """The row buffer, and the exact rows' when asked for, for ``num_rows`` rows."""
    nbytes = num_rows * layouts.BVH_PAIR_NODE.itemsize
    rows = cl.Buffer(context, cl.mem_flags.READ_WRITE, nbytes)
    return rows, cl.Buffer(context, cl.mem_flags.READ_WRITE, nbytes) if keep_boxes else None


def queue_sort(k, launch, ws, kind: str, n: int, keys: list, ids: list, state: cl.Buffer) -> cl.Buffer:
    """Queue the radix sort of the n (key, id) pairs in keys[0], ids[0],
    ping-ponging between the two buffers of each (build_sort.cl): on a GPU one
    launch a pass (decoupled look-back), elsewhere three; ``state`` as
    init_build_state leaves it.  Returns the buffer of the sorted ids (the
    sorted keys are in keys[0]: SORT_PASSES is even)."""
    tiles = max(-(-n // (BUILD_GROUP * 8)), 1)          # SORT_TILE = BUILD_GROUP * SORT_ITEMS
    bins = 1 << RADIX_BITS
    if kind == "gpu":
        sort_status = ws.get("sort_status", 4 * 2 * tiles * bins)     # two halves, see radix_scatter_lookback
        launch("sort", k["radix_digit_counts"], min(_groups(n), MAX_REDUCE_GROUPS), keys[0], np.uint32(n), state,
               sort_status, np.uint32(tiles * bins))
    else:
        tile_counts = ws.get("tile_counts", 4 * bins * tiles)
    for p in range(SORT_PASSES):
        src, dst = p % 2, 1 - p % 2
        if kind == "gpu":
            launch("sort", k["radix_scatter_lookback"], tiles, keys[src], ids[src], np.uint32(n), np.uint32(p),
                   state, sort_status, keys[dst], ids[dst])
            continue
        shift = np.uint32(p * RADIX_BITS)
        launch("sort", k["radix_histogram"], tiles, keys[src], np.uint32(n), shift, tile_counts)
        launch("sort", k["scan_counts"], 1, tile_counts, np.uint32(bins * tiles))
        launch("sort", k["radix_scatter"], tiles, keys[src], ids[src], np.uint32(n), shift, tile_counts,
               keys[dst], ids[dst])
    return ids[SORT_PASSES % 2]


def _hand_over(queue, state: cl.Buffer, first_iteration: int) -> None:
    """Write at STATE_TAIL what ploc_tail leaves ploc_top when it merges
    nothing (build_state.cl's TAIL_COUNT, TAIL_NEXT_NODE, TAIL_ITERATIONS,
    TAIL_FLAGS, in this order): the count before ``first_iteration``, the
    node counter and the iterations that merged, as they stand."""
    head = np.empty(STATE_INTS, np.int32)
    cl.enqueue_copy(queue, head, state, is_blocking=True)
    tail = np.array([head[STATE["STATE_COUNTS"] + first_iteration % STATE["COUNT_RING"]],
                     head[STATE["STATE_NEXT_NODE"]], head[STATE["STATE_ITERATIONS"]], 0], np.int32)
    cl.enqueue_copy(queue, state, tail, dst_offset=4 * STATE["STATE_TAIL"], is_blocking=True)


def _root_height(queue, heights: cl.Buffer, F: int) -> int:
    """Nodes on the longest root-to-leaf path (blocking read of the root's height)."""
    if F == 1:
        return 1
    value = np.empty(1, np.int32)
    cl.enqueue_copy(queue, value, heights, src_offset=4 * (F - 2), is_blocking=True)   # root 2F - 2
    return int(value[0])


def _partition(k, launch, ws, F: int, budget: int, corners, state, sample_part, keys, ids) -> None:
    """Queue the SAH partition of the F triangles into at most ``budget``
    segments (build_partition.cl), decided on every ``stride``-th triangle
    (PART_SAMPLES of them at most), then every triangle's key and id for the
    sort: its segment above a Morton code within it.  ``sample_part``: an int
    per sample of scratch (its partition node), free until the sort."""
    stride = -(-F // PART_SAMPLES)
    samples = -(-F // stride)
    limit = np.int32(max(1, samples // budget))     # a segment of more samples is split
    parts = ws.get("parts", layouts.BUILD_PART.itemsize * PART_MAX_NODES)
    bins = ws.get("part_bins", 4 * 7 * 3 * PART_BINS * PART_MAX_NODES)
    launch("partition", k["partition_clear"], _groups(max(PART_MAX_NODES * 3 * PART_BINS, samples)), bins,
           sample_part, np.uint32(samples))
    launch("partition", k["partition_init"], 1, parts, state, np.int32(samples), limit, group=1)
    k["partition_bin"].set_args(corners, np.uint32(samples), np.uint32(stride), sample_part, parts, bins, state)
    k["partition_split"].set_args(parts, bins, state, limit, np.int32(budget))
    k["partition_assign"].set_args(corners, np.uint32(samples), np.uint32(stride), sample_part, parts, state)
    groups = min(_groups(samples), MAX_REDUCE_GROUPS)    # grid-stride: each group pools its samples
    for _ in range(PART_LEVELS):
        launch("partition", k["partition_bin"], groups)
        launch("partition", k["partition_split"], 1)
        launch("partition", k["partition_assign"], groups)
    launch("partition", k["partition_order"], 1, parts, state, group=1)
    # (in the partition's phase: a phase's time spans its first launch to its last)
    launch("partition", k["partition_morton_codes"], _groups(F), corners, np.uint32(F), parts, keys, ids)


def _ploc(queue, k, launch, F, clusters, merged, tile_kept, tile_status, nodes, heights, state, leaf_size,
          tail_threshold, cpu: bool = False) -> int:
    """Queue PLOC iterations until at most ``tail_threshold`` clusters are
    left (ploc_tail does the rest); returns how many were queued.

    Iteration i's kernels read its cluster count from the state ring; the
    host queues a batch of iterations sized for the last count it read (an
    upper bound: counts only fall), then reads the count after the batch.
    On a GPU one launch of ploc_merge makes an iteration, from one cluster
    buffer into the other.  On a ``cpu`` device,
    ploc_merge_tiles writes every place's cluster into ``merged`` and
    ploc_compact moves the kept ones back into ``clusters`` (build_ploc_cpu.cl
    says why).
    """
    ring = STATE["COUNT_RING"]
    known = F                         # clusters before iteration `iteration` (at most)
    iteration = 0
    count = np.empty(1, np.int32)
    buffers = (clusters, merged)
    while known > max(tail_threshold, 1):
        batch = max(1, math.ceil(math.log(known / max(tail_threshold, 1)) / -math.log(MIN_SHRINK)))
        batch = min(batch, ring - 1)  # the ring holds the counts of one batch
        for _ in range(batch):
            groups = _groups(known)
            if not cpu:
                k["ploc_merge"].set_args(buffers[iteration % 2], buffers[1 - iteration % 2], tile_status, nodes,
                                         heights, F, state, iteration, leaf_size)
                launch("ploc", k["ploc_merge"], groups)
                iteration += 1
                continue
            # a few work-items a core, striding over the tiles
            workers = min(groups, CPU_TILE_WORKERS * queue.device.max_compute_units)
            launch("ploc", k["ploc_merge_tiles"], workers, clusters, merged, tile_kept, state, iteration, group=1)
            k["ploc_compact"].set_args(merged, clusters, tile_kept, nodes, heights, F, state, iteration, leaf_size)
            launch("ploc", k["ploc_compact"], workers, group=1)
            iteration += 1
        cl.enqueue_copy(queue, count, state, src_offset=4 * (STATE["STATE_COUNTS"] + iteration % ring),
                        is_blocking=True)
        if int(count[0]) >= known:    # every iteration merges at least one pair
            raise RuntimeError("device BVH build: PLOC did not converge")
        known = int(count[0])
    return iteration

