"""Parsing shared by the text formats (OFF, OBJ, ASCII PLY): lines, number
tables, vertex rows and polygon rows (:mod:`.triangulate` makes triangles of them).

Each parser first tries a vectorised path (np.loadtxt over a block of lines
with a uniform column count) and falls back to a per-line Python path, which
also finds the offending line for the error message.
"""

from __future__ import annotations

import io
import re
import warnings

import numpy as np

from clrt.scene.formats.part import fail, short


def decode(data: bytes) -> str:
    """Text of an ASCII format; latin-1 never fails, and numbers are ASCII anyway."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    return data.decode("latin-1")


def nonblank_lines(text: str) -> "list[str]":
    """Lines of ``text`` after removing ``#`` comments, without blank ones."""
    if "#" in text:
        text = re.sub(r"#[^\r\n]*", "", text)
    return [line for line in text.splitlines() if line and not line.isspace()]


def loadtxt(text: str, dtype) -> "np.ndarray | None":
    """(rows, k) array if every nonblank line of ``text`` holds k numbers of ``dtype``, else None."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.loadtxt(io.StringIO(text), dtype=dtype, ndmin=2, comments=None)
    except (ValueError, OverflowError):
        return None


def table(lines: "list[str]", dtype) -> "np.ndarray | None":
    """(len(lines), k) array if every line holds k numbers of ``dtype``, else None."""
    if not lines:
        return None
    values = loadtxt("\n".join(lines), dtype)
    return values if values is not None and len(values) == len(lines) else None


def xyz(lines: "list[str]", label: str, what: str = "vertex") -> np.ndarray:
    """(n, 3) float64 from lines of >= 3 numbers; extra columns (w, colour, normal) dropped."""
    values = table(lines, np.float64)
    if values is not None and values.shape[1] >= 3:
        return values[:, :3]
    rows = [line.split() for line in lines]
    for number, row in enumerate(rows, 1):
        if len(row) < 3:
            raise fail(label, f"{what} {number} has fewer than 3 coordinates")
    try:
        return np.array([row[:3] for row in rows], dtype=np.float64).reshape(-1, 3)
    except ValueError as exc:
        raise fail(label, f"malformed number in {what} data ({short(exc)})") from None


def polygons(lines: "list[str]", label: str, counted: bool, exact: bool = False):
    """``(counts (P,) int64, flat (sum(counts),) int64)`` of one polygon per line.

    counted: each line starts with its corner count (OFF, PLY), else every
    token is a corner (OBJ, slashes already removed).  Values after the
    corners are ignored (OFF face colours) unless ``exact``.
    """
    start = 1 if counted else 0
    values = table(lines, np.int64)
    if values is not None and values.shape[1] > start:
        corners = values[:, start:]
        width = corners.shape[1]
        counts = values[:, 0].copy() if counted else np.full(len(values), width, dtype=np.int64)
        lengths = np.full(len(values), width, dtype=np.int64)
        rows = None
    else:
        rows = [line.split() for line in lines]
        lengths = np.fromiter((len(row) - start for row in rows), dtype=np.int64,
                              count=len(rows))
        try:
            counts = (np.array([row[0] if row else "0" for row in rows], dtype=np.int64)
                      if counted else lengths)
        except (ValueError, OverflowError) as exc:
            raise fail(label, f"malformed face corner count ({short(exc)})") from None
    bad = np.flatnonzero(counts < 3)
    if bad.size:
        raise fail(label, f"face {bad[0] + 1} has {counts[bad[0]]} corners (needs at least 3)")
    bad = np.flatnonzero(counts != lengths if exact else counts > lengths)
    if bad.size:
        raise fail(label, f"face {bad[0] + 1} has {lengths[bad[0]]} values "
                          f"for {counts[bad[0]]} corners")
    if rows is None:
        # Row-major boolean mask keeps polygon order and corner order.
        flat = corners[np.arange(width) < counts[:, None]]
    else:
        try:
            flat = np.array([i for row, n in zip(rows, counts.tolist())
                             for i in row[start:start + n]], dtype=np.int64)
        except (ValueError, OverflowError) as exc:
            raise fail(label, f"malformed face index ({short(exc)})") from None
    return counts, flat

