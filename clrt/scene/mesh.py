"""The triangle mesh every later stage works on."""

from __future__ import annotations

from dataclasses import dataclass

import math

import numpy as np

from clrt import config
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
        if np.abs(v).max() > config.MAX_COORDINATE:
            raise MeshLoadError(f"{label}vertex coordinates must lie within +-{config.MAX_COORDINATE:.0e} "
                                "(the device computes in float32)".replace("e+", "e"))
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

    def split_at_creases(self, crease: float = config.DEFAULT_CREASE_ANGLE) -> "Mesh":
        """The same triangles, in the same order and at the same (bitwise)
        positions, with vertices shared exactly where smooth shading should
        blend normals: coincident vertices are merged (STL files and many
        exporters repeat a vertex for every face), then split again along
        creases -- edges whose two faces meet at more than ``crease`` degrees
        -- so that :meth:`vertex_normals` of the result gives each corner the
        area-weighted normal of the faces around its vertex on its own side of
        any crease (Blender's auto-smooth, trimesh's ``smooth_shade``).  A box
        keeps flat faces, a sphere stays round; ``crease=180`` smooths every edge.

        Each corner starts as its own vertex; the two corners that a smooth
        edge's faces have at each end of the edge are joined (union-find by
        label propagation), so a vertex's faces fall into the fans between
        its creases.
        """
        faces = self.faces
        n_faces = len(faces)
        # Merge bitwise-equal positions (-0.0 and 0.0 stay apart, so positions never change).
        v = np.ascontiguousarray(self.vertices, dtype=np.float32)
        _, weld = np.unique(v.view(np.dtype((np.void, 12))).reshape(-1), return_inverse=True)
        welded = weld.reshape(-1)[faces].astype(np.int64)               # (F, 3)
        normals = self.face_normals()
        # Half-edge 3f + k runs from corner k to corner k + 1 of face f.
        a, b = welded.reshape(-1), np.roll(welded, -1, axis=1).reshape(-1)
        key = np.minimum(a, b) * (int(weld.max()) + 1) + np.maximum(a, b)
        order = np.argsort(key)
        sorted_key = key[order]
        same = np.flatnonzero(sorted_key[1:] == sorted_key[:-1])
        h1, h2 = order[same], order[same + 1]                           # half-edges of one edge
        f1, f2 = h1 // 3, h2 // 3
        cos_limit = math.cos(math.radians(float(crease))) - 1e-6         # float32 positions: ~1e-7
        smooth = (f1 != f2) & (np.einsum("ij,ij->i", normals[f1], normals[f2]) >= cos_limit)
        h1, h2, f1, f2 = h1[smooth], h2[smooth], f1[smooth], f2[smooth]
        n1 = 3 * f1 + (h1 + 1) % 3                                      # corner at the half-edge's end
        n2 = 3 * f2 + (h2 + 1) % 3
        straight = a[h1] == a[h2]                                       # both run the same way
        left = np.concatenate([h1, n1])
        right = np.concatenate([np.where(straight, h2, n2), np.where(straight, n2, h2)])
        label = np.arange(3 * n_faces)
        while len(left):
            low = np.minimum(label[left], label[right])
            before = label.copy()
            np.minimum.at(label, left, low)
            np.minimum.at(label, right, low)
            while True:   # pointer jumping: every corner to its group's smallest corner
                jumped = label[label]
                if np.array_equal(jumped, label):
                    break
                label = jumped
            if np.array_equal(label, before):
                break
        is_root = label == np.arange(3 * n_faces)
        corner_vertex = (np.cumsum(is_root) - 1)[label]
        vertices = self.vertices[faces.reshape(-1)[is_root]]
        return Mesh(vertices, corner_vertex.reshape(n_faces, 3).astype(np.int32), self.name)

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
