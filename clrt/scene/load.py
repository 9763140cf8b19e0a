"""Load a triangle mesh from a file: OBJ, OFF, PLY, STL, GLB/GLTF or 3DS.

Every failure (missing or unreadable file, unknown extension, corrupt or
truncated content, no triangles) raises :class:`MeshLoadError` with a one-line
message that names the file; nothing in a file is ever executed.

Face order is the file's order, so a primitive id is a face's position in the
file.  Polygons are fan-triangulated in place (polygon ``i`` of ``n`` corners
becomes ``n - 2`` consecutive triangles).

OBJ, OFF and ASCII PLY are parsed here rather than by trimesh (5.2.0
checked), whose readers break that contract: its OFF reader crashes on any
face with more than four corners; its OBJ reader emits ``usemtl`` sections in
reverse order, moves the second triangle of every quad to the end of the mesh,
and opens the ``mtllib`` and texture files named inside the OBJ; its ASCII PLY
reader silently drops a truncated last face.  Binary PLY, STL and glTF are
parsed by trimesh with ``process=False`` (no vertex merging or face removal);
scenes are flattened with each node's transform applied.  3DS has its own
reader in :mod:`clrt.scene.load_3ds`.
"""

from __future__ import annotations

import io
import logging
import math
import os
import re
import stat
import warnings

import numpy as np

from clrt.errors import MeshLoadError
from clrt.scene import load_3ds
from clrt.scene.mesh import Mesh

SUPPORTED_EXTENSIONS = (".3ds", ".glb", ".gltf", ".obj", ".off", ".ply", ".stl")

# File extension (lower case) -> trimesh file type, for formats trimesh reads.
_TRIMESH_TYPES = {".stl": "stl", ".glb": "glb", ".gltf": "gltf"}

# OFF header keywords: [ST][C][N]OFF.  "4OFF"/"nOFF" (other dimensions) and
# "OFF BINARY" are rejected explicitly rather than misparsed.
_OFF_KEYWORD = re.compile(r"(ST)?C?N?OFF")
_MAX_REASON = 160


def _fail(label: str, reason: str) -> MeshLoadError:
    """A MeshLoadError whose message is ``'<file>: <reason>'`` on one line."""
    return MeshLoadError(f"{label}: {' '.join(str(reason).split())}")


def _short(exc: BaseException) -> str:
    """One line, bounded length description of a foreign exception."""
    text = " ".join(str(exc).split())
    if len(text) > _MAX_REASON:
        text = text[:_MAX_REASON - 3] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# ---------------------------------------------------------------------------
# Shared helpers for the text formats
#
# Each parser first tries a vectorised path (np.loadtxt over a block of lines
# with a uniform column count) and falls back to a per-line Python path, which
# also finds the offending line for the error message.


def _decode(data: bytes) -> str:
    """Text of an ASCII format; latin-1 never fails, and numbers are ASCII anyway."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    return data.decode("latin-1")


def _nonblank_lines(text: str) -> "list[str]":
    """Lines of ``text`` after removing ``#`` comments, without blank ones."""
    if "#" in text:
        text = re.sub(r"#[^\r\n]*", "", text)
    return [line for line in text.splitlines() if line and not line.isspace()]


def _table(lines: "list[str]", dtype) -> "np.ndarray | None":
    """(len(lines), k) array if every line holds k numbers of ``dtype``, else None."""
    if not lines:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            table = np.loadtxt(io.StringIO("\n".join(lines)), dtype=dtype, ndmin=2,
                               comments=None)
    except (ValueError, OverflowError):
        return None
    return table if len(table) == len(lines) else None


def _xyz(lines: "list[str]", label: str, what: str = "vertex") -> np.ndarray:
    """(n, 3) float64 from lines of >= 3 numbers; extra columns (w, colour, normal) dropped."""
    table = _table(lines, np.float64)
    if table is not None and table.shape[1] >= 3:
        return table[:, :3]
    rows = [line.split() for line in lines]
    for number, row in enumerate(rows, 1):
        if len(row) < 3:
            raise _fail(label, f"{what} {number} has fewer than 3 coordinates")
    try:
        return np.array([row[:3] for row in rows], dtype=np.float64).reshape(-1, 3)
    except ValueError as exc:
        raise _fail(label, f"malformed number in {what} data ({_short(exc)})") from None


def _polygons(lines: "list[str]", label: str, counted: bool, exact: bool = False):
    """``(counts (P,) int64, flat (sum(counts),) int64)`` of one polygon per line.

    counted: each line starts with its corner count (OFF, PLY), else every
    token is a corner (OBJ, slashes already removed).  Values after the
    corners are ignored (OFF face colours) unless ``exact``.
    """
    start = 1 if counted else 0
    table = _table(lines, np.int64)
    if table is not None and table.shape[1] > start:
        values = table[:, start:]
        width = values.shape[1]
        counts = table[:, 0].copy() if counted else np.full(len(table), width, dtype=np.int64)
        lengths = np.full(len(table), width, dtype=np.int64)
        rows = None
    else:
        rows = [line.split() for line in lines]
        lengths = np.fromiter((len(row) - start for row in rows), dtype=np.int64,
                              count=len(rows))
        try:
            counts = (np.array([row[0] if row else "0" for row in rows], dtype=np.int64)
                      if counted else lengths)
        except (ValueError, OverflowError) as exc:
            raise _fail(label, f"malformed face corner count ({_short(exc)})") from None
    bad = np.flatnonzero(counts < 3)
    if bad.size:
        raise _fail(label, f"face {bad[0] + 1} has {counts[bad[0]]} corners (needs at least 3)")
    bad = np.flatnonzero(counts != lengths if exact else counts > lengths)
    if bad.size:
        raise _fail(label, f"face {bad[0] + 1} has {lengths[bad[0]]} values "
                           f"for {counts[bad[0]]} corners")
    if rows is None:
        # Row-major boolean mask keeps polygon order and corner order.
        flat = values[np.arange(width) < counts[:, None]]
    else:
        try:
            flat = np.array([i for row, n in zip(rows, counts.tolist())
                             for i in row[start:start + n]], dtype=np.int64)
        except (ValueError, OverflowError) as exc:
            raise _fail(label, f"malformed face index ({_short(exc)})") from None
    return counts, flat


def _fan_triangulate(counts: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Triangulate polygons as fans, keeping polygon order.

    counts: (P,) int64 corners per polygon, all >= 3.
    flat: (sum(counts),) int64 corner indices of all polygons, concatenated.
    Returns (sum(counts - 2), 3) int64: polygon ``p`` with corners ``c0..ck``
    becomes triangles ``(c0, c1, c2), (c0, c2, c3), ...`` in that order.
    """
    if (counts == 3).all():
        return flat.reshape(-1, 3)
    starts = np.cumsum(counts) - counts
    tris = counts - 2
    first = np.repeat(starts, tris)
    # Index of each triangle within its own polygon: 0, 1, ..., tris[p] - 1.
    local = np.arange(int(tris.sum())) - np.repeat(np.cumsum(tris) - tris, tris)
    return np.stack([flat[first], flat[first + local + 1], flat[first + local + 2]], axis=1)


# ---------------------------------------------------------------------------
# OFF


def _parse_off(data: bytes, label: str):
    """``(vertices (V, 3) float64, faces (F, 3) int64)`` of an ASCII OFF file."""
    lines = _nonblank_lines(_decode(data))
    if not lines:
        raise _fail(label, "file contains only comments or blank lines")
    head = lines[0].split()
    if len(head) > 1 and head[1].upper() == "BINARY":
        raise _fail(label, "binary OFF is not supported")
    if not _OFF_KEYWORD.fullmatch(head[0]):
        if re.fullmatch(r"\S*OFF", head[0]):
            raise _fail(label, f"unsupported OFF variant '{head[0]}'")
        raise _fail(label, "not an OFF file (first line must start with 'OFF')")
    # The counts may share the keyword's line ("OFF 8 6 0") or follow it.
    if len(head) > 1:
        counts, body = head[1:], 1
    else:
        counts, body = (lines[1].split() if len(lines) > 1 else []), 2
    if len(counts) < 2:
        raise _fail(label, "missing vertex/face count line")
    try:
        n_vertices, n_faces = int(counts[0]), int(counts[1])
    except ValueError:
        raise _fail(label, f"malformed count line '{' '.join(counts[:3])}'") from None
    if n_vertices < 0 or n_faces < 0:
        raise _fail(label, f"negative count in header ({n_vertices} vertices, {n_faces} faces)")
    # Check the header against the file before allocating anything, so that a
    # 100-byte file claiming 10^12 vertices fails at once.
    available = len(lines) - body
    if n_vertices + n_faces > available:
        raise _fail(label, f"truncated: header declares {n_vertices} vertices and {n_faces} "
                           f"faces but only {available} data lines follow")
    if n_faces == 0:
        raise _fail(label, "contains no triangles (0 faces)")
    vertices = _xyz(lines[body:body + n_vertices], label)
    face_lines = lines[body + n_vertices:body + n_vertices + n_faces]
    return vertices, _fan_triangulate(*_polygons(face_lines, label, counted=True))


# ---------------------------------------------------------------------------
# OBJ


def _parse_obj(data: bytes, label: str):
    """``(vertices (V, 3) float64, faces (F, 3) int64)`` of a Wavefront OBJ file.

    Only ``v`` and ``f`` statements are read; texture coordinates, normals,
    materials, lines and points are ignored, and no other file is opened.
    """
    text = _decode(data)
    # A trailing backslash continues a statement on the next line.
    text = text.replace("\\\r\n", " ").replace("\\\n", " ").replace("\t", " ")
    if "#" in text:
        text = re.sub(r"#[^\r\n]*", "", text)
    if re.search(r"^ ", text, flags=re.MULTILINE):
        text = re.sub(r"^ +", "", text, flags=re.MULTILINE)
    lines = text.splitlines()
    vertex_lines = [line[2:] for line in lines if line.startswith("v ")]
    face_lines = [line[2:] for line in lines if line.startswith("f ")]
    if not face_lines:
        what = f"only {len(vertex_lines)} vertices" if vertex_lines else "no geometry"
        raise _fail(label, f"contains no triangles ({what})")
    vertices = _xyz(vertex_lines, label)
    # A corner is "v", "v/vt", "v//vn" or "v/vt/vn": keep the vertex index.
    face_text = "\n".join(face_lines)
    if "/" in face_text:
        face_text = re.sub(r"/\S*", "", face_text)
    counts, flat = _polygons(face_text.split("\n"), label, counted=False)
    if (flat == 0).any():
        raise _fail(label, "face index 0 (OBJ indices start at 1)")
    if (flat < 0).any():
        # Negative indices count back from the vertices defined so far.
        defined, base = 0, []
        for line in lines:
            if line.startswith("v "):
                defined += 1
            elif line.startswith("f "):
                base.append(defined)
        flat = np.where(flat > 0, flat, np.repeat(np.asarray(base, dtype=np.int64), counts)
                        + flat + 1)
    return vertices, _fan_triangulate(counts, flat - 1)


# ---------------------------------------------------------------------------
# PLY


def _ply_header(data: bytes, label: str):
    """``(format, elements, body_offset)`` of a PLY header.

    ``elements`` is a list of ``(name, count, properties)`` in file order, each
    property a ``(name, is_list)`` pair.
    """
    marker = re.search(rb"end_header[ \t]*\r?\n", data)
    if not data.startswith(b"ply") or marker is None:
        raise _fail(label, "not a PLY file (missing 'ply' or 'end_header')")
    fmt, elements = None, []
    for line in data[:marker.start()].decode("latin-1").splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            try:
                count = int(words[2])
            except ValueError:
                raise _fail(label, f"malformed PLY header line '{line.strip()}'") from None
            if count < 0:
                raise _fail(label, f"negative element count in '{line.strip()}'")
            elements.append((words[1], count, []))
        elif words[0] == "property" and elements and len(words) in (3, 5):
            elements[-1][2].append((words[-1], words[1] == "list"))
        else:
            raise _fail(label, f"malformed PLY header line '{line.strip()[:40]}'")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise _fail(label, f"unknown PLY format {fmt!r}")
    return fmt, elements, marker.end()


def _ply_vertices(lines: "list[str]", props, label: str) -> np.ndarray:
    """(n, 3) float64 x, y, z columns of ASCII PLY vertex rows."""
    names = [name for name, _ in props]
    if any(is_list for _, is_list in props) or not {"x", "y", "z"} <= set(names):
        raise _fail(label, "PLY vertex element needs scalar x, y, z properties")
    table = _table(lines, np.float64)
    if table is None or table.shape[1] != len(props):
        for number, line in enumerate(lines, 1):
            if len(line.split()) != len(props):
                raise _fail(label, f"vertex {number} has {len(line.split())} values, "
                                   f"expected {len(props)}")
        raise _fail(label, "malformed number in vertex data")
    return table[:, [names.index(axis) for axis in "xyz"]]


def _ply_faces(lines: "list[str]", props, label: str) -> np.ndarray:
    """(F, 3) int64 fan triangles of ASCII PLY face rows, in row order."""
    lists = [name for name, is_list in props if is_list]
    target = next((p for p in ("vertex_indices", "vertex_index") if p in lists),
                  lists[0] if lists else None)
    if target is None:
        raise _fail(label, "PLY face element has no vertex index list")
    if len(props) == 1:
        return _fan_triangulate(*_polygons(lines, label, counted=True, exact=True))
    # Other properties around the index list (colours, texture coordinate
    # lists): walk each row.
    flat, counts = [], []
    try:
        for number, line in enumerate(lines, 1):
            tokens, pos = line.split(), 0
            for name, is_list in props:
                n = int(tokens[pos]) if is_list else 0
                if name == target:
                    if n < 3:
                        raise _fail(label, f"face {number} has {n} corners (needs at least 3)")
                    flat.extend(tokens[pos + 1:pos + 1 + n])
                    counts.append(n)
                pos += 1 + n
            if pos != len(tokens):
                raise _fail(label, f"face {number} has {len(tokens)} values, expected {pos}")
        indices = np.array(flat, dtype=np.int64)
    except (ValueError, IndexError, OverflowError) as exc:
        raise _fail(label, f"malformed face data ({_short(exc)})") from None
    return _fan_triangulate(np.asarray(counts, dtype=np.int64), indices)


def _parse_ply_ascii(data: bytes, elements, body: int, label: str):
    """``(vertices (V, 3) float64, faces (F, 3) int64)`` of an ASCII PLY body.

    One element per line.  Row lengths are checked exactly, so a truncated
    file is an error rather than a mesh with its last faces missing.
    """
    lines = _nonblank_lines(_decode(data[body:]))
    declared = sum(count for _, count, _ in elements)
    # Checked before touching any row so that absurd counts fail at once.
    if declared > len(lines):
        raise _fail(label, f"truncated: header declares {declared} rows, "
                           f"only {len(lines)} follow")
    vertices = faces = None
    row = 0
    for name, count, props in elements:
        rows = lines[row:row + count]
        row += count
        if name == "vertex":
            vertices = _ply_vertices(rows, props, label)
        elif name == "face" and count:
            faces = _ply_faces(rows, props, label)
    if vertices is None or faces is None or len(faces) == 0:
        raise _fail(label, "contains no triangles")
    return vertices, faces


def _load_ply(data: bytes, label: str):
    """``(vertices (V, 3) float64, faces (F, 3) int64)`` of a PLY file.

    ASCII PLY is parsed here: trimesh silently drops a truncated last face and
    reorders mixed polygons.  Binary PLY goes to trimesh's parser, which checks
    the exact byte size; it is called directly rather than via ``trimesh.load``
    because the Trimesh constructor would split quads as ``[all first halves,
    all second halves]``.  trimesh's binary reader takes every face's corner
    count from the first face, so binary files mixing polygon sizes fail.
    """
    fmt, elements, body = _ply_header(data, label)
    if fmt == "ascii":
        return _parse_ply_ascii(data, elements, body, label)
    from trimesh.exchange.ply import load_ply

    try:
        with np.errstate(all="ignore"):  # bad numbers are reported by Mesh.from_arrays
            # skip_materials: do not open a texture image named in the header.
            # fix_texture=False: do not split vertices along UV seams.
            kwargs = load_ply(io.BytesIO(data), skip_materials=True, fix_texture=False)
        vertices, faces = kwargs.get("vertices"), kwargs.get("faces")
        if vertices is None or faces is None or len(faces) == 0:
            raise _fail(label, "contains no triangles")
        faces = np.asarray(faces)
        if faces.ndim != 2 or faces.shape[1] < 3 or faces.dtype == object:
            raise _fail(label, f"unexpected face array of shape {faces.shape}")
        counts = np.full(len(faces), faces.shape[1], dtype=np.int64)
        flat = faces.astype(np.int64).reshape(-1)
        return np.asarray(vertices, dtype=np.float64), _fan_triangulate(counts, flat)
    except MeshLoadError:
        raise
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error
        raise _fail(label, f"corrupt or unsupported PLY file ({_short(exc)})") from exc


# ---------------------------------------------------------------------------
# STL and glTF through trimesh


def _BufferFileResolver(path: str):
    """trimesh's resolver for the buffers a .gltf names: only regular files in the
    .gltf's folder (trimesh refuses paths leaving it; a FIFO or device there would
    block the read forever)."""
    import trimesh

    class Resolver(trimesh.resolvers.FilePathResolver):
        def get(self, name: str):
            full = self.absolute(name)
            if not full.is_file():
                raise ValueError(f"buffer '{name}' is not a regular file")
            return super().get(name)

    return Resolver(path)


def _load_trimesh(data: bytes, file_type: str, path: str):
    """``[(vertices, faces), ...]`` of every triangle mesh in an STL or glTF file.

    Scenes are flattened in graph order with each node's transform applied to
    its geometry's vertices (an instanced geometry appears once per node).
    trimesh is imported here, when a file needs it (it takes seconds on some
    machines), and learns our 3DS reader then.
    """
    import trimesh
    load_3ds.register_with_trimesh()

    kwargs = {"process": False, "validate": False, "skip_materials": True}
    if file_type == "gltf":
        # A .gltf names its buffers as files beside it.
        kwargs["resolver"] = _BufferFileResolver(os.path.abspath(path))
    try:
        with np.errstate(all="ignore"):  # bad numbers are reported by Mesh.from_arrays
            scene = trimesh.load(io.BytesIO(data), file_type=file_type, force="scene", **kwargs)
        parts = []
        for node in scene.graph.nodes_geometry:
            transform, geometry_name = scene.graph[node]
            geometry = scene.geometry.get(geometry_name)
            # Point clouds and paths have no faces; they are not rendered.
            if not isinstance(geometry, trimesh.Trimesh) or len(geometry.faces) == 0:
                continue
            vertices = np.asarray(geometry.vertices, dtype=np.float64)
            matrix = np.asarray(transform, dtype=np.float64)
            if not np.array_equal(matrix, np.eye(4)):
                vertices = vertices @ matrix[:3, :3].T + matrix[:3, 3]
            parts.append((vertices, np.asarray(geometry.faces)))
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error
        reason = f"corrupt or unsupported {file_type.upper()} file ({_short(exc)})"
        raise _fail(path, reason) from exc
    if not parts:
        raise _fail(path, "contains no triangles")
    return parts


# ---------------------------------------------------------------------------
# Entry point


def _read_bytes(path: str) -> bytes:
    """The file's contents; MeshLoadError for anything but a readable regular file."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise MeshLoadError(f"no such file: {path}") from None
    except OSError as exc:
        raise _fail(path, f"cannot access file ({exc.strerror or _short(exc)})") from None
    if stat.S_ISDIR(info.st_mode):
        raise _fail(path, "is a directory, not a mesh file")
    # A FIFO or device could block forever or never end.
    if not stat.S_ISREG(info.st_mode):
        raise _fail(path, "not a regular file")
    ext = os.path.splitext(path)[1].lower()
    if ext == ".toml":
        raise _fail(path, "is a scene file, not a mesh (render it with clrt render or clrt.render, "
                          "or read it with clrt.load_scene)")
    if ext not in SUPPORTED_EXTENSIONS:
        shown = f"'{ext}'" if ext else "no extension"
        raise _fail(path, f"unknown mesh format ({shown}); supported: "
                          + ", ".join(SUPPORTED_EXTENSIONS))
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except PermissionError:
        raise _fail(path, "permission denied") from None
    except OSError as exc:
        raise _fail(path, f"cannot read file ({exc.strerror or _short(exc)})") from None
    if not data.strip():
        raise _fail(path, "file is empty")
    return data


def _build(parts, label: str, name: str) -> Mesh:
    """Validate ``[(vertices, faces), ...]`` and concatenate them into one Mesh."""
    meshes = []
    for vertices, faces in parts:
        try:
            meshes.append(Mesh.from_arrays(vertices, faces))
        except MeshLoadError as exc:
            raise _fail(label, str(exc)) from None
    if len(meshes) == 1:
        return Mesh(meshes[0].vertices, meshes[0].faces, name)
    return Mesh.concatenate(meshes, name=name)


def load_mesh(path) -> Mesh:
    """Load the mesh file at ``path`` into one :class:`Mesh` named after the file.

    The format is chosen by the extension (case-insensitive), one of
    :data:`SUPPORTED_EXTENSIONS`.  Raises :class:`MeshLoadError` on any problem.
    """
    path = os.fspath(path)
    data = _read_bytes(path)
    ext = os.path.splitext(path)[1].lower()
    name = os.path.splitext(os.path.basename(path))[0]
    try:
        if ext == ".3ds":
            return load_3ds.parse_3ds(data, label=path, name=name)
        if ext == ".off":
            parts = [_parse_off(data, path)]
        elif ext == ".obj":
            parts = [_parse_obj(data, path)]
        elif ext == ".ply":
            parts = [_load_ply(data, path)]
        else:
            parts = _load_trimesh(data, _TRIMESH_TYPES[ext], path)
        return _build(parts, path, name)
    except MeshLoadError:
        raise
    except Exception as exc:  # a parser bug must still not leak a traceback to the user
        raise _fail(path, f"cannot parse {ext[1:].upper()} file ({_short(exc)})") from exc


# ---------------------------------------------------------------------------
# Camera nodes of glTF files


def _gltf_json(data: bytes, ext: str) -> dict:
    """The JSON document of a .gltf file or of a .glb file's first chunk."""
    import json
    import struct
    if ext == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise ValueError("not a GLB file")
        length, kind = struct.unpack_from("<II", data, 12)
        if kind != 0x4E4F534A:   # "JSON"
            raise ValueError("GLB file without a JSON chunk first")
        data = data[20:20 + length]
    return json.loads(data.decode("utf-8"))


def _node_matrix(node: dict) -> np.ndarray:
    """A glTF node's local transform: ``matrix``, else T * R * S."""
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T   # column-major
    m = np.eye(4)
    if "translation" in node:
        m[:3, 3] = node["translation"]
    if "rotation" in node:
        x, y, z, w = (float(c) for c in node["rotation"])
        m[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    if "scale" in node:
        m[:3, :3] = m[:3, :3] @ np.diag(np.asarray(node["scale"], dtype=np.float64))
    return m


def file_camera(path) -> dict | None:
    """The first perspective camera node of a glTF/GLB file, in world space:
    ``{"eye", "forward", "up", "fov" (vertical, degrees), "aspect" (width / height
    or None), "name"}``; None for other formats, a file without one, or a camera
    clrt cannot use (orthographic, degenerate).  glTF cameras look down their
    node's -z axis with +y up; parent nodes' transforms apply."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".glb", ".gltf"):
        return None
    try:
        doc = _gltf_json(_read_bytes(path), ext)
        nodes, cameras = doc.get("nodes", []), doc.get("cameras", [])
        scenes = doc.get("scenes", [])
        roots = scenes[doc.get("scene", 0)].get("nodes", []) if scenes else range(len(nodes))
        stack = [(int(i), np.eye(4)) for i in reversed(list(roots))]
        seen = set()
        while stack:   # depth first, in file order
            index, parent = stack.pop()
            if index in seen:   # a cycle would never end
                continue
            seen.add(index)
            node = nodes[index]
            world = parent @ _node_matrix(node)
            if "camera" in node:
                perspective = cameras[node["camera"]].get("perspective")
                if perspective is not None:
                    forward, up = -world[:3, 2], world[:3, 1]
                    if np.linalg.norm(forward) > 0 and np.linalg.norm(np.cross(forward, up)) > 0:
                        aspect = perspective.get("aspectRatio")
                        return {"eye": world[:3, 3].copy(), "forward": forward / np.linalg.norm(forward),
                                "up": up / np.linalg.norm(up), "fov": math.degrees(float(perspective["yfov"])),
                                "aspect": float(aspect) if aspect else None,
                                "name": cameras[node["camera"]].get("name", "")}
            stack += [(int(c), world) for c in reversed(node.get("children", []))]
    except MeshLoadError:
        raise
    except Exception as exc:  # noqa: BLE001 -- a malformed camera is reported, not a traceback
        raise _fail(path, f"cannot read the file's camera ({_short(exc)})") from None
    return None


def as_mesh(source) -> Mesh:
    """A Mesh from a Mesh, a mesh file path (str or os.PathLike), a trimesh.Trimesh
    (anything with ``vertices`` and ``faces``) or ``(vertices, faces)``; InputError
    for anything else, MeshLoadError for a bad file or bad arrays."""
    from clrt.errors import InputError
    if isinstance(source, Mesh):
        return source
    if isinstance(source, (str, os.PathLike)):
        return load_mesh(source)
    if hasattr(source, "vertices") and hasattr(source, "faces"):
        return Mesh.from_arrays(source.vertices, source.faces)
    if isinstance(source, tuple) and len(source) == 2:
        return Mesh.from_arrays(*source)
    raise InputError(f"expected a mesh (a clrt.Mesh, a file path, a trimesh object or (vertices, faces)), "
                     f"got {type(source).__name__}")


# trimesh logs warnings with tracebacks (e.g. for a corrupt ASCII STL) while we
# report the failure ourselves; without any handler configured Python's
# last-resort handler would print them to stderr.  A NullHandler stops that and
# still lets an application that configures logging see them.
if not any(isinstance(h, logging.NullHandler) for h in logging.getLogger("trimesh").handlers):
    logging.getLogger("trimesh").addHandler(logging.NullHandler())

