"""What every format reader shares: the part a reader hands back, its failure
message, and the reading of the files themselves.

Every failure (missing or unreadable file, corrupt or truncated content, no
triangles) raises :class:`MeshLoadError` with a one-line message that names
the file (:func:`fail`); nothing in a file is ever executed.
"""

from __future__ import annotations

import logging
import os
import stat

from dataclasses import dataclass, field, replace

import numpy as np

from clrt.errors import InputError, MeshLoadError
from clrt.scene.mesh import Mesh
from clrt.scene.texture import Texture, srgb_decode

_MAX_REASON = 160


def fail(label: str, reason: str) -> MeshLoadError:
    """A MeshLoadError whose message is ``'<file>: <reason>'`` on one line."""
    return MeshLoadError(f"{label}: {' '.join(str(reason).split())}")


def short(exc: BaseException) -> str:
    """One line, bounded length description of a foreign exception."""
    text = " ".join(str(exc).split())
    if len(text) > _MAX_REASON:
        text = text[:_MAX_REASON - 3] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@dataclass
class Part:
    """One mesh of a file as its parser found it, before checks.

    vertices (V, 3), faces (F, 3) triangles; normals (V, 3); uv (F, 3, 2) per
    corner; colours in 0..1 (each parser scales them by the types the file
    declares, never by their values) of vertices (V, 3) or of polygons (P, 3), sRGB unless
    ``srgb_colors`` is False, with ``polygon_sizes`` (P,) when polygons were
    triangulated (each polygon's colour goes to its triangles);
    face_material (F,) indexing ``materials`` (dicts of Material fields, shared
    by all parts of a file), -1 for none.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uv: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    face_colors: np.ndarray | None = None
    polygon_sizes: np.ndarray | None = None
    srgb_colors: bool = True
    face_material: np.ndarray | None = None
    materials: list = field(default_factory=list)

    def corner_colors(self) -> np.ndarray | None:
        """(F, 3, 3) linear colours of the triangles' corners, or None."""
        if self.vertex_colors is not None:
            colors = np.asarray(self.vertex_colors, np.float64)[self.faces]
        elif self.face_colors is not None:
            per_face = np.asarray(self.face_colors, np.float64)
            if self.polygon_sizes is not None:
                per_face = np.repeat(per_face, self.polygon_sizes - 2, axis=0)
            colors = np.repeat(per_face[:, None], 3, axis=1)
        else:
            return None
        return srgb_decode(colors) if self.srgb_colors else colors


def build(parts: "list[Part]", label: str, name: str) -> "tuple[Mesh, list]":
    """Validate the parts and concatenate them into one Mesh; with the file's materials."""
    meshes = []
    for part in parts:
        try:
            mesh = Mesh.from_arrays(part.vertices, part.faces)
            meshes.append(mesh.with_detail(normals=part.normals, uv=part.uv, colors=part.corner_colors(),
                                           face_material=part.face_material))
        except MeshLoadError as exc:
            raise fail(label, str(exc)) from None
    mesh = meshes[0] if len(meshes) == 1 else Mesh.concatenate(meshes)
    return replace(mesh, name=name), parts[0].materials


def placed(part: Part, world: np.ndarray) -> Part:
    """A part moved into world space by a node's 4x4 ``world`` transform, as a
    glTF node places its mesh: normals by the inverse transpose, and a
    transform that mirrors (negative determinant) swaps the triangles' corners
    1 and 2 (and their texture coordinates), so that faces still face out, as
    the glTF specification says."""
    out = replace(part)
    m = world[:3, :3]
    if not np.array_equal(world, np.eye(4)):
        out.vertices = part.vertices @ m.T + world[:3, 3]
        if part.normals is not None:
            det = np.linalg.det(m)
            out.normals = part.normals @ (np.linalg.inv(m) if det != 0 else np.linalg.pinv(m))
    if np.linalg.det(m) < 0:
        out.faces = part.faces[:, [0, 2, 1]]
        if part.uv is not None:
            out.uv = part.uv[:, [0, 2, 1]]
    return out


def fill_normals(parts: "list[Part]") -> None:
    """Give the parts without normals their smooth (area-weighted) ones when
    another part has authored normals, which are kept (Mesh.concatenate keeps
    normals only when every mesh has them)."""
    if any(p.normals is not None for p in parts):
        for part in parts:
            if part.normals is None:
                try:
                    part.normals = Mesh.from_arrays(part.vertices, part.faces).vertex_normals()
                except MeshLoadError:
                    pass   # build reports it, naming the file


def first_cycle(children: list) -> int | None:
    """A node that is its own ancestor in a hierarchy given as each node's list
    of children (a glTF file's nodes); None when there is no cycle."""
    state = [0] * len(children)   # 0 unseen, 1 on the current path, 2 done
    for root in range(len(children)):
        if state[root]:
            continue
        state[root], path = 1, [(root, iter(children[root]))]
        while path:
            node, rest = path[-1]
            child = next(rest, None)
            if child is None:
                state[node] = 2
                path.pop()
            elif state[child] == 1:
                return int(child)
            elif state[child] == 0:
                state[child] = 1
                path.append((child, iter(children[child])))
    return None


# ---------------------------------------------------------------------------
# Reading files


def regular_file(path: str) -> None:
    """MeshLoadError unless ``path`` names a regular file that can be looked at."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise MeshLoadError(f"no such file: {path}") from None
    except OSError as exc:
        raise fail(path, f"cannot access file ({exc.strerror or short(exc)})") from None
    if stat.S_ISDIR(info.st_mode):
        raise fail(path, "is a directory, not a mesh file")
    # A FIFO or device could block forever or never end.
    if not stat.S_ISREG(info.st_mode):
        raise fail(path, "not a regular file")


def read_bytes(path: str, side_file: bool = False, prefix: int | None = None) -> bytes:
    """The bytes of the file at ``path`` (its first ``prefix`` bytes if given);
    MeshLoadError for anything but a readable regular file (a non-empty mesh
    file, unless ``side_file``: one that a mesh file names).  The dispatcher
    (:mod:`clrt.scene.load`) checks a mesh file's extension before reading it."""
    regular_file(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read() if prefix is None else fh.read(prefix)
    except PermissionError:
        raise fail(path, "permission denied") from None
    except OSError as exc:
        raise fail(path, f"cannot read file ({exc.strerror or short(exc)})") from None
    if not data.strip() and not side_file:
        raise fail(path, "file is empty")
    return data


def read_side_file(path: str, label: str) -> bytes:
    """A file a mesh file names (an MTL library): MeshLoadError naming the mesh file if unreadable."""
    try:
        return read_bytes(path, side_file=True)
    except MeshLoadError as exc:
        raise fail(label, str(exc)) from None


def texture(path: str, wrap_s: str, wrap_t: str, label: str) -> Texture:
    """The texture image a mesh file names; MeshLoadError naming the mesh file if it cannot be read."""
    try:
        return Texture.read(path, wrap_s, wrap_t)
    except InputError as exc:
        raise fail(label, str(exc)) from None


# trimesh (which reads binary PLY and STL) logs warnings with tracebacks (e.g.
# for a corrupt ASCII STL) while we report the failure ourselves; without any
# handler configured Python's last-resort handler would print them to stderr.
# A NullHandler stops that and still lets an application that configures
# logging see them.
if not any(isinstance(h, logging.NullHandler) for h in logging.getLogger("trimesh").handlers):
    logging.getLogger("trimesh").addHandler(logging.NullHandler())
