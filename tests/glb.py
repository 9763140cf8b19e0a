"""GLB files with their JSON chunk edited: the tests' way to make a glTF that a
writer (trimesh) cannot -- an extension added, a reference broken, a node
cycle -- from one that it writes."""

import json
import struct


def glb_with_json(glb: bytes, edit) -> bytes:
    """The GLB ``glb`` with its JSON chunk's document changed in place by
    ``edit(doc)`` (padded with spaces to 4 bytes, as the format asks); the
    binary chunk after it is kept as it is."""
    (length,) = struct.unpack_from("<I", glb, 12)
    doc = json.loads(glb[20:20 + length])
    edit(doc)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = glb[20 + length:]
    return struct.pack("<4sII", b"glTF", 2, 20 + len(text) + len(rest)) + struct.pack("<I", len(text)) + b"JSON" \
        + text + rest


def edit_glb_file(path, edit, target=None):
    """``path``'s GLB with ``edit(doc)`` applied to its JSON, written to
    ``target`` (default: ``path`` itself); returns where it was written."""
    target = path if target is None else target
    target.write_bytes(glb_with_json(path.read_bytes(), edit))
    return target
