"""Command-line options do what they say on every kind of input, and the CLI's
small promises hold (one path printed, one error line, --version, Ctrl-C)."""

import json
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import clrt
from clrt import cli
from clrt.scene import primitives

REPO = Path(__file__).resolve().parents[1]
SHOWCASE = REPO / "assets" / "scenes" / "showcase.toml"


def _cli(args, device, capsys):
    dev = ["--device", device] if device else []
    code = cli.main([*args, *dev])
    out, err = capsys.readouterr()
    return code, out, err


def _obj(mesh, path):
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
    return path


# ---------------------------------------------------------------------------
# Material options override every object's material (scene files, built-in scene)

MATERIAL_OPTIONS = [["--color", "1,0,0"], ["--flat"], ["--ambient", "0.6"], ["--diffuse", "0.1"],
                    ["--specular", "0"], ["--shininess", "2"]]


@pytest.mark.parametrize("source", ["showcase", "built-in"])
def test_material_options_change_the_pixels(source, tmp_path, device, capsys):
    base = ([str(SHOWCASE)] if source == "showcase" else []) + [
        "--width", "48", "--height", "36", "--samples", "1", "--max-depth", "1", "--builder", "paper", "-q"]
    images = {}
    # The built-in scene has ~68,000 triangles: three options there, all on the showcase.
    options = MATERIAL_OPTIONS if source == "showcase" else [["--color", "1,0,0"], ["--flat"], ["--specular", "0"]]
    for extra in [[]] + options:
        out = tmp_path / f"{'_'.join(extra).strip('-') or 'plain'}.png"
        code, _, err = _cli(["render", *base, *extra, "-o", str(out)], device, capsys)
        assert code == 0, err
        images[" ".join(extra)] = np.asarray(Image.open(out)).astype(int)
    plain = images.pop("")
    for option, image in images.items():
        changed = (np.abs(image - plain).max(axis=2) > 2).sum()
        assert changed > 8, f"{option} left the {source} scene as it was ({changed} pixels changed)"
    red = images["--color 1,0,0"]
    redness = (red[..., 0] - red[..., 1]).mean(), (plain[..., 0] - plain[..., 1]).mean()
    assert (red[..., 1] <= plain[..., 1]).all() and redness[0] > redness[1] + 10


def test_override_materials_replaces_only_the_fields_given():
    scene = clrt.load_scene(SHOWCASE)
    before = [o.material for o in scene.objects]
    scene.override_materials(color=(1, 0, 0), ambient=None)
    for old, o in zip(before, scene.objects):
        assert o.material.color == (1.0, 0.0, 0.0)
        assert (o.material.ambient, o.material.ior, o.material.smooth) == (old.ambient, old.ior, old.smooth)


# ---------------------------------------------------------------------------
# Camera nodes of glTF files

def _glb_with_camera(mesh, path, eye, yfov, aspect):
    """A GLB written by trimesh, with a camera node added (trimesh writes the
    camera but no node that places it)."""
    import trimesh
    data = trimesh.Scene(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)).export(file_type="glb")
    (length,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + length])
    rest = data[20 + length:]
    doc["cameras"] = [{"type": "perspective",
                       "perspective": {"yfov": yfov, "aspectRatio": aspect, "znear": 0.01}}]
    # A parent node moves the camera: parents' transforms apply.
    doc["nodes"] += [{"translation": [0.0, 0.0, eye[2] - 1.0], "children": [len(doc["nodes"]) + 1]},
                     {"camera": 0, "translation": [eye[0], eye[1], 1.0]}]
    doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 2)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 20 + len(text) + len(rest))
                     + struct.pack("<II", len(text), 0x4E4F534A) + text + rest)


def test_a_glb_camera_node_is_used(tmp_path, device, capsys):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    glb = tmp_path / "t.glb"
    _glb_with_camera(mesh, glb, eye=(0.3, 0.2, 4.0), yfov=np.radians(40.0), aspect=1.5)
    out = tmp_path / "t.png"
    assert clrt.scene_from_mesh(glb).camera.width == 720, "480 pixels high, the file's aspect ratio"
    code, text, err = _cli(["render", str(glb), "-o", str(out), "--width", "60", "--height", "40"], device, capsys)
    assert code == 0, err
    assert f"camera from {glb}" in text.splitlines()[0]
    image = np.asarray(Image.open(out))
    assert image.shape == (40, 60, 3)
    # The same view, given by hand through the Python API:
    camera = clrt.Camera((0.3, 0.2, 4.0), (0.3, 0.2, 0.0), fov=40.0, width=60, height=40)
    expected = clrt.render(mesh, camera, device=device)
    np.testing.assert_array_equal(image, expected)
    assert not np.array_equal(clrt.render(mesh, width=60, height=40, device=device), expected)
    assert np.array_equal(clrt.render(glb, width=60, height=40, device=device), expected)
    # an explicit camera option wins, and the summary no longer claims the file's
    code, text, err = _cli(["render", str(glb), "-o", str(out), "--width", "60", "--height", "40", "--eye", "0,3,3"],
                           device, capsys)
    assert code == 0 and "camera from" not in text


# ---------------------------------------------------------------------------
# Small promises

def test_output_path_is_printed_absolute_with_and_without_q(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _obj(primitives.icosphere(1), tmp_path / "m.obj")
    for quiet in ([], ["-q"]):
        code, out, err = _cli(["render", "m.obj", "-o", "x.png", "--width", "8", "--height", "8", *quiet],
                              device, capsys)
        assert code == 0, err
        assert out.splitlines()[-1] == str(tmp_path / "x.png")
    assert "BVH of boxes" in _cli(["render", "m.obj", "-o", "x.png", "--width", "8", "--height", "8"],
                                  device, capsys)[1]
    assert "BVH of ellipsoids" in _cli(["render", "m.obj", "-o", "x.png", "--width", "8", "--height", "8",
                                        "--accel", "ellipse"], device, capsys)[1]


@pytest.mark.parametrize("output, fragment", [
    ("", "-o must name an image file, got ''"),
    (" ", "-o must name an image file, got ' '"),
    ("folder", "cannot write folder: it is a folder"),
    ("newfolder/", "names a folder"),
    ("x", "no image type suffix"),
])
def test_bad_output_names(output, fragment, tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    code, out, err = _cli(["render", "-o", output, "--width", "8", "--height", "8"], device, capsys)
    assert code == 2 and err.count("\n") == 1 and fragment in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder"]


def test_usage_errors_are_prefixed_once(capsys):
    assert cli.main(["render", "--widht", "3"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("clrt: ") and "clrt: clrt" not in err and err.count("\n") == 1


def test_version(capsys):
    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"clrt {clrt.__version__}"


def test_info_mesh_uses_the_device(tmp_path, capsys):
    mesh = _obj(primitives.icosphere(1), tmp_path / "m.obj")
    assert cli.main(["info", str(mesh), "--device", "7:7"]) == 3
    assert cli.main(["info", str(mesh), "--device", "nope"]) == 2
    capsys.readouterr()


def test_bench_bad_size_makes_no_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["bench", "--size", "0x0", "--out", "results"]) == 2
    assert "1..65536" in capsys.readouterr().err
    assert not (tmp_path / "results").exists()


def test_bench_missing_scan_suggests_mesh_dir(tmp_path, capsys):
    code = cli.main(["bench", "--meshes", "camel", "--mesh-dir", str(tmp_path / "none"),
                     "--out", str(tmp_path / "r")])
    assert code == 2 and "--mesh-dir" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_ctrl_c_while_starting_is_one_line_and_130(tmp_path):
    """Ctrl-C during the imports (before main runs) ends as cleanly as a later one."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "clrt", "render", "-o", "x.png"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(0.2)   # the interpreter is up, clrt's imports (about 0.5 s) are running
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err == "clrt: interrupted\n"
    assert list(tmp_path.iterdir()) == []


def test_a_glb_camera_is_read_from_the_json_chunk_alone(tmp_path):
    """The camera comes from the JSON chunk: the binary chunk (the buffers,
    read once already with the mesh) is not read again -- here it is cut
    short, which the mesh loader would refuse."""
    from clrt.scene.load import file_camera
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    glb = tmp_path / "t.glb"
    _glb_with_camera(mesh, glb, eye=(0.3, 0.2, 4.0), yfov=np.radians(40.0), aspect=1.5)
    whole = file_camera(glb)
    data = glb.read_bytes()
    (length,) = struct.unpack_from("<I", data, 12)
    glb.write_bytes(data[:20 + length + 12])             # the binary chunk's header and a few bytes
    cut = file_camera(glb)
    assert cut is not None and np.allclose(cut["eye"], (0.3, 0.2, 4.0)) and cut["aspect"] == 1.5
    assert all(np.array_equal(np.asarray(cut[k]), np.asarray(whole[k])) for k in whole)


@pytest.mark.parametrize("command", [["render", "--width", "8", "--height", "8"], ["info"]])
def test_a_malformed_pyopencl_ctx_is_bad_input_like_device(command, tmp_path, capsys, monkeypatch):
    """PYOPENCL_CTX=foo was OpenCL trouble (exit 3) where --device foo is bad
    input (exit 2): both are now one line with the same rule, exit 2."""
    monkeypatch.chdir(tmp_path)
    assert cli.main([*command, "--device", "foo"]) == 2
    by_option = capsys.readouterr().err
    monkeypatch.setenv("PYOPENCL_CTX", "foo")
    assert cli.main(command) == 2
    by_env = capsys.readouterr().err
    assert by_env.count("\n") == 1 and by_env == by_option.replace("--device", "PYOPENCL_CTX"), (by_env, by_option)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setenv("PYOPENCL_CTX", "7:7")   # well formed, but no such device: OpenCL trouble
    assert cli.main(command) == 3
    capsys.readouterr()
