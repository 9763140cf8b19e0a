"""The device builder's reinsertion pass (build_reinsert.cl): its settings and
its launches, queued by clrt.device.build between PLOC and the treelets.

Each iteration moves, all at once, the emitted nodes whose move to another
place in the tree lowers the SAH cost most and touches no other move's
nodes, then refits the tree; the kernel file says how.
"""

from __future__ import annotations

import numpy as np

from clrt import layouts

# Iterations per device type: (fewer triangles than, iterations), the first
# that applies; none above the last.  Each is five launches over the nodes.
# On the H200 (docs/benchmarks.md, "Building the BVH on the device"), 0 / 2 /
# 4 iterations: SAH cost over the host SAH tree's bunny00 1.055 / 1.013 /
# 1.001, camel 1.057 / 1.013 / 0.993; primary rays 1.039 / 1.028 / 1.011 and
# 1.088 / 0.990 / 0.980 of the host SAH tree's time, random rays 1.081 /
# 1.066 / 1.049 and 1.062 / 1.022 / 1.003; the build 2.2 / 2.6 / 2.8 ms
# (bunny00).  Counted on PoCL (benchmarks/tree_counts.py, random rays' warp
# cost, which followed the H200's random-ray times within 1 %), 4 / 8 / 12 /
# 24 iterations: bunny00 1.044 / 1.037 / 1.010 / 1.010, elephant 1.038 /
# 1.020 / 1.017 / 1.016, camel 0.994 / - / 0.986 / 0.985, homer 0.998 / 0.990
# / 0.988 / 0.988 of the host SAH tree's: 12 below 250,000 triangles (the
# meshes counted have at most 75K; at 250K 8 more iterations would cost about
# 2 ms, by the 1 ms a million below: an estimate).  Above a million triangles
# an iteration costs 1 ms a million (10M: 52 -> 91 ms with 4), where the
# build's time is what issue 38 counts against Warp's: off there for now.  On
# a CPU the build is what a user waits for (each iteration costs bunny00
# about 30 ms on 2 cores): off, as the treelets are.  The trees are the same
# from build to build (PLOC numbers its nodes in a fixed order: reinsertion
# breaks ties of gain by node number).
REINSERT_ITERATIONS = {"gpu": ((250_000, 12), (1_000_000, 4)), "cpu": ()}
REINSERT_MAX = 64        # the most iterations a build takes (build_on_device checks)
# Subtrees one search holds postponed (build_reinsert.cl): a search that
# would hold more leaves the rest unsearched (the tree stays valid).
REINSERT_STACK = 32
# Ancestors a search climbs to (build_reinsert.cl): the work of a search is
# bounded on any tree (a chain of nested triangles is as tall as it has
# triangles).  SAH cost after 4 iterations with the search climbing 2 / 4 /
# 8 / 12 / 16 / all levels: bunny00 35.59 / 34.64 / 34.04 / 33.98 / 33.98 /
# 33.98, camel 24.33 / 23.58 / 23.08 / 23.04 / 23.04 / 23.04.
REINSERT_CLIMB = 16


def reinsert_defines() -> dict:
    return {"REINSERT_STACK": REINSERT_STACK, "REINSERT_CLIMB": REINSERT_CLIMB}


def default_iterations(kind: str, num_tris: int) -> int:
    """Reinsertion's iterations when the caller does not say: the first of
    REINSERT_ITERATIONS' tiers of the device type that num_tris is below, else none."""
    return next((iterations for below, iterations in REINSERT_ITERATIONS[kind] if num_tris < below), 0)


def check_iterations(iterations) -> int:
    from clrt import checks
    return checks.integer("reinsert_iterations", iterations, 0, REINSERT_MAX)


def queue_reinsertion(k, launch, groups, iterations: int, num_tris: int, nodes, heights, moves, locks,
                      arrivals, leaf_size: int) -> None:
    """Queue ``iterations`` of reinsertion on the BuildNode tree ``nodes`` of
    ``num_tris`` triangles (its root 2F - 2 stays the root).  ``moves``,
    ``locks``: scratch of at least 2F - 1 BuildMove and BuildLock; ``arrivals``
    of F - 1 ints; ``launch(phase, kernel, groups, *args)`` and ``groups(n)``
    as clrt.device.build's."""
    if iterations <= 0 or num_tris < 3:
        return
    assert moves.size >= layouts.BUILD_MOVE.itemsize * (2 * num_tris - 1)
    assert locks.size >= layouts.BUILD_LOCK.itemsize * (2 * num_tris - 1)
    F = np.int32(num_tris)
    nodes_groups = groups(2 * num_tris - 1)
    launch("reinsert", k["reinsert_clear"], nodes_groups, locks, np.int32(2 * num_tris - 1))
    k["reinsert_search"].set_args(nodes, moves, locks, arrivals, F)
    k["reinsert_claim"].set_args(nodes, moves, locks, F)
    k["reinsert_check"].set_args(nodes, moves, locks, F)
    k["reinsert_apply"].set_args(nodes, moves, locks, F)
    k["reinsert_refit"].set_args(nodes, heights, arrivals, F, np.uint32(leaf_size))
    for _ in range(iterations):
        for name in ("reinsert_search", "reinsert_claim", "reinsert_check", "reinsert_apply"):
            launch("reinsert", k[name], nodes_groups)
        launch("reinsert", k["reinsert_refit"], groups(num_tris))
