"""The device builder's reinsertion pass (build_reinsert.cl): its settings and
its launches, queued by clrt.device.build between PLOC and the treelets.

Each iteration moves, all at once, the emitted nodes whose move to another
place in the tree lowers the SAH cost most and touches no other move's
nodes, then refits the tree; the kernel file says how.
"""

from __future__ import annotations

import numpy as np

from clrt import layouts

# Iterations per device type (0: none).  Each is five launches over the
# nodes.  The GPU's trees (treelets after the reinsertion), SAH cost after
# 0 / 2 / 4 / 8 iterations, measured on PoCL (python -m benchmarks.tree_counts;
# docs/benchmarks.md has the rays' traversal counts): bunny00 35.82 / 34.37 /
# 33.98 / 33.76 (host SAH tree 33.95), camel 24.52 / 23.50 / 23.04 / 22.84
# (23.21), 14 x bunny00 (1.06M triangles) 45.85 / 44.03 / 43.48 (43.10).
# Not measured on a GPU yet (docs/benchmarks.md gives the command).  On a
# CPU the build is what a user waits for (each iteration costs bunny00 about
# 30 ms on 2 cores, 14 x bunny00 0.6 s): off there, as the treelets are.
# Off by default on GPUs too until the H200 has measured it.  (Its trees
# differed from build to build while PLOC numbered its nodes by an atomic
# counter, in the order its tiles ran: reinsertion breaks ties of gain by node
# number.  PLOC's numbers are the same in every build now:
# tests/test_reinsert.py.)
REINSERT_ITERATIONS = {"gpu": 0, "cpu": 0}
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
