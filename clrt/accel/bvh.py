"""What an acceleration build hands to the device, and its statistics."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clrt.accel.rows import tree_stats
from clrt.accel.topdown import C_INTERSECT, C_TRAVERSAL, surface_area
from clrt.layouts import BVH_PAIR_NODE, TRIANGLE_VERTS


@dataclass
class Acceleration:
    """The acceleration structure over a list of triangles, ready for upload.

    accel:     "none" or the BVH's volume shape (clrt.config.ACCELS).
    builder:   the builder's name (None without a BVH).
    rows:      (R,) ``BVH_PAIR_NODE`` (clrt/layouts.py); one unused row without a BVH.
    prim_ids:  (F,) int32, input triangle index stored in each slot: upload the
               triangles as ``triangles[prim_ids]``, report ``prim_ids[slot]``
               (the identity without a BVH).
    depth:     nodes on the longest root-to-leaf path (root counts 1; 0 without a
               BVH): a traversal stack of ``depth`` entries always suffices.
    build_ms:  wall time of the whole build, front end included.
    leaf_size: the most triangles a leaf may hold.
    counts:    (N,) int64 triangles of each depth-first node, 0 for inner nodes
               (statistics; None without a BVH).
    boxes:     (N, 2, 3) float32 exact (unpadded) box of each depth-first node
               (statistics; None without a BVH).
    device_buffers: the device builder's buffers, for the first geometry on
               their context to take over (:meth:`take_device_buffers`).
    exact_rows: the rows with the exact (unpadded) boxes in box layout, from a
               builder that keeps no ``counts`` and ``boxes`` on the host (the
               device builder): :meth:`stats` computes its numbers from them
               when first asked (a first image does not wait for them).
    """

    accel: str
    builder: str | None
    rows: np.ndarray
    prim_ids: np.ndarray
    depth: int
    build_ms: float
    leaf_size: int = 0
    counts: np.ndarray | None = field(repr=False, default=None)
    boxes: np.ndarray | None = field(repr=False, default=None)
    exact_rows: np.ndarray | None = field(repr=False, default=None)
    device_buffers: object = field(repr=False, default=None, compare=False)
    _summary: dict | None = field(repr=False, default=None)
    # A two-level scene's instance table (clrt.accel.instances.TwoLevel); None here.
    instances = None

    def take_device_buffers(self, context):
        """The device builder's buffers (rows, tri_verts, prim_ids: clrt.device.build.
        DeviceBvh) if they live on ``context``; handed out once, to the first
        geometry made on that context (a refit writes into them)."""
        built = self.device_buffers
        if built is None or built.rows is None or built.queue.context.int_ptr != context.int_ptr:
            return None
        self.device_buffers = None
        return built

    def keep_on_host(self) -> None:
        """Hold every host copy and let the device buffers go (an Acceleration
        built on the device reads its host copies when first asked for:
        clrt.device.acceleration.DeviceAcceleration); here they are all on
        the host already."""
        self.device_buffers = None

    def settle(self) -> None:
        """Fix the statistics of the tree as built before a refit moves its
        triangles (a device build computes them when first asked for)."""

    def __getstate__(self):
        state = dict(self.__dict__)
        state["device_buffers"] = None        # device memory does not travel
        return state

    @classmethod
    def brute_force(cls, num_triangles: int) -> "Acceleration":
        """No acceleration: every ray meets every triangle, in input order."""
        return cls("none", None, np.zeros(1, BVH_PAIR_NODE), np.arange(num_triangles, dtype=np.int32), 0, 0.0)

    def slot_order(self) -> np.ndarray:
        """The row of the input corners each slot holds: the triangles go to the
        device as ``corners[slot_order()]`` -- ``prim_ids`` here; a two-level
        scene's slots hold its meshes' corners, mesh after mesh, while its
        ``prim_ids`` count within each mesh (clrt.accel.instances)."""
        return self.prim_ids

    @property
    def is_bvh(self) -> bool:
        return self.accel != "none"

    @property
    def num_slots(self) -> int:
        """Triangles the device holds, one a slot (``len(prim_ids)``)."""
        return len(self.prim_ids)

    @property
    def num_rows(self) -> int:
        """``len(rows)``."""
        return len(self.rows)

    def device_bytes(self) -> int:
        """Bytes the kernels read: rows, triangle ids and the slot-ordered triangles."""
        return int(self.num_rows * BVH_PAIR_NODE.itemsize + (4 + TRIANGLE_VERTS.itemsize) * self.num_slots)

    def stats(self) -> dict:
        """Summary numbers: nodes, leaves, depth, leaf sizes, SAH cost, build time,
        device bytes.

        ``sah_cost`` is the expected cost of a random ray of the *box* topology:
        sum over inner nodes of ``C_TRAVERSAL * A(n)`` plus sum over leaves of
        ``C_INTERSECT * count * A(n)``, divided by ``A(root)`` (A = surface area of
        the exact node box; constants ``C_TRAVERSAL = C_INTERSECT = 1``).
        """
        if not self.is_bvh:
            return {"build_ms": float(self.build_ms), "device_bytes": self.device_bytes()}
        if self.exact_rows is not None:
            if self._summary is None:
                self._summary = tree_stats(self.exact_rows, self.depth)
            return {**self._summary, "build_ms": float(self.build_ms), "device_bytes": self.device_bytes()}
        count = self.counts
        leaf = count > 0
        area = surface_area(self.boxes[:, 0].astype(np.float64), self.boxes[:, 1].astype(np.float64))
        ratio = area / area[0] if area[0] > 0 else np.ones_like(area)
        sah = C_TRAVERSAL * ratio[~leaf].sum() + C_INTERSECT * (ratio[leaf] * count[leaf]).sum()
        return {
            "nodes": int(len(count)),
            "leaves": int(leaf.sum()),
            "depth": int(self.depth),
            "max_leaf_size": int(count.max()),
            "mean_leaf_size": float(count[leaf].mean()),
            "sah_cost": float(sah),
            "build_ms": float(self.build_ms),
            "device_bytes": self.device_bytes(),
        }
