"""What the inside queries (winding numbers, signed distances, ``contains``,
SDF grids: :class:`~clrt.query.points.PointQueries`) need beyond the scene on
the device.

- The far fields of the tree (``WINDING_NODE``, winding.cl): made on the
  device from the uploaded rows and triangles, one launch of trace.cl's
  ``winding_nodes`` a tree level, deepest first -- so for every builder
  (host or device) and volume shape alike, and again after a refit, without
  reading the triangles back.  A CPU device that walks the wide BVH reads
  them gathered lane by lane into its nodes (``WIDE_WINDING_NODE``, on the
  host: its memory is the device's).  For bunny00 (75k triangles, 44k rows)
  on PoCL (2 cores) both took 28 ms, where the same sums in numpy on the
  host took 211 ms before any upload (``python -m benchmarks.inside``).
- The pseudo-normals of every slot (``PSEUDO_NORMALS``, signs by normal),
  made on the host from the mesh.
- The sample points of :meth:`~clrt.query.points.PointQueries.sdf_grid`,
  made on the device a chunk at a time (point_grid.cl), from their axes.
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl as cl

from clrt import checks
from clrt.accel.bvh import Acceleration
from clrt.accel.rows import tree_levels
from clrt.device.context import format_bytes
from clrt.device.program import launch_size
from clrt.errors import DeviceMemoryError, InputError
from clrt.accel.wide import WideBvh
from clrt.layouts import PLACED_WINDING_NODE, PSEUDO_NORMALS, WIDE_WINDING_NODE, WINDING_NODE

#: The sign rules of signed distances: the query kernel of each (trace.cl).
SIGN_KERNELS = {"winding": "query_signed_distance_winding", "parity": "query_signed_distance_parity",
                "normal": "query_signed_distance_normal"}

#: How far sdf_grid's default bounds reach past the mesh's box on every side:
#: this times the box's longest side.
GRID_MARGIN = 0.05
#: Work-items per work-group of winding_nodes (a fixed size: PoCL keeps one
#: variant of a kernel per size it runs).
WINDING_NODES_GROUP = 64


def sign_kernel(sign) -> str:
    """The query kernel of sign rule ``sign``; InputError for another value."""
    return SIGN_KERNELS[checks.choice("sign", sign, SIGN_KERNELS)]


def winding_nodes(queue: cl.CommandQueue, kernel: cl.Kernel, acceleration: Acceleration, geometry_args: tuple,
                  max_alloc: int, wide: WideBvh | None = None) -> cl.Buffer:
    """The far fields that the winding numbers' walk reads (winding.cl's
    WindingFarField): the WindingNodes (``2 * len(rows)``) of the uploaded tree
    whose rows the host holds (``acceleration.rows``) -- a two-level scene's
    PlacedWindingNodes (winding_placed.cl) --, made on the device by ``kernel``
    (trace.cl's winding_nodes) with the geometry's arguments ``geometry_args``
    (its buffers, then its SceneInfo) -- or, where the device walks the wide
    BVH ``wide``, those gathered lane by lane into its WideWindingNodes.
    DeviceMemoryError when they exceed one allocation (``max_alloc`` bytes)."""
    rows = acceleration.rows
    node = PLACED_WINDING_NODE if acceleration.instances is not None else WINDING_NODE
    nbytes = 2 * len(rows) * node.itemsize
    if wide is not None:
        nbytes = max(nbytes, len(wide.nodes) * WIDE_WINDING_NODE.itemsize)
    if nbytes > max_alloc:
        raise DeviceMemoryError(f"the winding numbers' far fields need {format_bytes(nbytes)} in one buffer, "
                                f"more than the device's largest allocation ({format_bytes(max_alloc)})")
    nodes = binary_winding_nodes(queue, kernel, 2 * len(rows) * node.itemsize, winding_levels(acceleration),
                                 geometry_args)
    if wide is None:
        return nodes
    binary = np.empty(2 * len(rows), WINDING_NODE)
    cl.enqueue_copy(queue, binary, nodes)
    return cl.Buffer(queue.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=wide_winding_nodes(binary, wide.sources))


def wide_winding_nodes(binary: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """(N,) WIDE_WINDING_NODE: lane k of node n the WindingNode ``binary[sources[n, k]]``
    (clrt.accel.wide.WideBvh.sources), zeros where that is -1."""
    present = sources >= 0
    lanes = binary[np.where(present, sources, 0)]
    out = np.zeros(len(sources), WIDE_WINDING_NODE)
    for k, name in enumerate(("cx", "cy", "cz", "radius")):
        out[name] = np.where(present, lanes["centre"][..., k], 0)
    for k, name in enumerate(("nx", "ny", "nz", "area")):
        out[name] = np.where(present, lanes["normal"][..., k], 0)
    for name in ("first", "second"):   # (N, 8, m) -> (N, m, 8)
        out[name] = np.where(present[..., None], lanes[name], 0).transpose(0, 2, 1)
    return out


def winding_levels(acceleration: Acceleration) -> list[tuple[np.ndarray, int]]:
    """The launches of winding_nodes, in order: the rows of each tree level,
    the deepest first, and whether they are a two-level scene's top level --
    there the meshes' levels come first (those of one depth below their roots
    in one launch), then the top level's, whose leaves are instances."""
    rows = acceleration.rows
    if acceleration.instances is None:
        return [(level, 0) for level in reversed(tree_levels(rows))]
    by_depth: list[list[np.ndarray]] = []
    for root in np.unique(acceleration.instances["root"]):
        for depth, level in enumerate(tree_levels(rows, int(root))):
            if depth == len(by_depth):
                by_depth.append([])
            by_depth[depth].append(level)
    meshes = [np.concatenate(levels) for levels in reversed(by_depth)]
    return [(level, 0) for level in meshes] + [(level, 1) for level in reversed(tree_levels(rows))]


def binary_winding_nodes(queue: cl.CommandQueue, kernel: cl.Kernel, nbytes: int, levels: list,
                         geometry_args: tuple) -> cl.Buffer:
    """The far fields of the uploaded tree's rows (``nbytes`` of them), one
    launch a level of ``levels`` (winding_levels)."""
    mf = cl.mem_flags
    nodes = cl.Buffer(queue.context, mf.READ_WRITE, nbytes)
    buffers = [cl.Buffer(queue.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=level) for level, _ in levels]
    for (level, top), rows in zip(levels, buffers):
        kernel.set_args(nodes, rows, np.uint32(len(level)), np.uint32(top), *geometry_args)
        cl.enqueue_nd_range_kernel(queue, kernel, *launch_size(len(level), WINDING_NODES_GROUP))
    queue.finish()   # before the level buffers go
    return nodes


def pseudo_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) PSEUDO_NORMALS of each face, in the faces' order: its edges' and
    corners' angle-weighted pseudo-normals (Baerentzen and Aanaes 2005) over
    the faces around them, with vertices at one position taken as one (a mesh
    split at its seams, a box with a vertex per face corner, keeps its edges)."""
    _, merged = np.unique(np.asarray(vertices, np.float64), axis=0, return_inverse=True)
    merged = merged.reshape(-1)
    f = merged[np.asarray(faces, np.int64)]
    corners = np.asarray(vertices, np.float64)[np.asarray(faces, np.int64)]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    unit = np.divide(normal, length[:, None], out=np.zeros_like(normal), where=length[:, None] > 0)
    count = int(merged.max()) + 1 if len(merged) else 0
    vertex_sum = np.zeros((count, 3))
    edge_keys = []
    for k in range(3):
        e1 = corners[:, (k + 1) % 3] - corners[:, k]
        e2 = corners[:, (k + 2) % 3] - corners[:, k]
        angle = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=1), np.einsum("fk,fk->f", e1, e2))
        for axis in range(3):
            vertex_sum[:, axis] += np.bincount(f[:, k], angle * unit[:, axis], minlength=count)
        a, b = f[:, k], f[:, (k + 1) % 3]
        edge_keys.append(np.minimum(a, b) * count + np.maximum(a, b))
    keys, edge = np.unique(np.stack(edge_keys, axis=1), return_inverse=True)
    edge = edge.reshape(-1, 3)
    edge_sum = np.zeros((len(keys), 3))
    for axis in range(3):
        edge_sum[:, axis] = np.bincount(edge.reshape(-1), np.repeat(unit[:, axis], 3), minlength=len(keys))
    out = np.zeros(len(f), PSEUDO_NORMALS)
    out["edge"][:, :, :3] = _unit_rows(edge_sum)[edge]
    out["vertex"][:, :, :3] = _unit_rows(vertex_sum)[f]
    return out


def _unit_rows(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0)


# --------------------------------------------------------------------------- sdf_grid's samples

def grid_axes(resolution, bounds, mesh_bounds) -> tuple:
    """The sample positions of sdf_grid along x, y and z, float64 arrays: each
    ``np.linspace(lo, hi, n)`` (both ends included) of ``resolution`` (one int
    for all three axes, or three, each >= 2) over ``bounds`` ((2, 3): the min
    and the max corner, min < max on every axis; None: the mesh's box
    ``mesh_bounds`` grown on every side by GRID_MARGIN times its longest side)."""
    if isinstance(resolution, (list, tuple, np.ndarray)):
        values = list(np.asarray(resolution, dtype=object).reshape(-1)) if np.ndim(resolution) <= 1 else None
        if values is None or len(values) != 3:
            raise checks.fail("resolution", "an integer >= 2 or 3 of them", resolution)
    else:
        values = [resolution] * 3
    sizes = [checks.integer("resolution", v.item() if isinstance(v, np.generic) else v, 2) for v in values]
    if bounds is None:
        lo, hi = (np.asarray(b, np.float64) for b in mesh_bounds)
        margin = GRID_MARGIN * float((hi - lo).max())
        lo, hi = lo - margin, hi + margin
    else:
        try:
            corners = np.asarray(bounds, dtype=object)
        except (TypeError, ValueError):
            corners = None
        if corners is None or corners.shape != (2, 3):
            raise checks.fail("bounds", "((xmin, ymin, zmin), (xmax, ymax, zmax))", bounds)
        lo = np.array(checks.vector("bounds[0]", list(corners[0])))
        hi = np.array(checks.vector("bounds[1]", list(corners[1])))
        if not (lo < hi).all():
            raise InputError(f"bounds must have min < max on every axis, got min {lo.tolist()} and max "
                             f"{hi.tolist()}")
    total = math.prod(sizes)
    checks.host_memory(4 * total, f"an SDF grid of {' x '.join(map(str, sizes))} samples",
                       "ask for a smaller resolution")
    return tuple(np.linspace(lo[k], hi[k], sizes[k]) for k in range(3))


class GridPoints:
    """The samples of a grid (axes ``xs``, ``ys``, ``zs``, float64) as a point
    batch in C order -- sample (i, j, k) is point (i * Y + j) * Z + k -- made a
    chunk at a time on the device (point_grid.cl's grid_points) from the axes
    rounded to float32: no host array of the samples."""

    normalise = False
    on_device = False

    def __init__(self, xs: np.ndarray, ys: np.ndarray, zs: np.ndarray):
        self.axes = (xs, ys, zs)
        self.shape = (len(xs), len(ys), len(zs))
        self.n = math.prod(self.shape)
        #: what grid_points reads: zs, then ys, then xs, float32
        self.axis_values = np.concatenate([zs, ys, xs]).astype(np.float32)

    def __len__(self) -> int:
        return self.n

    def points(self, start: int, stop: int) -> np.ndarray:
        """(M, 3) float32 samples start..stop-1 (on the host: for messages)."""
        flat = np.arange(start, stop, dtype=np.int64)
        _, y, z = self.shape
        index = (flat // (y * z), flat // z % y, flat % z)
        return np.stack([axis[i] for axis, i in zip(self.axes, index)], axis=1).astype(np.float32)

    def bad_ray_message(self, kind: str, i: int, reach=None) -> str:
        return f"grid sample {i} is {self.points(i, i + 1)[0].tolist()}: not finite"
