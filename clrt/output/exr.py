"""OpenEXR files: the linear image, unclamped and without any sRGB curve, with
named channels (AOVs) beside R, G, B -- written through the optional OpenEXR
package (the 'exr' extra, imported only when an .exr is written), clrt's mark a
header attribute."""

from __future__ import annotations

from clrt.errors import InputError, OutputError
from clrt.output.files import mark_text

#: What writing an .exr says when OpenEXR is not installed.
EXR_INSTALL_HINT = "pip install 'clrt[exr]'"
# OpenEXR files carry the mark as a string attribute of their header, under this
# name (the header's other attributes are OpenEXR's own; tools such as
# exrheader and OpenImageIO list it).
EXR_MARK_ATTRIBUTE = "software"


def require_exr():
    """The OpenEXR module (the optional 'exr' extra), imported on first use -- only
    where an .exr is written; OutputError naming the fix where it is missing."""
    try:
        import OpenEXR
    except ImportError:
        raise OutputError(f"writing .exr files needs the OpenEXR package: {EXR_INSTALL_HINT}") from None
    return OpenEXR


def _exr_pixels(name: str, values, shape):
    """One channel as OpenEXR stores it: float16 (HALF) and float32 (FLOAT) as they
    are, float64 as float32, bool as HALF 0/1, integers as UINT (uint32; signed
    ones by their two's complement, so -1 reads back as 0xFFFFFFFF, and
    ``.view(np.int32)`` gives the signed values again)."""
    import numpy as np
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


def exr_layers(image, channels: dict | None = None) -> dict:
    """The channels of the EXR file :func:`clrt.output.write_exr` writes: R, G, B
    (and A) of ``image``, then ``channels``, each a C-contiguous (H, W) array of
    float32, float16 or uint32."""
    import numpy as np
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


def exr_writer(image, channels: dict | None = None):
    """(image, named channels) -> write(name): the OpenEXR file of ``image`` and
    ``channels`` (:func:`exr_layers`) at the path ``name``.  One part,
    scanlines, ZIP compression (lossless), clrt's mark in the header."""
    OpenEXR = require_exr()
    layers = exr_layers(image, channels)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              EXR_MARK_ATTRIBUTE: mark_text()}

    def write(name: str) -> None:
        try:
            OpenEXR.File(header, layers).write(name)
        except (RuntimeError, TypeError) as exc:   # OpenEXR's errors (a full disk, ...): "cannot write PATH: ..."
            raise OSError(str(exc)) from None

    return write
