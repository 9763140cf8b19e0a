"""The paper's builder (Halim, Liliana, Intan): top-down median split.

A node with at most ``leaf_size`` triangles is a leaf.  Any other node is split at
the median of its triangle centroids along one axis: the left child gets the
floor(n/2) triangles with the smallest centroid coordinate (ties by triangle id),
the right child the rest.  The axis is the longest axis of the node's centroid
bounds (ties: x before y before z); for the sphere volume, which the paper says
has no longest axis, the axis cycles x, y, z, x, ... with the depth.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from clrt.accel.topdown import Level, Topology, build_topdown

AXIS_RULES = ("longest", "round_robin")


def median_split(level: Level, leaf_size: int, axis_rule: str = "longest"):
    """Split rule: (axis (S,) int64, n_left (S,) int64), n_left = 0 for leaves."""
    if axis_rule == "round_robin":
        axis = np.full(len(level.counts), level.depth % 3, np.int64)
    else:
        extent = np.stack([hi - lo for lo, hi in map(level.key_bounds, range(3))], 1)
        axis = np.argmax(extent, axis=1)                      # first maximum on ties
    # Each node's list for ``axis`` is kept sorted by (centroid, id), so the median
    # split is a count: the first floor(n/2) entries go left.
    n_left = np.where(level.counts <= leaf_size, 0, level.counts // 2)
    return axis, n_left


def build(centroids: np.ndarray, leaf_size: int, axis_rule: str = "longest") -> Topology:
    """Median-split tree over triangle centroids (F, 3) float64 (the paper's rule
    needs no boxes).  ``axis_rule``: "longest" or "round_robin"."""
    if axis_rule not in AXIS_RULES:
        raise ValueError(f"axis_rule must be one of {AXIS_RULES}, got {axis_rule!r}")
    return build_topdown(centroids.T,
                         partial(median_split, leaf_size=leaf_size, axis_rule=axis_rule))
