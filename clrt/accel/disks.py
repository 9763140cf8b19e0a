"""Flat cylinders ("disks") around the triangles of every child of a wide BVH
node, for the point queries of CPU devices (kernels/point.cl's
walk_wide_points): ``WIDE_DISK`` in clrt/layouts.py, one per wide node, lane k
for child k.

Why: a point far from the surface is about as far from dozens of leaves'
boxes as from its nearest triangle -- an axis-aligned box around a tilted
patch of a smooth surface sticks out towards the point -- and each of those
leaves costs a test of its triangles.  A disk of the patch's own orientation
does not stick out: its distance follows the surface's.  On bunny00 (75k
triangles, 100k points in its box) the walk's leaves fell from 36 a point to
14 and its nodes from 28 to 20, its time by a quarter (the box and the disk
are both lower bounds of the distance: the walk takes the larger).

Each child's triangles are its binary child's (``WideBvh.sources``),
consecutive slots; its disk: the axis n, the sum of their vector areas made
unit (any unit vector where that sum is zero); the centre c, their corners'
mean moved along n to the middle of their extent along it; ``half_height``,
half that extent (every corner x has |n.(x - c)| <= half_height) and
``radius``, the largest distance of a corner from the axis.  The triangles are
the convex hulls of their corners, so they lie in the cylinder too.  Centre
and axis are rounded to float32 first, and half_height and radius measured
about the rounded ones, in float64, rounded up.
"""

from __future__ import annotations

import numpy as np

from clrt.accel.rows import child_refs, tree_levels
from clrt.layouts import WIDE_DISK


def child_slots(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(2R,) int64 first slot and slot count of each binary child (row * 2 + side);
    count 0 for a missing child.  A subtree's slots are consecutive (leaf
    order), so an inner child's run joins its row's two."""
    refs = child_refs(rows).astype(np.int64)
    ref, count = refs[:, 0::2].reshape(-1), refs[:, 1::2].reshape(-1)
    first = np.where(count > 0, ref, 0)
    size = np.where(count > 0, count, 0)
    for level in reversed(tree_levels(rows)):   # the deepest first: an inner child's row is done
        for side in (0, 1):
            at = 2 * level.astype(np.int64) + side
            inner = at[count[at] == 0]
            left, right = 2 * ref[inner], 2 * ref[inner] + 1
            first[inner] = np.minimum(first[left], first[right])
            size[inner] = size[left] + size[right]
    return first, size


def wide_disks(rows: np.ndarray, sources: np.ndarray, slotted: np.ndarray) -> np.ndarray:
    """(N,) WIDE_DISK of the wide nodes whose lanes hold the binary children
    ``sources`` ((N, 8), -1: none) of ``rows``, over the slot-ordered corners
    ``slotted`` ((F, 3, 3) float32, device frame); zeros in empty lanes."""
    first, size = child_slots(rows)
    present = sources >= 0
    lane_child = sources[present]
    s0, n = first[lane_child], size[lane_child]
    corners = slotted.astype(np.float64)
    vector_area = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    cum_area = np.concatenate([np.zeros((1, 3)), np.cumsum(vector_area, axis=0)])
    cum_corner = np.concatenate([np.zeros((1, 3)), np.cumsum(corners.sum(axis=1), axis=0)])
    axis = cum_area[s0 + n] - cum_area[s0]
    length = np.linalg.norm(axis, axis=1)
    axis = np.where(length[:, None] > 0, axis / np.where(length > 0, length, 1)[:, None], [0.0, 0.0, 1.0])
    axis = axis.astype(np.float32).astype(np.float64)
    mean = (cum_corner[s0 + n] - cum_corner[s0]) / (3 * np.maximum(n, 1))[:, None]
    # every lane's slots in turn (each lane's a consecutive run)
    lane = np.repeat(np.arange(len(s0)), n)
    starts = np.cumsum(n) - n
    slot = s0[lane] + np.arange(len(lane)) - starts[lane]
    along = np.einsum("tkj,tj->tk", corners[slot], axis[lane])                 # (T, 3)
    lo = np.minimum.reduceat(along.min(axis=1), starts) if len(lane) else np.zeros(0)
    hi = np.maximum.reduceat(along.max(axis=1), starts) if len(lane) else np.zeros(0)
    centre = mean + ((lo + hi) / 2 - np.einsum("lj,lj->l", mean, axis))[:, None] * axis
    centre = centre.astype(np.float32).astype(np.float64)
    offset = corners[slot] - centre[lane][:, None]                             # (T, 3, 3)
    height = np.einsum("tkj,tj->tk", offset, axis[lane])
    lateral = np.linalg.norm(offset - height[..., None] * axis[lane][:, None], axis=2)
    half = np.maximum.reduceat(np.abs(height).max(axis=1), starts) if len(lane) else np.zeros(0)
    radius = np.maximum.reduceat(lateral.max(axis=1), starts) if len(lane) else np.zeros(0)
    out = np.zeros(len(sources), WIDE_DISK)
    values = {"cx": centre[:, 0], "cy": centre[:, 1], "cz": centre[:, 2], "nx": axis[:, 0], "ny": axis[:, 1],
              "nz": axis[:, 2], "radius": _up(radius), "half_height": _up(half)}
    for name, v in values.items():
        column = np.zeros(sources.shape, np.float32)
        column[present] = v
        out[name] = column
    return out


def _up(x: np.ndarray) -> np.ndarray:
    """float64 values rounded up to float32."""
    f = x.astype(np.float32)
    return np.where(f.astype(np.float64) < x, np.nextafter(f, np.float32(np.inf)), f)


def packet_corners(packets: np.ndarray, num_slots: int) -> np.ndarray:
    """(num_slots, 3, 3) float32: the corners of each slot's triangle, from the
    TRIANGLE_PACKET lanes that hold them (every slot of a wide BVH is in one)."""
    slot = packets["slot"].reshape(-1)
    lanes = slot >= 0
    out = np.zeros((num_slots, 3, 3), np.float32)
    for k, name in enumerate(("v0", "v1", "v2")):   # (P, 3 axes, 4 lanes) -> (P * 4, 3)
        out[slot[lanes], k] = packets[name].transpose(0, 2, 1).reshape(-1, 3)[lanes]
    return out
