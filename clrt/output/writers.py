"""The formats clrt writes, in one table (:data:`WRITERS`) that says what each
can hold, and the one rule for every file clrt writes.

Every writer -- ``clrt render -o``, the AOV files, batch frames, the Python
API -- finds its format with :func:`writer_for` (by the file's suffix), which
says in one line which formats can hold what was asked when this one cannot.
Adding a format is one entry below and its write function.

The rule: a file is written through a temporary file and a rename, with the
record of its SHA-256 beside it (the hidden file ``.NAME.clrt``,
clrt.output.files), and an existing file is replaced without ``force`` only if
it is still exactly what clrt wrote there (:func:`check_replace`) -- so a
re-run replaces its own outputs, and a file a user made, edited or put in
their place is refused.  Images in formats with room for text also carry
clrt's mark (PNG and TIFF "Software", JPEG and GIF comment, WebP XMP, OpenEXR
a ``software`` header attribute): it says who made them, and decides nothing.

numpy is imported by the functions that use it: the command line builds its
options from this table without it.
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral
from pathlib import Path
from typing import Callable

from clrt.errors import InputError, OutputError
from clrt.output.exr import exr_writer, require_exr
from clrt.output.files import ABSENT, CHANGED, NOT_A_FILE, OURS, file_state, record_path, replace_atomically
from clrt.output.pillow import pillow_writer
from clrt.output.png import png_writer

#: What a format can hold, by the pixels' dtype: "8-bit" sRGB codes (uint8),
#: "16-bit" sRGB codes (uint16), "float" linear light as it is (float32; float16
#: as half), or any "array" as it is (.npy).
DEPTHS = {"8-bit": "8-bit sRGB", "16-bit": "16-bit sRGB", "float": "linear float32", "array": "any array"}
#: Its channel sets, by the array's shape: (H, W) "gray", (H, W, 2) "gray+alpha",
#: (H, W, 3) "RGB", (H, W, 4) "RGBA"; "named": more channels by name (the AOVs of
#: clrt.query.aov.EXR_CHANNELS); "any": arrays of any shape.
CHANNELS = ("gray", "gray+alpha", "RGB", "RGBA", "named", "any")
#: The sRGB-encoded bit depths of ``--bit-depth`` and ``bit_depth=``.
BIT_DEPTHS = (8, 16)
_ALL = ("gray", "gray+alpha", "RGB", "RGBA")
_BITS = {"8-bit": 8, "16-bit": 16}


@dataclass(frozen=True)
class Writer:
    """One output format: what it holds and how clrt writes and recognises its files."""

    name: str                        # as messages name it
    suffixes: tuple[str, ...]        # the file names it is chosen by; clrt names new files with the first
    depths: tuple[str, ...]          # of DEPTHS
    channels: tuple[str, ...]        # of CHANNELS
    lossless: bool                   # reads back the pixels written
    mark: str                        # where clrt's mark goes ("none": no room); the record beside it decides
    prepare: Callable                # (pixels, named channels) -> write(target), which fills the temporary file
    by_name: bool = False            # write() gets the temporary file's name, not an open file
    require: Callable | None = None  # imports an optional package, OutputError naming the fix

    @property
    def suffix(self) -> str:
        return self.suffixes[0]

    def holds(self, depth: str | None = None, channels=()) -> bool:
        """Can this format hold images of ``depth`` (of DEPTHS) with ``channels``
        (of CHANNELS: a name or several)?"""
        channels = (channels,) if isinstance(channels, str) else channels
        return (depth is None or depth in self.depths) and all(c in self.channels for c in channels)

    def describe(self) -> str:
        """What it holds, in words: '8-bit sRGB or 16-bit sRGB gray, gray+alpha, RGB or RGBA images'."""
        return _phrase(self.depths, self.channels, " (and named channels)")


def _phrase(depths, channels, named=" with named channels") -> str:
    """'8-bit sRGB RGB images', 'linear float32 RGB images with named channels'."""
    if "array" in depths:
        return "arrays of any dtype and shape"
    named = named if "named" in channels else ""
    words = [_either(DEPTHS[d] for d in depths), _either(c for c in channels if c != "named"), "images"]
    return " ".join(w for w in words if w) + named


def _either(words) -> str:
    words = list(words)
    return " or ".join([", ".join(words[:-1]), words[-1]] if len(words) > 1 else words)


def _npy_writer(values, named=None):
    import numpy as np
    return lambda file: np.save(file, values)


#: Every format clrt writes, by name.  clrt itself writes PNG and .npy, Pillow
#: JPEG, TIFF, WebP (gray kept as RGB), GIF, BMP and PPM, OpenEXR the .exr files.
WRITERS = {w.suffix.lstrip("."): w for w in (
    Writer("PNG", (".png",), depths=("8-bit", "16-bit"), channels=_ALL, lossless=True,
           mark="Software text chunk", prepare=png_writer),
    Writer("JPEG", (".jpg", ".jpeg"), depths=("8-bit",), channels=("gray", "RGB"), lossless=False,
           mark="comment", prepare=pillow_writer("JPEG")),
    Writer("TIFF", (".tif", ".tiff"), depths=("8-bit",), channels=_ALL, lossless=True,
           mark="Software tag", prepare=pillow_writer("TIFF")),
    Writer("WebP", (".webp",), depths=("8-bit",), channels=_ALL, lossless=True,
           mark="XMP", prepare=pillow_writer("WEBP")),
    Writer("GIF", (".gif",), depths=("8-bit",), channels=("gray", "RGB"), lossless=False,   # 256 colours
           mark="comment", prepare=pillow_writer("GIF")),
    Writer("BMP", (".bmp",), depths=("8-bit",), channels=("gray", "RGB"), lossless=True,
           mark="none", prepare=pillow_writer("BMP")),
    Writer("PPM", (".ppm",), depths=("8-bit",), channels=("gray", "RGB"), lossless=True,
           mark="none", prepare=pillow_writer("PPM")),
    Writer("OpenEXR", (".exr",), depths=("float",), channels=("RGB", "RGBA", "named"), lossless=True,
           mark="software header attribute", prepare=exr_writer, by_name=True,
           require=require_exr),
    Writer("NumPy", (".npy",), depths=("array",), channels=("any",), lossless=True,
           mark="none", prepare=_npy_writer),
)}
_BY_SUFFIX = {s: w for w in WRITERS.values() for s in w.suffixes}
#: Writers of images (not only arrays), and their suffixes: what ``-o`` takes.
IMAGE_WRITERS = {k: w for k, w in WRITERS.items() if set(w.depths) - {"array"}}
IMAGE_SUFFIXES = tuple(s for w in IMAGE_WRITERS.values() for s in w.suffixes)
#: ``--format`` names: each image suffix without its dot.
FORMAT_NAMES = tuple(s.lstrip(".") for s in IMAGE_SUFFIXES)


def writer_for(path, depth: str | None = None, channels=()) -> Writer:
    """The writer of ``path``, by its suffix (any case), checked to hold
    ``depth`` (of DEPTHS) and ``channels`` (of CHANNELS, a name or several)
    where given: OutputError for an unknown suffix, InputError naming the
    formats that can hold what was asked -- one line either way."""
    path = Path(path)
    channels = (channels,) if isinstance(channels, str) else tuple(channels)
    writer = _BY_SUFFIX.get(path.suffix.lower())
    if writer is None:
        kind = f"unknown image type {path.suffix!r}" if path.suffix else "no image type suffix"
        known = [s for w in WRITERS.values() if w.holds(depth) for s in w.suffixes] if depth else IMAGE_SUFFIXES
        raise OutputError(f"cannot write {path}: {kind} (use one of {', '.join(known)})")
    if not writer.holds(depth, channels):
        asked = _phrase([depth] if depth else [], channels)
        able = [s for w in WRITERS.values() if w.holds(depth, channels) for s in w.suffixes]
        raise InputError(f"cannot write {path}: {writer.name} holds {writer.describe()}, not {asked}"
                         + (f"; formats that can: {', '.join(able)}" if able else ""))
    return writer


def format_writer(name: str, option: str = "format") -> Writer:
    """The image writer called ``name`` (a suffix without its dot: png, jpg, exr, ...)."""
    if not isinstance(name, str) or name.lower().lstrip(".") not in FORMAT_NAMES:
        raise InputError(f"{option} must be one of {', '.join(FORMAT_NAMES)}, got {name!r}")
    return _BY_SUFFIX["." + name.lower().lstrip(".")]


def check_bit_depth(bit_depth, option: str = "bit_depth") -> int | None:
    """None, or one of BIT_DEPTHS (an integer: not 8.0, not True)."""
    if bit_depth is None:
        return None
    if isinstance(bit_depth, bool) or not isinstance(bit_depth, Integral) or bit_depth not in BIT_DEPTHS:
        raise InputError(f"{option} must be {' or '.join(map(str, BIT_DEPTHS))}, got {bit_depth!r}")
    return int(bit_depth)


def linear_depth(writer: Writer, bit_depth: int | None = None) -> str:
    """The depth a linear image -- a render's -- is written at: ``bit_depth``'s,
    else linear float where the format holds it (OpenEXR), else 8-bit.  (A
    render's 8-bit image comes from the kernels' own sRGB encoding; 16-bit and
    float are made of its linear image.)"""
    bit_depth = check_bit_depth(bit_depth)
    if bit_depth is not None:
        return f"{bit_depth}-bit"
    return "float" if writer.holds("float") else "8-bit"


def render_writer(path, bit_depth: int | None = None) -> tuple[Writer, str]:
    """(writer, depth) of a render written to ``path`` at ``bit_depth`` (None: the
    format's own), checked before any render: one-line InputError (or
    OutputError) if the format cannot hold it, or its optional package is missing."""
    writer = writer_for(path)
    depth = linear_depth(writer, bit_depth)
    writer_for(path, depth, "RGB")
    if writer.require:
        writer.require()
    return writer, depth


# --------------------------------------------------------------------------- pixels

def encode_srgb(image, bits: int = 8):
    """A linear float image as sRGB codes: uint8 for ``bits`` 8, uint16 for 16, by
    the kernels' transfer function (clrt.scene.texture.srgb_encode: clamped to
    0..1, rounded to the nearest code).  The last channel of a gray+alpha or
    RGBA image is coverage, not light: scaled linearly.  Encoded a block of rows
    at a time, so that the float64 temporaries stay small."""
    import numpy as np

    from clrt.scene.texture import srgb_encode
    image = np.asarray(image)
    out = np.empty(image.shape, np.uint8 if bits == 8 else np.uint16)
    alpha = image.ndim == 3 and image.shape[2] in (2, 4)
    top = float(np.iinfo(out.dtype).max)
    step = max(1, (1 << 18) // max(1, image[:1].size))
    for r in range(0, image.shape[0], step):
        block = image[r:r + step]
        if alpha:
            out[r:r + step, :, :-1] = srgb_encode(block[..., :-1], bits)
            coverage = np.clip(np.nan_to_num(block[..., -1].astype(np.float64), nan=0.0), 0.0, 1.0)
            out[r:r + step, :, -1] = np.rint(top * coverage)
        else:
            out[r:r + step] = srgb_encode(block, bits)
    return out


def image_pixels(image, path, bit_depth: int | None = None, named: bool = False):
    """(writer, the pixels it stores) of ``image`` written to ``path``: uint8 as
    8-bit sRGB, uint16 as 16-bit sRGB (both as they are); floats as linear light
    -- as they are where the format holds linear floats (OpenEXR), else encoded
    to sRGB at ``bit_depth`` (default 8).  ``named``: the file also gets named
    channels.  InputError in one line for another dtype or shape, or what the
    format cannot hold."""
    import numpy as np
    image = np.asarray(image)
    path = Path(path)
    bit_depth = check_bit_depth(bit_depth)
    layout = "gray" if image.ndim == 2 else _ALL[image.shape[2] - 1] if image.ndim == 3 and 1 < image.shape[2] <= 4 \
        else None
    if layout is None or 0 in image.shape[:2]:
        raise InputError(f"cannot write {path}: an image must be (H, W) gray or (H, W, 2|3|4) gray+alpha, RGB "
                         f"or RGBA with at least one pixel, got shape {image.shape}")
    if image.dtype in (np.uint8, np.uint16):
        depth = f"{8 * image.dtype.itemsize}-bit"
        if bit_depth is not None and depth != f"{bit_depth}-bit":
            raise InputError(f"cannot write {path} at {bit_depth} bits: a {image.dtype} image is {DEPTHS[depth]} "
                             "already (give the linear float image to encode it)")
    elif image.dtype.kind == "f":
        depth = linear_depth(writer_for(path), bit_depth)
    else:
        raise InputError(f"cannot write {path}: image pixels must be uint8 (8-bit sRGB), uint16 (16-bit sRGB) "
                         f"or floats (linear), got {image.dtype}")
    try:
        writer = writer_for(path, depth, (layout, "named") if named else (layout,))
    except InputError as exc:
        if image.dtype.kind == "f" or not writer_for(path).holds("float"):
            raise
        raise InputError(f"{exc}; render with linear=True for the linear image") from None
    if image.dtype.kind == "f" and depth != "float":
        image = encode_srgb(image, _BITS[depth])
    return writer, image


# --------------------------------------------------------------------------- the one rule

def written_by_clrt(path: Path) -> bool:
    """Is the file at ``path`` exactly what clrt wrote there: does the record
    beside it (``.NAME.clrt``) hold its SHA-256?  (clrt.output.files.file_state)"""
    return file_state(path) == OURS


def check_replace(path: Path, force: bool, option: str = "-o") -> None:
    """OutputError unless ``path`` may be written: it does not exist, or it is
    exactly what clrt wrote there (its record holds its SHA-256), or ``force``.
    A folder or other non-file is never replaced.  ``option``: the command-line
    option that names the output, for the message."""
    state = file_state(path)
    if state == NOT_A_FILE:
        raise OutputError(f"cannot write {path}: it is not a regular file")
    if force or state in (ABSENT, OURS):
        return
    if state == CHANGED:
        raise OutputError(f"{path} was changed since clrt wrote it (its bytes are not those whose SHA-256 "
                          f"{record_path(path).name} holds); pass --force (-f; force=True in Python) to replace it, "
                          f"or choose another {option}")
    raise OutputError(f"{path} exists and was not written by clrt; pass --force (-f; force=True in Python) "
                      f"to replace it, or choose another {option}")


def _write(writer: Writer, path: Path, pixels, named: dict | None, force: bool) -> None:
    check_replace(path, force)
    if writer.require:
        writer.require()
    write = writer.prepare(pixels, named)
    replace_atomically(path, write, by_name=writer.by_name)


def write_image(image, path, force: bool = False, *, bit_depth: int | None = None,
                channels: dict | None = None) -> None:
    """Write an image in the format of ``path``'s suffix (:data:`WRITERS`), through
    a temporary file in the same folder and a rename, so that a reader never
    sees a half-written image and a failure leaves no file behind (an existing
    file stays as it was).  An existing file is replaced only if clrt wrote it,
    or with ``force`` (:func:`check_replace`).

    ``image``: (H, W) gray, (H, W, 2) gray+alpha, (H, W, 3) RGB or (H, W, 4)
    RGBA pixels -- uint8 (8-bit sRGB) or uint16 (16-bit sRGB, .png) as they
    are, or floats: linear light (``render(linear=True)``), written as they are
    to .exr and encoded to sRGB for any other format, at ``bit_depth`` 8
    (default) or 16 (.png).  ``channels``: more channels by name, for a format
    that holds them (.exr; :func:`write_exr`).  Any other dtype or shape, or
    what the format cannot hold: InputError naming the formats that can."""
    path = Path(path)
    writer, pixels = image_pixels(image, path, bit_depth, named=bool(channels))
    _write(writer, path, pixels, channels, force)


def write_exr(image, path, channels: dict | None = None, force: bool = False) -> None:
    """Write a linear image as an OpenEXR file (``.exr``), unclamped and without
    any sRGB curve, for compositing and tone mapping: ``image`` (H, W, 3) float
    linear RGB (``render(linear=True)``; float32 as FLOAT channels R, G, B, an
    RGBA image gets A), ``channels`` more channels by name (e.g. ``{"Z": depth}``,
    :func:`clrt.query.aov.exr_channels`), (H, W) arrays of float (FLOAT, or HALF
    for float16), bool (HALF 0/1) or integers (UINT).  One part, scanlines,
    ZIP compression (lossless), clrt's mark in the header (EXR_MARK_ATTRIBUTE).
    Written as :func:`write_image` writes: through a temporary file and a
    rename, over an existing file only if clrt wrote it or ``force``.  Needs
    the OpenEXR package (``pip install 'clrt[exr]'``; OutputError without it)."""
    path = Path(path)
    if writer_for(path) is not WRITERS["exr"]:
        raise OutputError(f"cannot write {path}: an OpenEXR file's name must end in {WRITERS['exr'].suffix}")
    write_image(image, path, force, channels=channels)


def write_array(values, path: Path, force: bool = False) -> None:
    """Write ``values`` as .npy, with its record beside it: an existing file is
    replaced only if it is what clrt wrote there, or with ``force``."""
    path = Path(path)
    _write(writer_for(path, "array"), path, values, None, force)


def write_file(data: bytes | str, path: Path, force: bool = False, option: str = "-o") -> None:
    """Write any other file clrt makes (a table, a chart, a ray file, a mesh),
    under the same rule as :func:`write_image`: atomically, with a record of its
    SHA-256 beside it, over an existing file only if clrt wrote it or ``force``."""
    path = Path(path)
    check_replace(path, force, option)
    if isinstance(data, str):
        data = data.encode("utf-8")
    replace_atomically(path, lambda f: f.write(data))
