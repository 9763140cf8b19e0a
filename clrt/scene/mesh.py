"""The triangle mesh every later stage works on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clrt.errors import MeshLoadError


@dataclass(frozen=True)
class Mesh:
    """An indexed triangle mesh.

    vertices: (V, 3) float32, faces: (F, 3) int32 indices into ``vertices``.
    Triangles keep their input order, so a primitive id reported by a query
    is the row of ``faces``.  Zero-area triangles are kept (they are never hit)
    so that ids stay aligned with the input file.
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = ""

    @classmethod
    def from_arrays(cls, vertices, faces, name: str = "") -> "Mesh":
        """Validate and convert arrays; raise :class:`MeshLoadError` on bad data."""
        label = f"{name}: " if name else ""
        try:
            v = np.asarray(vertices, dtype=np.float64)
            f = np.asarray(faces)
        except (TypeError, ValueError) as exc:
            raise MeshLoadError(f"{label}vertices/faces are not numeric arrays ({exc})") from None
        if v.ndim != 2 or v.shape[1] != 3:
            raise MeshLoadError(f"{label}vertices must have shape (V, 3), got {v.shape}")
        if f.size == 0:
            raise MeshLoadError(f"{label}mesh has no triangles")
        if f.ndim != 2 or f.shape[1] != 3:
            raise MeshLoadError(f"{label}faces must have shape (F, 3), got {f.shape}")
        if not np.issubdtype(f.dtype, np.integer):
            if not np.all(np.isfinite(f)) or np.any(f != np.round(f)):
                raise MeshLoadError(f"{label}face indices must be integers")
        f = f.astype(np.int64)
        if f.min() < 0 or f.max() >= len(v):
            raise MeshLoadError(
                f"{label}face index out of range (indices {f.min()}..{f.max()}, {len(v)} vertices)")
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            raise MeshLoadError(
                f"{label}{int(bad.sum())} vertices have NaN or infinite coordinates")
        if np.abs(v).max() > 1e30:
            raise MeshLoadError(f"{label}vertex coordinates exceed float32 range")
        return cls(np.ascontiguousarray(v, dtype=np.float32),
                   np.ascontiguousarray(f, dtype=np.int32), name)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: min and max corner of the vertices used by faces."""
        used = self.vertices[self.faces.reshape(-1)].astype(np.float64)
        return np.stack([used.min(axis=0), used.max(axis=0)])

    def face_normals(self) -> np.ndarray:
        """(F, 3) float64 unit geometric normals (zero for zero-area triangles)."""
        tri = self.vertices[self.faces].astype(np.float64)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, length, out=np.zeros_like(n), where=length > 0)

    def vertex_normals(self) -> np.ndarray:
        """(V, 3) float32 area-weighted vertex normals for smooth shading."""
        tri = self.vertices[self.faces].astype(np.float64)
        area_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        acc = np.zeros((len(self.vertices), 3))
        for corner in range(3):
            np.add.at(acc, self.faces[:, corner], area_n)
        length = np.linalg.norm(acc, axis=1, keepdims=True)
        return np.divide(acc, length, out=np.zeros_like(acc), where=length > 0).astype(np.float32)

    def transformed(self, matrix: np.ndarray) -> "Mesh":
        """A copy with a 4x4 affine transform applied to the vertices."""
        m = np.asarray(matrix, dtype=np.float64)
        v = self.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        return Mesh(v.astype(np.float32), self.faces, self.name)

    @staticmethod
    def concatenate(meshes: "list[Mesh]", name: str = "") -> "Mesh":
        """One mesh holding all triangles, in order."""
        offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
        v = np.concatenate([m.vertices for m in meshes])
        f = np.concatenate([m.faces + o for m, o in zip(meshes, offsets)])
        return Mesh(v.astype(np.float32), f.astype(np.int32), name)
