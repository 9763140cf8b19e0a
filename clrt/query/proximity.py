"""A drop-in for trimesh's proximity queries (``mesh.nearest``), answered on
the OpenCL device.

    import trimesh, clrt
    mesh = trimesh.load("bunny.ply")
    mesh.nearest = clrt.ProximityQuery(mesh)           # the one-line switch
    closest, distance, triangle_id = mesh.nearest.on_surface(points)
    inside_positive = mesh.nearest.signed_distance(points)

The methods, signatures and results are those of
``trimesh.proximity.ProximityQuery``: ``on_surface``, ``signed_distance`` and
``vertex``.  What differs:

* The nearest triangle is clrt's (``Accel.closest_points``); the closest
  point on it and its distance are then computed in float64 by trimesh's own
  ``trimesh.triangles.closest_point``, so they are trimesh's to the last bit
  for that triangle.  Where several triangles are as near (within trimesh's
  ``tol.merge`` of the squared distance: the point is nearest to an edge or a
  corner they share), the one whose normal faces the point most is taken, as
  trimesh does.
* ``signed_distance`` keeps trimesh's sign (positive inside, negative
  outside, positive within ``tol.merge`` of the surface), decided by the
  winding number (``Accel.contains``) rather than by trimesh's face normal and
  ray test: the same on closed meshes, and defined on open ones.
* ``vertex`` (the nearest vertex) is trimesh's own (its k-d tree, scipy).
* Bad input raises :class:`clrt.InputError` rather than ValueError.
"""

from __future__ import annotations

import numpy as np

from clrt import checks
from clrt.config import DEFAULT_ACCEL, DEFAULT_LEAF_SIZE, HOST_DEFAULT_BUILDER
from clrt.query.intersector import RayMeshIntersector
from clrt.query.rays import host_rows

#: trimesh.constants.tol.merge: squared distances within it are ties, and
#: points within it of the surface are on it (positive signed distance).
TOL_MERGE = 1e-8


class ProximityQuery:
    """trimesh's ``ProximityQuery`` interface on clrt's point queries.

    ``mesh``: a ``trimesh.Trimesh`` (followed: a changed mesh is uploaded again
    on the next query, as by :class:`clrt.RayMeshIntersector`, which holds the
    upload), a :class:`clrt.Mesh`, a path or (vertices, faces); the options
    are those of :class:`clrt.Accel`, by keyword, the builder defaulting to
    the host SAH builder as the intersector's."""

    @checks.keyword_options("accel", "builder", "leaf_size", "device", "chunk_rays")
    def __init__(self, mesh, *, accel: str = DEFAULT_ACCEL, builder: str = HOST_DEFAULT_BUILDER,
                 leaf_size: int = DEFAULT_LEAF_SIZE, device: str | None = None, chunk_rays: int | None = None):
        self._rays = RayMeshIntersector(mesh, accel=accel, builder=builder, leaf_size=leaf_size, device=device,
                                        chunk_rays=chunk_rays)

    @property
    def mesh(self):
        return self._rays.mesh

    def on_surface(self, points):
        """The nearest point of the mesh to each point.

        Returns ``closest`` (m, 3) float64, ``distance`` (m,) float64 and
        ``triangle_id`` (m,) int64: the point on the triangle nearest to each
        query point, its distance, and the triangle (of equally near ones, the
        one whose normal faces the point most)."""
        points = self._points(points)
        near = self._rays.accel.closest_points(points, fields=("prim", "u", "v"))
        triangles = self._triangles()
        tid = near.prim.astype(np.int64)
        boundary = (near.u <= 1e-6) | (near.v <= 1e-6) | (near.u + near.v >= 1 - 1e-6)
        if boundary.any():
            tid[boundary] = self._facing(points[boundary], tid[boundary], triangles)
        closest = _closest_on(triangles[tid], points)
        return closest, np.linalg.norm(points - closest, axis=1), tid

    def signed_distance(self, points) -> np.ndarray:
        """(m,) float64: each point's distance to the mesh (:meth:`on_surface`'s),
        positive inside (winding number >= 1/2) or within 1e-8 of the surface,
        negative outside -- trimesh's sign."""
        points = self._points(points)
        _, distance, _ = self.on_surface(points)
        inside = self._rays.accel.contains(points)
        return np.where(inside | (distance <= TOL_MERGE), distance, -distance)

    def vertex(self, points):
        """``(distance (m,), vertex_id (m,))`` of the nearest vertex: trimesh's own
        answer (its k-d tree)."""
        from trimesh.proximity import ProximityQuery as TrimeshProximity
        return TrimeshProximity(self._trimesh()).vertex(points)

    # ------------------------------------------------------------------ helpers

    @staticmethod
    def _points(points) -> np.ndarray:
        return np.asarray(host_rows(points, "points"), np.float64)

    def _trimesh(self):
        import trimesh
        mesh = self.mesh
        return mesh if isinstance(mesh, trimesh.Trimesh) else trimesh.Trimesh(mesh.vertices, mesh.faces,
                                                                              process=False)

    def _triangles(self) -> np.ndarray:
        mesh = self.mesh
        return np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces, np.int64)]

    def _facing(self, points: np.ndarray, tid: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """For points nearest to an edge or a corner of triangle ``tid``: of the
        triangles sharing a corner position with it that are as near (squared
        distances within TOL_MERGE of the nearest's), the one whose unit normal
        has the largest dot product with the unit vector to the point (trimesh's
        choice)."""
        faces = np.asarray(self.mesh.faces, np.int64)
        _, position = np.unique(np.asarray(self.mesh.vertices, np.float64), axis=0, return_inverse=True)
        corner = position.reshape(-1)[faces]                     # (F, 3) corner positions
        flat = corner.reshape(-1)
        order = np.argsort(flat, kind="stable")
        first = np.searchsorted(flat[order], np.arange(position.max() + 2))
        # every (point, triangle at one of its triangle's corners) pair
        at = corner[tid]                                         # (k, 3)
        counts = (first[at + 1] - first[at]).reshape(-1)
        point_of = np.repeat(np.repeat(np.arange(len(tid)), 3), counts)
        starts = np.repeat(first[at].reshape(-1), counts)
        offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        candidate = order[starts + offsets] // 3
        q = _closest_on(triangles[candidate], points[point_of])
        vector = points[point_of] - q
        d2 = np.einsum("ij,ij->i", vector, vector)
        best = np.full(len(tid), np.inf)
        np.minimum.at(best, point_of, d2)
        normal = np.cross(triangles[candidate, 1] - triangles[candidate, 0],
                          triangles[candidate, 2] - triangles[candidate, 0])
        length = np.linalg.norm(normal, axis=1) * np.sqrt(d2)
        with np.errstate(invalid="ignore", divide="ignore"):
            facing = np.einsum("ij,ij->i", normal, vector) / length
        tied = (d2 - best[point_of] < TOL_MERGE) & (d2 > TOL_MERGE) & np.isfinite(facing)
        score = np.where(tied, facing, -np.inf)
        chosen = tid.copy()
        top = np.full(len(tid), -np.inf)
        np.maximum.at(top, point_of, score)
        winner = tied & (score == top[point_of])
        # the lowest candidate index among equal scores, as the walk's ties
        pick = np.full(len(tid), np.iinfo(np.int64).max)
        np.minimum.at(pick, point_of[winner], candidate[winner])
        found = pick < np.iinfo(np.int64).max
        chosen[found] = pick[found]
        return chosen


def _closest_on(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(k, 3) float64 closest points of ``triangles`` (k, 3, 3) to ``points`` (k, 3):
    trimesh's own ``trimesh.triangles.closest_point``."""
    from trimesh.triangles import closest_point
    if not len(points):
        return np.zeros((0, 3))
    return np.asarray(closest_point(triangles=triangles, points=points), np.float64)
