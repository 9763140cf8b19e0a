"""One rule for every file clrt writes: a re-run replaces clrt's own outputs, and
any other file -- or one changed since clrt wrote it -- is refused without --force."""

import os

import numpy as np
import pytest
from PIL import Image

from clrt import cli, config, output
from clrt.scene import primitives

FORMATS = sorted(config.IMAGE_FORMATS)


@pytest.fixture
def mesh_obj(tmp_path):
    mesh = primitives.icosphere(1)
    path = tmp_path / "m.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
    return path


def _render(mesh, out, device, *extra):
    dev = ["--device", device] if device else []
    return cli.main(["render", str(mesh), "-o", str(out), "--width", "12", "--height", "9", "-q", *dev, *extra])


@pytest.mark.parametrize("suffix", FORMATS)
def test_running_a_command_twice_replaces_its_own_outputs(suffix, mesh_obj, tmp_path, device, capsys):
    out = tmp_path / "out" / f"x{suffix}"
    out.parent.mkdir()
    for _ in range(2):
        code = _render(mesh_obj, out, device, "--aov", "depth,prim")
        assert code == 0, capsys.readouterr().err
    written = sorted(p.name for p in out.parent.iterdir() if not p.name.startswith("."))
    assert written == sorted([out.name, "x.depth.npy", "x.depth.png", "x.prim.npy", "x.prim.png"])
    assert Image.open(out).size == (12, 9)
    assert np.load(out.parent / "x.prim.npy").shape == (9, 12)
    hidden = [p.name for p in out.parent.iterdir() if p.name.startswith(".")]
    assert all(name.endswith(".clrt") for name in hidden), f"temporary files left behind: {hidden}"


@pytest.mark.parametrize("suffix", FORMATS + [".npy"])
def test_a_file_clrt_did_not_write_is_refused_without_force(suffix, mesh_obj, tmp_path, device, capsys):
    image = tmp_path / "x.png"
    target = tmp_path / f"x.depth{suffix}" if suffix == ".npy" else tmp_path / f"x{suffix}"
    if suffix == ".npy":
        np.save(target, np.zeros(3))   # a user's own array where an AOV would go
        args = ["--aov", "depth"]
    else:
        Image.new("RGB", (4, 4), (9, 9, 9)).save(target)   # a user's own image (PIL, no mark)
        image, args = target, []
    before = target.read_bytes()
    assert _render(mesh_obj, image, device, *args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "was not written by clrt" in err and "--force" in err
    assert target.read_bytes() == before
    assert _render(mesh_obj, image, device, *args, "--force") == 0
    assert target.read_bytes() != before
    assert _render(mesh_obj, image, device, *args) == 0, "once clrt wrote it, a re-run replaces it"


@pytest.mark.parametrize("suffix", [".npy", ".bmp", ".ppm"])
def test_a_recorded_file_changed_since_is_refused(suffix, tmp_path):
    """Formats without room for a mark are recognised by the SHA-256 in their record."""
    path = tmp_path / f"a{suffix}"
    if suffix == ".npy":
        output.write_array(np.arange(4.0), path)
    else:
        output.write_image(np.zeros((2, 3, 3), np.uint8), path)
    assert output.record_path(path).is_file() and output.written_by_clrt(path)
    path.write_bytes(path.read_bytes() + b"\0")
    assert not output.written_by_clrt(path)
    with pytest.raises(output.OutputError, match="or was changed since"):
        output.check_replace(path, force=False)
    output.check_replace(path, force=True)


def test_marked_formats_need_no_record(tmp_path):
    for suffix in (".png", ".jpg", ".tif", ".webp", ".gif"):
        path = tmp_path / f"a{suffix}"
        output.write_image(np.full((4, 4, 3), 128, np.uint8), path)
        assert output.written_by_clrt(path) and not output.record_path(path).exists()


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads the umask from /proc/self/status")
def test_new_images_get_the_umask_without_it_being_changed(tmp_path, monkeypatch):
    """os.umask can only be read by setting it, and a thread creating a file
    meanwhile (batch workers write images in threads) would get the temporary
    mask: the umask is read from /proc instead, and files get 0666 less it."""
    old = os.umask(0o027)
    try:
        def refuse(mask):
            raise AssertionError("os.umask called while writing an image")
        monkeypatch.setattr(os, "umask", refuse)
        out = tmp_path / "a.png"
        output.write_image(np.zeros((4, 5, 3), np.uint8), out)
        assert out.stat().st_mode & 0o777 == 0o640
    finally:
        monkeypatch.undo()
        os.umask(old)
