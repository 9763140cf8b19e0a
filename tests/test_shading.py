"""Smooth shading normals: coincident vertices merged, hard edges kept at creases.

An STL file (a vertex per face corner) and an OBJ file (shared vertices) of
the same mesh render the same; a box keeps flat faces; a sphere stays round.
The work is on the host (Mesh.split_at_creases), so the reference tracer sees
the very same normals.
"""

import struct

import numpy as np
import pytest
from PIL import Image

import clrt
from clrt import cli
from clrt.reference import render_reference
from clrt.scene import primitives
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Material, scene_from_mesh
from clrt.scene.scene_file import load_scene


def _unwelded(mesh: Mesh) -> Mesh:
    """Every face with its own three vertices, as an STL file stores it."""
    return Mesh(mesh.vertices[mesh.faces].reshape(-1, 3),
                np.arange(3 * len(mesh.faces), dtype=np.int32).reshape(-1, 3), mesh.name)


def _write_obj(mesh: Mesh, path):
    # repr of the float32 values as float64: read back to the same float32 bits
    path.write_text("".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in mesh.vertices)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))


def _write_stl(mesh: Mesh, path):
    tri = mesh.vertices[mesh.faces].astype("<f4")
    rows = b"".join(struct.pack("<3f", 0, 0, 0) + t.tobytes() + b"\0\0" for t in tri)
    path.write_bytes(b"\0" * 80 + struct.pack("<I", len(tri)) + rows)


def _box_on_torus() -> Mesh:
    """Curved and hard-edged parts in one mesh."""
    torus = primitives.torus(1.0, 0.35, 24, 12)
    box = primitives.box((0.8, 0.8, 0.8), center=(0.0, 0.8, 0.0))
    return Mesh.concatenate([torus, box], "box on torus")


def test_split_keeps_triangles_and_merges_corners():
    box = primitives.box()
    split = box.split_at_creases()
    assert len(split.vertices) == 24, "four corners of each of the six faces"
    np.testing.assert_array_equal(split.vertices[split.faces], box.vertices[box.faces])   # same triangles, bits
    for f, n in enumerate(box.face_normals()):
        np.testing.assert_allclose(split.vertex_normals()[split.faces[f]], [n] * 3, atol=1e-6)
    smooth = box.split_at_creases(180)
    assert len(smooth.vertices) == 8
    sphere = primitives.icosphere(2)
    assert len(sphere.split_at_creases().vertices) == len(sphere.vertices)
    # An STL-like copy of the sphere becomes the very same shading mesh.
    welded = _unwelded(sphere).split_at_creases()
    np.testing.assert_array_equal(welded.faces, sphere.split_at_creases().faces)
    np.testing.assert_array_equal(welded.vertices, sphere.split_at_creases().vertices)


def test_stl_and_obj_of_one_mesh_render_identically(tmp_path, device):
    mesh = _box_on_torus()
    _write_obj(mesh, tmp_path / "m.obj")
    _write_stl(mesh, tmp_path / "m.stl")
    assert len(clrt.load_mesh(tmp_path / "m.stl").vertices) == 3 * len(mesh.faces)   # as the file stores it
    obj = clrt.render(tmp_path / "m.obj", width=64, height=48, device=device)
    stl = clrt.render(tmp_path / "m.stl", width=64, height=48, device=device)
    np.testing.assert_array_equal(obj, stl)
    flat = clrt.render(clrt.scene_from_mesh(tmp_path / "m.stl", {"smooth": False}), width=64, height=48,
                       device=device)
    assert (np.abs(flat.astype(int) - stl).max(axis=2) > 8).sum() > 50, "the torus is smooth, not faceted"


def _render(mesh, material, device, size=(64, 48)):
    scene = scene_from_mesh(mesh, material)
    camera = Camera.framing(scene.bounds, *size)
    return clrt.Renderer(scene, device=device).render(camera).image.astype(int)


def test_a_box_renders_with_flat_faces_and_a_sphere_stays_smooth(device):
    box = primitives.box((1.0, 0.6, 1.4))
    smooth, flat = _render(box, Material(), device), _render(box, Material(smooth=False), device)
    blob = _render(box, Material(crease=180), device)
    assert np.abs(smooth - flat).max() <= 2, "a box's faces stay flat"
    assert np.abs(blob - flat).max() > 30, "blending over 90-degree edges makes a blob"

    sphere = primitives.icosphere(2)
    smooth, flat = _render(sphere, Material(), device), _render(sphere, Material(smooth=False), device)
    np.testing.assert_array_equal(smooth, _render(sphere, Material(crease=180), device))
    assert (np.abs(smooth - flat).max(axis=2) > 8).sum() > 50, "the sphere is not faceted"


def test_crease_normals_match_the_reference(device):
    scene = scene_from_mesh(_box_on_torus(), Material(crease=40))
    camera = Camera.framing(scene.bounds, 40, 30)
    frame = clrt.Renderer(scene, device=device).render(camera, linear=True, hits=True)
    color, prim, _ = render_reference(scene, camera)
    assert (frame.prim == prim).mean() >= 0.999
    same = (frame.prim == prim) & (prim >= 0)
    assert same.sum() > 100
    assert (np.abs(frame.image - color).max(axis=2)[same] <= 2e-3).mean() >= 0.995


def test_crease_from_the_cli_and_scene_files(tmp_path, device, capsys):
    box = primitives.box((1.0, 0.6, 1.4))
    _write_obj(box, tmp_path / "box.obj")
    dev = ["--device", device] if device else []
    images = {}
    for crease in ("45", "180"):
        out = tmp_path / f"c{crease}.png"
        assert cli.main(["render", str(tmp_path / "box.obj"), "-o", str(out), "--width", "48", "--height", "36",
                         "--crease", crease, "-q", *dev]) == 0, capsys.readouterr().err
        images[crease] = np.asarray(Image.open(out)).astype(int)
    assert np.abs(images["45"] - images["180"]).max() > 30
    (tmp_path / "s.toml").write_text('[[objects]]\ntype = "mesh"\npath = "box.obj"\nmaterial = { crease = 10 }\n')
    assert load_scene(tmp_path / "s.toml").objects[0].material.crease == 10


@pytest.mark.parametrize("crease", [0, 30, 90])
def test_every_corner_keeps_its_position(crease):
    mesh = _unwelded(primitives.torus(1.0, 0.35, 12, 6))
    split = mesh.split_at_creases(crease)
    np.testing.assert_array_equal(split.vertices[split.faces], mesh.vertices[mesh.faces])
    assert len(split.vertices) <= len(mesh.vertices)
