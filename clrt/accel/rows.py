"""The device rows of a BVH (``BVH_PAIR_NODE`` in clrt/layouts.py): one row per
inner node, holding both children's volumes and references, depth-first, the
root at row 0.  Written from a depth-first tree (``topdown.DepthFirst``) and
the fitted volumes of its nodes (``volumes.fit``)."""

from __future__ import annotations

import numpy as np

from clrt.accel.topdown import C_INTERSECT, C_TRAVERSAL, surface_area
from clrt.layouts import BVH_PAIR_NODE


def pair_rows(first: np.ndarray, count: np.ndarray, right: np.ndarray, bound_a: np.ndarray,
              bound_b: np.ndarray, volume: str) -> np.ndarray:
    """Rows of a tree given per depth-first node: ``first``, ``count``, ``right`` as
    in :class:`clrt.accel.topdown.DepthFirst`, volumes ``bound_a``/``bound_b``
    (N, 4) float32 of ``volume`` (volumes.fit)."""
    inner = np.nonzero(count == 0)[0]
    if len(inner) == 0:   # the whole tree is one leaf: hang it on the left of a root row
        rows = np.zeros(1, BVH_PAIR_NODE)
        _set_child(rows, "left", bound_a[:1], bound_b[:1], first[:1], count[:1], volume)
        child_refs(rows)[:, 2:] = -1        # no right child
        return rows
    row = np.full(len(count), -1, np.int64)
    row[inner] = np.arange(len(inner))      # the root (node 0) is inner: row 0
    rows = np.zeros(len(inner), BVH_PAIR_NODE)
    for side, child in (("left", first[inner]), ("right", right[inner])):
        leaf = count[child] > 0
        _set_child(rows, side, bound_a[child], bound_b[child], np.where(leaf, first[child], row[child]),
                   count[child], volume)
    return rows


def child_refs(rows: np.ndarray) -> np.ndarray:
    """(N, 4) int32 view of the rows' child references: left, left_count, right,
    right_count (the w lanes of left_a, left_b, right_a, right_b)."""
    return rows.view(np.int32).reshape(len(rows), 16)[:, 3::4]


def tree_levels(rows: np.ndarray, root: int = 0) -> list[np.ndarray]:
    """(R_k,) int32 rows of each level of the tree whose root is row ``root``,
    the root's level first: a row's inner children lie one level deeper (the
    order of the bottom-up passes over a tree on the device: refit, winding
    numbers' far fields).  In a two-level scene's rows, the top level's from
    row 0 (its leaves are instances), a mesh's from its root."""
    refs = child_refs(rows)
    levels, current = [], np.full(1, root, np.int32)
    while len(current):
        levels.append(current)
        r = refs[current]
        current = np.concatenate([r[r[:, 1] == 0, 0], r[r[:, 3] == 0, 2]]).astype(np.int32)
    return levels


def _set_child(rows, side: str, bound_a, bound_b, ref, count, volume: str) -> None:
    """Write one side of rows: the child's volume (xyz lanes) and reference (w lanes)."""
    rows[f"{side}_a"][:, :3] = bound_a[:, :3]
    if volume == "sphere":   # the radius leaves bound_a.w, which holds the reference here
        rows[f"{side}_b"][:, 0] = bound_a[:, 3]
    else:
        rows[f"{side}_b"][:, :3] = bound_b[:, :3]
    refs = child_refs(rows)
    k = 0 if side == "left" else 2
    refs[:, k] = ref
    refs[:, k + 1] = count


def tree_stats(exact_rows: np.ndarray, depth: int) -> dict:
    """Bvh.stats()'s tree numbers from BVH_PAIR_NODE rows that hold exact boxes
    (box layout): nodes, leaves, depth, leaf sizes and the SAH cost -- inner
    nodes' areas plus leaves' areas times their counts, over the root's area
    (constants of topdown.py)."""
    refs = child_refs(exact_rows)
    counts = refs[:, [1, 3]].reshape(-1)
    present = counts >= 0
    lo = np.stack([exact_rows["left_a"][:, :3], exact_rows["right_a"][:, :3]], 1).reshape(-1, 3)
    hi = np.stack([exact_rows["left_b"][:, :3], exact_rows["right_b"][:, :3]], 1).reshape(-1, 3)
    area = surface_area(lo.astype(np.float64), hi.astype(np.float64))
    root_lo = lo[present].min(axis=0).astype(np.float64)
    root_hi = hi[present].max(axis=0).astype(np.float64)
    root_area = float(surface_area(root_lo, root_hi))
    ratio = area / root_area if root_area > 0 else np.ones_like(area)
    leaf = counts > 0
    inner = counts == 0
    one_leaf = not inner.any() and leaf.sum() == 1          # a root row holding the whole tree
    sah = (0.0 if one_leaf else C_TRAVERSAL) + C_TRAVERSAL * ratio[inner].sum() \
        + C_INTERSECT * (ratio[leaf] * counts[leaf]).sum()
    return {"nodes": int(leaf.sum() + inner.sum() + (0 if one_leaf else 1)), "leaves": int(leaf.sum()),
            "depth": int(depth), "max_leaf_size": int(counts.max()),
            "mean_leaf_size": float(counts[leaf].mean()), "sah_cost": float(sah)}


def exact_rows(rows: np.ndarray, slotted: np.ndarray) -> np.ndarray:
    """``rows`` with every child's exact box in box layout (its min corner in
    the a lanes, its max corner in the b lanes, the references kept in the w
    lanes), found from ``slotted``, the (F, 3, 3) float32 triangle corners in
    slot order: what the device builder writes into its exact rows when asked
    (clrt.device.build, ``keep_boxes``), for :func:`tree_stats`, here made only
    when statistics are asked for.  Float32 minima and maxima are exact, so
    the boxes are those of any builder's exact fit, bit for bit."""
    refs = child_refs(rows)
    tri_lo = np.minimum(np.minimum(slotted[:, 0], slotted[:, 1]), slotted[:, 2])
    tri_hi = np.maximum(np.maximum(slotted[:, 0], slotted[:, 1]), slotted[:, 2])
    # Boxes by child, 2 * row + side (as refit.cl keeps them): flat indices, not
    # fancy indexing of (row, side) pairs or of the rows' fields (5x faster).
    lo = np.zeros((2 * len(rows), 3), np.float32)
    hi = np.zeros((2 * len(rows), 3), np.float32)
    counts = refs[:, [1, 3]].reshape(-1)
    refs_by_child = refs[:, [0, 2]].reshape(-1)
    # The leaves' slot ranges tile the slots: in order of their first slot,
    # one reduceat gives every leaf's box.
    leaves = np.flatnonzero(counts > 0)
    leaves = leaves[np.argsort(refs_by_child[leaves], kind="stable")]
    first = refs_by_child[leaves]
    if len(first) and (first[0] != 0 or not np.array_equal(first[1:], (first + counts[leaves])[:-1])):
        raise ValueError("the rows' leaves do not cover the slots one after the other")
    lo[leaves] = np.minimum.reduceat(tri_lo, first, axis=0)
    hi[leaves] = np.maximum.reduceat(tri_hi, first, axis=0)
    # Inner children bottom-up, a level at a time (a child row lies one level deeper).
    for level in reversed(tree_levels(rows)):
        children = (2 * level[:, None] + np.arange(2)).reshape(-1)
        inner = children[counts[children] == 0]
        child = 2 * refs_by_child[inner]
        lo[inner] = np.minimum(lo[child], lo[child + 1])
        hi[inner] = np.maximum(hi[child], hi[child + 1])
    exact = rows.copy()
    lanes = exact.view(np.float32).reshape(len(rows), 2, 8)      # per side: a (4 floats), b (4 floats)
    present = (counts >= 0).reshape(-1, 2, 1)
    lanes[:, :, 0:3] = np.where(present, lo.reshape(-1, 2, 3), lanes[:, :, 0:3])
    lanes[:, :, 4:7] = np.where(present, hi.reshape(-1, 2, 3), lanes[:, :, 4:7])
    return exact
