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
instead of 7,573: about 4 % faster on PoCL (docs/benchmark-log.md).  The work is
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


def collapse_defines() -> dict:
    """The constants above as program defines, for the collapse on the device
    (kernels/build_wide.cl; repr of a float is a C double literal of the same value)."""
    return {"WIDE": WIDE, "PACKET": PACKET, "MERGE": MERGE, "C_NODE": f"((double){C_NODE!r})",
            "C_PACKET": f"((double){C_PACKET!r})"}


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

    @property
    def packets_at(self) -> int:
        """Byte offset of the packets after the nodes in one buffer."""
        return self.nodes.nbytes

    @property
    def nbytes(self) -> int:
        return self.nodes.nbytes + self.packets.nbytes

    def refit(self, rows: np.ndarray, slotted: np.ndarray) -> None:
        """Take the boxes of refitted ``rows`` (the same tree) and the corners of
        ``slotted`` (moved triangles, the same slots)."""
        fill_boxes(self.nodes, self.sources, rows)
        fill_packets(self.packets, slotted)


def _entries(rows: np.ndarray):
    """Per binary child (row * 2 + side): reference and count (int64), and its
    8 words as float32 ((2R, 8): box lo xyz, reference, box hi xyz, count --
    a row is its two children's words)."""
    rows = np.ascontiguousarray(rows)
    refs = rows.view(np.int32).reshape(-1, 8)
    return refs[:, 3].astype(np.int64), refs[:, 7].astype(np.int64), rows.view(np.float32).reshape(-1, 8)


def _levels(ref: np.ndarray, count: np.ndarray) -> list:
    """The binary rows top down in blocks: level by level (the root row alone
    first) those with an inner child, then all the others (twigs: rows whose
    children are leaves or absent) in one block.  (Any order within a block
    will do: the nodes are numbered from the tree alone, _numbers.)"""
    forks = (count[0::2] == 0) | (count[1::2] == 0)          # rows with an inner child
    blocks, twigs, frontier = [], [], np.zeros(1, np.int64)
    while len(frontier):
        blocks.append(frontier)
        kids = np.concatenate([2 * frontier, 2 * frontier + 1])
        rows = ref[kids[count[kids] == 0]]
        fork = forks[rows]
        twigs.append(rows[~fork])
        frontier = rows[fork]
    return blocks + [np.concatenate(twigs)]


# Decisions of the collapse per binary child and lane budget (_plan).
LEAF, NODE, ABSENT = -1, -2, -3


class _Tree:
    """The binary tree in breadth-first order, for work level by level on
    slices: row p is the p-th row of _levels, and child x = side * R + p is
    side 0 (left) or 1 (right) of row p.  Per child: ``entry`` (its binary
    child, row * 2 + side), ``count``, ``area``, ``row`` (the row it is, for an
    inner child; else -1); per row: ``parent`` (the child that is this row; -1
    at the root) and ``parent_row`` (the row of that child)."""

    def __init__(self, ref, count, area):
        blocks = _levels(ref, count)
        order = np.concatenate(blocks)
        self.R = R = len(order)
        self.starts = np.cumsum([0] + [len(block) for block in blocks])
        self.entry = np.concatenate([2 * order, 2 * order + 1])
        self.count = count[self.entry]
        self.area = area[self.entry]
        self.ref = ref[self.entry]
        at = np.zeros(len(ref) // 2, np.int64)
        at[order] = np.arange(R)
        inner = np.nonzero(self.count == 0)[0]
        self.row = np.full(2 * R, -1, np.int64)
        self.row[inner] = at[self.ref[inner]]
        self.parent = np.full(R, -1, np.int64)
        self.parent[self.row[inner]] = inner
        self.parent_row = self.parent - np.where(self.parent >= R, R, 0)

    def blocks(self):
        """(start, stop) of _levels's blocks of rows, top down (the twigs last)."""
        return list(zip(self.starts[:-1], self.starts[1:]))


def _spread(left, right):
    """Best split of rows' two children over k = 2..WIDE lanes, from the
    children's costs per lane budget (``left``, ``right``: (WIDE + 1, n)):
    (WIDE + 1, n) costs and left budgets (k < 2: inf and 0).  Of equal splits
    the one giving the left child fewest lanes.  (By the left child's budget
    i, the splits i + (k - i) of every k > i are one slice of the right
    child's costs: no gathers, and no masked writes.)"""
    n = left.shape[1]
    out = np.empty((WIDE + 1, n))
    arg = np.empty((WIDE + 1, n), np.int8)
    out[:2], arg[:2] = np.inf, 0
    c, better, i_better = np.empty((WIDE - 1, n)), np.empty((WIDE - 1, n), bool), np.empty((WIDE - 1, n), np.int8)
    np.add(left[1], right[1:WIDE], out=out[2:])                   # i = 1: k = 2 .. WIDE
    np.less(out[2:], np.inf, out=better)
    arg[2:] = better.view(np.int8)
    for i in range(2, WIDE):
        m = WIDE - i                                              # k = i + 1 .. WIDE
        np.add(left[i], right[1:m + 1], out=c[:m])
        np.less(c[:m], out[i + 1:], out=better[:m])
        np.minimum(out[i + 1:], c[:m], out=out[i + 1:])
        # i where better: i exceeds every budget tried before
        np.maximum(arg[i + 1:], np.multiply(better[:m].view(np.int8), np.int8(i), out=i_better[:m]), out=arg[i + 1:])
    return out, arg


def _plan(tree: _Tree):
    """Ylitie et al. 2017, section 3: the SAH-optimal collapse of the binary
    tree into nodes of up to WIDE children, by dynamic programming bottom up.
    cost[x, k] is the least SAH cost of child x's subtree spread over at most
    k lanes of its wide parent: as one leaf (C_PACKET a packet, for a subtree
    of at most MERGE triangles or a binary leaf), as one lane holding a wide
    node (C_NODE plus its own children's best spread over WIDE lanes), or split
    into its two children's lanes (i + (k - i)).  choice[x, k] says which
    (LEAF, NODE, or i > 0: the split; ABSENT: no child, or k = 0).  Returns
    choice, per row the left child's lane budget when it is a wide node
    (best), per child its subtree's first slot and triangles, and the tree's
    cost below the root node (the root's lanes and everything under them).
    (A level's rows read their children's costs as columns, (WIDE + 1, n), and
    write them to the children that they are as rows: both contiguous.)"""
    R = tree.R
    count = tree.count
    tris = np.maximum(count, 0)
    first = np.where(count > 0, tree.ref, 0)
    # leaves and absent children: the same at every budget k >= 1 (np.repeat: the fastest broadcast)
    alone = np.where(count > 0, C_PACKET * tree.area * -(-tris // PACKET), np.where(count < 0, 0.0, np.inf))
    cost = np.repeat(alone, WIDE + 1).reshape(2 * R, WIDE + 1)
    cost[:, 0] = np.inf
    choice = np.repeat(np.where(count > 0, LEAF, ABSENT).astype(np.int8), WIDE + 1).reshape(2 * R, WIDE + 1)
    choice[:, 0] = ABSENT
    rows_of_choice = choice.view(np.dtype((np.void, WIDE + 1))).reshape(-1)   # a child's choices as one item
    best = np.zeros(R, np.int8)

    def settle(rows, right, sub, arg):
        """The triangles, first slots, costs and choices of the children that
        rows ``rows`` are, from the best splits of the rows' own children
        (``sub``, ``arg``: _spread's).  ``rows`` and ``right`` index the rows'
        left and right children."""
        best[rows] = arg[WIDE]
        x = tree.parent[rows]                     # the children that are these rows
        n = tris[rows] + tris[right]
        tris[x] = n
        first[x] = first[rows]                    # the left subtree's slots come first
        area = tree.area[x]
        node = C_NODE * area + sub[WIDE]
        leaf = np.where(n <= MERGE, C_PACKET * area * -(-n // PACKET), np.inf)
        one = np.minimum(leaf, node)
        one_choice = np.where(leaf <= node, LEAF, NODE).astype(np.int8)
        split = sub[2:] < one                     # else the child takes one lane
        sub[1] = one
        np.minimum(sub[2:], one, out=sub[2:])
        cost[x] = sub.T
        arg[0], arg[1] = ABSENT, one_choice
        arg[2:] -= one_choice                     # arg where split, else one_choice
        arg[2:] *= split
        arg[2:] += one_choice
        rows_of_choice[x] = np.ascontiguousarray(arg.T).view(rows_of_choice.dtype).reshape(-1)

    # Twigs (rows whose children are leaves or absent, 40 % of the rows) depend
    # on no other row: all at once, first.  Their children cost the same at
    # every budget, so every split i + (k - i) costs the same sum as 1 + (k - 1),
    # which _spread would take.
    *levels, (s, e) = tree.blocks()
    pair = cost[s:e, 1] + cost[R + s:R + e, 1]
    sub = np.empty((WIDE + 1, e - s))
    sub[:2], sub[2:] = np.inf, pair
    arg = np.zeros((WIDE + 1, e - s), np.int8)
    arg[2:] = pair < np.inf
    settle(slice(s, e), slice(R + s, R + e), sub, arg)
    for s, e in reversed(levels):                 # bottom up: a row's children are done
        sub, arg = _spread(np.ascontiguousarray(cost[s:e].T), np.ascontiguousarray(cost[R + s:R + e].T))
        if s == 0:                                # the root row: its best split only
            best[0] = arg[WIDE, 0]
            break
        settle(slice(s, e), slice(R + s, R + e), sub, arg)
    return choice, best, first, tris, float(sub[WIDE, 0])


def _lanes(tree: _Tree, choice, best):
    """Top down: the lane budget, first lane and owner (its wide node's row) of
    every child; a child that is not split over lanes (choice LEAF or NODE at
    its budget) takes one lane.  Returns per lane (in child order): child x,
    owner row, first lane, whether it holds a wide node; and per row its wide
    depth (the wide nodes above it)."""
    R = tree.R
    budget = np.zeros(2 * R, np.int8)
    lane = np.zeros(2 * R, np.int8)
    chosen = np.full(2 * R, ABSENT, np.int8)
    owner = np.zeros(R, np.int64)
    depth = np.zeros(R, np.int64)
    flat = choice.reshape(-1)
    at = np.arange(0, 2 * R * (WIDE + 1), WIDE + 1)           # choice[x, 0] in flat
    for s, e in tree.blocks():
        if s == 0:                                  # the root row: the root node
            budget[0], budget[R], lane[R] = best[0], WIDE - best[0], best[0]
        else:
            x, p = tree.parent[s:e], tree.parent_row[s:e]
            c = chosen[x]
            split, node = c > 0, c == NODE
            b = best[s:e] * node                    # a new node: its own best split
            # split: budgets c and budget - c from the child's first lane; a new node: from lane 0
            budget[s:e] = np.where(split, c, b)
            budget[R + s:R + e] = np.where(split, budget[x] - c, (WIDE - b) * node)
            lane[s:e] = lane[x] * split
            lane[R + s:R + e] = np.where(split, lane[x] + c, b)
            owner[s:e] = np.where(split, owner[p], np.arange(s, e))
            depth[s:e] = depth[p] + ~split
        chosen[s:e] = flat[at[s:e] + budget[s:e]]
        chosen[R + s:R + e] = flat[at[R + s:R + e] + budget[R + s:R + e]]
    x = np.nonzero((budget > 0) & ((chosen == LEAF) | (chosen == NODE)))[0]
    p = x - np.where(x >= R, R, 0)
    return x, owner[p], lane[x], chosen[x] == NODE, depth


def _numbers(tree: _Tree, x, owner, lane, is_node, depth):
    """Per row its wide node's number (-1: none), and the number of wide
    levels: nodes level after level (wide depth), each level in the order of
    its parents' numbers and then their lanes -- breadth first, as the waves
    of the greedy collapse numbered them.  Arguments: those of _lanes."""
    number = np.full(tree.R, -1, np.int64)
    number[0] = 0
    rows, parent, at = tree.row[x[is_node]], owner[is_node], lane[is_node]
    level = depth[parent]                         # its parent's level
    start, levels = 1, 1
    for d in range(int(level.max()) + 1 if len(level) else 0):
        pick = np.nonzero(level == d)[0]
        pick = pick[np.argsort(number[parent[pick]] * WIDE + at[pick])]
        number[rows[pick]] = start + np.arange(len(pick))
        start += len(pick)
        levels += 1
    return number, levels


def collapse(rows: np.ndarray, slotted: np.ndarray) -> WideBvh:
    """The wide BVH of ``rows`` (BVH_PAIR_NODE, box volumes) over ``slotted``
    ((F, 3, 3) float32 corners in slot order)."""
    ref, count, words = _entries(rows)
    area = surface_area(words[:, 0:3].astype(np.float64), words[:, 4:7].astype(np.float64))
    tree = _Tree(ref, count, area)
    choice, best, first, tris, _ = _plan(tree)
    x, owner, lane, is_node, depth = _lanes(tree, choice, best)

    number, levels = _numbers(tree, x, owner, lane, is_node, depth)
    n = int(number.max()) + 1

    # Each lane's place: its node, and its rank among the node's lanes in the
    # order of the binary tree (a child spread over k lanes leaves k - 1 unused).
    node = number[owner]
    taken = np.zeros((n, WIDE), np.int8)
    taken[node, lane] = 1
    rank = (np.cumsum(taken, axis=1, dtype=np.int8) - 1)[node, lane]
    sources = np.full((n, WIDE), -1, np.int64)
    sources[node, rank] = tree.entry[x]
    child = np.zeros((n, WIDE), np.int64)
    lane_count = np.full((n, WIDE), -1, np.int64)
    child[node[is_node], rank[is_node]] = number[tree.row[x[is_node]]]
    lane_count[node[is_node], rank[is_node]] = 0

    # Leaves: their slots in packets of PACKET lanes, leaf after leaf in slot order.
    leaf = ~is_node
    first_slot, leaf_tris = first[x[leaf]], tris[x[leaf]]
    per_leaf = -(-leaf_tris // PACKET)
    at_slot = np.full(int(first_slot.max()) + 1, -1)          # leaves hold distinct slots:
    at_slot[first_slot] = np.arange(len(first_slot))
    order = at_slot[at_slot >= 0]                              # the leaves in slot order
    first_packet = np.empty(len(order), np.int64)
    first_packet[order] = np.cumsum(per_leaf[order]) - per_leaf[order]
    packet_leaf = np.repeat(order, per_leaf[order])                   # the leaf of each packet
    within = np.arange(len(packet_leaf)) - first_packet[packet_leaf]  # its packet number in the leaf
    k = within[:, None] * PACKET + np.arange(PACKET)                   # triangle of the leaf in each lane
    slots = np.where(k < leaf_tris[packet_leaf, None], first_slot[packet_leaf, None] + k, -1)
    child[node[leaf], rank[leaf]] = first_packet
    lane_count[node[leaf], rank[leaf]] = per_leaf

    nodes = np.empty(n, BVH_WIDE_NODE)             # every word written: boxes, child, count
    nodes["child"], nodes["count"] = child, lane_count
    _fill_boxes(nodes, sources, words)
    packets = np.empty(len(slots), TRIANGLE_PACKET)  # every word written: corners, slot
    packets["slot"] = slots
    fill_packets(packets, slotted)
    return WideBvh(nodes, packets, levels, sources)


def fill_boxes(nodes: np.ndarray, sources: np.ndarray, rows: np.ndarray) -> None:
    """Write each lane's box from the binary child it holds (``sources``) in
    ``rows``; empty lanes get zeros."""
    _fill_boxes(nodes, sources, _entries(rows)[2])


def _fill_boxes(nodes: np.ndarray, sources: np.ndarray, words: np.ndarray) -> None:
    """fill_boxes from the rows' words per binary child ((2R, 8) float32: lo
    xyz, reference, hi xyz, count): one gather (np.take: whole rows of words)
    and one copy into the nodes' words, lane by lane."""
    n = len(nodes)
    present = sources >= 0
    lanes = np.take(words, np.where(present, sources, 0).reshape(-1), axis=0).reshape(n, WIDE, 8)
    boxes = nodes.view(np.float32).reshape(n, -1)[:, :6 * WIDE].reshape(n, 6, WIDE)   # lo xyz, hi xyz
    boxes[:, 0:3] = lanes[:, :, 0:3].transpose(0, 2, 1)
    boxes[:, 3:6] = lanes[:, :, 4:7].transpose(0, 2, 1)
    node, lane = np.nonzero(~present)
    boxes[node, :, lane] = 0.0


def fill_packets(packets: np.ndarray, slotted: np.ndarray) -> None:
    """Write the corners of ``slotted`` ((F, 3, 3) float32, slot order) into the
    packets' lanes, as their ``slot`` fields say (empty lanes: zeros)."""
    n = len(packets)
    slots = packets["slot"]
    used = slots >= 0
    corners = np.take(np.asarray(slotted).reshape(-1, 9), np.where(used, slots, 0).reshape(-1), axis=0)
    corners = corners.reshape(n, PACKET, 9)                     # (P, lane, corner and axis)
    words = packets.view(np.float32).reshape(n, -1)[:, :9 * PACKET].reshape(n, 9, PACKET)
    for lane in range(PACKET):                                  # (P, corner and axis, lane)
        words[:, :, lane] = corners[:, lane]
    packet, lane = np.nonzero(~used)
    words[packet, :, lane] = 0.0
