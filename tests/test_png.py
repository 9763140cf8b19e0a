"""clrt's own PNG writer (clrt.output.png_bytes) against Pillow and against a
decoder written from the PNG specification: the same pixels and mode, 8 and 16
bits a sample, a file Pillow verifies, clrt's mark inside; other arrays refused."""

import io
import struct

import numpy as np
import pytest
from PIL import Image
from png_reference import spec_decode

from clrt import InputError, output


def decoded(data: bytes) -> Image.Image:
    Image.open(io.BytesIO(data)).verify()   # chunk CRCs and structure
    image = Image.open(io.BytesIO(data))
    image.load()
    return image


def pillow_png(array: np.ndarray) -> Image.Image:
    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="PNG")
    return decoded(buffer.getvalue())


def images():
    rng = np.random.default_rng(7)
    for shape in [(1, 1, 3), (1, 9, 3), (9, 1, 3), (31, 17, 3), (8, 5), (6, 7, 4), (1, 1), (5, 6, 2)]:
        yield f"random {shape}", rng.integers(0, 256, size=shape, dtype=np.uint8)
    flat = np.zeros((40, 60, 3), np.uint8)
    flat[10:30, 20:50] = (200, 30, 255)
    yield "flat with a box", flat
    yield "a column slice (not contiguous)", rng.integers(0, 256, size=(12, 20, 3), dtype=np.uint8)[:, ::2]
    yield "transposed", rng.integers(0, 256, size=(5, 11, 3), dtype=np.uint8).transpose(1, 0, 2)


@pytest.mark.parametrize("name, array", list(images()), ids=[name for name, _ in images()])
def test_same_pixels_and_mode_as_pillow(name, array):
    ours, theirs = decoded(output.png_bytes(array)), pillow_png(array)
    assert ours.mode == theirs.mode and ours.size == theirs.size
    np.testing.assert_array_equal(np.asarray(ours), array)
    np.testing.assert_array_equal(spec_decode(output.png_bytes(array)), array)
    assert ours.info["Software"].startswith(output.SOFTWARE_MARK)


@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (6, 4, 2), (9, 11, 3), (3, 8, 4), (1, 1, 3)])
def test_16_bit_images_keep_every_bit(shape):
    """16 bits a sample, big-endian: the specification's decoder gets the array
    back; Pillow (which holds no 16-bit colour mode) reads gray exactly and
    colour as the high bytes."""
    array = np.random.default_rng(11).integers(0, 1 << 16, size=shape, dtype=np.uint16)
    array.flat[0] = 0x0102   # high and low byte differ: a swapped pair would show
    data = output.png_bytes(array)
    assert struct.unpack(">IIBB", data[16:26])[2] == 16
    decoded_array = spec_decode(data)
    assert decoded_array.dtype == np.uint16 and np.array_equal(decoded_array, array)
    ours = decoded(data)
    assert ours.info["Software"].startswith(output.SOFTWARE_MARK)
    if len(shape) == 2:
        assert np.array_equal(np.asarray(ours).astype(np.int64), array)
    elif shape[2] in (3, 4):
        assert np.array_equal(np.asarray(ours), (array >> 8).astype(np.uint8))


def test_write_image_marks_its_png_and_records_it(tmp_path):
    path = tmp_path / "a.png"
    image = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    output.write_image(image, path)
    assert output.written_by_clrt(path) and output.record_path(path).exists()
    assert Image.open(path).info["Software"].startswith(output.SOFTWARE_MARK)
    np.testing.assert_array_equal(np.asarray(Image.open(path)), image)


@pytest.mark.parametrize("array", [np.zeros((4, 4, 3), np.float32), np.zeros((4, 4, 5), np.uint8),
                                   np.zeros((4, 4, 1), np.uint8), np.zeros((4, 4), np.int32),
                                   np.zeros((2, 2, 2, 3), np.uint8), np.zeros((0, 4, 3), np.uint8)],
                         ids=["float", "five channels", "one channel", "int32", "4-d", "empty"])
def test_other_arrays_are_refused(array):
    with pytest.raises(InputError, match="a PNG image must be"):
        output.png_bytes(array)


def test_gray_and_alpha_written(tmp_path):
    path = tmp_path / "la.png"
    array = np.full((3, 4, 2), 77, np.uint8)
    output.write_image(array, path)
    assert Image.open(path).mode == "LA" and output.written_by_clrt(path)


def test_a_png_edited_with_its_mark_kept_is_no_longer_clrts(tmp_path):
    """An image editor keeps a PNG's text chunks, clrt's Software mark among them:
    the mark says nothing about the pixels, the SHA-256 in the record does."""
    from PIL import Image, PngImagePlugin
    path = tmp_path / "e.png"
    image = np.random.default_rng(2).integers(0, 256, (20, 30, 3), dtype=np.uint8)
    output.write_image(image, path)
    assert output.file_state(path) == output.OURS
    with Image.open(path) as im:
        mark = im.info["Software"]
        edited = np.asarray(im).copy()
    edited[3, 4] = 255 - edited[3, 4]
    info = PngImagePlugin.PngInfo()
    info.add_text("Software", mark)                     # the mark kept, as editors keep it
    Image.fromarray(edited).save(path, pnginfo=info)
    with Image.open(path) as im:
        assert im.info["Software"] == mark
    assert output.file_state(path) == output.CHANGED and not output.written_by_clrt(path)
    # a copy of clrt's own file beside it, without the record, is not clrt's either
    copy = tmp_path / "copy.png"
    copy.write_bytes(output.png_bytes(image))
    assert output.file_state(copy) == output.FOREIGN
