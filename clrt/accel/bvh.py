"""The BVH a build produces, the top-down engine both builders share, and the
linearisation of a builder's tree into the device's ``BVH_NODE`` buffer.

Three separate pieces (see ``../shared/STYLE.md``):

* a *builder* (``paper.py``, ``sah.py``) is only a split rule: given the open nodes
  of one tree level it says, per node, "leaf" or "split along axis a, the first k
  triangles in key order go left" (keys: centroids for the paper, box centres for
  SAH).  It sees triangle boxes and keys only.
* :func:`build_topdown` runs a split rule level by level over all nodes of a level
  at once (numpy, no per-node or per-triangle Python loop) and returns a
  :class:`Topology`.
* :func:`linearise` turns that tree into depth-first ``BVH_NODE`` records; the
  bounding volume of each node is fitted afterwards by ``volumes.py``.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, List, Optional, Tuple

import numpy as np

from clrt.device.layouts import BVH_NODE, BVH_PAIR_NODE

# Cost model of Bvh.stats()["sah_cost"] and of the SAH builder (sah.py): one unit
# per node visited (its children's volume tests) and one unit per ray/triangle
# test.  Equal costs keep the number readable as "expected node visits plus
# triangle tests of a ray that hits the root box".
C_TRAVERSAL = 1.0
C_INTERSECT = 1.0

# Bytes per triangle in the leaf-ordered TriangleVerts buffer (three float4).
TRIANGLE_BYTES = 48

# numpy releases the GIL inside its array loops, so the per-axis work of a large
# level (partitioning the three sorted lists; the SAH candidates of the three axes)
# runs in one thread per axis.  The threads share no output: the tree is the same
# for any BUILD_THREADS (1: everything in the calling thread).  Levels of fewer than
# THREADED_MIN triangles stay in the calling thread, where threads cost more than
# they save.
BUILD_THREADS = min(3, os.cpu_count() or 1)
THREADED_MIN = 2 ** 18


@lru_cache(maxsize=None)
def _thread_pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(BUILD_THREADS, thread_name_prefix="clrt-bvh")


# A forked child has none of its parent's threads: it makes a pool of its own.
if hasattr(os, "register_at_fork"):                  # POSIX only
    os.register_at_fork(after_in_child=_thread_pool.cache_clear)


def for_each_axis(work: Callable[[int], object], n_triangles: int) -> List[object]:
    """[work(0), work(1), work(2)] for a level of ``n_triangles``, in threads if it
    is large (see ``BUILD_THREADS``)."""
    if BUILD_THREADS < 2 or n_triangles < THREADED_MIN:
        return [work(a) for a in range(3)]
    return list(_thread_pool().map(work, range(3)))


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
        device bytes (of the uploaded pair-node rows, ids and triangles).

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
            # what the device holds: one BVH_PAIR_NODE row per inner node (a lone
            # leaf takes one), the triangle ids and the triangles
            "device_bytes": int(BVH_PAIR_NODE.itemsize * max(int((~leaf).sum()), 1)
                                + self.prim_id.nbytes + TRIANGLE_BYTES * len(self.prim_id)),
        }


def surface_area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Half the surface area of boxes ``(..., 3)``; only ratios are ever used."""
    d = hi - lo
    return d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0]


def triangle_centroids(triangles: np.ndarray) -> np.ndarray:
    """(F, 3, 3) float32 corners -> centroid (F, 3) float64 (mean of the corners,
    computed in float64)."""
    centroids = triangles[:, 0].astype(np.float64)
    centroids += triangles[:, 1]
    centroids += triangles[:, 2]
    centroids /= 3.0
    return centroids


# --------------------------------------------------------------------------------------
# Top-down engine shared by the builders.


@dataclass
class Level:
    """The open nodes of one tree level (all at the same ``depth``, root = 0), as a
    split rule sees them: S nodes holding n triangles in total.

    Every per-triangle array comes as one *sorted list* per axis ``a`` (a tuple of
    three): node s owns positions ``offsets[s] : offsets[s] + counts[s]`` of each,
    and list ``a`` is sorted there by (key[a], triangle id), ``key`` being the
    builder's sort key (see :func:`build_topdown`).

    ids:     3 x (n,) int32 triangle ids.
    boxes:   3 x 6 rows (n,) float32, the builder's triangle boxes in the order of
             ``ids[a]`` (rows min x, min y, min z, -max x, -max y, -max z for SAH),
             or None if not carried.
    offsets, counts: (S,) int64.
    keys:    3 x (F,) the sort keys, by triangle id (see :meth:`key_bounds`).
    """

    depth: int
    ids: Tuple[np.ndarray, ...]
    boxes: Optional[Tuple[Tuple[np.ndarray, ...], ...]]
    offsets: np.ndarray
    counts: np.ndarray
    keys: Tuple[np.ndarray, ...]

    def key_bounds(self, a: int, nodes: Optional[np.ndarray] = None
                   ) -> Tuple[np.ndarray, np.ndarray]:
        """Smallest and largest axis-``a`` key of each of ``nodes`` (default: all):
        the keys of the node's first and last triangle in list ``a``."""
        first = self.offsets if nodes is None else self.offsets[nodes]
        last = first + (self.counts if nodes is None else self.counts[nodes]) - 1
        return self.keys[a][self.ids[a][first]], self.keys[a][self.ids[a][last]]


# A split rule returns, per node of the level, (axis (S,) int, n_left (S,) int):
# n_left == 0 makes a leaf, else the first n_left triangles of list ``axis`` go left
# (1 <= n_left < count, so no child is ever empty).
SplitRule = Callable[[Level], Tuple[np.ndarray, np.ndarray]]


@dataclass
class Topology:
    """A builder's tree in level order: parents before children; inside a level,
    the left children of the previous level's inner nodes (in their order), then
    their right children.

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


def _exclusive_cumsum(x: np.ndarray) -> np.ndarray:
    out = np.empty(len(x) + 1, np.int64)
    out[0] = 0
    np.cumsum(x, out=out[1:])
    return out


def _sorted_ids(key: np.ndarray) -> np.ndarray:
    """(F,) int32 ids ordered by (key, id)."""
    if key.dtype != np.float32:
        return np.argsort(key, kind="stable").astype(np.int32)
    # float32 keys: sort (key bits mapped to ascending unsigned, id) as one 64-bit
    # integer.  These are unique, so any sort is stable, and numpy's (SIMD) integer
    # sort is several times faster than a stable argsort.  (+0.0 turns -0.0 into
    # +0.0: equal keys must differ only by id.)
    bits = (key + np.float32(0.0)).view(np.int32)
    ascending = (bits ^ ((bits >> 31) | np.int32(-2 ** 31))).view(np.uint32)
    packed = ascending.astype(np.uint64) << np.uint64(32)
    del bits, ascending
    packed |= np.arange(len(key), dtype=np.uint64)
    packed.sort()
    return packed.astype(np.uint32).view(np.int32)     # the low 32 bits: the id


def _ranges(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The ranges ``starts[i] : starts[i] + lengths[i]``, concatenated (int64)."""
    out = np.arange(int(lengths.sum()), dtype=np.int64)
    out += np.repeat(starts - _exclusive_cumsum(lengths)[:-1], lengths)
    return out


class _SortedList:
    """The rows (ids, and box rows if carried) of one axis' sorted list:
    the first n entries of full-length buffers, reused level after level."""

    def __init__(self, rows: List[np.ndarray]):
        self.buffers = rows
        self.n = len(rows[0])

    @property
    def rows(self) -> List[np.ndarray]:
        return [buffer[:self.n] for buffer in self.buffers]

    def permute(self, order: np.ndarray, spares: dict) -> None:
        """Keep the entries ``order`` (int64) in that order; each row is gathered into
        the spare buffer of its dtype, and its old buffer becomes that spare."""
        for i, buffer in enumerate(self.buffers):
            spare = spares[buffer.dtype]
            np.take(buffer[:self.n], order, out=spare[:len(order)], mode="clip")  # clip: unbuffered
            self.buffers[i], spares[buffer.dtype] = spare, buffer
        self.n = len(order)


# Where a triangle goes when its node is done with (``build_topdown``'s side codes).
LEFT, RIGHT, LEAF = 0, 1, 2


def build_topdown(keys, rule: SplitRule, boxes: Optional[np.ndarray] = None) -> Topology:
    """Grow a binary tree top-down, one level per iteration, all nodes of a level at once.

    keys: the sort key of every triangle on each axis, (3, F) (or three (F,)
    arrays), or a function of ``boxes`` that returns them.  ``boxes``: (6, F)
    float32 rows to carry in every list (:attr:`Level.boxes`); the engine keeps
    only the per-list copies, so a caller that passes ``boxes`` without keeping a
    reference lets the (6, F) array go.

    The triangles are kept in three sorted lists, one per axis (stable sort from
    id order, so ties go by triangle id), each a few separate rows: ids and the
    carried box rows.  Splitting a node takes a prefix of one list; the other two
    lists are *stably partitioned* by the same per-triangle side, so every list
    stays sorted inside every node without re-sorting (the presorted-lists
    technique of kd-tree builders).  The next level holds first the left children
    of all split nodes, then all right children: a list's new order is then just
    "its left triangles, then its right ones", one order-keeping index per list
    and one gather per row, into a reused buffer.  Triangles of finished leaves go
    to their slots and leave the lists in the same gather.
    """
    if callable(keys):
        keys = keys(boxes)
    F = len(keys[0])

    def sorted_list(a: int, boxes) -> _SortedList:
        ids = _sorted_ids(keys[a])
        rows = [ids]
        if boxes is not None:
            rows.extend(np.take(row, ids) for row in boxes)
        return _SortedList(rows)

    # One axis at a time: the sorts' temporaries would outweigh the lists otherwise.
    lists = [sorted_list(a, boxes) for a in range(3)]    # per axis: rows [ids, (6 box rows)]
    carry_boxes = boxes is not None
    del boxes                                # only the per-list copies from here on
    # One spare buffer per row type: a partition gathers a row into the spare and
    # the row's old buffer becomes the spare, so no level allocates (and page-faults
    # in) fresh rows.
    spares = [{row.dtype: np.empty(F, row.dtype) for row in lists[0].rows}
              for _ in range(3 if BUILD_THREADS > 1 else 1)]     # one set per thread

    offsets = np.zeros(1, np.int64)
    counts = np.array([F], np.int64)
    slots = np.zeros(1, np.int64)            # first leaf slot of each open node
    prim_id = np.empty(F, np.int32)
    side = np.empty(F, np.int8)              # per triangle id, rewritten every level
    per_level = []                           # (first, count, leaf) of each level's nodes
    depth = 0
    while True:
        level = Level(depth, tuple(lst.rows[0] for lst in lists),
                      tuple(tuple(lst.rows[1:]) for lst in lists) if carry_boxes else None,
                      offsets, counts, tuple(keys))
        axis, n_left = rule(level)
        del level                            # its rows are views of buffers reused below
        axis = np.asarray(axis, np.int64)
        n_left = np.asarray(n_left, np.int64)
        if np.any((n_left < 0) | (n_left >= counts) | ((n_left > 0) & ((axis < 0) | (axis > 2)))):
            raise RuntimeError("split rule produced an empty child or a bad axis")
        leaf = n_left == 0
        per_level.append((slots, counts, leaf))

        # Side of every triangle: LEFT unless marked otherwise below.
        split = ~leaf
        side.fill(LEFT)
        if leaf.any():
            # Leaves take the slots [first, first + count), in the order of list 0,
            # and their triangles leave the lists.
            leaf_ids = np.take(lists[0].rows[0], _ranges(offsets[leaf], counts[leaf]))
            prim_id[_ranges(slots[leaf], counts[leaf])] = leaf_ids
            if leaf.all():
                break
            side[leaf_ids] = LEAF
            del leaf_ids
        # A split node's RIGHT triangles, read off its split list: all but the first
        # n_left.
        chosen = np.unique(axis[split])
        for a in chosen:
            mine = split & (axis == a)
            right_part = _ranges(offsets[mine] + n_left[mine], counts[mine] - n_left[mine])
            side[np.take(lists[a].rows[0], right_part)] = RIGHT

        # Stable partition of every list: lefts in order, then rights in order (the
        # next level's nodes); leaf triangles are in neither and drop out.
        def partition(a: int) -> None:
            if len(chosen) == 1 and chosen[0] == a:
                # Every split is along this list: its sides are plain prefix/suffix.
                order = np.concatenate((_ranges(offsets[split], n_left[split]),
                                        _ranges(offsets[split] + n_left[split],
                                                counts[split] - n_left[split])))
            else:
                sides = np.take(side, lists[a].rows[0], mode="clip")
                order = np.concatenate((np.flatnonzero(sides == LEFT),
                                        np.flatnonzero(sides == RIGHT)))
                del sides
            lists[a].permute(order, spares[a % len(spares)])

        for_each_axis(partition, lists[0].n)
        n_left, counts, slots = n_left[split], counts[split], slots[split]
        counts = np.concatenate((n_left, counts - n_left))
        slots = np.concatenate((slots, slots + n_left))
        offsets = _exclusive_cumsum(counts)[:-1]
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
        # The next level: left children of these parents in order, then right children.
        left[parents] = level_offsets[lvl + 1] + np.arange(len(parents))
        right[parents] = left[parents] + len(parents)
    return Topology(left, right, first, count, level, level_offsets, prim_id)


# --------------------------------------------------------------------------------------
# From the builder's tree to the device layout.


def _inner_by_level(topo: Topology) -> List[np.ndarray]:
    """The inner nodes of each level, as node ids."""
    inner = topo.left >= 0
    bounds = topo.level_offsets
    return [bounds[lvl] + np.flatnonzero(inner[bounds[lvl]:bounds[lvl + 1]])
            for lvl in range(len(bounds) - 1)]


def node_boxes(topo: Topology, triangles: np.ndarray) -> np.ndarray:
    """(N, 2, 3) float32 exact box of each node's triangles (corners (F, 3, 3)
    float32), in topology order.

    Leaf boxes come from the corners of their slots; inner boxes are merged
    bottom-up, one level per step.
    """
    leaves = np.flatnonzero(topo.left < 0)
    first, count = topo.first[leaves], topo.count[leaves]
    # Slot r of every leaf at once (short leaves repeat their last triangle): one
    # (L, 3, 3) gather and contiguous min/max per r.
    lo = np.full((len(leaves), 3), np.inf, np.float32)
    hi = np.full((len(leaves), 3), -np.inf, np.float32)
    for r in range(int(count.max())):
        corners = np.take(triangles, topo.prim_id[first + np.minimum(r, count - 1)], axis=0)
        for xyz in corners.transpose(1, 0, 2):
            np.minimum(lo, xyz, out=lo)
            np.maximum(hi, xyz, out=hi)
    # Merged as rows (min xyz, -max xyz), so that one minimum merges a whole box.
    boxes = np.empty((len(topo.first), 2, 3), np.float32)
    boxes[leaves, 0] = lo
    boxes[leaves, 1] = -hi
    del lo, hi
    rows = boxes.reshape(-1, 6)
    for parents in reversed(_inner_by_level(topo)):
        rows[parents] = np.minimum(rows[topo.left[parents]], rows[topo.right[parents]])
    np.negative(boxes[:, 1], out=boxes[:, 1])
    return boxes


def linearise(topo: Topology) -> Tuple[np.ndarray, np.ndarray]:
    """Depth-first ``BVH_NODE`` records (bounds still zero) and ``order`` (N,) int64,
    the topology node stored at each depth-first position.

    Preorder positions without a traversal, one level per step: a node's left child
    comes right after it, its right child after the whole left subtree, whose node
    count is summed bottom-up first.
    """
    N = len(topo.first)
    inner = _inner_by_level(topo)
    size = np.ones(N, np.int64)                  # nodes in each subtree
    for p in reversed(inner):
        size[p] += size[topo.left[p]] + size[topo.right[p]]
    position = np.zeros(N, np.int64)
    right = np.full(N, -1, np.int32)             # right child's position, by position
    for p in inner:
        left_position = position[p] + 1
        position[topo.left[p]] = left_position
        position[topo.right[p]] = right[position[p]] = left_position + size[topo.left[p]]
    del size
    order = np.empty(N, np.int64)
    order[position] = np.arange(N)
    leaf = right < 0
    nodes = np.zeros(N, BVH_NODE)
    nodes["left_first"] = np.where(leaf, topo.first[order], np.arange(1, N + 1))
    nodes["count"] = np.where(leaf, topo.count[order], 0)
    nodes["right"] = right
    return nodes, order
