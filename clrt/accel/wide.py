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

Collapsing (Ylitie et al. 2017, "Efficient incoherent ray traversal on GPUs
through compressed wide BVHs", section 3): each binary child becomes a leaf
lane, a lane holding a wide node, or is spread over its parent's lanes through
its own two children -- whichever gives the least SAH cost, found by dynamic
programming bottom up (_plan); a subtree of at most ``MERGE`` triangles (its
slots are consecutive) may become one leaf, a binary leaf stays one.  Against
the greedy collapse it replaces (open the largest inner child until the node
is full) nodes hold 6.4 children instead of 4.3 and bunny00 takes 5,055 nodes
instead of 7,573: about 4 % faster on PoCL (docs/benchmarks.md).  The work is
done level by level for all rows of a level at once, in numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clrt.accel.rows import child_refs
from clrt.accel.topdown import surface_area
from clrt.layouts import BVH_WIDE_NODE, TRIANGLE_PACKET

WIDE = 8        # children per wide node: the lanes of the kernels' float8 box test
PACKET = 4      # triangles per packet: the lanes of the float4 triangle test
MERGE = PACKET  # subtrees of at most this many triangles may become one leaf
# SAH costs of the collapse (_plan): a ray's test of one wide node (one float8
# slab test) and of one packet (one float4 watertight test).
C_NODE = 1.0
C_PACKET = 1.0


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


def _levels(ref: np.ndarray, count: np.ndarray) -> list:
    """The binary rows level by level, top down (the root row alone first)."""
    levels, frontier = [], np.zeros(1, np.int64)
    while len(frontier):
        levels.append(frontier)
        kids = np.concatenate([2 * frontier, 2 * frontier + 1])
        frontier = ref[kids[count[kids] == 0]]
    return levels


def _subtrees(ref: np.ndarray, count: np.ndarray, levels: list):
    """Per binary child: the first slot and the number of triangles of its
    subtree (a subtree's slots are consecutive: leaves take slots depth first).
    Absent children: (0, 0)."""
    inner = np.nonzero(count == 0)[0]
    entry_of_row = np.full(len(ref) // 2, -1, np.int64)
    entry_of_row[ref[inner]] = inner              # the child that is row r
    first = np.where(count > 0, ref, 0)
    tris = np.maximum(count, 0)
    for rows in reversed(levels[1:]):             # bottom up: a row's children are done
        entry = entry_of_row[rows]
        tris[entry] = tris[2 * rows] + tris[2 * rows + 1]
        first[entry] = first[2 * rows]            # the left subtree's slots come first
    return first, tris


# Decisions of the collapse per binary child and lane budget (_plan).
LEAF, NODE, ABSENT = -1, -2, -3


def _plan(ref, count, tris, area, levels):
    """Ylitie et al. 2017, section 3: the SAH-optimal collapse of the binary
    tree into nodes of up to WIDE children, by dynamic programming bottom up.
    cost[e, k] is the least SAH cost of binary child e's subtree spread over at
    most k lanes of its wide parent: as one leaf (C_PACKET a packet, for a
    subtree of at most MERGE triangles or a binary leaf), as one lane holding a
    wide node (C_NODE plus its own children's best spread over WIDE lanes), or
    split into its two children's lanes (i + (k - i)).  choice[e, k] says which
    (LEAF, NODE, or i > 0: the split).  Returns choice, per row r the left
    child's lane budget when r is a wide node (best[r]), and the tree's cost
    below the root node (the root's lanes and everything under them)."""
    n = len(ref)
    cost = np.full((n, WIDE + 1), np.inf)
    choice = np.full((n, WIDE + 1), ABSENT, np.int8)
    best = np.zeros(n // 2, np.int64)
    packets = -(-tris // PACKET)

    pairs = cost.reshape(-1, 2, WIDE + 1)          # a row's two children: one gather

    def spread(rows):
        """Best split of each row's two children over k = 2..WIDE lanes:
        (len(rows), WIDE + 1) costs and left budgets (k < 2: inf).  Of equal
        splits the one giving the left child fewest lanes.  (By the left
        child's budget i, the splits i + (k - i) of every k > i are one slice
        of the right child's costs: no gathers inside the loop.)"""
        both = pairs[rows]
        left, right = both[:, 0], both[:, 1]
        out = np.full((len(rows), WIDE + 1), np.inf)
        arg = np.zeros((len(rows), WIDE + 1), np.int64)
        for i in range(1, WIDE):
            c = left[:, i:i + 1] + right[:, 1:WIDE + 1 - i]      # k = i + 1 .. WIDE
            better = c < out[:, i + 1:]
            out[:, i + 1:][better] = c[better]
            arg[:, i + 1:][better] = i
        return out, arg

    for rows in reversed(levels):                 # bottom up: a row's children are done
        entries = np.concatenate([2 * rows, 2 * rows + 1])
        absent = entries[count[entries] < 0]
        cost[absent, 1:] = 0.0
        leaves = entries[count[entries] > 0]
        cost[leaves, 1:] = (C_PACKET * area[leaves] * packets[leaves])[:, None]
        choice[leaves, 1:] = LEAF
        inner = entries[count[entries] == 0]
        if len(inner) == 0:
            continue
        sub, arg = spread(ref[inner])
        best[ref[inner]] = arg[:, WIDE]
        node = C_NODE * area[inner] + sub[:, WIDE]
        leaf = np.where(tris[inner] <= MERGE, C_PACKET * area[inner] * packets[inner], np.inf)
        one = np.minimum(leaf, node)
        cost[inner, 1] = one
        choice[inner, 1] = np.where(leaf <= node, LEAF, NODE)
        split = sub[:, 2:] < one[:, None]
        cost[inner, 2:] = np.where(split, sub[:, 2:], one[:, None])
        choice[inner, 2:] = np.where(split, arg[:, 2:], choice[inner, 1][:, None])
    sub, arg = spread(np.zeros(1, np.int64))
    best[0] = arg[0, WIDE]
    return choice, best, float(sub[0, WIDE])


def _lanes(rows, ref, choice, best):
    """The lanes of the wide nodes made from binary ``rows``: (len(rows), WIDE)
    binary children (-1: empty), in the order of the binary tree."""
    # items: (node, binary child, lane budget, first lane)
    node = np.repeat(np.arange(len(rows)), 2)
    entry = np.stack([2 * rows, 2 * rows + 1], 1).reshape(-1)
    budget = np.stack([best[rows], WIDE - best[rows]], 1).reshape(-1)
    pos = np.stack([np.zeros_like(rows), best[rows]], 1).reshape(-1)
    while True:
        c = choice[entry, budget].astype(np.int64)
        split = c > 0
        if not split.any():
            break
        keep = ~split
        s = np.nonzero(split)[0]
        # a split child's left child takes its lanes from pos, its right child from pos + c
        node = np.concatenate([node[keep], node[s], node[s]])
        entry_s = entry[s]
        entry = np.concatenate([entry[keep], 2 * ref[entry_s], 2 * ref[entry_s] + 1])
        budget_s, c_s = budget[s], c[s]
        budget = np.concatenate([budget[keep], c_s, budget_s - c_s])
        pos_s = pos[s]
        pos = np.concatenate([pos[keep], pos_s, pos_s + c_s])
    present = choice[entry, budget] != ABSENT
    node, entry, pos = node[present], entry[present], pos[present]
    order = np.lexsort((pos, node))
    node, entry = node[order], entry[order]
    lane = np.arange(len(node)) - np.searchsorted(node, node)   # rank within its node
    src = np.full((len(rows), WIDE), -1, np.int64)
    src[node, lane] = entry
    return src


def collapse(rows: np.ndarray, slotted: np.ndarray) -> WideBvh:
    """The wide BVH of ``rows`` (BVH_PAIR_NODE, box volumes) over ``slotted``
    ((F, 3, 3) float32 corners in slot order)."""
    ref, count, lo, hi = _children(rows)
    levels = _levels(ref, count)
    first, tris = _subtrees(ref, count, levels)
    area = surface_area(lo.astype(np.float64), hi.astype(np.float64))
    choice, best, _ = _plan(ref, count, tris, area, levels)

    waves = []                          # per level: (its binary rows, (m, WIDE) lane sources)
    frontier = np.zeros(1, np.int64)
    while len(frontier):
        src = _lanes(frontier, ref, choice, best)
        waves.append((frontier, src))
        lane = src[src >= 0]
        frontier = ref[lane[_is_node(lane, count, choice)]]   # row-major: the next level in lane order

    # Wide node numbers: level after level, each level in the order its rows were found.
    wide_of_row = np.full(len(rows), -1, np.int64)
    start = 0
    for frontier, _ in waves:
        wide_of_row[frontier] = start + np.arange(len(frontier))
        start += len(frontier)
    sources = np.concatenate([src for _, src in waves])
    present = sources >= 0
    index = np.where(present, sources, 0)
    inner = present & _is_node(index, count, choice)
    leaf = present & ~inner
    lane_ref = np.where(inner, ref[index], np.where(leaf, first[index], 0))
    lane_count = np.where(inner, 0, np.where(leaf, tris[index], -1))

    # Leaves: their slots in packets of PACKET lanes, leaf after leaf in slot order.
    first_slot, leaf_tris = lane_ref[leaf], lane_count[leaf]
    per_leaf = -(-leaf_tris // PACKET)
    order = np.argsort(first_slot, kind="stable")
    first_packet = np.empty(len(order), np.int64)
    first_packet[order] = np.cumsum(per_leaf[order]) - per_leaf[order]
    packet_leaf = np.repeat(order, per_leaf[order])                   # the leaf of each packet
    within = np.arange(len(packet_leaf)) - first_packet[packet_leaf]  # its packet number in the leaf
    k = within[:, None] * PACKET + np.arange(PACKET)                   # triangle of the leaf in each lane
    slots = np.where(k < leaf_tris[packet_leaf, None], first_slot[packet_leaf, None] + k, -1)

    nodes = np.zeros(len(sources), BVH_WIDE_NODE)
    child = np.zeros_like(lane_ref)
    child[inner] = wide_of_row[lane_ref[inner]]
    child[leaf] = first_packet
    lane_count[leaf] = per_leaf
    nodes["child"], nodes["count"] = child, lane_count
    fill_boxes(nodes, sources, rows)
    packets = np.zeros(len(slots), TRIANGLE_PACKET)
    packets["slot"] = slots
    fill_packets(packets, slotted)
    return WideBvh(nodes, packets, len(waves), sources)


def _is_node(entries, count, choice):
    """Which of the lanes' binary children (from _lanes) hold a wide node of their own."""
    return (count[entries] == 0) & (choice[entries, 1] == NODE)


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
