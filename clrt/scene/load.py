"""Load a triangle mesh from a file: OBJ, OFF, PLY, STL, GLB/GLTF or 3DS.

:data:`READERS` is the table of input formats, and the one place a new one is
registered: each entry names a reader in :mod:`clrt.scene.formats` (one
module per format, whose docstring says what of the format is read), the
file extensions it takes, and what its files can carry besides triangles.
The extension (case-insensitive) alone picks the reader.

Every failure (missing or unreadable file, unknown extension, corrupt or
truncated content, no triangles) raises :class:`MeshLoadError` with a one-line
message that names the file; nothing in a file is ever executed.

Face order is the file's order, so a primitive id is a face's position in the
file.  Polygons are triangulated in place (polygon ``i`` of ``n`` corners
becomes ``n - 2`` consecutive triangles: a fan when it is convex, else by ear
clipping; :mod:`clrt.scene.formats.triangulate`).
"""

from __future__ import annotations

import os

from dataclasses import dataclass
from typing import Callable

from clrt.errors import InputError, MeshLoadError
from clrt.scene.formats import gltf, obj, off, ply, stl, tds, trimesh_objects
from clrt.scene.formats.part import fail, read_bytes, regular_file, short
from clrt.scene.mesh import Mesh


@dataclass(frozen=True)
class Reader:
    """One input format: the function that reads its files, and what they can
    carry besides triangles (what the reader takes from them, that is)."""

    name: str
    extensions: tuple[str, ...]   # lower case, with the dot
    # (file bytes, path, mesh name) -> (Mesh, materials as dicts of clrt.Material fields);
    # MeshLoadError naming the path for any problem.
    read: Callable[[bytes, str, str], "tuple[Mesh, list[dict]]"]
    colors: bool = False          # vertex or face colours
    normals: bool = False         # authored vertex normals
    uv: bool = False              # texture coordinates
    materials: bool = False       # materials, with texture images
    objects: bool = False         # several objects, all read (placed where the format places them), in file order
    # path -> the file's camera, as file_camera describes it, or None
    camera: Callable[[str], "dict | None"] | None = None


READERS = (
    Reader("3DS", (".3ds",), tds.read, objects=True),
    Reader("glTF binary", (".glb",), gltf.read_glb, colors=True, normals=True, uv=True, materials=True,
           objects=True, camera=gltf.glb_camera),
    Reader("glTF", (".gltf",), gltf.read_gltf, colors=True, normals=True, uv=True, materials=True,
           objects=True, camera=gltf.gltf_camera),
    Reader("OBJ", (".obj",), obj.read, normals=True, uv=True, materials=True, objects=True),
    Reader("OFF", (".off",), off.read, colors=True),
    Reader("PLY", (".ply",), ply.read, colors=True, normals=True, uv=True),
    Reader("STL", (".stl",), stl.read, objects=True),
)

_BY_EXTENSION = {ext: reader for reader in READERS for ext in reader.extensions}
SUPPORTED_EXTENSIONS = tuple(sorted(_BY_EXTENSION))
#: A TOML scene file (:mod:`clrt.scene.scene_file`), which names mesh files.
SCENE_EXTENSION = ".toml"


def reader_of(path: str) -> Reader:
    """The reader of a mesh file, by its extension; MeshLoadError naming the
    file for a scene file or an unknown extension."""
    ext = os.path.splitext(path)[1].lower()
    if ext == SCENE_EXTENSION:
        raise fail(path, "is a scene file, not a mesh (render it with clrt render or clrt.render, "
                         "or read it with clrt.load_scene)")
    reader = _BY_EXTENSION.get(ext)
    if reader is None:
        shown = f"'{ext}'" if ext else "no extension"
        raise fail(path, f"unknown mesh format ({shown}); supported: " + ", ".join(SUPPORTED_EXTENSIONS))
    return reader


def load_mesh(path) -> Mesh:
    """Load the mesh file at ``path`` into one :class:`Mesh` named after the file,
    with the surface detail the file has (normals, texture coordinates, colours,
    face material ids: :func:`load_asset` also returns the materials).

    The format is chosen by the extension (case-insensitive), one of
    :data:`SUPPORTED_EXTENSIONS`.  Raises :class:`MeshLoadError` on any problem.
    """
    return load_asset(path)[0]


def load_asset(path) -> "tuple[Mesh, list[dict]]":
    """The mesh of a file and its materials, as dicts of :class:`clrt.Material`
    fields (``mesh.face_material`` indexes them; [] for a file without any).
    OBJ reads its ``mtllib`` files and their ``map_Kd`` images from the OBJ's
    folder (a missing one is left out, with a :class:`clrt.errors.MeshLoadWarning`:
    the faces keep the default material, or the material its colour)."""
    try:
        path = os.fspath(path)
    except TypeError:
        raise MeshLoadError(f"a mesh file's path must be a str or os.PathLike, got {type(path).__name__}") from None
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    regular_file(path)   # first: a missing file is missing, whatever its name
    reader = reader_of(path)
    data = read_bytes(path)
    ext = os.path.splitext(path)[1].lower()
    name = os.path.splitext(os.path.basename(path))[0]
    try:
        return reader.read(data, path, name)
    except MeshLoadError:
        raise
    except Exception as exc:  # a parser bug must still not leak a traceback to the user
        raise fail(path, f"cannot parse {ext[1:].upper()} file ({short(exc)})") from exc


def file_camera(path) -> dict | None:
    """The first perspective camera of a mesh file whose format has cameras
    (glTF/GLB), in world space: ``{"eye", "forward", "up", "fov" (vertical,
    degrees), "aspect" (width / height or None), "name"}``; None for other
    formats, a file without one, or a camera clrt cannot use (orthographic,
    degenerate)."""
    path = os.fspath(path)
    reader = _BY_EXTENSION.get(os.path.splitext(path)[1].lower())
    if reader is None or reader.camera is None:
        return None
    return reader.camera(path)


def as_mesh(source) -> Mesh:
    """A Mesh from a Mesh, a mesh file path (str or os.PathLike), a trimesh.Trimesh
    (anything with ``vertices`` and ``faces``), a trimesh.Scene (every geometry
    placed by its node) or ``(vertices, faces)``; InputError for anything else,
    MeshLoadError for a bad file or bad arrays."""
    return as_asset(source)[0]


def as_asset(source) -> "tuple[Mesh, list[dict]]":
    """:func:`as_mesh`'s mesh and the materials its source gives its faces, as
    dicts of :class:`clrt.Material` fields (``mesh.face_material`` indexes
    them): a file's (:func:`load_asset`) or a trimesh object's (its
    TextureVisuals' materials, mapped as the file readers map the same:
    :mod:`clrt.scene.formats.trimesh_objects`); [] for the others."""
    if isinstance(source, Mesh):
        return source, []
    if isinstance(source, (str, os.PathLike)):
        return load_asset(source)
    if hasattr(source, "vertices") and hasattr(source, "faces") or trimesh_objects.is_trimesh_scene(source):
        return trimesh_objects.asset_of(source)
    if isinstance(source, (tuple, list)) and len(source) == 2:
        return Mesh.from_arrays(*source), []
    raise InputError(f"expected a mesh (a clrt.Mesh, a file path, a trimesh object or (vertices, faces)), "
                     f"got {type(source).__name__}")
