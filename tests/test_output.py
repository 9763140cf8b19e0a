"""One rule for every file clrt writes: a re-run replaces clrt's own outputs, and
any other file -- or one changed since clrt wrote it -- is refused without --force."""

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import clrt
from clrt import OutputError, cli, output
from clrt.scene import primitives

FORMATS = sorted(s for w in output.WRITERS.values() if w.holds("8-bit", "RGB") for s in w.suffixes)


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


@pytest.mark.parametrize("suffix", FORMATS + [".exr", ".npy"])
def test_a_file_changed_since_clrt_wrote_it_is_refused(suffix, tmp_path):
    """Every format is recognised by the SHA-256 in its record: cut short, one
    byte changed, or replaced by another file, it is no longer clrt's."""
    if suffix == ".exr":
        pytest.importorskip("OpenEXR")
    path = tmp_path / f"a{suffix}"

    def write(value=0):
        if suffix == ".npy":
            output.write_array(np.arange(4.0) + value, path)
        else:
            output.write_image(np.full((2, 3, 3), value, np.float32 if suffix == ".exr" else np.uint8), path)

    write()
    ours = path.read_bytes()
    assert output.record_path(path).is_file() and output.file_state(path) == output.OURS
    for changed in (ours[:len(ours) // 2], ours[:-1] + bytes([ours[-1] ^ 1]), b""):
        path.write_bytes(changed)
        assert output.file_state(path) == output.CHANGED and not output.written_by_clrt(path)
        with pytest.raises(OutputError, match="was changed since clrt wrote it.*--force"):
            output.check_replace(path, force=False)
        output.check_replace(path, force=True)
        with pytest.raises(OutputError, match="was changed since"):
            write(1)
        assert path.read_bytes() == changed, "refused: left as it was"
    path.write_bytes(ours)
    assert output.written_by_clrt(path), "the same bytes again: clrt's"
    write(1)   # its own: replaced without force, and recorded anew
    assert path.read_bytes() != ours and output.file_state(path) == output.OURS


def test_the_cli_refuses_an_edited_png_that_kept_its_mark(mesh_obj, tmp_path, device, capsys):
    """clrt render -o e.png; the PNG edited in an editor that keeps its text
    chunks (clrt's Software mark among them); the command run again: refused,
    exit 2, the edit kept -- until --force."""
    from PIL import PngImagePlugin
    out = tmp_path / "e.png"
    assert _render(mesh_obj, out, device) == 0
    with Image.open(out) as im:
        info = PngImagePlugin.PngInfo()
        info.add_text("Software", im.info["Software"])
        edited = np.asarray(im).copy()
    edited[0, 0] = 255 - edited[0, 0]
    Image.fromarray(edited).save(out, pnginfo=info)
    before = out.read_bytes()
    capsys.readouterr()
    assert _render(mesh_obj, out, device) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "was changed since clrt wrote it" in err and "--force" in err, err
    assert out.read_bytes() == before
    assert _render(mesh_obj, out, device, "--force") == 0 and output.written_by_clrt(out)


def test_every_format_gets_a_record(tmp_path):
    for suffix in FORMATS:
        path = tmp_path / f"a{suffix}"
        output.write_image(np.full((4, 4, 3), 128, np.uint8), path)
        assert output.written_by_clrt(path) and output.record_path(path).is_file()
        assert output.record_path(path).read_text().split()[2:] == ["sha256", output.files.sha256(path)]


def test_a_record_goes_in_before_its_file_and_a_failed_rename_restores_the_old_one(tmp_path, monkeypatch):
    """A process killed between the two renames leaves the new record beside the
    old file (CHANGED) or beside nothing (ABSENT), never a new file without a
    record (FOREIGN: a batch would refuse its own frame); a rename that fails
    puts the old record back."""
    path = tmp_path / "a.png"
    replace = os.replace
    seen, failing = [], set()

    def spy(src, dst):
        seen.append(Path(dst).name)
        if Path(dst).name in failing:
            raise OSError(5, "Input/output error")
        return replace(src, dst)

    monkeypatch.setattr(os, "replace", spy)
    output.write_image(np.zeros((2, 2, 3), np.uint8), path)
    assert seen == [".a.png.clrt", "a.png"]
    record = output.record_path(path).read_bytes()
    failing.update({"a.png", "new.png"})
    with pytest.raises(OutputError, match="Input/output error"):
        output.write_image(np.ones((2, 2, 3), np.uint8), path)
    assert output.record_path(path).read_bytes() == record and output.written_by_clrt(path)
    with pytest.raises(OutputError):
        output.write_image(np.ones((2, 2, 3), np.uint8), tmp_path / "new.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".a.png.clrt", "a.png"]


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


# --------------------------------------------------------------------------- the WRITERS table

IMAGE_CHANNELS = {"gray": (5, 7), "gray+alpha": (5, 7, 2), "RGB": (5, 7, 3), "RGBA": (5, 7, 4)}
PILLOW_MODES = {"gray": "L", "gray+alpha": "LA", "RGB": "RGB", "RGBA": "RGBA"}


def _sample(channels, dtype):
    rng = np.random.default_rng(5)
    shape = IMAGE_CHANNELS[channels]
    if np.dtype(dtype).kind == "f":
        return (rng.random(shape) * 1.5).astype(dtype)
    return rng.integers(0, np.iinfo(dtype).max + 1, shape, dtype=dtype)


def _read_back(path, writer, channels, dtype):
    if writer.holds("float"):
        OpenEXR = pytest.importorskip("OpenEXR")
        with OpenEXR.File(str(path), separate_channels=True) as f:
            layers = {name: c.pixels for name, c in f.channels().items()}
        return np.stack([layers[c] for c in "RGBA"[:IMAGE_CHANNELS[channels][2]]], axis=-1)
    image = Image.open(path)
    if dtype == np.uint16 and channels == "gray":   # Pillow holds 16-bit gray; colour comes as its high bytes
        return np.asarray(image).astype(np.uint16)
    return np.asarray(image.convert(PILLOW_MODES[channels]))   # WebP stores gray as RGB, Pillow 16-bit LA as RGBA


@pytest.mark.parametrize("name", sorted(output.IMAGE_WRITERS))
def test_each_writer_holds_what_the_table_says(name, tmp_path):
    """Every depth and channel set a writer claims is written, marked or recorded,
    and read back exactly where the format is lossless; anything else is refused
    in one line naming the formats that hold it, and nothing is written."""
    writer = output.WRITERS[name]
    for dtype in (np.uint8, np.uint16, np.float32):
        for channels in IMAGE_CHANNELS:
            image = _sample(channels, dtype)
            # a float image is written as it is where the format holds floats, else encoded to 8-bit sRGB
            depth = {np.uint8: "8-bit", np.uint16: "16-bit"}.get(dtype) or \
                ("float" if writer.holds("float") else "8-bit")
            path = tmp_path / f"{np.dtype(dtype).name}-{channels}{writer.suffix}"
            if not writer.holds(depth, channels):
                with pytest.raises(clrt.InputError) as caught:
                    output.write_image(image, path)
                able = [s for w in output.WRITERS.values() if w.holds(depth, channels) for s in w.suffixes]
                message = str(caught.value)
                assert "\n" not in message and f"{writer.name} holds {writer.describe()}" in message
                assert message.partition("formats that can: ")[2].split(";")[0].split(", ") == (able or [""])
                assert not path.exists()
                continue
            if writer.require:
                pytest.importorskip("OpenEXR")
            output.write_image(image, path)
            assert output.written_by_clrt(path) and output.record_path(path).exists(), (name, channels)
            if not writer.lossless:
                continue
            stored = output.encode_srgb(image) if dtype == np.float32 and depth == "8-bit" else image
            expected = (stored >> 8).astype(np.uint8) if dtype == np.uint16 and channels != "gray" else stored
            assert np.array_equal(_read_back(path, writer, channels, dtype), expected), (name, dtype, channels)
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".") and not p.name.endswith(".clrt")]


@pytest.mark.parametrize("image, fragment", [
    (np.zeros((4, 4, 3), np.int32), "must be uint8 (8-bit sRGB), uint16 (16-bit sRGB) or floats (linear), got int32"),
    (np.zeros((4, 4, 3), bool), "got bool"),
    (np.zeros((4, 4, 1), np.uint8), "got shape (4, 4, 1)"),
    (np.zeros((4, 4, 5), np.uint8), "got shape (4, 4, 5)"),
    (np.zeros((2, 4, 4, 3), np.uint8), "got shape (2, 4, 4, 3)"),
    (np.zeros((0, 4, 3), np.uint8), "at least one pixel"),
    (np.zeros(4, np.uint8), "got shape (4,)"),
])
def test_other_dtypes_and_shapes_are_one_line_input_errors(image, fragment, tmp_path):
    for suffix in (".png", ".bmp", ".exr"):
        with pytest.raises(clrt.InputError) as caught:
            output.write_image(image, tmp_path / f"a{suffix}")
        assert fragment in str(caught.value) and "\n" not in str(caught.value)
    assert list(tmp_path.iterdir()) == []


def test_bit_depth_is_that_of_the_dtype_or_asked_for_a_linear_image(tmp_path):
    linear = np.linspace(0, 1, 5 * 6 * 3, dtype=np.float32).reshape(5, 6, 3)
    for bits, dtype in ((8, np.uint8), (16, np.uint16)):
        with pytest.raises(clrt.InputError, match="already"):
            output.write_image(np.zeros((2, 2, 3), dtype), tmp_path / "a.png", bit_depth=24 - bits)
        output.write_image(linear, tmp_path / f"{bits}.png", bit_depth=bits)
        output.write_image(output.encode_srgb(linear, bits), tmp_path / f"{bits}-encoded.png", bit_depth=bits)
        assert (tmp_path / f"{bits}.png").read_bytes() == (tmp_path / f"{bits}-encoded.png").read_bytes()
    for bad in (12, 8.0, True, "16"):
        with pytest.raises(clrt.InputError, match="bit_depth must be 8 or 16"):
            output.write_image(linear, tmp_path / "b.png", bit_depth=bad)
    with pytest.raises(clrt.InputError, match="JPEG holds 8-bit sRGB gray or RGB images, not 16-bit"):
        output.write_image(linear, tmp_path / "b.jpg", bit_depth=16)
    with pytest.raises(clrt.InputError, match="formats that can: .png; render with linear=True"):
        output.write_image(np.zeros((2, 2, 3), np.uint16), tmp_path / "b.exr")
    assert not (tmp_path / "b.png").exists() and not (tmp_path / "b.jpg").exists()


def test_srgb_encoding_is_the_kernels_at_8_bits_and_finer_at_16():
    """16-bit codes are the same transfer function at 65535 levels: reduced to 8
    bits (code 257 k is 8-bit code k) they are the 8-bit codes, within one level
    where the two roundings straddle a half; alpha is scaled, not curved."""
    from clrt.scene.texture import srgb_encode8
    rng = np.random.default_rng(3)
    linear = np.concatenate([rng.random(100_000), [0.0, 0.0031308, 1.0, 1.5, -0.2, np.inf, np.nan]])
    image = linear.astype(np.float32).reshape(-1, 1, 1).repeat(3, axis=2)
    eight, sixteen = output.encode_srgb(image, 8), output.encode_srgb(image, 16)
    assert eight.dtype == np.uint8 and sixteen.dtype == np.uint16
    assert np.array_equal(eight, srgb_encode8(image))
    reduced = np.rint(sixteen / 257.0).astype(int)
    assert np.abs(reduced - eight).max() <= 1 and np.mean(reduced == eight) > 0.99
    assert sixteen[-7:, 0, 0].tolist() == [0, round(0.04045 * 65535), 65535, 65535, 0, 65535, 0]
    order = np.argsort(linear[:100_000])
    assert (np.diff(sixteen[:100_000, 0, 0][order].astype(int)) >= 0).all(), "monotonic"
    rgba = np.concatenate([image[:4], np.full((4, 1, 1), 0.5, np.float32)], axis=2)
    assert (output.encode_srgb(rgba, 16)[..., 3] == 32768).all() and (output.encode_srgb(rgba)[..., 3] == 128).all()


def test_one_lookup_by_suffix(tmp_path):
    assert output.writer_for("A.PNG") is output.WRITERS["png"]
    assert output.writer_for(tmp_path / "x.Jpeg") is output.writer_for("y.jpg") is output.WRITERS["jpg"]
    assert len(set(output.IMAGE_SUFFIXES)) == len(output.IMAGE_SUFFIXES)
    assert output.format_writer("TIFF") is output.WRITERS["tif"] and output.format_writer("exr").suffix == ".exr"
    for bad, fragment in (("x.psd", "unknown image type '.psd' (use one of .png, .jpg"), ("x", "no image type suffix")):
        with pytest.raises(clrt.OutputError, match=fragment.replace("(", r"\(").replace(".", r"\.")):
            output.writer_for(bad)
    with pytest.raises(clrt.InputError, match="NumPy holds arrays of any dtype and shape, not 8-bit sRGB images"):
        output.writer_for("x.npy", "8-bit")
    with pytest.raises(clrt.InputError, match="format must be one of png, jpg"):
        output.format_writer("npy")


def test_the_readme_lists_the_table():
    """README's table of output formats is WRITERS: a row per format, its
    suffixes, what it holds and where its mark goes."""
    from pathlib import Path
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.strip().startswith("|") and len(cells) == 4 and cells[1].startswith("`."):
            rows[cells[1]] = cells
    assert len(rows) == len(output.WRITERS)
    for writer in output.WRITERS.values():
        name, _, holds, mark = rows[" ".join(f"`{s}`" for s in writer.suffixes)]
        assert name.split()[0] == writer.name and holds.startswith(writer.describe()) and mark == writer.mark
