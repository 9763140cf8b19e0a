"""The two-level acceleration structure of a scene of instances
(docs/instances.md): bottom-level BVHs, one per distinct mesh, concatenated;
the instance table; a top-level BVH over the instances' world boxes.

    >>> table, boxes = instance_table(instances, mesh_origins, origin)
    >>> two = assemble(bottoms, instances, table, boxes, corners, "box")
    >>> two.rows, two.prim_ids, two.instances      # ready for upload (DeviceGeometry)

The bottom levels are built elsewhere (any builder: clrt.device.acceleration
builds them, one mesh at a time); here they are only joined: every child
reference is made global (a row index counts from the first row of the whole
buffer, a leaf's first slot from the first slot), the top level's rows first.
The top level is built here, on the host: binned SAH (sah.py) over the
instances' boxes, one instance a leaf, whose reference is then rewritten to
the instance's own index.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from clrt.accel import build
from clrt.accel.bvh import Acceleration
from clrt.accel.rows import child_refs
from clrt.accel.volumes import round_down32, round_up32
from clrt.config import INSTANCE_MIRROR
from clrt.errors import InputError
from clrt.layouts import BVH_PAIR_NODE, INSTANCE
from clrt.scene.instances import Instances, mapped_boxes

# The world box of an instance is padded by this times the transform's
# condition number times the box's size and distance from the device origin
# (its largest coordinate): the move of a ray into object space rounds its
# origin and direction by a few float32 ulps of their size (mapped back into
# the world, times the condition number), so an object-space hit may lie that
# far outside the exact world box -- this keeps such a ray in the box (2^-20 =
# 16 ulps, for rays that start within the scene's box; docs/instances.md).
INSTANCE_BOX_PAD = 2.0 ** -20


@dataclass
class TwoLevel(Acceleration):
    """An Acceleration of a scene of instances: ``rows`` the top level's then
    each mesh's (every reference global), ``prim_ids`` each slot's row in its
    own mesh's faces, and beside them:

    instances: (I,) ``INSTANCE`` (clrt/layouts.py), in the caller's order.
    top:       the top level's Acceleration (its rows are the first of ``rows``;
               None without a BVH).
    bottoms:   each distinct mesh's Acceleration, as built (own references).
    order:     (S,) int64, the row of the meshes' concatenated corners (input
               order, mesh after mesh) that each slot holds.
    move_ms:   host milliseconds of the last move of the instances (:func:`move`
               with its instance table and upload: clrt.device.instances), 0 before.
    """

    instances: np.ndarray = field(repr=False, default=None)
    top: Acceleration | None = field(repr=False, default=None)
    bottoms: list = field(repr=False, default_factory=list)
    order: np.ndarray = field(repr=False, default=None)
    move_ms: float = 0.0

    def slot_order(self) -> np.ndarray:
        return self.order

    def device_bytes(self) -> int:
        return super().device_bytes() + int(self.instances.nbytes)

    def stats(self) -> dict:
        """The top level's numbers (None without a BVH), the instances and meshes
        counted, each mesh's numbers, build time and device bytes."""
        return {"instances": int(len(self.instances)), "meshes": len(self.bottoms),
                "top": self.top.stats() if self.top is not None else None,
                "bottoms": [b.stats() for b in self.bottoms], "depth": int(self.depth),
                "build_ms": float(self.build_ms), "device_bytes": self.device_bytes()}


def instance_table(instances: Instances, mesh_origins: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The INSTANCE rows of ``instances`` but their mesh's place (root, first,
    count: :func:`assemble`): the transforms between each mesh's device frame
    (its vertices moved by ``-mesh_origins[m]``) and the world's (moved by
    ``-origin``), computed in float64, each rounded to float32 once; the world
    boxes, padded (INSTANCE_BOX_PAD) and rounded outwards; the mirror flag."""
    mesh_of = instances.mesh_of
    to_world = instances.transforms.copy()
    linear = to_world[:, :3, :3]
    # p_world - origin = A (p_dev + c) + b - origin
    to_world[:, :3, 3] += np.einsum("nij,nj->ni", linear, mesh_origins[mesh_of]) - origin
    to_object = np.linalg.inv(to_world)
    mesh_boxes = np.stack([m.bounds for m in instances.meshes]).astype(np.float64) - mesh_origins[:, None]
    boxes = mapped_boxes(to_world, mesh_boxes[mesh_of])
    singular = np.linalg.svd(linear, compute_uv=False)
    condition = singular[:, 0] / singular[:, 2]
    size = np.linalg.norm(boxes[:, 1] - boxes[:, 0], axis=1) + np.abs(boxes).max(axis=(1, 2))
    pad = (INSTANCE_BOX_PAD * condition * size)[:, None]
    table = np.zeros(len(instances), INSTANCE)
    table["to_world"] = to_world[:, :3].astype(np.float32)
    table["to_object"] = to_object[:, :3].astype(np.float32)
    table["lo"][:, :3] = round_down32(boxes[:, 0] - pad)
    table["hi"][:, :3] = round_up32(boxes[:, 1] + pad)
    table["mesh"] = mesh_of
    table["flags"] = np.where(np.linalg.det(linear) < 0.0, INSTANCE_MIRROR, 0)
    table["min_scale"] = round_down32(singular[:, 2] * (1.0 - 2.0 ** -20))
    return table


def top_level(table: np.ndarray, accel: str) -> Acceleration:
    """The top-level BVH over the instances' boxes (binned SAH, one instance a
    leaf), each leaf's reference rewritten to its instance's row of ``table``."""
    lo, hi = table["lo"][:, :3], table["hi"][:, :3]
    # A "triangle" (lo, hi, lo) has exactly the box as its bounds and its centre as
    # SAH's key: the builders see boxes and centres only.
    top = build(np.stack([lo, hi, lo], axis=1), accel, "sah", leaf_size=1)
    refs = child_refs(top.rows)
    for k in (0, 2):
        leaf = refs[:, k + 1] > 0
        if (refs[leaf, k + 1] != 1).any():   # the SAH builder splits every node above leaf_size
            raise RuntimeError("the top level must hold one instance a leaf")
        refs[leaf, k] = top.prim_ids[refs[leaf, k]]
    return top


def assemble(bottoms: list, table: np.ndarray, accel: str, start: float | None = None) -> TwoLevel:
    """The TwoLevel of the distinct meshes' Accelerations ``bottoms`` (built over
    each mesh's corners in its device frame, in mesh order) and the instance
    rows ``table`` (:func:`instance_table`, completed here); ``start``: when
    the build began (perf_counter), for build_ms."""
    start = time.perf_counter() if start is None else start
    counts = np.array([len(b.prim_ids) for b in bottoms], np.int64)
    if counts.sum() >= 2**31 - 1:
        raise InputError(f"the distinct meshes of a scene hold at most {2**31 - 2:,} triangles (slots are "
                         f"int32), got {int(counts.sum()):,}")
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    top = top_level(table, accel) if accel != "none" else None
    rows, root = [top.rows if top is not None else np.zeros(1, BVH_PAIR_NODE)], []
    base = len(rows[0])
    for b, slot in zip(bottoms, first):
        if top is None:
            root.append(0)
            continue
        r = b.rows.copy()
        refs = child_refs(r)
        for k in (0, 2):
            refs[refs[:, k + 1] == 0, k] += base
            refs[refs[:, k + 1] > 0, k] += slot
        rows.append(r)
        root.append(base)
        base += len(r)
    mesh_of = table["mesh"]
    table["root"], table["first"], table["count"] = np.array(root)[mesh_of], first[mesh_of], counts[mesh_of]
    depth = top.depth + 1 + max(b.depth for b in bottoms) if top is not None else 0
    prim_ids = np.concatenate([b.prim_ids for b in bottoms]).astype(np.int32)
    order = np.concatenate([b.prim_ids.astype(np.int64) + f for b, f in zip(bottoms, first)])
    return TwoLevel(accel, bottoms[0].builder, np.concatenate(rows), prim_ids, depth=int(depth),
                    build_ms=1e3 * (time.perf_counter() - start), leaf_size=bottoms[0].leaf_size,
                    instances=table, top=top, bottoms=list(bottoms), order=order)


def move(two: TwoLevel, table: np.ndarray) -> int:
    """Place ``two``'s instances anew: ``table`` their INSTANCE rows for the
    new transforms (:func:`instance_table`; their meshes' places are copied
    here), the top level built again over its boxes, as :func:`assemble`
    builds it -- the meshes' levels stay, rows and all: a binary top level
    over I instances, one a leaf, has I - 1 rows (one for a single instance)
    whatever the boxes, so every mesh's rows keep their place.  Returns how
    many rows from the first changed (the top level's; 0 without a BVH)."""
    for name in ("mesh", "root", "first", "count", "material"):
        table[name] = two.instances[name]
    two.instances = table
    if two.top is None:
        return 0
    top = top_level(table, two.accel)
    base = len(two.top.rows)
    if len(top.rows) != base:   # (cannot happen: the count above)
        raise RuntimeError(f"a top level of {len(table)} instances has {len(top.rows)} rows, not {base}")
    two.rows[:base] = top.rows
    two.top = top
    two.depth = int(top.depth + 1 + max(b.depth for b in two.bottoms))
    return base
