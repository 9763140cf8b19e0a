"""clrt batch render with vector options (colours), and Ctrl-C while a render
writes its AOVs: found by an audit of the command line's valid use; lossless
formats and 16-bit PNG (--bit-depth 16)."""

import numpy as np
import pytest
from PIL import Image
from png_reference import spec_decode

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


def test_16_bit_png_is_the_8_bit_render_finer(ball, tmp_path, device, capsys, monkeypatch):
    """--bit-depth 16 renders linear and encodes on the host with the kernel's
    transfer function: reduced to 8 bits it is the 8-bit render, within one
    level; the AOV files beside it are as they are for an 8-bit image."""
    dev = ["--device", device] if device else []
    size = ["--width", "40", "--height", "30", "--samples", "2", "-q", *dev]
    eight, sixteen = tmp_path / "o8.png", tmp_path / "o16.png"
    assert main(["render", str(ball), "-o", str(eight), *size, "--aov", "depth"]) == 0
    assert main(["render", str(ball), "-o", str(sixteen), *size, "--aov", "depth", "--bit-depth", "16"]) == 0
    capsys.readouterr()
    codes = spec_decode(sixteen.read_bytes())
    assert codes.dtype == np.uint16 and codes.shape == (30, 40, 3)
    reduced = np.rint(codes / 257.0).astype(int)
    image = np.asarray(Image.open(eight)).astype(int)
    assert np.abs(reduced - image).max() <= 1 and np.mean(reduced == image) > 0.99
    assert len(np.unique(codes)) > len(np.unique(image)), "finer steps than 8 bits"
    assert np.array_equal(np.asarray(Image.open(sixteen)), (codes >> 8).astype(np.uint8)), "Pillow reads it"
    assert Image.open(sixteen).info["Software"].startswith("clrt")
    for suffix in (".npy", ".png"):
        assert (tmp_path / f"o16.depth{suffix}").read_bytes() == (tmp_path / f"o8.depth{suffix}").read_bytes()
    assert main(["render", str(ball), "-o", str(sixteen), *size, "--bit-depth", "16"]) == 0, "its own: replaced"

    def no_render(*args, **kwargs):
        raise AssertionError("rendered before the output was checked")

    monkeypatch.setattr("clrt.renderer.Renderer", no_render)
    assert main(["render", str(ball), "-o", str(tmp_path / "o.tif"), *size, "--bit-depth", "16"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "TIFF holds 8-bit sRGB" in err and "formats that can: .png" in err
    assert not (tmp_path / "o.tif").exists()
