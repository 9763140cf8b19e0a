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

* A hit must lie strictly in front of the origin (t > 0); trimesh's numpy
  intersector also keeps hits up to 1e-6 behind it.
* Hits come sorted by ray, then distance (trimesh gives no order).
* With locations (``intersects_location``, or ``return_locations=True``), hits
  of one ray closer together than float32 can tell apart (a ray through an
  edge or a vertex, or coincident faces) are reported once, as trimesh does by
  merging equal locations; without, every triangle met is listed.
* Locations are computed in float64 on the hit triangle's plane (as trimesh
  does), from the device's float32 hit.
* Bad input raises :class:`clrt.InputError` rather than ValueError.
"""

from __future__ import annotations

import numpy as np

from clrt.query.accel import Accel
from clrt.query.rays import RayBatch
from clrt.scene.sources import as_mesh


class RayMeshIntersector:
    """trimesh's ``RayMeshIntersector`` interface on clrt's device queries.

    ``mesh``: a ``trimesh.Trimesh`` (followed: a changed mesh is uploaded again
    on the next query), a :class:`clrt.Mesh`, a path or (vertices, faces).
    The other arguments are those of :class:`clrt.Accel`.
    """

    def __init__(self, mesh, accel: str = "box", builder: str = "sah", leaf_size: int = 4,
                 device: str | None = None, chunk_rays: int | None = None):
        import trimesh
        from clrt.scene.load_3ds import register_with_trimesh
        register_with_trimesh()   # trimesh.load("x.3ds") works for users of the drop-in too
        self._trimesh = isinstance(mesh, trimesh.Trimesh)
        self.mesh = mesh if self._trimesh else as_mesh(mesh)
        self._options = dict(accel=accel, builder=builder, leaf_size=leaf_size, device=device,
                             chunk_rays=chunk_rays)
        self._accel = None
        self._key = None

    @property
    def accel(self) -> Accel:
        """The uploaded mesh (rebuilt when a trimesh mesh changed since)."""
        key = hash(self.mesh) if self._trimesh else None
        if self._accel is None or key != self._key:
            self._accel = Accel(self.mesh, **self._options)
            self._key = key
            vertices = np.asarray(self.mesh.vertices, dtype=np.float64)
            faces = np.asarray(self.mesh.faces, dtype=np.int64)
            self._corner0 = vertices[faces[:, 0]]
            self._normals = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                     vertices[faces[:, 2]] - vertices[faces[:, 0]])
            lo, hi = vertices.min(axis=0), vertices.max(axis=0)
            self._scale = float(np.linalg.norm(hi - lo) + np.abs(np.stack([lo, hi])).max())
        return self._accel

    # ------------------------------------------------------------------ trimesh's methods

    def intersects_id(self, ray_origins, ray_directions, return_locations: bool = False,
                      multiple_hits: bool = True, max_hits: int | None = None, **kwargs):
        """Triangles hit by the rays.

        Returns ``index_tri`` (h,) int64, ``index_ray`` (h,) int64 and, with
        ``return_locations``, ``locations`` (h, 3) float64.  ``multiple_hits``:
        every hit of each ray, else only the first; ``max_hits``: at most that
        many per ray (nearest first).
        """
        accel = self.accel
        batch = RayBatch(ray_origins, ray_directions)
        if multiple_hits:
            found = accel.all_hits(batch.origins, batch.directions)
            ray, tri, t = found.ray_id, found.prim.astype(np.int64), found.t
        else:
            hits = accel.trace(batch.origins, batch.directions)
            ray = np.nonzero(hits.hit)[0].astype(np.int64)
            tri, t = hits.prim[ray].astype(np.int64), hits.t[ray]
        locations = None
        if return_locations:
            locations = self._locations(batch, ray, tri, t)
            if multiple_hits:
                keep = self._first_of_each_place(ray, t)
                ray, tri, locations = ray[keep], tri[keep], locations[keep]
        if max_hits is not None and multiple_hits and len(ray):
            first = np.r_[0, np.nonzero(np.diff(ray))[0] + 1]
            rank = np.arange(len(ray)) - np.repeat(first, np.diff(np.r_[first, len(ray)]))
            keep = rank < int(max_hits)
            ray, tri = ray[keep], tri[keep]
            locations = None if locations is None else locations[keep]
        if return_locations:
            return tri, ray, locations
        return tri, ray

    def intersects_location(self, ray_origins, ray_directions, multiple_hits: bool = True, **kwargs):
        """``(locations (h, 3) float64, index_ray (h,) int64, index_tri (h,) int64)``:
        where the rays hit, each place along a ray once."""
        tri, ray, locations = self.intersects_id(ray_origins, ray_directions, return_locations=True,
                                                 multiple_hits=multiple_hits, **kwargs)
        return locations, ray, tri

    def intersects_first(self, ray_origins, ray_directions, **kwargs) -> np.ndarray:
        """(n,) int64: the first triangle each ray hits, -1 for none."""
        return self.accel.trace(ray_origins, ray_directions).prim.astype(np.int64)

    def intersects_any(self, ray_origins, ray_directions, **kwargs) -> np.ndarray:
        """(n,) bool: does each ray hit anything?"""
        return self.accel.any_hit(ray_origins, ray_directions)

    def contains_points(self, points) -> np.ndarray:
        """(n,) bool: is each point inside the (closed) mesh?  trimesh's own test:
        the parity of the places hit by rays cast both ways, retried in another
        direction where the two disagree.  Undefined on the surface."""
        from trimesh.ray.ray_util import contains_points
        return contains_points(self, np.asarray(points, dtype=np.float64))

    # ------------------------------------------------------------------ helpers

    def _locations(self, batch: RayBatch, ray, tri, t) -> np.ndarray:
        """Hit points in float64: on the triangle's plane where the ray crosses it
        at a fair angle, else origin + t * direction."""
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
        return o + np.where(fair, t_plane, t.astype(np.float64))[:, None] * d

    def _first_of_each_place(self, ray, t) -> np.ndarray:
        """Mask keeping, along each ray (hits sorted by ray then t), the first of
        hits that float32 cannot tell apart."""
        keep = np.ones(len(ray), bool)
        if len(ray) > 1:
            t64 = t.astype(np.float64)
            tol = 1e-5 * (self._scale + np.abs(t64[1:]))
            keep[1:] = (ray[1:] != ray[:-1]) | (t64[1:] - t64[:-1] > tol)
        return keep
