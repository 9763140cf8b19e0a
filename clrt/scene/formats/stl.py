"""STL (stereolithography), binary and ASCII, read by trimesh.

Only triangles are read (no colours: the binary format's attribute bytes have
no agreed meaning); an ASCII file of several solids gives one object each.
Before trimesh sees the bytes, :func:`_stl_checked` decides which kind of
STL they are and refuses a binary file whose length disagrees with its
triangle count, which trimesh would misreport.
"""

from __future__ import annotations

import struct

from clrt.scene.formats.part import build, fail
from clrt.scene.formats.trimesh_objects import read_with_trimesh
from clrt.scene.mesh import Mesh


def read(data: bytes, path: str, name: str) -> "tuple[Mesh, list]":
    """The mesh of an STL file's bytes (no materials)."""
    return build(read_with_trimesh(_stl_checked(data, path), "stl", path), path, name)


_STL_HEADER, _STL_TRIANGLE = 84, 50   # binary STL: 80-byte header and a uint32 count; 50 bytes a triangle


def _stl_checked(data: bytes, label: str) -> bytes:
    """The STL file's bytes for trimesh, once its kind is clear: a binary STL must
    be exactly as long as its header's triangle count says (else trimesh falls
    back to its ASCII reader, whose error hides the real problem); an ASCII STL
    starts with 'solid' and holds no NUL byte, and goes to trimesh as UTF-8
    (its own decoding of other text needs an optional package)."""
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
        raise fail(label, f"not an STL file ({len(data)} bytes: too short for a binary STL's "
                          f"{_STL_HEADER}-byte header, and not ASCII STL, which starts with 'solid')")
    room = (len(data) - _STL_HEADER) // _STL_TRIANGLE
    if len(data) < _STL_HEADER + _STL_TRIANGLE * count:
        raise fail(label, f"truncated binary STL (header says {count} triangles, the file holds room for {room})")
    raise fail(label, f"binary STL longer than its header says (header says {count} triangles, the file "
                      f"holds room for {room}{' and some bytes' if (len(data) - _STL_HEADER) % _STL_TRIANGLE else ''})")
