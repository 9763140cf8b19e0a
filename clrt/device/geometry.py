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
from clrt.errors import InputError

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
    return SlotOrder(tri_verts[prim_ids], prim_ids, pair_nodes(bvh.nodes), defines, bvh,
                     1e3 * (time.perf_counter() - start))


def pair_nodes(nodes: np.ndarray) -> np.ndarray:
    """BVH_NODE rows (depth-first, root at 0) -> BVH_PAIR_NODE rows, one per inner
    node, each holding both children's volumes (see layouts.py)."""
    inner = np.nonzero(nodes["count"] == 0)[0]
    if len(inner) == 0:   # the whole tree is one leaf: hang it on the left of a root row
        pair = np.zeros(1, layouts.BVH_PAIR_NODE)
        pair["left_a"], pair["left_b"] = nodes["bound_a"][0], nodes["bound_b"][0]
        pair["left"], pair["left_count"] = nodes["left_first"][0], nodes["count"][0]
        pair["right"], pair["right_count"] = -1, -1
        return pair
    row = np.full(len(nodes), -1, np.int64)
    row[inner] = np.arange(len(inner))      # the root (node 0) is inner: row 0
    pair = np.zeros(len(inner), layouts.BVH_PAIR_NODE)
    for side, child in (("left", nodes["left_first"][inner]), ("right", nodes["right"][inner])):
        pair[f"{side}_a"] = nodes["bound_a"][child]
        pair[f"{side}_b"] = nodes["bound_b"][child]
        leaf = nodes["count"][child] > 0
        pair[side] = np.where(leaf, nodes["left_first"][child], row[child])
        pair[f"{side}_count"] = nodes["count"][child]
    return pair


class DeviceGeometry:
    """Uploaded slot-ordered triangles, BVH nodes and slot -> triangle ids."""

    def __init__(self, context: cl.Context, order: SlotOrder):
        self.order = order
        mf = cl.mem_flags

        def upload(array):
            return cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(array))

        self.tris = upload(order.tri_verts)
        self.nodes = upload(order.nodes)
        self.prim_ids = upload(order.prim_ids)
        self.num_tris = np.uint32(len(order.tri_verts))
        self.nbytes = order.tri_verts.nbytes + order.nodes.nbytes + order.prim_ids.nbytes

    @property
    def args(self) -> tuple:
        """Kernel arguments matching ACCEL_PARAMS in accel.cl."""
        return (self.tris, self.num_tris, self.nodes, self.prim_ids)
