"""Mesh file loading: every format, face order, triangulation, and hostile input.

All files are generated in ``tmp_path``; only ``test_shared_cow_3ds_matches_off``
needs ``../shared/meshes`` and skips without it.
"""

import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

from glb import glb_with_json

from clrt.errors import MeshLoadError, MeshLoadWarning
from clrt.scene import load as load_module
from clrt.scene.formats import part as part_module
from clrt.scene.formats.tds import encode_3ds, parse_3ds, write_3ds
from clrt.scene.load import READERS, SUPPORTED_EXTENSIONS, load_asset, load_mesh
from clrt.scene.mesh import Mesh

SHARED_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"

TETRA_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def tetra(name="tetra", offset=(0.0, 0.0, 0.0)) -> Mesh:
    return Mesh.from_arrays(TETRA_V + offset, TETRA_F, name)


def triangles(mesh: Mesh) -> np.ndarray:
    """(F, 3, 3) corner coordinates: compares meshes independent of vertex numbering."""
    return mesh.vertices[mesh.faces].astype(np.float64)


def write(tmp_path, name, data) -> Path:
    path = tmp_path / name
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def assert_one_line_error(path, *fragments):
    """load_mesh(path) raises MeshLoadError with a one-line message naming the file."""
    with pytest.raises(MeshLoadError) as info:
        load_mesh(path)
    message = str(info.value)
    assert "\n" not in message
    assert str(path) in message
    for fragment in fragments:
        assert fragment in message, message
    return message


# ---------------------------------------------------------------------------
# Formats


def test_obj_keeps_face_order_across_materials(tmp_path):
    # trimesh would emit the usemtl sections in reverse order.
    text = """mtllib /nonexistent/materials.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vn 0 0 1
usemtl a
f 1/1/1 2/1/1 3/1/1
usemtl b
f 1//1 3//1 4//1
usemtl a
f 2 3 4 # trailing comment
"""
    with pytest.warns(MeshLoadWarning, match="/nonexistent/materials.mtl not found"):
        mesh = load_mesh(write(tmp_path, "order.obj", text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 2, 3]]
    assert mesh.vertices.dtype == np.float32 and mesh.faces.dtype == np.int32
    assert mesh.name == "order"


def test_obj_polygons_fan_triangulated_in_place(tmp_path):
    corners = [(0, 0), (1, 0), (1, 1), (0, 1), (2, 0), (2, 1), (3, 0.5)]
    text = "\n".join(f"v {x} {y} 0" for x, y in corners)
    text += "\nf 1 2 3 4\nf 2 5 6\nf 2 5 7 6 3\n"
    mesh = load_mesh(write(tmp_path, "quads.obj", text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 5],
                                   [1, 4, 6], [1, 6, 5], [1, 5, 2]]


def test_obj_only_quads_fan_triangulated_in_place(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nf 1 2 3 4\nf 2 3 6 5\n"
    mesh = load_mesh(write(tmp_path, "q.obj", text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 2, 5], [1, 5, 4]]


def test_obj_negative_indices_are_relative(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 0 0 1\nf -4 -1 -3\n"
    mesh = load_mesh(write(tmp_path, "rel.obj", text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 3, 1]]


def test_off_polygons_colours_and_comments(tmp_path):
    text = """# a comment before the header
COFF
7 3 0
0 0 0 255 0 0 255
1 0 0 255 0 0 255
1 1 0 255 0 0 255
0 1 0 255 0 0 255   # comment
2 0 0 255 0 0 255
2 1 0 255 0 0 255
3 0.5 0 255 0 0 255
4 0 1 2 3 0.5 0.5 0.5
3 1 4 5
5 1 4 6 5 2
"""
    mesh = load_mesh(write(tmp_path, "poly.off", text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 5],
                                   [1, 4, 6], [1, 6, 5], [1, 5, 2]]
    assert mesh.vertices.tolist()[6] == [3.0, 0.5, 0.0]


def test_off_counts_on_header_line_and_upper_case_extension(tmp_path):
    text = "OFF 4 4 6\n" + "\n".join(" ".join(map(str, v)) for v in TETRA_V) + "\n"
    text += "\n".join("3 " + " ".join(map(str, f)) for f in TETRA_F) + "\n"
    mesh = load_mesh(write(tmp_path, "T.OFF", text))
    np.testing.assert_array_equal(mesh.faces, TETRA_F)
    np.testing.assert_array_equal(mesh.vertices, TETRA_V)


@pytest.mark.parametrize("encoding", ["ascii", "binary"])
def test_ply_round_trip(tmp_path, encoding):
    source = trimesh.Trimesh(TETRA_V, TETRA_F, process=False)
    path = write(tmp_path, "t.ply", source.export(file_type="ply", encoding=encoding))
    mesh = load_mesh(path)
    np.testing.assert_array_equal(mesh.faces, TETRA_F)
    np.testing.assert_allclose(mesh.vertices, TETRA_V)


def test_ply_quads_fan_triangulated_in_place(tmp_path):
    text = """ply
format ascii 1.0
element vertex 6
property float x
property float y
property float z
element face 2
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
1 0 1
4 0 1 2 3
4 1 2 5 4
"""
    mesh = load_mesh(write(tmp_path, "q.ply", text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 2, 5], [1, 5, 4]]


def test_ply_mixed_polygons_and_extra_properties(tmp_path):
    text = """ply
format ascii 1.0
comment mixed polygon sizes, a colour per face, an edge element
element vertex 7
property float x
property float y
property float z
property uchar red
element face 3
property list uchar int vertex_indices
property uchar red
element edge 1
property int vertex1
property int vertex2
end_header
0 0 0 1
1 0 0 1
1 1 0 1
0 1 0 1
2 0 0 1
2 1 0 1
3 0.5 0 1
4 0 1 2 3 9
3 1 4 5 9
5 1 4 6 5 2 9
0 1
"""
    mesh = load_mesh(write(tmp_path, "mixed.ply", text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 5],
                                   [1, 4, 6], [1, 6, 5], [1, 5, 2]]
    assert mesh.vertices.tolist()[6] == [3.0, 0.5, 0.0]


def test_binary_ply_quads_fan_triangulated_in_place(tmp_path):
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 6\n"
              b"property float x\nproperty float y\nproperty float z\nelement face 2\n"
              b"property list uchar int vertex_indices\nend_header\n")
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1]], "<f4")
    faces = b"".join(struct.pack("<B4i", 4, *quad) for quad in [(0, 1, 2, 3), (1, 2, 5, 4)])
    mesh = load_mesh(write(tmp_path, "q.ply", header + vertices.tobytes() + faces))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 2, 5], [1, 5, 4]]


# ---------------------------------------------------------------------------
# Concave polygons: ear clipping where a fan would cover the outside (issue 34)

L_SHAPE = [(2, 0), (2, 1), (1, 1), (1, 2), (0, 2), (0, 0)]   # area 3; the fan from (2, 0) covers 4
DART = [(0, 0), (2, 1), (0, 2), (0.5, 1)]                    # area 1.5; reflex at the last corner
L_CLOCKWISE = [(0, 2), (1, 2), (1, 1), (2, 1), (2, 0), (0, 0)]   # area -3; the fan from (0, 2) covers 4


def triangle_areas(mesh: Mesh) -> np.ndarray:
    """(F,) signed areas of the triangles projected on the xy plane (positive: anticlockwise)."""
    a, b, c = (mesh.vertices[mesh.faces[:, k]].astype(np.float64) for k in range(3))
    return 0.5 * np.cross(b - a, c - a)[:, 2]


def polygon_file(ext: str, corners) -> str:
    """One polygon (z = 0) as an OBJ, OFF or ASCII PLY file."""
    n = len(corners)
    rows = "".join(f"{x} {y} 0\n" for x, y in corners)
    if ext == ".obj":
        return "".join(f"v {x} {y} 0\n" for x, y in corners) + "f " + " ".join(str(i + 1) for i in range(n)) + "\n"
    face = f"{n} " + " ".join(str(i) for i in range(n)) + "\n"
    if ext == ".off":
        return f"OFF\n{n} 1 0\n" + rows + face
    return (f"ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 1\nproperty list uchar int vertex_indices\nend_header\n" + rows + face)


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply"])
@pytest.mark.parametrize("corners", [L_SHAPE, DART, L_CLOCKWISE], ids=["L", "dart", "L-clockwise"])
def test_concave_polygons_are_ear_clipped(tmp_path, ext, corners):
    mesh = load_mesh(write(tmp_path, "concave" + ext, polygon_file(ext, corners)))
    areas = triangle_areas(mesh)
    xy = np.asarray(corners, np.float64)
    shoelace = 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
    assert len(mesh.faces) == len(corners) - 2
    assert np.all(np.sign(areas) == np.sign(shoelace))   # every triangle wound as the polygon
    assert areas.sum() == pytest.approx(shoelace)


def test_concave_binary_ply_polygons_are_ear_clipped(tmp_path):
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 6\n"
              b"property float x\nproperty float y\nproperty float z\nelement face 2\n"
              b"property list uchar int vertex_indices\nend_header\n")
    vertices = np.array([(x, y, 0) for x, y in L_SHAPE], "<f4")
    faces = b"".join(struct.pack("<B6i", 6, *polygon) for polygon in [range(6), range(5, -1, -1)])
    mesh = load_mesh(write(tmp_path, "l.ply", header + vertices.tobytes() + faces))
    areas = triangle_areas(mesh)
    assert (areas[:4] > 0).all() and (areas[4:] < 0).all()
    assert areas[:4].sum() == pytest.approx(3) and areas[4:].sum() == pytest.approx(-3)


def test_concave_obj_polygons_keep_their_place_texture_coordinates_and_materials(tmp_path):
    """A concave polygon's triangles stay where its fan's were, with their corners'
    texture coordinates and the polygon's material; convex ones stay fans."""
    (tmp_path / "m.mtl").write_text("newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\n")
    corners = L_SHAPE + [(x + 5, y, 0) for x, y in DART] + [(9, 0), (10, 0), (10, 1), (9, 1)]
    text = "mtllib m.mtl\n" + "".join(f"v {c[0]} {c[1]} 0\nvt {c[0] / 10} {c[1] / 10}\n" for c in corners)
    text += "usemtl a\nf 1/1 2/2 3/3\nf " + " ".join(f"{i}/{i}" for i in range(1, 7))
    text += "\nusemtl b\nf " + " ".join(f"{i}/{i}" for i in range(7, 11)) + "\nf 11/11 12/12 13/13 14/14\n"
    mesh, _ = load_asset(write(tmp_path, "m.obj", text))
    assert mesh.faces[0].tolist() == [0, 1, 2]
    assert set(mesh.faces[1:5].ravel().tolist()) == set(range(6))
    assert set(mesh.faces[5:7].ravel().tolist()) == set(range(6, 10))
    assert mesh.faces[7:].tolist() == [[10, 11, 12], [10, 12, 13]]   # convex: the fan
    assert mesh.face_material.tolist() == [0] * 5 + [1] * 4
    np.testing.assert_allclose(mesh.uv, mesh.vertices[mesh.faces][..., :2] / 10, atol=1e-7)
    areas = triangle_areas(mesh)
    assert (areas > 0).all() and areas[1:5].sum() == pytest.approx(3) and areas[5:7].sum() == pytest.approx(1.5)


def test_ear_clipping_triangulates_random_simple_polygons_in_any_plane():
    """Star-shaped polygons of 4 to 40 corners (many reflex), rotated into random
    planes, some wound each way: n - 2 triangles of the polygon's own corners,
    each wound as the polygon, covering exactly its area."""
    from clrt.scene.formats.triangulate import triangulate
    rng = np.random.default_rng(34)
    counts = rng.integers(4, 41, 300)
    polygons, normals, areas = [], [], []
    for n in counts:
        angles = (np.arange(n) + rng.uniform(0.05, 0.95, n)) * 2 * np.pi / n   # one a sector: the centre inside
        radii = rng.uniform(0.2, 1.0, n)
        xy = np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=1)
        if rng.random() < 0.5:
            xy = xy[::-1]
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        polygons.append(np.column_stack([xy, np.zeros(n)]) @ rotation.T + rng.normal(size=3))
        normals.append(rotation[:, 2])
        areas.append(0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]))
    vertices = np.concatenate(polygons)
    flat = rng.permutation(len(vertices))   # corners named through an index, as in a file
    vertices[flat] = vertices.copy()
    triangles = triangulate(counts, flat, vertices)
    assert triangles.shape == (int((counts - 2).sum()), 3)
    first = 0
    for n, normal, area, start in zip(counts, normals, areas, np.cumsum(counts) - counts):
        tris = triangles[first:first + n - 2]
        first += n - 2
        assert set(tris.ravel().tolist()) <= set(flat[start:start + n].tolist())
        a, b, c = (vertices[tris[:, k]] for k in range(3))
        signed = 0.5 * np.cross(b - a, c - a) @ normal
        assert np.all(np.sign(signed) == np.sign(area))
        assert signed.sum() == pytest.approx(area, rel=1e-9)


def comb(teeth: int) -> list:
    """A comb-shaped polygon, anticlockwise: a back 1 high and ``teeth`` teeth 1
    wide and 2 long, 1 apart; 4 corners a tooth, area 4 a tooth - 1."""
    corners = [(0, 0), (2 * teeth - 1, 0)]
    for k in range(teeth - 1, -1, -1):
        corners += [(2 * k + 1, 3), (2 * k, 3)] + ([(2 * k, 1), (2 * k - 1, 1)] if k else [])
    return corners


def test_large_concave_polygons_are_ear_clipped_one_by_one(tmp_path):
    corners = comb(50)   # 200 corners: past the numpy steps' sizes
    mesh = load_mesh(write(tmp_path, "comb.off", polygon_file(".off", corners)))
    areas = triangle_areas(mesh)
    assert len(areas) == 198 and (areas > 0).all() and areas.sum() == pytest.approx(199)


def test_ear_clipping_one_by_one_and_all_at_once_agree():
    """The numpy steps for many polygons and the one-by-one loop for large ones
    cut the same ears, on simple, degenerate and self-intersecting polygons."""
    from clrt.scene.formats import triangulate
    rng = np.random.default_rng(35)
    for n in rng.integers(4, 30, 150):
        angles = (np.arange(n) + rng.uniform(0.05, 0.95, n)) * 2 * np.pi / n
        xy = np.stack([np.cos(angles), np.sin(angles)], axis=1) * rng.uniform(0.2, 1.0, (n, 1))
        kind = rng.integers(3)
        if kind == 1:
            xy = np.round(xy * 4) / 4        # corners on straight lines, and at the same place
        elif kind == 2:
            xy = rng.random((n, 2))          # self-intersecting
        np.testing.assert_array_equal(triangulate._ear_clip_all(xy[None])[0], triangulate._ear_clip_one(xy))


def test_ear_clipping_of_a_hostile_file_is_bounded(tmp_path):
    """A 40,000-corner concave polygon would take ear clipping a minute: past
    the work budget (counted in corners, not timed) it keeps its fan.
    (How long such a file takes to load: python -m benchmarks.fail_fast.)"""
    corners = comb(10_000)
    path = write(tmp_path, "big.obj", polygon_file(".obj", corners))
    mesh = load_mesh(path)
    n = len(corners)
    assert mesh.faces.tolist() == [[0, k, k + 1] for k in range(1, n - 1)]


# ---------------------------------------------------------------------------
# Colour scale from the declared types (never guessed from the values)

from clrt.scene.texture import srgb_decode  # noqa: E402

PLY_COLOURED = ("ply\nformat {fmt} 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                "property {t} red\nproperty {t} green\nproperty {t} blue\nelement face 1\n"
                "property list uchar int vertex_indices\nend_header\n")


def test_ply_float_colours_are_0_to_1_even_a_hair_above_one(tmp_path):
    # a float colour of 1.0000001 is 1 (clamped), not a reason to read all as 0..255
    text = PLY_COLOURED.format(fmt="ascii", t="float") + (
        "0 0 0 1.0000001 0.5 0.5\n1 0 0 0.5 0.5 0.5\n0 1 0 0.5 0.5 0.5\n3 0 1 2\n")
    mesh = load_mesh(write(tmp_path, "f.ply", text))
    assert mesh.colors[0, 0] == pytest.approx([1.0, *srgb_decode([0.5, 0.5])], abs=1e-6)
    assert mesh.colors[0, 1] == pytest.approx(srgb_decode([0.5, 0.5, 0.5]), abs=1e-6)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("t, top, code", [("uchar", 255, "B"), ("int", 255, "i"), ("ushort", 65535, "H"),
                                          ("double", 1, "d")])
def test_ply_colour_scale_follows_the_property_type(tmp_path, fmt, t, top, code):
    # uchar colours of only 0 and 1 are 0 and 1/255 (near black), not 0 and white
    rows = [(0, 0, 0, 1, 1, 1), (1, 0, 0, 1, 0, 1), (0, 1, 0, 0, 1, 0)]
    head = PLY_COLOURED.format(fmt=fmt, t=t)
    if fmt == "ascii":
        data = head + "".join(" ".join(map(str, r)) + "\n" for r in rows) + "3 0 1 2\n"
    else:
        o = "<" if "little" in fmt else ">"
        data = head.encode() + b"".join(struct.pack(f"{o}fff{code * 3}", *r) for r in rows) \
            + struct.pack(f"{o}Biii", 3, 0, 1, 2)
    mesh = load_mesh(write(tmp_path, "c.ply", data))
    assert mesh.colors[0].tolist() == pytest.approx(srgb_decode(np.array(rows)[:, 3:] / top), abs=1e-6)


@pytest.mark.parametrize("colour, expected", [("1 1 1 255", 1 / 255), ("255 255 255 255", 1.0),
                                              ("1.0 1.0 1.0 1.0", 1.0), ("1 1 1.0 1", 1.0),
                                              ("0.5 0.5 0.5 1", 0.5)])
def test_coff_integer_colours_are_0_to_255_and_float_ones_0_to_1(tmp_path, colour, expected):
    text = "COFF\n3 1 0\n" + "".join(f"{x} {y} 0 {colour}\n" for x, y in [(0, 0), (1, 0), (0, 1)]) + "3 0 1 2\n"
    mesh = load_mesh(write(tmp_path, "c.off", text))
    np.testing.assert_allclose(mesh.colors[0], srgb_decode(np.full((3, 3), expected)), atol=1e-6)


@pytest.mark.parametrize("colour, expected", [("1 0 0", 1 / 255), ("255 0 0", 1.0), ("1.0 0 0", 1.0)])
def test_off_face_colours_by_how_they_are_written(tmp_path, colour, expected):
    text = f"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 {colour}\n"
    mesh = load_mesh(write(tmp_path, "f.off", text))
    np.testing.assert_allclose(mesh.colors[0, 0], [srgb_decode(expected), 0, 0], atol=1e-6)


@pytest.mark.parametrize("keyword, extra", [
    ("COFF", "{c}"), ("CNOFF", "0 0 1  {c}"), ("STCOFF", "{c}  0.25 0.75"), ("STCNOFF", "0 0 1  {c}  0.25 0.75"),
    ("CNOFF", "0 0 1  {c3}"), ("STCNOFF", "0 0 1  {c3}  0.25 0.75"), ("NOFF", "0 0 1"), ("STOFF", "0.25 0.75"),
])
def test_off_vertex_columns_in_geomviews_order(tmp_path, keyword, extra):
    # Geomview: x y z [nx ny nz] [r g b a] [s t], in that order, by the N, C, ST prefixes
    line = extra.format(c="255 0 0 255", c3="255 0 0")
    text = f"{keyword}\n3 1 0\n" + "".join(f"{x} {y} 0  {line}\n" for x, y in [(0, 0), (1, 0), (0, 1)]) + "3 0 1 2\n"
    mesh = load_mesh(write(tmp_path, "v.off", text))
    assert mesh.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    if "C" in keyword:
        assert mesh.colors[0].tolist() == [[1.0, 0.0, 0.0]] * 3
    else:
        assert mesh.colors is None


# ---------------------------------------------------------------------------
# Binary PLY with faces of mixed sizes (trimesh's reader refuses them)

MIXED_HEAD = ("ply\nformat {fmt} 1.0\nelement vertex 7\nproperty float x\nproperty float y\nproperty float z\n"
              "element face 3\nproperty list uchar int vertex_indices\nproperty uchar red\nproperty uchar green\n"
              "property uchar blue\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n")
MIXED_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0), (3, 0.5, 0)]
MIXED_F = [((0, 1, 2, 3), (255, 0, 0)), ((1, 4, 5), (0, 255, 0)), ((1, 4, 6, 5, 2), (0, 0, 1))]


def _mixed_ply(fmt: str) -> bytes:
    o = "<" if "little" in fmt else ">"
    body = b"".join(struct.pack(f"{o}3f", *v) for v in MIXED_V)
    body += b"".join(struct.pack(f"{o}B{len(f)}i3B", len(f), *f, *c) for f, c in MIXED_F)
    return MIXED_HEAD.format(fmt=fmt).encode() + body + struct.pack(f"{o}2i", 0, 1)


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian"])
def test_binary_ply_with_faces_of_mixed_sizes(tmp_path, fmt):
    mesh = load_mesh(write(tmp_path, "mixed.ply", _mixed_ply(fmt)))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 4, 6], [1, 6, 5], [1, 5, 2]]
    assert mesh.vertices.tolist() == [list(v) for v in MIXED_V]
    np.testing.assert_allclose(mesh.colors[:, 0], [[1, 0, 0]] * 2 + [[0, 1, 0]] + [[0, 0, srgb_decode(1 / 255)]] * 3,
                               atol=1e-6)
    # the same file in ASCII loads the same
    ascii_text = MIXED_HEAD.format(fmt="ascii") + "".join(" ".join(map(str, v)) + "\n" for v in MIXED_V) \
        + "".join(f"{len(f)} {' '.join(map(str, f))} {' '.join(map(str, c))}\n" for f, c in MIXED_F) + "0 1\n"
    same = load_mesh(write(tmp_path, "mixed_ascii.ply", ascii_text))
    assert same.faces.tolist() == mesh.faces.tolist() and np.array_equal(same.colors, mesh.colors)


@pytest.mark.parametrize("cut, reason", [(-3, "truncated"), (-9, "truncated"), (-30, "truncated"),
                                         (2, "longer than its header says (2 bytes after the last element)")])
def test_binary_ply_of_mixed_sizes_cut_or_padded(tmp_path, cut, reason):
    data = _mixed_ply("binary_little_endian")
    data = data[:cut] if cut < 0 else data + b"\0" * cut
    assert_one_line_error(write(tmp_path, "bad.ply", data), reason)


def test_ascii_ply_truncated_at_every_offset(tmp_path):
    source = trimesh.Trimesh(TETRA_V, TETRA_F, process=False)
    data = source.export(file_type="ply", encoding="ascii").rstrip()
    for size in range(len(data)):
        with pytest.raises(MeshLoadError):
            load_mesh(write(tmp_path, f"cut{size}.ply", data[:size]))
    assert len(load_mesh(write(tmp_path, "whole.ply", data)).faces) == 4


def test_obj_tabs_and_indentation(tmp_path):
    text = "  v\t0 0 0\n\tv 1 0 0\nv 0 1 0 1.0\n   f\t1 2 \\\n 3\n"
    mesh = load_mesh(write(tmp_path, "tabs.obj", text))
    assert mesh.faces.tolist() == [[0, 1, 2]]


@pytest.mark.parametrize("file_type", ["stl", "stl_ascii"])
def test_stl_round_trip(tmp_path, file_type):
    source = trimesh.Trimesh(TETRA_V, TETRA_F, process=False)
    mesh = load_mesh(write(tmp_path, "t.stl", source.export(file_type=file_type)))
    np.testing.assert_allclose(triangles(mesh), TETRA_V[TETRA_F])


def test_broken_binary_stl_says_what_is_wrong(tmp_path):
    # Not trimesh's ASCII fallback's error (a missing optional package, once).
    data = trimesh.Trimesh(TETRA_V, TETRA_F, process=False).export(file_type="stl")   # 84 + 4 * 50 bytes
    assert_one_line_error(write(tmp_path, "t.stl", data[:200]),
                          "truncated binary STL (header says 4 triangles, the file holds room for 2)")
    huge = data[:80] + struct.pack("<I", 0xFFFFFFFF) + data[84:]
    assert_one_line_error(write(tmp_path, "h.stl", huge),
                          "truncated binary STL (header says 4294967295 triangles, the file holds room for 4)")
    assert_one_line_error(write(tmp_path, "l.stl", data + b"xy"), "binary STL longer than its header says")
    assert_one_line_error(write(tmp_path, "s.stl", b"\x01\x02\x03"), "not an STL file (3 bytes")
    solid = b"solid" + data[5:]   # a binary header may start with 'solid' too
    assert_one_line_error(write(tmp_path, "b.stl", solid[:200]), "truncated binary STL")


def test_latin1_ascii_stl_loads(tmp_path):
    text = trimesh.Trimesh(TETRA_V, TETRA_F, process=False).export(file_type="stl_ascii").encode()
    mesh = load_mesh(write(tmp_path, "a.stl", text.replace(b"solid", b"solid caf\xe9", 1)))
    np.testing.assert_allclose(triangles(mesh), TETRA_V[TETRA_F])


def _two_object_scene() -> "tuple[trimesh.Scene, np.ndarray]":
    """A scene with two transformed instances and the (F, 3, 3) triangles expected."""
    scene = trimesh.Scene()
    rotate = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 0, 1])
    shift = trimesh.transformations.translation_matrix([5, 0, 0])
    scale = np.diag([2.0, 2.0, 2.0, 1.0])
    expected = []
    for name, matrix in [("a", rotate), ("b", shift @ scale)]:
        scene.add_geometry(trimesh.Trimesh(TETRA_V, TETRA_F, process=False),
                           node_name=name, geom_name=name, transform=matrix)
        expected.append(TETRA_V[TETRA_F] @ matrix[:3, :3].T + matrix[:3, 3])
    return scene, np.concatenate(expected)


def _sorted_triangles(tris: np.ndarray) -> np.ndarray:
    """Triangles in a canonical order, so scene node order does not matter."""
    flat = np.round(tris.reshape(len(tris), 9), 5)
    return flat[np.lexsort(flat.T[::-1])]


def test_glb_scene_is_flattened_with_transforms(tmp_path):
    scene, expected = _two_object_scene()
    mesh = load_mesh(write(tmp_path, "scene.glb", scene.export(file_type="glb")))
    assert len(mesh.faces) == 8
    np.testing.assert_allclose(_sorted_triangles(triangles(mesh)),
                               _sorted_triangles(expected), atol=1e-5)


def test_gltf_with_external_buffer(tmp_path):
    scene, expected = _two_object_scene()
    for name, data in scene.export(file_type="gltf").items():
        write(tmp_path, name, data)
    mesh = load_mesh(tmp_path / "model.gltf")
    np.testing.assert_allclose(_sorted_triangles(triangles(mesh)),
                               _sorted_triangles(expected), atol=1e-5)


TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)


def _gltf_file(path, meshes, nodes=None, scenes=None, materials=None, edit=None):
    """A .gltf with an embedded buffer. meshes: list of lists of primitive dicts
    {attribute name: array, "indices": array, "mode": int, "material": int};
    integer attributes of two dimensions are normalized."""
    import base64
    import json
    buf, views, accessors = bytearray(), [], []
    codes = {"float32": 5126, "uint8": 5121, "uint16": 5123, "uint32": 5125}

    def add(a):
        a = np.ascontiguousarray(a)
        buf.extend(b"\0" * (-len(buf) % 4))
        views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": a.nbytes})
        buf.extend(a.tobytes())
        acc = {"bufferView": len(views) - 1, "componentType": codes[a.dtype.name], "count": len(a),
               "type": "SCALAR" if a.ndim == 1 else f"VEC{a.shape[1]}"}
        if a.dtype != np.float32 and a.ndim == 2:
            acc["normalized"] = True
        if a.ndim == 2 and a.shape[1] == 3 and a.dtype == np.float32:
            acc["min"], acc["max"] = a.min(0).tolist(), a.max(0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    out = []
    for prims in meshes:
        ps = []
        for p in prims:
            q = {"attributes": {k: add(v) for k, v in p.items() if k.isupper()}}
            q.update({k: (add(v) if k == "indices" else v) for k, v in p.items() if not k.isupper()})
            ps.append(q)
        out.append({"primitives": ps})
    nodes = nodes if nodes is not None else [{"mesh": i} for i in range(len(out))]
    doc = {"asset": {"version": "2.0"}, "scene": 0,
           "scenes": scenes or [{"nodes": list(range(len(nodes)))}], "nodes": nodes,
           "meshes": out, "accessors": accessors, "bufferViews": views}
    if materials:
        doc["materials"] = materials
    if edit:
        edit(doc, buf, views, accessors)
    buf.extend(b"\0" * (-len(buf) % 4))
    doc["buffers"] = [{"byteLength": len(buf),
                       "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(buf)).decode()}]
    path.write_text(json.dumps(doc))
    return path


def test_gltf_face_order_is_a_depth_first_walk_in_file_order(tmp_path):
    # scene roots 2 then 0; node 0's children 1; so nodes 2, 0, 1: meshes 2, 0, 1
    meshes = [[{"POSITION": TRI + np.float32(10 * i)}] for i in range(3)]
    p = _gltf_file(tmp_path / "order.gltf", meshes, nodes=[{"mesh": 0, "children": [1]}, {"mesh": 1}, {"mesh": 2}],
                   scenes=[{"nodes": [2, 0]}])
    mesh = load_mesh(p)
    assert mesh.vertices[mesh.faces][:, 0, 0].tolist() == [20, 0, 10]
    p = _gltf_file(tmp_path / "two.gltf", [[{"POSITION": TRI}], [{"POSITION": TRI + np.float32(10)}]])
    mesh = load_mesh(p)
    assert mesh.vertices[mesh.faces][:, 0].tolist() == [[0, 0, 0], [10, 10, 10]]


def test_gltf_mirroring_node_keeps_faces_facing_out(tmp_path):
    # glTF 2.0 (3.7.4): a negative determinant reverses the winding; refraction reads winding
    f = np.array(TETRA_F, np.uint16).reshape(-1)   # outward, counter-clockwise
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32)
    p = _gltf_file(tmp_path / "m.gltf", [[{"POSITION": TETRA_V.astype(np.float32), "TEXCOORD_0": uv, "indices": f}]],
                   nodes=[{"children": [1], "scale": [1, 1, -2]}, {"mesh": 0, "scale": [-1, 1, 1]},
                          {"mesh": 0, "scale": [-1, 1, 1]}], scenes=[{"nodes": [0, 2]}])
    mesh = load_mesh(p)
    assert len(mesh.faces) == 8
    for half in (slice(0, 4), slice(4, 8)):
        faces = mesh.faces[half]
        centre = mesh.vertices[np.unique(faces)].mean(0)
        normals = mesh.face_normals()[half]
        assert (np.einsum("ij,ij->i", normals, mesh.vertices[faces].mean(1) - centre) > 0).all()
    # corners and their texture coordinates stay together
    expected = 1 - uv[:, 1]
    np.testing.assert_allclose(mesh.uv[4:, :, 1], expected[TETRA_F[:, [0, 2, 1]]])


def test_gltf_sparse_accessor_is_applied(tmp_path):
    def sparse(doc, buf, views, accessors):
        buf.extend(b"\0" * (-len(buf) % 4))
        views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": 2})
        buf.extend(struct.pack("<H", 1) + b"\0\0")
        views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": 12})
        buf.extend(struct.pack("<3f", 5, 5, 5))
        a = accessors[doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
        a["sparse"] = {"count": 1, "indices": {"bufferView": len(views) - 2, "componentType": 5123},
                       "values": {"bufferView": len(views) - 1}}
        a["max"] = [5, 5, 5]
    p = _gltf_file(tmp_path / "s.gltf", [[{"POSITION": TRI}]], edit=sparse)
    mesh = load_mesh(p)
    assert mesh.vertices[mesh.faces][0].tolist() == [[0, 0, 0], [5, 5, 5], [0, 1, 0]]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_gltf_normalized_integer_texcoords(tmp_path, dtype):
    top = np.iinfo(dtype).max
    uv = np.array([[0, 1], [1, 1], [0, 0]], np.float64) * top
    p = _gltf_file(tmp_path / "uv.gltf", [[{"POSITION": TRI, "TEXCOORD_0": uv.astype(dtype), "material": 0}]],
                   materials=[{"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}}])
    mesh = load_mesh(p)
    assert mesh.uv[0].tolist() == [[0, 0], [1, 0], [0, 1]]   # v' = 1 - v, as for float ones


def test_gltf_base_colour_texture_reads_its_texcoord_set(tmp_path):
    uv0 = np.zeros((3, 2), np.float32)
    uv1 = np.array([[0, 1], [1, 1], [0, 0]], np.float32)
    (tmp_path / "red.png").write_bytes(_png_bytes((255, 0, 0)))

    def texture(doc, buf, views, accessors):
        doc["textures"], doc["images"] = [{"source": 0}], [{"uri": "red.png"}]
    p = _gltf_file(tmp_path / "uv1.gltf", [[{"POSITION": TRI, "TEXCOORD_0": uv0, "TEXCOORD_1": uv1, "material": 0}]],
                   materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "texCoord": 1}}}],
                   edit=texture)
    mesh, (material,) = load_module.load_asset(p)
    assert mesh.uv[0].tolist() == [[0, 0], [1, 0], [0, 1]]
    assert material["texture"].pixels.tolist() == [[[255, 0, 0]]]


def _png_bytes(rgb) -> bytes:
    import io

    from PIL import Image
    out = io.BytesIO()
    Image.new("RGB", (1, 1), rgb).save(out, format="PNG")
    return out.getvalue()


@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_gltf_colours_without_material_keep_their_precision(tmp_path, dtype):
    c = np.array([[1, 0, 0, 1], [0, 0.5, 0, 1], [0, 0, 0.25, 1]])
    stored = (c * 65535).round().astype(dtype) if dtype == np.uint16 else c.astype(dtype)
    p = _gltf_file(tmp_path / "c.gltf", [[{"POSITION": TRI, "COLOR_0": stored}]])
    mesh = load_mesh(p)
    assert mesh.colors[0] == pytest.approx(c[:, :3], abs=1e-4)


def test_gltf_triangle_strips_and_fans(tmp_path):
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    strip = np.array([0, 1, 3, 2], np.uint16)
    p = _gltf_file(tmp_path / "fan.gltf", [[{"POSITION": TRI}, {"POSITION": quad + np.float32(5), "mode": 6},
                                            {"POSITION": quad, "indices": strip, "mode": 5}]])
    mesh = load_mesh(p)
    assert mesh.faces.tolist()[1:] == [[3, 4, 5], [3, 5, 6], [7, 8, 10], [8, 9, 10]]
    assert (mesh.face_normals()[:, 2] > 0).all()


def test_gltf_normals_kept_when_another_primitive_has_none(tmp_path):
    n = np.array([[0, 0.6, 0.8]] * 3, np.float32)
    p = _gltf_file(tmp_path / "n.gltf", [[{"POSITION": TRI, "NORMAL": n}, {"POSITION": TRI + np.float32(2)}]])
    mesh = load_mesh(p)
    np.testing.assert_allclose(mesh.vertex_normals(), [[0, 0.6, 0.8]] * 3 + [[0, 0, 1]] * 3, atol=1e-6)


def test_gltf_compressed_primitive_is_refused(tmp_path):
    def draco(doc, buf, views, accessors):
        doc["meshes"][0]["primitives"][0]["extensions"] = {"KHR_draco_mesh_compression": {}}
    p = _gltf_file(tmp_path / "d.gltf", [[{"POSITION": TRI}]], edit=draco)
    assert_one_line_error(p, "compressed with KHR_draco_mesh_compression")


# ---------------------------------------------------------------------------
# 3DS


def test_3ds_round_trip_two_objects(tmp_path):
    path = tmp_path / "two.3ds"
    write_3ds(path, [tetra("a"), tetra("b", offset=(3, 0, 0))])
    mesh = load_mesh(path)
    assert len(mesh.faces) == 8 and mesh.name == "two"
    expected = np.concatenate([TETRA_V[TETRA_F], (TETRA_V + [3, 0, 0])[TETRA_F]])
    np.testing.assert_allclose(triangles(mesh), expected)


def test_3ds_upper_case_extension(tmp_path):
    path = tmp_path / "UP.3DS"
    write_3ds(path, [tetra()])
    assert len(load_mesh(path).faces) == 4


def test_3ds_write_splits_over_uint16_limits(tmp_path):
    n = 70_000  # triangles with unshared corners: 210000 vertices
    rng = np.random.default_rng(1)
    big = Mesh.from_arrays(rng.random((3 * n, 3)), np.arange(3 * n).reshape(n, 3), "big")
    path = tmp_path / "big.3ds"
    write_3ds(path, [big])
    mesh = load_mesh(path)
    np.testing.assert_array_equal(triangles(mesh), triangles(big))


def _chunk(cid, *payload):
    body = b"".join(payload)
    return struct.pack("<HI", cid, 6 + len(body)) + body


def _hand_built_3ds(matrix=None, extra=b"") -> bytes:
    """One object with an unknown chunk, a material group after the faces, and a matrix."""
    v = TETRA_V.astype("<f4")
    faces = np.column_stack([TETRA_F, np.full(4, 7)]).astype("<u2")
    material_group = _chunk(0x4130, b"mat\0", struct.pack("<HHH", 2, 0, 3))
    smoothing = _chunk(0x4150, struct.pack("<4I", 1, 1, 1, 1))
    local = np.eye(4, 3) if matrix is None else matrix
    mesh = _chunk(
        0x4100,
        _chunk(0x4110, struct.pack("<H", 4), v.tobytes()),
        _chunk(0x4111, b"\x00" * 8),  # vertex flags: unknown to us, skipped
        _chunk(0x4120, struct.pack("<H", 4), faces.tobytes(), material_group, smoothing),
        _chunk(0x4160, np.asarray(local, dtype="<f4").tobytes()),
    )
    light = _chunk(0x4000, b"lamp\0", _chunk(0x4600, struct.pack("<3f", 1, 2, 3)))
    obj = _chunk(0x4000, b"tetra\0", mesh)
    material = _chunk(0xAFFF, _chunk(0xA000, b"mat\0"))
    editor = _chunk(0x3D3D, _chunk(0x3D3E, struct.pack("<I", 3)), material, light, obj, extra)
    return _chunk(0x4D4D, _chunk(0x0002, struct.pack("<I", 3)), editor,
                  _chunk(0xB000, b"\x00" * 10))


def test_3ds_hand_built_with_unknown_and_sub_chunks(tmp_path):
    mesh = load_mesh(write(tmp_path, "hand.3ds", _hand_built_3ds()))
    np.testing.assert_array_equal(mesh.faces, TETRA_F)
    np.testing.assert_array_equal(mesh.vertices, TETRA_V)


def test_3ds_local_matrix_is_not_applied(tmp_path):
    # Vertices are stored in world space; the matrix is only the pivot frame.
    matrix = np.array([[2, 0, 0], [0, 2, 0], [0, 0, 2], [10, 20, 30]])
    mesh = load_mesh(write(tmp_path, "m.3ds", _hand_built_3ds(matrix=matrix)))
    np.testing.assert_array_equal(mesh.vertices, TETRA_V)


def test_3ds_registered_with_trimesh(tmp_path):
    # clrt registers its reader when it first hands trimesh a file (an STL or
    # glTF); done here, so that the test does not depend on the tests before it
    from clrt.scene.formats.tds import register_with_trimesh
    assert register_with_trimesh()
    path = tmp_path / "reg.3ds"
    write_3ds(path, [tetra()])
    loaded = trimesh.load(str(path), force="mesh", process=False)
    np.testing.assert_array_equal(np.asarray(loaded.faces), TETRA_F)


def _in_editor(*chunks) -> bytes:
    return _chunk(0x4D4D, _chunk(0x3D3D, *chunks))


def _one_mesh(*chunks) -> bytes:
    return _in_editor(_chunk(0x4000, b"x\0", _chunk(0x4100, *chunks)))


@pytest.mark.parametrize("data, reason", [
    (b"MM\x06\x00\x00", "too short"),
    (b"\x00\x00" + struct.pack("<I", 6), "not a 3DS file"),
    (_chunk(0x4D4D, struct.pack("<HI", 0x3D3D, 3)), "invalid length 3"),
    (_chunk(0x4D4D, struct.pack("<HI", 0x3D3D, 100)), "only 6 remain"),
    (_chunk(0x4D4D)[:2] + struct.pack("<I", 99), "truncated"),
    (_in_editor(_chunk(0x4000, b"noname")), "not NUL-terminated"),
    (_one_mesh(_chunk(0x4110, struct.pack("<H", 50), b"\0" * 24)), "claims 50 vertices"),
    (_one_mesh(_chunk(0x4110, struct.pack("<H", 1), b"\0" * 12),
               _chunk(0x4120, struct.pack("<H", 9), b"\0" * 8)), "claims 9 faces"),
    (_one_mesh(_chunk(0x4110, struct.pack("<H", 1), b"\0" * 12),
               _chunk(0x4120, struct.pack("<5H", 1, 0, 1, 0, 0))), "out of range"),
    (_one_mesh(_chunk(0x4120, struct.pack("<5H", 1, 0, 0, 0, 0))), "no vertex list"),
    (_one_mesh(_chunk(0x4110, struct.pack("<H", 1), b"\0" * 12),
               _chunk(0x4120, struct.pack("<5H", 1, 0, 0, 0, 0), b"\0\0")),
     "truncated chunk header"),
    (_in_editor(), "contains no triangles"),
])
def test_3ds_corruption_reasons(data, reason):
    with pytest.raises(MeshLoadError, match=reason):
        parse_3ds(data, label="bad.3ds")


def test_3ds_truncated_at_every_offset(tmp_path):
    data = encode_3ds([tetra("a"), tetra("b", offset=(2, 0, 0))])
    for size in range(len(data)):
        path = write(tmp_path, f"cut{size}.3ds", data[:size])
        with pytest.raises(MeshLoadError):
            load_mesh(path)


# ---------------------------------------------------------------------------
# Errors


def test_missing_file(tmp_path):
    assert_one_line_error(tmp_path / "nope.off", "no such file")


def test_directory(tmp_path):
    folder = tmp_path / "dir.obj"
    folder.mkdir()
    assert_one_line_error(folder, "directory")


def test_unknown_extension_lists_supported(tmp_path):
    message = assert_one_line_error(write(tmp_path, "mesh.xyz", "1 2 3\n"), "'.xyz'")
    for ext in SUPPORTED_EXTENSIONS:
        assert ext in message


@pytest.mark.parametrize("ext", SUPPORTED_EXTENSIONS)
def test_empty_file(tmp_path, ext):
    assert_one_line_error(write(tmp_path, "empty" + ext, b""), "empty")


def test_unreadable_file(tmp_path, monkeypatch):
    path = write(tmp_path, "secret.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")
    # chmod 000 does not stop root, so simulate the refusal at open().
    monkeypatch.setattr(part_module, "open", denied, raising=False)
    assert_one_line_error(path, "permission denied")


def test_off_nan_vertex(tmp_path):
    text = "OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n"
    assert_one_line_error(write(tmp_path, "nan.off", text), "NaN")


def test_off_huge_header_count_is_refused(tmp_path):
    """Refused from what the file holds, not after allocating what its header promises
    (how long it takes: python -m benchmarks.fail_fast)."""
    text = "OFF\n1000000000000 1000000000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    assert len(text) < 100
    assert_one_line_error(write(tmp_path, "huge.off", text), "truncated")


@pytest.mark.parametrize("encoding", ["ascii", "binary_little_endian"])
def test_ply_huge_header_count_is_refused(tmp_path, encoding):
    header = (f"ply\nformat {encoding} 1.0\nelement vertex 1000000000000\nproperty float x\n"
              "property float y\nproperty float z\nelement face 1\n"
              "property list uchar int vertex_indices\nend_header\n")
    assert_one_line_error(write(tmp_path, "huge.ply", header + "0 0 0\n"))


@pytest.mark.parametrize("faces, expected", [
    ("f 1 2 3\nf 1 2 4\n", "face 2 names vertex 4, but the file defines 3 vertices (OBJ indices 1..3"),
    ("f 1 2 3 -4\n", "face 1 names vertex -4, but the file defines 3 vertices"),
    ("vn 0 0 1\nf 1//1 2//1 5//1\n", "face 1 names vertex 5,"),
])
def test_obj_face_index_out_of_range_in_the_files_numbering(tmp_path, faces, expected):
    # 1-based, as the file counts; not the 0-based "indices 0..3" of Mesh.from_arrays.
    message = assert_one_line_error(write(tmp_path, "range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n" + faces), expected)
    assert "0.." not in message


def test_off_face_index_out_of_range(tmp_path):
    text = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"
    assert_one_line_error(write(tmp_path, "range.off", text), "out of range")


@pytest.mark.parametrize("name, data", [
    ("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
    ("lines.obj", "v 0 0 0\nv 1 0 0\nl 1 2\n"),
    ("points.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
                   "property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n"),
    ("nofaces.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n"),
])
def test_no_triangles(tmp_path, name, data):
    assert_one_line_error(write(tmp_path, name, data), "no triangles")


def test_broken_gltf_gets_the_mesh_readers_reason(tmp_path):
    """Not the camera reader's error, nor an exception name of trimesh's."""
    from clrt.scene.scene import scene_from_mesh
    glb = trimesh.Trimesh(TETRA_V, TETRA_F, process=False).export(file_type="glb")
    cases = {
        "random.glb": (bytes(range(256)) * 2, "corrupt or unsupported GLB file: not a GLB file"),
        "cut.glb": (glb[:60], "corrupt or unsupported GLB file: truncated GLB file (its JSON chunk is"),
        "short.glb": (glb[:-8], "corrupt or unsupported GLB file: truncated GLB file (header says"),
        "bad.gltf": (b'{"asset": {"version": "2.0"}, "meshes": [', "corrupt or unsupported GLTF file: invalid JSON ("),
        "accessor.glb": (glb_with_json(glb, lambda d: d["meshes"][0]["primitives"][0]["attributes"]
                                            .update(POSITION=7)),
                         "corrupt GLB file: meshes[0].primitives[0].attributes.POSITION: accessor 7 does not "
                         "exist (the file has 2)"),
        "indices.glb": (glb_with_json(glb, lambda d: d["meshes"][0]["primitives"][0].update(indices=-1)),
                        "meshes[0].primitives[0].indices: accessor -1 does not exist"),
        "view.glb": (glb_with_json(glb, lambda d: d["accessors"][0].update(bufferView=9)),
                     "accessors[0].bufferView: bufferView 9 does not exist"),
        "node.glb": (glb_with_json(glb, lambda d: d["nodes"][0].update(mesh=3)),
                     "nodes[0].mesh: mesh 3 does not exist (the file has 1)"),
    }
    for name, (data, expected) in cases.items():
        path = write(tmp_path, name, data)
        message = assert_one_line_error(path, expected)
        assert "Error" not in message and "camera" not in message, message
        with pytest.raises(MeshLoadError) as info:   # the path clrt render takes: camera after mesh
            scene_from_mesh(str(path))
        assert str(info.value) == message


@pytest.mark.parametrize("statement, expected", [
    ("Kd 2 nan -1", "Kd must be 3 finite numbers, got (2, nan, -1)"),
    ("Ns inf", "Ns must be a finite number, got inf"),
    ("Ns 1e300", "Ns 1e300 is out of range: material shininess must be a number in 0..10000, got 1e300"),
    ("Ni 1e9", "Ni 1e9 is out of range: material ior must be a number in 1..100, got 1e9"),
    ("Ks 5000 5000 5000", "Ks (5000, 5000, 5000) is out of range: material specular must be a number in 0..1000"),
])
def test_bad_mtl_values_name_the_file_and_material(tmp_path, statement, expected):
    obj = write(tmp_path, "m.obj", "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n")
    write(tmp_path, "m.mtl", f"newmtl green\nKd 0 1 0\nnewmtl red\n{statement}\n")
    message = assert_one_line_error(obj, f"m.mtl: material 'red': {expected}")
    assert message.startswith(f"{obj}: m.mtl: material 'red': "), message


def test_glb_point_cloud_has_no_triangles(tmp_path):
    cloud = trimesh.Scene(trimesh.PointCloud(TETRA_V))
    assert_one_line_error(write(tmp_path, "cloud.glb", cloud.export(file_type="glb")),
                          "no triangles")


def _samples() -> "dict[str, bytes]":
    """One small valid file per format, for the mutation test."""
    source = trimesh.Trimesh(TETRA_V, TETRA_F, process=False)
    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in TETRA_V)
    obj += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in TETRA_F)
    return {
        "3ds": encode_3ds([tetra("a"), tetra("b", offset=(2, 0, 0))]),
        "off": trimesh.exchange.off.export_off(source).encode(),
        "obj": obj.encode(),
        "ply": source.export(file_type="ply", encoding="binary"),
        "ply-ascii": source.export(file_type="ply", encoding="ascii"),
        "stl": source.export(file_type="stl"),
        "stl-ascii": source.export(file_type="stl_ascii").encode(),
        "glb": source.export(file_type="glb"),
    }


@pytest.mark.parametrize("kind", ["3ds", "off", "obj", "ply", "ply-ascii", "stl", "stl-ascii",
                                  "glb"])
def test_random_byte_mutations(tmp_path, kind, capfd):
    """200 mutated copies per format: each loads or raises MeshLoadError (how long
    each takes: python -m benchmarks.fail_fast)."""
    data = _samples()[kind]
    ext = "." + kind.split("-")[0]
    rng = np.random.default_rng(20240521)
    for case in range(200):
        mutated = bytearray(data)
        for _ in range(rng.integers(1, 4)):
            position = rng.integers(len(mutated))
            if rng.random() < 0.5:
                mutated[position] = rng.integers(256)
            else:  # text formats mostly break on digits, so favour plausible ones
                mutated[position] = ord(str(rng.integers(10)))
        path = write(tmp_path, f"m{case}{ext}", bytes(mutated))
        try:
            mesh = load_mesh(path)
        except MeshLoadError as exc:
            assert "\n" not in str(exc)
        else:
            assert mesh.faces.dtype == np.int32 and len(mesh.faces) > 0
            assert mesh.faces.max() < len(mesh.vertices)
            assert np.isfinite(mesh.vertices).all()
    # trimesh's logged warnings (with tracebacks) must not reach the terminal.
    assert capfd.readouterr().err == ""


# ---------------------------------------------------------------------------
# Shared data


def test_shared_cow_3ds_matches_off():
    if not SHARED_MESHES.is_dir():
        pytest.skip(f"shared meshes not present at {SHARED_MESHES}")
    from_3ds = load_mesh(SHARED_MESHES / "cow.3ds")
    from_off = load_mesh(SHARED_MESHES / "cow.off")
    assert len(from_3ds.faces) == len(from_off.faces)
    np.testing.assert_allclose(from_3ds.bounds, from_off.bounds, rtol=1e-4, atol=1e-4)


SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float64)


@pytest.mark.parametrize("vertices, faces, message", [
    (SQUARE_V, [[0, 1, -1]], "face index out of range (indices -1..1, 4 vertices)"),
    (SQUARE_V, [[0, 1, 4]], "face index out of range (indices 0..4, 4 vertices)"),
    (SQUARE_V, [[True, False, True]], "faces must be real numbers, got an array of bool"),
    (SQUARE_V, [[0, 1, 2.5]], "face indices must be integers"),
    (SQUARE_V, np.zeros((0, 3), int), "mesh has no triangles"),
    (SQUARE_V.astype(complex), [[0, 1, 2]], "vertices must be real numbers, got an array of complex128"),
    ([[np.nan, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], "1 vertices have NaN or infinite coordinates"),
    (SQUARE_V * 1e31, [[0, 1, 2]], "vertex coordinates must lie within +-1e30"),
    ([[0, 0], [1, 1]], [[0, 1, 1]], "vertices must have shape (V, 3), got (2, 2)"),
])
def test_mesh_constructor_checks_its_arrays(vertices, faces, message):
    """clrt.Mesh(V, F) is checked as the loaders' meshes are: a negative index
    would otherwise pick a vertex from the end and trace a triangle not given."""
    with pytest.raises(MeshLoadError) as info:
        Mesh(vertices, faces)
    assert message in str(info.value)


def test_mesh_detail_and_transform_are_checked():
    mesh = Mesh(SQUARE_V, [[0, 1, 2], [1, 3, 2]], "sq")
    assert mesh.vertices.dtype == np.float32 and mesh.faces.dtype == np.int32
    with pytest.raises(MeshLoadError, match=r"sq: normals must have shape \(4, 3\), got \(2, 3\)"):
        Mesh(SQUARE_V, [[0, 1, 2]], "sq", normals=np.zeros((2, 3)))
    with pytest.raises(MeshLoadError, match="sq: face material ids must be integers >= -1"):
        mesh.with_detail(face_material=[0, -2])
    # a transform taking vertices past float32 is refused, not cast to inf
    with pytest.raises(MeshLoadError, match=r"within \+-1e30"):
        mesh.transformed(np.diag([1e31, 1.0, 1.0, 1.0]))
    assert np.isfinite(mesh.transformed(np.diag([2.0, 2.0, 2.0, 1.0])).vertices).all()


# ---------------------------------------------------------------------------
# The table of formats


def _rich_gltf_scene() -> trimesh.Scene:
    """Two objects (a textured cube, a sphere with vertex colours and normals) and a camera."""
    from PIL import Image
    box = trimesh.creation.box()
    corners = box.vertices[box.faces].reshape(-1, 3)
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=Image.new("RGB", (2, 2), (9, 99, 199)))
    cube = trimesh.Trimesh(corners, np.arange(len(corners)).reshape(-1, 3), process=False,
                           visual=trimesh.visual.TextureVisuals(uv=corners[:, :2], material=material))
    sphere = trimesh.creation.icosphere(1)
    sphere = trimesh.Trimesh(sphere.vertices, sphere.faces, vertex_normals=sphere.vertices, process=False,
                             vertex_colors=np.tile([255, 0, 0, 255], (len(sphere.vertices), 1)))
    scene = trimesh.Scene()
    scene.add_geometry(cube, node_name="cube")
    scene.add_geometry(sphere, node_name="sphere", transform=trimesh.transformations.translation_matrix([3, 0, 0]))
    scene.set_camera()
    return scene


def format_samples(folder: Path) -> dict:
    """``{extension: (file, faces)}``: a file holding everything its format can say
    besides triangles (OFF: normals too, which clrt does not read), and of two
    objects where the format has several; ``faces`` is how many triangles it has."""
    tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    ply = ("ply\nformat ascii 1.0\nelement vertex 3\n"
           + "".join(f"property float {p}\n" for p in "x y z nx ny nz red green blue u v".split())
           + "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
           + "0 0 0 0 0 1 1 0 0 0 0\n1 0 0 0 0 1 0 1 0 1 0\n0 1 0 0 0 1 0 0 1 0 1\n3 0 1 2\n")
    solid = ("solid {0}\nfacet normal 0 0 1\nouter loop\nvertex 0 0 {1}\nvertex 1 0 {1}\nvertex 0 1 {1}\n"
             "endloop\nendfacet\nendsolid {0}\n")
    scene = _rich_gltf_scene()
    files = {
        ".3ds": (encode_3ds([tetra(), tetra("b", (2.0, 0.0, 0.0))]), 8),
        ".glb": (scene.export(file_type="glb"), 92),
        ".gltf": (trimesh.exchange.gltf.export_gltf(scene, embed_buffers=True)["model.gltf"], 92),
        ".obj": ("mtllib m.mtl\no one\n" + tri + "vt 0 0\nvn 0 0 1\nusemtl red\nf 1/1/1 2/1/1 3/1/1\n"
                 "o two\nv 0 0 1\nf 2/1/1 3/1/1 4/1/1\n", 2),
        ".off": ("CNOFF\n3 1 0\n0 0 0 0 0 1 1 0 0 1\n1 0 0 0 0 1 0 1 0 1\n0 1 0 0 0 1 0 0 1 1\n3 0 1 2\n", 1),
        ".ply": (ply, 1),
        ".stl": (solid.format("a", 0) + solid.format("b", 1), 2),
    }
    (folder / "m.mtl").write_text("newmtl red\nKd 1 0 0\n")
    return {ext: (write(folder, "sample" + ext, data), faces) for ext, (data, faces) in files.items()}


def test_the_table_of_formats_says_what_each_one_carries(tmp_path):
    """Each reader's entry in READERS (colours, normals, texture coordinates,
    materials, several objects, a camera) against what a file that has them
    all gives; a new format needs a sample here."""
    samples = format_samples(tmp_path)
    assert sorted(samples) == list(SUPPORTED_EXTENSIONS)
    for reader in READERS:
        for ext in reader.extensions:
            path, faces = samples[ext]
            mesh, materials = load_asset(path)
            carried = {"colors": mesh.colors is not None, "normals": mesh.normals is not None,
                       "uv": mesh.uv is not None, "materials": bool(materials),
                       "camera": load_module.file_camera(path) is not None}
            claimed = {key: bool(getattr(reader, key)) for key in carried}
            assert carried == claimed, ext
            assert len(mesh.faces) == faces, ext
            if reader.objects:
                assert faces > 1, f"{ext}: its sample should hold two objects"
