"""The wide BVH of CPU devices (clrt/accel/wide.py) collapsed on the device
from a tree the device built (kernels in clrt/kernels/build_wide.cl, part of
the device builder's program).

    >>> wide = collapse_on_device(context, queue, bvh.rows, bvh.num_rows, bvh.tri_verts, bvh.kernels)
    >>> wide.buffer, wide.packets_at        # nodes then packets, ready for accel_wide.cl
    >>> wide.nodes, wide.packets, wide.sources   # host copies, read when first asked for

The same nodes and packets, bit for bit, as clrt.accel.wide.collapse makes on
the host from the rows read back (tests/test_wide_build.py): on 2 cores the
host's collapse took 26 of the 100 ms of bunny00's ``Accel``, and the rows and
slot-ordered triangles had to be read back and the result uploaded; here the
rows and triangles stay where the build left them.  The host reads four ints
between the two launches (the sizes of the nodes and packets) and makes the
buffer to fit.
"""

from __future__ import annotations

import functools

import numpy as np
import pyopencl as cl

from clrt.accel.wide import WIDE, fill_boxes, fill_packets
from clrt.device.build import BUILD_GROUP, build_defines, device_kind
from clrt.device.build_kernels import launched_kernels, one_build_per_context, workspace
from clrt.device.program import build_program
from clrt.layouts import BVH_WIDE_NODE, TRIANGLE_PACKET

WIDE_STATE_INTS = 4       # wide_plan's counts: nodes, leaves, packets, levels (build_wide.cl)


def wide_kernels(context: cl.Context) -> dict:
    """The device builder's kernels (its program holds the collapse's) as a
    box build on the context's CPU device has them."""
    defines = build_defines("box", device_kind(context.devices[0]))
    return workspace(context).kernels_of(build_program(context, "build_bvh.cl", defines,
                                                       kernels=launched_kernels("cpu", wide=True)), defines)


class DeviceWideBvh:
    """A wide BVH on the device: ``buffer`` holds ``num_nodes`` BVH_WIDE_NODE
    and from byte ``packets_at`` on ``num_packets`` TRIANGLE_PACKET; ``depth``
    as clrt.accel.wide.WideBvh's.  ``nodes``, ``packets`` and ``sources``
    (that class's fields) are read back when first asked for (point queries,
    a refit)."""

    def __init__(self, queue: cl.CommandQueue, buffer: cl.Buffer, sources: cl.Buffer, num_nodes: int,
                 num_packets: int, depth: int):
        self.queue, self.buffer, self._sources = queue, buffer, sources
        self.num_nodes, self.num_packets, self.depth = num_nodes, num_packets, depth
        self.packets_at = num_nodes * BVH_WIDE_NODE.itemsize

    @property
    def nbytes(self) -> int:
        return self.packets_at + self.num_packets * TRIANGLE_PACKET.itemsize

    @functools.cached_property
    def nodes(self) -> np.ndarray:
        nodes = np.empty(self.num_nodes, BVH_WIDE_NODE)
        cl.enqueue_copy(self.queue, nodes, self.buffer, is_blocking=True)
        return nodes

    @functools.cached_property
    def packets(self) -> np.ndarray:
        packets = np.empty(self.num_packets, TRIANGLE_PACKET)
        cl.enqueue_copy(self.queue, packets, self.buffer, src_offset=self.packets_at, is_blocking=True)
        return packets

    @functools.cached_property
    def sources(self) -> np.ndarray:
        sources = np.empty((self.num_nodes, WIDE), np.int32)
        cl.enqueue_copy(self.queue, sources, self._sources, is_blocking=True)
        return sources.astype(np.int64)

    def refit(self, rows: np.ndarray, slotted: np.ndarray) -> None:
        """As clrt.accel.wide.WideBvh.refit, on the host copies (the caller uploads them)."""
        fill_boxes(self.nodes, self.sources, rows)
        fill_packets(self.packets, slotted)


@one_build_per_context
def collapse_on_device(context: cl.Context, queue: cl.CommandQueue, rows: cl.Buffer, num_rows: int,
                       tris: cl.Buffer, kernels: dict | None = None, fits=None) -> DeviceWideBvh:
    """The wide BVH of ``num_rows`` BVH_PAIR_NODE rows (box volumes) in
    ``rows`` over the slot-ordered TRIANGLE_VERTS in ``tris``, on the queue's
    device; complete when this returns.  ``kernels``: the device builder's
    (clrt.device.build.DeviceBvh.kernels; default :func:`wide_kernels`).
    ``fits``: called with the wide BVH's bytes before its buffer is made
    (DeviceGeometry's memory check).  Builds take turns with the device
    builder's on the context (they share its scratch buffers)."""
    if kernels is None or not kernels.compiled("wide_plan"):   # (a GPU's tree built on this CPU: as-gpu)
        kernels = wide_kernels(context)
    ws = workspace(context)
    R = max(int(num_rows), 1)
    budgets = WIDE + 1
    # A wide node per row at most, a leaf per binary leaf (R + 1) at most.
    lanes = ws.get("wide_lanes", 16 * WIDE * R)
    leaves = ws.get("wide_leaves", 16 * (R + 1))
    state = ws.get("wide_state", 4 * WIDE_STATE_INTS)
    kernels["wide_plan"].set_args(rows, np.int32(R), ws.get("wide_cost", 8 * budgets * R),
                                  ws.get("wide_choice", budgets * R), ws.get("wide_best", R),
                                  ws.get("wide_subtree", 8 * R), ws.get("wide_node_rows", 4 * R),
                                  ws.get("wide_stack", 8 * (R + 2)), lanes, leaves, state)
    cl.enqueue_nd_range_kernel(queue, kernels["wide_plan"], (1,), (1,))
    counts = np.empty(WIDE_STATE_INTS, np.int32)
    cl.enqueue_copy(queue, counts, state, is_blocking=True)
    num_nodes, num_leaves, num_packets, depth = (int(c) for c in counts)
    nbytes = num_nodes * BVH_WIDE_NODE.itemsize + num_packets * TRIANGLE_PACKET.itemsize
    if fits is not None:
        fits(nbytes)
    wide = cl.Buffer(context, cl.mem_flags.READ_WRITE, nbytes)
    sources = cl.Buffer(context, cl.mem_flags.READ_WRITE, 4 * WIDE * num_nodes)
    items = -(-max(num_nodes, num_leaves) // BUILD_GROUP) * BUILD_GROUP
    kernels["wide_write"].set_args(rows, tris, lanes, leaves, np.int32(num_nodes), np.int32(num_leaves), wide,
                                   np.uint64(num_nodes * BVH_WIDE_NODE.itemsize), sources)
    cl.enqueue_nd_range_kernel(queue, kernels["wide_write"], (items,), (BUILD_GROUP,)).wait()
    return DeviceWideBvh(queue, wide, sources, num_nodes, num_packets, depth)
