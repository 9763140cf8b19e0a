"""PNG files, written by clrt itself: 8-bit and 16-bit gray, gray+alpha, RGB
and RGBA, with clrt's mark in a ``Software`` text chunk."""

from __future__ import annotations

import struct
import zlib

from clrt.errors import InputError
from clrt.output.files import mark_text

# zlib level 1 for PNG files: for a 1920x1080 render of bunny00 (png_bytes,
# 2-core development machine) 18 ms for 179 KB, where level 6 (zlib's and
# Pillow's default) took 48 ms for 123 KB and level 0 10 ms for 6.2 MB.
PNG_COMPRESS_LEVEL = 1
_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# channels -> PNG colour type: gray, gray+alpha, RGB, RGBA
_COLOR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}


def png_bytes(image) -> bytes:
    """The PNG file of an image -- (H, W) gray, (H, W, 2) gray+alpha, (H, W, 3)
    RGB or (H, W, 4) RGBA; uint8 for 8 bits a sample, uint16 for 16 -- with
    clrt's mark in a ``Software`` text chunk.  InputError for any other array.

    Written here rather than by Pillow, for time to the first image, and
    because Pillow writes no 16-bit colour PNG: every row gets the Sub filter
    (each byte minus the same byte of the pixel to its left; a render's flat
    background becomes runs of zeros) and the whole image one zlib stream at
    PNG_COMPRESS_LEVEL.  For a 1920x1080 render of bunny00 on the 2-core
    development machine that took 18-24 ms for 179 KB, where Pillow at the
    same level took 68 ms for 169 KB -- choosing a filter for each row cost it
    some 50 ms (53 ms at level 0) -- and importing Pillow another 20 ms.  The
    8-bit pixels are those Pillow writes (tests/test_png.py).
    """
    import numpy as np
    image = np.asarray(image)
    channels = 1 if image.ndim == 2 else image.shape[2] if image.ndim == 3 and image.shape[2] > 1 else 0
    if image.dtype not in (np.uint8, np.uint16) or channels not in _COLOR_TYPES or 0 in image.shape[:2]:
        raise InputError(f"a PNG image must be (H, W) or (H, W, 2|3|4) uint8 or uint16 with at least one "
                         f"pixel, got {image.dtype} {image.shape}")
    bits = 8 * image.dtype.itemsize
    height, width = image.shape[:2]
    # 16-bit samples are big-endian; the filter works on bytes either way.
    flat = np.ascontiguousarray(image, dtype=image.dtype.newbyteorder(">")).view(np.uint8)
    flat = flat.reshape(height, width * channels * image.dtype.itemsize)
    step = channels * image.dtype.itemsize   # bytes a pixel
    rows = np.empty((height, 1 + flat.shape[1]), np.uint8)
    rows[:, 0] = 1   # filter type Sub
    rows[:, 1:1 + step] = flat[:, :step]
    np.subtract(flat[:, step:], flat[:, :-step], out=rows[:, 1 + step:])   # modulo 256
    data = zlib.compress(rows, PNG_COMPRESS_LEVEL)

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", width, height, bits, _COLOR_TYPES[channels], 0, 0, 0)
    mark = f"Software\0{mark_text()}".encode("latin-1")
    size = 1 << 24   # IDAT chunks of at most 16 MiB (the format allows 2 GiB)
    return b"".join([_SIGNATURE, chunk(b"IHDR", header), chunk(b"tEXt", mark),
                     *(chunk(b"IDAT", data[i:i + size]) for i in range(0, len(data), size)),
                     chunk(b"IEND", b"")])


def png_writer(image, named=None):
    """(image, named channels) -> write(file): the file of :func:`png_bytes`,
    encoded before the temporary file is made."""
    data = png_bytes(image)
    return lambda file: file.write(data)
