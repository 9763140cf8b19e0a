"""The top level of a scene of instances, built on the device: the instance
table computed from the transforms, and a linear BVH over the instances'
world boxes (build_instances.cl, in the device builder's program; docs/instances.md).

    >>> top = DeviceTopLevel(context, table, mesh_bounds, mesh_origins, "box")
    >>> last = top.place(transforms, checked)     # the table and rows, in top's buffers
    >>> table, acceleration = top.read()          # host copies (the first build; statistics)
    >>> top.set_mesh_frame(k, bounds, origin)     # mesh k refitted: its box and origin for the next place

What it is for: moving instances (clrt.device.instances.move_instances)
rebuilds only the table and the top level, and their host part must be
tiny -- the transforms' upload, the launches
(fourteen on a GPU) queued at once, the device choosing the world's frame
itself, one read of a dozen numbers for the host's checks.  The host's twin is clrt.accel.instances
(instance_table, the same rows bit for bit; top_level, a binned SAH tree):
a scene built with a host builder moves there.

The table, the rows and all their scratch (the sort's keys, ids and state
too) are this object's own, and so are its kernel objects, whose arguments
are set once (_LaunchSites): a place() takes no lock of the builder's.
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from clrt.accel import Acceleration
from clrt.accel.instances import lbvh_depth_bound, top_rows
from clrt.accel.rows import child_refs, tree_levels
from clrt.device.build import (BUILD_GROUP, GROUP_RESULTS, MAX_REDUCE_GROUPS, STATE_INTS, build_defines,
                               queue_sort)
from clrt.device.build_kernels import BUILD_KERNELS, top_level_kernels, Workspace, build_queue
from clrt.device.context import device_kind
from clrt.device.program import build_program
from clrt.device.signature import typed_kernels
from clrt.layouts import BVH_PAIR_NODE, INSTANCE
from clrt.scene import arrays

# (The copy of the moved transforms takes one thread: 10k instances moved in
# 0.82 ms so on the H200, 0.98 with the copies on two threads, 1.18 on four,
# 1.58 on eight -- the pool's hand-offs cost more than the 1.28 MB copies they
# split; 2026-12-02.)

# Phases of a place(), in order, as its timings name them.
PHASES = ("upload", "place", "rows", "sort", "nodes", "fit")


def _groups(n: int) -> int:
    return max(-(-int(n) // BUILD_GROUP), 1)


class _LaunchSites:
    """The build kernels by name, as ``ws.kernels_of`` gives them, but a
    kernel object of its own for each launch of a place() in order (the
    sort launches one kernel eight times, with other arguments each pass):
    every place() of one top level makes the same launches with the same
    arguments -- its own buffers, the same count -- so each object's
    arguments are set at the first and kept (``bound``).  A move is a dozen
    launches, and setting their arguments anew was a good part of its host
    time."""

    def __init__(self, program: cl.Program, defines: dict):
        self.program, self.defines = program, defines
        self.kernels: list[cl.Kernel] = []
        self.next = 0

    def __getitem__(self, name: str) -> cl.Kernel:
        if self.next == len(self.kernels):
            kernel = typed_kernels(self.program, BUILD_KERNELS, self.defines)[name]
            kernel.bound, kernel.site_name = False, name
            self.kernels.append(kernel)
        kernel = self.kernels[self.next]
        assert kernel.site_name == name, "a place() launched other kernels than the last"
        self.next += 1
        return kernel


class DeviceTopLevel:
    """The instance table and top level of one scene of instances on
    ``context``: ``table`` (I,) INSTANCE whose mesh, root, first, count and
    material the scene keeps (the rest is computed here); the meshes' boxes
    ``mesh_bounds`` (M, 2, 3) and device origins ``mesh_origins`` (M, 3), as
    clrt.accel.instances.instance_table takes them (set_mesh_frame: a
    refitted mesh's anew); ``volume`` the BVH's shape.  Buffers:
    ``table``, ``rows`` (top_rows(I) BVH_PAIR_NODE) and ``exact_rows``
    (their exact boxes, box layout), written by each place()."""

    def __init__(self, context: cl.Context, table: np.ndarray, mesh_bounds: np.ndarray,
                 mesh_origins: np.ndarray, volume: str):
        self.context, self.volume, self.count = context, volume, len(table)
        device = context.devices[0]
        self.kind = device_kind(device)
        self.defines = build_defines(volume, self.kind)
        self.program = build_program(context, "build_bvh.cl", self.defines,
                                     kernels=top_level_kernels(self.kind))
        meshes = np.zeros((len(mesh_bounds), 3, 4))
        meshes[:, :2, :3], meshes[:, 2, :3] = mesh_bounds, mesh_origins
        mf, n = cl.mem_flags, self.count
        self.meshes = cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=meshes)
        self.mesh_of = cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=table["mesh"].astype(np.int32))
        self.table = cl.Buffer(context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(table))
        self.transforms = cl.Buffer(context, mf.READ_ONLY, 128 * n)
        self.groups = min(_groups(n), MAX_REDUCE_GROUPS)
        self.group_results = cl.Buffer(context, mf.READ_WRITE, 8 * GROUP_RESULTS * self.groups)
        self.results = np.empty((self.groups, GROUP_RESULTS))
        self.frame = cl.Buffer(context, mf.READ_WRITE, 48)
        self.summary = cl.Buffer(context, mf.READ_WRITE, 8 * 12)
        self.summary_host = np.zeros(12)
        # Scratch of its own (the sort's keys, ids and state): the builder's
        # grow and go, and the launch sites keep their arguments.
        self.scratch = Workspace(context)
        self.sites = _LaunchSites(self.program, self.defines)
        self.num_rows = top_rows(n)
        self.rows = cl.Buffer(context, mf.READ_WRITE, self.num_rows * BVH_PAIR_NODE.itemsize)
        self.exact_rows = cl.Buffer(context, mf.READ_WRITE, self.num_rows * BVH_PAIR_NODE.itemsize)
        self.children = cl.Buffer(context, mf.READ_WRITE, 8 * max(n - 1, 1))
        self.parents = cl.Buffer(context, mf.READ_WRITE, 4 * (2 * n - 1))
        self.boxes = cl.Buffer(context, mf.READ_WRITE, 32 * (2 * n - 1))
        self.arrivals = cl.Buffer(context, mf.READ_WRITE, 4 * max(n - 1, 1))
        # The transforms are uploaded from the caller's memory (the driver
        # stages them): a copy into page-locked memory first, whose DMA is
        # three times faster, took longer in all for 1.28 MB (10k instances:
        # a move in 0.83 ms so on the H200, 0.78 without; 2026-12-02).
        self.source = np.empty((n, 4, 4))     # the last place's transforms
        self.last: cl.Event | None = None
        self.writes = ()
        self.place_ms = 0.0     # host ms of the last place() (its launches queued, not done)
        self.depth_bound = lbvh_depth_bound(n)

    def set_mesh_frame(self, mesh: int, bounds: np.ndarray, origin: np.ndarray) -> None:
        """Mesh ``mesh``'s box ``bounds`` ((2, 3), its own frame) and device
        origin ``origin`` (3,) anew, for the next place(): its vertices were
        refitted (clrt.device.instances.refit_meshes).  Written before this
        returns, behind every place() queued."""
        row = np.zeros((3, 4))
        row[:2, :3], row[2, :3] = bounds, origin
        queue = build_queue(self.context, self.context.devices[0])
        cl.enqueue_copy(queue, self.meshes, row, dst_offset=row.nbytes * int(mesh), is_blocking=True)

    def place(self, transforms: np.ndarray, checked, queue: cl.CommandQueue | None = None,
              timings: dict | None = None) -> cl.Event:
        """Build the table and the top level for ``transforms`` ((I, 4, 4),
        object -> world) into this object's buffers; returns the last launch's
        event (nothing waits for it here).

        Every launch is queued at once: the device chooses the world's frame
        itself (instance_frame, as the host's device_origin).  Then the host
        waits for the summary of the first pass -- the device goes on with the
        rest -- and calls ``checked(recheck, far, bounds, origin)`` with the
        first instance whose transform it must check
        (clrt.accel.instances.to_recheck; None if none), the first placed
        past MAX_COORDINATE (or None), the instances' world box ((2, 3)
        float64, the caller's frame) and the world's device origin ((3,)
        float64); it may raise -- then this object's buffers hold the refused
        placement (the caller places the last good one again), the scene's
        are untouched.

        ``queue``: a queue with profiling to run on (benchmarks; ``timings``
        then gets each phase's device ms, PHASES), else the context's build
        queue.  ``timings`` also gets host ms: "host" (the copy of the
        transforms, the launches' queueing, the checks) and "wait" (for the
        summary)."""
        n = self.count
        profiled = queue is not None
        queue = queue if profiled else build_queue(self.context, self.context.devices[0])
        events = {phase: [] for phase in PHASES}

        def launch(phase, kernel, groups, *args, group=BUILD_GROUP):
            if not kernel.bound:
                kernel.set_args(*args)
                kernel.bound = True
            event = cl.enqueue_nd_range_kernel(queue, kernel, (groups * group,), (group,))
            events[phase].append(event)
            return event

        ws = self.scratch
        start = time.perf_counter()
        k = self.sites
        k.next = 0
        state = ws.get("state", 4 * STATE_INTS)
        keys = [ws.get("keys0", 4 * n), ws.get("keys1", 4 * n)]
        ids = [ws.get("ids0", 4 * n), ws.get("ids1", 4 * n)]
        self.source = np.ascontiguousarray(transforms, np.float64)
        upload = cl.enqueue_copy(queue, self.transforms, self.source, is_blocking=False)
        events["upload"].append(upload)
        launch("place", k["place_instances"], self.groups, self.transforms, self.mesh_of, self.meshes,
               np.uint32(n), self.group_results, state)
        frame_kernel = k["instance_frame"]
        frame_kernel.bound = False     # its arguments each time: RECENTRE_DISTANCE may change (tests)
        launch("place", frame_kernel, 1, self.group_results, np.uint32(self.groups),
               np.float64(arrays.RECENTRE_DISTANCE), self.frame, self.summary, group=1)
        summary = cl.enqueue_copy(queue, self.summary_host, self.summary, is_blocking=False)
        launch("rows", k["instance_rows"], _groups(n), self.transforms, self.mesh_of, self.meshes,
               self.frame, np.uint32(n), self.table, keys[0], ids[0], self.arrivals)
        sorted_ids = ids[0]
        if n > 1:
            sorted_ids = queue_sort(k, launch, ws, self.kind, n, keys, ids, state)
            launch("nodes", k["lbvh_nodes"], _groups(n - 1), keys[0], np.uint32(n), self.children,
                   self.parents)
        last = launch("fit", k["lbvh_fit"], _groups(n), self.children, self.parents, sorted_ids, self.table,
                      np.uint32(n), self.boxes, self.arrivals, self.rows, self.exact_rows)
        queue.flush()
        queued = time.perf_counter()
        summary.wait()
        waited = time.perf_counter()
        self.last = last
        self.writes = (upload,)   # (pyopencl waits for a write from host memory when its event goes)
        r = self.summary_host
        try:
            checked(*[int(f) if f < n else None for f in r[9:11]], r[0:6].reshape(2, 3).copy(), r[6:9].copy())
        finally:
            self.place_ms = 1e3 * (time.perf_counter() - start)
            if timings is not None:
                timings["host"] = 1e3 * ((queued - start) + (time.perf_counter() - waited))
                timings["wait"] = 1e3 * (waited - queued)
        # (the next place's launches reuse the scratch: on the build queue
        # they queue behind these; a queue of the caller's is waited for)
        if profiled:
            last.wait()
            if timings is not None:
                for phase, done in events.items():
                    timings[phase] = 1e-6 * sum(e.profile.end - e.profile.start for e in done)
        return last

    def transforms_copy(self) -> np.ndarray:
        """A copy of the transforms of the last place(), (I, 4, 4) float64."""
        return self.source.copy()

    def read(self) -> tuple[np.ndarray, Acceleration]:
        """Host copies of the last place(): the table (I,) INSTANCE, and the
        top level's Acceleration (its rows; ``prim_ids`` the instances in
        leaf order; its depth; the exact rows for statistics)."""
        queue = build_queue(self.context, self.context.devices[0])
        table = np.empty(self.count, INSTANCE)
        rows = np.empty(self.num_rows, BVH_PAIR_NODE)
        exact = np.empty(self.num_rows, BVH_PAIR_NODE)
        wait = [self.last] if self.last is not None else None
        cl.enqueue_copy(queue, table, self.table, wait_for=wait)
        cl.enqueue_copy(queue, rows, self.rows, wait_for=wait)
        cl.enqueue_copy(queue, exact, self.exact_rows, wait_for=wait, is_blocking=True)
        refs = child_refs(rows)
        leaves = np.stack([refs[:, 0], refs[:, 2]], axis=1)[np.stack([refs[:, 1], refs[:, 3]], axis=1) == 1]
        depth = 1 if self.count == 1 else len(tree_levels(rows)) + 1
        top = Acceleration(self.volume, "device", rows, leaves.astype(np.int32), depth=depth,
                           build_ms=self.place_ms, leaf_size=1, exact_rows=exact)
        return table, top
