"""The triangle mesh every later stage works on."""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, replace
from functools import cached_property, partial

import numpy as np

from clrt import config
from clrt.errors import MeshLoadError
from clrt.scene.blocks import map_blocks


def _real_array(value, what: str) -> np.ndarray:
    """``value`` as a numpy array of real numbers (integers or floats, not bools
    or complex numbers); MeshLoadError otherwise."""
    try:
        a = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise MeshLoadError(f"{what} are not numeric arrays ({exc})") from None
    if a.dtype == object:
        try:
            a = a.astype(np.float64)
        except (TypeError, ValueError) as exc:
            raise MeshLoadError(f"{what} are not numeric arrays ({exc})") from None
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise MeshLoadError(f"{what} must be real numbers, got an array of {a.dtype}")
    return a


def _checked_vertices(vertices, label: str) -> np.ndarray:
    """(V, 3) float32 of finite coordinates within +-MAX_COORDINATE (checked in
    the caller's own precision, before the cast could turn 1e39 into inf)."""
    v = _real_array(vertices, f"{label}vertices")
    if v.ndim != 2 or v.shape[1] != 3:
        raise MeshLoadError(f"{label}vertices must have shape (V, 3), got {v.shape}")
    if not v.size:
        return np.zeros((0, 3), np.float32)
    low, high = min_max(v)   # NaN if any is (no temporary arrays)
    if not (np.isfinite(low) and np.isfinite(high)):
        bad = ~np.isfinite(v).all(axis=1)
        raise MeshLoadError(f"{label}{int(bad.sum())} vertices have NaN or infinite coordinates "
                            f"(the first: {vertex_text(v, int(np.argmax(bad)))})")
    if max(high, -low) > config.MAX_COORDINATE:
        with np.errstate(over="ignore"):
            bad = (np.abs(v) > config.MAX_COORDINATE).any(axis=1)   # only on the way to the error
        raise MeshLoadError(f"{label}vertex coordinates must lie within +-{config.MAX_COORDINATE:.0e} "
                            f"(the device computes in float32): {int(bad.sum())} lie beyond (the first: "
                            f"{vertex_text(v, int(np.argmax(bad)))})".replace("e+", "e"))
    return np.ascontiguousarray(v, dtype=np.float32)


def _welded(vertices: np.ndarray) -> np.ndarray:
    """(V,) int64: for each vertex the rank of its position among the distinct
    ones, positions equal when bitwise equal (-0.0 and 0.0 stay apart, so
    positions never change) -- the ranks np.unique gives their 12 bytes as
    void records, in memory order, found as two sorts of integers (the
    first 8 bytes read big-endian, then the last 4 with that rank): a third
    of np.unique's time over the bytes (memcmp for every comparison).  The
    same labels, so the crease split ties edges in the same order."""
    raw = np.ascontiguousarray(vertices, dtype=np.float32).view(np.uint8).reshape(-1, 12)
    head = np.ascontiguousarray(raw[:, :8]).view(">u8").reshape(-1).astype(np.uint64)
    tail = np.ascontiguousarray(raw[:, 8:]).view(">u4").reshape(-1).astype(np.uint64)
    _, head_rank = np.unique(head, return_inverse=True)
    _, weld = np.unique((head_rank.reshape(-1).astype(np.uint64) << np.uint64(32)) | tail, return_inverse=True)
    return weld.reshape(-1)


# Rows of (N, 3) points folded into one row of a reduction: numpy reduces an
# (N / 1024, 3072) array along its first axis at memory speed, an (N, 3) one
# three numbers at a time (1M vertices: 0.4 ms against 40 ms).
FOLD_ROWS = 1024
# Faces whose corners Mesh.bounds marks in one step (its intp indices: 2 MB).
MARK_ROWS = 1 << 18
# Rows min_max reduces at a time (1.5 MB of faces or vertices).
MIN_MAX_ROWS = 1 << 17


def min_max(a: np.ndarray) -> tuple:
    """The least and the greatest element of a non-empty array (NaN if one is),
    its blocks of rows reduced side by side (clrt.scene.blocks)."""
    def block(start: int, stop: int) -> list:
        # A slice at a time: its max reads it from the cache its min left it in
        # (10M triangles' faces on the 2-core machine: 8 ms against 11).
        slices = (a[at:min(stop, at + MIN_MAX_ROWS)] for at in range(start, stop, MIN_MAX_ROWS))
        return [(part.min(), part.max()) for part in slices]

    parts = np.array([pair for pairs in map_blocks(block, len(a)) for pair in pairs])
    return parts[:, 0].min(), parts[:, 1].max()


def column_bounds(points: np.ndarray) -> np.ndarray:
    """(2, 3) float64: the minimum and maximum of each column of (N, 3) points, N >= 1."""
    points = np.asarray(points)
    parts = np.array(map_blocks(lambda start, stop: _column_bounds(points[start:stop]), len(points)))
    return np.stack([parts[:, 0].min(axis=0), parts[:, 1].max(axis=0)])


def _column_bounds(points: np.ndarray) -> np.ndarray:
    whole = len(points) - len(points) % FOLD_ROWS
    parts = [points[whole:]] if whole < len(points) else []
    if whole:
        folded = points[:whole].reshape(-1, 3 * FOLD_ROWS)
        parts += [folded.min(axis=0).reshape(-1, 3), folded.max(axis=0).reshape(-1, 3)]
    rows = np.concatenate(parts)
    return np.stack([rows.min(axis=0), rows.max(axis=0)]).astype(np.float64)


def crease_cos_limit(crease: float) -> float:
    """The least cosine of the angle between two faces' normals at which the
    crease split (Mesh.split_at_creases) smooths their edge: cos(crease),
    less 1e-6 for the rounding of normals of float32 positions (~1e-7)."""
    return math.cos(math.radians(float(crease))) - 1e-6


def unit_rows(n: np.ndarray) -> np.ndarray:
    """(N, 3) float64 rows ``n`` divided by their lengths, zero rows where the
    length is 0.  Each length is sqrt((x*x + y*y) + z*z) in float64, in that
    order (what np.linalg.norm gives along a row of three), so that a device
    taking the same steps gets the same bits (kernels/crease.cl)."""
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    length = np.sqrt((x * x + y * y) + z * z)[:, None]
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def vertex_text(vertices, index: int) -> str:
    """'vertex 3 at (0, -4.4e28, 0)', for errors: coordinates to 3 significant
    digits, or 9 where 3 would round one past +-MAX_COORDINATE into range."""
    def text(x: float) -> str:
        short = f"{x:.3g}"
        return short if abs(float(short)) > config.MAX_COORDINATE or not abs(x) > config.MAX_COORDINATE \
            else f"{x:.9g}"
    xyz = ", ".join(text(float(x)).replace("e+", "e") for x in np.asarray(vertices[index], np.float64))
    return f"vertex {index} at ({xyz})"


def _checked_faces(faces, n_vertices: int, label: str) -> np.ndarray:
    """(F, 3) int32 indices into ``n_vertices`` vertices, at least one face."""
    f = _real_array(faces, f"{label}faces")
    if f.size == 0:
        raise MeshLoadError(f"{label}mesh has no triangles")
    if f.ndim != 2 or f.shape[1] != 3:
        raise MeshLoadError(f"{label}faces must have shape (F, 3), got {f.shape}")
    if not np.issubdtype(f.dtype, np.integer):
        if not np.all(np.isfinite(f)) or np.any(f != np.round(f)):
            raise MeshLoadError(f"{label}face indices must be integers")
    low, high = min_max(f)
    if low < 0 or high >= n_vertices:
        raise MeshLoadError(f"{label}face index out of range (indices {int(low)}..{int(high)}, "
                            f"{n_vertices} vertices)")
    return np.ascontiguousarray(f, dtype=np.int32)


@dataclass(frozen=True, eq=False)   # compared and hashed by identity: == of numpy arrays is no bool
class Mesh:
    """An indexed triangle mesh.

    vertices: (V, 3) float32, faces: (F, 3) int32 indices into ``vertices``.
    Triangles keep their input order, so a primitive id reported by a query
    is the row of ``faces``.  Zero-area triangles are kept (they are never hit)
    so that ids stay aligned with the input file.

    What a file may say about the surface besides its shape (None when it says
    nothing; set through :meth:`with_detail`, which checks it):

    normals: (V, 3) float32 authored vertex normals (smooth shading uses them
        instead of computed ones; the crease split keeps them).
    uv: (F, 3, 2) float32 texture coordinates of each face's corners.
    colors: (F, 3, 3) float32 linear RGB of each face's corners (vertex or face
        colours), multiplied into the material's colour.
    face_material: (F,) int32 index into the object's ``materials``
        (:class:`clrt.scene.scene.SceneObject`), -1 for the object's own material.

    UVs and colours are stored per corner, not per vertex, so that seams need no
    duplicated vertices and re-indexing vertices (the crease split) leaves them be.
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = ""
    normals: np.ndarray | None = None
    uv: np.ndarray | None = None
    colors: np.ndarray | None = None
    face_material: np.ndarray | None = None

    def __post_init__(self):
        # Every Mesh is checked, however it is made (``clrt.Mesh(V, F)`` as much
        # as the loaders): a negative face index would otherwise pick a vertex
        # from the end (numpy's indexing) and trace a triangle that is not there.
        label = f"{self.name}: " if self.name else ""
        object.__setattr__(self, "vertices", _checked_vertices(self.vertices, label))
        object.__setattr__(self, "faces", _checked_faces(self.faces, len(self.vertices), label))
        for key in self.DETAIL:
            value = getattr(self, key)
            if value is not None:
                object.__setattr__(self, key, self._checked_detail(key, value, label))

    @classmethod
    def from_arrays(cls, vertices, faces, name: str = "") -> "Mesh":
        """Validate and convert arrays; raise :class:`MeshLoadError` on bad data
        (as the constructor does)."""
        return cls(vertices, faces, name)

    DETAIL = ("normals", "uv", "colors", "face_material")

    def __repr__(self) -> str:
        detail = [key for key in self.DETAIL if getattr(self, key) is not None]
        split_of = self.crease_split_of
        if split_of is not None and "faces" not in self.__dict__:   # (not made for a repr)
            counts = (f"{self.num_triangles:,} triangles split at creases of {split_of[1]:g} degrees "
                      "when first used")
        else:
            counts = f"{len(self.vertices):,} vertices, {len(self.faces):,} triangles"
        return f"Mesh({self.name!r}, {counts}" + (f", with {', '.join(detail)}" if detail else "") + ")"

    def with_detail(self, normals=None, uv=None, colors=None, face_material=None) -> "Mesh":
        """A copy with the surface detail given (not None) checked and set;
        :class:`MeshLoadError` on bad shapes or values."""
        given = {"normals": normals, "uv": uv, "colors": colors, "face_material": face_material}
        return replace(self, **{key: value for key, value in given.items() if value is not None})

    def _checked_detail(self, key: str, value, label: str) -> np.ndarray:
        n_faces, n_vertices = len(self.faces), len(self.vertices)
        shape = {"normals": (n_vertices, 3), "uv": (n_faces, 3, 2), "colors": (n_faces, 3, 3),
                 "face_material": (n_faces,)}[key]
        dtype = np.int32 if key == "face_material" else np.float32
        if isinstance(value, np.ndarray) and value.dtype == dtype and value.shape == shape \
                and value.flags.c_contiguous and (key == "face_material" or np.isfinite(value).all()):
            if key == "face_material" and value.size and value.min() < -1:
                raise MeshLoadError(f"{label}face material ids must be integers >= -1")
            return value    # already checked: a copy made by replace() or _keep_detail
        a = _real_array(value, f"{label}{key}")
        if a.shape != shape:
            raise MeshLoadError(f"{label}{key} must have shape {shape}, got {a.shape}")
        if not np.isfinite(a).all():
            raise MeshLoadError(f"{label}{key} contain NaN or infinite values")
        if key == "colors":
            a = np.clip(a, 0.0, 1.0)   # colours are albedos: a file's 1.0000001 is 1
        if key == "uv" and np.abs(a).max(initial=0) > config.MAX_COORDINATE:
            raise MeshLoadError(f"{label}texture coordinates must lie within +-{config.MAX_COORDINATE:.0e}")
        if key == "face_material" and ((a != np.round(a)).any() or a.min(initial=0) < -1):
            raise MeshLoadError(f"{label}face material ids must be integers >= -1")
        return np.ascontiguousarray(a, dtype=dtype)

    @cached_property
    def _variants(self) -> "weakref.WeakValueDictionary":
        # What split_at_creases and the scene's objects derive from this mesh,
        # by what was asked for: asked again, the same Mesh object comes back
        # while anything holds it -- so that the objects of a scene that place
        # one mesh many times share one mesh (one bottom-level BVH), not copies.
        return weakref.WeakValueDictionary()

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state.pop("_variants", None)   # weak references do not pickle (and a copy makes its own)
        if "_split_of" in state:       # a crease split travels as its mesh and angle, made again where used
            for key in ("vertices", "faces", "_bounds", "_area_normals"):
                state.pop(key, None)
        return state

    def __getattr__(self, name: str):
        # Reached only for what the instance lacks: the vertices and faces of a
        # crease split not made yet (split_at_creases), made here on first use.
        split_of = self.__dict__.get("_split_of")
        if split_of is not None and name in ("vertices", "faces"):
            vertices, faces = split_of[0]._split(split_of[1])
            self.__dict__.update(vertices=vertices, faces=faces)
            return self.__dict__[name]
        raise AttributeError(f"'Mesh' object has no attribute {name!r}")

    @property
    def num_triangles(self) -> int:
        """``len(faces)``, without making a crease split for it."""
        split_of = self.crease_split_of
        return len(self.faces) if split_of is None else split_of[0].num_triangles

    @property
    def crease_split_of(self) -> "tuple[Mesh, float] | None":
        """``(mesh, crease)`` where this Mesh is ``mesh.split_at_creases(crease)``
        (made or not yet), else None."""
        return self.__dict__.get("_split_of")

    def variant(self, key, make) -> "Mesh":
        """``make()``, a Mesh derived from this one, made once for each ``key``
        while it is in use (the same object for every caller that asks)."""
        found = self._variants.get(key)
        if found is None:
            found = make()
            if found is not self:   # (a mesh holding itself would never be let go)
                self._variants[key] = found
        return found

    def _keep_detail(self, vertices, faces, name, normals=None) -> "Mesh":
        """A Mesh of new vertices and faces (the same faces in the same order) with this one's per-face detail."""
        return Mesh(vertices, faces, name, normals, self.uv, self.colors, self.face_material)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: min and max corner of the vertices used by faces."""
        return self._bounds.copy()

    @cached_property
    def _bounds(self) -> np.ndarray:
        # Computed once: scenes, cameras and lights ask for the bounds again and
        # again (a mesh is not changed after it is made).  The float32 minima
        # and maxima are exact: no float64 copy; no copy at all where every
        # vertex is used (the usual mesh).  A crease split's are its mesh's
        # (the same corners), not a reason to make it.
        if self.crease_split_of is not None:
            return self.crease_split_of[0]._bounds
        used, faces = np.zeros(len(self.vertices), bool), self.faces

        def mark(start: int, stop: int, corner: int) -> None:
            # (threads marking blocks of faces store the same byte, True, where they meet.)  Indices
            # cast to intp a slice at a time: numpy 2.4 assigns through int32 ones 2.5x slower,
            # and a whole array's cast is a large new temporary.
            for at in range(start, stop, MARK_ROWS):
                used[faces[at:min(stop, at + MARK_ROWS), corner].astype(np.intp)] = True

        # Corner by corner: the faces' first corners alone often use every
        # vertex (a generated grid's do), the first two nearly every one.
        for corner in range(3):
            map_blocks(partial(mark, corner=corner), len(faces))
            if used.all():
                return column_bounds(self.vertices)
        # The used rows as 12-byte records: numpy 2.4 copies a (V, 3) array's
        # rows chosen by a mask 15x slower, three numbers at a time.
        rows = self.vertices.view(np.dtype((np.void, 12))).reshape(-1)[used]
        return column_bounds(rows.view(np.float32).reshape(-1, 3))

    @cached_property
    def _area_normals(self) -> np.ndarray:
        """(F, 3) float64 cross products of each triangle's two edges from corner 0:
        normal times twice the area.  Computed once, read only: the crease split
        needs them, and then the split mesh's vertex normals, which are the same
        numbers (its triangles are bitwise the same)."""
        if self.crease_split_of is not None:
            return self.crease_split_of[0]._area_normals
        # The corners gathered in float32 (np.take: several times faster than
        # v[index], numpy 2.4), the edges in float64, and np.cross's products
        # written out (the same operations, so the same bits, at 2/3 of the time).
        corners = np.take(self.vertices, self.faces, axis=0)
        first = corners[:, 0].astype(np.float64)
        (x1, y1, z1), (x2, y2, z2) = (corners[:, 1] - first).T, (corners[:, 2] - first).T
        n = np.stack([y1 * z2 - z1 * y2, z1 * x2 - x1 * z2, x1 * y2 - y1 * x2], axis=1)
        n.flags.writeable = False
        return n

    def face_normals(self) -> np.ndarray:
        """(F, 3) float64 unit geometric normals (zero for zero-area triangles)."""
        return unit_rows(self._area_normals)

    def vertex_normals(self) -> np.ndarray:
        """(V, 3) float32 vertex normals for smooth shading: the file's own (unit
        length), else area-weighted ones."""
        if self.normals is not None:
            n = self.normals.astype(np.float64)
            length = np.linalg.norm(n, axis=1, keepdims=True)
            return np.divide(n, length, out=np.zeros_like(n), where=length > 0).astype(np.float32)
        area_n = self._area_normals
        # Sums in a fixed order -- every face's corner 0, then corner 1, then corner 2,
        # faces in order -- with np.bincount, which adds its weights in index order
        # (as three np.add.at calls would, at a few times their speed), from 0.0.
        # The device's twin (kernels/crease.cl, vertex_normals) adds in this order too.
        corners = self.faces.T.reshape(-1)
        acc = np.stack([np.bincount(corners, weights=np.tile(area_n[:, k], 3), minlength=len(self.vertices))
                        for k in range(3)], axis=1)
        return unit_rows(acc).astype(np.float32)

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
        edge's faces have at each end of the edge are joined (union-find), so
        a vertex's faces fall into the fans between its creases.  The
        half-edges of one edge (between the same two merged positions) are
        taken in index order (half-edge 3f + k runs from corner k of face f to
        corner k + 1), and each is paired with the next: an edge of three or
        more faces is joined as a chain in that order.  Each group of corners
        becomes one vertex, numbered in the order of their smallest corners.

        The split is made when first needed: the Mesh returned holds this mesh
        and the angle (:attr:`crease_split_of`) until its vertices or faces are
        asked for -- a Renderer on a GPU has the device split the uploaded
        triangles instead (clrt.device.crease), bit for bit the same, and the
        host never makes it.

        A mesh with authored normals is returned as it is: the file already
        says where its edges are hard (by giving a vertex one normal per side).
        """
        if self.normals is not None:
            return self
        crease = float(crease)
        return self.variant(("split", crease), lambda: self._split_later(crease))

    def _split_later(self, crease: float) -> "Mesh":
        """split_at_creases' Mesh, its vertices and faces made on first use (__getattr__)."""
        split = object.__new__(Mesh)
        split.__dict__.update(name=self.name, normals=None, uv=self.uv, colors=self.colors,
                              face_material=self.face_material, _split_of=(self, crease))
        return split

    def _split(self, crease: float) -> tuple[np.ndarray, np.ndarray]:
        """The vertices and faces of split_at_creases(crease), made on the host."""
        faces = self.faces
        n_faces = len(faces)
        weld = _welded(self.vertices)
        welded = weld[faces]                                            # (F, 3)
        normals = self.face_normals()
        # Half-edge 3f + k runs from corner k to corner k + 1 of face f.
        a, b = welded.reshape(-1), np.roll(welded, -1, axis=1).reshape(-1)
        key = np.minimum(a, b).astype(np.int64) * (int(weld.max()) + 1) + np.maximum(a, b)
        # Stable: the half-edges of one edge in index order (the rule of the
        # docstring, which the device follows; numpy's default sort is not stable).
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        same = np.flatnonzero(sorted_key[1:] == sorted_key[:-1])
        h1, h2 = order[same], order[same + 1]                           # half-edges of one edge
        f1, f2 = h1 // 3, h2 // 3
        cos_limit = crease_cos_limit(crease)
        n1, n2 = np.take(normals, f1, axis=0), np.take(normals, f2, axis=0)
        # (x1 x2 + y1 y2) + z1 z2, in this order (einsum adds in an order of its own)
        cosine = (n1[:, 0] * n2[:, 0] + n1[:, 1] * n2[:, 1]) + n1[:, 2] * n2[:, 2]
        smooth = (f1 != f2) & (cosine >= cos_limit)
        h1, h2, f1, f2 = h1[smooth], h2[smooth], f1[smooth], f2[smooth]
        n1 = 3 * f1 + (h1 + 1) % 3                                      # corner at the half-edge's end
        n2 = 3 * f2 + (h2 + 1) % 3
        straight = a[h1] == a[h2]                                       # both run the same way
        left = np.concatenate([h1, n1]).astype(np.int32)               # (int32: half the memory traffic)
        right = np.concatenate([np.where(straight, h2, n2), np.where(straight, n2, h2)]).astype(np.int32)
        # Union-find over the joins: hook the larger root of each join still apart
        # under the smaller, jump pointers until every corner points at its root,
        # and repeat over the joins that are still apart.  Labels only decrease
        # (each a corner of the same group), so every group ends labelled by its
        # smallest corner, whatever the order of the joins.
        label = np.arange(3 * n_faces, dtype=np.int32)
        low, high = np.minimum(left, right), np.maximum(left, right)   # at first every corner is a root
        while len(low):
            np.minimum.at(label, high, low)
            while True:
                jumped = label[label]
                if np.array_equal(jumped, label):
                    break
                label = jumped
            low, high = label[left], label[right]
            low, high = np.minimum(low, high), np.maximum(low, high)
            apart = low != high
            left, right, low, high = left[apart], right[apart], low[apart], high[apart]
        is_root = label == np.arange(3 * n_faces, dtype=np.int32)
        corner_vertex = (np.cumsum(is_root, dtype=np.int32) - 1)[label]
        vertices = np.take(self.vertices, faces.reshape(-1)[is_root], axis=0)
        return vertices, corner_vertex.reshape(n_faces, 3).astype(np.int32)

    def transformed(self, matrix: np.ndarray) -> "Mesh":
        """A copy with a 4x4 affine transform applied to the vertices (and to
        authored normals, by the inverse transpose, so they stay perpendicular)."""
        m = np.asarray(matrix, dtype=np.float64)
        v = self.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        normals = self.normals
        if normals is not None:
            normals = (normals.astype(np.float64) @ np.linalg.inv(m[:3, :3])).astype(np.float32)
        # float64 into the constructor: its range check sees a transform that
        # takes vertices past float32 before the cast would make them infinite
        return self._keep_detail(v, self.faces, self.name, normals)

    @staticmethod
    def concatenate(meshes: "list[Mesh]", name: str = "") -> "Mesh":
        """One mesh holding all triangles, in order.  Detail that some meshes lack is
        filled in: UV (0, 0), colour white, the object's own material; normals
        are kept only when every mesh has them (else all are computed)."""
        offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
        v = np.concatenate([m.vertices for m in meshes])
        f = np.concatenate([m.faces + o for m, o in zip(meshes, offsets)])
        fill = {"uv": lambda m: np.zeros((len(m.faces), 3, 2), np.float32),
                "colors": lambda m: np.ones((len(m.faces), 3, 3), np.float32),
                "face_material": lambda m: np.full(len(m.faces), -1, np.int32)}
        detail = {key: np.concatenate([getattr(m, key) if getattr(m, key) is not None else make(m)
                                       for m in meshes])
                  for key, make in fill.items() if any(getattr(m, key) is not None for m in meshes)}
        if all(m.normals is not None for m in meshes):
            detail["normals"] = np.concatenate([m.normals for m in meshes])
        return Mesh(v.astype(np.float32), f.astype(np.int32), name, **detail)
