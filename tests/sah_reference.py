"""A plain top-down SAH builder: the reference ``clrt.accel.sah`` is tested against.

Slow on purpose -- one node at a time, one candidate plane at a time, in float64 --
so that it can be read against the definition in ``clrt/accel/sah.py``'s docstring:

* candidate planes lie between consecutive *distinct* box centres (the centre of
  each triangle's bounding box), sorted on each axis; every one of them is tried
  (no bins);
* cost(split) = C_TRAVERSAL + C_INTERSECT * (A(L) N(L) + A(R) N(R)) / A(node),
  cost(leaf)  = C_INTERSECT * N, A = half the surface area of the exact box of
  the triangles (a zero-area node counts its area ratios as 1);
* leaf policy: 1 triangle -> leaf; more than ``leaf_size`` -> split at the
  cheapest plane, whatever it costs (halved by triangle id when all centres
  coincide); otherwise split only when the cheapest plane is strictly cheaper
  than a leaf.

Ties between planes go to the first axis (x, y, z), then the lowest plane, as in
the fast builder.  The fast builder also switches to median splits from depth 48
on; the meshes the tests use never get that deep.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional

import numpy as np

C_TRAVERSAL = 1.0   # the constants of clrt.accel.bvh (checked in the test module)
C_INTERSECT = 1.0


@dataclass
class Node:
    """A node of the reference tree: the triangle ids below it and its exact box."""

    ids: List[int]
    lo: np.ndarray
    hi: np.ndarray
    left: Optional["Node"] = None
    right: Optional["Node"] = None
    depth: int = 0

    @property
    def is_leaf(self) -> bool:
        return self.left is None


def half_area(lo, hi) -> float:
    """Half the surface area of the box [lo, hi]."""
    dx, dy, dz = (float(h - l) for l, h in zip(lo, hi))
    return dx * dy + dy * dz + dz * dx


def _box(ids, tri_lo, tri_hi):
    lo = tri_lo[ids[0]].copy()
    hi = tri_hi[ids[0]].copy()
    for i in ids[1:]:
        lo = np.minimum(lo, tri_lo[i])
        hi = np.maximum(hi, tri_hi[i])
    return lo, hi


def best_plane(ids, tri_lo, tri_hi, centre):
    """(cost, axis, k, ordered ids) of the cheapest candidate plane of a node
    (the first k triangles of ``ordered`` go left), or None when all centres
    coincide.  cost is the full split cost, C_TRAVERSAL included."""
    n = len(ids)
    lo, hi = _box(ids, tri_lo, tri_hi)
    area = half_area(lo, hi)
    best = None
    for axis in range(3):
        ordered = sorted(ids, key=lambda i: (centre[i][axis], i))
        # Boxes of every prefix and every suffix, grown one triangle at a time.
        prefix, suffix = [None] * n, [None] * n
        for k in range(n):
            i = ordered[k]
            if k == 0:
                prefix[k] = (tri_lo[i].copy(), tri_hi[i].copy())
            else:
                prefix[k] = (np.minimum(prefix[k - 1][0], tri_lo[i]), np.maximum(prefix[k - 1][1], tri_hi[i]))
        for k in range(n - 1, -1, -1):
            i = ordered[k]
            if k == n - 1:
                suffix[k] = (tri_lo[i].copy(), tri_hi[i].copy())
            else:
                suffix[k] = (np.minimum(suffix[k + 1][0], tri_lo[i]), np.maximum(suffix[k + 1][1], tri_hi[i]))
        for k in range(1, n):          # k triangles left, n - k right
            if centre[ordered[k - 1]][axis] == centre[ordered[k]][axis]:
                continue               # no plane between equal centres
            weighted = half_area(*prefix[k - 1]) * k + half_area(*suffix[k]) * (n - k)
            ratio = weighted / area if area > 0 else n
            cost = C_TRAVERSAL + C_INTERSECT * ratio
            if best is None or cost < best[0]:
                best = (cost, axis, k, ordered)
    return best


def build(triangles, leaf_size: int) -> Node:
    """The reference tree over triangles (F, 3, 3) (corners as float32, as the
    device stores them; all arithmetic in float64)."""
    corners = np.asarray(triangles, np.float32).astype(np.float64)
    tri_lo, tri_hi = corners.min(axis=1), corners.max(axis=1)
    centre = (tri_lo + tri_hi) / 2

    def grow(ids: List[int], depth: int) -> Node:
        lo, hi = _box(ids, tri_lo, tri_hi)
        node = Node(ids, lo, hi, depth=depth)
        n = len(ids)
        if n == 1:
            return node
        best = best_plane(ids, tri_lo, tri_hi, centre)
        if n > leaf_size:
            if best is None:                 # coincident centres: halve by id
                ordered = sorted(ids)
                left, right = ordered[:n // 2], ordered[n // 2:]
            else:
                _, _, k, ordered = best
                left, right = ordered[:k], ordered[k:]
        elif best is not None and best[0] < C_INTERSECT * n:
            _, _, k, ordered = best
            left, right = ordered[:k], ordered[k:]
        else:
            return node
        node.left, node.right = grow(left, depth + 1), grow(right, depth + 1)
        return node

    return grow(list(range(len(corners))), 0)


def nodes(root: Node):
    """Every node of the tree, parents before children."""
    out, todo = [], [root]
    while todo:
        node = todo.pop()
        out.append(node)
        if not node.is_leaf:
            todo += [node.right, node.left]
    return out
