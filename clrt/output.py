"""Writing files safely: through a temporary file and a rename, and never over a
file that clrt did not write unless asked to (``force``)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from clrt.errors import OutputError

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
        return {"pnginfo": info}
    if fmt == "TIFF":
        return {"tiffinfo": {305: text}}
    if fmt in ("JPEG", "GIF"):
        return {"comment": text}
    if fmt == "WEBP":
        return {"xmp": text.encode()}
    return {}


def written_by_clrt(path: Path) -> bool:
    """Does the image file at ``path`` carry clrt's mark?  Only its header is read."""
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


def check_replace(path: Path, force: bool) -> None:
    """OutputError unless ``path`` may be written: it does not exist, or clrt wrote
    it, or ``force``.  A folder or other non-file is never replaced."""
    if not os.path.lexists(path):
        return
    if path.is_dir() or (path.exists() and not path.is_file()):
        raise OutputError(f"cannot write {path}: it is not a regular file")
    if not force and not written_by_clrt(path):
        raise OutputError(f"{path} exists and was not written by clrt; "
                          "pass --force (-f) to replace it, or choose another -o")


def _new_file_mode(path: Path) -> int:
    """The replaced file's permissions, else 0666 less the umask."""
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def write_image(image: np.ndarray, path: Path, force: bool = False) -> None:
    """Write an image through a temporary file in the same folder and a rename, so
    that a reader never sees a half-written image and a failure leaves no file
    behind (an existing file stays as it was).  An existing file is replaced only
    if clrt wrote it, or with ``force`` (:func:`check_replace`)."""
    from PIL import Image
    path = Path(path)
    check_replace(path, force)
    fmt = Image.registered_extensions()[path.suffix.lower()]
    _replace_atomically(path, lambda f: Image.fromarray(image).save(f, format=fmt, **_mark_options(fmt)))


def _replace_atomically(path: Path, write) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it into place."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        os.fchmod(fd, _new_file_mode(path))
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, (OSError, ValueError, KeyError)):
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise OutputError(f"cannot write {path}: {reason}") from None
        raise


def write_text(text: str, path: Path) -> None:
    """Write a text file (UTF-8) through a temporary file and a rename, replacing
    any file there (as :func:`write_image`, but without the mark check)."""
    data = text.encode("utf-8")
    _replace_atomically(Path(path), lambda f: f.write(data))


def write_array(values: np.ndarray, path: Path, marked_by: Path, force: bool = False) -> None:
    """Write ``values`` as .npy.  A .npy file carries no mark, so an existing one is
    replaced only if the image ``marked_by`` beside it was written by clrt, or
    with ``force``."""
    path = Path(path)
    if os.path.lexists(path) and not force:
        check_replace(path, force=written_by_clrt(Path(marked_by)))
    _replace_atomically(path, lambda f: np.save(f, values))
