"""clrt batch render with vector options (colours), and Ctrl-C while a render
writes its AOVs: found by an audit of the command line's valid use."""

import numpy as np
import pytest
from PIL import Image

from clrt.cli import main
from clrt.scene import primitives


def _write_obj(path, mesh):
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in mesh.vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces.tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def ball(tmp_path):
    return _write_obj(tmp_path / "ball.obj", primitives.icosphere(1))


@pytest.mark.parametrize("option", [["--color", "1,0,0"], ["--background", "0.2,0.1,0"]])
def test_batch_render_takes_color_and_background(option, ball, tmp_path, device, capsys):
    pytest.importorskip("distributed")
    dev = ["--device", device] if device else []
    size = ["--width", "20", "--height", "14"]
    code = main(["batch", "render", str(ball), "-o", str(tmp_path / "out"), "--views", "1", *size, *option,
                 "--workers", "1", "-q", *dev])
    err = capsys.readouterr().err
    assert code == 0, err
    frame = tmp_path / "out" / "ball" / "view-0000.png"
    assert frame.exists()
    single = tmp_path / "single.png"
    assert main(["render", str(ball), "-o", str(single), *size, *option, "-q", *dev]) == 0
    assert np.array_equal(np.asarray(Image.open(frame)), np.asarray(Image.open(single)))


def test_interrupt_while_writing_aovs_leaves_no_image(ball, tmp_path, device, capsys, monkeypatch):
    import clrt.query.aov as aov

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt   # Ctrl-C during the AOV pass, after the image was written

    monkeypatch.setattr(aov, "write_aovs", interrupted)
    dev = ["--device", device] if device else []
    out = tmp_path / "o.png"
    code = main(["render", str(ball), "-o", str(out), "--width", "20", "--height", "14",
                 "--aov", "depth,prim", "-q", *dev])
    capsys.readouterr()
    assert code == 130
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ball.obj"], "interrupted render left files"


def test_lossless_formats_keep_every_pixel(ball, tmp_path, device, capsys):
    """PNG, TIFF, WebP (written lossless), BMP and PPM hold the same pixels."""
    dev = ["--device", device] if device else []
    images = {}
    for suffix in (".png", ".tif", ".webp", ".bmp", ".ppm"):
        out = tmp_path / f"o{suffix}"
        assert main(["render", str(ball), "-o", str(out), "--width", "40", "--height", "30", "-q", *dev]) == 0
        images[suffix] = np.asarray(Image.open(out).convert("RGB"))
    capsys.readouterr()
    for suffix, image in images.items():
        assert np.array_equal(image, images[".png"]), suffix
