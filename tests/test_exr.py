"""OpenEXR output: ``clrt render -o x.exr`` and ``clrt.output.write_exr`` write the
linear image (float32, unclamped, no sRGB curve), with ``--aov`` as channels of
the same file; the same overwrite and temporary-file rules as every output; and
OpenEXR stays optional (the 'exr' extra, which the test extra includes)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import clrt
from clrt import cli, output
from clrt.query.aov import AOVS, EXR_CHANNELS
from clrt.scene import primitives
from clrt.scene.render_setup import CAMERA_OPTIONS, SCENE_OPTIONS, render_camera, render_lights, render_scene

REPO = Path(__file__).resolve().parents[1]
SIZE = ["--width", "32", "--height", "24"]


@pytest.fixture
def exr():
    return pytest.importorskip("OpenEXR", reason="EXR output needs the exr extra (the test extra has it)")


@pytest.fixture
def mesh_obj(tmp_path):
    mesh = primitives.icosphere(2)
    path = tmp_path / "mesh" / "m.obj"
    path.parent.mkdir()
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
    return path


def _render(mesh, out, device, *extra):
    dev = ["--device", device] if device else []
    return cli.main(["render", str(mesh), "-o", str(out), *SIZE, "-q", *dev, *extra])


def _read(exr, path) -> dict:
    with exr.File(str(path), separate_channels=True) as f:
        return {name: channel.pixels for name, channel in f.channels().items()}, dict(f.header())


def _files(folder) -> list:
    """The files in ``folder`` but the records of clrt's (``.NAME.clrt``), each
    beside its file: no other hidden file (no temporary left behind)."""
    names = sorted(p.name for p in Path(folder).iterdir())
    visible = [n for n in names if not n.startswith(".")]
    assert all(n.endswith(".clrt") and n[1:-5] in visible for n in names if n.startswith(".")), names
    return visible


def _cli_linear(mesh, device, *extra) -> np.ndarray:
    """What ``clrt render MESH *extra`` renders, as Renderer.render(linear=True) gives it."""
    args = cli._parser().parse_args(["render", str(mesh), *SIZE, *extra])
    scene = render_scene(args.mesh, **{k: getattr(args, k) for k in SCENE_OPTIONS})
    camera = render_camera(scene, **{k: getattr(args, k) for k in CAMERA_OPTIONS})
    scene.lights = render_lights(scene.bounds, camera, scene.lights, args.light)
    return clrt.Renderer(scene, device=device).render(camera, linear=True).image


def test_the_cli_writes_the_linear_image_bit_for_bit(exr, mesh_obj, tmp_path, device, capsys):
    out = tmp_path / "out" / "x.exr"
    out.parent.mkdir()
    bright = ["--diffuse", "20"]        # values far above 1: nothing may be clamped
    assert _render(mesh_obj, out, device, *bright) == 0, capsys.readouterr().err
    assert _files(out.parent) == ["x.exr"], "no temporary files, no AOV files"
    channels, header = _read(exr, out)
    assert sorted(channels) == ["B", "G", "R"]
    assert all(c.dtype == np.float32 for c in channels.values())
    image = np.stack([channels[c] for c in "RGB"], axis=-1)
    expected = _cli_linear(mesh_obj, device, *bright)
    assert image.shape == (24, 32, 3) and image.tobytes() == expected.tobytes()
    assert image.max() > 1.5, "linear light, unclamped"
    assert header[output.EXR_MARK_ATTRIBUTE].startswith(output.SOFTWARE_MARK)
    assert output.written_by_clrt(out)


def test_write_exr_round_trips_a_linear_render(exr, tmp_path, device):
    image = clrt.render(clrt.default_scene(32, 24), linear=True, device=device)
    path = tmp_path / "a.exr"
    output.write_image(image, path)            # write_image sends .exr to write_exr
    channels, _ = _read(exr, path)
    assert np.stack([channels[c] for c in "RGB"], axis=-1).tobytes() == image.tobytes()
    extra = {"Z": np.full((24, 32), np.inf, np.float32), "id": np.full((24, 32), -1, np.int64),
             "mask": np.eye(24, 32, dtype=bool), "half": np.ones((24, 32), np.float16),
             "wide": np.linspace(0, 1, 24 * 32).reshape(24, 32)}
    output.write_exr(image, path, channels=extra)   # clrt's own file: replaced without force
    channels, _ = _read(exr, path)
    assert np.isinf(channels["Z"]).all() and channels["Z"].dtype == np.float32
    assert channels["id"].dtype == np.uint32 and (channels["id"].view(np.int32) == -1).all()
    assert channels["mask"].dtype == np.float16 and np.array_equal(channels["mask"], np.eye(24, 32))
    assert channels["half"].dtype == np.float16
    assert channels["wide"].dtype == np.float32 and np.array_equal(channels["wide"], extra["wide"].astype(np.float32))
    assert _files(tmp_path) == ["a.exr"]


def test_aov_channels_hold_the_values_of_the_npy_files(exr, mesh_obj, tmp_path, device, capsys):
    names = ",".join(AOVS)
    png, out = tmp_path / "p" / "x.png", tmp_path / "e" / "x.exr"
    png.parent.mkdir()
    out.parent.mkdir()
    assert _render(mesh_obj, png, device, "--aov", names) == 0, capsys.readouterr().err
    assert _render(mesh_obj, out, device, "--aov", names) == 0, capsys.readouterr().err
    assert _files(out.parent) == ["x.exr"], "AOVs go into the .exr, not beside it"
    channels, _ = _read(exr, out)
    assert sorted(channels) == sorted(["R", "G", "B", *(c for n in AOVS for c in EXR_CHANNELS[n])])
    npy = {name: np.load(png.parent / f"x.{name}.npy") for name in AOVS}
    assert npy["hit"].any() and not npy["hit"].all(), "the view must show hits and background"
    assert channels["Z"].dtype == np.float32 and np.array_equal(channels["Z"], npy["depth"])
    assert np.isinf(channels["Z"][~npy["hit"]]).all()
    assert np.array_equal(channels["distance"], npy["distance"])
    normal = np.stack([channels[c] for c in ("N.X", "N.Y", "N.Z")], axis=-1)
    assert normal.dtype == np.float32 and np.array_equal(normal, npy["normal"])
    assert channels["prim"].dtype == np.uint32
    assert np.array_equal(channels["prim"].view(np.int32), npy["prim"])
    assert (channels["prim"][~npy["hit"]] == 0xFFFFFFFF).all()
    for flag in ("hit", "front"):
        assert channels[flag].dtype == np.float16
        assert np.array_equal(channels[flag] == 1, npy[flag]) and np.isin(channels[flag], (0, 1)).all()


def test_a_users_exr_is_refused_and_clrts_own_is_replaced(exr, mesh_obj, tmp_path, device, capsys):
    target = tmp_path / "x.exr"
    users = np.full((4, 4), 0.5, np.float32)
    exr.File({"software": "Blender 4.2"}, {"R": users, "G": users, "B": users}).write(str(target))
    before = target.read_bytes()
    assert not output.written_by_clrt(target)
    assert _render(mesh_obj, target, device) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "was not written by clrt" in err and "--force" in err
    assert target.read_bytes() == before
    with pytest.raises(clrt.OutputError, match="not written by clrt"):
        output.write_exr(np.zeros((2, 2, 3), np.float32), target)
    assert _render(mesh_obj, target, device, "--force") == 0
    assert target.read_bytes() != before and output.written_by_clrt(target)
    first = target.read_bytes()
    assert _render(mesh_obj, target, device, "--diffuse", "0.2") == 0, "clrt's own .exr: replaced"
    assert target.read_bytes() != first
    assert _files(tmp_path) == ["mesh", "x.exr"]


@pytest.mark.parametrize("content", [b"", b"not an exr", b"v/1\x01\x02\x00\x00\x00software\x00string\x00\x04",
                                     b"v/1\x01\x02\x00\x00\x00software\x00string\x00\x04\x00\x00\x00clrt\x00"])
def test_a_broken_or_foreign_exr_is_not_clrts(content, tmp_path):
    """Without the record of its SHA-256 an .exr is not clrt's -- even one whose
    header carries clrt's mark -- and with a record it is clrt's only while its
    bytes match."""
    path = tmp_path / "b.exr"
    path.write_bytes(content)
    assert not output.written_by_clrt(path) and output.file_state(path) == output.FOREIGN
    output.record_path(path).write_text(f"clrt 0.1.0 sha256 {output.files.sha256(path)}\n")
    assert output.written_by_clrt(path)
    path.write_bytes(content + b"\0")
    assert output.file_state(path) == output.CHANGED


def test_without_openexr_the_cli_says_how_to_install_it(mesh_obj, tmp_path, device, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "OpenEXR", None)     # import OpenEXR -> ImportError
    out = tmp_path / "out" / "x.exr"
    out.parent.mkdir()
    assert _render(mesh_obj, out, device, "--aov", "depth") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "OpenEXR" in err and "pip install 'clrt[exr]'" in err
    assert _files(out.parent) == []
    with pytest.raises(clrt.OutputError, match=r"pip install 'clrt\[exr\]'"):
        output.write_exr(np.zeros((2, 2, 3), np.float32), out)
    assert _files(out.parent) == []


def test_a_failed_or_interrupted_write_leaves_nothing_behind(exr, tmp_path, monkeypatch):
    path = tmp_path / "a.exr"
    output.write_exr(np.ones((2, 3, 3), np.float32), path)
    before = path.read_bytes()

    class Failing:
        def __init__(self, header, channels):
            pass

        def write(self, name):
            Path(name).write_bytes(b"v/1\x01half")       # a partial file, then the failure
            raise self.error

    for error, caught in ((RuntimeError("disk full"), clrt.OutputError), (KeyboardInterrupt(), KeyboardInterrupt)):
        Failing.error = error
        monkeypatch.setattr(exr, "File", Failing)
        with pytest.raises(caught):
            output.write_exr(np.zeros((2, 3, 3), np.float32), path)
        monkeypatch.undo()
        assert _files(tmp_path) == ["a.exr"] and path.read_bytes() == before


def test_bad_images_and_channels_are_refused(exr, tmp_path):
    path = tmp_path / "a.exr"
    rgb = np.zeros((2, 3, 3), np.float32)
    with pytest.raises(clrt.InputError, match="linear=True"):
        output.write_exr(np.zeros((2, 3, 3), np.uint8), path)      # an 8-bit sRGB image
    with pytest.raises(clrt.InputError, match="shape"):
        output.write_exr(rgb, path, {"Z": np.zeros((3, 2), np.float32)})
    with pytest.raises(clrt.InputError, match="other than R, G, B"):
        output.write_exr(rgb, path, {"G": np.zeros((2, 3), np.float32)})
    with pytest.raises(clrt.InputError, match="32 bits|int32"):
        output.write_exr(rgb, path, {"id": np.full((2, 3), 1 << 40)})
    with pytest.raises(clrt.OutputError, match=r"must end in \.exr"):
        output.write_exr(rgb, tmp_path / "a.png")
    assert _files(tmp_path) == []


def test_import_clrt_does_not_load_openexr():
    code = ("import sys, clrt, clrt.output, clrt.cli, clrt.query.aov; "
            "print('OpenEXR' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert result.stdout.strip() == "False"
