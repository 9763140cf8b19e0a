"""Binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding
volume hierarchies").

Each open node bins its triangles by centroid into ``BINS`` equal slots of its
centroid bounds on each axis and evaluates the surface area heuristic at the
``BINS - 1`` bin boundaries:

    cost(split) = C_TRAVERSAL + (A(L) * N(L) + A(R) * N(R)) / A(node) * C_INTERSECT
    cost(leaf)  = N * C_INTERSECT

with boxes (whatever the final volume shape) and the constants of ``bvh.py``.

Leaf policy (``leaf_size`` is a hard maximum, SAH decides below it):

* 1 triangle -> leaf;
* more than ``leaf_size`` triangles -> always split, at the cheapest boundary even
  when its cost exceeds the leaf cost;
* otherwise split only when the best split is strictly cheaper than a leaf.

Degenerate nodes whose centroids coincide (no axis with a positive centroid extent)
are split at the median of triangle ids.  Below depth ``MAX_SAH_DEPTH`` the
paper's median split on the longest axis takes over, which bounds the depth by
``MAX_SAH_DEPTH + ceil(log2 F)`` even on adversarial inputs (e.g. exponentially
spaced triangles, where every SAH split peels off one bin).

Vectorisation: the engine keeps the triangles of each node sorted by centroid on
every axis, so bin numbers ascend inside a node; the bins are runs, reduced with
``ufunc.reduceat``, and the left/right sweeps over bins are segmented prefix scans
(Hillis-Steele doubling, log2(BINS) steps) over all nodes of the level at once.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from clrt.accel.bvh import C_INTERSECT, C_TRAVERSAL, Level, Topology, build_topdown, surface_area
from clrt.accel.paper import median_split

BINS = 32
MAX_SAH_DEPTH = 48


def _segmented_prefix_min(values: np.ndarray, seg: np.ndarray, span: int) -> np.ndarray:
    """Inclusive running minimum of ``values`` (R, k) restarting where ``seg`` (R,)
    changes; no segment is longer than ``span``."""
    out = values.copy()
    step = 1
    while step < span:
        same = (seg[step:] == seg[:-step])[:, None]
        out[step:] = np.where(same, np.minimum(out[step:], out[:-step]), out[step:])
        step *= 2
    return out


def _best_split_on_axis(level: Level, a: int):
    """Cheapest bin boundary of every node along axis ``a``.

    Returns cost (S,) float64 = A(L) N(L) + A(R) N(R) (inf when the centroid extent
    is zero), n_left (S,) int64, and the node's box area (S,) float64.
    """
    S = len(level.counts)
    ids = level.order[a]
    seg = level.seg
    extent = level.cmax[:, a] - level.cmin[:, a]
    scale = np.divide(BINS, extent, out=np.zeros(S), where=extent > 0)
    b = (level.centroids[ids, a] - level.cmin[seg, a]) * scale[seg]
    key = seg * BINS + np.minimum(b.astype(np.int64), BINS - 1)

    # Bins are runs of equal key (ascending within a node): reduce each run once.
    starts = np.flatnonzero(np.concatenate(([True], key[1:] != key[:-1])))
    run_seg = seg[starts]
    run_count = np.diff(np.append(starts, len(ids)))
    # One min-reduction for both corners: store -max next to min.
    box = np.concatenate([level.lo[ids], -level.hi[ids]], axis=1)
    run_box = np.minimum.reduceat(box, starts, axis=0)
    first_run = np.flatnonzero(np.concatenate(([True], run_seg[1:] != run_seg[:-1])))  # (S,)
    last = np.append(first_run[1:] - 1, len(starts) - 1)                               # (S,)

    before = _segmented_prefix_min(run_box, run_seg, BINS)
    after = _segmented_prefix_min(run_box[::-1], run_seg[::-1], BINS)[::-1]
    count_left = np.cumsum(run_count)
    count_left -= (count_left - run_count)[first_run][run_seg]

    area_before = surface_area(before[:, :3].astype(np.float64), -before[:, 3:].astype(np.float64))
    area_after = surface_area(after[:, :3].astype(np.float64), -after[:, 3:].astype(np.float64))
    cost = np.full(len(starts), np.inf)
    cut = np.ones(len(starts), bool)
    cut[last] = False
    cut = np.flatnonzero(cut)                                 # split after run j
    cost[cut] = (area_before[cut] * count_left[cut]
                 + area_after[cut + 1] * (level.counts[run_seg[cut]] - count_left[cut]))

    best_cost = np.minimum.reduceat(cost, first_run)
    # First run reaching the minimum of its node (lowest boundary on ties).
    hits = np.flatnonzero(cost == best_cost[run_seg])
    hits = hits[np.concatenate(([True], run_seg[hits][1:] != run_seg[hits][:-1]))]
    n_left = np.where(np.isfinite(best_cost), count_left[hits], 0)
    return best_cost, n_left, area_before[last]


def sah_split(level: Level, leaf_size: int):
    """Split rule: (axis (S,) int64, n_left (S,) int64), n_left = 0 for leaves."""
    if level.depth >= MAX_SAH_DEPTH:
        return median_split(level, leaf_size, "longest")
    counts = level.counts
    per_axis = [_best_split_on_axis(level, a) for a in range(3)]
    cost = np.stack([c for c, _, _ in per_axis], 1)
    axis = np.argmin(cost, axis=1)
    rows = np.arange(len(counts))
    best = cost[rows, axis]
    n_left = np.stack([n for _, n, _ in per_axis], 1)[rows, axis]
    area = per_axis[0][2]

    # A zero-area node (all triangles on one line or point): area ratios count as 1.
    ratio = np.divide(best, area, out=counts.astype(np.float64), where=area > 0)
    split_cost = C_TRAVERSAL + C_INTERSECT * ratio
    splittable = np.isfinite(best)
    forced = counts > leaf_size
    do_split = splittable & (forced | (split_cost < C_INTERSECT * counts)) & (counts > 1)
    n_left = np.where(do_split, n_left, 0)
    # Coincident centroids: no binned split exists; halve by triangle id (every
    # list is in id order inside such a node, so axis 0 will do).
    by_id = forced & ~splittable
    n_left[by_id] = counts[by_id] // 2
    axis[by_id] = 0
    return axis, n_left


def build(lo: np.ndarray, hi: np.ndarray, centroids: np.ndarray, leaf_size: int) -> Topology:
    """Binned-SAH tree over triangles given by box min/max (F, 3) float32 and
    centroids (F, 3) float64."""
    return build_topdown(centroids, lo, hi, partial(sah_split, leaf_size=leaf_size))
