"""Triangles and their acceleration structure, uploaded to one OpenCL device.

This is the part of a scene that ray queries need (``closest_hit`` and
``any_hit`` in the kernels); the renderer and the batch ray queries share it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from clrt.device import layouts
from clrt.device.context import format_bytes
from clrt.errors import DeviceMemoryError, InputError

ACCELS = ("none", "box", "sphere", "ellipse")
_DEFINE_OF_VOLUME = {"box": "VOLUME_BOX", "sphere": "VOLUME_SPHERE", "ellipse": "VOLUME_ELLIPSE"}


@dataclass
class SlotOrder:
    """The triangles in the order the kernels walk them, and how that order came about."""

    tri_verts: np.ndarray     # (F,) TRIANGLE_VERTS in slot order
    prim_ids: np.ndarray      # (F,) int32: input triangle index of each slot
    nodes: np.ndarray         # (N,) BVH_PAIR_NODE (one unused node without a BVH)
    defines: dict             # program build options that select the traversal
    bvh: object | None        # clrt.accel.bvh.Bvh, or None for brute force
    build_ms: float


def order_triangles(tri_verts: np.ndarray, accel: str = "box", builder: str = "sah",
                    leaf_size: int = 4) -> SlotOrder:
    """Build the acceleration structure (or none) over ``tri_verts`` (input order)."""
    if accel not in ACCELS:
        raise InputError(f"unknown accel {accel!r}: choose one of {', '.join(ACCELS)}")
    start = time.perf_counter()
    if accel == "none":
        return SlotOrder(tri_verts, np.arange(len(tri_verts), dtype=np.int32),
                         np.zeros(1, layouts.BVH_PAIR_NODE), {}, None, 0.0)
    from clrt.accel import build_bvh
    corners = np.stack([tri_verts[k][:, :3] for k in ("v0", "v1", "v2")], axis=1)
    bvh = build_bvh(corners, volume=accel, builder=builder, leaf_size=leaf_size)
    prim_ids = np.ascontiguousarray(bvh.prim_id, dtype=np.int32)
    defines = {"ACCEL_BVH": None, _DEFINE_OF_VOLUME[accel]: None, "BVH_STACK_SIZE": max(int(bvh.depth), 1)}
    return SlotOrder(tri_verts[prim_ids], prim_ids, pair_nodes(bvh.nodes, accel), defines, bvh,
                     1e3 * (time.perf_counter() - start))


def pair_nodes(nodes: np.ndarray, volume: str = "box") -> np.ndarray:
    """BVH_NODE rows (depth-first, root at 0) of a tree of ``volume``s ->
    BVH_PAIR_NODE rows, one per inner node, each holding both children's volumes
    and references (see layouts.py)."""
    inner = np.nonzero(nodes["count"] == 0)[0]
    if len(inner) == 0:   # the whole tree is one leaf: hang it on the left of a root row
        pair = np.zeros(1, layouts.BVH_PAIR_NODE)
        _set_child(pair, "left", nodes[:1], nodes["left_first"][:1], volume)
        pair_child_refs(pair)[:, 2:] = -1        # no right child
        return pair
    row = np.full(len(nodes), -1, np.int64)
    row[inner] = np.arange(len(inner))      # the root (node 0) is inner: row 0
    pair = np.zeros(len(inner), layouts.BVH_PAIR_NODE)
    for side, child in (("left", nodes["left_first"][inner]), ("right", nodes["right"][inner])):
        leaf = nodes["count"][child] > 0
        _set_child(pair, side, nodes[child], np.where(leaf, nodes["left_first"][child], row[child]), volume)
    return pair


def pair_child_refs(pair: np.ndarray) -> np.ndarray:
    """(N, 4) int32 view of the rows' child references: left, left_count, right,
    right_count (the w lanes of left_a, left_b, right_a, right_b)."""
    return pair.view(np.int32).reshape(len(pair), 16)[:, 3::4]


def _set_child(pair: np.ndarray, side: str, child: np.ndarray, ref: np.ndarray, volume: str) -> None:
    """Write one side of rows: the child's volume (xyz lanes) and reference (w lanes)."""
    pair[f"{side}_a"][:, :3] = child["bound_a"][:, :3]
    if volume == "sphere":   # the radius leaves bound_a.w, which holds the reference here
        pair[f"{side}_b"][:, 0] = child["bound_a"][:, 3]
    else:
        pair[f"{side}_b"][:, :3] = child["bound_b"][:, :3]
    refs = pair_child_refs(pair)
    k = 0 if side == "left" else 2
    refs[:, k] = ref
    refs[:, k + 1] = child["count"]


MAX_PARTS = 4   # parts per split buffer: the SPLIT_PARAMS of split.cl


class DeviceGeometry:
    """Uploaded slot-ordered triangles, BVH nodes and slot -> triangle ids, and
    any further per-slot or per-vertex ``extra`` arrays the kernels index (the
    renderer's shading data), by their kernel parameter names.

    A buffer larger than the device's largest allocation is uploaded in parts
    (see split.cl): then every buffer here is, and ``defines`` says so to the
    program build.  ``max_buffer_bytes`` lowers the limit below the device's
    (tests and benchmarks use it to split small scenes).
    """

    max_buffer_bytes: int | None = None

    def __init__(self, context: cl.Context, order: SlotOrder, extra: dict | None = None):
        self.order = order
        arrays = {"tris": order.tri_verts, "nodes": order.nodes, "prim_ids": order.prim_ids, **(extra or {})}
        arrays = {name: np.ascontiguousarray(a) for name, a in arrays.items()}
        limit = min(d.max_mem_alloc_size for d in context.devices)
        if self.max_buffer_bytes is not None:
            limit = min(limit, int(self.max_buffer_bytes))
        self.shifts = part_shifts(arrays, limit)
        self.defines = {} if self.shifts is None else {
            "SPLIT_BUFFERS": None, **{f"{name}_PART_SHIFT": shift for name, shift in self.shifts.items()}}
        mf = cl.mem_flags

        def upload(array):
            return cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=array)

        self.buffers: dict[str, tuple] = {}
        for name, array in arrays.items():
            if self.shifts is None:
                self.buffers[name] = (upload(array),)
                continue
            step = 1 << self.shifts[name]
            parts = [upload(array[k:k + step]) for k in range(0, max(len(array), 1), step)]
            self.buffers[name] = tuple(parts + parts[-1:] * (MAX_PARTS - len(parts)))
        self.num_tris = np.uint32(len(order.tri_verts))
        self.nbytes = sum(a.nbytes for a in arrays.values())

    @property
    def args(self) -> tuple:
        """Kernel arguments matching ACCEL_PARAMS in accel.cl."""
        b = self.buffers
        return (*b["tris"], self.num_tris, *b["nodes"], *b["prim_ids"])

    def parts(self) -> int:
        """Buffers of the largest split array (1: nothing split)."""
        return max(len(set(b)) for b in self.buffers.values())


def part_shifts(arrays: dict, limit: int) -> dict | None:
    """None when every array fits in one buffer of ``limit`` bytes, else per array
    log2 of the elements per part: the most whole elements, a power of two
    (the kernels find the part with a shift), that fit in ``limit``.
    DeviceMemoryError when an array needs more than MAX_PARTS parts."""
    if all(a.nbytes <= limit for a in arrays.values()):
        return None
    shifts = {}
    for name, a in arrays.items():
        row = max(a[:1].nbytes, 1) if len(a) else a.itemsize
        per_part = limit // row
        if per_part < 1:
            raise DeviceMemoryError(f"one element of the {name} buffer ({row} B) exceeds the "
                                    f"largest allocation of {format_bytes(limit)}")
        shift = min(int(per_part).bit_length() - 1, 30)
        if -(-len(a) // (1 << shift)) > MAX_PARTS:
            raise DeviceMemoryError(
                f"the {name} buffer needs {format_bytes(a.nbytes)}, more than {MAX_PARTS} buffers of at "
                f"most {format_bytes(limit)} (the device's largest allocation) can hold")
        shifts[name] = shift
    return shifts
