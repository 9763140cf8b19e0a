"""Writing files safely: through a temporary file and a rename, and never over a
file that clrt did not write unless asked to (``force``).

One rule for every file clrt writes: an existing file is replaced without
``force`` only if clrt can tell that it wrote it.  Images in formats with room
for text carry clrt's mark inside (PNG and TIFF "Software", JPEG and GIF
comment, WebP XMP, OpenEXR a ``software`` header attribute); files without
such room (.npy arrays, BMP, PPM) get a record beside them, the hidden file ``.NAME.clrt`` holding the SHA-256 of
what clrt wrote -- so a re-run replaces its own outputs, and a file a user
made or changed since is refused.
"""

from __future__ import annotations

import hashlib
import os
import struct
import tempfile
import threading
import zlib
from pathlib import Path

import numpy as np

from clrt import config
from clrt.errors import InputError, OutputError

# Every image clrt writes carries this mark ("Software" in PNG and TIFF, a comment in
# JPEG and GIF, XMP in WebP); an existing output is replaced without --force only
# if it carries the mark, so a re-run replaces its own render but never a user's file.
SOFTWARE_MARK = "clrt"


def _mark_options(fmt: str) -> dict:
    from PIL import PngImagePlugin

    from clrt import __version__
    text = f"{SOFTWARE_MARK} {__version__}"
    if fmt == "PNG":
        info = PngImagePlugin.PngInfo()
        info.add_text("Software", text)
        return {"pnginfo": info, "compress_level": PNG_COMPRESS_LEVEL}
    if fmt == "TIFF":
        return {"tiffinfo": {305: text}}
    if fmt in ("JPEG", "GIF"):
        return {"comment": text}
    if fmt == "WEBP":   # lossless: a render's pixels are exact (Pillow's default is lossy, quality 80)
        return {"xmp": text.encode(), "lossless": True}
    return {}


MARKED_FORMATS = ("PNG", "TIFF", "JPEG", "GIF", "WEBP")   # _mark_options can mark these
# OpenEXR files carry the mark as a string attribute of their header, under this
# name (the header's other attributes are OpenEXR's own; tools such as
# exrheader and OpenImageIO list it).
EXR_MARK_ATTRIBUTE = "software"
# zlib level 1 for PNG files: for a 1920x1080 render of bunny00 (png_bytes,
# 2-core development machine) 18 ms for 179 KB, where level 6 (zlib's and
# Pillow's default) took 48 ms for 123 KB and level 0 10 ms for 6.2 MB.
PNG_COMPRESS_LEVEL = 1
RECORD_PREFIX, RECORD_SUFFIX = ".", ".clrt"


def record_path(path: Path) -> Path:
    """The record beside a file clrt cannot mark: ``dir/.NAME.clrt``."""
    path = Path(path)
    return path.with_name(f"{RECORD_PREFIX}{path.name}{RECORD_SUFFIX}")


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _record_text(digest: str) -> str:
    from clrt import __version__
    return f"{SOFTWARE_MARK} {__version__} sha256 {digest}\n"


def _matches_record(path: Path) -> bool:
    """Is ``path`` exactly the file that clrt recorded writing there?"""
    try:
        words = record_path(path).read_text(encoding="ascii", errors="replace").split()
        return (len(words) == 4 and words[0] == SOFTWARE_MARK and words[2] == "sha256"
                and words[3] == _sha256(path))
    except OSError:
        return False


def written_by_clrt(path: Path) -> bool:
    """Did clrt write the file at ``path``?  Images of MARKED_FORMATS: does the
    file carry clrt's mark (only its header is read)?  Any other file: does its
    record (:func:`record_path`) hold the file's SHA-256?"""
    path = Path(path)
    if path.suffix.lower() == config.EXR_SUFFIX:
        return _exr_mark(path) or _matches_record(path)
    if config.IMAGE_FORMATS.get(path.suffix.lower()) not in MARKED_FORMATS:
        return _matches_record(path)
    # a chart or sheet written by write_file has a record rather than a mark
    return _has_mark(path) or _matches_record(path)


def _png_mark(path: Path) -> bool | None:
    """Does a PNG carry clrt's mark in a ``Software`` tEXt chunk before its image
    data (where clrt and Pillow write it)?  Read here without Pillow, whose
    import costs a re-render over its own output some 20 ms; None where unsure
    (not a PNG, compressed or international text chunks, a short file): then
    Pillow decides."""
    try:
        with open(path, "rb") as f:
            if f.read(8) != b"\x89PNG\r\n\x1a\n":
                return None
            while True:
                head = f.read(8)
                if len(head) < 8:
                    return None
                length, kind = struct.unpack(">I4s", head)
                if kind in (b"IDAT", b"IEND"):
                    return False
                if kind in (b"zTXt", b"iTXt"):
                    return None
                if kind == b"tEXt":
                    body = f.read(length)
                    keyword, _, text = body.partition(b"\0")
                    if keyword == b"Software" and text.decode("latin-1").startswith(SOFTWARE_MARK):
                        return True
                    f.seek(4, os.SEEK_CUR)           # its CRC
                else:
                    f.seek(length + 4, os.SEEK_CUR)
    except OSError:
        return None


_EXR_MAGIC = b"\x76\x2f\x31\x01"
_EXR_HEADER_LIMIT = 1 << 20   # clrt's headers are under 1 KB; one this long is not clrt's


def _exr_mark(path: Path) -> bool:
    """Does an OpenEXR file carry clrt's mark -- a string attribute
    EXR_MARK_ATTRIBUTE starting with SOFTWARE_MARK -- in its (first) header?
    The header is read here, without OpenEXR: a re-render over its own .exr
    needs only this, and a user's .exr is refused even where OpenEXR is not
    installed.  Layout (openexr.com, "OpenEXR File Layout"): magic number,
    4 version bytes, then attributes -- name NUL, type NUL, int32 size, value
    -- until an empty name."""
    try:
        with open(path, "rb") as f:
            head = f.read(_EXR_HEADER_LIMIT)
    except OSError:
        return False
    if head[:4] != _EXR_MAGIC:
        return False
    at = 8
    while True:
        end = head.find(b"\0", at)
        if end < 0 or end == at:   # cut short, or the empty name that ends the header
            return False
        name = head[at:end]
        type_end = head.find(b"\0", end + 1)
        if type_end < 0 or type_end + 5 > len(head):
            return False
        kind = head[end + 1:type_end]
        (size,) = struct.unpack("<i", head[type_end + 1:type_end + 5])
        value = head[type_end + 5:type_end + 5 + size]
        if size < 0 or len(value) < size:
            return False
        if name == EXR_MARK_ATTRIBUTE.encode() and kind == b"string":
            return value.decode("latin-1").startswith(SOFTWARE_MARK)
        at = type_end + 5 + size


def _has_mark(path: Path) -> bool:
    if config.IMAGE_FORMATS.get(Path(path).suffix.lower()) == "PNG":
        marked = _png_mark(path)
        if marked is not None:
            return marked
    import warnings

    from PIL import Image
    limit = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None   # our own large renders are no decompression bombs
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                values = [im.info.get("Software"), im.info.get("comment"), im.info.get("xmp")]
                tags = getattr(im, "tag_v2", None)
                if tags is not None:
                    values.append(tags.get(305))
    except Exception:  # noqa: BLE001 -- not an image PIL can read: not ours
        return False
    finally:
        Image.MAX_IMAGE_PIXELS = limit
    for value in values:
        if isinstance(value, bytes):
            value = value.decode("latin-1")
        if isinstance(value, str) and value.startswith(SOFTWARE_MARK):
            return True
    return False


def check_replace(path: Path, force: bool, option: str = "-o") -> None:
    """OutputError unless ``path`` may be written: it does not exist, or clrt wrote
    it, or ``force``.  A folder or other non-file is never replaced.  ``option``:
    the command-line option that names the output, for the message."""
    if not os.path.lexists(path):
        return
    if path.is_dir() or (path.exists() and not path.is_file()):
        raise OutputError(f"cannot write {path}: it is not a regular file")
    if not force and not written_by_clrt(path):
        raise OutputError(f"{path} exists and was not written by clrt (or was changed since); "
                          f"pass --force (-f; force=True in Python) to replace it, or choose another {option}")


def _umask() -> int:
    """The process's umask, read without changing it: os.umask can only be read
    by setting it, and another thread creating a file or folder in between (the
    batch workers write images in threads) would get the temporary mask.  Linux
    lists it in /proc/self/status; elsewhere the set-and-restore is kept."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    with _UMASK_LOCK:
        umask = os.umask(0)
        os.umask(umask)
    return umask


_UMASK_LOCK = threading.Lock()


def _new_file_mode(path: Path) -> int:
    """The replaced file's permissions, else 0666 less the umask."""
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        return 0o666 & ~_umask()


_PNG_COLOR_TYPES = {(2, 1): 0, (3, 3): 2, (3, 4): 6}   # (ndim, channels) -> gray, RGB, RGBA


def png_bytes(image: np.ndarray) -> bytes | None:
    """The PNG file of an 8-bit image -- (H, W) gray, (H, W, 3) RGB or (H, W, 4)
    RGBA uint8, the modes PIL.Image.fromarray gives them -- with clrt's mark in a
    ``Software`` text chunk; None for any other array (Pillow writes those).

    Written here rather than by Pillow, for time to the first image: every row
    gets the Sub filter (each byte minus the same channel of the pixel to its
    left; a render's flat background becomes runs of zeros) and the whole image
    one zlib stream at PNG_COMPRESS_LEVEL.  For a 1920x1080 render of bunny00 on
    the 2-core development machine that took 18-24 ms for 179 KB, where Pillow
    at the same level took 68 ms for 169 KB -- choosing a filter for each row
    cost it some 50 ms (53 ms at level 0) -- and importing Pillow another 20 ms.
    The pixels are the same either way (tests/test_png.py).
    """
    if image.dtype != np.uint8 or image.ndim not in (2, 3) or 0 in image.shape[:2]:
        return None
    channels = 1 if image.ndim == 2 else image.shape[2]
    color_type = _PNG_COLOR_TYPES.get((image.ndim, channels))
    if color_type is None:
        return None
    from clrt import __version__
    height, width = image.shape[:2]
    flat = np.ascontiguousarray(image).reshape(height, width * channels)
    rows = np.empty((height, 1 + flat.shape[1]), np.uint8)
    rows[:, 0] = 1   # filter type Sub
    rows[:, 1:1 + channels] = flat[:, :channels]
    np.subtract(flat[:, channels:], flat[:, :-channels], out=rows[:, 1 + channels:])   # modulo 256
    data = zlib.compress(rows, PNG_COMPRESS_LEVEL)

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0)
    mark = f"Software\0{SOFTWARE_MARK} {__version__}".encode("latin-1")
    step = 1 << 24   # IDAT chunks of at most 16 MiB (the format allows 2 GiB)
    return b"".join([b"\x89PNG\r\n\x1a\n", chunk(b"IHDR", header), chunk(b"tEXt", mark),
                     *(chunk(b"IDAT", data[i:i + step]) for i in range(0, len(data), step)),
                     chunk(b"IEND", b"")])


def write_image(image: np.ndarray, path: Path, force: bool = False) -> None:
    """Write an image through a temporary file in the same folder and a rename, so
    that a reader never sees a half-written image and a failure leaves no file
    behind (an existing file stays as it was).  An existing file is replaced only
    if clrt wrote it, or with ``force`` (:func:`check_replace`).  ``image``: 8-bit
    (H, W[, C]) uint8; for an ``.exr`` path, the float linear RGB image
    (:func:`write_exr`)."""
    path = Path(path)
    if path.suffix.lower() == config.EXR_SUFFIX:   # linear light, as OpenEXR
        write_exr(image, path, force=force)
        return
    check_replace(path, force)
    fmt = config.IMAGE_FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise OutputError(f"cannot write {path}: unknown image type {path.suffix!r} "
                          f"(use one of {', '.join(config.OUTPUT_SUFFIXES)})")
    data = png_bytes(image) if fmt == "PNG" else None
    if data is not None:
        _replace_atomically(path, lambda f: f.write(data))
        return
    from PIL import Image
    _replace_atomically(path, lambda f: Image.fromarray(image).save(f, format=fmt, **_mark_options(fmt)),
                        record=fmt not in MARKED_FORMATS)


def _replace_atomically(path: Path, write, record: bool = False, by_name: bool = False) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it into
    place; with ``record``, also (re)write the record of its SHA-256 beside it.
    ``by_name``: ``write`` gets the temporary file's path instead (for writers
    that open files themselves)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        os.fchmod(fd, _new_file_mode(path))
        with os.fdopen(fd, "wb") as f:
            write(tmp if by_name else f)
        digest = _sha256(Path(tmp)) if record else None
        os.replace(tmp, path)
        if record:   # after the file: a crash in between leaves a stale record, which refuses (safe)
            _write_record(path, digest)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, (OSError, ValueError, KeyError)):
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise OutputError(f"cannot write {path}: {reason}") from None
        raise


def write_file(data: bytes | str, path: Path, force: bool = False, option: str = "-o") -> None:
    """Write any other file clrt makes (a table, a chart, a ray file, a mesh),
    under the same rule as :func:`write_image`: atomically, with a record of its
    SHA-256 beside it, over an existing file only if clrt wrote it or ``force``."""
    path = Path(path)
    check_replace(path, force, option)
    if isinstance(data, str):
        data = data.encode("utf-8")
    _replace_atomically(path, lambda f: f.write(data), record=True)


def remove_written(paths) -> None:
    """Remove files this run wrote (and their records), when a later step of the
    same output failed or was interrupted: a half-finished set of outputs (an
    image without its AOVs) is not left behind."""
    for path in paths:
        for p in (Path(path), record_path(Path(path))):
            try:
                p.unlink()
            except OSError:
                pass


def _write_record(path: Path, digest: str) -> None:
    target = record_path(path)
    fd, tmp = tempfile.mkstemp(prefix=f"{target.name}.", dir=path.parent)
    try:
        os.fchmod(fd, _new_file_mode(target))
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(_record_text(digest))
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_array(values: np.ndarray, path: Path, force: bool = False) -> None:
    """Write ``values`` as .npy, with its record beside it (a .npy file has no room
    for a mark): an existing file is replaced only if it is what clrt wrote there,
    or with ``force``."""
    path = Path(path)
    check_replace(path, force)
    _replace_atomically(path, lambda f: np.save(f, values), record=True)


# --------------------------------------------------------------------------- OpenEXR

def require_exr():
    """The OpenEXR module (the optional 'exr' extra), imported on first use -- only
    where an .exr is written; OutputError naming the fix where it is missing."""
    try:
        import OpenEXR
    except ImportError:
        raise OutputError(f"writing .exr files needs the OpenEXR package: {config.EXR_INSTALL_HINT}") from None
    return OpenEXR


def _exr_pixels(name: str, values, shape) -> np.ndarray:
    """One channel as OpenEXR stores it: float16 (HALF) and float32 (FLOAT) as they
    are, float64 as float32, bool as HALF 0/1, integers as UINT (uint32; signed
    ones by their two's complement, so -1 reads back as 0xFFFFFFFF, and
    ``.view(np.int32)`` gives the signed values again)."""
    values = np.asarray(values)
    if values.shape != shape:
        raise InputError(f"EXR channel {name!r} must have the image's shape {shape}, got {values.shape}")
    kind = values.dtype.kind
    if kind == "b":
        return values.astype(np.float16)
    if kind == "f":
        return np.ascontiguousarray(values if values.dtype in (np.float16, np.float32) else values.astype(np.float32))
    if kind in "iu":
        limits = np.iinfo(np.int32 if kind == "i" else np.uint32)
        if values.size and (values.min() < limits.min or values.max() > limits.max):
            raise InputError(f"EXR channel {name!r}: integers must fit in {limits.dtype}")
        if kind == "i":
            return np.ascontiguousarray(values.astype(np.int32)).view(np.uint32)
        return np.ascontiguousarray(values.astype(np.uint32))
    raise InputError(f"EXR channel {name!r} must hold numbers, got {values.dtype}")


def exr_layers(image: np.ndarray, channels: dict | None = None) -> dict:
    """The channels of the EXR file :func:`write_exr` writes: R, G, B (and A) of
    ``image``, then ``channels``, each a C-contiguous (H, W) array of float32,
    float16 or uint32."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] not in (3, 4) or image.dtype.kind != "f":
        raise InputError(f"an EXR image must be linear RGB (or RGBA) floats of shape (H, W, 3) or (H, W, 4), "
                         f"got {image.dtype} {image.shape}; render with linear=True")
    if 0 in image.shape[:2]:
        raise InputError(f"an EXR image needs at least one pixel, got shape {image.shape}")
    # RGB as float32 (FLOAT), not half: the renderer computes in float32, and the
    # file then holds exactly what render(linear=True) returned.  Half keeps only
    # 11 bits (about 3 digits), turns anything above 65504 -- a bright
    # highlight, the weights go up to 1000 -- into inf, and would round dark
    # values that a later exposure change brings up; twice the size (ZIP
    # compressed) is the price.  A float16 image is written as half.
    names = "RGBA"[:image.shape[2]]
    layers = {c: _exr_pixels(c, image[..., k], image.shape[:2]) for k, c in enumerate(names)}
    for name, values in (channels or {}).items():
        if not isinstance(name, str) or not name or name in layers:
            raise InputError(f"EXR channel names must be distinct non-empty strings other than "
                             f"{', '.join(names)}, got {name!r}")
        layers[name] = _exr_pixels(name, values, image.shape[:2])
    return layers


def write_exr(image: np.ndarray, path: Path, channels: dict | None = None, force: bool = False) -> None:
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
    if path.suffix.lower() != config.EXR_SUFFIX:
        raise OutputError(f"cannot write {path}: an OpenEXR file's name must end in {config.EXR_SUFFIX}")
    check_replace(path, force)
    OpenEXR = require_exr()
    layers = exr_layers(image, channels)
    from clrt import __version__
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              EXR_MARK_ATTRIBUTE: f"{SOFTWARE_MARK} {__version__}"}

    def write(name: str) -> None:
        try:
            OpenEXR.File(header, layers).write(name)
        except (RuntimeError, TypeError) as exc:   # OpenEXR's errors (a full disk, ...)
            raise OutputError(f"cannot write {path}: {exc}") from None

    _replace_atomically(path, write, by_name=True)
