"""Textures: images that colour a surface, as materials reference them.

A :class:`Texture` holds an image as the file stores it -- 8-bit sRGB, rows from
the top -- and how coordinates outside 0..1 wrap (clrt.config.TEXTURE_WRAPS).
Texture coordinates follow OBJ's (and trimesh's) convention: (0, 0) is the
image's bottom-left corner, (1, 1) its top-right one.  The kernels and the
reference tracer decode sRGB and filter bilinearly, each its own way.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from clrt import checks, config
from clrt.errors import InputError


def srgb_decode(values) -> np.ndarray:
    """Linear values (float64) of sRGB-encoded ones in 0..1 (IEC 61966-2-1)."""
    c = np.asarray(values, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def srgb_encode(linear, bits: int = 8) -> np.ndarray:
    """sRGB codes of linear values (IEC 61966-2-1), clamped to 0..1 (NaN as 0)
    and rounded to the nearest code: uint8 for ``bits`` 8 -- what the kernels'
    pixel colour does (render.cl) -- or uint16 for 16 (code 257 * k is the 8-bit code k)."""
    dtype = {8: np.uint8, 16: np.uint16}[bits]
    c = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float64), nan=0.0), 0.0, 1.0)
    codes = float(np.iinfo(dtype).max) * np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.rint(codes).astype(dtype)


def srgb_encode8(linear) -> np.ndarray:
    """8-bit sRGB codes (uint8) of linear values, clamped to 0..1 (what render.cl's pixel colour writes)."""
    return srgb_encode(linear, 8)


# Pillow's modes of 16-bit greyscale images (I: 32-bit integers, as which some
# Pillow versions open a 16-bit greyscale PNG).
_GREY_16 = ("I;16", "I;16L", "I;16B", "I;16N", "I")


@dataclass(frozen=True, eq=False)
class Texture:
    """An 8-bit sRGB image (``pixels``: (H, W, 3) uint8, row 0 at the top) and its
    wrap modes along u (``wrap_s``) and v (``wrap_t``): "repeat", "clamp" or
    "mirror".  Compared by identity (two loads of one file are two textures)."""

    pixels: np.ndarray = field(repr=False)
    wrap_s: str = "repeat"
    wrap_t: str = "repeat"
    name: str = ""

    def __post_init__(self):
        p = np.asarray(self.pixels)
        if p.ndim != 3 or p.shape[2] != 3 or p.dtype != np.uint8 or p.shape[0] < 1 or p.shape[1] < 1:
            raise InputError(f"texture pixels must be a (H, W, 3) uint8 array, got {p.dtype} {p.shape}")
        if max(p.shape[:2]) > config.MAX_IMAGE_SIDE:
            raise InputError(f"texture sides must be at most {config.MAX_IMAGE_SIDE} pixels, got "
                             f"{p.shape[1]}x{p.shape[0]}")
        object.__setattr__(self, "pixels", np.ascontiguousarray(p))
        for key in ("wrap_s", "wrap_t"):
            checks.choice(f"texture {key}", getattr(self, key), config.TEXTURE_WRAPS)

    def __repr__(self) -> str:
        h, w = self.pixels.shape[:2]
        return f"Texture({self.name!r}, {w}x{h}, wrap_s={self.wrap_s!r}, wrap_t={self.wrap_t!r})"

    @classmethod
    def from_image(cls, image, wrap_s: str = "repeat", wrap_t: str = "repeat", name: str = "") -> "Texture":
        """A Texture from a PIL image (any mode; alpha is dropped: Whitted shading has no coverage).

        16-bit greyscale (modes I;16, I;16L, I;16B, I;16N, and I, as which Pillow
        may open a 16-bit PNG) is scaled to 8 bits (v / 257, rounded):
        Pillow's own convert("RGB") would clip it at 255, making it white.
        Pillow opens 16-bit RGB(A) PNG files as 8-bit RGB(A) itself."""
        if image.mode in _GREY_16:
            grey = np.asarray(image).astype(np.float64)
            grey = np.rint(np.clip(grey, 0.0, 65535.0) / 257.0).astype(np.uint8)
            return cls(np.repeat(grey[:, :, None], 3, axis=2), wrap_s, wrap_t, name)
        return cls(np.asarray(image.convert("RGB"), dtype=np.uint8), wrap_s, wrap_t, name)

    @classmethod
    def read(cls, path, wrap_s: str = "repeat", wrap_t: str = "repeat") -> "Texture":
        """A Texture from an image file (PNG, JPEG, ... whatever Pillow reads);
        InputError naming the file if it cannot be read."""
        from PIL import Image, UnidentifiedImageError
        path = os.fspath(path)
        try:
            with Image.open(path) as image:
                image.load()
                return cls.from_image(image, wrap_s, wrap_t, os.path.basename(path))
        except FileNotFoundError:
            raise InputError(f"no such texture file: {path}") from None
        except (OSError, UnidentifiedImageError, ValueError, Image.DecompressionBombError) as exc:
            raise InputError(f"{path}: cannot read the texture image ({type(exc).__name__})") from None
