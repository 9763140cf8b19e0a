"""3DS (Autodesk 3D Studio): reader and minimal writer.

trimesh cannot read 3DS, so this is our own parser of the binary chunk format.
Every chunk starts with a little-endian header ``uint16 id, uint32 length``
where ``length`` counts the 6 header bytes too.  Only the geometry is read::

    0x4D4D main
      0x3D3D editor
        0x4000 named object: NUL-terminated name, then sub-chunks
          0x4100 triangle mesh
            0x4110 vertex list: uint16 n, n * float32[3]
            0x4120 face list:   uint16 n, n * uint16[4] (a, b, c, flags),
                                then sub-chunks (0x4130 material groups, ...)
            0x4160 local coordinate system: float32[4][3]

Everything else (materials, lights, cameras, keyframer) is skipped by its
length.  The file is untrusted: every read is bounds-checked against the
enclosing chunk and any inconsistency raises :class:`MeshLoadError`.
"""

from __future__ import annotations

import os
import struct

import numpy as np

from clrt.errors import MeshLoadError
from clrt.scene.mesh import Mesh

MAIN = 0x4D4D
VERSION = 0x0002
EDITOR = 0x3D3D
MESH_VERSION = 0x3D3E
OBJECT = 0x4000
TRIMESH = 0x4100
VERTICES = 0x4110
FACES = 0x4120
LOCAL_MATRIX = 0x4160

_HEADER = struct.Struct("<HI")
_U16 = struct.Struct("<H")
_MAX_U16 = 0xFFFF
# Default edge-visibility flags (AB, BC and CA visible), as 3ds Max writes them.
_FACE_FLAGS = 0x0007
# 3D Studio limits object names to 10 characters; other readers may rely on it.
_MAX_NAME = 10


class _Corrupt(Exception):
    """Internal: a structural problem; turned into MeshLoadError with the path."""


def _chunks(data: bytes, start: int, end: int):
    """Yield ``(id, body_start, body_end)`` for the chunks in ``data[start:end]``.

    Each chunk must lie entirely inside ``[start, end)``.  A length below 6
    would not advance the cursor, so it is rejected as corruption; that also
    guarantees the loop terminates.
    """
    pos = start
    while pos < end:
        if end - pos < _HEADER.size:
            raise _Corrupt(f"truncated chunk header at offset {pos}")
        cid, length = _HEADER.unpack_from(data, pos)
        if length < _HEADER.size:
            raise _Corrupt(f"chunk 0x{cid:04X} at offset {pos} has invalid length {length}")
        if length > end - pos:
            raise _Corrupt(f"chunk 0x{cid:04X} at offset {pos} claims {length} bytes "
                           f"but only {end - pos} remain in its parent")
        yield cid, pos + _HEADER.size, pos + length
        pos += length


def _read_vertices(data: bytes, start: int, end: int) -> np.ndarray:
    """(n, 3) float32 vertex positions of a 0x4110 chunk body."""
    if end - start < 2:
        raise _Corrupt(f"vertex list at offset {start} is truncated")
    (n,) = _U16.unpack_from(data, start)
    if 2 + 12 * n > end - start:
        raise _Corrupt(f"vertex list at offset {start} claims {n} vertices "
                       f"but holds only {(end - start - 2) // 12}")
    return np.frombuffer(data, dtype="<f4", count=3 * n, offset=start + 2).reshape(n, 3)


def _read_faces(data: bytes, start: int, end: int) -> np.ndarray:
    """(n, 3) uint16 vertex indices of a 0x4120 chunk body; sub-chunks are skipped."""
    if end - start < 2:
        raise _Corrupt(f"face list at offset {start} is truncated")
    (n,) = _U16.unpack_from(data, start)
    face_end = start + 2 + 8 * n
    if face_end > end:
        raise _Corrupt(f"face list at offset {start} claims {n} faces "
                       f"but holds only {(end - start - 2) // 8}")
    # Per face: a, b, c, edge flags.  The flags carry nothing we render.
    faces = np.frombuffer(data, dtype="<u2", count=4 * n, offset=start + 2).reshape(n, 4)[:, :3]
    # Material groups (0x4130), smoothing groups (0x4150) etc. follow the face
    # array inside the same chunk; walk them only to check they are well formed.
    for _ in _chunks(data, face_end, end):
        pass
    return faces


def _read_trimesh(data: bytes, start: int, end: int):
    """``(vertices, faces)`` of a 0x4100 chunk body, either may be None."""
    vertices = faces = None
    for cid, s, e in _chunks(data, start, end):
        if cid == VERTICES:
            if vertices is not None:
                raise _Corrupt(f"second vertex list at offset {s - 6}")
            vertices = _read_vertices(data, s, e)
        elif cid == FACES:
            if faces is not None:
                raise _Corrupt(f"second face list at offset {s - 6}")
            faces = _read_faces(data, s, e)
        elif cid == LOCAL_MATRIX:
            # The 4x3 local coordinate system is the object's pivot frame for
            # the keyframer.  3DS stores mesh vertices already transformed to
            # world space, so applying this matrix would transform them twice
            # (readers such as lib3ds multiply by its *inverse* to recover
            # object space).  We want world space, so it is only size-checked.
            if e - s < 48:
                raise _Corrupt(f"local coordinate system at offset {s - 6} is truncated")
    return vertices, faces


def _read_object(data: bytes, start: int, end: int):
    """``(name, vertices, faces)`` of a 0x4000 chunk body; arrays may be None."""
    nul = data.find(b"\0", start, end)
    if nul < 0:
        raise _Corrupt(f"object name at offset {start} is not NUL-terminated")
    # Only used in messages; 3DS names are at most 10 characters when valid.
    name = data[start:min(nul, start + 40)].decode("latin-1")
    vertices = faces = None
    for cid, s, e in _chunks(data, nul + 1, end):
        if cid == TRIMESH:
            if vertices is not None or faces is not None:
                raise _Corrupt(f"object {name!r} has a second triangle mesh")
            vertices, faces = _read_trimesh(data, s, e)
        # Lights (0x4600) and cameras (0x4700) hold no triangles: skipped.
    return name, vertices, faces


def read(data: bytes, path: str, name: str) -> "tuple[Mesh, list]":
    """The mesh of a 3DS file's bytes (its materials are not read)."""
    return parse_3ds(data, label=path, name=name), []


def parse_3ds(data: bytes, label: str = "", name: str = "") -> Mesh:
    """Parse the bytes of a 3DS file into one :class:`Mesh` named ``name``.

    Objects are concatenated in file order, so face ids follow the file.
    ``label`` (usually the path) prefixes every error message.  Objects without
    faces (empty meshes, lights, cameras) are skipped.
    """
    prefix = f"{label}: " if label else ""
    data = bytes(data)
    try:
        if len(data) < _HEADER.size:
            raise _Corrupt("file is too short to be a 3DS file")
        cid, length = _HEADER.unpack_from(data, 0)
        if cid != MAIN:
            raise _Corrupt(f"not a 3DS file (first chunk is 0x{cid:04X}, expected 0x4D4D)")
        if length < _HEADER.size:
            raise _Corrupt(f"main chunk has invalid length {length}")
        if length > len(data):
            raise _Corrupt(f"file is truncated (main chunk claims {length} bytes, "
                           f"file has {len(data)})")
        # Bytes after the main chunk are ignored: some exporters pad files.
        parts = []
        for cid, s, e in _chunks(data, _HEADER.size, length):
            if cid != EDITOR:
                continue  # version, keyframer (0xB000), ...
            for obj_cid, obj_start, obj_end in _chunks(data, s, e):
                if obj_cid != OBJECT:
                    continue  # materials (0xAFFF), mesh version, ...
                obj_name, vertices, faces = _read_object(data, obj_start, obj_end)
                if faces is None or len(faces) == 0:
                    continue
                if vertices is None:
                    raise _Corrupt(f"object {obj_name!r} has faces but no vertex list")
                if faces.max() >= len(vertices):
                    raise _Corrupt(f"object {obj_name!r}: face index {int(faces.max())} "
                                   f"out of range ({len(vertices)} vertices)")
                parts.append((obj_name, vertices, faces))
    except _Corrupt as exc:
        raise MeshLoadError(f"{prefix}{exc}") from None
    if not parts:
        raise MeshLoadError(f"{prefix}3DS file contains no triangles")
    meshes = []
    for obj_name, vertices, faces in parts:
        try:
            meshes.append(Mesh.from_arrays(vertices, faces))
        except MeshLoadError as exc:
            raise MeshLoadError(f"{prefix}object {obj_name!r}: {exc}") from None
    if len(meshes) == 1:
        return Mesh(meshes[0].vertices, meshes[0].faces, name)
    return Mesh.concatenate(meshes, name=name)


# ---------------------------------------------------------------------------
# Writer


def _chunk(cid: int, *payload: bytes) -> bytes:
    """One chunk: header (id, total length) followed by ``payload``."""
    body = b"".join(payload)
    length = _HEADER.size + len(body)
    if length > 0xFFFFFFFF:
        raise ValueError("3DS chunk larger than 4 GiB")
    return _HEADER.pack(cid, length) + body


def _split_for_uint16(vertices: np.ndarray, faces: np.ndarray):
    """Yield ``(vertices, faces)`` pieces with at most 65535 vertices and faces each.

    Face order is preserved across the pieces.  A block of 21845 faces uses at
    most 3 * 21845 = 65535 distinct vertices, so fixed-size blocks always fit.
    """
    if len(vertices) <= _MAX_U16 and len(faces) <= _MAX_U16:
        yield vertices, faces
        return
    block = _MAX_U16 // 3
    for lo in range(0, len(faces), block):
        f = faces[lo:lo + block]
        used, local = np.unique(f, return_inverse=True)
        yield vertices[used], local.reshape(f.shape)


def _object_chunk(name: str, vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A 0x4000 object chunk holding one triangle mesh (<= 65535 vertices/faces)."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    f = np.empty((len(faces), 4), dtype="<u2")
    f[:, :3] = faces
    f[:, 3] = _FACE_FLAGS
    identity = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]], dtype="<f4")
    mesh = _chunk(
        TRIMESH,
        _chunk(VERTICES, _U16.pack(len(v)), v.tobytes()),
        _chunk(FACES, _U16.pack(len(f)), f.tobytes()),
        _chunk(LOCAL_MATRIX, identity.tobytes()),
    )
    return _chunk(OBJECT, name.encode("latin-1") + b"\0", mesh)


def _object_name(name: str, index: int, taken: set) -> str:
    """A unique, printable, NUL-free name of at most 10 characters."""
    clean = "".join(c for c in name if c.isascii() and c.isprintable())[:_MAX_NAME]
    if not clean or clean in taken:
        clean = f"obj{index}"[:_MAX_NAME]
    taken.add(clean)
    return clean


def encode_3ds(meshes: "list[Mesh]") -> bytes:
    """The bytes of a 3DS file with one object per mesh (split when over uint16 limits)."""
    objects, taken = [], set()
    for mesh in meshes:
        for vertices, faces in _split_for_uint16(mesh.vertices, mesh.faces):
            name = _object_name(mesh.name, len(objects), taken)
            objects.append(_object_chunk(name, vertices, faces))
    editor = _chunk(EDITOR, _chunk(MESH_VERSION, struct.pack("<I", 3)), *objects)
    return _chunk(MAIN, _chunk(VERSION, struct.pack("<I", 3)), editor)


def write_3ds(path, meshes: "list[Mesh]") -> None:
    """Write ``meshes`` to ``path`` as a 3DS file, one named object per mesh.

    3DS indexes with uint16, so a mesh with more than 65535 vertices or faces
    is written as several objects (in face order); reading the file back gives
    the same triangles in the same order, though vertices may be renumbered.
    """
    if not meshes:
        raise ValueError("write_3ds needs at least one mesh")
    data = encode_3ds(list(meshes))
    with open(os.fspath(path), "wb") as fh:
        fh.write(data)


# ---------------------------------------------------------------------------
# trimesh integration


def _trimesh_loader(file_obj, **kwargs) -> dict:
    """A ``trimesh.exchange.load.mesh_loaders`` entry: bytes -> Trimesh kwargs."""
    mesh = parse_3ds(file_obj.read(), label=getattr(file_obj, "name", "") or "")
    return {"vertices": mesh.vertices.astype(np.float64), "faces": mesh.faces.astype(np.int64)}


def register_with_trimesh() -> bool:
    """Make ``trimesh.load('x.3ds')`` use this reader; True if it is registered.

    trimesh has no public plugin API, but ``trimesh.exchange.load`` dispatches
    through the module-level dict ``mesh_loaders`` (extension -> function
    returning constructor kwargs) in every 4.x/5.x release, and
    ``trimesh.available_formats()`` is derived from it.  We only add the key
    when it is absent, so a future native 3DS reader in trimesh wins.
    """
    try:
        from trimesh.exchange import load as tm_load
    except Exception:  # trimesh missing or broken: registration is optional
        return False
    loaders = getattr(tm_load, "mesh_loaders", None)
    if not isinstance(loaders, dict):
        return False
    loaders.setdefault("3ds", _trimesh_loader)
    return True
