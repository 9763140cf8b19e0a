"""Binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding
volume hierarchies").

Every open node evaluates, on each axis, the surface area heuristic

    cost(split) = C_TRAVERSAL + C_INTERSECT * (A(L) N(L) + A(R) N(R)) / A(node)
    cost(leaf)  = C_INTERSECT * N

(boxes, whatever the final volume shape; constants in ``topdown.py``) at candidate
planes between the triangles' *box centres* (the centre of each triangle's
bounding box, as in Wald's paper: it places planes better than the mean of the
corners, and comes free with the boxes):

* a node of more than ``SWEEP_MAX`` triangles bins the centres into ``BINS``
  equal slots of its centre bounds and tries the ``BINS - 1`` bin boundaries;
* a smaller node tries every plane between consecutive distinct centres (an
  exact sweep: never worse than binning, and cheaper here than bins of a few
  triangles, which cost one reduction each).

Leaf policy (``leaf_size`` is a hard maximum, SAH decides below it):

* 1 triangle -> leaf;
* more than ``leaf_size`` triangles -> always split, at the cheapest candidate even
  when that costs more than a leaf;
* otherwise split only when the best split is strictly cheaper than a leaf.

A node whose centres all coincide has no candidate plane; when it must split it
is halved by triangle id.  From depth ``MAX_SAH_DEPTH`` on, the paper's median
split (of the centres) on the longest axis takes over, which bounds the depth
(nodes on a path) by ``MAX_SAH_DEPTH + ceil(log2 F) + 1`` even on adversarial
input (e.g. geometrically growing triangles, where every SAH split peels off a
single one).

Precision: the boxes are scaled by a power of two (exact) so that the largest
coordinate is about ``2**SCALE_TO``, and everything is computed from these
float32 values.  The key on axis a is ``min + max`` in float32 (twice the
centre), so centres closer than a float32 step count as equal.

Vectorisation: the engine keeps each node's triangles sorted by key on every
axis, so a bin is a run of the sorted list: its boundaries are found by binary
search (few large nodes) or by counting (many smaller ones), and its box is one
``minimum.reduceat`` per box row.  Bins, or the triangles of small nodes, are
then laid out as dense planes ``(6, m, K)`` -- box coordinate, bin/triangle,
node -- so that the left and right sweeps are ``m`` contiguous ``np.minimum``
calls over K nodes at once.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from clrt.accel.topdown import C_INTERSECT, C_TRAVERSAL, Level, Topology, build_topdown, for_each_axis
from clrt.accel.paper import median_split

BINS = 32
SWEEP_MAX = 256         # nodes of at most this many triangles are swept exactly
# Small nodes are swept in groups of similar size, padded to the group's largest
# (powers of two and their midpoints: at most a third of the slots are padding),
# about SWEEP_SLOTS slots (triangles and padding) at a time: bounded scratch memory.
SLOT_CLASSES = tuple(sorted({m for k in range(1, SWEEP_MAX.bit_length())
                             for m in (2 ** k, 3 * 2 ** (k - 1)) if m <= SWEEP_MAX}))
SWEEP_SLOTS = 2 ** 17
ARGMIN_LOOP_MAX = 8     # nodes' best plane: a running minimum up to this many planes
STEPPED_SWEEP_MIN = 64  # nodes swept at once from which slot-by-slot steps pay off
# Bin boundaries of a big node are binary-searched when that takes fewer than one
# probe (a cache miss) per PROBE_COST triangles, else every triangle is binned,
# COUNT_SLOTS list positions at a time.
PROBE_COST = 8
COUNT_SLOTS = 2 ** 20
MAX_SAH_DEPTH = 48
# Costs are evaluated in float32, on coordinates scaled by a power of two (exact)
# so that the largest is about 2**45: area * count then stays below float32's
# maximum for any count < 2**31, and small nodes stay far from underflow.
SCALE_TO = 45


def _area(box: np.ndarray) -> np.ndarray:
    """Half surface area of boxes stored as (6, ...) rows min xyz, -max xyz."""
    d = box[3:] + box[:3]              # minus the extents (exactly), signs cancel below
    area = d[0] * d[1]
    term = d[1] * d[2]
    area += term
    np.multiply(d[2], d[0], out=term)
    area += term
    return area


def _centre_key(low: np.ndarray, negated_high: np.ndarray) -> np.ndarray:
    """Sort key of boxes on one axis, from their min and -max on it: min + max
    (twice the box centre) in float32."""
    return low - negated_high


def _sweep(planes: np.ndarray, n_left: np.ndarray, n_right: np.ndarray, invalid: np.ndarray):
    """Best split of K nodes from their m slots (bins or single triangles).

    planes:  (6, m, K) float32 slot boxes (+inf rows for empty slots), destroyed.
    n_left, n_right: (m - 1, K) float triangles left / right of the plane after
             slot r.
    invalid: (m - 1, K) bool, planes that are no candidate (an empty side, or equal
             centres on both sides).
    Returns cost (K,) ``A(L) N(L) + A(R) N(R)`` (inf: no candidate), n_left (K,)
    int64 and the node box area (K,).
    """
    m, K = planes.shape[1:]
    # Running boxes of slots 0..r (left) and r..m-1 (in place): m contiguous steps
    # over all K nodes, or for few nodes one (slower per slot) accumulate call.
    if K < STEPPED_SWEEP_MIN:
        left = np.minimum.accumulate(planes, axis=1)
        np.minimum.accumulate(planes[:, ::-1], axis=1, out=planes[:, ::-1])
    else:
        left = np.empty_like(planes)
        left[:, 0] = planes[:, 0]
        for r in range(1, m):
            np.minimum(left[:, r - 1], planes[:, r], out=left[:, r])
        for r in range(m - 2, -1, -1):
            np.minimum(planes[:, r], planes[:, r + 1], out=planes[:, r])
    with np.errstate(invalid="ignore", over="ignore"):    # empty running boxes are +-inf
        cost = _area(left[:, :-1])
        cost *= n_left
        cost += _area(planes[:, 1:]) * n_right
        area = _area(left[:, -1])
    np.copyto(cost, np.inf, where=invalid)
    # Cheapest plane of every node, the first (lowest) on ties.  For a few planes a
    # running minimum (m - 1 contiguous steps) beats np.argmin along a non-last axis.
    nodes = np.arange(K)
    if m - 1 > ARGMIN_LOOP_MAX:
        best = np.argmin(cost, axis=0)
        best_cost = cost[best, nodes]
    else:
        best_cost = cost[0].copy()
        best = np.zeros(len(nodes), np.intp)
        for r in range(1, m - 1):
            better = cost[r] < best_cost
            np.copyto(best_cost, cost[r], where=better)
            np.copyto(best, r, where=better)
    return best_cost, n_left[best, nodes].astype(np.int64), area


def _bin_edges(level: Level, a: int, nodes: np.ndarray) -> np.ndarray:
    """(K, BINS + 1) list positions where each bin of the big ``nodes`` (K,) starts
    on axis ``a``, then the node's end.  A triangle's bin is
    min(floor((key - lo) * scale), BINS - 1) over the node's key bounds."""
    start = level.offsets[nodes]
    counts = level.counts[nodes]
    lo, hi = level.key_bounds(a, nodes)
    lo = lo.astype(np.float64)
    extent = hi - lo
    scale = np.divide(BINS, extent, out=np.zeros(len(nodes)), where=extent > 0)
    edges = np.empty((len(nodes), BINS + 1), np.int64)
    edges[:, 0] = start
    edges[:, -1] = start + counts
    probes = (BINS - 1) * len(nodes) * int(counts.max()).bit_length()
    if probes * PROBE_COST < counts.sum():
        edges[:, 1:-1] = _search_bins(level.boxes[a], a, edges, lo, scale)
    else:
        edges[:, 1:-1] = start[:, None] + np.cumsum(_count_bins(level, a, nodes, lo, scale), axis=1)
    return edges


def _search_bins(box, a: int, edges: np.ndarray, lo: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(K, BINS - 1) first position of bins 1.. of few large nodes: keys ascend in a
    node, so bin k starts at the first position whose (key - lo) * scale reaches k;
    one binary search for every node and boundary at once."""
    lo, scale = lo[:, None], scale[:, None]
    bound = np.arange(1, BINS, dtype=np.float64)
    first = np.repeat(edges[:, :1], BINS - 1, axis=1)
    past = np.repeat(edges[:, -1:], BINS - 1, axis=1)
    while True:
        searching = first < past
        if not searching.any():
            return first
        mid = (first + past) >> 1
        key = _centre_key(np.take(box[a], mid, mode="clip"), np.take(box[3 + a], mid, mode="clip"))
        reached = (key - lo) * scale >= bound
        np.copyto(past, mid, where=searching & reached)
        np.copyto(first, mid + 1, where=searching & ~reached)


def _count_bins(level: Level, a: int, nodes: np.ndarray, lo: np.ndarray,
                scale: np.ndarray) -> np.ndarray:
    """(K, BINS - 1) triangles in bins 0..BINS-2 of many smaller ``nodes``: every
    triangle binned, about ``COUNT_SLOTS`` list positions at a time.  Positions of
    other nodes in between go to a spare row that is dropped."""
    box = level.boxes[a]
    S = len(level.counts)
    rank = np.full(S, len(nodes))                # row of each node's bins; others: spare
    rank[nodes] = np.arange(len(nodes))
    node_lo = np.zeros(S)
    node_lo[nodes] = lo
    node_scale = np.zeros(S)
    node_scale[nodes] = scale
    ends = level.offsets + level.counts
    n_in = np.zeros((len(nodes) + 1) * BINS, np.int64)
    first = nodes[0]
    while first <= nodes[-1]:
        # Nodes first..past-1: about COUNT_SLOTS positions, at least one node.
        past = int(np.searchsorted(ends, level.offsets[first] + COUNT_SLOTS, "right"))
        past = min(max(past, first + 1), nodes[-1] + 1)
        span = slice(level.offsets[first], ends[past - 1])
        repeat = partial(np.repeat, repeats=level.counts[first:past])
        t = _centre_key(box[a][span], box[3 + a][span]).astype(np.float64)
        t -= repeat(node_lo[first:past])
        t *= repeat(node_scale[first:past])
        cell = np.minimum(t.astype(np.intp), BINS - 1)
        cell += repeat(rank[first:past] * BINS)
        n_in += np.bincount(cell, minlength=len(n_in))
        first = past
    return n_in.reshape(-1, BINS)[:-1, :-1]


def _binned(level: Level, a: int, nodes: np.ndarray):
    """Binned candidates on axis ``a`` for the given big ``nodes`` (K,)."""
    edges = _bin_edges(level, a, nodes)
    n_in = np.diff(edges, axis=1)                               # (K, BINS) triangles per bin
    filled = n_in > 0
    # Each filled bin is one run of the list: reduce every run at once.  The runs
    # are listed node by node, each node's end closing its last bin (what lies
    # between big nodes is reduced too and thrown away).
    is_run = np.ones(edges.shape, bool)
    is_run[:, :-1] = filled
    run_start = edges[is_run]
    is_bin = np.zeros(edges.shape, bool)
    is_bin[:, :-1] = filled
    is_bin = is_bin[is_run]
    if run_start[-1] == len(level.ids[a]):                      # the list's end closes nothing
        run_start, is_bin = run_start[:-1], is_bin[:-1]
    planes = np.full((6, BINS, len(nodes)), np.inf, np.float32)
    for plane, row in zip(planes, level.boxes[a]):
        plane.T[filled] = np.minimum.reduceat(row, run_start)[is_bin]
    n_left = np.cumsum(n_in[:, :-1].T, axis=0, dtype=np.float64)  # exact beyond 2**24
    n_right = level.counts[nodes] - n_left
    return _sweep(planes, n_left, n_right, (n_left == 0) | (n_right == 0))


def _sweep_chunks(counts: np.ndarray):
    """[(m, nodes)] for the small nodes (2..SWEEP_MAX triangles) of a level: nodes
    of size class ``m`` (more than the next smaller class, at most m), about
    ``SWEEP_SLOTS`` slots at a time."""
    size_class = np.searchsorted(SLOT_CLASSES, counts).astype(np.uint8)   # big: past the end
    size_class[counts < 2] = len(SLOT_CLASSES)
    by_class = np.argsort(size_class, kind="stable")          # a radix sort for uint8
    class_end = np.cumsum(np.bincount(size_class, minlength=len(SLOT_CLASSES)))
    chunks = []
    for c, m in enumerate(SLOT_CLASSES):
        group = by_class[class_end[c - 1] if c else 0:class_end[c]]
        step = max(1, SWEEP_SLOTS // m)
        chunks.extend((m, group[i:i + step]) for i in range(0, len(group), step))
    return chunks


def _swept(level: Level, a: int, m: int, nodes: np.ndarray):
    """Exact sweep on axis ``a`` for small ``nodes`` (K,) of at most m triangles:
    one slot per triangle."""
    c = level.counts[nodes]
    slot = np.arange(m)[:, None]
    # Padding slots repeat the node's last triangle: a duplicate changes no running
    # box, and splits after the last triangle are invalid anyway.
    index = level.offsets[nodes] + np.minimum(slot, c - 1)
    planes = np.empty((6, m, len(nodes)), np.float32)
    for plane, row in zip(planes, level.boxes[a]):
        np.take(row, index, out=plane, mode="clip")           # "clip": unbuffered out
    key = _centre_key(planes[a], planes[3 + a])
    n_left = np.minimum(slot[1:], c).astype(np.float32)
    n_right = c.astype(np.float32) - n_left
    invalid = key[1:] == key[:-1]                              # no plane between equal centres
    invalid |= n_right == 0
    return _sweep(planes, n_left, n_right, invalid)


def _best_on_axis(level: Level, big: np.ndarray, small_chunks, a: int):
    """cost, n_left, area (S,) of every node's best candidate on axis ``a``: binned
    for the ``big`` nodes, swept for the ``small_chunks`` (see ``_sweep_chunks``)."""
    S = len(level.counts)
    cost, n_left, area = np.full(S, np.inf), np.zeros(S, np.int64), np.zeros(S)
    if len(big):
        cost[big], n_left[big], area[big] = _binned(level, a, big)
    for m, nodes in small_chunks:
        cost[nodes], n_left[nodes], area[nodes] = _swept(level, a, m, nodes)
    return cost, n_left, area


def sah_split(level: Level, leaf_size: int):
    """Split rule: (axis (S,) int64, n_left (S,) int64), n_left = 0 for leaves."""
    if level.depth >= MAX_SAH_DEPTH:
        return median_split(level, leaf_size, "longest")
    counts = level.counts
    best_on_axis = partial(_best_on_axis, level, np.flatnonzero(counts > SWEEP_MAX),
                           _sweep_chunks(counts))
    per_axis = for_each_axis(best_on_axis, len(level.ids[0]))
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
    # Coincident centres: no candidate plane; halve by triangle id (inside such a
    # node every list is in id order, so axis 0 will do).
    by_id = forced & ~splittable
    n_left[by_id] = counts[by_id] // 2
    axis[by_id] = 0
    return axis, n_left


def build(triangles: np.ndarray, leaf_size: int) -> Topology:
    """SAH tree over triangles given by their corners (F, 3, 3) float32."""
    # The box rows are made in the call, not kept here: the engine holds only its
    # sorted copies of them (and the centre keys, computed from them).
    return build_topdown(lambda rows: [_centre_key(rows[a], rows[3 + a]) for a in range(3)],
                         partial(sah_split, leaf_size=leaf_size), boxes=_scaled_box_rows(triangles))


def _scaled_box_rows(triangles: np.ndarray) -> np.ndarray:
    """(6, F) float32 rows min xyz, -max xyz of the triangles' boxes, scaled by a
    power of two (exact) so that the largest magnitude is about 2**SCALE_TO."""
    corners = triangles.transpose(1, 2, 0)                     # (corner, axis, F) view
    rows = np.empty((6, len(triangles)), np.float32)
    np.minimum(corners[0], corners[1], out=rows[:3])
    np.minimum(rows[:3], corners[2], out=rows[:3])
    np.maximum(corners[0], corners[1], out=rows[3:])
    np.maximum(rows[3:], corners[2], out=rows[3:])
    biggest = float(max(-rows[:3].min(), rows[:3].max(), -rows[3:].min(), rows[3:].max()))
    np.negative(rows[3:], out=rows[3:])
    if biggest > 0:
        np.ldexp(rows, SCALE_TO - int(np.ceil(np.log2(biggest))), out=rows)
    return rows
