"""Batch ray queries on the device: closest hit and occlusion against a mesh.

    >>> hits = clrt.trace("bunny.off", origins, directions)          # t, prim, u, v
    >>> blocked = clrt.occluded(mesh, origins, directions, t_max)
    >>> accel = clrt.Accel(mesh, accel="box", builder="sah")         # build once ...
    >>> accel.trace(origins, directions); accel.occluded(...)        # ... query often

Directions need not be unit length: they are normalised, and ``t`` is the
distance along the normalised direction.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import pyopencl as cl

from clrt.device import layouts
from clrt.device.context import create_context, device_label
from clrt.device.geometry import DeviceGeometry, order_triangles
from clrt.device.program import build_program
from clrt.errors import InputError
from clrt.scene.mesh import Mesh


class Hits(NamedTuple):
    """Closest hits, one entry per ray."""

    t: np.ndarray      # (N,) float32 distance, inf on a miss
    prim: np.ndarray   # (N,) int32 triangle index (row of the mesh's faces), -1 on a miss
    u: np.ndarray      # (N,) float32 barycentric weight of the triangle's vertex 1
    v: np.ndarray      # (N,) float32 barycentric weight of the triangle's vertex 2


def as_mesh(source) -> Mesh:
    """A Mesh from a Mesh, a path, a trimesh.Trimesh or (vertices, faces)."""
    if isinstance(source, Mesh):
        return source
    if isinstance(source, (str, Path)):
        from clrt.scene.load import load_mesh
        return load_mesh(source)
    if hasattr(source, "vertices") and hasattr(source, "faces"):
        return Mesh.from_arrays(source.vertices, source.faces)
    if isinstance(source, tuple) and len(source) == 2:
        return Mesh.from_arrays(*source)
    raise InputError(f"expected a mesh, a path or (vertices, faces), got {type(source).__name__}")


def _rays(origins, directions, tmin, tmax) -> np.ndarray:
    """Validated (N,) RAY records from (3,) or (N, 3) inputs of any float dtype."""
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    o = o.reshape(1, 3) if o.shape == (3,) else o
    d = d.reshape(1, 3) if d.shape == (3,) else d
    if o.ndim != 2 or o.shape[1] != 3 or d.ndim != 2 or d.shape[1] != 3:
        raise InputError(f"origins and directions must have shape (3,) or (N, 3), got {o.shape}, {d.shape}")
    o, d = np.broadcast_arrays(o, d) if len(o) == 1 or len(d) == 1 else (o, d)
    if len(o) != len(d):
        raise InputError(f"{len(o)} origins but {len(d)} directions")
    if not (np.isfinite(o).all() and np.isfinite(d).all()):
        raise InputError("origins and directions must be finite (no NaN or inf)")
    length = np.linalg.norm(d, axis=1)
    if (length == 0).any():
        raise InputError(f"{int((length == 0).sum())} directions have zero length")
    n = len(o)
    rays = np.zeros(n, layouts.RAY)
    rays["origin"][:, :3] = o
    rays["dir"][:, :3] = d / length[:, None]
    rays["origin"][:, 3] = np.broadcast_to(np.asarray(tmin, np.float32), n)
    rays["dir"][:, 3] = np.broadcast_to(np.asarray(tmax, np.float32), n)
    return rays


class Accel:
    """A mesh and its acceleration structure, uploaded once to one device.

    ``accel``: "box" (default), "sphere", "ellipse" or "none"; ``builder``:
    "sah" (default) or "paper"; ``leaf_size``: most triangles per leaf.
    """

    def __init__(self, mesh, accel: str = "box", builder: str = "sah", leaf_size: int = 4,
                 device: str | None = None):
        from clrt.render import flatten_scene
        from clrt.scene.scene import Scene, SceneObject
        self.mesh = as_mesh(mesh)
        tri_verts = flatten_scene(Scene([SceneObject(self.mesh)], [])).tri_verts
        self.order = order_triangles(tri_verts, accel, builder, leaf_size)
        self.context, self.queue = create_context(device)
        self.device = device_label(self.queue.device)
        self.geometry = DeviceGeometry(self.context, self.order)
        program = build_program(self.context, "trace.cl", self.order.defines)
        self.kernels = {name: cl.Kernel(program, name) for name in
                        ("trace_closest", "trace_any", "trace_camera", "occlude_camera")}

    @property
    def bvh(self):
        """The host BVH (clrt.accel.bvh.Bvh), or None for accel="none"."""
        return self.order.bvh

    def _run(self, kernel, rays: np.ndarray, out: np.ndarray) -> np.ndarray:
        mf = cl.mem_flags
        ray_buf = cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=rays)
        out_buf = cl.Buffer(self.context, mf.WRITE_ONLY, max(out.nbytes, 1))
        kernel.set_args(ray_buf, out_buf, np.uint32(len(rays)), *self.geometry.args)
        event = cl.enqueue_nd_range_kernel(self.queue, kernel, (len(rays),), None)
        cl.enqueue_copy(self.queue, out, out_buf, wait_for=[event])
        return out

    def trace(self, origins, directions, tmin=0.0, tmax=np.inf) -> Hits:
        """Closest hit of each ray with tmin < t <= tmax (scalars or per-ray arrays)."""
        rays = _rays(origins, directions, tmin, tmax)
        if len(rays) == 0:
            return Hits(np.zeros(0, np.float32), np.zeros(0, np.int32), np.zeros(0, np.float32),
                        np.zeros(0, np.float32))
        hits = self._run(self.kernels["trace_closest"], rays, np.empty(len(rays), layouts.HIT))
        return Hits(hits["t"].copy(), hits["prim"].copy(), hits["u"].copy(), hits["v"].copy())

    def occluded(self, origins, directions, t_max=np.inf, tmin=0.0) -> np.ndarray:
        """(N,) bool: does anything lie on each ray with tmin < t <= t_max?"""
        rays = _rays(origins, directions, tmin, t_max)
        if len(rays) == 0:
            return np.zeros(0, bool)
        return self._run(self.kernels["trace_any"], rays, np.empty(len(rays), np.uint8)).astype(bool)


    def launch_camera(self, camera, out: cl.Buffer, occlusion: bool = False) -> cl.Event:
        """Enqueue the kernel that makes and traces one ray per pixel of ``camera``
        (closest hits as HIT records, or occlusion bytes, into ``out``)."""
        from clrt.render import camera_args
        kernel = self.kernels["occlude_camera" if occlusion else "trace_camera"]
        kernel.set_args(out, *camera_args(camera), *self.geometry.args)
        return cl.enqueue_nd_range_kernel(self.queue, kernel, (camera.width, camera.height), None)

    def trace_camera(self, camera) -> Hits:
        """Closest hits of the camera's pixel-centre rays, as (H, W) arrays."""
        out = cl.Buffer(self.context, cl.mem_flags.WRITE_ONLY, camera.width * camera.height * layouts.HIT.itemsize)
        hits = np.empty((camera.height, camera.width), layouts.HIT)
        cl.enqueue_copy(self.queue, hits, out, wait_for=[self.launch_camera(camera, out)])
        return Hits(hits["t"].copy(), hits["prim"].copy(), hits["u"].copy(), hits["v"].copy())


def trace(mesh, origins, directions, accel: str = "box", builder: str = "sah", leaf_size: int = 4,
          device: str | None = None, tmin=0.0, tmax=np.inf) -> Hits:
    """Closest hits of a batch of rays: ``Hits(t, prim, u, v)``; build once with :class:`Accel`
    to query a mesh many times."""
    return Accel(mesh, accel, builder, leaf_size, device).trace(origins, directions, tmin, tmax)


def occluded(mesh, origins, directions, t_max=np.inf, accel: str = "box", builder: str = "sah",
             leaf_size: int = 4, device: str | None = None) -> np.ndarray:
    """(N,) bool: is each ray blocked before ``t_max``?"""
    return Accel(mesh, accel, builder, leaf_size, device).occluded(origins, directions, t_max)
