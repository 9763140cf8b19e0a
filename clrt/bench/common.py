"""The option types of ``clrt bench``, which the developer benchmarks (``benchmarks/``) share."""

from __future__ import annotations

import argparse


def parse_size(text: str) -> tuple[int, int]:
    """argparse type for an image size 'WxH', each side in 1..MAX_IMAGE_SIDE (checked
    while parsing, so that a bad size fails before any output folder is made)."""
    from clrt.config import MAX_IMAGE_SIDE
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        w = h = 0
    if not (1 <= w <= MAX_IMAGE_SIDE and 1 <= h <= MAX_IMAGE_SIDE):
        raise argparse.ArgumentTypeError(f"expected WxH with each side in 1..{MAX_IMAGE_SIDE}, got {text!r}")
    return w, h


def int_at_least(lo: int, hi: int | None = None):
    """argparse type: an integer >= lo (--repeat: 1, --warmup: 0), and <= hi if given."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = lo - 1
        if value < lo or (hi is not None and value > hi):
            rule = f"an integer in {lo}..{hi}" if hi is not None else f"an integer >= {lo}"
            raise argparse.ArgumentTypeError(f"expected {rule}, got {text!r}")
        return value
    return parse


POSITIVE, NON_NEGATIVE = int_at_least(1), int_at_least(0)


def rate(value: float) -> str:
    """A rate (Mrays/s, rays/s) to three significant figures, with thousands
    separators from 1,000 up (whole numbers there) and no exponent: 0.0123,
    1.50, 32.4, 873, 12,346; "inf" and "nan" as such."""
    import math
    if not math.isfinite(value):
        return str(value)
    if value == 0:
        return "0"
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    # round first: 99.96 becomes 100, then gets no decimals
    digits = 2 - math.floor(math.log10(abs(float(f"{value:.3g}"))))
    return f"{value:,.{max(0, digits)}f}"
