"""PLY (the Stanford polygon format): ASCII and binary, either byte order.

Read: the ``vertex`` element's x, y, z and, when present, normals (nx, ny,
nz), colours (red, green, blue, scaled to 0..1 by their declared types) and
texture coordinates (texture_u/v, u/v or s/t); the ``face`` element's vertex
index list (``vertex_indices`` or ``vertex_index``, else its first list;
polygons of any size, triangulated in place) and face colours.  Other
elements and properties are skipped; a texture image named in the header is
not opened.

ASCII PLY is parsed here: trimesh (5.2.0 checked) silently drops a truncated
last face.  Binary PLY goes to trimesh's parser (:func:`_load_ply` says why
and when not).
"""

from __future__ import annotations

import io
import re
import struct

import numpy as np

from clrt.errors import MeshLoadError
from clrt.scene.formats.part import Part, build, fail, short
from clrt.scene.formats.text import decode, nonblank_lines, polygons, table
from clrt.scene.formats.triangulate import triangulate
from clrt.scene.mesh import Mesh


def read(data: bytes, path: str, name: str) -> "tuple[Mesh, list]":
    """The mesh of a PLY file's bytes (no materials)."""
    return build([_load_ply(data, path)], path, name)


def _ply_header(data: bytes, label: str):
    """``(format, elements, body_offset)`` of a PLY header.

    ``elements`` is a list of ``(name, count, properties)`` in file order, each
    property a ``(name, is_list, types)`` triple: ``types`` is ``(type,)`` for a
    scalar, ``(count type, item type)`` for a list, as the header names them.
    """
    marker = re.search(rb"end_header[ \t]*\r?\n", data)
    if not data.startswith(b"ply") or marker is None:
        raise fail(label, "not a PLY file (missing 'ply' or 'end_header')")
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
                raise fail(label, f"malformed PLY header line '{line.strip()}'") from None
            if count < 0:
                raise fail(label, f"negative element count in '{line.strip()}'")
            elements.append((words[1], count, []))
        elif words[0] == "property" and elements and len(words) in (3, 5):
            is_list = words[1] == "list"
            elements[-1][2].append((words[-1], is_list, tuple(words[2:4]) if is_list else (words[1],)))
        else:
            raise fail(label, f"malformed PLY header line '{line.strip()[:40]}'")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise fail(label, f"unknown PLY format {fmt!r}")
    return fmt, elements, marker.end()


def _ply_vertices(lines: "list[str]", props, label: str) -> dict:
    """``{property: (n,) float64 column}`` of ASCII PLY vertex rows (x, y, z at least)."""
    names = [p[0] for p in props]
    if any(p[1] for p in props) or not {"x", "y", "z"} <= set(names):
        raise fail(label, "PLY vertex element needs scalar x, y, z properties")
    values = table(lines, np.float64)
    if values is None or values.shape[1] != len(props):
        for number, line in enumerate(lines, 1):
            if len(line.split()) != len(props):
                raise fail(label, f"vertex {number} has {len(line.split())} values, "
                                  f"expected {len(props)}")
        raise fail(label, "malformed number in vertex data")
    return dict(zip(names, values.T))


def _ply_faces(lines: "list[str]", props, label: str):
    """``(counts (P,) int64, flat corner indices, {scalar property: (P,) column})``
    of ASCII PLY face rows, in row order."""
    lists = [name for name, is_list, _ in props if is_list]
    target = next((p for p in ("vertex_indices", "vertex_index") if p in lists),
                  lists[0] if lists else None)
    if target is None:
        raise fail(label, "PLY face element has no vertex index list")
    if len(props) == 1:
        return (*polygons(lines, label, counted=True, exact=True), {})
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
                        raise fail(label, f"face {number} has {n} corners (needs at least 3)")
                    flat.extend(tokens[pos + 1:pos + 1 + n])
                    counts.append(n)
                elif not is_list:
                    scalars[name].append(float(tokens[pos]))
                pos += 1 + n
            if pos != len(tokens):
                raise fail(label, f"face {number} has {len(tokens)} values, expected {pos}")
        indices = np.array(flat, dtype=np.int64)
    except (ValueError, IndexError, OverflowError) as exc:
        raise fail(label, f"malformed face data ({short(exc)})") from None
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
              normals=None) -> Part:
    """A part from PLY vertex and face property columns: normals (nx, ny, nz),
    colours (red, green, blue, of vertices or else of faces, scaled to 0..1 by
    their declared types) and texture coordinates (texture_u/v, u/v or s/t, per
    vertex).  ``types``: :func:`_ply_types` of the header."""
    vertices = np.stack([vertex[a] for a in "xyz"], axis=1)
    part = Part(vertices, triangulate(counts, flat, vertices))
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
    lines = nonblank_lines(decode(data[body:]))
    declared = sum(count for _, count, _ in elements)
    # Checked before touching any row so that absurd counts fail at once.
    if declared > len(lines):
        raise fail(label, f"truncated: header declares {declared} rows, "
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
        raise fail(label, "contains no triangles")
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
            raise fail(label, f"PLY list {name!r} has a non-integer count type {types[0]!r}")
        layout.append((name, is_list, struct.Struct(order + codes[0]), codes[-1]))
    scalars = {name: [] for name, is_list, _ in props if not is_list}
    counts, flat, cache = [], [], {}
    smallest = sum(s.size for _, _, s, _ in layout)
    if count * smallest > len(data) - pos:
        raise fail(label, f"truncated: header declares {count} rows of at least {smallest} bytes, "
                          f"only {len(data) - pos} bytes follow")
    for number in range(1, count + 1):
        for name, is_list, head, code in layout:
            if pos + head.size > len(data):
                raise fail(label, f"truncated binary PLY (row {number} of {count})")
            value = head.unpack_from(data, pos)[0]
            pos += head.size
            if not is_list:
                scalars[name].append(value)
                continue
            if name == target and value < 3:
                raise fail(label, f"face {number} has {value} corners (needs at least 3)")
            if value < 0:
                raise fail(label, f"row {number} of {count} has a list of {value} items")
            items = cache.get((value, code))
            if items is None:
                items = cache[value, code] = struct.Struct(f"{order}{value}{code}")
            if pos + items.size > len(data):
                raise fail(label, f"truncated binary PLY (row {number} of {count}: a list of {value} items)")
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
        raise fail(label, f"unknown PLY property type {type_name!r}")
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


def _parse_ply_binary(data: bytes, fmt: str, elements, body: int, label: str) -> Part:
    """A binary PLY body read here, for what trimesh's reader refuses: faces of
    mixed sizes (it takes every face's corner count from the first face).
    Elements without lists are read at once; the others row by row, so this is
    the slower reader, used only when trimesh's fails on the file's length."""
    order = "<" if fmt == "binary_little_endian" else ">"
    pos, vertex, faces = body, None, None
    for name, count, props in elements:
        if name == "vertex" and (any(p[1] for p in props) or not {"x", "y", "z"} <= {p[0] for p in props}):
            raise fail(label, "PLY vertex element needs scalar x, y, z properties")
        if any(p[1] for p in props):
            columns, pos, target = _ply_binary_rows(data, pos, count, props, order, label)
            if name == "face":
                faces = (*columns.pop(target), columns)
            continue
        dtype = np.dtype([(f"p{i}", _ply_dtype(p[2][0], label).newbyteorder(order)) for i, p in enumerate(props)])
        if count * dtype.itemsize > len(data) - pos:
            raise fail(label, f"truncated: header declares {count} {name} rows of {dtype.itemsize} bytes, "
                              f"only {len(data) - pos} bytes follow")
        table = np.frombuffer(data, dtype, count, pos)
        pos += count * dtype.itemsize
        if name == "vertex":
            vertex = {p[0]: table[f"p{i}"].astype(np.float64) for i, p in enumerate(props)}
    if pos != len(data):
        raise fail(label, f"binary PLY longer than its header says ({len(data) - pos} bytes after the last element)")
    if vertex is None or faces is None or len(faces[0]) == 0:
        raise fail(label, "contains no triangles")
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
            raise fail(label, "contains no triangles")
        faces = np.asarray(faces)
        if faces.ndim != 2 or faces.shape[1] < 3 or faces.dtype == object:
            raise fail(label, f"unexpected face array of shape {faces.shape}")
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
        raise fail(label, f"corrupt or unsupported PLY file ({short(exc)})") from exc
