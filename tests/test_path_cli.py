"""clrt render --integrator path: the files it writes (linear EXR with the
denoisers' albedo and normal channels, tone-mapped PNG), the bad input it
refuses in one line with exit 2 and no file, and Ctrl-C after a pass of
samples, which keeps the passes done."""

import importlib

import numpy as np
import pytest
from PIL import Image

from clrt import cli
from clrt.renderer.path import QUEUED_LAUNCHES, tone_map

render_module = importlib.import_module("clrt.renderer.frame")

SCENE = ('[camera]\neye = [0, 0.8, 3.2]\ntarget = [0, -0.2, 0]\nwidth = 16\nheight = 12\n'
         '[render]\nintegrator = "path"\nspp = 4\nbackground = [0.5, 0.6, 0.7]\n'
         '[[objects]]\ntype = "sphere"\nsubdivisions = 1\n'
         '[[objects]]\ntype = "plane"\nsize = [8, 8]\ntranslate = [0, -1, 0]\n'
         '[[lights]]\nposition = [1, 3, 1]\nintensity = 20\n')


@pytest.fixture
def scene_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "room.toml"
    path.write_text(SCENE)
    return path


def _run(args, device, capsys):
    code = cli.main(["render", *args, *(["--device", device] if device else [])])
    out, err = capsys.readouterr()
    return code, out, err


def test_exr_holds_the_linear_image_and_the_denoisers_guides(scene_file, device, capsys):
    OpenEXR = pytest.importorskip("OpenEXR")
    code, out, err = _run([str(scene_file), "-o", "room.exr", "--seed", "3"], device, capsys)
    assert code == 0, err
    assert "path tracing 4 spp" in out
    channels = OpenEXR.File("room.exr", separate_channels=True).channels()
    assert {"R", "G", "B", "albedo.R", "albedo.G", "albedo.B", "normal.X", "normal.Y", "normal.Z"} <= set(channels)
    normal = np.stack([channels[f"normal.{c}"].pixels for c in "XYZ"], axis=-1)
    # the floor seen from above: its normals point up (where the sphere is not)
    assert (normal[-1, :, 1] > 0.9).all()
    assert channels["albedo.R"].pixels.dtype == np.float32
    # The PNG is the same render tone-mapped: x 2^exposure, clamped, sRGB.
    code, _, err = _run([str(scene_file), "-o", "room.png", "--seed", "3", "--exposure", "1"], device, capsys)
    assert code == 0, err
    linear = np.stack([channels[c].pixels for c in "RGB"], axis=-1)
    np.testing.assert_array_equal(np.asarray(Image.open("room.png")), tone_map(linear, 1.0))


@pytest.mark.parametrize("words, says", [
    (["--spp", "0"], "--spp must be an integer in 1..2147483647, got 0"),
    (["--spp", "2147483648"], "--spp must be an integer in 1..2147483647, got 2147483648"),
    (["--max-depth", "0"], "--max-depth must be -1 (unbounded) or an integer in 1..1024"),
    (["--integrator", "whitted", "--spp", "8"], "--spp is the path tracer's: add --integrator path"),
    (["--environment", "sky.exr"], "environment"),
    (["--environment", "notes.hdr"], "not a Radiance .hdr image"),
])
def test_bad_input_is_one_line_exit_2_and_no_file(words, says, scene_file, device, capsys):
    (scene_file.parent / "sky.exr").write_text("this is not an image")
    (scene_file.parent / "notes.hdr").write_text("nor is this")
    before = sorted(p.name for p in scene_file.parent.iterdir())
    code, _, err = _run([str(scene_file), "-o", "out.png", *words], device, capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("clrt: ") and says in err, err
    assert sorted(p.name for p in scene_file.parent.iterdir()) == before


def test_ctrl_c_after_a_pass_keeps_the_passes_done(scene_file, device, capsys, monkeypatch):
    real_wait, calls = render_module.wait_for, []

    def interrupted(event):   # Ctrl-C while waiting for the third launch (the pass of 2 samples)
        real_wait(event)
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
    monkeypatch.setattr(render_module, "wait_for", interrupted)
    code, _, err = _run([str(scene_file), "-o", "cut.png", "--spp", "64", "--seed", "2"], device, capsys)
    # The launch queued behind it (QUEUED_LAUNCHES), the pass of 4, finishes too: passes 1, 1, 2, 4.
    assert QUEUED_LAUNCHES == 1
    assert code == 130 and err.startswith("clrt: interrupted after 8 of 64 samples per pixel; wrote "), err
    cut = np.asarray(Image.open("cut.png"))
    monkeypatch.setattr(render_module, "wait_for", real_wait)
    code, _, err = _run([str(scene_file), "-o", "eight.png", "--spp", "8", "--seed", "2"], device, capsys)
    assert code == 0, err
    np.testing.assert_array_equal(cut, np.asarray(Image.open("eight.png")))


def test_emitters_light_a_file_without_lights(tmp_path, device, capsys, monkeypatch):
    """A glTF whose only light is an emissive quad: the path tracer adds no
    default light, Whitted its usual one."""
    trimesh = pytest.importorskip("trimesh")
    from trimesh.visual.material import PBRMaterial
    monkeypatch.chdir(tmp_path)
    ground = trimesh.Trimesh([[-3, 0, -3], [3, 0, -3], [3, 0, 3], [-3, 0, 3]], [[0, 2, 1], [0, 3, 2]])
    ground.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(baseColorFactor=[255, 255, 255, 255],
                                                                       metallicFactor=0.0))
    lamp = trimesh.Trimesh([[-1, 1, -1], [1, 1, -1], [1, 1, 1], [-1, 1, 1]], [[0, 1, 2], [0, 2, 3]])
    lamp.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(baseColorFactor=[0, 0, 0, 255],
                                                                     emissiveFactor=[1, 1, 1]))
    trimesh.Scene([ground, lamp]).export("lamp.glb")
    view = ["--eye", "0,0.5,2.5", "--target", "0,0,0", "--width", "16", "--height", "12"]
    code, out, err = _run(["lamp.glb", "-o", "lamp.png", "--integrator", "path", "--spp", "8", *view], device, capsys)
    assert code == 0, err
    assert "0 light(s)" in out
    assert np.asarray(Image.open("lamp.png"))[-1].min() > 20   # the ground under the lamp is lit
    code, out, err = _run(["lamp.glb", "-o", "whitted.png", *view], device, capsys)
    assert code == 0 and "1 light(s)" in out, err

