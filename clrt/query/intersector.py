"""A drop-in for trimesh's ray intersectors, answered on the OpenCL device.

    import trimesh, clrt
    mesh = trimesh.load("bunny.ply")
    mesh.ray = clrt.RayMeshIntersector(mesh)      # the one-line switch
    mesh.ray.intersects_location(origins, directions)
    mesh.contains(points)                         # trimesh calls mesh.ray too

The methods, signatures and results are those of
``trimesh.ray.ray_triangle.RayMeshIntersector`` (and of its Embree twin):
``intersects_id``, ``intersects_location``, ``intersects_first``,
``intersects_any`` and ``contains_points``.  Differences worth knowing:

* A hit counts from the origin on (t >= 0), as with Embree; trimesh's numpy
  intersector also keeps hits up to 1e-6 behind it.
* Hits come sorted by ray, then distance (trimesh gives no order).
* With ``multiple_hits``, each ray reports one hit per surface crossing, as
  trimesh's Embree engine does: a ray through an edge or a vertex meets every
  triangle there, and they count once (see :meth:`RayMeshIntersector._crossings`).
  ``every_triangle=True`` lists every triangle met instead, as trimesh's numpy
  engine does; with locations, hits at one place are then still reported once.
* Locations are computed in float64 on the hit triangle's plane (as trimesh
  does), from the device's float32 hit.
* Bad input raises :class:`clrt.InputError` rather than ValueError.
* Pickling or copying keeps the mesh and the options; the device state (the
  uploaded :class:`clrt.Accel`) is made again on first use.
"""

from __future__ import annotations

import threading

import numpy as np

from clrt import checks
from clrt.config import DEFAULT_ACCEL, DEFAULT_LEAF_SIZE, HOST_DEFAULT_BUILDER
from clrt.device import sharing
from clrt.errors import InputError
from clrt.query.accel import Accel
from clrt.query.rays import RayBatch, host_rows
from clrt.scene.sources import as_mesh


# Hits from t = 0 on: the smallest normal float32 below zero, so that a hit at
# exactly t = 0 passes the kernels' tmin < t (a subnormal could be flushed to -0).
TMIN = -float(np.finfo(np.float32).tiny)
# Two hits of a ray are at one place when their distances differ by at most
# PLACE_REL of the mesh's size (its extent, not its distance from anything), plus
# PLACE_ULPS float32 steps at that distance where a distance is the device's
# float32 one; hits on triangles that touch (share a corner position) by
# CROSSING_ULPS float32 steps.  See RayMeshIntersector._crossings.
PLACE_REL = 1e-5
PLACE_ULPS = 1
CROSSING_ULPS = 8


class RayMeshIntersector:
    """trimesh's ``RayMeshIntersector`` interface on clrt's device queries.

    ``mesh``: a ``trimesh.Trimesh`` (followed: a changed mesh is uploaded again
    on the next query), a :class:`clrt.Mesh`, a path or (vertices, faces).
    ``every_triangle``: with ``multiple_hits``, list every triangle a ray meets
    (trimesh's numpy engine) rather than one hit per surface crossing (its
    Embree engine, the default).  The other arguments are those of :class:`clrt.Accel`,
    by keyword as there, except that the builder defaults to the host SAH builder.
    (trimesh's own second argument, ``scale_to_box``, has no meaning here: a
    positional one raises InputError rather than being taken for ``accel``.)
    """

    # Left out of pickles and copies: rebuilt on first use (see ``accel``).
    _DEVICE_STATE = ("_lock", "_accel", "_key", "_corner0", "_normals", "_scale", "_size", "_corners")

    @checks.keyword_options("accel", "builder", "leaf_size", "device", "chunk_rays", "every_triangle")
    def __init__(self, mesh, *, accel: str = DEFAULT_ACCEL, builder: str = HOST_DEFAULT_BUILDER,
                 leaf_size: int = DEFAULT_LEAF_SIZE, device: str | None = None, chunk_rays: int | None = None,
                 every_triangle: bool = False):
        import trimesh
        from clrt.scene.formats.tds import register_with_trimesh
        register_with_trimesh()   # trimesh.load("x.3ds") works for users of the drop-in too
        self._trimesh = isinstance(mesh, trimesh.Trimesh)
        self.mesh = mesh if self._trimesh else as_mesh(mesh)
        self._options = dict(accel=accel, builder=builder, leaf_size=leaf_size, device=device,
                             chunk_rays=chunk_rays)
        self.every_triangle = bool(every_triangle)
        self._lock = threading.Lock()
        self._accel = None
        self._key = None

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k not in self._DEVICE_STATE}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()
        self._accel = None
        self._key = None

    @property
    def accel(self) -> Accel:
        """The uploaded mesh (rebuilt when a trimesh mesh changed since)."""
        key = hash(self.mesh) if self._trimesh else None
        sharing.check_process()   # a forked child: DeviceError, not a wait on a lock held in the parent
        with self._lock:   # threads see the Accel only with the arrays below made for it
            if self._accel is None or key != self._key:
                self._upload(key)
            return self._accel

    def _upload(self, key) -> None:
        """Upload the mesh, and the host arrays that go with it (see _distances, _crossings)."""
        self._accel = Accel(self.mesh, **self._options)
        self._key = key
        vertices = np.asarray(self.mesh.vertices, dtype=np.float64)
        faces = np.asarray(self.mesh.faces, dtype=np.int64)
        self._corner0 = vertices[faces[:, 0]]
        self._normals = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                 vertices[faces[:, 2]] - vertices[faces[:, 0]])
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        self._scale = float(np.linalg.norm(hi - lo) + np.abs(np.stack([lo, hi])).max())
        self._size = float(np.linalg.norm(hi - lo))
        # corners by position (float32, as the device sees them), so that
        # triangles touch where they share a corner even without sharing an index
        _, position = np.unique(vertices.astype(np.float32), axis=0, return_inverse=True)
        self._corners = position.reshape(-1)[faces]

    # ------------------------------------------------------------------ trimesh's methods

    def intersects_id(self, ray_origins, ray_directions, return_locations: bool = False,
                      multiple_hits: bool = True, max_hits: int | None = None,
                      every_triangle: bool | None = None, **kwargs):
        """Triangles hit by the rays.

        Returns ``index_tri`` (h,) int64, ``index_ray`` (h,) int64 and, with
        ``return_locations``, ``locations`` (h, 3) float64.  ``multiple_hits``:
        one hit per surface crossing of each ray (or, with ``every_triangle``,
        every triangle met; default: the intersector's), else only the first;
        ``max_hits``: at most that many per ray (nearest first).
        """
        if max_hits is not None:
            max_hits = checks.integer("max_hits", max_hits, 1)
        accel = self.accel
        batch = RayBatch(ray_origins, ray_directions)
        every = self.every_triangle if every_triangle is None else bool(every_triangle)
        if multiple_hits:
            found = accel.all_hits(batch.origins, batch.directions, tmin=TMIN)
            ray, tri, t = found.ray_id, found.prim.astype(np.int64), found.t
        else:
            hits = accel.trace(batch.origins, batch.directions, tmin=TMIN)
            ray = np.nonzero(hits.hit)[0].astype(np.int64)
            tri, t = hits.prim[ray].astype(np.int64), hits.t[ray]
        distance, exact = self._distances(batch, ray, tri, t)
        if multiple_hits and (return_locations or not every):
            keep = self._crossings(ray, tri, t, distance, exact, touching=not every)
            ray, tri, distance = ray[keep], tri[keep], distance[keep]
        if max_hits is not None and multiple_hits and len(ray):
            first = np.r_[0, np.nonzero(np.diff(ray))[0] + 1]
            rank = np.arange(len(ray)) - np.repeat(first, np.diff(np.r_[first, len(ray)]))
            keep = rank < max_hits
            ray, tri, distance = ray[keep], tri[keep], distance[keep]
        if return_locations:
            o = batch.origins[ray].astype(np.float64)
            d = batch.directions[ray].astype(np.float64)
            return tri, ray, o + distance[:, None] * (d / np.linalg.norm(d, axis=1, keepdims=True))
        return tri, ray

    def intersects_location(self, ray_origins, ray_directions, multiple_hits: bool = True, **kwargs):
        """``(locations (h, 3) float64, index_ray (h,) int64, index_tri (h,) int64)``:
        where the rays hit, each place along a ray once."""
        tri, ray, locations = self.intersects_id(ray_origins, ray_directions, return_locations=True,
                                                 multiple_hits=multiple_hits, **kwargs)
        return locations, ray, tri

    def intersects_first(self, ray_origins, ray_directions, **kwargs) -> np.ndarray:
        """(n,) int64: the first triangle each ray hits, -1 for none."""
        return self.accel.trace(ray_origins, ray_directions, tmin=TMIN).prim.astype(np.int64)

    def intersects_any(self, ray_origins, ray_directions, **kwargs) -> np.ndarray:
        """(n,) bool: does each ray hit anything?"""
        return self.accel.any_hit(ray_origins, ray_directions, tmin=TMIN)

    def contains_points(self, points) -> np.ndarray:
        """(n,) bool: is each point inside the (closed) mesh?  trimesh's own test:
        the parity of the places hit by rays cast both ways, retried in another
        direction where the two disagree.  Undefined on the surface."""
        from trimesh.ray.ray_util import contains_points
        points = host_rows(points, "points")   # InputError, as every query, rather than trimesh's
        if not np.isfinite(points).all():
            bad = int(np.argmin(np.isfinite(points).all(axis=1)))
            raise InputError(f"point {bad} is {points[bad].tolist()}: points must be finite")
        return contains_points(self, points.astype(np.float64))

    # ------------------------------------------------------------------ helpers

    def _distances(self, batch: RayBatch, ray, tri, t):
        """(h,) float64 distance of each hit along its unit direction, and (h,) bool
        whether it is exact: on the triangle's plane, in float64 (as trimesh
        computes locations) where the ray crosses it at a fair angle, else the
        device's float32 t."""
        o = batch.origins[ray].astype(np.float64)
        d = batch.directions[ray].astype(np.float64)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        n = self._normals[tri]
        denom = np.einsum("ij,ij->i", d, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_plane = np.einsum("ij,ij->i", self._corner0[tri] - o, n) / denom
        n_len = np.linalg.norm(n, axis=1)
        fair = (np.abs(denom) > 1e-3 * n_len) & np.isfinite(t_plane)
        fair &= np.abs(t_plane - t) <= 1e-4 * (self._scale + np.abs(t))
        return np.where(fair, t_plane, t.astype(np.float64)), fair

    def _crossings(self, ray, tri, t, distance, exact, touching: bool = True) -> np.ndarray:
        """Mask keeping, along each ray (hits sorted by ray, then t, then
        triangle), the first hit of each surface crossing.

        A hit is at the place of the hit before it when their distances differ
        by at most PLACE_REL of the mesh's size, plus PLACE_ULPS float32 steps
        at that distance unless both distances are exact (float64, on the
        triangles' planes): two surfaces merge only when they are one place, or
        float32 cannot tell them apart, never merely for lying far from the
        origin.  With ``touching``, a hit whose triangle shares a corner
        position with the previous one also belongs to its crossing when within
        CROSSING_ULPS float32 steps: a ray through an edge or a vertex meets
        every triangle there (trimesh's Embree engine reports that crossing
        once), each at a distance of its own rounding."""
        keep = np.ones(len(ray), bool)
        if len(ray) < 2:
            return keep
        gap = np.abs(distance[1:] - distance[:-1])
        size = PLACE_REL * self._size
        step = np.spacing(np.maximum(np.abs(t[1:]), np.abs(t[:-1])).astype(np.float32)).astype(np.float64)
        inexact = ~(exact[1:] & exact[:-1])
        same = gap <= size + np.where(inexact, PLACE_ULPS * step, 0.0)
        if touching:
            a, b = self._corners[tri[:-1]], self._corners[tri[1:]]
            touch = (a[:, :, None] == b[:, None, :]).any(axis=(1, 2))
            same |= touch & (gap <= size + CROSSING_ULPS * step)
        keep[1:] = (ray[1:] != ray[:-1]) | ~same
        return keep
