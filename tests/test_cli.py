"""The command line as a user meets it: outputs, exit codes, one-line errors."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clrt.cli import main
from clrt.scene import primitives


@pytest.fixture
def sphere_obj(tmp_path):
    mesh = primitives.icosphere(1)
    path = tmp_path / "sphere.obj"
    lines = [f"v {x} {y} {z}" for x, y, z in mesh.vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def _render(args, device, capsys):
    dev = ["--device", device] if device else []
    code = main(["render", *args, *dev])
    out, err = capsys.readouterr()
    return code, out, err


def test_render_mesh_writes_png_and_prints_path(sphere_obj, tmp_path, device, capsys):
    out_png = tmp_path / "out.png"
    code, out, err = _render([str(sphere_obj), "-o", str(out_png), "--width", "40", "--height", "30",
                              "--light", "2,3,4", "--light", "-2,3,4", "--color", "0.9,0.2,0.1"],
                             device, capsys)
    assert code == 0, err
    assert out.strip().splitlines()[-1] == str(out_png.resolve())
    assert "40x30 pixels, 80 triangles, 2 light(s)" in out
    for stage in ("initialisation", "acceleration build", "copy to device", "ray generation",
                  "pixel colour", "read back"):
        assert stage in out
    image = np.asarray(Image.open(out_png))
    assert image.shape == (30, 40, 3)
    centre = image[15, 20].astype(int)
    assert centre[0] > centre[1] + 30, "the material colour should show"
    assert [p.name for p in tmp_path.glob(".out.png.*")] == [".out.png.clrt"], "no temporary file left behind"


def test_default_scene_renders_without_arguments(tmp_path, device, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = _render(["--width", "32", "--height", "24"], device, capsys)
    assert code == 0, err
    assert (tmp_path / "clrt-default.png").is_file()
    assert Image.open(tmp_path / "clrt-default.png").size == (32, 24)


@pytest.mark.parametrize("args, fragment", [
    (["missing.obj"], "no such file"),
    (["--fov", "180"], "fov"),
    (["--width", "0"], "width"),
    (["--eye", "1,2"], "--eye"),
    (["--eye", "0,0,0", "--target", "0,0,0"], "eye and target"),
    (["--up", "0,0,0"], "up"),
    (["-o", "picture.xyz"], "unknown image type"),
    (["-o", "picture.npy"], "NumPy holds arrays"),
    (["-o", "picture.jpg", "--bit-depth", "16"], "JPEG holds 8-bit sRGB gray or RGB images, not 16-bit sRGB RGB "
                                                 "images; formats that can: .png"),
    (["-o", "picture.exr", "--bit-depth", "8"], "OpenEXR holds linear float32"),
    (["--bit-depth", "12"], "--bit-depth must be 8 or 16, got 12"),
    (["-o", "no/such/folder/a.png"], "does not exist"),
    (["--shininess", "-1"], "shininess"),
])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(args, fragment, tmp_path, device, capsys,
                                                         monkeypatch):
    monkeypatch.chdir(tmp_path)
    existing = tmp_path / "clrt-default.png"
    existing.write_bytes(b"keep me")
    mesh_args = args
    if "--shininess" in args:   # material options need a mesh
        mesh = primitives.box()
        (tmp_path / "box.obj").write_text(
            "".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
            + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
        mesh_args = ["box.obj", "-o", "clrt-default.png", *args]
    code, out, err = _render(mesh_args, device, capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("clrt: ")
    assert fragment in err
    assert existing.read_bytes() == b"keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) in (["clrt-default.png"],
                                                          ["box.obj", "clrt-default.png"])


def test_a_mesh_too_large_to_frame_is_refused_from_any_camera(tmp_path, device, capsys):
    """A mesh too large for the framed camera to stay within +-1e30 is refused
    with that reason; from a camera the user places (--eye and --target, or a
    scene file's camera) it is refused too, in one line, because its triangles
    are far too large for the float32 triangle test (clrt.device.reach): such a
    render once went on and drew nothing."""
    huge = tmp_path / "huge.off"
    huge.write_text("OFF\n3 1 0\n-9e29 -9e29 0\n9e29 -9e29 0\n0 9e29 0\n3 0 1 2\n")
    size = ["--width", "8", "--height", "6"]
    code, out, err = _render([str(huge), "-o", str(tmp_path / "framed.png"), *size], device, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "cannot frame the scene" in err
    code, out, err = _render([str(huge), "-o", str(tmp_path / "placed.png"), *size,
                              "--eye", "0,0,9.5e29", "--target", "0,0,0"], device, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "float32 triangle test overflows" in err, err
    (tmp_path / "scene.toml").write_text('[camera]\neye = [0, 0, 9.5e29]\ntarget = [0, 0, 0]\n'
                                         'width = 8\nheight = 6\n[[objects]]\ntype = "mesh"\n'
                                         'path = "huge.off"\n')
    code, out, err = _render([str(tmp_path / "scene.toml"), "-o", str(tmp_path / "file.png")], device, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "float32 triangle test overflows" in err, err
    # Only --eye: the rest of the camera is still framed, so still one line, exit 2.
    code, out, err = _render([str(huge), "-o", str(tmp_path / "half.png"), *size, "--eye", "0,0,9.5e29"],
                             device, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "cannot frame the scene" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["huge.off", "scene.toml"], "nothing written"


def test_info_lists_devices_and_marks_one(capsys):
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "Platform 0" in out and "*" in out


def test_unknown_device_is_exit_3(capsys):
    assert main(["render", "--device", "7:7", "--width", "8", "--height", "8"]) == 3
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1


def test_python_dash_m_missing_mesh(tmp_path):
    """The real entry point, as a user types it: one line on stderr, exit 2."""
    repo = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([repo, os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([sys.executable, "-m", "clrt", "render", "missing.obj"],
                            cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0 and "missing.obj" in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_progress_bar_appears_only_after_the_delay(monkeypatch, capsys):
    """tqdm is imported and the bar made only once a render has run
    PROGRESS_DELAY seconds; it then starts from the samples already done."""
    pytest.importorskip("tqdm")
    from clrt import cli, config
    clock = [100.0]
    monkeypatch.setattr(cli.time, "perf_counter", lambda: clock[0])
    bar = cli._progress_bar(1000)
    bar.update(100)
    assert bar.bar is None
    clock[0] += config.PROGRESS_DELAY + 0.01
    bar.update(200)
    assert bar.bar is not None and bar.bar.n == 300 and bar.bar.total == 1000
    bar.update(50)
    assert bar.bar.n == 350
    bar.close()
