"""Bounding-volume shapes: fit a box, sphere or ellipsoid to every node.

Input is the exact box of each node's triangles; output is two float4 rows per
node, ``bound_a``/``bound_b``, which ``rows.py`` writes into the device layout.  Everything is computed in float64 from the float32
corners and then rounded *outwards* to float32, after padding by

    pad = REL_PAD * (largest extent of the node) + ULP_PAD * ulp32(|coordinate|) + PAD_FLOOR

per axis.  The exact box already contains every corner, but the kernel tests a
ray against the volume in float32 (slab or quadratic), whose rounding can lose a
ray that grazes a face or edge lying on the volume's boundary; the pad moves the
boundary about ten float32 ulps of the node's size (and at least four ulps of the
coordinates) away from every triangle.
Sphere radii and ellipsoid semi-axes are also inflated by ``EVAL_SLACK`` so that
the float32 evaluation of ``|p - c|^2 <= r^2`` or ``sum(((p - c) * inv)^2) <= 1``
holds for every point of the padded box.
"""

from __future__ import annotations

from typing import Tuple

import numpy as np

from clrt.config import VOLUMES


REL_PAD = 1e-6          # of the node's largest extent: ~10 float32 ulps of the node size
ULP_PAD = 4             # float32 ulps of the coordinate magnitude (covers tiny/flat nodes)
PAD_FLOOR = 1e-30       # keeps a point-sized node's volume a normal float32
EVAL_SLACK = 1e-6       # relative inflation of radius / semi-axes for float32 tests
ELLIPSE_FLOOR = 1e-3    # smallest semi-axis, relative to the node's largest semi-axis
SQRT3 = np.sqrt(3.0)
FIT_CHUNK = 2 ** 16     # nodes fitted at once


def fit_defines() -> dict:
    """The constants above as the device's fit (build_fit.cl) takes them, ``-D``
    defines of the device builder's and refit's programs: one source of truth
    (repr() of a float is a C double literal of the same value)."""
    return {"REL_PAD": repr(float(REL_PAD)), "ULP_PAD": int(ULP_PAD), "PAD_FLOOR": repr(float(PAD_FLOOR)),
            "EVAL_SLACK": repr(float(EVAL_SLACK)), "ELLIPSE_FLOOR": repr(float(ELLIPSE_FLOOR)),
            "SQRT3": repr(float(SQRT3))}


def round_down32(x: np.ndarray) -> np.ndarray:
    """float64 -> the largest float32 <= x."""
    y = x.astype(np.float32)
    np.nextafter(y, np.float32(-np.inf), out=y, where=y.astype(np.float64) > x)
    return y


def round_up32(x: np.ndarray) -> np.ndarray:
    """float64 -> the smallest float32 >= x."""
    y = x.astype(np.float32)
    np.nextafter(y, np.float32(np.inf), out=y, where=y.astype(np.float64) < x)
    return y


def padded_boxes(boxes: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(N, 2, 3) node boxes -> padded min, max (N, 3) float64 (not yet rounded)."""
    lo = boxes[:, 0].astype(np.float64)
    hi = boxes[:, 1].astype(np.float64)
    d = hi - lo
    extent = np.maximum(np.maximum(d[:, 0], d[:, 1]), d[:, 2])[:, None]
    magnitude = np.maximum(np.abs(boxes[:, 0]), np.abs(boxes[:, 1]))       # float32
    pad = ULP_PAD * np.spacing(magnitude).astype(np.float64)
    pad += REL_PAD * extent
    pad += PAD_FLOOR
    lo -= pad
    hi += pad
    return lo, hi


def fit(volume: str, boxes: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Bounds of every node for ``volume`` in ``VOLUMES``.

    boxes: (N, 2, 3) exact min/max of each node's triangles.
    Returns bound_a, bound_b: (N, 4) float32: box (min, max), sphere (centre +
    radius in w, zeros), ellipse (centre, reciprocal semi-axes); unused lanes 0.
    """
    if volume not in VOLUMES:
        raise ValueError(f"volume must be one of {VOLUMES}, got {volume!r}")
    a = np.zeros((len(boxes), 4), np.float32)
    b = np.zeros((len(boxes), 4), np.float32)
    # In chunks: the float64 temporaries stay small next to the tree itself.
    for start in range(0, len(boxes), FIT_CHUNK):
        end = start + FIT_CHUNK
        _fit(volume, boxes[start:end], a[start:end], b[start:end])
    return a, b


def _fit(volume: str, boxes: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
    """``fit`` of some nodes, written to their rows ``a``, ``b`` (zeroed)."""
    lo, hi = padded_boxes(boxes)
    if volume == "box":
        a[:, :3] = round_down32(lo)
        b[:, :3] = round_up32(hi)
        return

    # The paper's centre: midpoint of min and max.  It is rounded to float32 first
    # and the size is measured from the rounded centre, so rounding cannot
    # uncover a corner.
    centre = (0.5 * (lo + hi)).astype(np.float32)
    c = centre.astype(np.float64)
    half = np.maximum(c - lo, hi - c)                     # (N, 3) reach to the far face
    a[:, :3] = centre
    if volume == "sphere":
        # Radius = distance from the centre to the (farthest) box corner.
        radius = np.sqrt((half ** 2).sum(axis=1)) * (1.0 + EVAL_SLACK)
        a[:, 3] = round_up32(radius)
        return

    # Axis-aligned ellipsoid with semi-axes sqrt(3) * half-extent: a box corner
    # (+-h_x, +-h_y, +-h_z) gives sum(h_i^2 / (3 h_i^2)) = 1, on the surface, so the
    # box is enclosed.  A flat node (zero extent on an axis, only the pad left)
    # would get a needle-thin semi-axis and a huge 1/R, badly conditioned in
    # float32; it is raised to a floor instead.  Raising a semi-axis only grows the
    # ellipsoid, and sqrt(3) stays enough on the other axes: on a flat axis the
    # corner's coordinate is the centre's, its term is 0 whatever R is, and the
    # two other terms sum to 2/3 < 1.
    semi = SQRT3 * half
    semi = np.maximum(semi, ELLIPSE_FLOOR * semi.max(axis=1, keepdims=True))
    semi *= 1.0 + EVAL_SLACK
    b[:, :3] = round_down32(1.0 / semi)                   # smaller 1/R = larger R
