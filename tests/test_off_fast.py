"""The OFF reader's fast path (clrt.scene.formats.off._off_plain) against its general path.

Every file here is read both ways: where the fast path takes a file, its arrays
must equal the general path's bit for bit; where it declines (None), the file
must be one the general path reads differently (polygons, colours) or refuses,
and the loader's answer -- arrays or error message -- must be the general path's.
"""

from pathlib import Path

import numpy as np
import pytest

from clrt.errors import MeshLoadError
from clrt.scene.formats import off
from clrt.scene.load import load_mesh

SHARED_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"


def outcome(parse, data: bytes):
    """('ok', vertices, faces, colours...) or ('error', message) of one parser."""
    try:
        part = parse(data, "m.off")
    except MeshLoadError as exc:
        return ("error", str(exc))
    extras = [part.vertex_colors, part.face_colors, part.polygon_sizes]
    return ("ok", part.vertices, part.faces, *extras)


def assert_same(a, b):
    assert a[0] == b[0], (a, b)
    if a[0] == "error":
        assert a[1] == b[1]
        return
    for x, y in zip(a[1:], b[1:]):
        if x is None or y is None:
            assert x is None and y is None
        else:
            x, y = np.asarray(x), np.asarray(y)
            assert x.dtype == y.dtype and x.shape == y.shape
            assert x.tobytes() == y.tobytes()   # bit for bit: -0.0, NaN payloads


def both_paths(data: bytes):
    """The loader's outcome and the general path's, asserted equal; and the fast path's verdict."""
    general = outcome(off._parse_off_lines, data)
    assert_same(outcome(off._parse_off, data), general)
    return off._off_plain(data) is not None, general


def off_text(vertices, faces, header="OFF\n{v} {f} 0\n", vsep=" ", eol="\n") -> str:
    text = header.format(v=len(vertices), f=len(faces))
    text += "".join(vsep.join(repr(float(c)) for c in v) + eol for v in vertices)
    text += "".join("3" + vsep + vsep.join(str(i) for i in f) + eol for f in faces)
    return text


def random_mesh(seed=1, n_vertices=50, n_faces=80):
    rng = np.random.default_rng(seed)
    vertices = rng.normal(size=(n_vertices, 3)) * 10.0 ** rng.integers(-6, 6, size=(n_vertices, 1))
    faces = rng.integers(0, n_vertices, size=(n_faces, 3))
    return vertices, faces


@pytest.mark.parametrize("name", sorted(p.name for p in SHARED_MESHES.glob("*.off")) or ["(none)"])
def test_shared_meshes_take_the_fast_path(name):
    if not SHARED_MESHES.is_dir():
        pytest.skip(f"shared meshes not present at {SHARED_MESHES}")
    fast, general = both_paths((SHARED_MESHES / name).read_bytes())
    assert fast and general[0] == "ok"


V, F = random_mesh()
PLAIN = off_text(V, F)
FAST_VARIANTS = {
    "plain": PLAIN,
    "header comment": "# made by hand\n" + PLAIN,
    "comments after values": PLAIN.replace("\n", "   # note\n"),
    "comment on the keyword line": PLAIN.replace("OFF\n", "OFF # keyword\n", 1),
    "blank lines after header, between parts and at the end":
        off_text(V, [], header="OFF\n{v} %d 0\n\n \n" % len(F)) + "\n\t\n"
        + off_text([], F, header="") + "\n\n  \n",
    "crlf": off_text(V, F, eol="\r\n", header="OFF\r\n{v} {f} 0\r\n"),
    "tabs and runs of spaces": off_text(V, F, vsep=" \t  "),
    "leading and trailing spaces": PLAIN.replace("\n", "  \n").replace("\n", "\n   "),
    "counts on the keyword line": off_text(V, F, header="OFF {v} {f} 0\n"),
    "two counts": off_text(V, F, header="OFF\n{v} {f}\n"),
    "no final line break": PLAIN.rstrip("\n"),
    "byte order mark": "\ufeff" + PLAIN,
    "COFF without colours": "C" + PLAIN,
    "number forms": off_text([[1e-3, -0.0, 5.0]] * 3, [[0, 1, 2]]).replace("0.001", "1E-3")
    .replace("5.0", "+5."),
    "nan and inf": off_text([[float("nan"), float("inf"), 0]] * 3, [[0, 1, 2]]),
    "leading zeros in indices": off_text(V, F).replace(" 1", " 001"),
    "face index out of range": off_text(V[:3], [[0, 1, 3]]),
    "negative face index": off_text(V[:3], [[0, 1, -1]]),
}


@pytest.mark.parametrize("name", FAST_VARIANTS)
def test_fast_path_equals_general_path(name):
    data = FAST_VARIANTS[name].encode("utf-8" if name == "byte order mark" else "latin-1")
    fast, general = both_paths(data)
    assert fast, "the fast path should read this file"
    assert general[0] == "ok"


def test_fast_path_on_the_loaded_mesh(tmp_path):
    """Through load_mesh: the same Mesh, and Mesh.from_arrays's errors for bad values."""
    path = tmp_path / "a.off"
    path.write_text(PLAIN)
    mesh = load_mesh(path)
    np.testing.assert_array_equal(mesh.faces, F)
    np.testing.assert_array_equal(mesh.vertices, V.astype(np.float32))
    path.write_text(FAST_VARIANTS["face index out of range"])
    with pytest.raises(MeshLoadError, match="out of range"):
        load_mesh(path)


QUAD = "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n"
GENERAL_VARIANTS = {
    # read by the general path only, with results the fast path does not produce
    "polygon": QUAD,
    "face colours": PLAIN.split("\n3 ")[0] + "".join(f"\n3 {a} {b} {c} 255 0 0" for a, b, c in F) + "\n",
    "vertex colours": "COFF\n3 1 0\n0 0 0 1 0 0\n1 0 0 0 1 0\n0 1 0 0 0 1\n3 0 1 2\n",
    "normals": "NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n",
    "comment line between vertices": PLAIN.replace("\n", "\n# vertex\n", 5),
    "blank line between vertices": PLAIN.replace("\n", "\n\n", 5),
    "trailing lines after the faces": PLAIN + "3 0 1 2\nanything\n",
    "lone carriage returns": PLAIN.replace("\n", "\r"),
    "form feed as a line break": PLAIN.replace("\n", "\x0c"),
    "next line (0x85) as a line break": PLAIN.replace("\n", "\x85"),
    "counts line with a word": off_text(V, F, header="OFF\n{v} {f} edges\n"),
    # broken: the general path's message
    "vertex with two coordinates": PLAIN.replace(f"\n{repr(float(V[1][0]))} ", "\n", 1),
    "vertex with two, the next with four": "OFF\n2 1 0\n0 0\n0 1 0 0\n3 0 1 1\n",
    "face of 2 values for 3 corners": "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n",
    "faces ragged but 4 values a line on average": "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n3 0 1 2 2\n",
    "face count 2": "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1 2\n",
    "float face index": "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2.0\n",
    "huge face index": "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 99999999999999999999\n",
    "malformed coordinate": "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 x\n3 0 1 2\n",
    "truncated": PLAIN[:len(PLAIN) // 2],
    "huge counts": "OFF\n1000000000000 1000000000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    "no faces": "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n",
    "no vertices": "OFF\n0 1 0\n3 0 1 2\n",
    "binary": "OFF BINARY\n3 1 0\n",
    "other dimension": "4OFF\n3 1 0\n0 0 0 0\n1 0 0 0\n0 1 0 0\n3 0 1 2\n",
    "not OFF": "PLY\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    "keyword glued to counts": "OFF3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    "only comments": "# nothing\n\n",
    "negative count": "OFF\n-3 1 0\n0 0 0\n",
}


@pytest.mark.parametrize("name", GENERAL_VARIANTS)
def test_general_path_answers_the_rest(name):
    fast, general = both_paths(GENERAL_VARIANTS[name].encode("latin-1"))
    assert not fast, "the fast path must leave this file to the general path"


def test_random_mutations_read_as_the_general_path_reads_them():
    """Small edits of plain files: whatever either path makes of them, the loader's
    answer is the general path's, and the fast path still reads many of them."""
    rng = np.random.default_rng(20260401)
    alphabet = list(b"0123456789 \n\r\t#.-+eE3") + [0x0B, 0x0C, 0x1C, 0x85, 0xA0, 0x00]
    taken = declined = 0
    for case in range(600):
        v, f = random_mesh(seed=case, n_vertices=6, n_faces=5)
        text = off_text(v, f, vsep=" " if case % 2 else "  ", header="OFF\n{v} {f} 0\n" if case % 3
                        else "OFF {v} {f} 0\n\n")
        data = bytearray(text.encode())
        for _ in range(rng.integers(0, 3)):
            position = int(rng.integers(len(data)))
            action = rng.integers(3)
            if action == 0:
                data[position] = alphabet[rng.integers(len(alphabet))]
            elif action == 1:
                del data[position]
            else:
                data.insert(position, alphabet[rng.integers(len(alphabet))])
        fast, _ = both_paths(bytes(data))
        taken += fast
        declined += not fast
    assert taken > 100 and declined > 100, (taken, declined)
