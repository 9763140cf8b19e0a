"""Image formats that Pillow writes for clrt -- JPEG, TIFF, WebP, GIF (clrt's
mark inside) and BMP, PPM (no room for it: a record beside them) -- and the
mark read back through Pillow.  Pillow is imported only when one is used."""

from __future__ import annotations

from pathlib import Path

from clrt.output.files import SOFTWARE_MARK, mark_text


def _mark_options(fmt: str) -> dict:
    """Pillow's save options that put clrt's mark into a ``fmt`` file."""
    text = mark_text()
    if fmt == "TIFF":
        return {"tiffinfo": {305: text}}
    if fmt in ("JPEG", "GIF"):
        return {"comment": text}
    if fmt == "WEBP":   # lossless: a render's pixels are exact (Pillow's default is lossy, quality 80);
        # exact: so is the colour under alpha 0 (libwebp would drop it)
        return {"xmp": text.encode(), "lossless": True, "exact": True}
    return {}


def pillow_writer(fmt: str):
    """The writer of Pillow's format ``fmt``: (8-bit image, named channels) ->
    write(file), saving the image with clrt's mark where ``fmt`` has room."""
    def prepare(image, named=None):
        def write(file) -> None:
            from PIL import Image
            Image.fromarray(image).save(file, format=fmt, **_mark_options(fmt))
        return write
    return prepare


def read_pillow_mark(path: Path) -> bool:
    """Does the image at ``path`` carry clrt's mark where Pillow reads it (PNG and
    GIF comments, TIFF Software tag, WebP XMP)?  Only its header is read."""
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
