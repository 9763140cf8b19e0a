"""Environment maps: the radiance arriving from every direction of the sky,
as an equirectangular (latitude-longitude) HDR image.

An :class:`Environment` holds the image as linear float32 RGB, row 0 at the
top (straight up, +y), columns going round the vertical axis with the middle
column looking along -z and u growing towards +x (lights.cl says the mapping
in full); ``rotation`` turns it by that many degrees about +y and
``strength`` scales it.  Only the path tracer draws it (``integrator="path"``):
as the background its camera rays see, and as a light, importance-sampled by
luminance x sin(theta) through marginal and conditional CDFs that the host
builds (clrt/scene/emitters.py).

Files: OpenEXR (``.exr``, through the optional OpenEXR package, the 'exr'
extra) and Radiance RGBE (``.hdr``, read here with numpy: flat and
run-length-encoded scanlines, the -Y +X orientation every tool writes).
Anything else, or a file that is not such an image, is one InputError line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from clrt import checks
from clrt.errors import InputError

#: What --environment reads, by suffix.
ENVIRONMENT_SUFFIXES = (".exr", ".hdr")
EXR_HINT = "pip install 'clrt[exr]'"


@dataclass(frozen=True, eq=False)
class Environment:
    """An equirectangular environment map.

    ``image``: a path (``.exr`` or ``.hdr``) or an (H, W, 3) array of linear,
    finite, non-negative radiance (float32 on the device).  ``rotation``:
    degrees about +y; ``strength``: a factor (>= 0) of the radiance.
    """

    image: object = field(repr=False)
    rotation: float = 0.0
    strength: float = 1.0
    name: str = ""

    def __post_init__(self):
        image = self.image
        name = self.name
        if isinstance(image, (str, os.PathLike)):
            name = name or os.fspath(image)
            image = read_environment(image)
        pixels = np.asarray(image)
        if pixels.ndim != 3 or pixels.shape[2] not in (3, 4) or pixels.shape[0] < 1 or pixels.shape[1] < 1 \
                or pixels.dtype.kind not in "fiu":
            raise InputError(f"environment must be an (H, W, 3) array of radiance or an .exr / .hdr file, got "
                             f"{_describe(pixels)}")
        pixels = np.ascontiguousarray(pixels[..., :3], dtype=np.float32)
        bad = ~np.isfinite(pixels) | (pixels < 0)
        if bad.any():
            row, col, _ = np.argwhere(bad)[0]
            raise InputError(f"environment {name or 'image'}: radiance must be finite and >= 0, got "
                             f"{checks.show(tuple(float(x) for x in pixels[row, col]))} at pixel ({col}, {row})")
        object.__setattr__(self, "image", pixels)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "rotation", checks.number("environment rotation", self.rotation))
        object.__setattr__(self, "strength", checks.number("environment strength", self.strength, ge=0))

    @classmethod
    def of(cls, value) -> "Environment":
        """An Environment from an Environment, a path, an array, or a dict of its
        fields (``{"image": "sky.exr", "rotation": 90}``, as a scene file gives it)."""
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            unknown = set(value) - {"image", "rotation", "strength"}
            if unknown:
                raise InputError(f"unknown environment field {sorted(unknown)[0]!r} (expected image, rotation, "
                                 "strength)")
            if "image" not in value:
                raise InputError("environment needs its image (a .exr or .hdr file)")
            return cls(**value)
        return cls(value)


def _describe(a: np.ndarray) -> str:
    return f"an array of shape {a.shape} and dtype {a.dtype}"


def read_environment(path) -> np.ndarray:
    """(H, W, 3) float32 linear radiance of an .exr or .hdr file, row 0 at the top."""
    text = os.fspath(path)
    suffix = os.path.splitext(text)[1].lower()
    if suffix not in ENVIRONMENT_SUFFIXES:
        raise InputError(f"environment {text}: expected an equirectangular .exr or .hdr image")
    if not os.path.isfile(text):
        raise InputError(f"environment {text}: no such file")
    if suffix == ".exr":
        return _read_exr(text)
    with open(text, "rb") as f:
        data = f.read()
    try:
        return read_hdr(data)
    except (ValueError, IndexError) as exc:
        raise InputError(f"environment {text}: not a Radiance .hdr image ({exc})") from None


def _read_exr(path: str) -> np.ndarray:
    try:
        import OpenEXR
    except ImportError:
        raise InputError(f"reading .exr environment maps needs the OpenEXR package: {EXR_HINT}") from None
    try:
        channels = OpenEXR.File(path).channels()
    except (RuntimeError, TypeError, ValueError) as exc:
        raise InputError(f"environment {path}: not an OpenEXR image ({str(exc).splitlines()[0]})") from None
    for name in ("RGB", "RGBA"):
        if name in channels:
            return np.asarray(channels[name].pixels, np.float32)[..., :3]
    if "Y" in channels:   # a grey map
        y = np.asarray(channels["Y"].pixels, np.float32)
        return np.repeat(y[..., None], 3, axis=2)
    raise InputError(f"environment {path}: no R, G, B (or Y) channels, has {', '.join(sorted(channels))}")


def read_hdr(data: bytes) -> np.ndarray:
    """(H, W, 3) float32 of a Radiance RGBE file's bytes; ValueError where they are not one."""
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise ValueError("no #?RADIANCE header")
    end = data.find(b"\n\n")
    if end < 0:
        raise ValueError("no end of header")
    header = data[:end].split(b"\n")
    if not any(line.strip() == b"FORMAT=32-bit_rle_rgbe" for line in header[1:]) and any(
            line.startswith(b"FORMAT=") for line in header):
        raise ValueError("only the 32-bit_rle_rgbe format is read")
    line_end = data.find(b"\n", end + 2)
    size = data[end + 2:line_end].split()
    if len(size) != 4 or size[0] != b"-Y" or size[2] != b"+X":
        raise ValueError("only the -Y H +X W orientation is read")
    height, width = int(size[1]), int(size[3])
    if not (0 < height <= 1 << 16 and 0 < width <= 1 << 16):
        raise ValueError(f"image size {width}x{height}")
    raw = np.frombuffer(data, np.uint8, offset=line_end + 1)
    rgbe = np.empty((height, width, 4), np.uint8)
    at = 0
    for row in range(height):
        if 8 <= width < 32768 and raw[at] == 2 and raw[at + 1] == 2 and raw[at + 2] < 128:
            if (int(raw[at + 2]) << 8 | int(raw[at + 3])) != width:
                raise ValueError("a scanline's length is not the image's width")
            at += 4
            for channel in range(4):   # run-length encoded, one channel after another
                x = 0
                while x < width:
                    count = int(raw[at])
                    at += 1
                    if count > 128:
                        count -= 128
                        if x + count > width:
                            raise ValueError("a run past the end of a scanline")
                        rgbe[row, x:x + count, channel] = raw[at]
                        at += 1
                    else:
                        if count == 0 or x + count > width:
                            raise ValueError("a bad run in a scanline")
                        rgbe[row, x:x + count, channel] = raw[at:at + count]
                        at += count
                    x += count
        else:   # a flat scanline
            if at + 4 * width > len(raw):
                raise ValueError("the file ends within the pixels")
            rgbe[row] = raw[at:at + 4 * width].reshape(width, 4)
            at += 4 * width
    exponent = rgbe[..., 3].astype(np.int32)
    scale = np.where(exponent > 0, np.ldexp(1.0, exponent - 136), 0.0)
    return (rgbe[..., :3].astype(np.float64) * scale[..., None]).astype(np.float32)
