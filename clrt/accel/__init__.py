"""Stage 2 of the pipeline: the bounding volume hierarchy over a scene's triangles.

    >>> from clrt.accel import build_bvh
    >>> bvh = build_bvh(mesh.vertices[mesh.faces], volume="ellipse", builder="paper")
    >>> bvh.nodes          # (N,) BVH_NODE, depth-first, ready for upload
    >>> bvh.prim_id        # (F,) int32: leaf slot -> input triangle id
    >>> bvh.stats()

Three independent choices, combined here: the *builder* (``paper``: the paper's
median split; ``sah``: binned surface area heuristic) decides the tree, the
*volume* (``box``, ``sphere``, ``ellipse``) is fitted to each node afterwards,
and ``bvh.linearise`` writes the device layout (``clrt.device.layouts.BVH_NODE``).
"""

from __future__ import annotations

import time

import numpy as np

from clrt.accel import paper, sah
from clrt.accel.bvh import Bvh, linearise, node_boxes, triangle_centroids
from clrt.accel.volumes import VOLUMES, fit
from clrt.errors import InputError
from clrt.scene.mesh import Mesh

BUILDERS = ("paper", "sah")
MAX_LEAF_SIZE = 255


def build_bvh(triangles, volume: str = "box", builder: str = "sah", leaf_size: int = 4) -> Bvh:
    """Build a BVH over triangles.

    triangles: (F, 3, 3) corners (converted to float32, the device precision), or a
        :class:`~clrt.scene.mesh.Mesh`.  Row order is the triangle id.
    volume: one of ``VOLUMES``; builder: one of ``BUILDERS``;
    leaf_size: int 1..255, the most triangles a leaf may hold.
    Raises :class:`~clrt.errors.InputError` on a bad argument.
    """
    start = time.perf_counter()
    if volume not in VOLUMES:
        raise InputError(f"unknown bounding volume {volume!r} (choose from {', '.join(VOLUMES)})")
    if builder not in BUILDERS:
        raise InputError(f"unknown BVH builder {builder!r} (choose from {', '.join(BUILDERS)})")
    if (isinstance(leaf_size, bool) or not isinstance(leaf_size, (int, np.integer))
            or not 1 <= leaf_size <= MAX_LEAF_SIZE):
        raise InputError(f"leaf size must be an integer from 1 to {MAX_LEAF_SIZE}, got {leaf_size!r}")
    leaf_size = int(leaf_size)
    tri = _triangles(triangles)

    if builder == "paper":
        # The paper: longest axis, except for spheres, which cycle the axis by depth.
        rule = "round_robin" if volume == "sphere" else "longest"
        topo = paper.build(triangle_centroids(tri), leaf_size, rule)
    else:
        topo = sah.build(tri, leaf_size)
    boxes = node_boxes(topo, tri)
    nodes, order = linearise(topo)
    boxes = boxes[order]
    nodes["bound_a"], nodes["bound_b"] = fit(volume, boxes)
    return Bvh(nodes=nodes, prim_id=topo.prim_id, volume=volume, builder=builder,
               leaf_size=leaf_size, depth=int(topo.level[-1]) + 1,
               build_ms=(time.perf_counter() - start) * 1e3, boxes=boxes)


def _triangles(triangles) -> np.ndarray:
    """Validate to a C-contiguous (F, 3, 3) float32 array with finite values."""
    if isinstance(triangles, Mesh):
        return triangles.vertices[triangles.faces]
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            tri = np.ascontiguousarray(triangles, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise InputError(f"triangles are not a numeric array ({exc})") from None
    if tri.ndim != 3 or tri.shape[1:] != (3, 3):
        raise InputError(f"triangles must have shape (F, 3, 3), got {tri.shape}")
    if len(tri) == 0:
        raise InputError("cannot build a BVH over zero triangles")
    if len(tri) >= 2 ** 31 - 1:
        raise InputError(f"too many triangles for int32 ids ({len(tri)})")
    if not np.isfinite(tri).all():
        raise InputError("triangle corners contain NaN or infinite (or beyond float32) values")
    return tri


__all__ = ["BUILDERS", "VOLUMES", "Bvh", "build_bvh"]
