"""OFF (Geomview's Object File Format), ASCII only.

Read: the ``[ST][C][N]OFF`` header keywords (binary OFF, ``4OFF`` and ``nOFF``
are refused by name), the counts on the keyword's line or the next, ``#``
comments, polygons of any size (triangulated in place), vertex colours
(``C``: r g b [a] after x y z [nx ny nz]) and face colours (r g b after a
face's corners), integers as 0..255 and floats as 0..1.  Normals and texture
coordinates of ``N``/``ST`` files are skipped.

Parsed here rather than by trimesh (5.2.0 checked), whose OFF reader crashes
on any face with more than four corners.  The common file (triangles, bare
vertices) takes a fast path, :func:`_off_plain`.
"""

from __future__ import annotations

import re

import numpy as np

from clrt.scene.formats.part import Part, build, fail
from clrt.scene.formats.text import decode, loadtxt, nonblank_lines, polygons, table, xyz
from clrt.scene.formats.triangulate import triangulate
from clrt.scene.mesh import Mesh

# OFF header keywords: [ST][C][N]OFF.  "4OFF"/"nOFF" (other dimensions) and
# "OFF BINARY" are rejected explicitly rather than misparsed.
_OFF_KEYWORD = re.compile(r"(ST)?C?N?OFF")
# The usual OFF header: keyword, then the vertex, face (and edge) counts on its
# line or the next, ending in a line break; with the blank lines after it.
# Anything else takes the general path.
_OFF_PLAIN_HEAD = re.compile(rb"\s*(?:ST)?C?N?OFF(?:[ \t]*\r?\n\s*|[ \t]+)"
                             rb"([0-9]+)[ \t]+([0-9]+)(?:[ \t]+[0-9]+)?[ \t]*\r?\n\s*")
# Line breaks of str.splitlines that np.loadtxt reads as spaces or text.
_OTHER_LINE_BREAKS = (b"\v", b"\f", b"\x1c", b"\x1d", b"\x1e", b"\x85")


def read(data: bytes, path: str, name: str) -> "tuple[Mesh, list]":
    """The mesh of an OFF file's bytes (no materials)."""
    return build([_parse_off(data, path)], path, name)


def _off_plain(data: bytes) -> "Part | None":
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
    vertices = loadtxt(body[:cut].decode("latin-1"), np.float64)
    if vertices is None or vertices.shape != (n_vertices, 3):
        return None
    faces = loadtxt(body[cut:].decode("latin-1"), np.int64)
    if faces is None or faces.shape != (n_faces, 4) or (faces[:, 0] != 3).any():
        return None
    return Part(vertices, np.ascontiguousarray(faces[:, 1:]))


def _parse_off(data: bytes, label: str) -> Part:
    """Geometry and colours (vertex colours of COFF, face colours) of an ASCII OFF file."""
    part = _off_plain(data)
    return part if part is not None else _parse_off_lines(data, label)


def _parse_off_lines(data: bytes, label: str) -> Part:
    """:func:`_parse_off` for every OFF file: polygons, colours, odd layouts, and
    the error message of a broken file."""
    lines = nonblank_lines(decode(data))
    if not lines:
        raise fail(label, "file contains only comments or blank lines")
    head = lines[0].split()
    if len(head) > 1 and head[1].upper() == "BINARY":
        raise fail(label, "binary OFF is not supported")
    if not _OFF_KEYWORD.fullmatch(head[0]):
        if re.fullmatch(r"\S*OFF", head[0]):
            raise fail(label, f"unsupported OFF variant '{head[0]}'")
        raise fail(label, "not an OFF file (first line must start with 'OFF')")
    # The counts may share the keyword's line ("OFF 8 6 0") or follow it.
    if len(head) > 1:
        counts, body = head[1:], 1
    else:
        counts, body = (lines[1].split() if len(lines) > 1 else []), 2
    if len(counts) < 2:
        raise fail(label, "missing vertex/face count line")
    try:
        n_vertices, n_faces = int(counts[0]), int(counts[1])
    except ValueError:
        raise fail(label, f"malformed count line '{' '.join(counts[:3])}'") from None
    if n_vertices < 0 or n_faces < 0:
        raise fail(label, f"negative count in header ({n_vertices} vertices, {n_faces} faces)")
    # Check the header against the file before allocating anything, so that a
    # 100-byte file claiming 10^12 vertices fails at once.
    available = len(lines) - body
    if n_vertices + n_faces > available:
        raise fail(label, f"truncated: header declares {n_vertices} vertices and {n_faces} "
                          f"faces but only {available} data lines follow")
    if n_faces == 0:
        raise fail(label, "contains no triangles (0 faces)")
    vertex_lines = lines[body:body + n_vertices]
    vertices = xyz(vertex_lines, label)
    face_lines = lines[body + n_vertices:body + n_vertices + n_faces]
    counts, flat = polygons(face_lines, label, counted=True)
    part = Part(vertices, triangulate(counts, flat, vertices))
    # Colours: r g b [a] of each vertex (C prefix) or after a face's corners,
    # used only when every row has them.  A vertex line is, in Geomview's
    # order, x y z [nx ny nz (N)] [r g b a (C)] [s t (ST)].
    if "C" in head[0]:
        values = table(vertex_lines, np.float64)
        start = 6 if "N" in head[0] else 3
        size = values.shape[1] - start - (2 if head[0].startswith("ST") else 0) if values is not None else 0
        if size in (3, 4):
            tokens = [line.split()[start:start + 3] for line in vertex_lines]
            part.vertex_colors = _off_colors(values[:, start:start + 3], tokens)
    if len(face_lines[0].split()) >= 4 + counts[0]:   # the first face has a colour: look for all
        colors = [line.split()[1 + n:4 + n] for line, n in zip(face_lines, counts.tolist())]
        if all(len(c) == 3 for c in colors):
            try:
                part.face_colors = _off_colors(np.array(colors, dtype=np.float64), colors)
                part.polygon_sizes = counts
            except ValueError:
                raise fail(label, "malformed face colour") from None
    return part


def _off_colors(values: np.ndarray, tokens: "list[list[str]]") -> np.ndarray:
    """OFF colours in 0..1: Geomview's OFF takes "integers 0..255 or floats
    0..1", so ``values`` are divided by 255 when every one of them is written as
    an integer (``tokens``, their text), whatever their size."""
    text = " ".join(" ".join(t) for t in tokens)
    return values if re.search(r"[^0-9\s+-]", text) else values / 255.0
