"""The wide BVH that CPU devices walk: the binary rows (``rows.py``) collapsed
into nodes of up to ``WIDE`` children, and the triangles of every leaf in
packets of ``PACKET`` (``BVH_WIDE_NODE`` and ``TRIANGLE_PACKET`` in
clrt/layouts.py).

Why: a CPU runs each work-item's traversal as scalar code, so only vector
types inside one work-item reach its SIMD units.  A wide node lets one ray
test all its children's boxes in a few float8 operations, and a packet its
leaf's triangles in float4 operations (Embree's single-ray BVH8 traversal and
its triangle4 leaves work the same way).  The volumes are the binary rows'
own, bit for bit, so the wide walk is exactly as conservative as the binary
one and finds the same hits.

Collapsing: a subtree of at most ``MERGE`` triangles is taken as one leaf
(its slots are consecutive).  Each wide node starts from one binary row's two
children and repeatedly opens its inner child of largest surface area (the
child most rays enter) until it holds ``WIDE`` children or only leaves; inner
children left become wide nodes of their own.  The work is done level by
level for all nodes of a level at once, in numpy.  (The SAH-optimal collapse
of Ylitie et al. 2017 would cost about 4 % less by the SAH on camel.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clrt.accel.rows import child_refs
from clrt.accel.topdown import surface_area
from clrt.layouts import BVH_WIDE_NODE, TRIANGLE_PACKET

WIDE = 8        # children per wide node: the lanes of the kernels' float8 box test
PACKET = 4      # triangles per packet: the lanes of the float4 triangle test
MERGE = PACKET  # subtrees of at most this many triangles become one leaf


@dataclass
class WideBvh:
    """nodes: (N,) BVH_WIDE_NODE, the root at 0; packets: (P,) TRIANGLE_PACKET;
    depth: wide nodes on the longest root-to-leaf path; sources: (N, WIDE)
    int64, the binary child each lane holds (row * 2 + side, -1: none), so
    that a refit keeps the wide tree and only gathers the new boxes."""

    nodes: np.ndarray
    packets: np.ndarray
    depth: int
    sources: np.ndarray

    def refit(self, rows: np.ndarray, slotted: np.ndarray) -> None:
        """Take the boxes of refitted ``rows`` (the same tree) and the corners of
        ``slotted`` (moved triangles, the same slots)."""
        fill_boxes(self.nodes, self.sources, rows)
        fill_packets(self.packets, slotted)


def _children(rows: np.ndarray):
    """Per binary child (row * 2 + side): reference, count, box lo, box hi."""
    refs = child_refs(rows).astype(np.int64)
    lo = np.stack([rows["left_a"][:, :3], rows["right_a"][:, :3]], axis=1).reshape(-1, 3)
    hi = np.stack([rows["left_b"][:, :3], rows["right_b"][:, :3]], axis=1).reshape(-1, 3)
    return refs[:, 0::2].reshape(-1), refs[:, 1::2].reshape(-1), lo, hi


def _subtrees(ref: np.ndarray, count: np.ndarray):
    """Per binary child: the first slot and the number of triangles of its
    subtree (a subtree's slots are consecutive: leaves take slots depth first).
    Absent children: (0, 0)."""
    inner = np.nonzero(count == 0)[0]
    entry_of_row = np.full(len(ref) // 2, -1, np.int64)
    entry_of_row[ref[inner]] = inner              # the child that is row r
    levels, frontier = [], np.zeros(1, np.int64)
    while len(frontier):                          # rows level by level, top down
        levels.append(frontier)
        kids = np.concatenate([2 * frontier, 2 * frontier + 1])
        frontier = ref[kids[count[kids] == 0]]
    first = np.where(count > 0, ref, 0)
    tris = np.maximum(count, 0)
    for rows in reversed(levels[1:]):             # bottom up: a row's children are done
        entry = entry_of_row[rows]
        tris[entry] = tris[2 * rows] + tris[2 * rows + 1]
        first[entry] = first[2 * rows]            # the left subtree's slots come first
    return first, tris


def collapse(rows: np.ndarray, slotted: np.ndarray) -> WideBvh:
    """The wide BVH of ``rows`` (BVH_PAIR_NODE, box volumes) over ``slotted``
    ((F, 3, 3) float32 corners in slot order)."""
    ref, count, lo, hi = _children(rows)
    # A subtree of at most MERGE triangles becomes one leaf: a packet tests
    # four triangles in about the time of one, and each node saved is a
    # 256-byte fetch saved.
    first, tris = _subtrees(ref, count)
    merged = (count == 0) & (tris <= MERGE)
    ref, count = np.where(merged, first, ref), np.where(merged, tris, count)
    area = surface_area(lo.astype(np.float64), hi.astype(np.float64))

    waves = []                          # per level: (its binary rows, (m, WIDE) lane sources)
    frontier = np.zeros(1, np.int64)
    while len(frontier):
        m = len(frontier)
        src = np.full((m, WIDE), -1, np.int64)
        src[:, 0], src[:, 1] = 2 * frontier, 2 * frontier + 1
        filled = np.full(m, 2)
        every = np.arange(m)
        for _ in range(WIDE - 2):
            present = src >= 0
            inner = present & (count[np.where(present, src, 0)] == 0)
            score = np.where(inner, area[np.where(present, src, 0)], -np.inf)
            j = np.argmax(score, axis=1)
            opens = np.nonzero(inner[every, j] & (filled < WIDE))[0]
            if len(opens) == 0:
                break
            row = ref[src[opens, j[opens]]]
            # the opened child's left child takes its lane, its right child the next free one
            src[opens, filled[opens]] = 2 * row + 1
            src[opens, j[opens]] = 2 * row
            filled[opens] += 1
        waves.append((frontier, src))
        present = src >= 0
        lane = src[present]
        frontier = ref[lane[count[lane] == 0]]          # row-major: the next level in lane order

    # Wide node numbers: level after level, each level in the order its rows were found.
    wide_of_row = np.full(len(rows), -1, np.int64)
    start = 0
    for frontier, _ in waves:
        wide_of_row[frontier] = start + np.arange(len(frontier))
        start += len(frontier)
    sources = np.concatenate([src for _, src in waves])
    present = sources >= 0
    lane_ref = np.where(present, ref[np.where(present, sources, 0)], 0)
    lane_count = np.where(present, count[np.where(present, sources, 0)], -1)

    # Leaves: their slots in packets of PACKET lanes, leaf after leaf in slot order.
    leaf = lane_count > 0
    first_slot, tris = lane_ref[leaf], lane_count[leaf]
    per_leaf = -(-tris // PACKET)
    order = np.argsort(first_slot, kind="stable")
    first_packet = np.empty(len(order), np.int64)
    first_packet[order] = np.cumsum(per_leaf[order]) - per_leaf[order]
    packet_leaf = np.repeat(order, per_leaf[order])                   # the leaf of each packet
    within = np.arange(len(packet_leaf)) - first_packet[packet_leaf]  # its packet number in the leaf
    k = within[:, None] * PACKET + np.arange(PACKET)                   # triangle of the leaf in each lane
    slots = np.where(k < tris[packet_leaf, None], first_slot[packet_leaf, None] + k, -1)

    nodes = np.zeros(len(sources), BVH_WIDE_NODE)
    child = np.zeros_like(lane_ref)
    inner = lane_count == 0
    child[inner] = wide_of_row[lane_ref[inner]]
    child[leaf] = first_packet
    lane_count[leaf] = per_leaf
    nodes["child"], nodes["count"] = child, lane_count
    fill_boxes(nodes, sources, rows)
    packets = np.zeros(len(slots), TRIANGLE_PACKET)
    packets["slot"] = slots
    fill_packets(packets, slotted)
    return WideBvh(nodes, packets, len(waves), sources)


def fill_boxes(nodes: np.ndarray, sources: np.ndarray, rows: np.ndarray) -> None:
    """Write each lane's box from the binary child it holds (``sources``) in
    ``rows``; empty lanes get zeros."""
    _, _, lo, hi = _children(rows)
    present = sources >= 0
    index = np.where(present, sources, 0)
    for axis, name in enumerate("xyz"):
        nodes[f"lo_{name}"] = np.where(present, lo[index, axis], 0.0)
        nodes[f"hi_{name}"] = np.where(present, hi[index, axis], 0.0)


def fill_packets(packets: np.ndarray, slotted: np.ndarray) -> None:
    """Write the corners of ``slotted`` ((F, 3, 3) float32, slot order) into the
    packets' lanes, as their ``slot`` fields say (empty lanes: zeros)."""
    slots = packets["slot"]
    used = slots >= 0
    corners = np.zeros(slots.shape + (3, 3), np.float32)   # (P, PACKET, corner, axis)
    corners[used] = slotted[slots[used]]
    for c, name in enumerate(("v0", "v1", "v2")):
        packets[name] = corners[:, :, c, :].transpose(0, 2, 1)   # (P, axis, lane)
