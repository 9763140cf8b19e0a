"""The BVH a build produces, the top-down engine both builders share, and the
linearisation of a builder's tree into the device's ``BVH_NODE`` buffer.

Three separate pieces (see ``../shared/STYLE.md``):

* a *builder* (``paper.py``, ``sah.py``) is only a split rule: given the open nodes
  of one tree level it says, per node, "leaf" or "split along axis a, the first k
  triangles in centroid order go left".  It sees triangle boxes and centroids only.
* :func:`build_topdown` runs a split rule level by level over all nodes of a level
  at once (numpy, no per-node or per-triangle Python loop) and returns a
  :class:`Topology`.
* :func:`linearise` turns that tree into depth-first ``BVH_NODE`` records; the
  bounding volume of each node is fitted afterwards by ``volumes.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional, Tuple

import numpy as np

from clrt.device.layouts import BVH_NODE

# Cost model of Bvh.stats()["sah_cost"] and of the SAH builder (sah.py): one unit
# per node visited (its children's volume tests) and one unit per ray/triangle
# test.  Equal costs keep the number readable as "expected node visits plus
# triangle tests of a ray that hits the root box".
C_TRAVERSAL = 1.0
C_INTERSECT = 1.0

# Bytes per triangle in the leaf-ordered TriangleVerts buffer (three float4).
TRIANGLE_BYTES = 48


@dataclass
class Bvh:
    """A built BVH, ready for upload.

    nodes:   (N,) ``BVH_NODE``, depth-first order, root at 0 (see
             ``clrt.device.layouts`` for the byte layout).
    prim_id: (F,) int32, input triangle id stored in each leaf slot; upload the
             triangle data as ``triangles[prim_id]`` and report ``prim_id[slot]``.
    boxes:   (N, 2, 3) float32, exact (unpadded) min/max box of each node's
             triangles, in node order; used for statistics and debugging.
    depth:   nodes on the longest root-to-leaf path (root counts 1); a traversal
             stack of ``depth`` entries always suffices.
    build_ms: wall time of the whole build, front end included.
    """

    nodes: np.ndarray
    prim_id: np.ndarray
    volume: str
    builder: str
    leaf_size: int
    depth: int
    build_ms: float
    boxes: np.ndarray = field(repr=False, default=None)

    def stats(self) -> dict:
        """Summary numbers: nodes, leaves, depth, leaf sizes, SAH cost, build time,
        device bytes.

        ``sah_cost`` is the expected cost of a random ray of the *box* topology:
        sum over inner nodes of ``C_TRAVERSAL * A(n)`` plus sum over leaves of
        ``C_INTERSECT * count * A(n)``, divided by ``A(root)`` (A = surface area of
        the exact node box; constants ``C_TRAVERSAL = C_INTERSECT = 1``).
        """
        count = self.nodes["count"]
        leaf = count > 0
        area = surface_area(self.boxes[:, 0].astype(np.float64), self.boxes[:, 1].astype(np.float64))
        ratio = area / area[0] if area[0] > 0 else np.ones_like(area)
        sah = C_TRAVERSAL * ratio[~leaf].sum() + C_INTERSECT * (ratio[leaf] * count[leaf]).sum()
        return {
            "nodes": int(len(self.nodes)),
            "leaves": int(leaf.sum()),
            "depth": int(self.depth),
            "max_leaf_size": int(count.max()),
            "mean_leaf_size": float(count[leaf].mean()),
            "sah_cost": float(sah),
            "build_ms": float(self.build_ms),
            "device_bytes": int(self.nodes.nbytes + self.prim_id.nbytes
                                + TRIANGLE_BYTES * len(self.prim_id)),
        }


def surface_area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Half the surface area of boxes ``(..., 3)``; only ratios are ever used."""
    d = hi - lo
    return d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0]


def triangle_bounds(triangles: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, 3, 3) float32 corners -> box min (F, 3) float32, box max (F, 3) float32,
    centroid (F, 3) float64 (mean of the corners, computed in float64)."""
    v0, v1, v2 = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    lo = np.minimum(np.minimum(v0, v1), v2)
    hi = np.maximum(np.maximum(v0, v1), v2)
    centroids = triangles[:, 0].astype(np.float64)
    centroids += triangles[:, 1]
    centroids += triangles[:, 2]
    centroids /= 3.0
    return lo, hi, centroids


# --------------------------------------------------------------------------------------
# Top-down engine shared by the builders.


@dataclass
class Level:
    """The open nodes of one tree level (all at the same ``depth``, root = 0), as a
    split rule sees them: S nodes holding n triangles in total.

    ids:     (3, n) int32 triangle ids; node s owns positions
             ``offsets[s] : offsets[s] + counts[s]`` of every row, and row ``a`` is
             sorted there by (centroid[:, a], triangle id).
    keys:    (3, n) float64 ``centroid[ids[a], a]``, or None if not carried.
    boxes:   (3, 6, n) float32 triangle boxes in the order of ``ids[a]``, rows
             (min x, min y, min z, -max x, -max y, -max z), or None if not carried.
    offsets, counts: (S,) int64.
    cmin, cmax: (S, 3) float64 centroid bounds of each node.
    """

    depth: int
    ids: np.ndarray
    keys: Optional[np.ndarray]
    boxes: Optional[np.ndarray]
    offsets: np.ndarray
    counts: np.ndarray
    cmin: np.ndarray
    cmax: np.ndarray


# A split rule returns, per node of the level, (axis (S,) int, n_left (S,) int):
# n_left == 0 makes a leaf, else the first n_left triangles of row ``axis`` go left
# (1 <= n_left < count, so no child is ever empty).
SplitRule = Callable[[Level], Tuple[np.ndarray, np.ndarray]]


@dataclass
class Topology:
    """A builder's tree in level order (parents before children, left before right).

    left, right: (N,) int64 child node ids, -1 at leaves.
    first, count: (N,) int64 first leaf slot and number of triangles of the subtree
                  (a subtree always covers a contiguous slot range).
    level:   (N,) int64 depth of each node, root 0; ``level_offsets`` (L + 1,) where
             each level starts.
    prim_id: (F,) int32 input triangle id of every leaf slot.
    """

    left: np.ndarray
    right: np.ndarray
    first: np.ndarray
    count: np.ndarray
    level: np.ndarray
    level_offsets: np.ndarray
    prim_id: np.ndarray

    @property
    def is_leaf(self) -> np.ndarray:
        return self.left < 0


def _exclusive_cumsum(x: np.ndarray) -> np.ndarray:
    out = np.empty(len(x) + 1, np.int64)
    out[0] = 0
    np.cumsum(x, out=out[1:])
    return out


def build_topdown(centroids: np.ndarray, rule: SplitRule, carry_keys: bool = False,
                  boxes: Optional[np.ndarray] = None) -> Topology:
    """Grow a binary tree top-down, one level per iteration, all nodes of a level at once.

    centroids: (F, 3) float64.  ``carry_keys`` / ``boxes`` ((F, 6) float32, rows
    min xyz, -max xyz) ask for per-list copies in :class:`Level` (what SAH needs).

    The triangles are kept in three id lists, each sorted once by one centroid axis
    (stable sort from id order, so ties go by triangle id).  Splitting a node takes
    a prefix of one list; the other two lists are *stably partitioned* by the same
    per-triangle side flag, so every list stays sorted inside every node without
    re-sorting (the presorted-lists technique of kd-tree builders).  A partition is
    two order-keeping ``compress`` and one gather: O(n) per level and list.
    Triangles of finished leaves are written to their slots and dropped from the
    lists.
    """
    F = len(centroids)
    ids = np.stack([np.argsort(centroids[:, a], kind="stable") for a in range(3)]).astype(np.int32)
    keys = np.stack([centroids[ids[a], a] for a in range(3)]) if carry_keys else None
    if boxes is not None:
        boxes = np.stack([np.take(boxes.T, ids[a], axis=1) for a in range(3)])
    offsets = np.zeros(1, np.int64)
    counts = np.array([F], np.int64)
    slots = np.zeros(1, np.int64)            # first leaf slot of each open node
    prim_id = np.empty(F, np.int32)
    goes_right = np.zeros(F, bool)           # per triangle, rewritten every level
    per_level = []                           # (first, count, leaf) of each level's nodes
    depth = 0
    while True:
        ends = offsets + counts - 1
        if keys is not None:
            cmin, cmax = keys[:, offsets].T, keys[:, ends].T
        else:
            cmin = np.stack([centroids[ids[a, offsets], a] for a in range(3)], 1)
            cmax = np.stack([centroids[ids[a, ends], a] for a in range(3)], 1)
        axis, n_left = rule(Level(depth, ids, keys, boxes, offsets, counts, cmin, cmax))
        axis = np.asarray(axis, np.int64)
        n_left = np.asarray(n_left, np.int64)
        if np.any((n_left < 0) | (n_left >= counts) | ((n_left > 0) & ((axis < 0) | (axis > 2)))):
            raise RuntimeError("split rule produced an empty child or a bad axis")
        leaf = n_left == 0
        per_level.append((slots, counts, leaf))

        if leaf.any():
            # Leaves take the slots [first, first + count); their triangles leave the lists.
            in_leaf = np.repeat(leaf, counts)
            slot = np.arange(len(in_leaf)) + np.repeat(slots - offsets, counts)
            prim_id[slot[in_leaf]] = ids[0, in_leaf]
            if leaf.all():
                break
            keep = ~in_leaf
            ids = np.compress(keep, ids, axis=1)
            keys = None if keys is None else np.compress(keep, keys, axis=1)
            boxes = None if boxes is None else np.compress(keep, boxes, axis=2)
            split = ~leaf
            counts, slots, axis, n_left = counts[split], slots[split], axis[split], n_left[split]
            offsets = _exclusive_cumsum(counts)[:-1]

        # Side of every triangle, read off the chosen axis' list.
        n = ids.shape[1]
        rank = np.arange(n, dtype=np.int32) - np.repeat(offsets.astype(np.int32), counts)
        right = rank >= np.repeat(n_left.astype(np.int32), counts)
        chosen = np.unique(axis)
        if len(chosen) == 1:
            goes_right[ids[chosen[0]]] = right
        else:
            for a in chosen:
                mine = np.repeat(axis == a, counts)
                goes_right[np.compress(mine, ids[a])] = np.compress(mine, right)

        # Stable partition of every list.  Node sizes do not change, so position j
        # of the new list is a left slot exactly where ``right[j]`` is False; the
        # k-th left slot takes the k-th left triangle of the old list (compress
        # keeps the order), the k-th right slot the k-th right triangle.
        n_lefts = n - int(np.count_nonzero(right))
        gather = np.cumsum(right, dtype=np.int32)
        gather += n_lefts - 1
        np.copyto(gather, np.cumsum(~right, dtype=np.int32) - 1, where=~right)
        position = np.arange(n, dtype=np.int32)
        carried = [x for x in (ids, keys, boxes) if x is not None]
        moved = [np.empty_like(x) for x in carried]
        for a in range(3):
            is_right = np.take(goes_right, ids[a])
            perm = np.take(np.concatenate([np.compress(~is_right, position),
                                           np.compress(is_right, position)]), gather)
            for old, new in zip(carried, moved):
                np.take(old[a], perm, axis=-1, out=new[a])
        ids = moved[0]
        keys = moved[1] if keys is not None else None
        boxes = moved[-1] if boxes is not None else None
        counts = np.stack([n_left, counts - n_left], 1).ravel()
        offsets = _exclusive_cumsum(counts)[:-1]
        slots = np.stack([slots, slots + n_left], 1).ravel()
        depth += 1
    return _assemble(per_level, prim_id)


def _assemble(per_level, prim_id) -> Topology:
    """Concatenate the per-level records into level-ordered node arrays."""
    sizes = [len(c) for _, c, _ in per_level]
    level_offsets = _exclusive_cumsum(np.array(sizes, np.int64))
    first = np.concatenate([s for s, _, _ in per_level])
    count = np.concatenate([c for _, c, _ in per_level])
    level = np.repeat(np.arange(len(sizes)), sizes)
    left = np.full(len(first), -1, np.int64)
    right = np.full(len(first), -1, np.int64)
    for lvl, (_, _, lf) in enumerate(per_level[:-1]):
        parents = level_offsets[lvl] + np.flatnonzero(~lf)
        left[parents] = level_offsets[lvl + 1] + 2 * np.arange(len(parents))
        right[parents] = left[parents] + 1
    return Topology(left, right, first, count, level, level_offsets, prim_id)


# --------------------------------------------------------------------------------------
# From the builder's tree to the device layout.


def node_boxes(topo: Topology, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N, 2, 3) float32 exact box of each node's triangles, in topology order.

    Leaf boxes come from their slots; inner boxes are merged bottom-up, one level
    per step.
    """
    boxes = np.empty((len(topo.first), 2, 3), np.float32)
    leaves = np.flatnonzero(topo.is_leaf)
    first, count = topo.first[leaves], topo.count[leaves]
    # Leaf boxes: one (m, L) gather per slot index r < m = largest leaf (short leaves
    # repeat their last triangle), reduced over r with contiguous min/max.
    slot = first + np.minimum(np.arange(count.max())[:, None], count - 1)
    tri = topo.prim_id[slot]
    boxes[leaves, 0] = np.take(lo, tri, axis=0).min(axis=0)
    boxes[leaves, 1] = np.take(hi, tri, axis=0).max(axis=0)
    for lvl in range(len(topo.level_offsets) - 2, -1, -1):
        nodes = np.arange(topo.level_offsets[lvl], topo.level_offsets[lvl + 1])
        nodes = nodes[~topo.is_leaf[nodes]]
        boxes[nodes, 0] = np.minimum(boxes[topo.left[nodes], 0], boxes[topo.right[nodes], 0])
        boxes[nodes, 1] = np.maximum(boxes[topo.left[nodes], 1], boxes[topo.right[nodes], 1])
    return boxes


def linearise(topo: Topology) -> Tuple[np.ndarray, np.ndarray]:
    """Depth-first ``BVH_NODE`` records (bounds still zero) and ``order`` (N,) int64,
    the topology node stored at each depth-first position.

    Preorder without a traversal: every subtree covers a contiguous, non-empty slot
    range, so two nodes are either nested (same first slot only along a leftmost
    chain, ancestor at the smaller level) or disjoint (ordered by first slot).
    Sorting by (first slot, level) is therefore exactly the preorder.
    """
    order = np.lexsort((topo.level, topo.first))
    position = np.empty_like(order)
    position[order] = np.arange(len(order))
    leaf = topo.is_leaf[order]
    nodes = np.zeros(len(order), BVH_NODE)
    nodes["left_first"] = np.where(leaf, topo.first[order], position[topo.left[order]])
    nodes["count"] = np.where(leaf, topo.count[order], 0)
    nodes["right"] = np.where(leaf, -1, position[topo.right[order]])
    return nodes, order
