"""Mitsuba 3's converged renders of the Cornell box (tests/data/cornell-box-mitsuba.npz) and a
noise-aware comparison of a path-traced image with them.  numpy only.

How the references are made, and how to make them again: docs/path-tracing.md, "Reference
images", and tests/data/README.md.  Layout: (H, W, 3) linear RGB, row 0 the top of the image and
column 0 its left, pixel (px, py) the average of the radiance over the square [px, px+1) x [py,
py+1) of clrt's camera model (clrt/kernels/camera.cl: sample offsets uniform in [0, 1)^2, a box
filter) -- the layout of clrt's own images, so that an image of ``clrt render`` compares as it is.

The comparison, :func:`compare`, works on blocks (8 x 8 pixels by default): the difference of the
block means of the two images over its standard error,

    z = (mean_block(image) - mean_block(reference)) / sqrt(var_block(image) + var_block(reference)),

var_block being the variance of a block mean: the sum of its pixels' variances over the block's
pixel count squared (pixels are independent).  Averaging over a block makes each z close to normal
even where single pixels are heavy-tailed (a path that finds the light by a BSDF sample), and it
keeps what a bias looks like: a wrong wall, a missing bounce, a light too bright all move whole
blocks.  Two figures decide: the largest |z| (a local error) and the mean of z^2 (a small error
spread over the whole image; 1 when the images agree).

Tolerance, for the 64 x 64 references here (64 blocks x 3 channels = 192 z's): when the image is
an unbiased estimate and its variance is right, max |z| <= 5 (Z_LIMIT) fails by chance with
probability about 1e-4, and mean z^2 <= 1.5 (MEAN_Z2_LIMIT: 1 + 5 sigma of a chi-square of 192
degrees of freedom over 192) about as rarely.  Measured with independent Mitsuba renders of the
same box at max depth 8 (20 of 256 spp; 10 stacks of 4 x 64 spp): max |z| at most 3.6 and 4.0,
mean z^2 0.57-1.07 and 0.81-1.14; depth 2 alike.  What that detects depends on the spp: one
path's standard deviation is about 0.86 x the pixel's value at max depth 8 (the median of
``sample_std / image``; 0.64 at depth 3, 0.26 at depth 2), so a block's relative standard error is
about 0.86 / sqrt(64 spp), 0.7 % at 256 spp.  At 256 spp a whole image 0.5 % too bright fails
(mean z^2 2.0 at depth 8, 5.4 at depth 2), and so does one 8 x 8 block 5 % off (|z| 9.8); at 64 spp
errors twice those.  The reference's own noise (65,536 spp) adds 0.4 % to the variance of a
256-spp image: negligible, and included.

The image's variance: pass ``variance`` (per pixel, of the image as an estimate) where the renderer
knows it, or render K >= 4 images with different seeds and pass them stacked, (K, H, W, 3): their
mean is compared and its variance estimated from their spread (:func:`mean_and_variance`).  With
neither, the variance is the reference's per-sample variance over ``spp`` -- Mitsuba's noise as a
stand-in for the renderer's, right only where both sample alike (NEE + MIS with the power
heuristic, as Mitsuba's ``path`` does); a renderer noisier by a factor r raises mean z^2 to r.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "data"
CORNELL_BOX_REFERENCE = DATA / "cornell-box-mitsuba.npz"
Z_LIMIT = 5.0          # largest |z| of a block
MEAN_Z2_LIMIT = 1.5    # mean of z^2 over blocks and channels


@dataclass(frozen=True)
class Reference:
    """A converged render: ``image`` (H, W, 3) float32 linear RGB, ``sample_std``
    (H, W, 3) float32 the standard deviation of one path's estimate of each
    pixel (measured from independent batches), ``spp`` the paths per pixel
    averaged, ``meta`` how it was made (scene file and its sha256, Mitsuba
    version and variant, the command, ...)."""

    image: np.ndarray
    sample_std: np.ndarray
    spp: int
    max_depth: int
    meta: dict

    @property
    def variance(self) -> np.ndarray:
        """(H, W, 3) variance of ``image`` itself, as an estimate of each pixel."""
        return self.sample_std.astype(np.float64) ** 2 / self.spp


def max_depths(path=CORNELL_BOX_REFERENCE) -> list[int]:
    """The max depths (Mitsuba's counting) the file holds a reference for."""
    with np.load(path, allow_pickle=False) as data:
        return sorted(int(k.split("_d")[1]) for k in data.files if k.startswith("image_d"))


def load_reference(max_depth: int = 8, path=CORNELL_BOX_REFERENCE) -> Reference:
    """The reference rendered with ``max_depth`` from ``path``."""
    with np.load(path, allow_pickle=False) as data:
        key = f"_d{max_depth}"
        if f"image{key}" not in data.files:
            raise KeyError(f"{path} has no reference for max depth {max_depth} (it has {max_depths(path)})")
        meta = json.loads(str(data["meta"]))
        return Reference(data[f"image{key}"].astype(np.float32), data[f"std{key}"].astype(np.float32),
                         int(meta["spp"]), max_depth, meta)


def mean_and_variance(renders) -> tuple[np.ndarray, np.ndarray]:
    """(K, H, W, 3) independent renders of equal spp (different seeds) -> their
    mean (H, W, 3) and the variance of that mean per pixel, from the spread of
    the K (unbiased: K - 1 degrees of freedom per pixel)."""
    renders = np.asarray(renders, dtype=np.float64)
    if renders.ndim != 4 or len(renders) < 2:
        raise ValueError(f"expected (K, H, W, 3) renders with K >= 2, got shape {renders.shape}")
    return renders.mean(axis=0), renders.var(axis=0, ddof=1) / len(renders)


def block_z(a, variance_a, b, variance_b, block: int = 8) -> np.ndarray:
    """(H/block, W/block, C) z of the block means of images ``a`` and ``b``
    (H, W, C), each with its per-pixel variance.  A block where both variances
    are 0 gets z 0 where the means are equal, else inf."""
    a, b, va, vb = (np.asarray(x, dtype=np.float64) for x in (a, b, variance_a, variance_b))
    h, w, c = a.shape
    if b.shape != a.shape or va.shape != a.shape or vb.shape != a.shape:
        raise ValueError(f"shapes differ: {a.shape}, {va.shape}, {b.shape}, {vb.shape}")
    if h % block or w % block:
        raise ValueError(f"a {w}x{h} image does not divide into {block}x{block} blocks")

    def sums(x):
        return x.reshape(h // block, block, w // block, block, c).sum(axis=(1, 3))

    n = block * block
    diff = (sums(a) - sums(b)) / n
    se = np.sqrt(sums(va + vb)) / n
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(se > 0, diff / np.where(se > 0, se, 1.0), np.where(diff == 0, 0.0, np.inf))


@dataclass(frozen=True)
class Comparison:
    """``z``: (H/block, W/block, 3) block z's (image minus reference);
    ``max_abs_z``, ``mean_z2``: the two figures the limits apply to;
    ``relative_bias``: (3,) whole-image mean of the image over the
    reference's, minus 1, per channel."""

    z: np.ndarray
    max_abs_z: float
    mean_z2: float
    relative_bias: np.ndarray

    def agrees(self, z_limit: float = Z_LIMIT, mean_z2_limit: float = MEAN_Z2_LIMIT) -> bool:
        return self.max_abs_z <= z_limit and self.mean_z2 <= mean_z2_limit

    def describe(self) -> str:
        worst = np.unravel_index(np.argmax(np.abs(np.nan_to_num(self.z, posinf=1e300, neginf=-1e300))), self.z.shape)
        return (f"max |z| {self.max_abs_z:.2f} (block row {worst[0]}, column {worst[1]}, channel {'RGB'[worst[2]]}), "
                f"mean z^2 {self.mean_z2:.3f} over {self.z.size}, whole-image bias RGB "
                + " ".join(f"{100 * b:+.2f}%" for b in self.relative_bias))


def compare(image, reference: Reference, spp: int | None = None, variance=None, block: int = 8) -> Comparison:
    """``image`` (H, W, 3) linear RGB -- or (K, H, W, 3) renders with different
    seeds -- against ``reference``.  The image's per-pixel variance: ``variance``
    if given, else the renders' spread, else ``reference.sample_std**2 / spp``
    (module docstring)."""
    image = np.asarray(image, dtype=np.float64)
    if image.ndim == 4:
        image, measured = mean_and_variance(image)
        variance = measured if variance is None else variance
    if image.shape != reference.image.shape:
        raise ValueError(f"image shape {image.shape}, reference {reference.image.shape}")
    if variance is None:
        if spp is None or spp < 1:
            raise ValueError("give the image's spp (or its variance, or several renders)")
        variance = reference.sample_std.astype(np.float64) ** 2 / spp
    z = block_z(image, variance, reference.image, reference.variance, block)
    finite = np.isfinite(z)
    ref_mean = reference.image.astype(np.float64).mean(axis=(0, 1))
    return Comparison(z, float(np.abs(z).max()) if finite.all() else float("inf"),
                      float(np.mean(z ** 2)) if finite.all() else float("inf"),
                      image.mean(axis=(0, 1)) / ref_mean - 1.0)


def assert_matches(image, reference: Reference, spp: int | None = None, variance=None,
                   z_limit: float = Z_LIMIT, mean_z2_limit: float = MEAN_Z2_LIMIT) -> Comparison:
    """:func:`compare`, and an AssertionError saying where and by how much
    unless the image agrees within the limits."""
    result = compare(image, reference, spp, variance)
    assert result.agrees(z_limit, mean_z2_limit), (
        f"max depth {reference.max_depth}: the image differs from Mitsuba's reference beyond noise "
        f"(limits: max |z| {z_limit}, mean z^2 {mean_z2_limit}): {result.describe()}")
    return result
