"""The top level of a scene of instances, built on the device: the instance
table computed from the transforms, and a linear BVH over the instances'
world boxes (build_instances.cl, in the device builder's program; docs/instances.md).

    >>> top = DeviceTopLevel(context, table, mesh_bounds, mesh_origins, "box")
    >>> last = top.place(transforms, frame_of)    # the table and rows, in top's buffers
    >>> table, acceleration = top.read()          # host copies (the first build; statistics)
    >>> top.set_mesh_frame(k, bounds, origin)     # mesh k refitted: its box and origin for the next place

What it is for: moving instances (clrt.device.instances.move_instances)
rebuilds only the table and the top level, and their host part must be
tiny -- one copy of the transforms into page-locked memory, one read of a
few hundred numbers between the two passes, the launches (thirteen on a GPU),
one wait at the end.  The host's twin is clrt.accel.instances
(instance_table, the same rows bit for bit; top_level, a binned SAH tree):
a scene built with a host builder moves there.

A place() holds the device builder's lock of the context (it shares the
builder's scratch buffers: the state, the sort's keys and ids); the table,
the rows and their scratch are this object's own.
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
from clrt.device.build_kernels import CPU_TOP_LEVEL_KERNELS, build_queue, workspace
from clrt.device.context import device_kind
from clrt.device.pinned import mapped_block
from clrt.device.program import build_program
from clrt.layouts import BVH_PAIR_NODE, INSTANCE

# Phases of a place(), in order, as its timings name them.
PHASES = ("upload", "place", "rows", "sort", "nodes", "fit")


def _groups(n: int) -> int:
    return max(-(-int(n) // BUILD_GROUP), 1)


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
                                     kernels=CPU_TOP_LEVEL_KERNELS if self.kind == "cpu" else None)
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
        self.frame = cl.Buffer(context, mf.READ_ONLY, 48)
        self.num_rows = top_rows(n)
        self.rows = cl.Buffer(context, mf.READ_WRITE, self.num_rows * BVH_PAIR_NODE.itemsize)
        self.exact_rows = cl.Buffer(context, mf.READ_WRITE, self.num_rows * BVH_PAIR_NODE.itemsize)
        self.children = cl.Buffer(context, mf.READ_WRITE, 8 * max(n - 1, 1))
        self.parents = cl.Buffer(context, mf.READ_WRITE, 4 * (2 * n - 1))
        self.boxes = cl.Buffer(context, mf.READ_WRITE, 32 * (2 * n - 1))
        self.arrivals = cl.Buffer(context, mf.READ_WRITE, 4 * max(n - 1, 1))
        # The transforms go through page-locked memory: the DMA reads it at
        # full speed, where a driver's own staging of ordinary memory runs at
        # a third of it (clrt.device.pinned).
        try:
            self.staged = mapped_block(context, build_queue(context, device), 128 * n).view(np.float64)
            self.staged = self.staged.reshape(n, 4, 4)
        except (cl.Error, MemoryError):    # page-locked memory is scarce: ordinary memory
            self.staged = np.empty((n, 4, 4))
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

    def place(self, transforms: np.ndarray, frame_of, queue: cl.CommandQueue | None = None,
              timings: dict | None = None) -> cl.Event:
        """Build the table and the top level for ``transforms`` ((I, 4, 4),
        object -> world) into this object's buffers; returns the last launch's
        event (nothing waits for it here).

        ``frame_of(recheck, far, bounds)`` is called between the passes, with
        the first instance whose transform the host must check
        (clrt.accel.instances.to_recheck; None if none), the first placed
        past MAX_COORDINATE (or None) and the instances' world box ((2, 3)
        float64, the caller's frame): it returns the world's device origin,
        or raises -- then only scratch has been written.

        ``queue``: a queue with profiling to run on (benchmarks; ``timings``
        then gets each phase's device ms, PHASES), else the context's build
        queue.  ``timings`` also gets host ms: "host" (the copy of the
        transforms, the launches' queueing, the frame) and "first pass" (the
        wait for the bounds)."""
        n = self.count
        profiled = queue is not None
        queue = queue if profiled else build_queue(self.context, self.context.devices[0])
        events = {phase: [] for phase in PHASES}

        def launch(phase, kernel, groups, *args, group=BUILD_GROUP):
            if args:
                kernel.set_args(*args)
            event = cl.enqueue_nd_range_kernel(queue, kernel, (groups * group,), (group,))
            events[phase].append(event)
            return event

        ws = workspace(self.context)
        with ws.lock:
            start = time.perf_counter()
            k = ws.kernels_of(self.program, self.defines)
            state = ws.get("state", 4 * STATE_INTS)
            keys = [ws.get("keys0", 4 * n), ws.get("keys1", 4 * n)]
            ids = [ws.get("ids0", 4 * n), ws.get("ids1", 4 * n)]
            np.copyto(self.staged, transforms)
            upload = cl.enqueue_copy(queue, self.transforms, self.staged, is_blocking=False)
            events["upload"].append(upload)
            launch("place", k["place_instances"], self.groups, self.transforms, self.mesh_of, self.meshes,
                   np.uint32(n), self.group_results, state)
            queued = time.perf_counter()
            cl.enqueue_copy(queue, self.results, self.group_results, is_blocking=True)
            read = time.perf_counter()
            r = self.results
            bounds = np.stack([r[:, 0:3].min(axis=0), r[:, 3:6].max(axis=0)])
            first = [int(r[:, 12 + j].min()) for j in range(2)]
            origin = np.asarray(frame_of(*[f if f < n else None for f in first], bounds), np.float64)
            # The Morton codes' box: the centres' bounds in the device's frame.
            frame = np.zeros((3, 4), np.float32)
            frame[0, :3] = origin
            frame[1, :3], frame[2, :3] = r[:, 6:9].min(axis=0) - origin, r[:, 9:12].max(axis=0) - origin
            # (pyopencl waits for a write from host memory when its event goes:
            # the writes' events stay until the next place, done by then.)
            self.writes = (upload, cl.enqueue_copy(queue, self.frame, frame, is_blocking=False))
            last = launch("rows", k["instance_rows"], _groups(n), self.transforms, self.mesh_of, self.meshes,
                          self.frame, np.uint32(n), self.table, keys[0], ids[0], self.arrivals)
            sorted_ids = ids[0]
            if n > 1:
                sorted_ids = queue_sort(k, launch, ws, self.kind, n, keys, ids, state)
                launch("nodes", k["lbvh_nodes"], _groups(n - 1), keys[0], np.uint32(n), self.children,
                       self.parents)
            last = launch("fit", k["lbvh_fit"], _groups(n), self.children, self.parents, sorted_ids, self.table,
                          np.uint32(n), self.boxes, self.arrivals, self.rows, self.exact_rows)
            self.last = last
            self.place_ms = 1e3 * (time.perf_counter() - start)
            if timings is not None:
                timings["host"] = 1e3 * ((queued - start) + (time.perf_counter() - read))
                timings["first pass"] = 1e3 * (read - queued)
            # The next build on this context reuses the keys and ids: on the
            # build queue its launches queue behind these (and the callers
            # wait for the end before they return); a queue of the caller's
            # is waited for here.
            if profiled:
                last.wait()
                if timings is not None:
                    for phase, done in events.items():
                        timings[phase] = 1e-6 * sum(e.profile.end - e.profile.start for e in done)
        return last

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
