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
reader silently drops a truncated last face.  Binary PLY and STL are parsed
by trimesh with ``process=False`` (no vertex merging or face removal).  glTF
is read here from its JSON and buffers (trimesh's reader drops sparse
accessors and triangle fans, and orders nodes its own way): its faces come in
a depth-first walk of the scene's nodes in file order (the scene's ``nodes``
in order, each node followed by its ``children`` in order, each child's own
children before the next child), within a node its mesh's primitives in
order, within a primitive its triangles in index order, strips and fans
triangulated as the glTF specification numbers them; an instanced mesh
appears once per node, with that node's world transform applied.  3DS has
its own reader in :mod:`clrt.scene.load_3ds`.
"""

from __future__ import annotations

import io
import logging
import math
import os
import re
import stat
import struct
import warnings

from dataclasses import dataclass, field, replace

import numpy as np

from clrt.config import DEFAULT_DIFFUSE, MATERIAL_RANGES
from clrt.errors import InputError, MeshLoadError
from clrt.scene import load_3ds
from clrt.scene.mesh import Mesh
from clrt.scene.texture import Texture, srgb_decode

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


def _loadtxt(text: str, dtype) -> "np.ndarray | None":
    """(rows, k) array if every nonblank line of ``text`` holds k numbers of ``dtype``, else None."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.loadtxt(io.StringIO(text), dtype=dtype, ndmin=2, comments=None)
    except (ValueError, OverflowError):
        return None


def _table(lines: "list[str]", dtype) -> "np.ndarray | None":
    """(len(lines), k) array if every line holds k numbers of ``dtype``, else None."""
    if not lines:
        return None
    table = _loadtxt("\n".join(lines), dtype)
    return table if table is not None and len(table) == len(lines) else None


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


# The usual OFF header: keyword, then the vertex, face (and edge) counts on its
# line or the next, ending in a line break; with the blank lines after it.
# Anything else takes the general path.
_OFF_PLAIN_HEAD = re.compile(rb"\s*(?:ST)?C?N?OFF(?:[ \t]*\r?\n\s*|[ \t]+)"
                             rb"([0-9]+)[ \t]+([0-9]+)(?:[ \t]+[0-9]+)?[ \t]*\r?\n\s*")
# Line breaks of str.splitlines that np.loadtxt reads as spaces or text.
_OTHER_LINE_BREAKS = (b"\v", b"\f", b"\x1c", b"\x1d", b"\x1e", b"\x85")


def _off_plain(data: bytes) -> "_Part | None":
    """The common OFF file -- every vertex line exactly ``x y z``, every face line
    exactly ``3 a b c`` -- read without splitting it into lines in Python; None
    for any other file, which :func:`_parse_off_lines` then reads (and reports).

    The body is cut after the ``V``-th line break, and each part goes to
    np.loadtxt as a whole: it skips blank lines, as the general path does, and
    refuses rows of another length, so a vertex part with blank lines (fewer than
    V rows) or any line of the wrong length gives None.  Both paths parse every
    number with np.loadtxt, so their arrays are equal bit for bit
    (tests/test_off_fast.py compares them).  np.loadtxt is also numpy's fastest
    exact reader here: np.fromstring(text, sep=" ") and np.array(data.split(),
    float) each took twice its time over bunny00.off, and any of them would
    still need the line structure checked.
    """
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    if b"#" in data:
        data = re.sub(rb"#[^\r\n]*", b"", data)
    head = _OFF_PLAIN_HEAD.match(data)
    if head is None:
        return None
    n_vertices, n_faces = int(head[1]), int(head[2])
    body = data[head.end():]
    if n_vertices == 0 or n_faces == 0 or any(c in body for c in _OTHER_LINE_BREAKS):
        return None
    breaks = np.flatnonzero(np.frombuffer(body, np.uint8) == ord("\n"))
    if len(breaks) < n_vertices:
        return None
    cut = int(breaks[n_vertices - 1]) + 1
    vertices = _loadtxt(body[:cut].decode("latin-1"), np.float64)
    if vertices is None or vertices.shape != (n_vertices, 3):
        return None
    faces = _loadtxt(body[cut:].decode("latin-1"), np.int64)
    if faces is None or faces.shape != (n_faces, 4) or (faces[:, 0] != 3).any():
        return None
    return _Part(vertices, np.ascontiguousarray(faces[:, 1:]))


def _parse_off(data: bytes, label: str) -> "_Part":
    """Geometry and colours (vertex colours of COFF, face colours) of an ASCII OFF file."""
    part = _off_plain(data)
    return part if part is not None else _parse_off_lines(data, label)


def _parse_off_lines(data: bytes, label: str) -> "_Part":
    """:func:`_parse_off` for every OFF file: polygons, colours, odd layouts, and
    the error message of a broken file."""
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
    vertex_lines = lines[body:body + n_vertices]
    vertices = _xyz(vertex_lines, label)
    face_lines = lines[body + n_vertices:body + n_vertices + n_faces]
    counts, flat = _polygons(face_lines, label, counted=True)
    part = _Part(vertices, _fan_triangulate(counts, flat))
    # Colours: r g b [a] of each vertex (C prefix) or after a face's corners,
    # used only when every row has them.  A vertex line is, in Geomview's
    # order, x y z [nx ny nz (N)] [r g b a (C)] [s t (ST)].
    if "C" in head[0]:
        table = _table(vertex_lines, np.float64)
        start = 6 if "N" in head[0] else 3
        size = table.shape[1] - start - (2 if head[0].startswith("ST") else 0) if table is not None else 0
        if size in (3, 4):
            tokens = [line.split()[start:start + 3] for line in vertex_lines]
            part.vertex_colors = _off_colors(table[:, start:start + 3], tokens)
    if len(face_lines[0].split()) >= 4 + counts[0]:   # the first face has a colour: look for all
        colors = [line.split()[1 + n:4 + n] for line, n in zip(face_lines, counts.tolist())]
        if all(len(c) == 3 for c in colors):
            try:
                part.face_colors = _off_colors(np.array(colors, dtype=np.float64), colors)
                part.polygon_sizes = counts
            except ValueError:
                raise _fail(label, "malformed face colour") from None
    return part


def _off_colors(values: np.ndarray, tokens: "list[list[str]]") -> np.ndarray:
    """OFF colours in 0..1: Geomview's OFF takes "integers 0..255 or floats
    0..1", so ``values`` are divided by 255 when every one of them is written as
    an integer (``tokens``, their text), whatever their size."""
    text = " ".join(" ".join(t) for t in tokens)
    return values if re.search(r"[^0-9\s+-]", text) else values / 255.0


# ---------------------------------------------------------------------------
# OBJ


def _parse_obj(data: bytes, label: str, folder: str | None = None) -> "_Part":
    """Geometry and surface detail of a Wavefront OBJ file.

    ``v``, ``vt``, ``vn``, ``f``, ``usemtl`` and ``mtllib`` are read; lines and
    points are ignored.  Texture coordinates and normals are used when every
    face corner names one.  Material libraries (``mtllib``, :func:`_parse_mtl`)
    are read from ``folder`` (the OBJ's own), when they are there.
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
    # A corner is "v", "v/vt", "v//vn" or "v/vt/vn": field 0 is the vertex index.
    face_text = "\n".join(face_lines)
    counts, flat = _polygons(_obj_field(face_text, 0).split("\n"), label, counted=False)
    if (flat == 0).any():
        raise _fail(label, "face index 0 (OBJ indices start at 1)")
    # The statements whose order matters: relative indices count back over them,
    # and a face has the material of the last usemtl before it.  Listed only
    # when needed: most files have neither.
    ordered = statements = None
    if (flat < 0).any() or "/" in face_text or any(line.startswith("usemtl ") for line in lines):
        ordered = [line for line in lines if line[:2] in ("v ", "f ", "vt", "vn", "us")]
        statements = [line.split(" ", 1)[0] for line in ordered]
    written = flat
    flat = _obj_absolute(flat, counts, statements, "v", label) - 1
    bad = np.flatnonzero((flat < 0) | (flat >= len(vertices)))
    if bad.size:   # said here, in the file's 1-based numbering (Mesh would say 0-based)
        face = int(np.searchsorted(np.cumsum(counts), bad[0], side="right")) + 1
        raise _fail(label, f"face {face} names vertex {int(written[bad[0]])}, but the file defines "
                           f"{len(vertices)} vertices (OBJ indices 1..{len(vertices)}, or negative counting back)")
    # Triangle corners as positions in the flat corner list, so that every
    # per-corner field triangulates exactly as the vertex indices do.
    corners = _fan_triangulate(counts, np.arange(len(flat)))
    part = _Part(vertices, flat[corners])
    if "/" in face_text:
        for field, keyword in ((1, "vt"), (2, "vn")):
            rows = [line.split()[1:] for line in lines if line.startswith(keyword + " ")]
            indices = _obj_field(face_text, field, missing="0").split()
            if not rows or len(indices) != len(flat) or "0" in indices:
                continue   # some corner lacks one: ignore them all
            try:
                table = np.array([row[:3] + ["0"] * (3 - len(row[:3])) for row in rows], dtype=np.float64)
                index = _obj_absolute(np.array(indices, dtype=np.int64), counts, statements, keyword, label)
            except ValueError as exc:
                raise _fail(label, f"malformed {keyword} data ({_short(exc)})") from None
            if index.max() > len(table):
                raise _fail(label, f"{keyword} index {index.max()} out of range ({len(table)} defined)")
            if keyword == "vt":
                part.uv = table[index - 1][corners][..., :2]
            else:   # a vertex with several normals becomes one vertex per normal
                pairs, inverse = np.unique(np.stack([flat, index - 1], axis=1), axis=0, return_inverse=True)
                part.vertices, part.normals = vertices[pairs[:, 0]], table[pairs[:, 1]]
                part.faces = inverse.reshape(-1)[corners]
    used = [line.split(None, 1)[1].strip() for line in lines if line.startswith("usemtl ") and " " in line]
    libraries = [line.split(None, 1)[1].strip() for line in lines
                 if line.startswith("mtllib ") and len(line.split()) > 1]
    if used and folder is not None:
        materials = {}
        for name in _mtl_libraries(libraries, folder):
            materials.update(_parse_mtl(os.path.join(folder, name), label))
        if materials:
            names = list(materials)
            current, polygon_material = -1, []
            for statement, line in zip(statements, ordered):
                if statement == "usemtl":
                    name = line.split(None, 1)[1].strip() if " " in line else ""
                    current = names.index(name) if name in materials else -1
                elif statement == "f":
                    polygon_material.append(current)
            part.face_material = np.repeat(np.asarray(polygon_material, np.int64), counts - 2)
            part.materials = [materials[n] for n in names]
    return part


def _mtl_libraries(arguments: "list[str]", folder: str) -> "list[str]":
    """The file names of ``mtllib`` statements (their arguments): one statement
    may name several libraries, separated by spaces (the OBJ specification);
    a whole argument naming a file in ``folder`` is one name with spaces."""
    names = []
    for text in arguments:
        names.extend([text] if os.path.isfile(os.path.join(folder, text)) else text.split())
    return names


def _obj_field(face_text: str, field: int, missing: str = "") -> str:
    """The face lines with each corner "v/vt/vn" replaced by one of its fields
    (``missing`` where the corner has none)."""
    if "/" not in face_text:
        return face_text if field == 0 else re.sub(r"\S+", missing, face_text)
    if field == 0:
        return re.sub(r"/\S*", "", face_text)
    return re.sub(r"\S+", lambda m: (m.group(0).split("/") + [""] * 2)[field] or missing, face_text)


def _obj_absolute(index: np.ndarray, counts: np.ndarray, statements: list, keyword: str, label: str) -> np.ndarray:
    """1-based indices of ``keyword`` rows, negative ones (counting back from
    the rows defined so far) made absolute."""
    if not (index < 0).any():
        return index
    defined, base = 0, []
    for statement in statements:
        if statement == keyword:
            defined += 1
        elif statement == "f":
            base.append(defined)
    return np.where(index > 0, index, np.repeat(np.asarray(base, dtype=np.int64), counts) + index + 1)


def _parse_mtl(path: str, label: str) -> dict:
    """``{name: material fields}`` of an MTL file (docs/scene-files.md has the
    table: Kd, Ks, Ns, d/Tr, Ni, illum, map_Kd); {} when the file is missing,
    as it often is beside downloaded OBJ files."""
    if not os.path.isfile(path):
        return {}
    text = _decode(_read_any(path, label))
    folder = os.path.dirname(path)
    materials, current = {}, None
    for raw in _nonblank_lines(text):
        words = raw.split()
        key, args = words[0], words[1:]
        if key == "newmtl":
            current = materials.setdefault(" ".join(args), {})
            continue
        if current is None or not args:
            continue
        try:
            if key == "map_Kd":
                # Options ("-clamp on", "-s 1 1 1", ...) come before the file name.
                clamp = "-clamp" in args and args[args.index("-clamp") + 1:][:1] == ["on"]
                wrap = "clamp" if clamp else "repeat"
                image = os.path.join(folder, args[-1])
                if os.path.isfile(image):
                    current["texture"] = _texture(image, wrap, wrap, label)
            elif key in ("Kd", "Ks"):
                current[key] = [float(x) for x in (args * 3)[:3]]
            elif key in ("Ns", "d", "Tr", "Ni", "illum"):
                current[key] = float(args[0])
        except ValueError:
            raise _fail(label, f"{os.path.basename(path)}: malformed {key} line") from None
    return {name: _mtl_material(m, f"{os.path.basename(path)}: material {name!r}", label)
            for name, m in materials.items()}


# The MTL statement behind each material field, for messages.
_MTL_KEYS = {"color": "Kd", "specular": "Ks", "reflectivity": "Ks", "shininess": "Ns", "transparency": "d",
             "ior": "Ni", "texture": "map_Kd"}


def _mtl_material(m: dict, where: str, label: str) -> dict:
    """:func:`_whitted_from_mtl`, its values checked: a bad one is an error naming
    the mesh file, the MTL file, the material and the statement, with the values
    as the file has them (not as clamped into range)."""
    from clrt import checks, config
    for key, value in m.items():
        values = value if isinstance(value, list) else [value] if isinstance(value, float) else []
        if not all(math.isfinite(v) for v in values):
            shown = checks.show(value)
            rule = f"{len(values)} finite numbers" if isinstance(value, list) else "a finite number"
            raise _fail(label, f"{where}: {key} must be {rule}, got {shown}")
    fields = _whitted_from_mtl(m)
    try:   # the checks clrt.Material makes of these fields (the color is clamped into range already)
        for name in config.MATERIAL_RANGES:
            if name in fields:
                checks.material_number(f"material {name}", fields[name], name)
    except InputError as exc:
        bad = next((f for f in fields if f"material {f} " in str(exc)), "")
        key = _MTL_KEYS.get(bad, "")
        if key == "d" and "d" not in m:
            key = "Tr"
        given = f"{key} {checks.show(m[key])} " if key in m else ""
        raise _fail(label, f"{where}: {given}is out of range: {exc}") from None
    return fields


def _whitted_from_mtl(m: dict) -> dict:
    """Material fields (clrt.Material) of an MTL material's statements."""
    fields = {}
    if "Kd" in m:
        fields["color"] = tuple(min(max(c, 0.0), 1.0) for c in m["Kd"])
    if "Ks" in m:
        fields["specular"] = max(sum(m["Ks"]) / 3, 0.0)
        if m.get("illum") in (3.0, 5.0, 7.0):   # "reflection on": mirror by Ks
            fields["reflectivity"] = min(fields["specular"], 1.0)
    if "Ns" in m:
        fields["shininess"] = max(m["Ns"], 0.0)
    opacity = m["d"] if "d" in m else 1.0 - m["Tr"] if "Tr" in m else 1.0
    if opacity < 1.0:
        fields["transparency"] = min(max(1.0 - opacity, 0.0), 1.0)
    if m.get("Ni", 0.0) >= 1.0:
        fields["ior"] = m["Ni"]
    if "texture" in m:
        fields["texture"] = m["texture"]
    return fields


# ---------------------------------------------------------------------------
# PLY


def _ply_header(data: bytes, label: str):
    """``(format, elements, body_offset)`` of a PLY header.

    ``elements`` is a list of ``(name, count, properties)`` in file order, each
    property a ``(name, is_list, types)`` triple: ``types`` is ``(type,)`` for a
    scalar, ``(count type, item type)`` for a list, as the header names them.
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
            is_list = words[1] == "list"
            elements[-1][2].append((words[-1], is_list, tuple(words[2:4]) if is_list else (words[1],)))
        else:
            raise _fail(label, f"malformed PLY header line '{line.strip()[:40]}'")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise _fail(label, f"unknown PLY format {fmt!r}")
    return fmt, elements, marker.end()


def _ply_vertices(lines: "list[str]", props, label: str) -> dict:
    """``{property: (n,) float64 column}`` of ASCII PLY vertex rows (x, y, z at least)."""
    names = [p[0] for p in props]
    if any(p[1] for p in props) or not {"x", "y", "z"} <= set(names):
        raise _fail(label, "PLY vertex element needs scalar x, y, z properties")
    table = _table(lines, np.float64)
    if table is None or table.shape[1] != len(props):
        for number, line in enumerate(lines, 1):
            if len(line.split()) != len(props):
                raise _fail(label, f"vertex {number} has {len(line.split())} values, "
                                   f"expected {len(props)}")
        raise _fail(label, "malformed number in vertex data")
    return dict(zip(names, table.T))


def _ply_faces(lines: "list[str]", props, label: str):
    """``(counts (P,) int64, flat corner indices, {scalar property: (P,) column})``
    of ASCII PLY face rows, in row order."""
    lists = [name for name, is_list, _ in props if is_list]
    target = next((p for p in ("vertex_indices", "vertex_index") if p in lists),
                  lists[0] if lists else None)
    if target is None:
        raise _fail(label, "PLY face element has no vertex index list")
    if len(props) == 1:
        return (*_polygons(lines, label, counted=True, exact=True), {})
    # Other properties around the index list (colours, texture coordinate
    # lists): walk each row.
    flat, counts = [], []
    scalars = {name: [] for name, is_list, _ in props if not is_list}
    try:
        for number, line in enumerate(lines, 1):
            tokens, pos = line.split(), 0
            for name, is_list, _ in props:
                n = int(tokens[pos]) if is_list else 0
                if name == target:
                    if n < 3:
                        raise _fail(label, f"face {number} has {n} corners (needs at least 3)")
                    flat.extend(tokens[pos + 1:pos + 1 + n])
                    counts.append(n)
                elif not is_list:
                    scalars[name].append(float(tokens[pos]))
                pos += 1 + n
            if pos != len(tokens):
                raise _fail(label, f"face {number} has {len(tokens)} values, expected {pos}")
        indices = np.array(flat, dtype=np.int64)
    except (ValueError, IndexError, OverflowError) as exc:
        raise _fail(label, f"malformed face data ({_short(exc)})") from None
    return np.asarray(counts, dtype=np.int64), indices, {k: np.asarray(v) for k, v in scalars.items()}


# PLY property types (both spellings) and their numpy codes.
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _ply_color_scale(type_name: str) -> float:
    """What a PLY colour property of this type holds at full intensity: float and
    double colours are 0..1, 16-bit unsigned ones 0..65535, every other integer
    type (uchar above all, the common one; int in many ASCII files) 0..255."""
    code = _PLY_TYPES.get(type_name, "f8")
    return 1.0 if code[0] == "f" else 65535.0 if code == "u2" else 255.0


def _ply_colors(columns: dict, types: dict) -> "np.ndarray | None":
    """(n, 3) float64 colours in 0..1 from the red, green, blue columns, each
    scaled by its declared type (:func:`_ply_color_scale`, never by its values);
    None without all three."""
    rgb = ("red", "green", "blue")
    if not set(rgb) <= set(columns):
        return None
    return np.stack([np.asarray(columns[c], np.float64) / _ply_color_scale(types.get(c, "float")) for c in rgb],
                    axis=1)


def _ply_types(elements) -> dict:
    """``{element name: {property name: value type}}`` of a PLY header."""
    return {name: {p[0]: p[2][-1] for p in props} for name, _, props in elements}


def _ply_part(vertex: dict, counts: np.ndarray, flat: np.ndarray, face: dict, types: dict,
              normals=None) -> "_Part":
    """A part from PLY vertex and face property columns: normals (nx, ny, nz),
    colours (red, green, blue, of vertices or else of faces, scaled to 0..1 by
    their declared types) and texture coordinates (texture_u/v, u/v or s/t, per
    vertex).  ``types``: :func:`_ply_types` of the header."""
    part = _Part(np.stack([vertex[a] for a in "xyz"], axis=1), _fan_triangulate(counts, flat))
    if normals is None and {"nx", "ny", "nz"} <= set(vertex):
        normals = np.stack([vertex[a] for a in ("nx", "ny", "nz")], axis=1)
    part.normals = normals
    vertex_colors = _ply_colors(vertex, types.get("vertex", {}))
    face_colors = _ply_colors(face, types.get("face", {}))
    if vertex_colors is not None:
        part.vertex_colors = vertex_colors
    elif face_colors is not None:
        part.face_colors, part.polygon_sizes = face_colors, counts
    for u, v in (("texture_u", "texture_v"), ("u", "v"), ("s", "t")):
        if u in vertex and v in vertex:
            part.uv = np.stack([vertex[u], vertex[v]], axis=1)[part.faces]
            break
    return part


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
    vertex = faces = None
    row = 0
    for name, count, props in elements:
        rows = lines[row:row + count]
        row += count
        if name == "vertex":
            vertex = _ply_vertices(rows, props, label)
        elif name == "face" and count:
            faces = _ply_faces(rows, props, label)
    if vertex is None or faces is None or len(faces[0]) == 0:
        raise _fail(label, "contains no triangles")
    return _ply_part(vertex, *faces, _ply_types(elements))


def _ply_binary_rows(data: bytes, pos: int, count: int, props, order: str, label: str):
    """``(columns, end, target)`` of ``count`` binary PLY rows with list
    properties from byte ``pos``, walked row by row (rows differ in length):
    ``columns`` maps each scalar property to its (count,) column and the vertex
    index list ``target`` (as :func:`_ply_faces` picks it) to ``(counts, flat)``;
    other lists are skipped.  ``end``: the byte after the last row."""
    lists = [name for name, is_list, _ in props if is_list]
    target = next((p for p in ("vertex_indices", "vertex_index") if p in lists), lists[0])
    layout = []
    for name, is_list, types in props:
        codes = [_PLY_STRUCT[_ply_dtype(t, label).str[1:]] for t in types]
        if is_list and codes[0] in "fd":
            raise _fail(label, f"PLY list {name!r} has a non-integer count type {types[0]!r}")
        layout.append((name, is_list, struct.Struct(order + codes[0]), codes[-1]))
    scalars = {name: [] for name, is_list, _ in props if not is_list}
    counts, flat, cache = [], [], {}
    smallest = sum(s.size for _, _, s, _ in layout)
    if count * smallest > len(data) - pos:
        raise _fail(label, f"truncated: header declares {count} rows of at least {smallest} bytes, "
                           f"only {len(data) - pos} bytes follow")
    for number in range(1, count + 1):
        for name, is_list, head, code in layout:
            if pos + head.size > len(data):
                raise _fail(label, f"truncated binary PLY (row {number} of {count})")
            value = head.unpack_from(data, pos)[0]
            pos += head.size
            if not is_list:
                scalars[name].append(value)
                continue
            if name == target and value < 3:
                raise _fail(label, f"face {number} has {value} corners (needs at least 3)")
            if value < 0:
                raise _fail(label, f"row {number} of {count} has a list of {value} items")
            items = cache.get((value, code))
            if items is None:
                items = cache[value, code] = struct.Struct(f"{order}{value}{code}")
            if pos + items.size > len(data):
                raise _fail(label, f"truncated binary PLY (row {number} of {count}: a list of {value} items)")
            if name == target:
                flat.extend(items.unpack_from(data, pos))
                counts.append(value)
            pos += items.size
    columns = {k: np.asarray(v, np.float64) for k, v in scalars.items()}
    columns[target] = (np.asarray(counts, np.int64), np.asarray(flat, np.int64))
    return columns, pos, target


# numpy codes -> struct codes
_PLY_STRUCT = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f", "f8": "d"}


def _ply_dtype(type_name: str, label: str) -> np.dtype:
    """The numpy dtype (native order) of a PLY property type; MeshLoadError for an unknown one."""
    code = _PLY_TYPES.get(type_name)
    if code is None:
        raise _fail(label, f"unknown PLY property type {type_name!r}")
    return np.dtype(code)


def _ply_faces_mixed(data: bytes, fmt: str, elements, body: int) -> bool:
    """Whether a binary PLY file's face lists differ in length from row to row
    (found when only list-free elements come before the faces; False when
    unknown).  trimesh's reader takes every row's list lengths from the first
    row: on such a file it fails on the length or, when the sizes happen to add
    up, reads garbage."""
    order = "<" if fmt == "binary_little_endian" else ">"
    try:
        pos = body
        for name, count, props in elements:
            if name == "face":
                break
            if any(p[1] for p in props):
                return False
            pos += count * sum(np.dtype(_PLY_TYPES[p[2][0]]).itemsize for p in props)
        else:
            return False
        fields, off = [], pos
        for i, (_, is_list, types) in enumerate(props):
            head = np.dtype(_PLY_TYPES[types[0]]).newbyteorder(order)
            if off + head.itemsize > len(data) or not count:
                return False
            fields.append((f"c{i}", head))
            off += head.itemsize
            if is_list:
                n = int(np.frombuffer(data, head, 1, off - head.itemsize)[0])
                item = np.dtype(_PLY_TYPES[types[1]]).newbyteorder(order)
                if n < 0 or off + n * item.itemsize > len(data):
                    return False
                fields.append((f"v{i}", item, (n,)))
                off += n * item.itemsize
        row = np.dtype(fields)
        if count * row.itemsize > len(data) - pos:
            return False
        table = np.frombuffer(data, row, count, pos)
        return any((table[f"c{i}"] != table[f"c{i}"][0]).any() for i, p in enumerate(props) if p[1])
    except (KeyError, ValueError, TypeError, OverflowError, MemoryError):
        return False


def _parse_ply_binary(data: bytes, fmt: str, elements, body: int, label: str) -> "_Part":
    """A binary PLY body read here, for what trimesh's reader refuses: faces of
    mixed sizes (it takes every face's corner count from the first face).
    Elements without lists are read at once; the others row by row, so this is
    the slower reader, used only when trimesh's fails on the file's length."""
    order = "<" if fmt == "binary_little_endian" else ">"
    pos, vertex, faces = body, None, None
    for name, count, props in elements:
        if name == "vertex" and (any(p[1] for p in props) or not {"x", "y", "z"} <= {p[0] for p in props}):
            raise _fail(label, "PLY vertex element needs scalar x, y, z properties")
        if any(p[1] for p in props):
            columns, pos, target = _ply_binary_rows(data, pos, count, props, order, label)
            if name == "face":
                faces = (*columns.pop(target), columns)
            continue
        dtype = np.dtype([(f"p{i}", _ply_dtype(p[2][0], label).newbyteorder(order)) for i, p in enumerate(props)])
        if count * dtype.itemsize > len(data) - pos:
            raise _fail(label, f"truncated: header declares {count} {name} rows of {dtype.itemsize} bytes, "
                               f"only {len(data) - pos} bytes follow")
        table = np.frombuffer(data, dtype, count, pos)
        pos += count * dtype.itemsize
        if name == "vertex":
            vertex = {p[0]: table[f"p{i}"].astype(np.float64) for i, p in enumerate(props)}
    if pos != len(data):
        raise _fail(label, f"binary PLY longer than its header says ({len(data) - pos} bytes after the last element)")
    if vertex is None or faces is None or len(faces[0]) == 0:
        raise _fail(label, "contains no triangles")
    return _ply_part(vertex, *faces, _ply_types(elements))


def _load_ply(data: bytes, label: str):
    """``(vertices (V, 3) float64, faces (F, 3) int64)`` of a PLY file.

    ASCII PLY is parsed here: trimesh silently drops a truncated last face and
    reorders mixed polygons.  Binary PLY goes to trimesh's parser, which checks
    the exact byte size; it is called directly rather than via ``trimesh.load``
    because the Trimesh constructor would split quads as ``[all first halves,
    all second halves]``.  trimesh's binary reader takes every face's corner
    count from the first face, so it misreads a file mixing polygon sizes or
    refuses it as of the wrong length: such a file (:func:`_ply_faces_mixed`),
    and any other it refuses so, is read by :func:`_parse_ply_binary`, which
    either reads it or says what is wrong.
    Colours are scaled to 0..1 by their declared types (:func:`_ply_color_scale`).
    """
    fmt, elements, body = _ply_header(data, label)
    if fmt == "ascii":
        return _parse_ply_ascii(data, elements, body, label)
    if _ply_faces_mixed(data, fmt, elements, body):
        return _parse_ply_binary(data, fmt, elements, body, label)
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
        vertices = np.asarray(vertices, dtype=np.float64)
        vertex = dict(zip("xyz", vertices.T))
        face = {}
        for colors, columns in ((kwargs.get("vertex_colors"), vertex), (kwargs.get("face_colors"), face)):
            if colors is not None:
                columns.update(zip(("red", "green", "blue"), np.asarray(colors).T[:3]))
        uv = getattr(kwargs.get("visual"), "uv", None)
        if uv is not None and len(uv) == len(vertices):
            vertex.update(u=uv[:, 0], v=uv[:, 1])
        return _ply_part(vertex, counts, flat, face, _ply_types(elements), kwargs.get("vertex_normals"))
    except MeshLoadError:
        raise
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error
        if "unexpected length" in str(exc):   # faces of mixed sizes, or a truncated or padded file
            return _parse_ply_binary(data, fmt, elements, body, label)
        raise _fail(label, f"corrupt or unsupported PLY file ({_short(exc)})") from exc


# ---------------------------------------------------------------------------
# STL and glTF through trimesh


_STL_HEADER, _STL_TRIANGLE = 84, 50   # binary STL: 80-byte header and a uint32 count; 50 bytes a triangle


def _stl_checked(data: bytes, label: str) -> bytes:
    """The STL file's bytes for trimesh, once its kind is clear: a binary STL must
    be exactly as long as its header's triangle count says (else trimesh falls
    back to its ASCII reader, whose error hides the real problem); an ASCII STL
    starts with 'solid' and holds no NUL byte, and goes to trimesh as UTF-8
    (its own decoding of other text needs an optional package)."""
    import struct
    count = struct.unpack_from("<I", data, 80)[0] if len(data) >= _STL_HEADER else None
    if count is not None and len(data) == _STL_HEADER + _STL_TRIANGLE * count:
        return data
    if data.lstrip()[:5].lower() == b"solid" and b"\0" not in data:
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            data = data.decode("latin-1").encode("utf-8")
        return data
    if count is None:
        raise _fail(label, f"not an STL file ({len(data)} bytes: too short for a binary STL's "
                           f"{_STL_HEADER}-byte header, and not ASCII STL, which starts with 'solid')")
    room = (len(data) - _STL_HEADER) // _STL_TRIANGLE
    if len(data) < _STL_HEADER + _STL_TRIANGLE * count:
        raise _fail(label, f"truncated binary STL (header says {count} triangles, the file holds room for {room})")
    raise _fail(label, f"binary STL longer than its header says (header says {count} triangles, the file "
                       f"holds room for {room}{' and some bytes' if (len(data) - _STL_HEADER) % _STL_TRIANGLE else ''})")


def _load_trimesh(data: bytes, file_type: str, path: str) -> "list[_Part]":
    """Every triangle mesh in an STL file (trimesh reads it) or a glTF file
    (read here: :func:`_gltf_parts`).

    trimesh is imported here, when a file needs it (it takes seconds on some
    machines), and learns our 3DS reader then.
    """
    if file_type in ("gltf", "glb"):
        return _gltf_parts(data, file_type, path)
    import trimesh
    load_3ds.register_with_trimesh()
    try:
        with np.errstate(all="ignore"):  # bad numbers are reported by Mesh.from_arrays
            scene = trimesh.load(io.BytesIO(data), file_type=file_type, force="scene", process=False,
                                 validate=False, skip_materials=True)
        parts = []
        for node in scene.graph.nodes_geometry:
            transform, geometry_name = scene.graph[node]
            geometry = scene.geometry.get(geometry_name)
            if not isinstance(geometry, trimesh.Trimesh) or len(geometry.faces) == 0:
                continue
            part = _trimesh_part(geometry, linear_colors=False)
            matrix = np.asarray(transform, dtype=np.float64)
            if not np.array_equal(matrix, np.eye(4)):
                part.vertices = part.vertices @ matrix[:3, :3].T + matrix[:3, 3]
            parts.append(part)
    except MeshLoadError:
        raise
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error
        raise _fail(path, f"corrupt or unsupported {file_type.upper()} file ({_short(exc)})") from exc
    if not parts:
        raise _fail(path, "contains no triangles")
    return parts


def _trimesh_part(geometry, linear_colors: bool) -> "_Part":
    """Vertices, faces, and what a trimesh.Trimesh's visual holds: texture
    coordinates, vertex or face colours (sRGB unless ``linear_colors``), and
    normals when they came from the file (trimesh keeps loaded normals in its
    cache; it only computes them when asked)."""
    part = _Part(np.asarray(geometry.vertices, dtype=np.float64), np.asarray(geometry.faces, dtype=np.int64))
    part.srgb_colors = not linear_colors
    if "vertex_normals" in geometry._cache.cache:
        part.normals = np.asarray(geometry.vertex_normals, dtype=np.float64)
    visual = geometry.visual
    n_vertices = len(part.vertices)
    kind = getattr(visual, "kind", None)
    if kind == "texture":
        uv = getattr(visual, "uv", None)
        if uv is not None and len(uv) == n_vertices:
            part.uv = np.asarray(uv, dtype=np.float64)[part.faces]
        colors = getattr(visual, "vertex_attributes", {}).get("color")
        if colors is not None and len(colors) == n_vertices:
            part.vertex_colors = _unit_colors(colors)
    elif kind == "vertex":
        part.vertex_colors = _unit_colors(visual.vertex_colors)
    elif kind == "face":
        part.face_colors = _unit_colors(visual.face_colors)
    return part


def _unit_colors(colors) -> np.ndarray:
    """(n, 3) float64 in 0..1 of RGB(A) colours stored as floats or as normalised integers."""
    c = np.asarray(colors)
    scale = np.iinfo(c.dtype).max if np.issubdtype(c.dtype, np.integer) else 1.0
    return c[:, :3].astype(np.float64) / scale


# ---------------------------------------------------------------------------
# glTF 2.0 (.gltf, .glb): geometry, materials and images read from the JSON
# document and its buffers.  trimesh's reader (5.2.0) drops sparse accessors
# and TRIANGLE_FAN primitives, takes normalised-integer texture coordinates
# as they are, quantises COLOR_0 to 8 bits, ignores a mirroring node's
# winding and orders nodes by its graph, not by the file.

_GLTF_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
                    5126: np.float32}
_GLTF_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_GLTF_COMPRESSION = ("KHR_draco_mesh_compression", "EXT_meshopt_compression")
_GLTF_WRAPS = {10497: "repeat", 33071: "clamp", 33648: "mirror"}
_GLTF_MAX_ACCESSOR = 1 << 28   # bytes of an accessor without a bufferView (all zeros, or sparse)


class _GltfError(ValueError):
    """What is wrong with a glTF file's content, in words."""


def _gltf_int(value, what: str, low: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise _GltfError(f"{what} is {value!r}, not an integer >= {low}")
    return value


class _GltfFile:
    """A glTF document and its buffers (read when first needed): accessors,
    primitives and images."""

    def __init__(self, doc: dict, data: bytes, file_type: str, path: str):
        self.doc, self.path = doc, path
        self.folder = os.path.dirname(os.path.abspath(path))
        self.buffers: dict = {}
        self.glb_bin = None
        if file_type == "glb":
            offset = 20 + struct.unpack_from("<I", data, 12)[0]
            if len(data) >= offset + 8:
                length, kind = struct.unpack_from("<II", data, offset)
                if kind == 0x004E4942:   # "BIN\0"
                    if len(data) < offset + 8 + length:
                        raise _GltfError(f"truncated GLB file (its binary chunk is {length} bytes, the file "
                                         f"holds {len(data) - offset - 8})")
                    self.glb_bin = memoryview(data)[offset + 8:offset + 8 + length]

    def item(self, kind: str, index, what: str) -> dict:
        items = self.doc.get(kind)
        n = len(items) if isinstance(items, list) else 0
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < n:
            raise _GltfError(f"{what} {index!r} does not exist (the file has {n})")
        if not isinstance(items[index], dict):
            raise _GltfError(f"{what} {index} is not an object")
        return items[index]

    def uri(self, uri, what: str) -> "bytes | None":
        """The bytes a URI names: a data URI, or a regular file in the file's
        folder (None if there is no such file)."""
        import base64
        import urllib.parse
        if not isinstance(uri, str):
            raise _GltfError(f"{what}: uri is not a string")
        if uri.startswith("data:"):
            head, sep, body = uri.partition(",")
            if not sep:
                raise _GltfError(f"{what}: malformed data URI")
            try:
                return base64.b64decode(body) if head.endswith(";base64") else urllib.parse.unquote_to_bytes(body)
            except ValueError:
                raise _GltfError(f"{what}: bad base64 in its data URI") from None
        name = urllib.parse.unquote(uri)
        folder = os.path.realpath(self.folder)
        full = os.path.realpath(os.path.join(folder, name))
        if os.path.isabs(name) or os.path.commonpath([full, folder]) != folder:
            raise _GltfError(f"{what}: '{uri}' escapes the folder of the file")
        if not os.path.exists(full):
            return None
        if not os.path.isfile(full):   # a FIFO or device could block forever
            raise _GltfError(f"{what}: '{uri}' is not a regular file")
        with open(full, "rb") as fh:
            return fh.read()

    def buffer(self, index) -> memoryview:
        if index not in self.buffers:
            b = self.item("buffers", index, "buffer")
            if "uri" not in b:
                if self.glb_bin is None or index != 0:
                    raise _GltfError(f"buffer {index} has no uri and the file no binary chunk")
                data = self.glb_bin
            else:
                data = self.uri(b["uri"], f"buffer {index}")
                if data is None:
                    raise _GltfError(f"buffer {index}: no such file '{b['uri']}'")
            length = _gltf_int(b.get("byteLength", len(data)), f"buffer {index} byteLength")
            if len(data) < length:
                raise _GltfError(f"buffer {index} holds {len(data)} bytes, its byteLength says {length}")
            self.buffers[index] = memoryview(data)[:length]
        return self.buffers[index]

    def _view_array(self, view_index, offset, dtype, width: int, count: int, what: str) -> np.ndarray:
        """(count, width) elements of ``dtype`` (little-endian) from a bufferView."""
        view = self.item("bufferViews", view_index, "bufferView")
        buf = self.buffer(view.get("buffer"))
        start = _gltf_int(view.get("byteOffset", 0), f"bufferView {view_index} byteOffset")
        length = _gltf_int(view.get("byteLength"), f"bufferView {view_index} byteLength")
        offset = _gltf_int(offset, f"{what} byteOffset")
        if start + length > len(buf):
            raise _GltfError(f"bufferView {view_index} ends past the end of its buffer")
        dtype = np.dtype(dtype).newbyteorder("<")
        size = dtype.itemsize * width
        stride = _gltf_int(view.get("byteStride", 0), f"bufferView {view_index} byteStride") or size
        if stride < size:
            raise _GltfError(f"{what}: bufferView {view_index} byteStride {stride} is less than an element")
        if count == 0:
            return np.zeros((0, width), dtype.newbyteorder("="))
        total = stride * (count - 1) + size
        if offset + total > length:
            raise _GltfError(f"{what} reads past the end of bufferView {view_index}")
        raw = np.frombuffer(buf, np.uint8, count=total, offset=start + offset)
        if stride != size:
            padded = np.zeros(stride * count, np.uint8)
            padded[:total] = raw
            raw = np.ascontiguousarray(padded.reshape(count, stride)[:, :size]).reshape(-1)
        return raw.view(dtype).reshape(count, width).astype(dtype.newbyteorder("="))

    def accessor(self, index, what: str, widths=None) -> "tuple[np.ndarray, bool]":
        """An accessor's elements (count, width), sparse values applied, in
        their stored type; and whether they are normalised integers."""
        a = self.item("accessors", index, "accessor")
        where = f"{what} (accessor {index})"
        dtype = _GLTF_COMPONENTS.get(a.get("componentType"))
        width = _GLTF_WIDTHS.get(a.get("type"))
        if dtype is None or width is None:
            raise _GltfError(f"{where}: unknown componentType {a.get('componentType')!r} or type {a.get('type')!r}")
        if widths is not None and width not in widths:
            raise _GltfError(f"{where} has type {a.get('type')}")
        count = _gltf_int(a.get("count"), f"{where} count")
        if "bufferView" in a:
            out = self._view_array(a["bufferView"], a.get("byteOffset", 0), dtype, width, count, where)
        else:
            if count * width * np.dtype(dtype).itemsize > _GLTF_MAX_ACCESSOR:
                raise _GltfError(f"{where}: count {count} without a bufferView is too large")
            out = np.zeros((count, width), dtype)
        sparse = a.get("sparse")
        if sparse is not None:
            if not isinstance(sparse, dict) or not isinstance(sparse.get("indices"), dict) \
                    or not isinstance(sparse.get("values"), dict):
                raise _GltfError(f"{where}: malformed sparse")
            n = _gltf_int(sparse.get("count"), f"{where} sparse count", 1)
            ind, val = sparse["indices"], sparse["values"]
            index_type = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32}.get(ind.get("componentType"))
            if index_type is None:
                raise _GltfError(f"{where}: sparse indices of componentType {ind.get('componentType')!r}")
            rows = self._view_array(ind.get("bufferView"), ind.get("byteOffset", 0), index_type, 1, n,
                                    f"{where} sparse indices")[:, 0].astype(np.int64)
            values = self._view_array(val.get("bufferView"), val.get("byteOffset", 0), dtype, width, n,
                                      f"{where} sparse values")
            if rows.max() >= count:
                raise _GltfError(f"{where}: sparse index {rows.max()} past its {count} elements")
            out = out.copy()
            out[rows] = values
        return out, bool(a.get("normalized", False))

    def floats(self, index, what: str, widths) -> np.ndarray:
        """An accessor's elements as float64, normalised integers mapped to 0..1 (-1..1 signed)."""
        values, normalized = self.accessor(index, what, widths)
        if normalized and np.issubdtype(values.dtype, np.integer):
            top = float(np.iinfo(values.dtype).max)
            return np.maximum(values / top, -1.0)
        return values.astype(np.float64)

    def primitive(self, mesh: int, k: int, prim) -> "_Part | None":
        """One primitive's triangles in the mesh's own space (None: points,
        lines, or no POSITION); faces in index order, strips and fans
        triangulated as the glTF specification numbers them."""
        where = f"meshes[{mesh}].primitives[{k}]"
        if not isinstance(prim, dict):
            raise _GltfError(f"{where} is not an object")
        compressed = [e for e in _GLTF_COMPRESSION if e in (prim.get("extensions") or {})]
        if compressed:
            raise _GltfError(f"{where} is compressed with {compressed[0]}, which clrt does not read")
        mode = prim.get("mode", 4)
        if mode in (0, 1, 2, 3):
            return None
        if mode not in (4, 5, 6):
            raise _GltfError(f"{where}: unknown mode {mode!r}")
        attributes = prim.get("attributes")
        if not isinstance(attributes, dict) or "POSITION" not in attributes:
            return None
        vertices = self.floats(attributes["POSITION"], f"{where}.attributes.POSITION", (3,))
        n = len(vertices)
        if "indices" in prim:
            values, _ = self.accessor(prim["indices"], f"{where}.indices", (1,))
            if not np.issubdtype(values.dtype, np.unsignedinteger):
                raise _GltfError(f"{where}.indices are not unsigned integers")
            index = values[:, 0].astype(np.int64)
        else:
            index = np.arange(n, dtype=np.int64)
        if index.size and index.max() >= n:
            raise _GltfError(f"{where}: vertex index {index.max()} past its {n} vertices")
        if mode == 4:
            if len(index) % 3:
                raise _GltfError(f"{where}: {len(index)} triangle indices, not a multiple of 3")
            faces = index.reshape(-1, 3)
        else:
            i = np.arange(max(len(index) - 2, 0))
            if mode == 5:   # strip: (i, i + 1, i + 2), the odd ones as (i, i + 2, i + 1)
                faces = np.stack([index[i], index[i + 1 + i % 2], index[i + 2 - i % 2]], axis=1)
            else:           # fan: (0, i + 1, i + 2)
                faces = np.stack([index[np.zeros_like(i)], index[i + 1], index[i + 2]], axis=1)
        part = _Part(vertices, faces.reshape(-1, 3), srgb_colors=False)   # COLOR_0 is linear
        if "NORMAL" in attributes:
            part.normals = self.floats(attributes["NORMAL"], f"{where}.attributes.NORMAL", (3,))
        texcoord = 0
        if "material" in prim:
            material = self.item("materials", prim["material"], f"{where}.material")
            info = (material.get("pbrMetallicRoughness") or {}).get("baseColorTexture")
            if isinstance(info, dict):
                texcoord = info.get("texCoord", 0)
            part.face_material = np.full(len(part.faces), prim["material"], dtype=np.int64)
        key = f"TEXCOORD_{texcoord}"
        if key in attributes:
            uv = self.floats(attributes[key], f"{where}.attributes.{key}", (2,))
            uv[:, 1] = 1.0 - uv[:, 1]   # glTF's v runs down the image; clrt's (OBJ's) up
            part.uv = uv[part.faces] if len(uv) == n else None
        if "COLOR_0" in attributes:
            colors = self.floats(attributes["COLOR_0"], f"{where}.attributes.COLOR_0", (3, 4))
            part.vertex_colors = np.clip(colors[:, :3], 0.0, 1.0) if len(colors) == n else None
        for name, array in (("NORMAL", part.normals),):
            if array is not None and len(array) != n:
                raise _GltfError(f"{where}.attributes.{name} has {len(array)} elements, POSITION {n}")
        return part

    def image(self, texture_index):
        """The PIL image of a texture; None for one in an extension's format
        only, or an image file that is not there."""
        texture = self.item("textures", texture_index, "texture")
        source = texture.get("source")
        if source is None:
            return None
        image = self.item("images", source, "image")
        if "bufferView" in image:
            view = self.item("bufferViews", image["bufferView"], "bufferView")
            data = self._view_array(image["bufferView"], 0, np.uint8, 1, _gltf_int(
                view.get("byteLength"), "bufferView byteLength"), f"image {source}").tobytes()
        elif "uri" in image:
            data = self.uri(image["uri"], f"image {source}")
        else:
            data = None
        if data is None:
            return None
        from PIL import Image
        try:
            with Image.open(io.BytesIO(data)) as opened:
                opened.load()
                return opened.copy()
        except (OSError, ValueError, Image.DecompressionBombError) as exc:
            raise _GltfError(f"image {source}: cannot read the texture image ({type(exc).__name__})") from None


def _gltf_walk(doc: dict):
    """``(node index, node, world matrix)`` of each node of the file's scene
    (``scene``, else the first; without scenes, every node that is no node's
    child, in file order), depth first in file order: a root node, then its
    children in their ``children`` order, each with its own children before
    the next; a node reached twice (a cycle) is visited once."""
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes", [])
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:
        children = {c for node in nodes for c in node.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    stack = [(int(i), np.eye(4)) for i in reversed(list(roots))]
    seen = set()
    while stack:
        index, parent = stack.pop()
        if index in seen:
            continue
        seen.add(index)
        node = nodes[index]
        world = parent @ _node_matrix(node)
        yield index, node, world
        stack += [(int(c), world) for c in reversed(node.get("children", []))]


def _gltf_parts(data: bytes, file_type: str, path: str) -> "list[_Part]":
    """Every triangle of a glTF file's scene, with its normals, texture
    coordinates, vertex colours and materials.

    Face order: nodes as :func:`_gltf_walk` visits them, in each node's mesh
    its primitives in order, in each primitive its triangles in index order
    (an instanced mesh appears once per node).  Each node's world transform is
    applied; a node whose transform mirrors (negative determinant) has its
    triangles' corners 1 and 2 swapped (and their texture coordinates), so
    that faces still face out, as the glTF specification says.  A primitive
    without NORMAL gets its smooth (area-weighted) normals when another
    primitive of the file has authored ones, which are kept."""
    kind = file_type.upper()
    try:
        doc = _gltf_json(data, "." + file_type)
        if file_type == "glb" and len(data) < struct.unpack_from("<I", data, 8)[0]:
            raise ValueError(f"truncated GLB file (header says {struct.unpack_from('<I', data, 8)[0]} "
                             f"bytes, the file has {len(data)})")
    except Exception as exc:  # noqa: BLE001 -- named in words
        raise _fail(path, f"corrupt or unsupported {kind} file: {_gltf_json_problem(exc)}") from None
    problem = _gltf_reference_problem(doc)
    if problem:
        raise _fail(path, f"corrupt {kind} file: {problem}")
    try:
        gltf = _GltfFile(doc, data, file_type, path)
        with np.errstate(all="ignore"):  # bad numbers are reported by Mesh.from_arrays
            materials = _gltf_materials(gltf)
            cache, parts = {}, []
            for _, node, world in _gltf_walk(doc):
                if "mesh" not in node:
                    continue
                primitives = gltf.item("meshes", node["mesh"], "mesh").get("primitives", [])
                for k, primitive in enumerate(primitives):
                    key = (node["mesh"], k)
                    if key not in cache:
                        cache[key] = gltf.primitive(node["mesh"], k, primitive)
                    if cache[key] is not None and len(cache[key].faces):
                        parts.append(_gltf_placed(cache[key], world, materials))
            if any(p.normals is not None for p in parts):
                for part in parts:
                    if part.normals is None:
                        try:
                            part.normals = Mesh.from_arrays(part.vertices, part.faces).vertex_normals()
                        except MeshLoadError:
                            pass   # _build reports it, naming the file
    except MeshLoadError:
        raise
    except _GltfError as exc:
        raise _fail(path, f"corrupt or unsupported {kind} file: {exc}") from None
    except Exception as exc:  # noqa: BLE001 -- a malformed document (a string where an object belongs, ...)
        raise _fail(path, f"corrupt or unsupported {kind} file ({_short(exc)})") from exc
    if not parts:
        raise _fail(path, "contains no triangles")
    return parts


def _gltf_placed(part: "_Part", world: np.ndarray, materials: list) -> "_Part":
    """A primitive's part in world space (see :func:`_gltf_parts`)."""
    placed = replace(part, materials=materials)
    m = world[:3, :3]
    if not np.array_equal(world, np.eye(4)):
        placed.vertices = part.vertices @ m.T + world[:3, 3]
        if part.normals is not None:
            det = np.linalg.det(m)
            placed.normals = part.normals @ (np.linalg.inv(m) if det != 0 else np.linalg.pinv(m))
    if np.linalg.det(m) < 0:
        placed.faces = part.faces[:, [0, 2, 1]]
        if part.uv is not None:
            placed.uv = part.uv[:, [0, 2, 1]]
    return placed


def _gltf_materials(gltf: "_GltfFile") -> list:
    """Material fields of each glTF material (the table in docs/scene-files.md):
    base colour (factor and texture, with the sampler's wrap modes),
    metallic/roughness to specular, shininess and reflectivity,
    KHR_materials_transmission and KHR_materials_ior to transparency and ior."""
    doc, path = gltf.doc, gltf.path
    textures, out = {}, []
    for i, m in enumerate(doc.get("materials", [])):
        pbr = m.get("pbrMetallicRoughness", {})
        extensions = m.get("extensions", {})
        base = [float(c) for c in pbr.get("baseColorFactor", [1.0] * 4)][:3]
        metallic = min(max(float(pbr.get("metallicFactor", 1.0)), 0.0), 1.0)
        roughness = min(max(float(pbr.get("roughnessFactor", 1.0)), 0.0), 1.0)
        reflectivity = metallic * (1.0 - roughness)
        fields = {"color": tuple(min(max(c, 0.0), 1.0) for c in base),
                  "diffuse": DEFAULT_DIFFUSE * (1.0 - reflectivity),
                  "specular": 1.0 - roughness,
                  # the highlight's width: Blinn-Phong's exponent 2 / alpha^2 - 2 (alpha = roughness^2),
                  # divided by 4 for the Phong (R.V)^n lobe the shader uses, whose angle to the
                  # mirror direction is about twice the half-vector's angle to the normal
                  "shininess": min(max((2.0 / max(roughness ** 4, 1e-6) - 2.0) / 4.0, 1.0), 1000.0),
                  "reflectivity": reflectivity}
        transmission = extensions.get("KHR_materials_transmission", {}).get("transmissionFactor", 0.0)
        if transmission:
            fields["transparency"] = min(max(float(transmission), 0.0), 1.0)
        if "KHR_materials_ior" in extensions:
            fields["ior"] = min(max(float(extensions["KHR_materials_ior"].get("ior", 1.5)), 1.0),
                                MATERIAL_RANGES["ior"][1])
        info = pbr.get("baseColorTexture")
        if isinstance(info, dict):
            texture = gltf.item("textures", info.get("index"), f"materials[{i}] baseColorTexture")
            sampler = texture.get("sampler")
            sampler = gltf.item("samplers", sampler, "sampler") if sampler is not None else {}
            wraps = tuple(_GLTF_WRAPS.get(sampler.get(k, 10497), "repeat") for k in ("wrapS", "wrapT"))
            key = (texture.get("source"), wraps)   # one texture (one copy of its texels) per image and sampler
            if key not in textures:
                image = gltf.image(info.get("index"))
                try:
                    textures[key] = None if image is None else Texture.from_image(
                        image, *wraps, name=f"{os.path.basename(path)} image")
                except InputError as exc:
                    raise _fail(path, str(exc)) from None
            if textures[key] is not None:
                fields["texture"] = textures[key]
        out.append(fields)
    return out


# ---------------------------------------------------------------------------
# Entry point


def _read_any(path: str, label: str) -> bytes:
    """A file a mesh file names (an MTL library): MeshLoadError naming the mesh file if unreadable."""
    try:
        return _read_bytes(path, side_file=True)
    except MeshLoadError as exc:
        raise _fail(label, str(exc)) from None


def _texture(path: str, wrap_s: str, wrap_t: str, label: str) -> Texture:
    """The texture image a mesh file names; MeshLoadError naming the mesh file if it cannot be read."""
    try:
        return Texture.read(path, wrap_s, wrap_t)
    except InputError as exc:
        raise _fail(label, str(exc)) from None


def _read_bytes(path: str, side_file: bool = False, prefix: int | None = None) -> bytes:
    """The file's contents (its first ``prefix`` bytes only, if given);
    MeshLoadError for anything but a readable regular file (a mesh file, unless
    ``side_file``: one that a mesh file names)."""
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
    if ext == ".toml" and not side_file:
        raise _fail(path, "is a scene file, not a mesh (render it with clrt render or clrt.render, "
                          "or read it with clrt.load_scene)")
    if ext not in SUPPORTED_EXTENSIONS and not side_file:
        shown = f"'{ext}'" if ext else "no extension"
        raise _fail(path, f"unknown mesh format ({shown}); supported: "
                          + ", ".join(SUPPORTED_EXTENSIONS))
    try:
        with open(path, "rb") as fh:
            data = fh.read() if prefix is None else fh.read(prefix)
    except PermissionError:
        raise _fail(path, "permission denied") from None
    except OSError as exc:
        raise _fail(path, f"cannot read file ({exc.strerror or _short(exc)})") from None
    if not data.strip() and not side_file:
        raise _fail(path, "file is empty")
    return data


@dataclass
class _Part:
    """One mesh of a file as its parser found it, before checks.

    vertices (V, 3), faces (F, 3) triangles; normals (V, 3); uv (F, 3, 2) per
    corner; colours in 0..1 (each parser scales them by the types the file
    declares, never by their values) of vertices (V, 3) or of polygons (P, 3), sRGB unless
    ``srgb_colors`` is False, with ``polygon_sizes`` (P,) when polygons were
    fan-triangulated (each polygon's colour goes to its triangles);
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


def _build(parts: "list[_Part]", label: str, name: str) -> "tuple[Mesh, list]":
    """Validate the parts and concatenate them into one Mesh; with the file's materials."""
    meshes = []
    for part in parts:
        try:
            mesh = Mesh.from_arrays(part.vertices, part.faces)
            meshes.append(mesh.with_detail(normals=part.normals, uv=part.uv, colors=part.corner_colors(),
                                           face_material=part.face_material))
        except MeshLoadError as exc:
            raise _fail(label, str(exc)) from None
    mesh = meshes[0] if len(meshes) == 1 else Mesh.concatenate(meshes)
    return replace(mesh, name=name), parts[0].materials


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
    folder (a missing one is skipped: the faces keep the default material)."""
    try:
        path = os.fspath(path)
    except TypeError:
        raise MeshLoadError(f"a mesh file's path must be a str or os.PathLike, got {type(path).__name__}") from None
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    data = _read_bytes(path)
    ext = os.path.splitext(path)[1].lower()
    name = os.path.splitext(os.path.basename(path))[0]
    try:
        if ext == ".3ds":
            return load_3ds.parse_3ds(data, label=path, name=name), []
        if ext == ".off":
            parts = [_parse_off(data, path)]
        elif ext == ".obj":
            parts = [_parse_obj(data, path, os.path.dirname(os.path.abspath(path)))]
        elif ext == ".ply":
            parts = [_load_ply(data, path)]
        elif ext == ".stl":
            parts = _load_trimesh(_stl_checked(data, path), "stl", path)
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
        if len(data) < 20 + length:
            raise ValueError(f"truncated GLB file (its JSON chunk is {length} bytes, the file holds "
                             f"{len(data) - 20} after the header)")
        data = data[20:20 + length]
    return json.loads(data.decode("utf-8"))


def _gltf_json_problem(exc: Exception) -> str:
    """What :func:`_gltf_json` found wrong, in words."""
    import json
    if isinstance(exc, json.JSONDecodeError):
        return f"invalid JSON ({exc})"
    if isinstance(exc, UnicodeDecodeError):
        return f"its JSON is not UTF-8 text (byte {exc.start})"
    if isinstance(exc, ValueError):   # ours: "not a GLB file", "truncated GLB file ..."
        return str(exc)
    return _short(exc)


# glTF objects that index others: (list, key, the list indexed).  Cameras are
# file_camera's concern: a broken one does not stop the mesh from loading.
_GLTF_REFERENCES = (("accessors", "bufferView", "bufferViews"), ("bufferViews", "buffer", "buffers"),
                    ("nodes", "mesh", "meshes"))


def _gltf_reference_problem(doc) -> str | None:
    """The first index in a glTF document that points past its list (an accessor
    that does not exist, ...), as ``'meshes[0].primitives[0].attributes.POSITION:
    accessor 7 does not exist (the file has 2)'``; None when all are in range.
    trimesh would fail on one with an internal error (UnboundLocalError, KeyError)."""
    if not isinstance(doc, dict):
        return f"the JSON is {type(doc).__name__}, not an object"

    def check(where: str, index, kind: str):
        items = doc.get(kind, [])
        n = len(items) if isinstance(items, list) else 0
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < n:
            what = kind[:-1] if kind != "meshes" else "mesh"
            return f"{where}: {what} {json_text(index)} does not exist (the file has {n})"
        return None

    def json_text(value):
        import json
        text = json.dumps(value)
        return text if len(text) <= 40 else text[:37] + "..."

    def listed(kind: str):
        items = doc.get(kind, [])
        return [(i, v) for i, v in enumerate(items) if isinstance(v, dict)] if isinstance(items, list) else []

    for i, mesh in listed("meshes"):
        primitives = mesh.get("primitives", [])
        for j, primitive in enumerate(primitives if isinstance(primitives, list) else []):
            if not isinstance(primitive, dict):
                continue
            where = f"meshes[{i}].primitives[{j}]"
            attributes = primitive.get("attributes", {})
            refs = [(f"{where}.attributes.{k}", v) for k, v in attributes.items()] if isinstance(attributes, dict) else []
            if "indices" in primitive:
                refs.append((f"{where}.indices", primitive["indices"]))
            for path, index in refs:
                problem = check(path, index, "accessors")
                if problem:
                    return problem
    for kind, key, target in _GLTF_REFERENCES:
        for i, item in listed(kind):
            if key in item:
                problem = check(f"{kind}[{i}].{key}", item[key], target)
                if problem:
                    return problem
    for kind, key in (("nodes", "children"), ("scenes", "nodes")):   # lists of node indices
        for i, item in listed(kind):
            nodes = item.get(key, [])
            for k, node in enumerate(nodes if isinstance(nodes, list) else []):
                problem = check(f"{kind}[{i}].{key}[{k}]", node, "nodes")
                if problem:
                    return problem
    if "scene" in doc:
        return check("scene", doc["scene"], "scenes")
    return None


def _glb_json_bytes(path: str) -> bytes:
    """A GLB file's header and JSON chunk, without its binary chunk: the
    camera is read after the mesh, and the buffers need not be read twice."""
    import struct
    head = _read_bytes(path, prefix=20)
    if len(head) < 20 or head[:4] != b"glTF":
        return head                          # _gltf_json says what is wrong
    return _read_bytes(path, prefix=20 + struct.unpack_from("<I", head, 12)[0])


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
        doc = _gltf_json(_glb_json_bytes(path) if ext == ".glb" else _read_bytes(path), ext)
        cameras = doc.get("cameras", [])
        for _, node, world in _gltf_walk(doc):   # depth first, in file order
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
        mesh = Mesh.from_arrays(source.vertices, source.faces)
        if hasattr(source, "visual"):   # a trimesh.Trimesh: its UVs and (sRGB) colours
            part = _trimesh_part(source, linear_colors=False)
            mesh = mesh.with_detail(uv=part.uv, colors=part.corner_colors())
        return mesh
    if isinstance(source, (tuple, list)) and len(source) == 2:
        return Mesh.from_arrays(*source)
    if type(source).__name__ == "Scene" and hasattr(source, "dump"):   # trimesh.load("x.glb") gives one
        raise InputError("expected a mesh, got a trimesh.Scene: pass the file's path instead (clrt reads its "
                         "nodes and materials), or scene.dump(concatenate=True)")
    raise InputError(f"expected a mesh (a clrt.Mesh, a file path, a trimesh object or (vertices, faces)), "
                     f"got {type(source).__name__}")


# trimesh logs warnings with tracebacks (e.g. for a corrupt ASCII STL) while we
# report the failure ourselves; without any handler configured Python's
# last-resort handler would print them to stderr.  A NullHandler stops that and
# still lets an application that configures logging see them.
if not any(isinstance(h, logging.NullHandler) for h in logging.getLogger("trimesh").handlers):
    logging.getLogger("trimesh").addHandler(logging.NullHandler())

