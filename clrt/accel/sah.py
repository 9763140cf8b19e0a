"""Binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding
volume hierarchies").

Every open node evaluates, on each axis, the surface area heuristic

    cost(split) = C_TRAVERSAL + C_INTERSECT * (A(L) N(L) + A(R) N(R)) / A(node)
    cost(leaf)  = C_INTERSECT * N

(boxes, whatever the final volume shape; constants in ``bvh.py``) at candidate
planes:

* a node of more than ``SWEEP_MAX`` triangles bins their centroids into ``BINS``
  equal slots of its centroid bounds and tries the ``BINS - 1`` bin boundaries;
* a smaller node tries every plane between consecutive distinct centroids (an
  exact sweep: never worse than binning, and cheaper here than short bins, which
  cost one reduction each).

Leaf policy (``leaf_size`` is a hard maximum, SAH decides below it):

* 1 triangle -> leaf;
* more than ``leaf_size`` triangles -> always split, at the cheapest candidate even
  when that costs more than a leaf;
* otherwise split only when the best split is strictly cheaper than a leaf.

A node whose centroids all coincide has no candidate plane; when it must split it
is halved by triangle id.  From depth ``MAX_SAH_DEPTH`` on, the paper's median
split on the longest axis takes over, which bounds the depth (nodes on a path) by
``MAX_SAH_DEPTH + ceil(log2 F) + 1`` even on adversarial input (e.g. geometrically
growing triangles, where every SAH split peels off a single one).

Vectorisation: the engine keeps each node's triangles sorted by centroid on every
axis, so bins are runs of the sorted lists (one ``minimum.reduceat``).  Bins, or
the triangles of small nodes, are then laid out as dense planes ``(6, m, K)`` --
box coordinate, bin/triangle, node -- so that the left and right sweeps are ``m``
contiguous ``np.minimum`` calls over all K nodes of the level at once.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from clrt.accel.bvh import C_INTERSECT, C_TRAVERSAL, Level, Topology, build_topdown
from clrt.accel.paper import median_split

BINS = 32
SWEEP_MAX = 128         # nodes of at most this many triangles are swept exactly
MAX_SAH_DEPTH = 48
# Costs are evaluated in float32, on coordinates scaled by a power of two (exact)
# so that the largest is about 2**45: area * count then stays below float32's
# maximum for any count < 2**31, and small nodes stay far from underflow.
SCALE_TO = 45


def _area(box: np.ndarray) -> np.ndarray:
    """Half surface area of boxes stored as (6, ...) rows min xyz, -max xyz."""
    d = -box[3:] - box[:3]
    return d[0] * d[1] + d[1] * d[2] + d[2] * d[0]


def _sweep(planes: np.ndarray, n_before: np.ndarray, counts: np.ndarray, tied=None):
    """Best split of K nodes from their m slots (bins or single triangles).

    planes:   (6, m, K) float32 slot boxes (+inf rows for empty slots), destroyed.
    n_before: (m, K) float triangles in slots 0..r (inclusive running count).
    counts:   (K,) int64 triangles per node.
    tied:     optional (m - 1, K) bool, True where slots r and r + 1 have equal
              centroids (no plane can separate them).
    Returns cost (K,) ``A(L) N(L) + A(R) N(R)`` (inf: no candidate), n_left (K,)
    int64 and the node box area (K,).
    """
    m = planes.shape[1]
    left = planes.copy()
    for r in range(1, m):                        # running box of slots 0..r
        np.minimum(left[:, r], left[:, r - 1], out=left[:, r])
    for r in range(m - 2, -1, -1):               # running box of slots r..m-1
        np.minimum(planes[:, r], planes[:, r + 1], out=planes[:, r])
    n_left = n_before[:-1]
    total = counts.astype(n_before.dtype)
    with np.errstate(invalid="ignore", over="ignore"):    # empty running boxes are +-inf
        cost = _area(left[:, :-1])
        cost *= n_left
        cost += _area(planes[:, 1:]) * (total - n_left)
        area = _area(left[:, -1])
    cost[(n_left == 0) | (n_left == total)] = np.inf
    if tied is not None:
        cost[tied] = np.inf
    best = np.argmin(cost, axis=0)                        # first (lowest) plane on ties
    cols = np.arange(len(counts))
    return cost[best, cols], n_left[best, cols].astype(np.int64), area


def _binned(level: Level, a: int, nodes: np.ndarray, mask):
    """Binned candidates on axis ``a`` for the given ``nodes`` (K,), whose triangles
    are the list positions selected by ``mask`` ((n,) bool, or None for all)."""
    counts = level.counts[nodes]
    K = len(nodes)
    keys, boxes = level.keys[a], level.boxes[a]
    if mask is not None:
        keys, boxes = np.compress(mask, keys), np.compress(mask, boxes, axis=1)
    lo = level.cmin[nodes, a]
    extent = level.cmax[nodes, a] - lo
    scale = np.divide(BINS, extent, out=np.zeros(K), where=extent > 0)
    t = (keys - np.repeat(lo, counts)) * np.repeat(scale, counts)
    cell = np.minimum(t.astype(np.int32), BINS - 1) * K
    cell += np.repeat(np.arange(K, dtype=np.int32), counts)
    # Keys ascend inside a node, so each bin is one run of the list.
    starts = np.flatnonzero(np.concatenate(([True], cell[1:] != cell[:-1])))
    planes = np.full((6, BINS * K), np.inf, np.float32)
    planes[:, cell[starts]] = np.minimum.reduceat(boxes, starts, axis=1)
    n_in = np.zeros(BINS * K)             # float64: counts stay exact beyond 2**24
    n_in[cell[starts]] = np.diff(np.append(starts, len(cell)))
    return _sweep(planes.reshape(6, BINS, K), np.cumsum(n_in.reshape(BINS, K), axis=0), counts)


def _swept(level: Level, a: int, nodes: np.ndarray):
    """Exact sweep on axis ``a`` for small ``nodes`` (K,): one slot per triangle,
    nodes grouped by power-of-two size so that padding stays below half."""
    counts = level.counts[nodes]
    keys = level.keys[a]
    tied_next = np.append(keys[1:] == keys[:-1], False)       # list position i ties i + 1
    out = (np.full(len(nodes), np.inf), np.zeros(len(nodes), np.int64), np.zeros(len(nodes)))
    m = 2
    while m // 2 < counts.max():
        group = np.flatnonzero((counts > m // 2) & (counts <= m))
        if len(group):
            c = counts[group]
            slot = np.arange(m)[:, None]
            # Padding slots repeat the node's last triangle: a duplicate changes no
            # running box, and splits after the last triangle are invalid anyway.
            index = level.offsets[nodes[group]] + np.minimum(slot, c - 1)
            planes = np.take(level.boxes[a], index, axis=1)          # (6, m, K)
            n_before = np.minimum(slot + 1, c).astype(np.float32)
            result = _sweep(planes, n_before, c, tied=np.take(tied_next, index[:-1]))
            for dst, src in zip(out, result):
                dst[group] = src
        m *= 2
    return out


def _best_on_axis(level: Level, a: int):
    """cost, n_left, area (S,) of every node's best candidate on axis ``a``."""
    S = len(level.counts)
    cost, n_left, area = np.full(S, np.inf), np.zeros(S, np.int64), np.zeros(S)
    big = level.counts > SWEEP_MAX
    small = np.flatnonzero(~big & (level.counts > 1))
    if big.any():
        nodes = np.flatnonzero(big)
        mask = None if big.all() else np.repeat(big, level.counts)
        cost[nodes], n_left[nodes], area[nodes] = _binned(level, a, nodes, mask)
    if len(small):
        cost[small], n_left[small], area[small] = _swept(level, a, small)
    return cost, n_left, area


def sah_split(level: Level, leaf_size: int):
    """Split rule: (axis (S,) int64, n_left (S,) int64), n_left = 0 for leaves."""
    if level.depth >= MAX_SAH_DEPTH:
        return median_split(level, leaf_size, "longest")
    counts = level.counts
    per_axis = [_best_on_axis(level, a) for a in range(3)]
    cost = np.stack([c for c, _, _ in per_axis], 1)
    axis = np.argmin(cost, axis=1)                               # x before y before z on ties
    rows = np.arange(len(counts))
    best = cost[rows, axis]
    n_left = np.stack([n for _, n, _ in per_axis], 1)[rows, axis]
    area = per_axis[0][2]

    # A zero-area node (all triangles on one line or point): area ratios count as 1.
    ratio = np.divide(best, area, out=counts.astype(np.float64), where=area > 0)
    split_cost = C_TRAVERSAL + C_INTERSECT * ratio
    splittable = np.isfinite(best)
    forced = counts > leaf_size
    do_split = splittable & (forced | (split_cost < C_INTERSECT * counts))
    n_left = np.where(do_split, n_left, 0)
    # Coincident centroids: no candidate plane; halve by triangle id (inside such a
    # node every list is in id order, so axis 0 will do).
    by_id = forced & ~splittable
    n_left[by_id] = counts[by_id] // 2
    axis[by_id] = 0
    return axis, n_left


def build(lo: np.ndarray, hi: np.ndarray, centroids: np.ndarray, leaf_size: int) -> Topology:
    """SAH tree over triangles given by box min/max (F, 3) float32 and centroids
    (F, 3) float64."""
    boxes = np.concatenate([lo, -hi], axis=1)
    biggest = float(np.abs(boxes).max())
    if biggest > 0:
        boxes = np.ldexp(boxes, SCALE_TO - int(np.ceil(np.log2(biggest))))
    return build_topdown(centroids, partial(sah_split, leaf_size=leaf_size),
                         carry_keys=True, boxes=boxes)
