"""Robustness: bad input, device faults, output safety, Ctrl-C, and the safety of inputs.

Every bad input ends in one line and a non-zero exit from the CLI, and in a
specific ``clrt.errors`` exception from the API; a failed or interrupted render
leaves an existing output as it was; the device's troubles (a broken kernel
build, allocation failures) are either worked around by tiling -- with the very
same image -- or reported with the sizes involved.
"""

import ast
import functools
import importlib
import os
import pickle
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pyopencl as cl
import pytest
from PIL import Image

import clrt
import clrt.device.program as program_module
from clrt import checks, cli, output
from clrt.errors import (DeviceError, DeviceMemoryError, InputError, KernelBuildError,
                         MeshLoadError, OutputError, TooLargeError)
from clrt.device.geometry import check_fits, part_shifts
from clrt.reference import render_reference
from clrt.renderer import Renderer, TileLimits
from clrt.scene import primitives
from clrt.scene.default import default_scene
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Scene, SceneObject, scene_from_mesh
from clrt.scene.scene_file import load_scene

REPO = Path(__file__).resolve().parents[1]
render_module = importlib.import_module("clrt.renderer.frame")


def _obj(mesh: Mesh) -> str:
    return ("".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
            + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))


def _cli(args, device, capsys):
    dev = ["--device", device] if device else []
    code = cli.main([*args, *dev])
    out, err = capsys.readouterr()
    return code, out, err


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clrt: "), err
    return lines[0]


# ---------------------------------------------------------------------------
# 1. Bad input: one line, non-zero exit, nothing written


_OFF = "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n"
BAD_FILES = {
    "empty.off": b"",
    "blank.obj": b"  \n\n",
    "mesh.xyz": b"1 2 3\n",
    "truncated.off": _OFF[:30].encode(),
    "huge-count.off": b"OFF\n99999999999 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    "nan.obj": b"v 0 0 0\nv nan 1 0\nv 0 1 0\nf 1 2 3\n",
    "inf.obj": b"v 0 0 0\nv inf 1 0\nv 0 1 0\nf 1 2 3\n",
    "huge.obj": b"v 0 0 0\nv 1e38 1 0\nv 0 1 0\nf 1 2 3\n",
    "index.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
    "text.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n0\n",
    "binary-nan.stl": b"\0" * 80 + struct.pack("<I", 1) + struct.pack("<12fH", 0, 0, 1, 0, 0, 0,
                                                                            np.nan, 0, 0, 0, 1, 0, 0),
    "short.stl": b"\0" * 80 + struct.pack("<I", 1000),
    "garbage.glb": b"glTF\x02\0\0\0" + os.urandom(40),
    "garbage.3ds": b"MM\xff\xff\xff\x7f" + b"\0" * 20,
    "points.obj": b"v 0 0 0\nv 1 0 0\n",
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bad_mesh_files(name, tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / name
    path.write_bytes(BAD_FILES[name])
    with pytest.raises(MeshLoadError) as info:
        clrt.load_mesh(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)
    code, out, err = _cli(["render", name, "--width", "8", "--height", "8"], device, capsys)
    assert code == 2
    assert name in _one_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name], "nothing written"


@pytest.mark.parametrize("name, says", [
    ("nan.obj", "1 vertices have NaN or infinite coordinates (the first: vertex 1 at (nan, 1, 0))"),
    ("huge.obj", "vertex coordinates must lie within +-1e30 (the device computes in float32): 1 lie beyond "
                 "(the first: vertex 1 at (1e38, 1, 0))"),
    ("binary-nan.stl", "NaN or infinite coordinates (the first: vertex "),
])
def test_out_of_range_vertices_are_named(name, says, tmp_path):
    """The file and the first vertex out of range, by index and coordinates."""
    path = tmp_path / name
    path.write_bytes(BAD_FILES[name])
    with pytest.raises(MeshLoadError) as info:
        clrt.load_mesh(path)
    assert str(info.value).startswith(f"{path}: ") and says in str(info.value), str(info.value)


def test_missing_unreadable_and_folder_inputs(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dir.obj").mkdir()
    os.mkfifo(tmp_path / "fifo.obj")   # would block a naive reader forever
    for name, fragment in (("missing.obj", "no such file"), ("dir.obj", "directory"),
                           ("fifo.obj", "not a regular file")):
        code, out, err = _cli(["render", name], device, capsys)
        assert code == 2 and fragment in _one_line(err)
        code, out, err = _cli(["info", name], device, capsys)
        assert code == 2 and fragment in _one_line(err)


@pytest.mark.parametrize("args, fragment", [
    (["--width", "-5"], "width"),
    (["--height", "0"], "height"),
    (["--width", "70000"], "width"),
    (["--width", "ten"], "--width"),
    (["--fov", "0"], "fov"),
    (["--fov", "180"], "fov"),
    (["--fov", "-30"], "fov"),
    (["--fov", "nan"], "fov"),
    (["--fov", "inf"], "fov"),
    (["--samples", "0"], "samples"),
    (["--max-depth", "-1"], "--max-depth"),
    (["--leaf-size", "0"], "--leaf-size"),
    (["--eye", "nan,0,0"], "--eye must be 3 finite numbers, got (nan, 0, 0)"),
    (["--eye", "1e39,0,0"], "1e39 overflows float32 (the largest float32 is about 3.4e38)"),
    (["--light", "0,inf,0"], "--light"),
    (["--target", "1,2"], "--target"),
    (["--up", "0,0,0"], "up"),
    (["--accel", "octree"], "--accel"),
    (["-o", "out.psd"], "unknown image type '.psd'"),
    (["--width", "65536", "--height", "65536"], "host memory"),
])
def test_bad_options(args, fragment, tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if "host memory" in fragment:   # the same on any machine: pretend 1 GiB is free
        monkeypatch.setattr(checks, "available_host_memory", lambda: 1 << 30)
    code, out, err = _cli(["render", "--width", "8", "--height", "8", *args], device, capsys)
    assert code == 2
    assert fragment in _one_line(err)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("option", ["--ambient", "--diffuse", "--specular", "--shininess"])
@pytest.mark.parametrize("value", ["nan", "inf", "-1"])
def test_bad_material_values(option, value, tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "box.obj").write_text(_obj(primitives.box()))
    code, out, err = _cli(["render", "box.obj", option, value], device, capsys)
    assert code == 2 and option.lstrip("-") in _one_line(err)


def test_api_errors_are_specific():
    with pytest.raises(InputError, match="width"):
        Camera((0, 0, 5), (0, 0, 0), width=0)
    with pytest.raises(InputError, match="height"):
        Camera((0, 0, 5), (0, 0, 0), height=-3)
    for fov in (0, 180, -1, 200, float("nan"), float("inf")):
        with pytest.raises(InputError, match="fov"):
            Camera((0, 0, 5), (0, 0, 0), fov=fov)
    with pytest.raises(InputError, match="eye and target"):
        Camera((1, 1, 1), (1, 1, 1))
    with pytest.raises(InputError, match="light position"):
        Light((0, float("nan"), 0))
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(MeshLoadError, match="NaN or infinite"):
            Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, bad, 0]], [[0, 1, 2]])
    with pytest.raises(MeshLoadError, match="out of range"):
        Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
    with pytest.raises(MeshLoadError, match="no triangles"):
        Mesh.from_arrays(np.zeros((3, 3)), np.zeros((0, 3), int))
    assert issubclass(MeshLoadError, InputError) and issubclass(OutputError, InputError)
    assert issubclass(TooLargeError, InputError)
    assert issubclass(KernelBuildError, DeviceError) and issubclass(DeviceMemoryError, DeviceError)


def test_render_rejects_bad_samples_and_depth(device):
    r = Renderer(scene_from_mesh(primitives.icosphere(0)), device=device)
    for kwargs in ({"samples": 0}, {"samples": 17}, {"max_depth": -1}, {"max_depth": 99}, {"samples": 1.5}):
        with pytest.raises(InputError):
            r.render(Camera.framing(r.arrays.bounds, 8, 8), **kwargs)


def test_trace_rejects_zero_and_nan_directions(device):
    accel = clrt.Accel(primitives.icosphere(1), device=device)
    o = np.array([[0, 0, 5.0], [0, 0, 5.0]])
    for bad in ([0, 0, 0], [np.nan, 0, -1], [0, np.inf, -1]):
        d = np.array([[0, 0, -1.0], bad])
        with pytest.raises(InputError):
            accel.trace(o, d)
        with pytest.raises(InputError):
            accel.occluded(o, d)
    with pytest.raises(InputError):
        accel.trace([np.nan, 0, 5], [0, 0, -1])
    good = accel.trace(o, np.array([[0, 0, -1.0], [0, 0, -2.0]]))
    assert (good.prim >= 0).all()


def test_zero_area_triangles_are_never_hit(device):
    sphere = primitives.icosphere(2)
    v = sphere.vertices.astype(np.float64)
    n = len(v)
    v = np.concatenate([v, [[0.3, 0.3, 0.3], [0.6, 0.6, 0.6], [0.9, 0.9, 0.9]]])
    degenerate = [[0, 0, 1], [2, 2, 2], [n, n + 1, n + 2], [5, 6, 5]]   # repeated corners, collinear
    mesh = Mesh.from_arrays(v, np.concatenate([sphere.faces, degenerate]))
    camera = Camera.framing(mesh.bounds, 40, 30)
    expected = Renderer(scene_from_mesh(sphere), device=device).render(camera, hits=True)
    for accel, builder in (("none", "sah"), ("box", "sah"), ("box", "paper"), ("sphere", "paper"),
                           ("sphere", "sah"), ("ellipse", "paper"), ("ellipse", "sah")):
        renderer = Renderer(scene_from_mesh(mesh), device=device, accel=accel, builder=builder)
        frame = renderer.render(camera, hits=True)
        assert frame.prim.max() < len(sphere.faces), (accel, builder)
        assert np.array_equal(frame.image, expected.image), (accel, builder)
    # A mesh of nothing but zero-area triangles renders (as background) and traces (as misses).
    flat = Mesh.from_arrays([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], [[0, 1, 2], [1, 2, 3]])
    with pytest.warns(clrt.NothingVisibleWarning, match="zero area"):
        frame = Renderer(scene_from_mesh(flat), device=device).render(Camera.framing(flat.bounds, 8, 8), hits=True)
    assert (frame.prim == -1).all() and not frame.visible
    assert (clrt.trace(flat, [[-1, 0.5, 0.5]], [[1, 0, 0]], device=device).prim == -1).all()


def test_nothing_visible_warns_with_the_reason(device, tmp_path, capsys, monkeypatch):
    """A frame in which no camera ray hits a triangle was an all-black image
    and exit 0, without a word: now a warning (one line from the CLI) saying
    why, read from the frame's own hits (a flag the kernels set)."""
    import warnings
    flat = Mesh.from_arrays([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], [[0, 1, 2], [1, 2, 3]])
    with pytest.warns(clrt.NothingVisibleWarning, match=r"^nothing visible in the 8x6 image, only the background: "
                                                         r"all 2 triangles of the scene have zero area"):
        frame = Renderer(scene_from_mesh(flat), device=device).render(Camera.framing(flat.bounds, 8, 6))
    assert not frame.visible
    sphere = primitives.icosphere(1)
    renderer = Renderer(scene_from_mesh(sphere), device=device)
    with pytest.warns(clrt.NothingVisibleWarning, match=r"the scene lies behind the camera \(the camera at "
                                                         r"\(0, 0, 5\) looks at \(0, 0, 9\)\)"):
        assert not renderer.render(Camera((0, 0, 5), (0, 0, 9), width=8, height=6)).visible
    with pytest.warns(clrt.NothingVisibleWarning, match="no camera ray hits the scene's 80 triangle"):
        renderer.render(Camera((0, 0, 5), (5, 0, 5), width=8, height=6))
    # Seen in one tile of many (the flag starts anew in each tile's first launch): visible, no warning.
    tiled = Renderer(scene_from_mesh(sphere), device=device, limits=TileLimits(max_tile_pixels=64, block=None))
    corner = Camera((-6, -4.5, 20), (-6, -4.5, 0), fov=40, width=32, height=24)   # the sphere in a corner
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frame = tiled.render(corner, hits=True)
        assert frame.tiles > 4 and frame.visible and 0 < (frame.prim >= 0).mean() < 0.2
        assert renderer.render(Camera.framing(sphere.bounds, 8, 6)).visible
    with pytest.warns(clrt.NothingVisibleWarning):   # and the next frame of the same buffers starts anew
        assert not renderer.render(Camera((0, 0, 5), (0, 0, 9), width=8, height=6)).visible
    # The CLI: the image is written, exit 0, and one line says why it is empty.
    monkeypatch.chdir(tmp_path)
    (tmp_path / "degenerate.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    code, out, err = _cli(["render", "degenerate.obj", "--width", "8", "--height", "6", "-q"], device, capsys)
    assert code == 0 and out == f"{tmp_path / 'degenerate.png'}\n"
    assert err == ("clrt: warning: nothing visible in the 8x6 image, only the background: the scene's only "
                   "triangle has zero area (a corrupt or flattened mesh?)\n"), err


def _inside_scene(light_inside: bool) -> tuple[Scene, Camera]:
    sphere = primitives.icosphere(2)
    floor = Mesh.from_arrays([[-4, -1.5, -4], [4, -1.5, -4], [4, -1.5, 4], [-4, -1.5, 4]],
                             [[0, 2, 1], [0, 3, 2]])
    light = Light((0.2, 0.3, 0.1)) if light_inside else Light((3, 5, 3))
    scene = Scene([SceneObject(sphere), SceneObject(floor)], [light], background=(0.1, 0.2, 0.3))
    return scene, Camera((0.1, -0.2, 0.3), (0.0, -0.2, -1.0), width=32, height=24, fov=60)


@pytest.mark.parametrize("light_inside", [False, True])
def test_eye_inside_a_mesh_renders_correctly(light_inside, device):
    scene, camera = _inside_scene(light_inside)
    frame = Renderer(scene, device=device).render(camera, linear=True, hits=True)
    colour, prim, t = render_reference(scene, camera)
    assert (frame.prim >= 0).all() and (frame.prim < 320).all(), "every pixel sees the sphere from inside"
    assert (frame.prim == prim).mean() >= 0.999
    np.testing.assert_allclose(frame.t, t, rtol=1e-5)
    assert (np.abs(frame.image - colour).max(axis=2) <= 2e-3).mean() >= 0.995
    lum = frame.image.sum(axis=2)
    ambient = 0.1 * 0.8 * 3
    if light_inside:
        assert (lum > 1.5 * ambient).mean() > 0.5, "a light inside with the eye lights the inside"
    else:
        np.testing.assert_allclose(lum, ambient, rtol=1e-4)   # the closed sphere shadows the inside


def test_light_inside_a_closed_mesh_shadows_everything_outside(device):
    box = primitives.box((1, 1, 1), center=(0, 0.5, 0))
    floor = Mesh.from_arrays([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], [[0, 2, 1], [0, 3, 2]])
    scene = Scene([SceneObject(floor), SceneObject(box)], [Light((0, 0.5, 0))])
    camera = Camera((3, 4, 5), (0, 0, 0), width=32, height=24)
    frame = Renderer(scene, device=device).render(camera, linear=True, hits=True)
    colour, prim, t = render_reference(scene, camera)
    assert (frame.prim == prim).mean() >= 0.999
    assert (np.abs(frame.image - colour).max(axis=2) <= 2e-3).mean() >= 0.995
    hit = frame.prim >= 0
    np.testing.assert_allclose(frame.image.sum(axis=2)[hit], 0.1 * 0.8 * 3, rtol=1e-4)


_SCENE_HEAD = '[[objects]]\ntype = "sphere"\n'


@pytest.mark.parametrize("text, fragment", [
    ("[camera]\nfov = 180\n" + _SCENE_HEAD, "camera.fov"),
    ("[camera]\nwidth = 0\n" + _SCENE_HEAD, "camera.width"),
    ("[camera]\nheight = -4\n" + _SCENE_HEAD, "camera.height"),
    ("[camera]\neye = [0, 0, nan]\ntarget = [0, 0, 0]\n" + _SCENE_HEAD, "camera.eye"),
    ("[camera]\neye = [1, 1, 1]\ntarget = [1, 1, 1]\n" + _SCENE_HEAD, "eye and target"),
    ("[render]\nsamples = 0\n" + _SCENE_HEAD, "render.samples"),
    ("[[lights]]\nposition = [0, inf, 0]\n" + _SCENE_HEAD, "lights[0].position"),
    (_SCENE_HEAD + "radius = -1\n", "objects[0].radius"),
    (_SCENE_HEAD + "material = { color = [2, 0, 0] }\n", "objects[0].material.color"),
    (_SCENE_HEAD + "colour = 1\n", "objects[0].colour"),
    ('[[objects]]\ntype = "mesh"\npath = "nowhere.obj"\n', "mesh file not found"),
    ("[camera\n", "invalid TOML"),
    ("", "no objects"),
])
def test_bad_scene_file_values(text, fragment, tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_scene(path)
    assert "\n" not in str(info.value) and fragment in str(info.value)
    code, out, err = _cli(["render", "scene.toml"], device, capsys)
    assert code == 2 and fragment in _one_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]


# ---------------------------------------------------------------------------
# 4. Output safety


def _render_args(*args):
    return ["render", "--width", "16", "--height", "12", "-q", *args]


def test_rerun_replaces_its_own_output_but_not_a_users_file(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # `clrt render` twice, as the quick start does: the second run replaces the first image.
    assert _cli(_render_args(), device, capsys)[0] == 0
    first = (tmp_path / "clrt-default.png").read_bytes()
    assert output.written_by_clrt(tmp_path / "clrt-default.png")
    code, out, err = _cli(_render_args("--width", "20"), device, capsys)
    assert code == 0, err
    assert Image.open(tmp_path / "clrt-default.png").size == (20, 12)
    assert (tmp_path / "clrt-default.png").read_bytes() != first
    # A file clrt did not write is refused before rendering, untouched ...
    photo = tmp_path / "photo.png"
    Image.fromarray(np.full((4, 4, 3), 7, np.uint8)).save(photo)
    before = photo.read_bytes()
    code, out, err = _cli(_render_args("-o", "photo.png"), device, capsys)
    assert code == 2 and "--force" in _one_line(err)
    assert photo.read_bytes() == before
    # ... and replaced with --force, after which it is clrt's own.
    assert _cli(_render_args("-o", "photo.png", "--force"), device, capsys)[0] == 0
    assert Image.open(photo).size == (16, 12) and output.written_by_clrt(photo)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".clrt-default.png.clrt", ".photo.png.clrt",
                                                         "clrt-default.png", "photo.png"]


@pytest.mark.parametrize("suffix", [".png", ".jpg", ".tif", ".webp", ".gif"])
def test_every_marked_format_is_recognised(suffix, tmp_path):
    path = tmp_path / f"a{suffix}"
    output.write_image(np.zeros((4, 4, 3), np.uint8), path)
    assert output.written_by_clrt(path)
    output.write_image(np.ones((4, 4, 3), np.uint8), path)   # replacing its own: no force needed
    (tmp_path / f"b{suffix}").write_bytes(path.read_bytes()[:20])
    assert not output.written_by_clrt(tmp_path / f"b{suffix}")


def test_output_never_replaces_folders_or_special_files(tmp_path):
    os.mkfifo(tmp_path / "pipe.png")
    for force in (False, True):
        with pytest.raises(OutputError, match="not a regular file"):
            output.write_image(np.zeros((2, 2, 3), np.uint8), tmp_path / "pipe.png", force=force)
    (tmp_path / "text.png").write_text("notes")
    with pytest.raises(OutputError, match="--force"):
        output.write_image(np.zeros((2, 2, 3), np.uint8), tmp_path / "text.png")
    assert (tmp_path / "text.png").read_text() == "notes"


def test_new_output_gets_normal_permissions_and_keeps_replaced_ones(tmp_path):
    umask = os.umask(0o022)
    try:
        output.write_image(np.zeros((2, 2, 3), np.uint8), tmp_path / "a.png")
        assert (tmp_path / "a.png").stat().st_mode & 0o777 == 0o644
        os.chmod(tmp_path / "a.png", 0o640)
        output.write_image(np.zeros((2, 2, 3), np.uint8), tmp_path / "a.png")
        assert (tmp_path / "a.png").stat().st_mode & 0o777 == 0o640
    finally:
        os.umask(umask)


@pytest.mark.parametrize("name", ["a.png", "a.tif"])   # clrt's own PNG writer, Pillow's TIFF writer
def test_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch, name):
    path = tmp_path / name
    output.write_image(np.zeros((2, 2, 3), np.uint8), path)
    before = path.read_bytes()
    fdopen = os.fdopen

    class FullDisk:   # the temporary file fills the disk after a few bytes
        def __init__(self, *args, **kwargs):
            self.file = fdopen(*args, **kwargs)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.file.close()

        def write(self, data):
            self.file.write(bytes(data)[:7])
            raise OSError(28, "No space left on device")

        def __getattr__(self, name):
            return getattr(self.file, name)
    monkeypatch.setattr(os, "fdopen", FullDisk)
    with pytest.raises(OutputError, match="No space left"):
        output.write_image(np.ones((2, 2, 3), np.uint8), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [f".{name}.clrt", name]


def test_failed_render_leaves_existing_output_untouched(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert _cli(_render_args(), device, capsys)[0] == 0
    before = (tmp_path / "clrt-default.png").read_bytes()

    def broken(self, *args, **kwargs):
        raise DeviceError("the device fell over")
    monkeypatch.setattr(Renderer, "render", broken)
    code, out, err = _cli(_render_args(), device, capsys)
    assert code == 3 and "fell over" in _one_line(err)
    assert (tmp_path / "clrt-default.png").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [".clrt-default.png.clrt", "clrt-default.png"]


def test_unwritable_folder_fails_before_rendering(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rendered = []
    monkeypatch.setattr(Renderer, "__init__", lambda *a, **k: rendered.append(1) or None)
    real_access = os.access
    monkeypatch.setattr(cli.os, "access", lambda p, mode: False if mode == os.W_OK else real_access(p, mode))
    code, out, err = _cli(_render_args("-o", "x.png"), device, capsys)
    assert code == 2 and "no permission" in _one_line(err)
    assert not rendered


# ---------------------------------------------------------------------------
# 5. Device faults


def test_kernel_build_failure_shows_the_compiler_log(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    broken = "__kernel void generate_rays(__global int* x) { x[0] = no_such_identifier_42; }\n"
    monkeypatch.setattr(program_module, "expand_source", lambda entry: broken)
    ctx, _ = clrt.device.context.create_context(device)
    with pytest.raises(KernelBuildError) as info:
        program_module.build_program(ctx, "render.cl")
    assert "render.cl" in str(info.value) and "no_such_identifier_42" in str(info.value)
    # (the host builder, so that render.cl is the first program built)
    code, out, err = _cli(_render_args("--builder", "sah"), device, capsys)
    assert code == 3
    assert err.startswith("clrt: OpenCL build of render.cl failed") and "no_such_identifier_42" in err
    assert "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_tiny_tiles_give_the_identical_image(device):
    scene = default_scene(40, 30, coarse=True)
    whole = Renderer(scene, device=device)
    expected = whole.render(hits=True, samples=2)
    assert expected.tiles == 1
    tiled = Renderer(scene, device=device, limits=TileLimits(max_tile_pixels=37, first_launch_pixels=37))
    # pieces of rows: 37 + 3 pixels
    frame = tiled.render(hits=True, samples=2)
    assert frame.tiles == 2 * 30
    for name in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, name), getattr(expected, name)), name
    linear = tiled.render(linear=True)
    assert np.array_equal(linear.image, whole.render(linear=True).image)
    # bands of 8 rows, read back in place
    banded = Renderer(scene, device=device, limits=TileLimits(max_tile_pixels=40 * 9, first_launch_pixels=40 * 9))
    frame = banded.render(hits=True, samples=2)
    assert frame.tiles == 4
    for name in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, name), getattr(expected, name)), name


def test_frames_kept_by_the_caller_are_never_overwritten(device):
    scene = default_scene(40, 30, coarse=True)
    r = Renderer(scene, device=device)
    near = scene.camera
    far = Camera(tuple(3 * np.asarray(near.eye)), near.target, near.up, near.fov, 40, 30)
    kept = [r.render(near).image for _ in range(5)]        # more frames than the pool holds
    copies = [k.copy() for k in kept]
    view = kept[0][10:20]                                  # a view keeps its image in use too
    del kept[0]
    other = r.render(far).image
    assert not np.array_equal(other, copies[0])
    assert np.array_equal(view, copies[0][10:20])
    for image, copy in zip(kept, copies[1:]):
        assert np.array_equal(image, copy)
    del view, kept, other
    again = [r.render(far).image for _ in range(10)]       # dropped images are reused, not piled up
    assert r.image_pool.buffers() <= 3 and all(np.array_equal(a, again[0]) for a in again)


def test_launches_are_split_to_stay_short(device):
    scene = scene_from_mesh(primitives.torus())
    camera = Camera.framing(scene.bounds, 48, 36)
    expected = Renderer(scene, device=device).render(camera)
    # "a watchdog of 0.1 microseconds"
    r = Renderer(scene, device=device, limits=TileLimits(launch_ms=1e-4, first_launch_pixels=64))
    frame = r.render(camera)
    assert frame.tiles > 20
    assert np.array_equal(frame.image, expected.image)


def _fake_allocation_failure(monkeypatch, above_pixels: int):
    """Launches over more than ``above_pixels`` work items fail as an out-of-memory
    device does (NVIDIA allocates buffers lazily, at their first use)."""
    real = cl.enqueue_nd_range_kernel
    failures = []

    def launch(queue, kernel, global_size, local_size, *args, **kwargs):
        work_items = int(np.prod(global_size))
        if work_items > above_pixels:
            failures.append(work_items)
            record = cl._cl._ErrorRecord("clEnqueueNDRangeKernel",
                                         cl.status_code.MEM_OBJECT_ALLOCATION_FAILURE, "fake")
            raise cl.MemoryError(record)
        return real(queue, kernel, global_size, local_size, *args, **kwargs)
    monkeypatch.setattr(render_module.cl, "enqueue_nd_range_kernel", launch)
    return failures


def test_out_of_memory_shrinks_the_tiles(device, monkeypatch):
    scene = scene_from_mesh(primitives.icosphere(2))
    camera = Camera.framing(scene.bounds, 48, 36)
    expected = Renderer(scene, device=device).render(camera, hits=True)
    r = Renderer(scene, device=device)
    failures = _fake_allocation_failure(monkeypatch, 500)
    frame = r.render(camera, hits=True)
    # One failure, then tiles of at most 1728 / 4 = 432 pixels: bands of 8 rows (and the last 4).
    assert failures == [48 * 40]            # 36 rows, launched in blocks of 8
    assert frame.tiles == 5
    assert np.array_equal(frame.image, expected.image) and np.array_equal(frame.prim, expected.prim)


def test_out_of_memory_at_the_smallest_tile_says_what_is_needed(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _fake_allocation_failure(monkeypatch, 0)
    r = Renderer(scene_from_mesh(primitives.icosphere(1)), device=device, builder="sah")   # the frame's failure
    with pytest.raises(DeviceMemoryError) as info:
        r.render(Camera.framing(r.arrays.bounds, 48, 36))
    message = str(info.value)
    assert "MEM_OBJECT_ALLOCATION_FAILURE" in message and "the scene needs" in message
    assert "256 pixels" in message and "\n" not in message
    for builder in ("sah", "device"):   # the device builder's launches fail first
        code, out, err = _cli(_render_args("--builder", builder), device, capsys)
        assert code == 3 and "out of device memory" in _one_line(err), err
    assert list(tmp_path.iterdir()) == []


def test_scene_larger_than_the_device_is_refused_with_sizes():
    arrays = {"triangles": np.zeros((1000, 12), np.float32), "BVH nodes": np.zeros((10, 12), np.float32)}
    # Larger than one allocation: split into parts, up to four of them (split.cl).
    assert part_shifts(arrays, 1 << 20) is None
    assert part_shifts(arrays, 20_000) == {"triangles": 8, "BVH nodes": 8}    # 256 rows of 48 B a part
    # 4 x 9.8 KiB would hold 46.9 KiB, but a part holds a power of two of rows:
    # 128 rows (6 KiB) each, 512 rows in all; the message says so, and names
    # where the limit came from.
    with pytest.raises(DeviceMemoryError, match=r"triangles buffer needs 46.9 KiB \(1,000 elements of 48 B\), "
                                                r"more than 4 parts can hold: each part holds a power-of-two "
                                                r"number of elements .* at most 128 \(6.0 KiB\) in a buffer of at "
                                                r"most 9.8 KiB \(the device's largest allocation\), so 4 parts "
                                                r"hold 512 elements \(24.0 KiB\)"):
        part_shifts(arrays, 10_000)
    with pytest.raises(DeviceMemoryError, match=r"9.8 KiB \(set by --max-buffer-mib 0.01\)"):
        part_shifts(arrays, 10_000, "set by --max-buffer-mib 0.01")
    tiny = SimpleNamespace(max_mem_alloc_size=1 << 20, global_mem_size=50_000)
    with pytest.raises(DeviceMemoryError, match="has 48.8 KiB"):
        check_fits(tiny, "a tiny GPU", sum(a.nbytes for a in arrays.values()), render_module.MIN_FRAME_BYTES)


def test_a_lowered_buffer_limit_is_named_in_the_error(device):
    """python -m benchmarks.speed --max-buffer-mib: a scene that four parts of
    that size cannot hold fails naming the option, not the device's limit."""
    from clrt.query import Accel
    from clrt.scene import primitives
    mesh = primitives.icosphere(4)          # 5,120 triangles, 48 B each
    with pytest.raises(DeviceMemoryError, match=r"at most 2.0 KiB \(set by --max-buffer-mib x\)"):
        Accel(mesh, device=device, max_buffer_bytes=2048, max_buffer_label="--max-buffer-mib x")


@pytest.mark.parametrize("builder", ["sah", "paper"])
def test_device_bytes_are_the_bytes_uploaded_wide_bvh_included(builder, device, monkeypatch):
    """Renderer.device_bytes, and the figure both memory checks compare with the
    device before any upload, are the sizes of the buffers actually made -- on
    CPU devices the wide BVH (nodes and triangle packets) among them."""
    import clrt.device.scene as scene_module
    from clrt.device.context import device_kind
    checked = []
    real = scene_module.check_fits

    def check(dev, label, nbytes, *rest):
        checked.append(nbytes)
        real(dev, label, nbytes, *rest)
    monkeypatch.setattr(scene_module, "check_fits", check)

    mesh = primitives.icosphere(3)
    r = Renderer(scene_from_mesh(mesh), device=device, builder=builder)
    made = {b.int_ptr: b.size for parts in r.geometry.buffers.values() for b in parts}
    made[r.tables.int_ptr] = r.tables.size
    assert r.device_bytes == sum(made.values())
    assert checked == [r.device_bytes], "checked with the same figure, once"
    wide = r.geometry.wide
    if device_kind(r.queue.device) == "cpu":   # PoCL: the wide BVH is built, uploaded and counted
        assert wide is not None
        assert r.geometry.buffers["wide"][0].size == wide.nodes.nbytes + wide.packets.nbytes > 0
    a = clrt.Accel(mesh, builder=builder, device=device)
    uploaded = sum({b.int_ptr: b.size for parts in a.geometry.buffers.values() for b in parts}.values())
    assert checked[1:] == [uploaded]
    assert a.memory()["scene"] == uploaded
    if a.geometry.wide is not None:
        assert uploaded == (a.acceleration.device_bytes() + a.geometry.wide.nodes.nbytes
                            + a.geometry.wide.packets.nbytes)


def test_failed_upload_is_a_device_memory_error(device, monkeypatch):
    def refuse(*args, **kwargs):
        raise cl.MemoryError(cl._cl._ErrorRecord("clCreateBuffer", cl.status_code.OUT_OF_RESOURCES, "fake"))
    import clrt.device.scene as scene_module
    monkeypatch.setattr(scene_module, "DeviceGeometry", refuse)
    with pytest.raises(DeviceMemoryError, match="OUT_OF_RESOURCES"):
        Renderer(scene_from_mesh(primitives.icosphere(1)), device=device)
    with pytest.raises(DeviceMemoryError, match="OUT_OF_RESOURCES"):   # the ray queries share the upload
        clrt.Accel(primitives.icosphere(1), device=device)


def test_ctrl_c_between_launches_stops_cleanly(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scene = default_scene(32, 24, coarse=True)
    r = Renderer(scene, device=device)
    expected = r.render()
    real_wait, calls = render_module.wait_for, []

    def interrupted(event):
        real_wait(event)
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
    monkeypatch.setattr(render_module, "wait_for", interrupted)
    r.limits = TileLimits(first_launch_pixels=100, max_tile_pixels=100)
    with pytest.raises(KeyboardInterrupt):
        r.render()
    assert len(calls) == 3
    assert np.array_equal(r.render().image, expected.image), "the renderer still works afterwards"
    # Through the CLI: exit 130, no output, an existing output untouched, no temporary file.
    (tmp_path / "keep.png").write_bytes(b"old")
    calls.clear()
    # Renderers the CLI makes start with tiles of 50 pixels, as on a slow device.
    monkeypatch.setattr(render_module, "TileLimits", functools.partial(TileLimits, first_launch_pixels=50))
    code, out, err = _cli(_render_args("-o", "keep.png", "-f"), device, capsys)
    assert code == 130 and _one_line(err) == "clrt: interrupted"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.png"]
    assert (tmp_path / "keep.png").read_bytes() == b"old"


def test_real_sigint_stops_the_cli_between_launches(tmp_path):
    """The user presses Ctrl-C during a long render: exit 130 within a launch, nothing written."""
    script = textwrap.dedent("""
        import importlib, sys
        from clrt import cli
        import functools
        r = importlib.import_module("clrt.renderer.frame")
        r.TileLimits = functools.partial(r.TileLimits, first_launch_pixels=64, max_tile_pixels=64)
        real = r.wait_for
        def wait(event):
            real(event)
            print("launch", flush=True)
        r.wait_for = wait
        sys.exit(cli.main(sys.argv[1:]))
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", script, "render", "--width", "640", "--height", "480",
                             "--samples", "4", "-o", "big.png"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "launch", proc.stderr.read()
        proc.send_signal(signal.SIGINT)
        sent = time.monotonic()
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert time.monotonic() - sent < 10
    assert err.strip().splitlines()[-1] == "clrt: interrupted" and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------
# 7. Safety of inputs


_FORBIDDEN_CALLS = {"eval", "exec", "compile", "__import__"}
_FORBIDDEN_MODULES = {"pickle", "cPickle", "dill", "marshal", "shelve", "joblib", "yaml"}


def test_no_code_in_clrt_executes_content():
    """No eval/exec, no pickle-like module, no np.load(allow_pickle=True) anywhere in clrt."""
    problems = []
    for path in sorted((REPO / "clrt").rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            where = f"{path.relative_to(REPO)}:{getattr(node, 'lineno', 0)}"
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FORBIDDEN_CALLS:
                problems.append(f"{where} calls {node.func.id}")
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                problems += [f"{where} imports {n}" for n in names if n.split(".")[0] in _FORBIDDEN_MODULES]
            if isinstance(node, ast.keyword) and node.arg == "allow_pickle":
                problems.append(f"{where} passes allow_pickle")
    assert not problems, problems


class _Payload:
    def __reduce__(self):
        return (os.mkdir, (os.path.join(os.environ["CLRT_TEST_SENTINEL"], "executed"),))


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply", ".stl", ".glb", ".gltf", ".3ds"])
def test_a_pickle_or_script_in_a_mesh_file_is_never_run(ext, tmp_path, monkeypatch):
    monkeypatch.setenv("CLRT_TEST_SENTINEL", str(tmp_path))
    for k, data in enumerate([pickle.dumps(_Payload()),
                              b"__import__('os').mkdir('executed')\n",
                              b'{"asset": {"version": "2.0"}, "extras": "__import__(\'os\')"}']):
        path = tmp_path / f"payload{k}{ext}"
        path.write_bytes(data)
        monkeypatch.chdir(tmp_path)
        with pytest.raises(MeshLoadError):
            clrt.load_mesh(path)
    assert not (tmp_path / "executed").exists()


def test_gltf_buffers_only_from_regular_files_beside_it(tmp_path):
    import json

    import trimesh
    scene = trimesh.Scene(trimesh.creation.box())
    doc = json.loads(trimesh.exchange.gltf.export_gltf(scene, embed_buffers=True)["model.gltf"])
    secret = tmp_path / "secret.bin"
    secret.write_bytes(b"\0" * 4096)
    (tmp_path / "models").mkdir()
    os.mkfifo(tmp_path / "models" / "fifo.bin")
    for uri, fragment in (("../secret.bin", "escapes"), (str(secret), "escapes"), ("fifo.bin", "regular file")):
        doc["buffers"][0]["uri"] = uri
        path = tmp_path / "models" / "m.gltf"
        path.write_text(json.dumps(doc))
        with pytest.raises(MeshLoadError, match=fragment):
            clrt.load_mesh(path)


def test_scene_file_mesh_paths_are_relative_to_the_scene_file(tmp_path, device, capsys, monkeypatch):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "scenes").mkdir()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "meshes" / "box.obj").write_text(_obj(primitives.box((1, 2, 3))))
    (tmp_path / "scenes" / "s.toml").write_text(
        '[camera]\nwidth = 16\nheight = 12\n[[objects]]\ntype = "mesh"\npath = "../meshes/box.obj"\n')
    monkeypatch.chdir(tmp_path / "elsewhere")
    scene = load_scene("../scenes/s.toml")
    np.testing.assert_allclose(scene.bounds, [[-0.5, -1, -1.5], [0.5, 1, 1.5]])
    code, out, err = _cli(["render", str(tmp_path / "scenes" / "s.toml"), "-q", "-o", "s.png"], device, capsys)
    assert code == 0, err
    assert (tmp_path / "elsewhere" / "s.png").is_file()
