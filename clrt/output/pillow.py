"""Image formats that Pillow writes for clrt -- JPEG, TIFF, WebP, GIF (clrt's
mark inside) and BMP, PPM (no room for it).  Pillow is imported only when one
is used."""

from __future__ import annotations

from clrt.output.files import mark_text


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
