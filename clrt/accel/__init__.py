"""Stage 2 of the pipeline: the acceleration structure over a scene's triangles.

    >>> from clrt import accel
    >>> built = accel.build(mesh.vertices[mesh.faces], accel="ellipse", builder="paper")
    >>> built.rows         # (R,) BVH_PAIR_NODE, depth-first, ready for upload
    >>> built.prim_ids     # (F,) int32: slot -> input triangle id
    >>> built.stats()

Three independent choices, combined here and nowhere else: the *builder*
(``paper.py``: the paper's median split; ``sah.py``: binned surface area
heuristic -- each only a split rule for the engine in ``topdown.py``) decides
the tree, the *volume* (``volumes.py``: box, sphere, ellipsoid) is fitted to
each node afterwards, and ``rows.py`` writes the device layout
(``BVH_PAIR_NODE`` in clrt/layouts.py).  The names and limits of the choices
are in clrt/config.py.
"""

from __future__ import annotations

import time

import numpy as np

from clrt import checks
from clrt.accel import paper, sah
from clrt.accel.bvh import Acceleration
from clrt.accel.rows import pair_rows
from clrt.accel.topdown import linearise, node_boxes, triangle_centroids
from clrt.accel.volumes import fit
from clrt.config import (ACCELS, BUILDERS, DEFAULT_ACCEL, DEFAULT_LEAF_SIZE, HOST_BUILDERS,
                         HOST_DEFAULT_BUILDER, MAX_LEAF_SIZE)
from clrt.errors import InputError


def build(triangles, accel: str = DEFAULT_ACCEL, builder: str = HOST_DEFAULT_BUILDER,
          leaf_size: int = DEFAULT_LEAF_SIZE) -> Acceleration:
    """Build the acceleration structure over triangles.

    triangles: (F, 3, 3) corners (converted to float32, the device precision).
        Row order is the triangle id.
    accel: one of ``clrt.config.ACCELS`` -- a volume shape, or "none" (no BVH);
    builder: one of ``clrt.config.BUILDERS``; leaf_size: int 1..255, the most
    triangles a leaf may hold.
    Raises :class:`~clrt.errors.InputError` on a bad argument.
    """
    start = time.perf_counter()
    check_options(accel, builder, leaf_size)
    if builder not in HOST_BUILDERS:
        raise InputError(f"builder {builder!r} runs on an OpenCL device: use clrt.device.acceleration.build_acceleration "
                         f"(clrt.accel builds with {', '.join(HOST_BUILDERS)})")
    tri = as_triangles(triangles)
    if accel == "none":
        return Acceleration.brute_force(len(tri))
    leaf_size = int(leaf_size)
    if builder == "paper":
        # The paper: longest axis, except for spheres, which cycle the axis by depth.
        rule = "round_robin" if accel == "sphere" else "longest"
        topo = paper.build(triangle_centroids(tri), leaf_size, rule)
    else:
        topo = sah.build(tri, leaf_size)
    boxes = node_boxes(topo, tri)
    tree = linearise(topo)
    boxes = boxes[tree.order]
    bound_a, bound_b = fit(accel, boxes)
    rows = pair_rows(tree.first, tree.count, tree.right, bound_a, bound_b, accel)
    return Acceleration(accel, builder, rows, np.ascontiguousarray(topo.prim_id, np.int32),
                        depth=int(topo.level[-1]) + 1, build_ms=(time.perf_counter() - start) * 1e3,
                        leaf_size=leaf_size, counts=tree.count, boxes=boxes)


def check_options(accel, builder, leaf_size) -> None:
    """InputError naming the first bad choice (a built builder: not "auto")."""
    checks.choice("accel", accel, ACCELS)
    checks.choice("builder", builder, BUILDERS)
    checks.integer("leaf_size", leaf_size, 1, MAX_LEAF_SIZE)


def as_triangles(triangles, check_finite: bool = True) -> np.ndarray:
    """Validate to a C-contiguous (F, 3, 3) float32 array with finite values
    (``check_finite=False``: the caller checks them, as the device builder
    does on the device)."""
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            tri = np.ascontiguousarray(triangles, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise InputError(f"triangles are not a numeric array ({exc})") from None
    if tri.ndim != 3 or tri.shape[1:] != (3, 3):
        raise InputError(f"triangles must have shape (F, 3, 3), got {tri.shape}")
    if len(tri) == 0:
        raise InputError("cannot build an acceleration structure over zero triangles")
    if len(tri) >= 2 ** 31 - 1:
        raise InputError(f"too many triangles for int32 ids ({len(tri)})")
    if check_finite and not np.isfinite(tri).all():
        raise InputError("triangle corners contain NaN or infinite (or beyond float32) values")
    return tri


__all__ = ["Acceleration", "as_triangles", "build", "check_options"]
